//! Ingest and the on-disk octree store (ARCHITECTURE.md step 1).
//!
//! **The octree.** The root cube is the points' bounding box, its largest edge enlarged by
//! [`CUBE_MARGIN`] and centred on the box. A cell at level `l` is one of the `8^l` equal cubes
//! of the root; its key ([`CellKey`]) is a level bit above its Morton code, so a parent's key
//! is its child's shifted right by three bits and the cells of a subtree are contiguous in key
//! order. The store's cells are the leaves of an adaptive cut of this octree: the coarsest
//! cells that hold at most `--max-cell-points` points ([`octree::Hierarchy`]).
//!
//! **The passes.** [`stage`] builds a store in four passes; two of them (count, scatter) read
//! every input point, each a parallel map over chunks of the memory-mapped inputs:
//!
//! 1. **bounds** ([`bounds`]): the provisional box, from the headers where every input has
//!    them (LAS; no read), else from a fixed sample of about 1/64 of the points, in windows
//!    of a fixed size (not the budget-sized chunks, so that the cube does not depend on
//!    `--threads` or `--mem`);
//! 2. **count** ([`count`]): each point's cell on a counting grid of `8^L` cells over the cube
//!    around the provisional box, `L` sized from the point count ([`octree::count_levels`])
//!    and the budget, while the exact bounds are measured and every coordinate checked
//!    finite. Only if the exact bounds leave the cube with less than half its margin is the
//!    count repeated on the exact cube. The grid is then cut into the hierarchy of cells;
//! 3. **scatter** ([`scatter`]): points grouped by cell and appended to per-cell buffers that
//!    are flushed as zstd frames of fixed-width records ([`cell_file`]) by a writer thread;
//! 4. **split** ([`split`]): a cell still over the limit (all its points in one grid cell) is
//!    counted again on a finer grid of its own and scattered into its sub-cells, reading only
//!    its own cell file.
//!
//! **Atomicity.** The store is built in a temporary directory next to the destination
//! ([`Staged`]); cell files are written there without a sync each (each carries a CRC-32 in
//! the manifest, so a store damaged by a power loss fails its check when read instead of
//! giving wrong points). [`Staged::commit`] writes `manifest.json` last, synced, and renames
//! the directory, so a store is either complete or absent. Between the two, the cells of a
//! staged store may be rewritten (with estimated normals, by the pipeline).
//!
//! **Checks.** [`Store::open`] trusts no manifest: it refuses one that lists a cell twice,
//! names a file outside `cells/` or miscounts, and cell files that are missing, linked or
//! resized ([`verify`]); reading a cell checks its record count and CRC-32.
//!
//! **Memory.** The counting grid ([`Share::CountingGrid`]), the chunks in flight
//! ([`Share::IngestChunks`], [`CHUNK_BYTES_PER_POINT`] a point) and the cell buffers
//! ([`Share::ScatterBuffers`]) are each admitted by the budget before they are allocated;
//! chunk size and buffer capacity are derived from it.

pub mod bounds;
pub mod cell_file;
pub mod count;
pub mod info;
pub mod input;
pub mod manifest;
pub mod octree;
pub mod scatter;
pub mod split;
pub mod verify;

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::exec::budget::Share;
use crate::io::InputSpec;
use crate::io::atomic;
use crate::types::{Aabb, CellKey, Cube, PointBatch, Viewpoint};
use cell_file::RecordLayout;
use input::Inputs;
use manifest::{CellEntry, EstimatedNormals, MANIFEST, Manifest, STORE_FORMAT, STORE_VERSION};
use octree::Hierarchy;
use scatter::{CellOut, Scatter};
use split::Splitter;

pub use info::{FileInfo, LasInfo, file_info};
pub use input::open_inputs;

/// The root cube is the bounding box's largest edge enlarged by 10% (PoissonRecon's default
/// `--scale 1.1`), centred on the box: reconstruction solves on this cube, and the margin keeps
/// the surface off its faces.
pub const CUBE_MARGIN: f64 = 0.1;

/// Bytes in flight per point of a chunk: mapped input (up to 64 bytes a record), the decoded
/// batch (52), its records (up to 52), and sort keys and leaf ids (12).
pub const CHUNK_BYTES_PER_POINT: u64 = 64 + 52 + 52 + 12;

/// Fewest points of a chunk sized from the budget: smaller chunks cost more in per-task and
/// per-read overhead than they save.
pub const MIN_CHUNK_POINTS: u64 = 4096;

/// Most points of a chunk (45 MiB in flight): larger ones only leave workers idle at the end
/// of a pass.
pub const MAX_CHUNK_POINTS: u64 = 1 << 18;

/// Chunks in flight per worker thread in a wave: one being processed, one ready for a worker
/// that finishes early.
const CHUNKS_PER_THREAD: usize = 2;

/// Directory of the cell files inside a store.
pub const CELLS_DIR: &str = "cells";

/// Where a store's normals come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NormalsMode {
    /// The inputs' normals when every input has them, else estimated.
    #[default]
    Auto,
    /// The inputs' normals; an input without them is an error.
    Use,
    /// Estimated, ignoring any normals in the inputs.
    Estimate,
}

impl std::str::FromStr for NormalsMode {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(NormalsMode::Auto),
            "use" => Ok(NormalsMode::Use),
            "estimate" => Ok(NormalsMode::Estimate),
            o => Err(Error::Usage(format!(
                "--normals \"{o}\": expected auto, use or estimate"
            ))),
        }
    }
}

/// Options of [`stage`].
#[derive(Debug, Clone)]
pub struct StoreParams {
    /// Cells are split until they hold at most this many points.
    pub max_cell_points: u64,
    /// Drop points with non-finite coordinates, or normals that are not finite or are zero,
    /// instead of failing.
    pub skip_invalid: bool,
    /// zstd level of cell files. The default, -1 (zstd's `--fast=1`), compresses twice as fast
    /// as level 1 for 6% larger cells (measured on 360 MB of sphere records: 0.74 s against
    /// 1.55 s, 276 MB against 261 MB).
    pub zstd_level: i32,
    /// Points per chunk; `None` sizes chunks from the budget.
    pub chunk_points: Option<u64>,
    /// Where normals come from; when they are to be estimated, the staged store's records
    /// carry none (and each point's scan while a viewpoint is known).
    pub normals: NormalsMode,
}

impl Default for StoreParams {
    fn default() -> Self {
        StoreParams {
            max_cell_points: 1_000_000,
            skip_invalid: false,
            zstd_level: -1,
            chunk_points: None,
            normals: NormalsMode::Auto,
        }
    }
}

/// What an ingest did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct IngestStats {
    /// Points stored.
    pub points: u64,
    /// Points dropped (`--skip-invalid`).
    pub skipped_invalid: u64,
    /// Cells written.
    pub cells: usize,
    /// Cells still over the limit (all their points in one finest cell).
    pub oversized_cells: usize,
    /// Input bytes.
    pub input_bytes: u64,
    /// Store bytes (cell files).
    pub store_bytes: u64,
    /// Wall time in seconds.
    pub secs: f64,
    /// Points per chunk used.
    pub chunk_points: u64,
    /// Counting grid levels.
    pub count_levels: u32,
    /// Normal estimation, when it ran: what it did and its wall time in seconds.
    pub normals: Option<(EstimatedNormals, f64)>,
}

/// Chunk and wave sizes of one ingest, derived from the budget.
#[derive(Debug, Clone, Copy)]
pub struct Sizes {
    /// Chunks read at once.
    pub wave: usize,
    /// Points per chunk.
    pub chunk_points: u64,
    /// Budget bytes of one chunk in flight.
    pub chunk_bytes: u64,
    /// Most levels a counting grid may have ([`count::max_levels`]).
    pub max_levels: u32,
}

impl Sizes {
    /// The sizes for `params` under `ctx`'s budget and threads.
    pub fn new(params: &StoreParams, ctx: &Ctx) -> Sizes {
        let wave = CHUNKS_PER_THREAD * ctx.threads();
        let chunk_points = params.chunk_points.unwrap_or_else(|| {
            (ctx.budget.share(Share::IngestChunks) / (wave as u64 * CHUNK_BYTES_PER_POINT))
                .clamp(MIN_CHUNK_POINTS, MAX_CHUNK_POINTS)
        });
        Sizes {
            wave,
            chunk_points,
            chunk_bytes: chunk_points * CHUNK_BYTES_PER_POINT,
            max_levels: count::max_levels(ctx.budget.share(Share::CountingGrid)),
        }
    }
}

/// The temporary directory a store is built in (`.NAME.tmp-<pid>`), removed unless committed.
struct TempDir(atomic::TempDir);

impl TempDir {
    /// A fresh temporary directory next to `out`, with its `cells/` directory.
    fn create(out: &Path) -> Result<TempDir> {
        let tmp = atomic::TempDir::create(out)
            .map_err(|e| Error::input(out, format!("cannot create the store: {e}")))?;
        let cells = tmp.path().join(CELLS_DIR);
        std::fs::create_dir(&cells).with_path(&cells)?;
        Ok(TempDir(tmp))
    }

    fn path(&self) -> &Path {
        self.0.path()
    }

    /// Rename the directory to `out`, unless something appeared there meanwhile.
    fn commit(self, out: &Path) -> Result<()> {
        if out.exists() {
            return Err(Error::input(
                out,
                "output store appeared while ingesting; not replaced",
            ));
        }
        self.0.commit(out)
    }
}

/// Run the four passes: ingest `inputs` into a store staged next to `out`, not yet committed.
pub fn stage(inputs: &[InputSpec], out: &Path, params: &StoreParams, ctx: &Ctx) -> Result<Staged> {
    let t0 = Instant::now();
    if params.max_cell_points == 0 {
        return Err(Error::Usage("--max-cell-points must be at least 1".into()));
    }
    if out.exists() {
        return Err(Error::input(
            out,
            "output store already exists; remove it or choose another -o",
        ));
    }
    let inputs = Inputs::open(inputs, params)?;
    let tmp = TempDir::create(out)?;
    let cells_dir = tmp.path().join(CELLS_DIR);
    let sizes = Sizes::new(params, ctx);
    let chunks = inputs.chunks(sizes.chunk_points)?;
    let input_bytes = inputs.input_bytes();

    // Pass 1: bounds.
    // The sample is cut in windows of a fixed size, not in the budget-sized chunks, so that
    // the cube (and every byte after it) is the same for any --threads and --mem.
    let windows = inputs.chunks(bounds::SAMPLE_WINDOW_POINTS)?;
    let window_bytes = bounds::SAMPLE_WINDOW_POINTS * CHUNK_BYTES_PER_POINT;
    let provisional = bounds::provisional(&inputs, &windows, window_bytes, ctx)?;

    // Pass 2: count (and exact bounds), cut into the hierarchy.
    let levels = octree::count_levels(inputs.total, params.max_cell_points, sizes.max_levels);
    let grid_permit = ctx
        .budget
        .acquire(count::grid_bytes(1u64 << (3 * levels)), "the counting grid")?;
    let counted = count::count_pass(
        &inputs,
        &chunks,
        sizes.chunk_bytes,
        &provisional,
        levels,
        ctx,
    )?;
    inputs.settle_colour_scale();
    if counted.bounds.is_empty() {
        return Err(Error::input(
            &inputs.specs[0].path,
            "no valid points: every point has a non-finite coordinate or an invalid normal",
        ));
    }
    let count::Counted {
        cube,
        counts,
        bounds,
        skipped,
    } = counted;
    let hier = Hierarchy::build(CellKey::ROOT, levels, &counts, params.max_cell_points);
    drop(counts);
    drop(grid_permit);

    // Pass 3: scatter.
    let cap = ctx.budget.share(Share::ScatterBuffers) as usize;
    let scatter_permit = ctx.budget.acquire(2 * cap as u64, "the cell buffers")?;
    let keys: Vec<CellKey> = hier.leaves.iter().map(|l| l.key).collect();
    let sc = Scatter::new(&cells_dir, &keys, inputs.layout, cap, params.zstd_level)?;
    let cells_out = scatter::scatter_pass(&inputs, &chunks, &sizes, &cube, &hier, sc, ctx)?;

    // Pass 4: split cells still over the limit.
    let splitter = Splitter {
        cube: &cube,
        layout: inputs.layout,
        max_cell_points: params.max_cell_points,
        zstd_level: params.zstd_level,
        sizes: &sizes,
        dir: &cells_dir,
    };
    let (cells_out, oversized_cells) = splitter.run(cells_out, &hier, ctx)?;
    drop(scatter_permit);

    let cells = cell_entries(&cells_out)?;
    Ok(Staged {
        tmp,
        out: out.to_path_buf(),
        inputs,
        cells,
        cube,
        bounds,
        levels,
        skipped,
        oversized_cells,
        input_bytes,
        chunk_points: sizes.chunk_points,
        max_cell_points: params.max_cell_points,
        zstd_level: params.zstd_level,
        t0,
    })
}

/// The manifest entries of the non-empty cells, in key order; the files of empty cells are
/// removed.
fn cell_entries(cells_out: &[CellOut]) -> Result<Vec<CellEntry>> {
    let mut cells: Vec<CellEntry> = cells_out
        .iter()
        .filter(|c| c.count > 0)
        .map(|c| {
            let (level, coords) = c.key.decode();
            CellEntry {
                key: c.key,
                level,
                coords,
                count: c.count,
                bounds: c.bounds,
                file: format!("{}.zst", c.key.file_name()),
                bytes: c.bytes,
                crc32: c.crc32(),
            }
        })
        .collect();
    for c in cells_out.iter().filter(|c| c.count == 0) {
        std::fs::remove_file(&c.file).with_path(&c.file)?;
    }
    cells.sort_by_key(|c| c.key);
    Ok(cells)
}

/// A store whose cells are written in its temporary directory, not yet committed: nothing
/// appears under its name until [`Staged::commit`], and dropping it removes the directory.
pub struct Staged {
    tmp: TempDir,
    out: PathBuf,
    inputs: Inputs,
    cells: Vec<CellEntry>,
    cube: Cube,
    bounds: Aabb,
    levels: u32,
    skipped: u64,
    oversized_cells: usize,
    input_bytes: u64,
    chunk_points: u64,
    max_cell_points: u64,
    zstd_level: i32,
    t0: Instant,
}

impl Staged {
    /// The temporary directory (scratch files may be kept in it until the commit).
    pub fn dir(&self) -> &Path {
        self.tmp.path()
    }

    /// The cells, in key order.
    pub fn cells(&self) -> &[CellEntry] {
        &self.cells
    }

    /// The root cube.
    pub fn cube(&self) -> &Cube {
        &self.cube
    }

    /// Layout of the records as written by the passes.
    pub fn layout(&self) -> RecordLayout {
        self.inputs.layout
    }

    /// Whether the normals are to be estimated before the commit (the records carry none).
    pub fn wants_normals(&self) -> bool {
        self.inputs.estimate_normals
    }

    /// Each input's viewpoint, by scan (the index the records carry).
    pub fn viewpoints(&self) -> Vec<Option<Viewpoint>> {
        self.inputs.specs.iter().map(|i| i.viewpoint).collect()
    }

    /// The file of cell `i`.
    pub fn cell_path(&self, i: usize) -> PathBuf {
        self.dir().join(CELLS_DIR).join(&self.cells[i].file)
    }

    /// Read every point of cell `i` as written by the passes, checking count and checksum.
    pub fn read_cell(&self, i: usize) -> Result<PointBatch> {
        let e = &self.cells[i];
        cell_file::read_cell_file(&self.cell_path(i), self.layout(), e.count, e.crc32)
    }

    /// Rewrite cell `i` from `b`, its points in the same order with their normals, in the
    /// layout with normals; returns the file's size and CRC-32 for [`Staged::set_cell_file`].
    pub fn rewrite_with_normals(&self, i: usize, b: &PointBatch) -> Result<(u64, u32)> {
        let layout = self.layout().with_normals();
        cell_file::write_cell_file(&self.cell_path(i), layout, b, self.zstd_level)
    }

    /// Record the size and CRC-32 of cell `i`'s rewritten file.
    pub fn set_cell_file(&mut self, i: usize, bytes: u64, crc32: u32) {
        self.cells[i].bytes = bytes;
        self.cells[i].crc32 = crc32;
    }

    /// Write the manifest (last, synced) and rename the directory to its final name. When
    /// [`Staged::wants_normals`], `normals` says how they were estimated and every cell must
    /// have been rewritten with them; else it is `None`.
    pub fn commit(self, normals: Option<(EstimatedNormals, f64)>) -> Result<IngestStats> {
        if normals.is_some() != self.wants_normals() {
            return Err(Error::Internal(format!(
                "store committed with estimated normals {}, but they were {}wanted",
                normals.is_some(),
                if self.wants_normals() { "" } else { "not " }
            )));
        }
        let layout = if normals.is_some() {
            self.layout().with_normals()
        } else {
            self.layout()
        };
        let points: u64 = self.cells.iter().map(|c| c.count).sum();
        let (skipped, total) = (self.skipped, self.inputs.total);
        if points + skipped != total {
            return Err(Error::Internal(format!(
                "ingest stored {points} points and skipped {skipped}, but the inputs hold {total}"
            )));
        }
        let store_bytes = self.cells.iter().map(|c| c.bytes).sum();
        let cells = self.cells.len();
        let manifest = Manifest {
            format: STORE_FORMAT.into(),
            version: STORE_VERSION,
            point_count: points,
            skipped_invalid: skipped,
            attributes: layout.attrs,
            record_bytes: layout.stride,
            record_fields: manifest::record_fields(layout.attrs, layout.pos_f32),
            position_f32: layout.pos_f32,
            compression: "zstd".into(),
            bounds: self.bounds,
            cube: self.cube,
            max_cell_points: self.max_cell_points,
            count_levels: self.levels,
            inputs: self.inputs.entries(),
            cells: self.cells,
            estimated_normals: normals.as_ref().map(|n| n.0.clone()),
        };
        manifest.save(self.tmp.path())?;
        self.tmp.commit(&self.out)?;
        Ok(IngestStats {
            points,
            skipped_invalid: skipped,
            cells,
            oversized_cells: self.oversized_cells,
            input_bytes: self.input_bytes,
            store_bytes,
            secs: self.t0.elapsed().as_secs_f64(),
            chunk_points: self.chunk_points,
            count_levels: self.levels,
            normals,
        })
    }
}

/// A store opened for reading.
#[derive(Debug, Clone)]
pub struct Store {
    /// Its directory.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: Manifest,
    /// Record layout.
    pub layout: RecordLayout,
}

impl Store {
    /// Open a store and check its manifest and that its cell files are there, each a regular
    /// file of the listed size ([`verify`]); reads no cell.
    pub fn open(dir: &Path) -> Result<Store> {
        let manifest = Manifest::load(dir)?;
        let layout = RecordLayout::new(manifest.attributes, manifest.position_f32);
        if layout.stride != manifest.record_bytes {
            return Err(Error::input(
                dir.join(MANIFEST),
                format!(
                    "record_bytes is {} but the attributes make records of {} bytes",
                    manifest.record_bytes, layout.stride
                ),
            ));
        }
        verify::check_manifest(dir, &manifest)?;
        let store = Store {
            dir: dir.to_path_buf(),
            manifest,
            layout,
        };
        verify::check_cell_files(&store)?;
        Ok(store)
    }

    /// The file of cell `i`.
    pub fn cell_path(&self, i: usize) -> PathBuf {
        self.dir.join(CELLS_DIR).join(&self.manifest.cells[i].file)
    }

    /// Read every point of cell `i`, checking its count and checksum.
    pub fn read_cell(&self, i: usize) -> Result<PointBatch> {
        let e = &self.manifest.cells[i];
        cell_file::read_cell_file(&self.cell_path(i), self.layout, e.count, e.crc32)
    }
}
