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
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, exec, fs, geom, types};
use scanflow_formats as io;

pub mod assemble;
pub mod bounds;
pub mod cell_file;
pub mod count;
pub mod info;
pub mod input;
pub mod manifest;
pub mod normals;
pub mod octree;
pub mod scatter;
pub mod split;
pub mod verify;

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, IoContext, Result, Setting};
use crate::exec::Ctx;
use crate::exec::budget::Share;
use crate::exec::progress::Stage;
use crate::fs::atomic;
use crate::io::{ChunkSpec, InputSpec};
use crate::types::{Aabb, CellKey, Cube, PointBatch, Viewpoint};
use cell_file::RecordLayout;
pub use count::Partial;
use input::Inputs;
use manifest::{CellEntry, EstimatedNormals, MANIFEST, Manifest, STORE_FORMAT, STORE_VERSION};
use octree::Hierarchy;
use scatter::{CellOut, PackIndex, Scatter, Scattered};
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
                "{} \"{o}\": expected auto, use or estimate",
                Setting::Normals
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
        let mut wave = CHUNKS_PER_THREAD * ctx.threads();
        let share = ctx.budget.share(Share::IngestChunks);
        let chunk_points = match params.chunk_points {
            // Chunks of a given size: as many in flight as the slice holds, two at least.
            Some(n) => {
                wave = wave
                    .min((share / (n * CHUNK_BYTES_PER_POINT).max(1)) as usize)
                    .max(2);
                n
            }
            None => (share / (wave as u64 * CHUNK_BYTES_PER_POINT))
                .clamp(MIN_CHUNK_POINTS, MAX_CHUNK_POINTS),
        };
        Sizes {
            wave,
            chunk_points,
            chunk_bytes: chunk_points * CHUNK_BYTES_PER_POINT,
            max_levels: count::max_levels(ctx.budget.share(Share::CountingGrid)),
        }
    }
}

/// The directory a store is built in: a temporary one next to the destination
/// (`.NAME.tmp-<pid>`, removed unless committed), or a split ingest's, shared by its tasks in
/// their work directory (left for the work directory's removal).
pub enum StageDir {
    /// One process's.
    Temp(atomic::TempDir),
    /// The shards'.
    Shared(PathBuf),
}

impl StageDir {
    /// A fresh temporary directory next to `out`, with its `cells/` directory.
    fn create(out: &Path) -> Result<StageDir> {
        let tmp = atomic::TempDir::create(out)
            .map_err(|e| Error::input(out, format!("cannot create the store: {e}")))?;
        let cells = tmp.path().join(CELLS_DIR);
        std::fs::create_dir(&cells).with_path(&cells)?;
        Ok(StageDir::Temp(tmp))
    }

    fn path(&self) -> &Path {
        match self {
            StageDir::Temp(t) => t.path(),
            StageDir::Shared(p) => p,
        }
    }

    /// Rename the directory to `out`, unless something appeared there meanwhile.
    fn commit(self, out: &Path) -> Result<()> {
        if out.exists() {
            return Err(Error::input(
                out,
                "output store appeared while ingesting; not replaced",
            ));
        }
        match self {
            StageDir::Temp(t) => t.commit(out),
            StageDir::Shared(p) => {
                std::fs::rename(&p, out).with_path(out)?;
                atomic::sync_parent_dir(out);
                Ok(())
            }
        }
    }
}

/// An ingest's inputs opened, its sizes chosen from the budget and the provisional bounds read
/// (pass 1): where one process's ingest ([`stage`]) and every task of a split one start.
pub struct Prepared {
    /// The opened inputs.
    pub inputs: Inputs,
    /// Chunk and wave sizes.
    pub sizes: Sizes,
    /// The options.
    pub params: StoreParams,
    /// The provisional bounds the first count's cube is laid around.
    pub provisional: Aabb,
    /// Levels of the counting grid.
    pub levels: u32,
    /// Bytes the cell buffers of a scatter hold before they are flushed.
    pub cap: usize,
    t0: Instant,
}

impl Prepared {
    /// Open `inputs` and read the provisional bounds (pass 1).
    pub fn open(inputs: &[InputSpec], params: &StoreParams, ctx: &Ctx) -> Result<Prepared> {
        Prepared::open_chunked(inputs, params, |_| params.chunk_points, ctx)
    }

    /// [`Prepared::open`], the points per chunk chosen by `chunk_points` from the inputs'
    /// point count (`None`: from the budget).
    pub fn open_chunked(
        inputs: &[InputSpec],
        params: &StoreParams,
        chunk_points: impl Fn(u64) -> Option<u64>,
        ctx: &Ctx,
    ) -> Result<Prepared> {
        let t0 = Instant::now();
        if params.max_cell_points == 0 {
            return Err(Error::Usage(format!(
                "{} must be at least 1",
                Setting::MaxCellPoints
            )));
        }
        let inputs = Inputs::open(inputs, params)?;
        let params = StoreParams {
            chunk_points: chunk_points(inputs.total),
            ..params.clone()
        };
        let sizes = Sizes::new(&params, ctx);
        // The sample is cut in windows of a fixed size, not in the budget-sized chunks, so that
        // the cube (and every byte after it) is the same for any --threads and --mem.
        let windows = inputs.chunks(bounds::SAMPLE_WINDOW_POINTS)?;
        let window_bytes = bounds::SAMPLE_WINDOW_POINTS * CHUNK_BYTES_PER_POINT;
        let provisional = bounds::provisional(&inputs, &windows, window_bytes, ctx)?;
        let levels = octree::count_levels(inputs.total, params.max_cell_points, sizes.max_levels);
        Ok(Prepared {
            inputs,
            sizes,
            params,
            provisional,
            levels,
            cap: ctx.budget.share(Share::ScatterBuffers) as usize,
            t0,
        })
    }

    /// Flush the cell buffers at `cap` bytes at most (a split ingest's tasks, whose budgets
    /// may differ a little, all flush alike: the cells' frames follow the flushes).
    pub fn limit_buffers(&mut self, cap: usize) {
        self.cap = self.cap.min(cap);
    }

    /// The inputs cut in chunks of [`Sizes::chunk_points`].
    pub fn chunks(&self) -> Result<Vec<(usize, ChunkSpec)>> {
        self.inputs.chunks(self.sizes.chunk_points)
    }

    /// Bytes the budget admits for one counting grid ([`count::grid_bytes`]).
    pub fn grid_bytes(&self) -> u64 {
        count::grid_bytes(1u64 << (3 * self.levels))
    }

    /// Count `chunks` on the grid over `cube` (a part of pass 2).
    pub fn count(
        &self,
        chunks: &[(usize, ChunkSpec)],
        cube: &Cube,
        stage: &Stage,
        ctx: &Ctx,
    ) -> Result<count::Partial> {
        count::count_chunks(
            &self.inputs,
            chunks,
            self.sizes.chunk_bytes,
            cube,
            self.levels,
            stage,
            ctx,
        )
    }

    /// The hierarchy of cells cut from the summed counts of the grid.
    pub fn hierarchy(&self, counts: &[u64]) -> Hierarchy {
        Hierarchy::build(
            CellKey::ROOT,
            self.levels,
            counts,
            self.params.max_cell_points,
        )
    }

    /// Scatter `chunks` into the leaves of `hier` over `cube`, `into` their cell files or one
    /// pack (a part of pass 3), the cell buffers admitted by the budget meanwhile.
    pub fn scatter(
        &self,
        into: ScatterInto,
        chunks: &[(usize, ChunkSpec)],
        cube: &Cube,
        hier: &Hierarchy,
        stage: &Stage,
        ctx: &Ctx,
    ) -> Result<Scattered> {
        let _permit = ctx
            .budget
            .acquire(2 * self.cap as u64, "the cell buffers")?;
        let keys: Vec<CellKey> = hier.leaves.iter().map(|l| l.key).collect();
        let (layout, level) = (self.inputs.layout, self.params.zstd_level);
        let sc = match into {
            ScatterInto::Cells(dir) => Scatter::new(dir, &keys, layout, self.cap, level)?,
            ScatterInto::Pack(pack) => Scatter::packed(pack, &keys, layout, self.cap, level)?,
        };
        scatter::scatter_pass(self, chunks, cube, hier, sc, stage, ctx)
    }

    /// [`Prepared::scatter`] into the one file `pack`, its index appended (a split ingest's
    /// slice of the inputs).
    pub fn scatter_pack(
        &self,
        chunks: &[(usize, ChunkSpec)],
        cube: &Cube,
        hier: &Hierarchy,
        pack: &Path,
        stage: &Stage,
        ctx: &Ctx,
    ) -> Result<PackIndex> {
        let out = self.scatter(ScatterInto::Pack(pack), chunks, cube, hier, stage, ctx)?;
        let idx = out
            .pack
            .ok_or_else(|| Error::Internal("a packed scatter returned no index".into()))?;
        idx.append_to(pack)?;
        Ok(idx)
    }

    /// The split pass (pass 4) over cube `cube`, writing into `dir`.
    pub fn splitter<'a>(&'a self, cube: &'a Cube, dir: &'a Path) -> Splitter<'a> {
        Splitter {
            cube,
            layout: self.inputs.layout,
            max_cell_points: self.params.max_cell_points,
            zstd_level: self.params.zstd_level,
            sizes: &self.sizes,
            dir,
            cap: self.cap,
        }
    }

    /// The store whose cells `cells` lie in `dir`'s `cells/`, ready for normals and the commit.
    pub fn staged(self, dir: StageDir, out: &Path, cells: Vec<CellEntry>, found: Found) -> Staged {
        Staged {
            tmp: dir,
            raw: None,
            out: out.to_path_buf(),
            input_bytes: self.inputs.input_bytes(),
            chunk_points: self.sizes.chunk_points,
            max_cell_points: self.params.max_cell_points,
            zstd_level: self.params.zstd_level,
            skip_invalid: self.params.skip_invalid,
            levels: self.levels,
            inputs: self.inputs,
            cells,
            found,
            t0: self.t0,
        }
    }
}

/// Where a scatter writes its frames.
#[derive(Debug, Clone, Copy)]
pub enum ScatterInto<'a> {
    /// One file per cell, in this directory.
    Cells(&'a Path),
    /// One pack file for every cell ([`Scatter::packed`]).
    Pack(&'a Path),
}

/// What the count and split passes found about the whole store.
#[derive(Debug, Clone, Copy)]
pub struct Found {
    /// The root cube.
    pub cube: Cube,
    /// The exact bounds of the points.
    pub bounds: Aabb,
    /// Points skipped as invalid.
    pub skipped: u64,
    /// Cells still over the limit.
    pub oversized_cells: usize,
}

/// Run the four passes: ingest `inputs` into a store staged next to `out`, not yet committed.
pub fn stage(inputs: &[InputSpec], out: &Path, params: &StoreParams, ctx: &Ctx) -> Result<Staged> {
    if out.exists() {
        return Err(Error::input(
            out,
            format!(
                "output store already exists; remove it or choose another {}",
                Setting::Output
            ),
        ));
    }
    let prep = Prepared::open(inputs, params, ctx)?;
    let tmp = StageDir::create(out)?;
    let cells_dir = tmp.path().join(CELLS_DIR);
    let chunks = prep.chunks()?;

    // Pass 2: count (and exact bounds), cut into the hierarchy.
    let grid_permit = ctx.budget.acquire(prep.grid_bytes(), "the counting grid")?;
    let counted = count::count_pass(
        &prep.inputs,
        &chunks,
        prep.sizes.chunk_bytes,
        &prep.provisional,
        prep.levels,
        ctx,
    )?;
    prep.inputs.settle_colour_scale();
    no_valid_points(&prep.inputs, &counted.bounds)?;
    let count::Counted {
        cube,
        counts,
        bounds,
        skipped,
    } = counted;
    let hier = prep.hierarchy(&counts);
    drop(counts);
    drop(grid_permit);

    // Pass 3: scatter.
    let stage = ctx
        .progress
        .stage("scatter", Some(prep.inputs.total), "points");
    let into = ScatterInto::Cells(&cells_dir);
    let cells_out = prep
        .scatter(into, &chunks, &cube, &hier, &stage, ctx)?
        .cells;
    stage.finish(None);

    // Pass 4: split cells still over the limit.
    let oversized: Vec<bool> = hier.leaves.iter().map(|l| l.oversized).collect();
    let (cells_out, oversized_cells) = prep
        .splitter(&cube, &cells_dir)
        .run(cells_out, &oversized, ctx)?;

    let cells = cell_entries(&cells_out)?;
    let found = Found {
        cube,
        bounds,
        skipped,
        oversized_cells,
    };
    Ok(prep.staged(tmp, out, cells, found))
}

/// The error when the count found no valid point.
pub fn no_valid_points(inputs: &Inputs, bounds: &Aabb) -> Result<()> {
    if bounds.is_empty() {
        return Err(Error::input(
            &inputs.specs[0].path,
            "no valid points: every point has a non-finite coordinate or an invalid normal",
        ));
    }
    Ok(())
}

/// The manifest entries of the non-empty cells, in key order; the files of empty cells are
/// removed.
fn cell_entries(cells_out: &[CellOut]) -> Result<Vec<CellEntry>> {
    let mut cells: Vec<CellEntry> = cells_out
        .iter()
        .filter(|c| c.count > 0)
        .map(cell_entry)
        .collect();
    for c in cells_out.iter().filter(|c| c.count == 0) {
        std::fs::remove_file(&c.file).with_path(&c.file)?;
    }
    cells.sort_by_key(|c| c.key);
    Ok(cells)
}

/// The manifest entry of a written cell.
pub fn cell_entry(c: &CellOut) -> CellEntry {
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
}

/// A store whose cells are written in its temporary directory, not yet committed: nothing
/// appears under its name until [`Staged::commit`], and dropping it removes the directory.
pub struct Staged {
    tmp: StageDir,
    raw: Option<PathBuf>,
    out: PathBuf,
    inputs: Inputs,
    cells: Vec<CellEntry>,
    found: Found,
    levels: u32,
    input_bytes: u64,
    chunk_points: u64,
    max_cell_points: u64,
    zstd_level: i32,
    skip_invalid: bool,
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
        &self.found.cube
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
        let path = match &self.raw {
            Some(d) => d.join(&e.file),
            None => self.cell_path(i),
        };
        cell_file::read_cell_file(&path, self.layout(), e.count, e.crc32)
    }

    /// Read the cells as written by the passes from the directory `dir` instead of the
    /// store's `cells/` (a split ingest, whose tasks write the cells with their normals into
    /// the store while others may still read the cells without).
    pub fn read_cells_from(&mut self, dir: PathBuf) {
        self.raw = Some(dir);
    }

    /// Write the points of `b` with their normals, in the layout with normals, to `path` (a
    /// cell's file, or a split ingest's checkpoint of it); returns the file's size and CRC-32
    /// for [`Staged::set_cell_file`].
    pub fn write_with_normals(&self, path: &Path, b: &PointBatch) -> Result<(u64, u32)> {
        let layout = self.layout().with_normals();
        cell_file::write_cell_file(path, layout, b, self.zstd_level)
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
        let (skipped, total) = (self.found.skipped, self.inputs.total);
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
            bounds: self.found.bounds,
            cube: self.found.cube,
            max_cell_points: self.max_cell_points,
            count_levels: self.levels,
            inputs: self.inputs.entries(),
            cells: self.cells,
            estimated_normals: normals.as_ref().map(|n| n.0.clone()),
            zstd_level: Some(self.zstd_level),
            skip_invalid: Some(self.skip_invalid),
        };
        manifest.save(self.tmp.path())?;
        self.tmp.commit(&self.out)?;
        Ok(IngestStats {
            points,
            skipped_invalid: skipped,
            cells,
            oversized_cells: self.found.oversized_cells,
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
