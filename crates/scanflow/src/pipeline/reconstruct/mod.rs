//! `reconstruct`: a store's points to a PLY mesh (ARCHITECTURE.md steps 3 to 5), in phases:
//! plan the grids and prepare the work directory; splat every point and solve the coarse
//! grid; solve the leaves in Morton-order waves, checkpointed; extract the tiles in
//! Morton-order waves (`pipeline::tiles`), welded and streamed to the writer.

use std::collections::BTreeSet;
use std::ops::Range;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::merge;
use super::points::PointSource;
use super::shard::{Claims, Shard};
use super::tiles::{self, TileJob};
use super::workdir::{self, RunIdentity, StoreSource, WorkDir};
use crate::error::{Error, Result, Setting};
use crate::exec::Ctx;
use crate::exec::budget::{Permit, Share};
use crate::exec::progress::Stage;
use crate::io::mesh_write::MeshTarget;
use crate::normals::{NormalParams, NormalsMode};
use crate::recon::checkpoint::{
    CellSplat, CoarseCheckpoint, CoarsePartKind, LeafSummary, coarse_part_path, coarse_path,
    leaf_path, read_coarse, read_density_parts, read_leaf_summary, read_splat_parts, write_coarse,
    write_density_parts, write_leaf, write_splat_parts,
};
use crate::recon::density::{DensityBox, DensityGrid};
use crate::recon::pou::unit_for;
use crate::recon::screen::SPARSE_SPACINGS;
use crate::recon::{
    CoarseField, DEFAULT_ERROR, DEFAULT_MIN_POINTS, LeafDetail, LeafPoints, LeafRule, LeafSolvers,
    Level, Moments, Plan, PlanBudget, PointWeight, grid, refine_leaf,
    screen::{
        self, NOISE_KEY_BYTES, NoiseStats, SCREEN_PART_ENTRY_BYTES, ScreenBuilder, Smoothing,
    },
    solve_coarse,
};
use crate::store::Store;
use crate::surface::Support;
use crate::types::{CellKey, PointBatch};

mod coarse;
mod leaves;
#[cfg(test)]
mod tests;

use coarse::{CoarsePass, coarse_or_checkpoint, smoothing_on};
use leaves::leaf_pass;

/// Bytes a decoded store point holds while the coarse pass splats it: position f64×3 (24),
/// normal f32×3 (12), colour u16×4 (8), intensity f32 (4), confidence f32 (4).
pub(super) const BATCH_POINT_BYTES: u64 = 52;

/// The most the plan gives the cache of sorted store cells, whatever the budget; a pass with
/// room grows it for its length ([`PointSource::begin_pass`]).
const POINT_CACHE_MAX_BYTES: u64 = 128 << 20;

/// The fewest points a solve accepts.
const MIN_POINTS: u64 = 16;

/// How the field is solved: every option of `reconstruct` that shapes the surface's geometry
/// (all of them in the run identity, so a resume or merge with others is refused).
#[derive(Debug, Clone)]
pub struct SolveParams {
    /// Octree depth: `2^depth` cells per edge of the cube (as PoissonRecon's `--depth`).
    pub depth: u32,
    /// The deepest the dense coarse solve may be (`--coarse-depth`; `None`: as deep as
    /// [`crate::recon::plan::levels`] allows); a shallower one adds levels of leaves.
    pub coarse_depth: Option<u32>,
    /// Gaussian smoothing width (`--smooth`: measured from the samples' precision, or a
    /// fixed width in voxels of each grid), see [`crate::recon::screen::Smoothing`].
    pub smoothing: Smoothing,
    /// Screening weight α (`--point-weight`: `standard`, 4 lowered for noise beyond a
    /// voxel; `auto`, also raised for precise samples; or a fixed α, 0: unscreened), see
    /// [`crate::recon::screen`].
    pub point_weight: PointWeight,
    /// Error tolerance relative to the bounding-box diagonal: a leaf whose samples lie
    /// within this mean distance of the coarse solution's surface is not refined.
    pub error: f64,
    /// Leaves with fewer points in their cell are not refined.
    pub min_points: u64,
    /// Refine a leaf only where it holds at least this many samples per fine voxel of a
    /// surface crossing it (PoissonRecon's `--samplesPerNode`): see
    /// [`SolveParams::least_leaf_points`].
    pub samples_per_node: Option<f64>,
    /// Weigh each sample's normal by its confidence ([`weigh_normals`]).
    pub confidence: bool,
}

impl SolveParams {
    /// The fewest points a leaf of `leaf_voxels` fine voxels a side must own to be refined:
    /// `--min-points`, or with `--samples-per-node S` at least `S·E²` (a surface crossing a
    /// leaf of edge `E` covers about `E²` fine voxels, so the leaf is refined only where the
    /// samples average `S` per fine voxel of surface; sparser parts keep the coarse solve's
    /// smoother surface, as PoissonRecon's octree stops where a node holds fewer than
    /// `--samplesPerNode` samples).
    pub fn least_leaf_points(&self, leaf_voxels: u64) -> u64 {
        let by_density = self.samples_per_node.map_or(0, |s| {
            (s * (leaf_voxels * leaf_voxels) as f64).ceil() as u64
        });
        self.min_points.max(by_density)
    }
}

/// What is made of the solved field: the vertex fit, trimming, and the densities written.
#[derive(Debug, Clone)]
pub struct MeshParams {
    /// Move each vertex onto the plane of its nearest input points (see
    /// [`crate::surface::FIT_NEIGHBOURS`]).
    pub fit: bool,
    /// Leave the surface open where no input point is within two coarse voxels.
    pub trim: bool,
    /// Give each vertex its sampling density (input points per square unit, from its
    /// [`crate::surface::FIT_NEIGHBOURS`] nearest points), written as the PLY's `quality`.
    pub density: bool,
    /// Drop the triangles whose corners' mean sampling density is below this (input points
    /// per square unit): PoissonRecon's trimming by density, as a threshold.
    pub trim_density: Option<f64>,
}

impl MeshParams {
    /// Whether the vertices' sampling densities are measured (written or trimmed by).
    pub fn measures_density(&self) -> bool {
        self.density || self.trim_density.is_some()
    }
}

/// How the run is carried out: its work directory, resume, its shard of a split run, the
/// tiles' size and the devices. None changes the CPU path's bytes; the GPU's solve changes
/// them by rounding and is part of the run identity.
#[derive(Debug, Clone)]
pub struct RunParams {
    /// Work directory (leaf checkpoints, run description).
    pub work_dir: PathBuf,
    /// Reuse the leaves a previous run with the same inputs and options left in `work_dir`.
    pub resume: bool,
    /// The slice of the work this process does ([`Shard::ALL`]: all of it, and the mesh; a
    /// split run leaves the tiles for [`crate::pipeline::merge()`]).
    pub shard: Shard,
    /// Tile edge in fine voxels (`None`: 64, at least one leaf, at most the cube).
    pub tile_voxels: Option<u64>,
    /// Tile fields and marching cubes on the GPU: auto (a real GPU when there is one), on,
    /// off (the default: the GPU path is not yet measured faster end to end, see
    /// `extract::gpu`).
    pub gpu: crate::extract::gpu::GpuMode,
    /// The leaves' fine solves on the GPU (`recon::gpu_solve`): auto, on, off (the default:
    /// the CPU's bytes). The mesh differs from the CPU solve's by rounding.
    pub gpu_solve: crate::extract::gpu::GpuMode,
}

impl RunParams {
    /// Whether checkpoints found in the work directory are reused: by a resumed run, and by
    /// every shard of a split run (another shard's work).
    pub fn reuses_checkpoints(&self) -> bool {
        self.resume || self.shard.is_split()
    }
}

/// Options of `reconstruct`: the solver's, the mesh's and the run's.
#[derive(Debug, Clone)]
pub struct ReconParams {
    /// How the field is solved.
    pub solve: SolveParams,
    /// What is made of the field.
    pub mesh: MeshParams,
    /// How the run is carried out.
    pub run: RunParams,
}

impl ReconParams {
    /// The identity of reconstructing `source` with these options; reads each input's
    /// fingerprint (see [`workdir`]'s module docs).
    pub fn identity(
        &self,
        source: &StoreSource,
        normals: NormalsMode,
        normal_params: &NormalParams,
    ) -> Result<RunIdentity> {
        let params = self;
        let options = [
            ("command", "reconstruct".to_string()),
            (Setting::Depth.name(), params.solve.depth.to_string()),
            // The measured width's and weight's rules are part of it: a run before the sparse
            // floor (`recon::screen::sparse_floor_voxels`) solved sparse samples otherwise,
            // and one before the noise of close pairs (`NoiseStats::pair_sigma_voxels`)
            // weighed and smoothed noisy relief otherwise, as one before those pairs were cut
            // (`PairStats::nugget`) did folded relief (their coarse checkpoints are of older
            // formats too).
            (
                Setting::Smooth.name(),
                match params.solve.smoothing {
                    Smoothing::Measured => format!(
                        "measured, narrowed by the noise's share of the quadrics' residual, \
                         at least {SPARSE_SPACINGS} of the samples' spacing"
                    ),
                    fixed => fixed.to_string(),
                },
            ),
            (
                Setting::PointWeight.name(),
                format!(
                    "{}, noise from close pairs cut at {} spreads, the relief's share from {} \
                     voxel of noise to {}",
                    params.solve.point_weight,
                    crate::recon::screen::PAIR_TRIM_SIGMAS,
                    crate::surface::fit::FIT_NOISE_LIMIT_VOXELS,
                    crate::recon::screen::NOISE_DOMINANT_VOXELS
                ),
            ),
            (Setting::Error.name(), params.solve.error.to_string()),
            (
                Setting::MinPoints.name(),
                params.solve.min_points.to_string(),
            ),
            (Setting::Trim.name(), params.mesh.trim.to_string()),
            (
                Setting::NoFit.name(),
                match params.mesh.fit {
                    true => format!(
                        "false, none from {} voxel of noise, noisy samples' misfit by half",
                        crate::surface::fit::FIT_NOISE_LIMIT_VOXELS
                    ),
                    false => "true".to_string(),
                },
            ),
            (
                Setting::GpuSolve.name(),
                crate::recon::gpu_solve::device_identity(params.run.gpu_solve)?,
            ),
            (Setting::Density.name(), params.mesh.density.to_string()),
            (
                Setting::Confidence.name(),
                params.solve.confidence.to_string(),
            ),
            (
                Setting::SamplesPerNode.name(),
                params
                    .solve
                    .samples_per_node
                    .map_or_else(|| "none".to_string(), |s| s.to_string()),
            ),
            (
                Setting::TrimDensity.name(),
                params
                    .mesh
                    .trim_density
                    .map_or_else(|| "none".to_string(), |d| d.to_string()),
            ),
        ];
        RunIdentity::with_options(source, normals, normal_params, &options)
    }

    /// Defaults for `depth` with work directory `work_dir`.
    pub fn new(depth: u32, work_dir: PathBuf) -> ReconParams {
        ReconParams {
            solve: SolveParams {
                depth,
                coarse_depth: None,
                smoothing: Smoothing::Measured,
                point_weight: PointWeight::Standard,
                error: DEFAULT_ERROR,
                min_points: DEFAULT_MIN_POINTS,
                samples_per_node: None,
                confidence: false,
            },
            mesh: MeshParams {
                fit: true,
                trim: false,
                density: false,
                trim_density: None,
            },
            run: RunParams {
                work_dir,
                resume: false,
                shard: Shard::ALL,
                tile_voxels: None,
                gpu: crate::extract::gpu::GpuMode::Off,
                gpu_solve: crate::extract::gpu::GpuMode::Off,
            },
        }
    }
}

/// What `reconstruct` did.
#[derive(Debug, Clone, Serialize)]
pub struct ReconStats {
    /// Output vertices.
    pub vertices: u64,
    /// Output triangles.
    pub faces: u64,
    /// Occupied leaves (solved or reused).
    pub leaves: usize,
    /// Leaves refined by a fine solve (the others were within `--error` of the coarse solve).
    pub leaves_refined: usize,
    /// Leaves found checkpointed in the work directory (by a resumed run's predecessor, or
    /// by another shard).
    pub leaves_reused: usize,
    /// Tiles extracted or read back (tiles with no surface are skipped); in a split run, the
    /// tiles this shard extracted.
    pub tiles: usize,
    /// Tiles that can hold surface, extracted by this process or another shard.
    pub tiles_total: usize,
    /// Iso-value.
    pub iso: f64,
    /// Screening weight α the solves used (0: unscreened).
    pub point_weight: f64,
    /// The Gaussian's width the finest leaves' solves used, in fine voxels (`--smooth`).
    pub smooth_voxels: f64,
    /// The typical distance between neighbouring samples, in fine voxels, from the sampling
    /// density ([`crate::recon::density::DensityGrid::sample_spacing`]).
    pub sample_spacing_voxels: Option<f64>,
    /// The samples' spread across the surface in fine voxels, where one could be measured
    /// ([`crate::recon::screen::NoiseStats`]).
    pub noise_voxels: Option<f64>,
    /// The samples' noise read from pairs of close samples in fine voxels, where enough
    /// pairs were found ([`crate::recon::screen::NoiseStats::pair_sigma_voxels`]).
    pub pair_noise_voxels: Option<f64>,
    /// The samples' spread about local quadric fits in fine voxels, where one could be
    /// measured ([`crate::recon::screen::NoiseStats::jet_sigma_voxels`]).
    pub jet_noise_voxels: Option<f64>,
    /// Conjugate-gradient iterations of the screened coarse solve.
    pub coarse_iterations: u32,
    /// The levels of leaves above the finest (the recursive scheme, from the top down; none
    /// where the dense coarse solve is the finest level's coarse field).
    pub levels_above: Vec<LevelStats>,
    /// Leaves whose fine solve ran in this run (refined and not reused).
    pub leaves_solved: usize,
    /// Conjugate-gradient iterations of the leaves' screened fine solves, summed over the
    /// leaves solved in this run.
    pub leaf_iterations: u64,
    /// Leaf edge in fine voxels.
    pub leaf_voxels: u64,
    /// Fine voxels per coarse voxel.
    pub coarse_ratio: u64,
    /// Tile edge in fine voxels.
    pub tile_voxels: u64,
    /// Most vertices held in the welder's frontier at once.
    pub peak_frontier: usize,
    /// Wall time in seconds.
    pub secs: f64,
    /// Input points.
    pub points: u64,
    /// Where the leaves are and which were refined, seen from above.
    pub leaf_map: LeafMap,
    /// The picture of the mesh, when asked for.
    #[serde(skip)]
    pub preview: Option<crate::io::preview::Preview>,
}

/// One level of leaves above the finest ([`crate::recon::plan::levels`]).
#[derive(Debug, Clone, Serialize)]
pub struct LevelStats {
    /// The level's depth.
    pub depth: u32,
    /// Its leaves holding points.
    pub leaves: usize,
    /// Those refined by a fine solve.
    pub refined: usize,
    /// Those read back from checkpoints.
    pub reused: usize,
    /// Samples its solved leaves read, each as often as a leaf's box holds it: one by one,
    /// and summed per voxel ([`crate::recon::voxel_sum`]).
    pub points_read: u64,
    /// Of which summed per voxel.
    pub points_summed: u64,
    /// The voxel sums holding those.
    pub voxel_sums: u64,
}

/// The ancestor of `key` at `level` (at most `key`'s level).
fn ancestor(mut key: CellKey, level: u32) -> CellKey {
    while key.level() > level {
        key = key.parent();
    }
    key
}

/// The leaves seen from above (along −z): per column `(x, y)` of the leaf grid, how many
/// leaves hold points and how many of them were refined by a fine solve, for the run
/// report's map.
#[derive(Debug, Clone, Default, Serialize)]
pub struct LeafMap {
    /// Leaves per axis.
    pub n: u32,
    /// Leaves holding points per column, row-major in y then x (`n × n`).
    pub occupied: Vec<u32>,
    /// Refined leaves per column.
    pub refined: Vec<u32>,
}

impl LeafMap {
    /// The map of `all` leaves, `refined` among them.
    fn new(all: &[CellKey], refined: &BTreeSet<CellKey>) -> LeafMap {
        let Some(level) = all.first().map(|k| k.level()) else {
            return LeafMap::default();
        };
        let n = 1u32 << level;
        let mut map = LeafMap {
            n,
            occupied: vec![0; (n * n) as usize],
            refined: vec![0; (n * n) as usize],
        };
        for k in all {
            let (l, c) = k.decode();
            if l != level {
                continue;
            }
            let i = (c[1] * n + c[0]) as usize;
            map.occupied[i] += 1;
            if refined.contains(k) {
                map.refined[i] += 1;
            }
        }
        map
    }
}

/// Reconstruct the surface of the points in `store` into the mesh `out`; a split run
/// (`params.shard`) does its slice of the leaves and tiles and leaves the mesh to
/// [`merge()`](crate::pipeline::merge()) (`out` is not written).
pub fn reconstruct(
    store: &Store,
    out: &MeshTarget,
    params: &ReconParams,
    ctx: &Ctx,
) -> Result<ReconStats> {
    let t0 = Instant::now();
    if params.run.shard.is_split() {
        // Other tasks, maybe on other hosts, write into the same work directory.
        crate::fs::atomic::tag_temps_with_host();
    }
    let mut levels = plan_run(store, params, ctx)?;
    let dirs = workdir::prepare(store, &levels, &params.run)?;
    let top = *levels.last().expect("a plan has a level");
    let coarse = coarse_or_checkpoint(store, &levels[0], &top, params, &dirs, ctx)?;
    let spacing = coarse.density.sample_spacing();
    measured_levels(&mut levels, params, &coarse, spacing);
    let plan = levels[0];
    let point_cap = ctx
        .budget
        .share(Share::PointCache)
        .min(POINT_CACHE_MAX_BYTES);
    let _cache_permit = ctx.budget.acquire_now(point_cap, "the store cell cache")?;
    let CoarsePass {
        field,
        density,
        _permit: _coarse_permit,
        occupied,
        support,
        iterations: coarse_iterations,
        noise,
        ..
    } = coarse;
    // Fixed point for the blend (`extract::field`): the coarse values within 2^21 units;
    // every level's details are stored in it.
    let unit = unit_for(field.max_abs());
    // The levels above the finest, from the top down: each is the coarse field of the next,
    // with a cache of its details (a sixteenth of the budget between them).
    let uppers = levels.len() as u64 - 1;
    let level_cache = ctx.budget.total() / 16 / uppers.max(1);
    let _level_permit = (uppers > 0)
        .then(|| {
            ctx.budget.acquire_now(
                level_cache * uppers,
                "the caches of the upper levels' details",
            )
        })
        .transpose()?;
    let mut field = field;
    let mut above = Vec::new();
    for k in (1..levels.len()).rev() {
        let p = levels[k];
        let keys: BTreeSet<CellKey> = occupied
            .iter()
            .map(|&key| ancestor(key, p.leaf_level))
            .collect();
        let mut src = PointSource::new(store, p, point_cap, Arc::clone(&density)).summing();
        let name = format!("leaves at depth {}", p.depth);
        let lp = leaf_pass(
            store, &p, params, keys, &field, unit, &dirs, &mut src, &name, ctx,
        )?;
        above.push(LevelStats {
            depth: p.depth,
            leaves: lp.all.len(),
            refined: lp.refined.len(),
            reused: lp.reused,
            points_read: lp.read.points,
            points_summed: lp.read.summed,
            voxel_sums: lp.read.sums,
        });
        let level = Level::new(p, field, lp.refined, dirs.leaves.clone(), unit, level_cache);
        field = CoarseField::level(level, levels[k - 1].coarse_ratio);
    }
    let mut src = PointSource::new(store, plan, point_cap, Arc::clone(&density));
    let leaves = leaf_pass(
        store, &plan, params, occupied, &field, unit, &dirs, &mut src, "leaves", ctx,
    )?;
    let m = &store.manifest;
    let (with_color, with_intensity) = (m.attributes.color, m.attributes.intensity);
    let points =
        (with_color || with_intensity || params.mesh.fit || params.mesh.measures_density())
            .then(|| Mutex::new(src.for_positions()));
    let job = TileJob {
        plan: &plan,
        params,
        coarse: &field,
        support: &support,
        refined: &leaves.refined,
        iso: leaves.iso,
        unit: leaves.unit,
        leaves_dir: &dirs.leaves,
        tiles_dir: &dirs.tiles,
        claims_dir: &dirs.claims,
        with_color,
        with_intensity,
        input: &store.dir,
        bounds: m.bounds,
    };
    let nonempty = tiles::nonempty_tiles(&job, &ctx.pool)?;
    let split = params.run.shard.is_split();
    if split {
        // What `merge` welds; every shard writes the same description.
        merge::describe(
            &params.run.work_dir,
            &merge::MergeDescription {
                plan,
                iso: leaves.iso,
                with_color,
                with_intensity,
                with_density: params.mesh.density,
                input: store.dir.clone(),
                bounds: m.bounds,
                tiles: nonempty.clone(),
            },
        )?;
    }
    let ts = tiles::run(&job, &nonempty, points, (!split).then_some(out), ctx)?;
    Ok(ReconStats {
        vertices: ts.vertices,
        faces: ts.faces,
        leaves: leaves.all.len(),
        leaves_refined: leaves.refined.len(),
        leaves_reused: leaves.reused,
        tiles: ts.tiles,
        tiles_total: nonempty.len(),
        iso: leaves.iso,
        point_weight: plan.point_weight,
        smooth_voxels: plan.sigma_vox,
        sample_spacing_voxels: spacing.map(|s| s / plan.spacing),
        noise_voxels: noise.sigma_voxels(),
        pair_noise_voxels: noise.pair_sigma_voxels(),
        jet_noise_voxels: noise.jet_sigma_voxels(),
        coarse_iterations,
        levels_above: above,
        leaves_solved: leaves.solved,
        leaf_iterations: leaves.iterations,
        leaf_voxels: plan.leaf_voxels,
        coarse_ratio: plan.coarse_ratio,
        tile_voxels: plan.tile,
        peak_frontier: ts.peak_frontier,
        secs: t0.elapsed().as_secs_f64(),
        points: m.point_count,
        leaf_map: LeafMap::new(&leaves.all, &leaves.refined),
        preview: ts.preview,
    })
}

/// What the coarse pass measured, into every level's plan: the weight the coarse solve used
/// (`auto` measures it there); the Gaussian's width per level, from the noise and the
/// samples' `spacing` on its grid, the coarse local solves taking the width of the field they
/// stand in for (the level above, or the dense solve).
fn measured_levels(
    levels: &mut [Plan],
    params: &ReconParams,
    coarse: &CoarsePass,
    spacing: Option<f64>,
) {
    for p in levels.iter_mut() {
        p.point_weight = coarse.point_weight;
        p.sigma_vox = smoothing_on(params, &coarse.noise, spacing, p.spacing);
        p.fit_noise_voxels = coarse.noise.fit_noise_voxels();
    }
    for i in 0..levels.len() {
        levels[i].coarse_sigma_vox = levels
            .get(i + 1)
            .map_or(coarse.sigma_vox, |up| up.sigma_vox);
    }
}

/// The samples' normals as the normal field weighs them, as PoissonRecon does:
///
/// - without `confidence`, unit normals: every sample counts once, however long the normals
///   a file carries;
/// - with `confidence` and a confidence per point (a PLY `confidence` property), unit normals
///   times the confidence clamped to [0, 1] (a non-finite one counts 0);
/// - with `confidence` and no such property, the normals as the inputs give them: their
///   lengths are the confidences (PoissonRecon's `--confidence` convention).
///
/// So samples a scanner trusts less (grazing angles, far ranges) pull the surface less where
/// better ones overlap them. The screening term and the iso-value keep unit weights.
///
/// Each normal is then scaled by its sample's share of the surface, the sampling-density
/// weight of `density` ([`DensityGrid::weight`]), so that dense and sparse parts of a scan
/// make the indicator jump alike.
pub fn weigh_normals(b: &mut PointBatch, confidence: bool, density: &DensityGrid) {
    let by_property = confidence && b.confidence.len() == b.normal.len();
    let by_length = confidence && !by_property;
    for (i, n) in b.normal.iter_mut().enumerate() {
        let area = density.weight(b.pos[i]);
        let w = if by_length {
            1.0
        } else {
            let c = if by_property { b.confidence[i] } else { 1.0 };
            let c = if c.is_finite() {
                c.clamp(0.0, 1.0)
            } else {
                0.0
            };
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            // Readers refuse zero normals; a zero one would splat nothing either way.
            if len > 0.0 { f64::from(c / len) } else { 0.0 }
        };
        let s = (w * area) as f32;
        *n = n.map(|x| x * s);
    }
}

/// Check that `store` can be reconstructed and choose the grids: the levels, finest first
/// ([`crate::recon::plan::levels`]).
fn plan_run(store: &Store, params: &ReconParams, ctx: &Ctx) -> Result<Vec<Plan>> {
    let m = &store.manifest;
    if !m.attributes.normal {
        return Err(Error::input(
            &store.dir,
            format!(
                "the store's points have no normals (nx ny nz), which reconstruction requires: ingest it again with {} auto or estimate, or reconstruct from the point files (normals are then estimated)",
                Setting::Normals
            ),
        ));
    }
    if m.point_count < MIN_POINTS {
        return Err(Error::input(
            &store.dir,
            format!(
                "only {} points: a solve needs at least {MIN_POINTS}",
                m.point_count
            ),
        ));
    }
    if params.solve.confidence && !m.attributes.confidence && m.estimated_normals.is_some() {
        return Err(Error::input(
            &store.dir,
            format!(
                "{}: the points carry no confidence (a PLY vertex property \"confidence\") and their normals were estimated (unit length), so there is nothing to weigh them by",
                Setting::Confidence
            ),
        ));
    }
    let mut levels = crate::recon::plan::levels(
        m.cube,
        params.solve.depth,
        // Before the noise is measured `measured` is the widest: the width is the solves'
        // alone, set by the coarse pass with the weight.
        params.solve.smoothing.voxels(&NoiseStats::default(), None),
        // Before the noise is measured `standard` and `auto` are the base weight: the grids
        // are sized for a screened solve, and the coarse pass sets the weight (never to 0).
        params.solve.point_weight.alpha(&NoiseStats::default()),
        params.run.tile_voxels,
        params.solve.coarse_depth,
        plan_budget(ctx.budget.total()),
    )?;
    for p in &mut levels {
        p.confidence = params.solve.confidence;
    }
    Ok(levels)
}

/// What a budget of `total` bytes gives the grids ([`Share`]): the coarse solve's scratch its
/// slice, and the coarse solution with one leaf solve what the point cache leaves.
fn plan_budget(total: u64) -> PlanBudget {
    let cache = Share::PointCache.of(total).min(POINT_CACHE_MAX_BYTES);
    PlanBudget {
        coarse: Share::CoarseGrid.of(total),
        leaf: total.saturating_sub(cache),
    }
}

/// The least `--mem` of any reconstruction: below it the point cache, a wave of one leaf
/// solve, one tile and the waves of the passes over the store are not worth planning for.
/// Measured: a 1M-point sphere at depth 10 peaks at 73 MiB under `--mem 64M` (README).
pub const MEM_FLOOR: u64 = 64 << 20;

/// The smallest `--mem` a reconstruction at `depth` can be planned in (screened or not): the
/// floor ([`MEM_FLOOR`]), or more where the smallest top level's coarse solve, and then its
/// coarse solution beside one leaf solve and the point cache, need more
/// ([`Plan::least_budget`]).
pub fn least_mem(depth: u32, screened: bool) -> u64 {
    let grids = Plan::least_budget(depth, screened, |need| {
        // The smallest total whose slices hold `need`: they grow with the total.
        let fits = |t: u64| {
            let b = plan_budget(t);
            b.coarse >= need.coarse && b.leaf >= need.leaf
        };
        let (mut lo, mut hi) = (0u64, 1u64 << 50);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if fits(mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        hi
    });
    grids.max(MEM_FLOOR)
}

/// Most of `--mem` the trim support's bits take: a 32nd (128 MiB under `--mem 4G`).
const SUPPORT_BUDGET_DIVISOR: u64 = 32;

/// The grid of the support `--trim` keeps triangles near (spacing, voxels an edge): the
/// finest level's coarse voxels (4 fine voxels, as a run of one level trims), halved while
/// their bits would take more than a [`SUPPORT_BUDGET_DIVISOR`]th of the budget `total`,
/// but never coarser than the dense solve's. Trimming at the dense solve's voxels, as
/// before, kept triangles up to 64 fine voxels from any point at depth 13 (a 100M-point
/// terrain: 5% of its area more than 4.4·10⁻³ of a width of 2 from the surface, against
/// 7.2·10⁻⁵ at depth 10).
fn support_grid(fine: &Plan, plan: &Plan, total: u64) -> (f64, u64) {
    let mut cells = fine.coarse_cells();
    while cells > plan.coarse_cells() && Support::bytes(cells) > total / SUPPORT_BUDGET_DIVISOR {
        cells /= 2;
    }
    (plan.cube.size / cells as f64, cells)
}
