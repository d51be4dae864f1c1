//! The tiles phase of `reconstruct` (ARCHITECTURE.md steps 4 and 5): tiles in Morton order, in
//! waves, each blended from the coarse solution and the leaf details, extracted on the CPU or
//! the GPU, fitted to the input points and coloured, trimmed, checkpointed, then welded and
//! streamed to the writer in Morton order.

use std::collections::{BTreeSet, HashMap, HashSet};
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use rayon::prelude::*;

use super::details::DetailCache;
use super::points::PointSource;
use super::reconstruct::ReconParams;
use super::shard::Claims;
use crate::error::{Error, Result};
use crate::exec::Ctx;
use crate::exec::budget::{Permit, Share};
use crate::exec::progress::Stage;
use crate::extract::cpu::McWorkspace;
use crate::extract::field::BlendEval;
use crate::extract::gpu::GpuExtractor;
use crate::extract::weld::Welder;
use crate::geom::vec::{add, cross, norm, sub};
use crate::io::mesh_write::{MeshTarget, MeshWriter, VertexFormat};
use crate::io::preview::Preview;
use crate::recon::checkpoint::{read_tile, tile_path, write_tile};
use crate::recon::{CoarseField, Plan, leaves_near, pou, tile_blend};
use crate::surface::{NearPoints, Support, settle, trim_by_density, trim_mesh};
use crate::types::{Aabb, CellKey, Detail, EdgeKey, GridGeom, TileMesh, demorton3, morton3};

mod sink;
pub(super) use sink::{MeshSink, VertexAttrs};

mod gpu;
use gpu::*;

/// Bytes a tile node holds while its field is built: the blend's i64 accumulator (8) and the
/// f32 field (4).
const TILE_NODE_BYTES: u64 = 12;

/// The margin around a tile whose input points its fit and colours read, in leaf edges.
const NEAR_MARGIN_LEAVES: f64 = 0.25;

/// Bytes a tile's input points hold: position f64×3, colour u16×3 and intensity f32.
const NEAR_POINT_BYTES: u64 = 24 + 6 + 4;

/// Tiles a wave may send to the GPU thread ahead of the pool finishing them.
const GPU_QUEUE: usize = 2;

/// What the tiles phase reads: the plan, the options, the solution and its checkpoints.
pub struct TileJob<'a> {
    /// The grids.
    pub plan: &'a Plan,
    /// The options.
    pub params: &'a ReconParams,
    /// The coarse solution.
    pub coarse: &'a CoarseField,
    /// Which voxels hold input points (for `--trim`).
    pub support: &'a Support,
    /// The refined leaves (those with a detail).
    pub refined: &'a BTreeSet<CellKey>,
    /// Iso-value.
    pub iso: f64,
    /// Fixed-point unit of the blend.
    pub unit: f32,
    /// Leaf checkpoints.
    pub leaves_dir: &'a Path,
    /// The input points' bounds (what a preview frames).
    pub bounds: Aabb,
    /// Tile checkpoints.
    pub tiles_dir: &'a Path,
    /// The shards' claims (a split run).
    pub claims_dir: &'a Path,
    /// Whether the output carries colours.
    pub with_color: bool,
    /// Whether the output carries intensities.
    pub with_intensity: bool,
    /// What errors about the input name (a reconstruction that finds no surface).
    pub input: &'a Path,
}

/// What the tiles phase did.
#[derive(Debug, Clone)]
pub struct TileStats {
    /// Output vertices.
    pub vertices: u64,
    /// Output triangles.
    pub faces: u64,
    /// Tiles extracted (or read back).
    pub tiles: usize,
    /// Most vertices held in the welder's frontier at once.
    pub peak_frontier: usize,
    /// The picture of the mesh, when asked for.
    pub preview: Option<Preview>,
}

/// A tile of a wave: its Morton index, lowest fine node and the refined leaves that reach it.
type WaveTile = (u64, [i64; 3], Vec<CellKey>);

/// A tile ready to extract: its Morton index, lowest fine node and leaf details (none: read
/// back from its checkpoint).
type LoadedTile = (u64, [i64; 3], Option<Vec<(CellKey, Arc<Detail>)>>);

/// The point source the fit and colours read, shared by the workers.
type SharedPoints<'a> = Option<Mutex<PointSource<'a>>>;

/// Extract, fit and checkpoint the tiles of `job` that its shard visits (`job.params.shard`:
/// every tile for the whole run), in waves; with `out`, weld and write them into the PLY mesh
/// `out` as they come (the whole run only). `points` is the input points when the fit or
/// colours need them. `tiles` is the non-empty tiles ([`nonempty_tiles`]).
pub fn run(
    job: &TileJob,
    tiles: &[u64],
    points: SharedPoints,
    out: Option<&MeshTarget>,
    ctx: &Ctx,
) -> Result<TileStats> {
    let plan = job.plan;
    let shard = job.params.run.shard;
    // The tiles work relative to the cube's lower corner (on its lattice, `types::Cube`), so
    // that translated inputs give the same numbers; the writer adds the corner back.
    let geom = GridGeom {
        origin: [0.0; 3],
        h: plan.spacing,
        n: plan.fine_cells,
    };
    let mut gpu = GpuExtractor::new(job.params.run.gpu)?;
    if let Some(g) = &gpu {
        log::info!("extracting tiles on the GPU: {}", g.adapter_name());
    }
    let mut sink = match out {
        Some(out) => Some(MeshSink::create(
            plan,
            &job.bounds,
            VertexAttrs {
                color: job.with_color,
                intensity: job.with_intensity,
                density: job.params.mesh.density,
            },
            out,
        )?),
        None => None,
    };
    // Tiles in Morton order reuse the leaves of their neighbours: the cache keeps twice the
    // leaves of the last wave (the next wave's tiles are its neighbours), within its share of
    // the budget.
    let detail_cap = ctx.budget.share(Share::DetailCache);
    let mut gpu_totals = GpuTotals::default();
    let mut details = DetailCache::new(job.leaves_dir, plan.detail_n(), detail_cap);
    let _detail_permit = ctx
        .budget
        .acquire_now(detail_cap, "the leaf detail cache")?;
    let stage = ctx
        .progress
        .stage("tiles", Some(tiles.len() as u64), "tiles");
    let sizes = WaveSizes {
        // 8 tiles a worker: tiles differ in work by far more than leaves (a corner of the
        // surface against a whole face), and a wave waits for its slowest tile (1M-point
        // bumpy sphere at depth 10 on 2 threads: 2 a worker 9.9–10.9 s, 8 a worker 7.9–8.8 s).
        tiles: 8 * ctx.threads(),
        tile_bytes: (plan.tile + 1).pow(3) * TILE_NODE_BYTES,
        detail_bytes: details.detail_bytes(),
    };
    let mut tiles_done = 0usize;
    // The cache grows into what two waves leave free: their tiles, each with the details of
    // every leaf its box and their overlaps meet (a tile spans whole leaves, plus one each
    // side).
    let reads = match points.as_ref() {
        Some(src) => {
            let near = (plan.tile / plan.leaf_voxels + 2).pow(3);
            let wave = sizes.tiles as u64 * (sizes.tile_bytes + near * sizes.detail_bytes);
            Some(lock(src)?.begin_pass(2 * wave, ctx))
        }
        None => None,
    };
    let order = shard.order(tiles.len());
    let claims = Claims::new(job.claims_dir);
    // A split run claims its tiles, then does every one still missing; one another shard
    // checkpointed is left for `merge` (`next_wave`).
    let mut visited = vec![false; tiles.len()];
    for &claiming in shard.passes() {
        let mut next = 0usize;
        loop {
            let free = ctx.budget.total().saturating_sub(ctx.budget.used());
            let pick = Pick {
                tiles,
                order: &order,
                visited: &mut visited,
                claims: claiming.then_some(&claims),
            };
            let (wave_tiles, wave_bytes) = next_wave(job, pick, &mut next, &sizes, free)?;
            if wave_tiles.is_empty() {
                break;
            }
            let _permit = admit_now(ctx, wave_bytes);
            details.fit(2 * wave_tiles.iter().map(|w| w.2.len()).sum::<usize>());
            let (loaded, near_pts) = load_wave(job, &wave_tiles, &points, &mut details, ctx)?;
            let near_bytes: u64 = near_pts.iter().flatten().map(near_points_bytes).sum();
            let _near_permit = admit_now(ctx, near_bytes);
            let meshes = match gpu.as_mut() {
                Some(g) => {
                    let shared = GpuWave {
                        job,
                        points: &points,
                        loaded: &loaded,
                        near_pts: &near_pts,
                        geom: &geom,
                    };
                    let meshes = extract_gpu(&shared, g, &mut gpu_totals, &ctx.pool)?;
                    stage.inc(wave_tiles.len() as u64);
                    meshes
                }
                None => extract_cpu(job, &points, &loaded, &near_pts, &geom, &ctx.pool, &stage),
            };
            for m in meshes {
                let (tt, mesh) = m?;
                if let Some(sink) = sink.as_mut() {
                    sink.add(tt, &mesh)?;
                }
                tiles_done += 1;
            }
        }
    }
    if shard.is_split() {
        stage.inc(visited.iter().filter(|v| !**v).count() as u64);
    }
    if let (Some(src), Some(reads)) = (points.as_ref(), reads) {
        lock(src)?.end_pass(reads, "tiles");
    }
    stage.finish(None);
    if gpu.is_some() {
        gpu_totals.log();
    }
    Ok(match sink {
        Some(sink) => TileStats {
            tiles: tiles_done,
            ..sink.finish(job.input, job.iso, job.params.solve.depth, ctx)?
        },
        None => TileStats {
            vertices: 0,
            faces: 0,
            tiles: tiles_done,
            peak_frontier: 0,
            preview: None,
        },
    })
}

/// The tiles that can hold surface, by Morton index: those a refined leaf reaches or over which
/// the coarse solution crosses the iso-value. Every one is extracted and checkpointed (its
/// mesh may still be empty); the others are skipped by every shard and by `merge`.
///
/// Errors: those of reading a level above in the recursive scheme ([`CoarseField::range`]).
pub fn nonempty_tiles(job: &TileJob, pool: &rayon::ThreadPool) -> Result<Vec<u64>> {
    let plan = job.plan;
    let ntiles_axis = plan.fine_cells / plan.tile;
    // In parallel: above a level of leaves a tile's range may blend a window of it.
    let keep: Vec<Result<Option<u64>>> = pool.install(|| {
        (0..ntiles_axis.pow(3))
            .into_par_iter()
            .map(|t| {
                let (lo, hi) = tile_box(plan, t);
                if !leaves_near(plan, job.refined, lo, hi).is_empty() {
                    return Ok(Some(t));
                }
                let (mn, mx) = job.coarse.range(lo, hi)?;
                Ok((!(mn as f64 > job.iso || (mx as f64) < job.iso)).then_some(t))
            })
            .collect()
    });
    keep.into_iter().filter_map(Result::transpose).collect()
}

/// The lowest and highest fine nodes of tile `t` (Morton index).
fn tile_box(plan: &Plan, t: u64) -> ([i64; 3], [i64; 3]) {
    let c = demorton3(t);
    let lo = c.map(|v| v as i64 * plan.tile as i64);
    (lo, lo.map(|v| v + plan.tile as i64))
}

/// How a wave of tiles is sized: at most `tiles` tiles, each holding `tile_bytes` while its
/// field is built and the leaf details it touches, `detail_bytes` each.
struct WaveSizes {
    tiles: usize,
    tile_bytes: u64,
    detail_bytes: u64,
}

/// Which tiles a wave takes: the non-empty `tiles` in the shard's `order`, those not
/// `visited` yet (marked as taken); in a split run those without a checkpoint, and in its
/// first pass only those this process can claim.
struct Pick<'p> {
    tiles: &'p [u64],
    order: &'p [usize],
    visited: &'p mut [bool],
    claims: Option<&'p Claims>,
}

/// The next wave of tiles from `pick.order[*next..]` (`*next` advanced past them), and the
/// bytes it holds: at most `sizes.tiles` tiles, as many as fit in `free` bytes with the
/// distinct leaf details they touch, and at least one (none when no tile is left). Which
/// tiles share a wave never changes the output: tiles are welded and written in Morton
/// order.
fn next_wave(
    job: &TileJob,
    pick: Pick,
    next: &mut usize,
    sizes: &WaveSizes,
    free: u64,
) -> Result<(Vec<WaveTile>, u64)> {
    let plan = job.plan;
    let split = job.params.run.shard.is_split();
    let mut wave_tiles = Vec::new();
    let mut leaves = HashSet::new();
    let mut bytes = 0u64;
    while *next < pick.order.len() && wave_tiles.len() < sizes.tiles {
        let i = pick.order[*next];
        let t = pick.tiles[i];
        if pick.visited[i] || (split && tile_path(job.tiles_dir, t).exists()) {
            *next += 1;
            continue;
        }
        let (lo, hi) = tile_box(plan, t);
        let near = leaves_near(plan, job.refined, lo, hi);
        let new_leaves = near.iter().filter(|k| !leaves.contains(*k)).count() as u64;
        let more = sizes.tile_bytes + new_leaves * sizes.detail_bytes;
        if !wave_tiles.is_empty() && bytes + more > free {
            // The tile opens the next wave.
            break;
        }
        *next += 1;
        if let Some(c) = pick.claims
            && !c.take(&format!("T{t}"))?
        {
            continue;
        }
        pick.visited[i] = true;
        bytes += more;
        leaves.extend(near.iter().copied());
        wave_tiles.push((t, lo, near));
    }
    Ok((wave_tiles, bytes))
}

/// Bytes held by the input points `p` of a tile.
fn near_points_bytes(p: &NearPoints) -> u64 {
    p.pos.len() as u64 * NEAR_POINT_BYTES
}

/// Charge `bytes` to the budget without waiting: every permit of `reconstruct` is held by the
/// thread that drives it, so waiting for one could wait forever. A wave of one tile (or leaf)
/// may need more than is free; it runs anyway, charged what is free (the rest is the margin
/// over `--mem`).
pub(super) fn admit_now(ctx: &Ctx, bytes: u64) -> Option<Permit> {
    let free = ctx.budget.total().saturating_sub(ctx.budget.used());
    ctx.budget.try_acquire(bytes.min(free))
}

/// The box whose points a tile's fit and colours read: the tile from fine node `lo` and a
/// margin (lower corner, upper corner, margin).
fn near_box(plan: &Plan, lo: [i64; 3]) -> ([f64; 3], [f64; 3], f64) {
    let a = plan.node_pos(lo);
    let b = plan.node_pos(lo.map(|v| v + plan.tile as i64));
    (
        a,
        b,
        plan.spacing * plan.leaf_voxels as f64 * NEAR_MARGIN_LEAVES,
    )
}

/// Lock the shared point source.
fn lock<'s, 'a>(
    src: &'s Mutex<PointSource<'a>>,
) -> Result<std::sync::MutexGuard<'s, PointSource<'a>>> {
    src.lock()
        .map_err(|_| Error::Internal("the point source was poisoned".into()))
}

/// Read what a wave needs: the leaf details of the tiles to extract and their input points
/// (read in parallel first: store cells for the fit and colours, details for the blend).
/// Tiles a resumed run checkpointed already are read back instead.
fn load_wave(
    job: &TileJob,
    wave_tiles: &[WaveTile],
    points: &SharedPoints,
    details: &mut DetailCache,
    ctx: &Ctx,
) -> Result<(Vec<LoadedTile>, Vec<Option<NearPoints>>)> {
    let plan = job.plan;
    let done: Vec<bool> = wave_tiles
        .iter()
        .map(|w| job.params.run.resume && tile_path(job.tiles_dir, w.0).exists())
        .collect();
    let todo: Vec<&WaveTile> = wave_tiles
        .iter()
        .zip(&done)
        .filter(|(_, done)| !**done)
        .map(|(w, _)| w)
        .collect();
    // The tiles' near points, read by the workers.
    let near_todo: Vec<NearPoints> = match points.as_ref() {
        Some(src) => {
            let boxes: Vec<_> = todo.iter().map(|(_, lo, _)| near_box(plan, *lo)).collect();
            let mut src = lock(src)?;
            let near = src.near_points_wave(&ctx.pool, &boxes)?;
            ctx.pool.install(|| {
                near.into_par_iter()
                    .map(|p| to_local(p, plan.cube.origin))
                    .collect()
            })
        }
        None => Vec::new(),
    };
    let keys: Vec<CellKey> = todo.iter().flat_map(|w| w.2.iter().copied()).collect();
    let held = details.load(&keys, &ctx.pool)?;
    let mut near_todo = near_todo.into_iter();
    let mut loaded = Vec::with_capacity(wave_tiles.len());
    let mut near_pts = Vec::with_capacity(wave_tiles.len());
    for ((tt, lo, near), &done) in wave_tiles.iter().zip(&done) {
        if done {
            loaded.push((*tt, *lo, None));
            near_pts.push(None);
            continue;
        }
        near_pts.push(near_todo.next());
        let mut ds = Vec::with_capacity(near.len());
        for k in near {
            let d = held
                .get(k)
                .ok_or_else(|| Error::Internal(format!("leaf {k:?} was not loaded")))?;
            ds.push((*k, Arc::clone(d)));
        }
        loaded.push((*tt, *lo, Some(ds)));
    }
    Ok((loaded, near_pts))
}

/// The pool's share of a tile after extraction: trim, fit and colours from its input points
/// `cp`, checkpoint. Returns the tile's Morton index `tt` and mesh.
fn finish_tile(
    job: &TileJob,
    points: &SharedPoints,
    tt: u64,
    mut mesh: TileMesh,
    cp: &Option<NearPoints>,
) -> Result<(u64, TileMesh)> {
    if job.params.mesh.trim {
        trim_mesh(&mut mesh, |c| job.support.near(c));
    }
    if let Some(cp) = cp {
        fit_tile(job, points, &mut mesh, cp)?;
    }
    if let Some(least) = job.params.mesh.trim_density {
        trim_by_density(&mut mesh, least);
        if !job.params.mesh.density {
            mesh.density.clear();
        }
    }
    write_tile(&tile_path(job.tiles_dir, tt), &mesh)?;
    Ok((tt, mesh))
}

/// Move the vertices of `mesh` onto their input points `cp` (when fitting) and give them
/// their colours and intensities.
fn fit_tile(
    job: &TileJob,
    points: &SharedPoints,
    mesh: &mut TileMesh,
    cp: &NearPoints,
) -> Result<()> {
    let h = job.plan.spacing;
    // The fit, with the samples' measured noise in input units (0 where unknown).
    let fit = job
        .params
        .mesh
        .fit
        .then(|| job.plan.fit_noise_voxels.unwrap_or(0.0) * h);
    // The tile meshes' frame: offsets from the cube's corner (see `to_local`).
    let geom = GridGeom {
        origin: [0.0; 3],
        h,
        n: job.plan.fine_cells,
    };
    let density = job.params.mesh.measures_density();
    let (mut fits, inexact) = cp.fit_vertices(&mesh.positions, &mesh.keys, &geom, fit, density);
    // Vertices whose neighbours may lie beyond the gathered box: their true neighbours lie
    // within their current farthest one, so one wider gather, of the points within the
    // largest such reach of their bounding box, is exact (rare: vertices far from every
    // point).
    if let (false, Some(src)) = (inexact.is_empty(), points.as_ref()) {
        let reach = inexact.iter().map(|&i| fits[i].reach).fold(0.0, f64::max);
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let vs: Vec<[f64; 3]> = inexact.iter().map(|&i| mesh.positions[i]).collect();
        let ks: Vec<EdgeKey> = inexact.iter().map(|&i| mesh.keys[i]).collect();
        for v in &vs {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        let o = job.plan.cube.origin;
        let (lo, hi) = (
            [0, 1, 2].map(|a| lo[a] + o[a]),
            [0, 1, 2].map(|a| hi[a] + o[a]),
        );
        let wide = to_local(
            lock(src)?.points_within(lo, hi, reach * (1.0 + 1e-9) + h * 1e-6)?,
            o,
        );
        let (fixed, _) = wide.fit_vertices(&vs, &ks, &geom, fit, density);
        for (&vi, f) in inexact.iter().zip(fixed) {
            fits[vi] = f;
        }
    }
    if fit.is_some() {
        mesh.positions = settle(
            &mesh.triangles,
            &mesh.keys,
            &fits,
            &geom,
            job.plan.leaf_voxels,
        );
    }
    if job.with_color {
        mesh.colors = fits.iter().map(|f| f.color).collect();
    }
    if job.with_intensity {
        mesh.intensity = fits.iter().map(|f| f.intensity).collect();
    }
    if density {
        mesh.density = fits.iter().map(|f| f.density).collect();
    }
    Ok(())
}

/// Input points `p` (world) relative to the cube's corner `origin`, the frame of the tile
/// meshes: exact on the cube's lattice, so translated inputs give the same numbers.
fn to_local(mut p: NearPoints, origin: [f64; 3]) -> NearPoints {
    for q in &mut p.pos {
        for a in 0..3 {
            q[a] -= origin[a];
        }
    }
    for a in 0..3 {
        p.lo[a] -= origin[a];
        p.hi[a] -= origin[a];
    }
    p
}

/// Extract a wave on the CPU pool: blend, marching cubes, finish, in parallel.
fn extract_cpu(
    job: &TileJob,
    points: &SharedPoints,
    loaded: &[LoadedTile],
    near_pts: &[Option<NearPoints>],
    geom: &GridGeom,
    pool: &rayon::ThreadPool,
    stage: &Stage,
) -> Vec<Result<(u64, TileMesh)>> {
    let plan = job.plan;
    let own = pou::leaf_weights(plan.leaf_voxels as i64, plan.overlap_voxels as i64);
    let dims = [(plan.tile + 1) as usize; 3];
    pool.install(|| {
        loaded
            .par_iter()
            .zip(near_pts.par_iter())
            .map_init(McWorkspace::new, |ws, ((tt, lo, ds), cp)| {
                let Some(ds) = ds else {
                    return Ok((*tt, read_tile(&tile_path(job.tiles_dir, *tt))?));
                };
                let f = tile_blend(plan, &own, job.coarse, job.unit, *lo, ds)?.eval();
                let mut mesh = TileMesh::default();
                ws.extract(
                    &f,
                    dims,
                    lo.map(|v| v as u64),
                    job.iso as f32,
                    geom,
                    &mut mesh,
                )?;
                let done = finish_tile(job, points, *tt, mesh, cp);
                stage.inc(1);
                done
            })
            .collect()
    })
}
