//! Ingest and the on-disk octree store (DESIGN.md step 1).
//!
//! `ingest` reads the memory-mapped inputs in two passes, each a parallel map over chunks:
//!
//! 0. **provisional bounds**: the headers' where every input has them (LAS), else the bounds
//!    of a fixed sample of about 1/64 of the chunks; the root cube is that box enlarged 10%;
//! 1. **count**: each point's cell on a counting grid of `8^L` cells over the root cube, `L`
//!    sized from the point count ([`octree::count_levels`]) and the budget, while the exact
//!    bounds are measured and every coordinate checked finite. Only if the exact bounds leave
//!    the cube with less than half its margin is the count repeated on the exact cube. The
//!    grid is cut into a hierarchy of cells of at most `--max-cell-points` points
//!    ([`octree::Hierarchy`]);
//! 2. **scatter**: points grouped by cell and appended to per-cell buffers that are flushed
//!    as zstd frames of fixed-width records ([`cell_file`]), written by a writer thread;
//! 3. **split**: a grid cell still over the limit is counted again on a finer grid of its own
//!    and scattered into its sub-cells.
//!
//! The store is built in a temporary directory next to the destination; `manifest.json` is
//! written last and the directory renamed, so a store is either complete or absent.
//!
//! Memory: the counting grid, the chunks in flight and the cell buffers are each admitted by
//! the budget before they are allocated; chunk size and buffer capacity are derived from it.

pub mod cell_file;
pub mod manifest;
pub mod octree;
pub mod scatter;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::io::{ChunkSpec, InputSpec, PointReader};
use crate::normals::{NormalParams, NormalsMode};
use crate::types::{Aabb, Attributes, CellKey, Cube, MAX_LEVEL, PointBatch, morton3};
use cell_file::{CellReader, RecordLayout};
use manifest::{
    CellEntry, EstimatedNormals, InputEntry, MANIFEST, Manifest, STORE_FORMAT, STORE_VERSION,
};
use octree::Hierarchy;
use scatter::{Grouped, Scatter};

/// Options of `ingest`.
#[derive(Debug, Clone)]
pub struct IngestParams {
    /// Cells are split until they hold at most this many points.
    pub max_cell_points: u64,
    /// Drop points with non-finite coordinates instead of failing.
    pub skip_invalid: bool,
    /// zstd level of cell files. The default, -1 (zstd's `--fast=1`), compresses twice as fast
    /// as level 1 for 6% larger cells (measured on 360 MB of sphere records: 0.74 s against
    /// 1.55 s, 276 MB against 261 MB).
    pub zstd_level: i32,
    /// Points per chunk; `None` sizes chunks from the budget.
    pub chunk_points: Option<u64>,
    /// Where normals come from.
    pub normals: NormalsMode,
    /// How they are estimated, when they are.
    pub normal_params: NormalParams,
}

impl Default for IngestParams {
    fn default() -> Self {
        IngestParams {
            max_cell_points: 1_000_000,
            skip_invalid: false,
            zstd_level: -1,
            chunk_points: None,
            normals: NormalsMode::Auto,
            normal_params: NormalParams::default(),
        }
    }
}

/// What `ingest` did.
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

/// The root cube is the bounding box's largest edge enlarged by 10% (PoissonRecon's default
/// `--scale 1.1`), centred on the box: reconstruction solves on this cube, and the margin keeps
/// the surface off its faces.
pub const CUBE_MARGIN: f64 = 0.1;

/// Bytes in flight per point of a chunk: mapped input (up to 64 bytes a record), the decoded
/// batch (52), its records (up to 52), and sort keys and leaf ids (12).
const CHUNK_BYTES_PER_POINT: u64 = 64 + 52 + 52 + 12;

/// Removes a temporary directory unless disarmed.
struct TempDir(Option<PathBuf>);

impl Drop for TempDir {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_dir_all(p);
        }
    }
}

/// Open every input and check that the set is usable.
pub fn open_inputs(inputs: &[InputSpec]) -> Result<Vec<Box<dyn PointReader>>> {
    if inputs.is_empty() {
        return Err(Error::Usage("no input files given".into()));
    }
    inputs.iter().map(|i| crate::io::open(&i.path)).collect()
}

/// Ingest `inputs` into a new store at `out`.
pub fn ingest(
    inputs: &[InputSpec],
    out: &Path,
    params: &IngestParams,
    ctx: &Ctx,
) -> Result<IngestStats> {
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
    let readers = open_inputs(inputs)?;
    let total: u64 = readers.iter().map(|r| r.len()).sum();
    if total == 0 {
        return Err(Error::input(
            &inputs[0].path,
            "no points: the input files hold 0 points",
        ));
    }
    let attrs = readers
        .iter()
        .map(|r| r.attributes())
        .reduce(Attributes::intersect)
        .unwrap_or_default();
    for r in &readers {
        if r.attributes() != attrs {
            log::warn!(
                "{}: carries {:?}, but not every input does; the store keeps {:?}",
                r.path().display(),
                r.attributes().names(),
                attrs.names()
            );
        }
    }
    // Positions are kept as f32 when that is exact: every input stores float32 coordinates
    // and none is transformed. Records shrink from 36 to 24 bytes for an oriented cloud.
    let pos_f32 = readers
        .iter()
        .zip(inputs)
        .all(|(r, i)| r.positions_f32() && i.transform.is_identity());
    // Normals: from the inputs, or estimated once the cells are written (the records then
    // carry each point's scan while a viewpoint is known, to orient them toward it).
    let estimate = match params.normals {
        NormalsMode::Estimate => true,
        NormalsMode::Auto => !attrs.normal,
        NormalsMode::Use => {
            if let Some(r) = readers.iter().find(|r| !r.attributes().normal) {
                return Err(Error::input(
                    r.path(),
                    "has no normals (nx ny nz) and --normals use was given; use --normals auto or estimate to estimate them",
                ));
            }
            false
        }
    };
    let mut attrs = attrs;
    // Airborne LiDAR is seen from above: LAS inputs without a viewpoint face up.
    let mut inputs_vp: Vec<InputSpec> = inputs.to_vec();
    if estimate {
        for (i, r) in inputs_vp.iter_mut().zip(&readers) {
            if i.viewpoint.is_none() && r.format() == crate::io::Format::Las {
                log::info!(
                    "{}: LAS without --viewpoint: normals face up (+z), as seen from the air",
                    i.path.display()
                );
                i.viewpoint = Some(crate::types::Viewpoint::Direction([0.0, 0.0, 1.0]));
            }
        }
    }
    let inputs = &inputs_vp[..];
    if estimate {
        attrs.normal = false;
        attrs.source = inputs.iter().any(|i| i.viewpoint.is_some());
        if attrs.source && inputs.len() > u16::MAX as usize + 1 {
            return Err(Error::Usage(format!(
                "{} inputs with viewpoints: at most {} are supported",
                inputs.len(),
                u16::MAX as usize + 1
            )));
        }
    }
    let layout = RecordLayout::new(attrs, pos_f32);

    // Temporary directory next to the destination.
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = out
        .file_name()
        .ok_or_else(|| Error::input(out, "output path has no file name"))?
        .to_string_lossy()
        .to_string();
    let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_path(&tmp)?;
    }
    std::fs::create_dir(&tmp).map_err(|e| {
        Error::input(
            out,
            format!(
                "cannot create the store: directory {} is not writable ({e})",
                parent.display()
            ),
        )
    })?;
    let guard = TempDir(Some(tmp.clone()));
    let cells_dir = tmp.join("cells");
    std::fs::create_dir(&cells_dir).with_path(&cells_dir)?;

    // Sizes from the budget.
    let budget = &ctx.budget;
    let threads = ctx.threads() as u64;
    let wave = 2 * threads;
    let chunk_points = params.chunk_points.unwrap_or_else(|| {
        (budget.total() / 2 / (wave * CHUNK_BYTES_PER_POINT)).clamp(4096, 1 << 18)
    });
    let chunk_bytes = chunk_points * CHUNK_BYTES_PER_POINT;
    let mut chunks: Vec<(usize, ChunkSpec)> = Vec::new();
    for (i, r) in readers.iter().enumerate() {
        chunks.extend(r.chunks(chunk_points)?.into_iter().map(|c| (i, c)));
    }
    let input_bytes: u64 = inputs
        .iter()
        .map(|i| std::fs::metadata(&i.path).map(|m| m.len()).unwrap_or(0))
        .sum();

    // LAS files often hold 8-bit colour in their 16-bit fields: the count pass records each
    // input's largest channel, and an input whose colours all fit 0..=255 is scaled by 257
    // when stored (the store's colours are always 16-bit).
    let max_color: Vec<std::sync::atomic::AtomicU16> = readers
        .iter()
        .map(|_| std::sync::atomic::AtomicU16::new(0))
        .collect();
    let scale8: Vec<std::sync::atomic::AtomicBool> = readers
        .iter()
        .map(|_| std::sync::atomic::AtomicBool::new(false))
        .collect();
    let load = |batch: &mut PointBatch, ri: usize, spec: &ChunkSpec| -> Result<u64> {
        batch.clear();
        let st = readers[ri].read_chunk(spec, params.skip_invalid, batch)?;
        if attrs.color && readers[ri].format() == crate::io::Format::Las {
            let m = batch
                .color
                .iter()
                .map(|c| c[0].max(c[1]).max(c[2]))
                .max()
                .unwrap_or(0);
            max_color[ri].fetch_max(m, Ordering::Relaxed);
            if scale8[ri].load(Ordering::Relaxed) {
                for c in &mut batch.color {
                    for v in &mut c[..3] {
                        *v = v.saturating_mul(257);
                    }
                }
            }
        }
        let t = &inputs[ri].transform;
        if !t.is_identity() {
            batch.transform(t);
        }
        if layout.attrs.source {
            batch.source.clear();
            batch.source.resize(batch.len(), ri as u16);
        }
        Ok(st.skipped_invalid)
    };

    // Provisional bounds: the headers' (LAS), else a deterministic sample of chunks. The
    // count pass then measures the exact bounds; only when they leave the provisional cube
    // (keeping less than half its margin) is the count repeated on the exact cube, so that
    // ingest reads typical inputs twice, not three times.
    let header_bounds: Option<Aabb> = readers
        .iter()
        .zip(inputs)
        .map(|(r, i)| r.header_bounds().map(|b| transform_box(&b, i)))
        .try_fold(Aabb::EMPTY, |acc, b| b.map(|b| acc.union(&b)));
    let provisional = match header_bounds {
        Some(b) => b,
        None => {
            let want = (chunks.len() / 64).max(8);
            let stride = (chunks.len() / want).max(1);
            let sample: Vec<&(usize, ChunkSpec)> = chunks
                .iter()
                .enumerate()
                .filter(|(i, _)| i % stride == 0 || *i + 1 == chunks.len())
                .map(|(_, c)| c)
                .collect();
            let res: Vec<Result<Aabb>> = ctx.pool.install(|| {
                sample
                    .par_iter()
                    .map_init(PointBatch::default, |batch, (ri, spec)| {
                        let _permit = budget.acquire(chunk_bytes, "a chunk of points")?;
                        load(batch, *ri, spec)?;
                        Ok(cell_file::batch_bounds(batch))
                    })
                    .collect()
            });
            let mut b = Aabb::EMPTY;
            for r in res {
                b = b.union(&r?);
            }
            b
        }
    };

    // Pass 1: count (and exact bounds).
    let max_levels_by_mem = {
        let mut l = 7u32;
        while l > 1 && (8u64 << (3 * l)) * 9 / 8 > budget.total() / 4 {
            l -= 1;
        }
        l
    };
    let levels = octree::count_levels(total, params.max_cell_points, max_levels_by_mem);
    let grid_cells = 1usize << (3 * levels);
    let grid_permit = budget.acquire(grid_cells as u64 * 8 * 9 / 8 * 2, "the counting grid")?;
    let count = |cube: &Cube| -> Result<(Vec<u64>, Aabb, u64)> {
        let counts: Vec<AtomicU64> = (0..grid_cells).map(|_| AtomicU64::new(0)).collect();
        let root_map = GridMap::new(cube, CellKey::ROOT, levels);
        let stage = ctx.progress.stage("count", Some(total), "points");
        let res: Vec<Result<(Aabb, u64)>> = ctx.pool.install(|| {
            chunks
                .par_iter()
                .map_init(PointBatch::default, |batch, (ri, spec)| {
                    let _permit = budget.acquire(chunk_bytes, "a chunk of points")?;
                    let skipped = load(batch, *ri, spec)?;
                    for p in &batch.pos {
                        counts[root_map.index(*p) as usize].fetch_add(1, Ordering::Relaxed);
                    }
                    stage.inc(spec.count);
                    Ok((cell_file::batch_bounds(batch), skipped))
                })
                .collect()
        });
        let mut bounds = Aabb::EMPTY;
        let mut s = 0;
        for r in res {
            let (bb, sk) = r?;
            bounds = bounds.union(&bb);
            s += sk;
        }
        stage.finish(None);
        Ok((
            counts.into_iter().map(|c| c.into_inner()).collect(),
            bounds,
            s,
        ))
    };
    let mut cube = Cube::around(&provisional, CUBE_MARGIN);
    let (mut counts, mut bounds, mut skipped) = if provisional.is_empty() {
        (Vec::new(), Aabb::EMPTY, 0)
    } else {
        count(&cube)?
    };
    if !bounds.is_empty() && !within(&bounds, &Cube::around(&provisional, CUBE_MARGIN / 2.0)) {
        log::info!("the points reach beyond the sampled bounds; counting again on the exact cube");
        cube = Cube::around(&bounds, CUBE_MARGIN);
        (counts, bounds, skipped) = count(&cube)?;
    } else if provisional.is_empty() {
        // Every sampled point was invalid: count on the exact bounds found by a full pass.
        let (_, b, _) = count(&Cube::around(
            &Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            0.0,
        ))?;
        if !b.is_empty() {
            cube = Cube::around(&b, CUBE_MARGIN);
            (counts, bounds, skipped) = count(&cube)?;
        }
    }
    for (ri, r) in readers.iter().enumerate() {
        let m = max_color[ri].load(Ordering::Relaxed);
        if attrs.color && r.format() == crate::io::Format::Las && m <= 255 {
            log::info!(
                "{}: colours are 8-bit (at most {m}) in 16-bit fields; scaled by 257",
                r.path().display()
            );
            scale8[ri].store(true, Ordering::Relaxed);
        }
    }
    if bounds.is_empty() {
        return Err(Error::input(
            &inputs[0].path,
            "no valid points: every point has a non-finite coordinate",
        ));
    }
    let hier = Hierarchy::build(CellKey::ROOT, levels, &counts, params.max_cell_points);
    drop(counts);
    drop(grid_permit);

    // Pass 3: scatter.
    let cap = (budget.total() / 8) as usize;
    let scatter_permit = budget.acquire(2 * cap as u64, "the cell buffers")?;
    let keys: Vec<CellKey> = hier.leaves.iter().map(|l| l.key).collect();
    let mut sc = Scatter::new(&cells_dir, &keys, layout, cap, params.zstd_level)?;
    let stage = ctx.progress.stage("scatter", Some(total), "points");
    for wave_chunks in chunks.chunks(wave as usize) {
        // The whole wave is admitted at once: its outputs live until they are appended.
        let _permit = budget.acquire(
            wave_chunks.len() as u64 * chunk_bytes,
            "a wave of chunks of points",
        )?;
        let outs: Vec<Result<Grouped>> = ctx.pool.install(|| {
            wave_chunks
                .par_iter()
                .map(|(ri, spec)| {
                    let mut batch = PointBatch::default();
                    load(&mut batch, *ri, spec)?;
                    let g = group_batch(&batch, &cube, &hier, &layout)?;
                    stage.inc(spec.count);
                    Ok(g)
                })
                .collect()
        });
        for o in outs {
            sc.push(&ctx.pool, &o?)?;
        }
    }
    let mut cells_out = sc.finish(&ctx.pool)?;
    stage.finish(None);

    // Pass 4: split cells still over the limit.
    let mut oversized: Vec<usize> = hier
        .leaves
        .iter()
        .enumerate()
        .filter(|(_, l)| l.oversized)
        .map(|(i, _)| i)
        .collect();
    let mut stuck = Vec::new();
    if !oversized.is_empty() {
        let stage = ctx
            .progress
            .stage("split", Some(oversized.len() as u64), "cells");
        let mut done: Vec<bool> = vec![false; cells_out.len()];
        while let Some(i) = oversized.pop() {
            let key = cells_out[i].key;
            let n = cells_out[i].count;
            let room = MAX_LEVEL.saturating_sub(key.level());
            let r = octree::count_levels(n, params.max_cell_points, room.min(max_levels_by_mem));
            if room == 0 {
                log::warn!(
                    "cell {} holds {} points within one finest cell; kept over the limit",
                    key.file_name(),
                    n
                );
                stuck.push(i);
                continue;
            }
            let new = split_cell(
                &cells_out[i],
                r,
                &cube,
                layout,
                params,
                chunk_points,
                &cells_dir,
                ctx,
            )?;
            std::fs::remove_file(&cells_out[i].file).with_path(&cells_out[i].file)?;
            done[i] = true;
            for (c, over) in new {
                cells_out.push(c);
                done.push(false);
                if over {
                    oversized.push(cells_out.len() - 1);
                }
            }
            stage.inc(1);
        }
        stage.finish(None);
        let mut k = 0;
        cells_out.retain(|_| {
            k += 1;
            !done[k - 1]
        });
    }
    drop(scatter_permit);

    // Manifest, written last; then the rename makes the store appear.
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
    let (attrs, layout, normals) = if estimate {
        let out_attrs = Attributes {
            normal: true,
            ..attrs
        };
        let out_layout = RecordLayout::new(out_attrs, pos_f32);
        let viewpoints: Vec<_> = inputs.iter().map(|i| i.viewpoint).collect();
        let r = crate::normals::estimate_cells(
            &tmp,
            &mut cells,
            &cube,
            layout,
            out_layout,
            &viewpoints,
            &params.normal_params,
            params.zstd_level,
            ctx,
        )?;
        (out_attrs, out_layout, Some(r))
    } else {
        (attrs, layout, None)
    };
    let points: u64 = cells.iter().map(|c| c.count).sum();
    if points + skipped != total {
        return Err(Error::Internal(format!(
            "ingest stored {points} points and skipped {skipped}, but the inputs hold {total}"
        )));
    }
    // Cell files are not fsynced one by one (that would double the run time on fast inputs);
    // each carries a CRC-32 in the manifest, so a store damaged by a power loss after the run
    // fails its check when read instead of giving wrong points.
    let store_bytes = cells.iter().map(|c| c.bytes).sum();
    let manifest = Manifest {
        format: STORE_FORMAT.into(),
        version: STORE_VERSION,
        point_count: points,
        skipped_invalid: skipped,
        attributes: attrs,
        record_bytes: layout.stride,
        record_fields: record_fields(attrs, pos_f32),
        position_f32: pos_f32,
        compression: "zstd".into(),
        bounds,
        cube,
        max_cell_points: params.max_cell_points,
        count_levels: levels,
        inputs: inputs
            .iter()
            .zip(&readers)
            .enumerate()
            .map(|(k, (i, r))| InputEntry {
                path: i.path.display().to_string(),
                format: r.format(),
                points: r.len(),
                transform: i.transform,
                viewpoint: i.viewpoint,
                color_scale: if scale8[k].load(Ordering::Relaxed) {
                    257
                } else {
                    1
                },
            })
            .collect(),
        cells,
        estimated_normals: normals.as_ref().map(|n| n.0.clone()),
    };
    manifest.save(&tmp)?;
    if out.exists() {
        return Err(Error::input(
            out,
            "output store appeared while ingesting; not replaced",
        ));
    }
    std::fs::rename(&tmp, out).with_path(out)?;
    std::mem::forget(guard);
    Ok(IngestStats {
        points,
        skipped_invalid: skipped,
        cells: manifest.cells.len(),
        oversized_cells: stuck.len(),
        input_bytes,
        store_bytes,
        secs: t0.elapsed().as_secs_f64(),
        chunk_points,
        count_levels: levels,
        normals,
    })
}

fn record_fields(a: Attributes, pos_f32: bool) -> Vec<String> {
    let t = if pos_f32 { "f32" } else { "f64" };
    let mut v: Vec<String> = ["x", "y", "z"].map(|c| format!("{c}:{t}")).to_vec();
    if a.normal {
        v.extend(["nx:f32", "ny:f32", "nz:f32"].map(String::from));
    }
    if a.color {
        v.extend(["red:u16", "green:u16", "blue:u16"].map(String::from));
        if a.alpha {
            v.push("alpha:u16".into());
        }
    }
    if a.intensity {
        v.push("intensity:f32".into());
    }
    if a.confidence {
        v.push("confidence:f32".into());
    }
    if a.source {
        v.push("scan:u16".into());
    }
    v
}

/// True when `b` lies inside cube `c`.
fn within(b: &Aabb, c: &Cube) -> bool {
    (0..3).all(|a| b.min[a] >= c.origin[a] && b.max[a] <= c.origin[a] + c.size)
}

/// The box holding `b` after the input's transform.
fn transform_box(b: &Aabb, i: &InputSpec) -> Aabb {
    let mut out = Aabb::EMPTY;
    for k in 0..8 {
        let c = [
            if k & 1 == 0 { b.min[0] } else { b.max[0] },
            if k & 2 == 0 { b.min[1] } else { b.max[1] },
            if k & 4 == 0 { b.min[2] } else { b.max[2] },
        ];
        out.add(i.transform.apply(c));
    }
    out
}

/// Maps points to Morton indices on the grid `levels` below a base cell.
#[derive(Debug, Clone, Copy)]
struct GridMap {
    origin: [f64; 3],
    inv: f64,
    base: [u64; 3],
    top: u64,
}

impl GridMap {
    fn new(cube: &Cube, base: CellKey, levels: u32) -> GridMap {
        let (bl, bc) = base.decode();
        let level = bl + levels;
        GridMap {
            origin: cube.origin,
            inv: (1u64 << level) as f64 / cube.size,
            base: bc.map(|c| (c as u64) << levels),
            top: (1u64 << levels) - 1,
        }
    }

    /// The grid cell of `p`, clamped into the grid. Agrees with [`Cube::cell_coords`]: the
    /// scale is a power of two times the cube's, so both floor the same products.
    #[inline(always)]
    fn index(&self, p: [f64; 3]) -> u64 {
        let mut c = [0u32; 3];
        for k in 0..3 {
            let v = (p[k] - self.origin[k]) * self.inv;
            // Truncation is floor for v > 0; v <= 0 (and NaN) clamp to 0.
            let g = if v > 0.0 { v as u64 } else { 0 };
            c[k] = g.saturating_sub(self.base[k]).min(self.top) as u32;
        }
        morton3(c)
    }
}

fn group_batch(
    b: &PointBatch,
    cube: &Cube,
    h: &Hierarchy,
    layout: &RecordLayout,
) -> Result<Grouped> {
    let map = GridMap::new(cube, h.base, h.levels);
    let mut leaf = Vec::with_capacity(b.len());
    for p in &b.pos {
        let m = map.index(*p);
        leaf.push(h.leaf_of(m).ok_or_else(|| {
            Error::Internal(format!(
                "point {p:?} fell in no cell (grid cell {m}); input changed while reading?"
            ))
        })?);
    }
    let mut g = Grouped::default();
    scatter::group(b, &leaf, h.leaves.len(), layout, &mut g);
    Ok(g)
}

/// Count a cell's points on a grid `r` levels finer and scatter them into its sub-cells.
/// Returns the new cells, each with whether it is still over the limit.
#[allow(clippy::too_many_arguments)]
fn split_cell(
    cell: &scatter::CellOut,
    r: u32,
    cube: &Cube,
    layout: RecordLayout,
    params: &IngestParams,
    chunk_points: u64,
    dir: &Path,
    ctx: &Ctx,
) -> Result<Vec<(scatter::CellOut, bool)>> {
    let grid = 1usize << (3 * r);
    let _grid_permit = ctx
        .budget
        .acquire(grid as u64 * 8 * 9 / 8 * 2, "the counting grid")?;
    let mut counts = vec![0u64; grid];
    let n = chunk_points as usize;
    let mut batch = PointBatch::default();
    let mut buf = Vec::new();
    {
        let mut rd = CellReader::open(&cell.file, layout)?;
        loop {
            batch.clear();
            if rd.read(n, &mut batch, &mut buf)? == 0 {
                break;
            }
            let map = GridMap::new(cube, cell.key, r);
            for p in &batch.pos {
                counts[map.index(*p) as usize] += 1;
            }
        }
    }
    let h = Hierarchy::build(cell.key, r, &counts, params.max_cell_points);
    drop(counts);
    let cap = (ctx.budget.total() / 8) as usize;
    let keys: Vec<CellKey> = h.leaves.iter().map(|l| l.key).collect();
    let mut sc = Scatter::new(dir, &keys, layout, cap, params.zstd_level)?;
    let mut rd = CellReader::open(&cell.file, layout)?;
    let wave = 2 * ctx.threads();
    loop {
        let mut batches = Vec::with_capacity(wave);
        for _ in 0..wave {
            let mut b = PointBatch::default();
            if rd.read(n, &mut b, &mut buf)? == 0 {
                break;
            }
            batches.push(b);
        }
        if batches.is_empty() {
            break;
        }
        let _permit = ctx.budget.acquire(
            batches.len() as u64 * chunk_points * CHUNK_BYTES_PER_POINT,
            "a chunk of points",
        )?;
        let outs: Vec<Result<Grouped>> = ctx.pool.install(|| {
            batches
                .par_iter()
                .map(|b| group_batch(b, cube, &h, &layout))
                .collect()
        });
        for o in outs {
            sc.push(&ctx.pool, &o?)?;
        }
    }
    let crc = rd.finish_crc();
    if crc != cell.crc32() {
        return Err(Error::Internal(format!(
            "{}: checksum changed while splitting",
            cell.file.display()
        )));
    }
    let cells = sc.finish(&ctx.pool)?;
    Ok(cells
        .into_iter()
        .zip(&h.leaves)
        .map(|(c, l)| (c, l.oversized))
        .collect())
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
    /// Open a store and check its manifest.
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
        Ok(Store {
            dir: dir.to_path_buf(),
            manifest,
            layout,
        })
    }

    /// The file of cell `i`.
    pub fn cell_path(&self, i: usize) -> PathBuf {
        self.dir.join("cells").join(&self.manifest.cells[i].file)
    }

    /// Read every point of cell `i`, checking its count and checksum.
    pub fn read_cell(&self, i: usize) -> Result<PointBatch> {
        let e = &self.manifest.cells[i];
        cell_file::read_cell_file(&self.cell_path(i), self.layout, e.count, e.crc32)
    }
}

/// What `info` reports about a point file.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FileInfo {
    /// Path.
    pub path: String,
    /// Format.
    pub format: crate::io::Format,
    /// Points (records).
    pub points: u64,
    /// Attributes carried.
    pub attributes: Vec<&'static str>,
    /// Bounds of the points (NaN points excluded).
    pub bounds: Aabb,
    /// Points with a non-finite coordinate.
    pub invalid_points: u64,
}

/// Read a file once to describe it.
pub fn file_info(path: &Path, ctx: &Ctx) -> Result<FileInfo> {
    let r = crate::io::open(path)?;
    let chunks = r.chunks(1 << 18)?;
    let stage = ctx.progress.stage("scan", Some(r.len()), "points");
    let res: Vec<Result<(Aabb, u64)>> = ctx.pool.install(|| {
        chunks
            .par_iter()
            .map_init(PointBatch::default, |b, spec| {
                let _p = ctx
                    .budget
                    .acquire(spec.count * CHUNK_BYTES_PER_POINT, "a chunk of points")?;
                b.clear();
                let st = r.read_chunk(spec, true, b)?;
                stage.inc(spec.count);
                Ok((cell_file::batch_bounds(b), st.skipped_invalid))
            })
            .collect()
    });
    stage.finish(None);
    let mut bounds = Aabb::EMPTY;
    let mut invalid = 0;
    for x in res {
        let (b, s) = x?;
        bounds = bounds.union(&b);
        invalid += s;
    }
    Ok(FileInfo {
        path: path.display().to_string(),
        format: r.format(),
        points: r.len(),
        attributes: r.attributes().names(),
        bounds,
        invalid_points: invalid,
    })
}
