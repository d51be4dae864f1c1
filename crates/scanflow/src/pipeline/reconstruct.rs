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
use crate::error::{Error, Result};
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
    Level, Moments, Plan, PlanBudget, PointWeight, fft_solve, refine_leaf,
    screen::{
        self, NOISE_KEY_BYTES, NoiseStats, SCREEN_PART_ENTRY_BYTES, ScreenBuilder, Smoothing,
    },
    solve_coarse,
};
use crate::store::Store;
use crate::surface::Support;
use crate::types::{CellKey, PointBatch};

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
            ("--depth", params.solve.depth.to_string()),
            // The measured width's and weight's rules are part of it: a run before the sparse
            // floor (`recon::screen::sparse_floor_voxels`) solved sparse samples otherwise,
            // and one before the noise of close pairs (`NoiseStats::pair_sigma_voxels`)
            // weighed and smoothed noisy relief otherwise, as one before those pairs were cut
            // (`PairStats::nugget`) did folded relief (their coarse checkpoints are of older
            // formats too).
            (
                "--smooth",
                match params.solve.smoothing {
                    Smoothing::Measured => format!(
                        "measured, narrowed by the noise's share of the quadrics' residual, \
                         at least {SPARSE_SPACINGS} of the samples' spacing"
                    ),
                    fixed => fixed.to_string(),
                },
            ),
            (
                "--point-weight",
                format!(
                    "{}, noise from close pairs cut at {} spreads, the relief's share from {} \
                     voxel of noise to {}",
                    params.solve.point_weight,
                    crate::recon::screen::PAIR_TRIM_SIGMAS,
                    crate::surface::fit::FIT_NOISE_LIMIT_VOXELS,
                    crate::recon::screen::NOISE_DOMINANT_VOXELS
                ),
            ),
            ("--error", params.solve.error.to_string()),
            ("--min-points", params.solve.min_points.to_string()),
            ("--trim", params.mesh.trim.to_string()),
            (
                "--no-fit",
                match params.mesh.fit {
                    true => format!(
                        "false, none from {} voxel of noise, noisy samples' misfit by half",
                        crate::surface::fit::FIT_NOISE_LIMIT_VOXELS
                    ),
                    false => "true".to_string(),
                },
            ),
            (
                "--gpu-solve",
                crate::recon::gpu_solve::device_identity(params.run.gpu_solve)?,
            ),
            ("--density", params.mesh.density.to_string()),
            ("--confidence", params.solve.confidence.to_string()),
            (
                "--samples-per-node",
                params
                    .solve
                    .samples_per_node
                    .map_or_else(|| "none".to_string(), |s| s.to_string()),
            ),
            (
                "--trim-density",
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
            "the store's points have no normals (nx ny nz), which reconstruction requires: ingest it again with --normals auto or estimate, or reconstruct from the point files (normals are then estimated)",
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
            "--confidence: the points carry no confidence (a PLY vertex property \"confidence\") and their normals were estimated (unit length), so there is nothing to weigh them by",
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

/// The permit of what the coarse pass leaves for the rest of the run: the coarse solution,
/// the sampling density and the support's bits (`support_n` voxels an edge).
fn acquire_coarse_results(plan: &Plan, support_n: u64, ctx: &Ctx) -> Result<Permit> {
    ctx.budget.acquire_now(
        plan.coarse_field_bytes() + plan.density_bytes() + Support::bytes(support_n),
        "the coarse solution, the sampling density and the trim support",
    )
}

/// What the coarse pass leaves: the coarse solution (its permit held while it lives), the
/// occupied leaf cells, and which voxels of the trim support hold points ([`support_grid`]).
struct CoarsePass {
    field: CoarseField,
    /// Every sample's share of the surface ([`crate::recon::density`]).
    density: Arc<DensityGrid>,
    _permit: Permit,
    occupied: BTreeSet<CellKey>,
    support: Support,
    iterations: u32,
    /// The screening weight of the run (`standard`'s or `auto`'s choice, or the one given).
    point_weight: f64,
    /// The Gaussian's width of the run, in voxels of each grid (measured, or the one given).
    sigma_vox: f64,
    /// The samples' noise, measured beside the splat.
    noise: NoiseStats,
}

/// The next wave of store cells from `*i` (advanced past them) up to `end`: at most `wave`
/// cells, within half of what the budget has free at `bytes(cell)` each, at least one; with
/// their bytes.
fn cell_wave(
    i: &mut usize,
    end: usize,
    wave: usize,
    bytes: &impl Fn(usize) -> u64,
    ctx: &Ctx,
) -> (Vec<usize>, u64) {
    let free = ctx.budget.total().saturating_sub(ctx.budget.used());
    let (mut ids, mut sum) = (Vec::with_capacity(wave), 0u64);
    while *i < end && ids.len() < wave {
        let b = bytes(*i);
        if !ids.is_empty() && sum + b > free / 2 {
            break;
        }
        ids.push(*i);
        sum += b;
        *i += 1;
    }
    (ids, sum)
}

/// Points in a chunk of a split run's coarse pass, at least (whole store cells, in order):
/// the work item its shards claim, a fraction of a second of reading. Store cells of
/// ingest's default size make a chunk each.
const COARSE_CHUNK_POINTS: u64 = 1 << 17;

/// The chunks of the store's cells a split run's coarse pass claims: consecutive cells, each
/// chunk closed once it holds [`COARSE_CHUNK_POINTS`]. A function of the store alone.
fn coarse_chunks(store: &Store) -> Vec<Range<usize>> {
    let mut chunks = Vec::new();
    let (mut from, mut points) = (0, 0u64);
    for (i, c) in store.manifest.cells.iter().enumerate() {
        points += c.count;
        if points >= COARSE_CHUNK_POINTS {
            chunks.push(from..i + 1);
            (from, points) = (i + 1, 0);
        }
    }
    if from < store.manifest.cells.len() {
        chunks.push(from..store.manifest.cells.len());
    }
    chunks
}

/// How one of the coarse pass's two reads of the store computes, sizes, checkpoints and
/// sums its parts (one per store cell).
struct CellParts<'a, P> {
    kind: CoarsePartKind,
    /// Bytes a store cell's read and part may hold at once, at most.
    cell_bytes: &'a (dyn Fn(usize) -> u64 + Sync),
    /// The part of store cell `i`.
    part: &'a (dyn Fn(usize) -> Result<P> + Sync),
    /// Bytes a part holds.
    size: fn(&P) -> u64,
    write: fn(&std::path::Path, &[P]) -> Result<()>,
    read: fn(&std::path::Path) -> Result<Vec<P>>,
}

/// One read of the store by the coarse pass: the part of every store cell, given to `add` in
/// cell order. One process reads the cells in waves and adds each wave's parts. A split run's
/// shards compute chunks of cells ([`coarse_chunks`]) as claimed work items, checkpointed in
/// the leaf directory, taking over in a second pass what other shards left undone (as the
/// leaf pass does); then every shard reads every chunk back and adds them in order. So `add`
/// sees the same parts in the same order wherever they were computed: the sums, and the
/// bits, are one process's for any shard count.
fn over_cells<P: Send>(
    store: &Store,
    params: &ReconParams,
    dirs: &WorkDir,
    how: CellParts<P>,
    mut add: impl FnMut(Vec<P>) -> Result<()>,
    ctx: &Ctx,
) -> Result<()> {
    let wave = 2 * ctx.threads();
    let run = |cells: Range<usize>, sink: &mut dyn FnMut(Vec<P>) -> Result<()>| -> Result<()> {
        let mut i = cells.start;
        while i < cells.end {
            let (ids, bytes) = cell_wave(&mut i, cells.end, wave, &how.cell_bytes, ctx);
            // The coarse grid's permit is held: admitted without waiting (`tiles::admit_now`).
            let _permit = tiles::admit_now(ctx, bytes);
            let parts: Vec<P> = ctx.pool.install(|| {
                ids.par_iter()
                    .map(|&j| (how.part)(j))
                    .collect::<Result<_>>()
            })?;
            sink(parts)?;
        }
        Ok(())
    };
    if !params.run.shard.is_split() {
        return run(0..store.manifest.cells.len(), &mut add);
    }
    let chunks = coarse_chunks(store);
    let claims = Claims::new(&dirs.claims);
    let path = |c: usize| coarse_part_path(&dirs.leaves, how.kind, c);
    let mut here = 0;
    for &claiming in params.run.shard.passes() {
        for c in params.run.shard.order(chunks.len()) {
            if path(c).exists()
                || (claiming && !claims.take(&format!("{}-{c}", how.kind.name()))?)
            {
                continue;
            }
            let (mut held, mut permits) = (Vec::new(), Vec::new());
            run(chunks[c].clone(), &mut |parts| {
                permits.push(tiles::admit_now(ctx, parts.iter().map(how.size).sum()));
                held.extend(parts);
                Ok(())
            })?;
            (how.write)(&path(c), &held)?;
            here += 1;
        }
    }
    log::info!(
        "{}: {here} of {} chunks of store cells read here, the others' parts read back",
        how.kind.name(),
        chunks.len()
    );
    for c in 0..chunks.len() {
        let parts = (how.read)(&path(c))?;
        let _permit = tiles::admit_now(ctx, parts.iter().map(how.size).sum());
        add(parts)?;
    }
    Ok(())
}

/// Nodes per axis that the points of store cell `i` reach on a grid of `nodes` nodes over
/// the cube, at most (its octree cell's share of the grid, and a few for the kernels).
fn cell_nodes(store: &Store, i: usize, nodes: u64) -> u64 {
    let level = store.manifest.cells[i].key.level();
    ((nodes >> level.min(63)) + 4).min(nodes + 1)
}

/// Pass 0: every point's sampling density, splatted onto a grid at the coarse spacing; each
/// store cell into a part of its own, the parts added in parallel over z-slabs of the grid
/// (the sums are integers: the same grid in any order, [`over_cells`]).
fn density_pass(
    store: &Store,
    plan: &Plan,
    params: &ReconParams,
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<DensityGrid> {
    let m = &store.manifest;
    // Charged with the coarse solve's scratch (`Plan::needs`).
    let mut grid = DensityGrid::new(&plan.cube, plan.coarse_cells());
    let layout = grid.layout();
    let stage = ctx.progress.stage("density", Some(m.point_count), "points");
    let nodes = plan.coarse_cells() + 1;
    let cell_bytes =
        |i: usize| m.cells[i].count * BATCH_POINT_BYTES + 4 * cell_nodes(store, i, nodes).pow(3);
    let part = |i: usize| {
        let b = store.read_cell(i)?;
        stage.inc(b.len() as u64);
        Ok(layout.part(&b.pos))
    };
    let how = CellParts {
        kind: CoarsePartKind::Density,
        cell_bytes: &cell_bytes,
        part: &part,
        size: DensityBox::bytes,
        write: write_density_parts,
        read: read_density_parts,
    };
    over_cells(
        store,
        params,
        dirs,
        how,
        |parts| {
            let parts: Vec<&DensityBox> = parts.iter().collect();
            ctx.pool.install(|| grid.add_parts(&parts));
            Ok(())
        },
        ctx,
    )?;
    grid.finish();
    stage.finish(None);
    Ok(grid)
}

/// Pass 1: splat every point into the coarse grid of `plan` (the top level), each normal
/// weighed by its sample's share of the surface (pass 0); collect the occupied leaf cells of
/// `fine` (the finest level), the noise in its voxels, the support's voxels holding points, and
/// the moments that refuse planar and linear inputs; solve. Each store cell's share
/// ([`CellSplat`]: its splat and screening aggregates apart from the grids, and the rest) is
/// computed on its own, in parallel; the shares are added in cell order, the grids' in
/// parallel over z-slabs ([`fft_solve::add_boxes`], [`ScreenBuilder::add_parts`]), so the
/// bits are the same for any thread and shard count ([`over_cells`]).
fn coarse_pass(
    store: &Store,
    fine: &Plan,
    plan: &Plan,
    params: &ReconParams,
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<CoarsePass> {
    let m = &store.manifest;
    let cgrid = plan.coarse_grid();
    let (support_h, support_n) = support_grid(fine, plan, ctx.budget.total());
    let permit = ctx.budget.acquire_now(
        plan.coarse_scratch_bytes() + plan.density_bytes() + Support::bytes(support_n),
        "the coarse global solve and the sampling density",
    )?;
    let density = Arc::new(density_pass(store, plan, params, dirs, ctx)?);
    let stage = ctx.progress.stage("splat", Some(m.point_count), "points");
    let mut v = vec![[0f32; 3]; cgrid.len()];
    let mut occupied = BTreeSet::new();
    // Relative to the cube's corner, as the tile meshes it trims (`pipeline::tiles`).
    let origin = plan.cube.origin;
    let mut support = Support::new([0.0; 3], support_h, support_n);
    let locate = support.layout();
    let mut moments = Moments::new(m.bounds.min);
    // The samples aggregated per coarse voxel for the screening: one entry per occupied coarse
    // voxel, admitted as it grows.
    let screened = plan.point_weight > 0.0;
    let mut noise = NoiseStats::default();
    let mut screen = ScreenBuilder::with_slabs(&cgrid, ctx.threads());
    let mut screen_permit: Option<Permit> = None;
    let noise_every = screen::noise_cell_stride(m.point_count);
    let nodes = cgrid.n as u64;
    let cell_bytes = |i: usize| {
        let box_bytes = fft_solve::SplatBox::bytes_within(cell_nodes(store, i, nodes));
        let screen_bytes = if screened {
            SCREEN_PART_ENTRY_BYTES * m.cells[i].count.min(box_bytes / 12)
        } else {
            0
        };
        m.cells[i].count * (BATCH_POINT_BYTES + NOISE_KEY_BYTES) + box_bytes + screen_bytes
    };
    // A store cell's share: its noise statistics, moments, occupied leaves and support
    // beside its splat and screening aggregates.
    let part = |j: usize| -> Result<CellSplat> {
        let mut b = store.read_cell(j)?;
        let noise = if j.is_multiple_of(noise_every) {
            NoiseStats::of(&b.pos, &b.normal, fine.cube.origin, fine.spacing)
        } else {
            NoiseStats::default()
        };
        weigh_normals(&mut b, plan.confidence, &density);
        let mut moments = Moments::new(m.bounds.min);
        // A cell's points are near each other: runs of one voxel or leaf are kept once as
        // they come, the rest once sorted.
        let (mut marks, mut leaves) = (Vec::new(), Vec::new());
        for p in &b.pos {
            let i = locate.index([0, 1, 2].map(|a| p[a] - origin[a])) as u64;
            if marks.last() != Some(&i) {
                marks.push(i);
            }
            let k = CellKey::new(fine.leaf_level, fine.cube.cell_coords(*p, fine.leaf_level));
            if leaves.last() != Some(&k) {
                leaves.push(k);
            }
            moments.add(*p);
        }
        marks.sort_unstable();
        marks.dedup();
        leaves.sort_unstable();
        leaves.dedup();
        stage.inc(b.len() as u64);
        Ok(CellSplat {
            splat: fft_solve::splat_box(&cgrid, &b.pos, &b.normal),
            screen: if screened {
                ScreenBuilder::part(&cgrid, &b.pos)
            } else {
                Vec::new()
            },
            noise,
            moments: moments.sums(),
            marks,
            leaves,
        })
    };
    let how = CellParts {
        kind: CoarsePartKind::Splat,
        cell_bytes: &cell_bytes,
        part: &part,
        size: CellSplat::bytes,
        write: write_splat_parts,
        read: read_splat_parts,
    };
    let add = |parts: Vec<CellSplat>| -> Result<()> {
        for r in &parts {
            noise.add(r.noise);
            moments.merge(&Moments::with_sums(m.bounds.min, r.moments));
            r.marks.iter().for_each(|&i| support.mark_index(i as usize));
            occupied.extend(&r.leaves);
        }
        let boxes: Vec<&fft_solve::SplatBox> = parts.iter().map(|r| &r.splat).collect();
        ctx.pool
            .install(|| fft_solve::add_boxes(&cgrid, &boxes, &mut v));
        if screened {
            let aggregates: Vec<&[_]> = parts.iter().map(|r| &r.screen[..]).collect();
            ctx.pool.install(|| screen.add_parts(&aggregates));
            let held = screen_permit.as_ref().map_or(0, |p| p.bytes());
            if screen.bytes() > held {
                // Doubled ahead, as the map grows.
                screen_permit = Some(ctx.budget.acquire_now(
                    2 * screen.bytes(),
                    "the screening samples of the coarse solve",
                )?);
            }
        }
        Ok(())
    };
    over_cells(store, params, dirs, how, add, ctx)?;
    stage.finish(None);
    moments.check_not_flat(&store.dir)?;
    let stage = ctx.progress.stage("coarse", None, "solves");
    let point_weight = params.solve.point_weight.alpha(&noise);
    let sigma_vox = smoothing_on(
        params,
        &noise,
        density.sample_spacing(),
        plan.coarse_spacing(),
    );
    let screen = screen.finish(point_weight);
    let solved = Plan { sigma_vox, ..*plan };
    let (field, conv) = ctx.pool.install(|| solve_coarse(&solved, v, &screen));
    drop(screen);
    drop(screen_permit);
    // From here on only the solution and the density grid are held (the plan counted on
    // them for the leaf pass).
    drop(permit);
    let permit = acquire_coarse_results(plan, support_n, ctx)?;
    stage.finish(None);
    Ok(CoarsePass {
        field,
        density,
        _permit: permit,
        occupied,
        support,
        iterations: conv.iterations,
        point_weight,
        sigma_vox,
        noise,
    })
}

/// The Gaussian's width for a grid of spacing `h` (input units), in its voxels: `--smooth`
/// for samples of the measured `noise` lying `spacing` apart (input units).
fn smoothing_on(params: &ReconParams, noise: &NoiseStats, spacing: Option<f64>, h: f64) -> f64 {
    params.solve.smoothing.voxels(noise, spacing.map(|s| s / h))
}

/// The coarse pass ([`coarse_pass`]) checkpointed in the work directory; or, where a resumed
/// run's predecessor or another shard left that checkpoint, its results read back, bit for
/// bit what the pass gives (the checkpoint lives beside the leaves', so it is dropped with
/// them when the plan changes). A shard that starts after another finished the pass, a
/// requeued task and a resumed run so skip the two reads of every point.
fn coarse_or_checkpoint(
    store: &Store,
    fine: &Plan,
    plan: &Plan,
    params: &ReconParams,
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<CoarsePass> {
    let path = coarse_path(&dirs.leaves);
    let found = params
        .run
        .reuses_checkpoints()
        .then(|| read_coarse(&path))
        .transpose()?
        .flatten();
    if let Some(c) = found {
        let bad = |what: &str| {
            Error::input(
                &path,
                format!("corrupt coarse checkpoint: {what} does not fit the plan"),
            )
        };
        let (support_h, support_n) = support_grid(fine, plan, ctx.budget.total());
        let permit = acquire_coarse_results(plan, support_n, ctx)?;
        if c.field.len() as u64 != plan.coarse_nodes.pow(3) {
            return Err(bad("the coarse solution"));
        }
        let density =
            DensityGrid::with_counts(&plan.cube, plan.coarse_cells(), c.density.into_owned())
                .ok_or_else(|| bad("the sampling density"))?;
        let support = Support::with_bits([0.0; 3], support_h, support_n, c.support.into_owned())
            .ok_or_else(|| bad("the support"))?;
        if c.occupied.iter().any(|k| k.level() != fine.leaf_level) {
            return Err(bad("an occupied leaf"));
        }
        // A function of the statistics read back, as the pass computed it.
        let sigma_vox = smoothing_on(
            params,
            &c.noise,
            density.sample_spacing(),
            plan.coarse_spacing(),
        );
        log::info!(
            "{}: the coarse pass's results read back ({} occupied leaves)",
            path.display(),
            c.occupied.len()
        );
        return Ok(CoarsePass {
            field: CoarseField::new(plan, c.field.into_owned()),
            density: Arc::new(density),
            _permit: permit,
            occupied: c.occupied.into_iter().collect(),
            support,
            iterations: c.iterations,
            point_weight: c.point_weight,
            sigma_vox,
            noise: c.noise,
        });
    }
    let c = coarse_pass(store, fine, plan, params, dirs, ctx)?;
    let field = c
        .field
        .dense_values()
        .ok_or_else(|| Error::Internal("the coarse pass gave a level's field".into()))?;
    write_coarse(
        &path,
        &CoarseCheckpoint {
            iterations: c.iterations,
            point_weight: c.point_weight,
            noise: c.noise,
            field: field.into(),
            density: c.density.counts().into(),
            support: c.support.bits().into(),
            occupied: c.occupied.iter().copied().collect(),
        },
    )?;
    Ok(c)
}

/// Bytes a leaf of `plan` reads of one level above it ([`CoarseField::local`]): the details
/// of the (at most 8) leaves of that level near it, and their blend on a window of
/// `(E/r + 4)³` nodes (8 bytes a node for the sum, 4 for the values).
fn window_bytes(plan: &Plan) -> u64 {
    let m = plan.detail_n() as u64;
    let w = plan.leaf_voxels / plan.coarse_ratio + 4;
    8 * 2 * m * m * m + 12 * w * w * w
}

/// What the leaf pass leaves: every occupied leaf, the refined ones, how many were reused, the
/// iso-value and the blend's fixed-point unit.
struct LeafPass {
    all: Vec<CellKey>,
    refined: BTreeSet<CellKey>,
    reused: usize,
    iso: f64,
    unit: f32,
    solved: usize,
    iterations: u64,
    /// What the leaves read.
    read: SampleReads,
}

/// The samples a leaf pass's solved leaves read, each as often as a leaf's box holds it.
#[derive(Default)]
struct SampleReads {
    /// Samples, one by one and summed alike.
    points: u64,
    /// Of which summed per voxel.
    summed: u64,
    /// The voxel sums holding those.
    sums: u64,
}

impl SampleReads {
    /// Count a leaf's gathered samples.
    fn add(&mut self, p: &LeafPoints) {
        let summed: u64 = p.voxels.iter().map(|v| v.count as u64).sum();
        self.points += p.pos.len() as u64 + summed;
        self.summed += summed;
        self.sums += p.voxels.len() as u64;
    }
}

/// Pass 2: the occupied leaves of the coarse pass (taken from it), in Morton order, solved
/// in parallel waves, spilled to the work directory. Leaves checkpointed already (by a
/// resumed run, or by another shard) are summed from their checkpoints' headers. A shard
/// visits the leaves in its order ([`Shard::order`]); the iso-value is summed in Morton order
/// whoever solved each leaf.
#[allow(clippy::too_many_arguments)]
fn leaf_pass(
    store: &Store,
    plan: &Plan,
    params: &ReconParams,
    leaves: BTreeSet<CellKey>,
    coarse: &CoarseField,
    unit: f32,
    dirs: &WorkDir,
    src: &mut PointSource,
    stage_name: &str,
    ctx: &Ctx,
) -> Result<LeafPass> {
    let leaves: Vec<CellKey> = leaves.into_iter().collect();
    // A solve, and the window of the levels above it reads: each level's details near it.
    let fine_bytes = plan.leaf_scratch_bytes() + coarse.levels() as u64 * window_bytes(plan);
    let stage = ctx
        .progress
        .stage(stage_name, Some(leaves.len() as u64), "leaves");
    let (mut solved, mut iterations) = (0, 0u64);
    let mut read = SampleReads::default();
    let rule = LeafRule {
        tolerance: params.solve.error * store.manifest.bounds.diagonal(),
        min_points: params.solve.least_leaf_points(plan.leaf_voxels),
    };
    let solvers = LeafSolvers::new(plan).with_gpu(params.run.gpu_solve)?;
    let reuse = params.run.reuses_checkpoints();
    let claims = Claims::new(&dirs.claims);
    let order = params.run.shard.order(leaves.len());
    let mut outcomes: Vec<Option<LeafOutcome>> = vec![None; leaves.len()];
    // With the fine solves on a GPU a worker waits for its leaf's batch (a third of its time
    // on an H100 with 16 cores): twice the workers keep the cores busy meanwhile, and more
    // leaves wait at once, so the device's batches grow. The budget still bounds the
    // solves at once.
    let gpu_pool = match solvers.gpu_stats() {
        Some(_) => Some(crate::exec::pool(2 * ctx.threads())?),
        None => None,
    };
    let pool = gpu_pool.as_ref().unwrap_or(&ctx.pool);
    let workers = pool.current_num_threads();
    let wave = 2 * workers;
    let solver = WaveSolver {
        plan,
        unit,
        solvers: &solvers,
        coarse,
        rule: &rule,
        dirs,
        stage: &stage,
        pool,
        fine_bytes,
    };
    // Room for a whole wave of solves and its points (as much as twice the plan's cache).
    let reads = src.begin_pass(workers as u64 * fine_bytes, ctx);
    for &claiming in params.run.shard.passes() {
        let mut next = 0;
        loop {
            let pick = WavePick {
                order: &order,
                leaves: &leaves,
                outcomes: &outcomes,
                reuse,
                claims: claiming.then_some(&claims),
                dirs,
            };
            let wave_idx = pick.next(&mut next, wave)?;
            if wave_idx.is_empty() {
                break;
            }
            let keys: Vec<CellKey> = wave_idx.iter().map(|&i| leaves[i]).collect();
            let gathered = src.gather_wave(&ctx.pool, &keys)?;
            let mut todo = Vec::with_capacity(wave_idx.len());
            for (&i, p) in wave_idx.iter().zip(gathered) {
                read.add(&p);
                todo.push((leaves[i], p));
            }
            let res = solver.solve_wave(&todo, ctx)?;
            for (r, &i) in res.into_iter().zip(&wave_idx) {
                let d = r?;
                iterations += d.iterations as u64;
                solved += d.detail.is_some() as usize;
                outcomes[i] = Some((d.iso_sum, d.iso_count, d.detail.is_some()));
            }
        }
    }
    let reused = read_unvisited(&leaves, &mut outcomes, dirs, ctx)?;
    stage.inc(reused as u64);
    let (iso_sum, iso_count, refined) = sum_outcomes(outcomes, &leaves)?;
    log_gpu_solves(&solvers);
    src.end_pass(reads, stage_name);
    stage.finish(None);
    let iso = if iso_count > 0 {
        iso_sum / iso_count as f64
    } else {
        0.0
    };
    if !iso.is_finite() {
        return Err(Error::input(
            &store.dir,
            format!(
                "no surface: the field's iso-value (its mean at the input points) is {iso}; the solve gave no usable field for these points"
            ),
        ));
    }
    Ok(LeafPass {
        all: leaves,
        refined,
        reused,
        iso,
        unit,
        solved,
        iterations,
        read,
    })
}

/// What a leaf's solve left for the pass's sums: its iso-value sum and count, and whether it
/// was refined.
type LeafOutcome = (f64, u64, bool);

/// The choice of a wave's leaves: in the shard's order, those without an outcome, no
/// checkpoint to reuse and (when claiming) a claim taken.
struct WavePick<'a> {
    order: &'a [usize],
    leaves: &'a [CellKey],
    outcomes: &'a [Option<LeafOutcome>],
    reuse: bool,
    claims: Option<&'a Claims>,
    dirs: &'a WorkDir,
}

impl WavePick<'_> {
    /// Up to `wave` leaves from `next` on (advanced past those looked at).
    fn next(&self, next: &mut usize, wave: usize) -> Result<Vec<usize>> {
        let mut wave_idx = Vec::with_capacity(wave);
        while *next < self.order.len() && wave_idx.len() < wave {
            let (i, k) = (self.order[*next], self.leaves[self.order[*next]]);
            *next += 1;
            if self.outcomes[i].is_some()
                || (self.reuse && leaf_path(&self.dirs.leaves, k).exists())
            {
                continue;
            }
            if let Some(claims) = self.claims
                && !claims.take(&format!("L{}", k.file_name()))?
            {
                continue;
            }
            wave_idx.push(i);
        }
        Ok(wave_idx)
    }
}

/// What every solve of the leaf pass shares.
struct WaveSolver<'a> {
    plan: &'a Plan,
    unit: f32,
    solvers: &'a LeafSolvers,
    coarse: &'a CoarseField,
    rule: &'a LeafRule,
    dirs: &'a WorkDir,
    stage: &'a Stage,
    pool: &'a rayon::ThreadPool,
    /// A solve's scratch and the window of the levels above it.
    fine_bytes: u64,
}

impl WaveSolver<'_> {
    /// Solve and checkpoint a wave's leaves in parallel, in groups that fit the budget: at
    /// most one solve a worker, and no more at once than fit in what is free (at least one).
    fn solve_wave(
        &self,
        todo: &[(CellKey, LeafPoints)],
        ctx: &Ctx,
    ) -> Result<Vec<Result<LeafDetail>>> {
        let (fine_bytes, workers) = (self.fine_bytes, self.pool.current_num_threads());
        let pts_bytes: u64 = todo.iter().map(|(_, p)| p.bytes()).sum();
        let free = ctx.budget.total().saturating_sub(ctx.budget.used());
        let at_once =
            (free.saturating_sub(pts_bytes) / fine_bytes.max(1)).clamp(1, workers as u64) as usize;
        let bytes = fine_bytes * todo.len().min(at_once) as u64 + pts_bytes;
        // Over the whole budget it is an error that names the sizes; otherwise it is
        // admitted without waiting on the permits this thread holds.
        let _permit = if bytes > ctx.budget.total() {
            Some(ctx.budget.acquire(bytes, "a wave of leaf solves")?)
        } else {
            tiles::admit_now(ctx, bytes)
        };
        let group = if at_once < workers {
            at_once
        } else {
            todo.len().max(1)
        };
        let mut res: Vec<Result<LeafDetail>> = Vec::with_capacity(todo.len());
        for g in todo.chunks(group) {
            res.extend(self.pool.install(|| {
                g.par_iter()
                    .map(|(k, p)| {
                        let d = refine_leaf(
                            self.plan,
                            self.unit,
                            self.solvers,
                            *k,
                            p,
                            self.coarse,
                            self.rule,
                        )?;
                        write_leaf(&self.dirs.leaves, *k, &d)?;
                        self.stage.inc(1);
                        Ok(d)
                    })
                    .collect::<Vec<_>>()
            }));
        }
        Ok(res)
    }
}

/// The leaves solved before (a resumed run) or by other shards: their outcomes from their
/// checkpoints' headers. Returns how many.
fn read_unvisited(
    leaves: &[CellKey],
    outcomes: &mut [Option<LeafOutcome>],
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<usize> {
    let rest: Vec<usize> = (0..leaves.len())
        .filter(|&i| outcomes[i].is_none())
        .collect();
    let sums: Vec<Result<LeafSummary>> = ctx.pool.install(|| {
        rest.par_iter()
            .map(|&i| read_leaf_summary(&dirs.leaves, leaves[i]))
            .collect()
    });
    for (&i, r) in rest.iter().zip(sums) {
        let d = r?;
        outcomes[i] = Some((d.iso_sum, d.iso_count, d.has_detail));
    }
    Ok(rest.len())
}

/// The iso-value's sum and count and the refined leaves, in Morton order, as one process sums
/// them: the same iso-value for any shard count.
fn sum_outcomes(
    outcomes: Vec<Option<LeafOutcome>>,
    leaves: &[CellKey],
) -> Result<(f64, u64, BTreeSet<CellKey>)> {
    let (mut iso_sum, mut iso_count) = (0.0, 0u64);
    let mut refined = BTreeSet::new();
    for (o, k) in outcomes.into_iter().zip(leaves) {
        let (s, c, is_refined) =
            o.ok_or_else(|| Error::Internal(format!("leaf {k:?} was not visited")))?;
        iso_sum += s;
        iso_count += c;
        if is_refined {
            refined.insert(*k);
        }
    }
    Ok((iso_sum, iso_count, refined))
}

/// The GPU leaf solves' figures, in the log, when the device solved them.
fn log_gpu_solves(solvers: &LeafSolvers) {
    if let Some((name, g)) = solvers.gpu_stats() {
        log::info!(
            "GPU leaf solves on {name}: {} leaves in {} batches ({:.1} a batch, {} submissions), device thread busy {:.2} s (upload {:.2} s, kernels and flag reads {:.2} s, read-back {:.2} s), idle {:.2} s; workers: host side {:.2} s, waiting {:.2} s{}",
            g.leaves,
            g.batches,
            g.leaves as f64 / g.batches.max(1) as f64,
            g.submissions,
            g.busy_s,
            g.upload_s,
            g.kernel_s,
            g.read_s,
            g.idle_s,
            g.host_s,
            g.wait_s,
            if g.failed > 0 {
                format!(
                    ", {} leaves solved on the CPU after a GPU failure",
                    g.failed
                )
            } else {
                String::new()
            }
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Cube;

    /// The trim support is the finest level's coarse grid where its bits fit a 32nd of the
    /// budget, halved where they do not, and never coarser than the dense solve's grid.
    #[test]
    fn the_trim_support_is_the_finest_coarse_grid_the_budget_allows() {
        let cube = Cube {
            origin: [0.0; 3],
            size: 2.0,
        };
        let g = 1u64 << 30;
        for (depth, mem, cells) in [
            (10, 64 << 20, 256),
            (11, 4 * g, 512),
            (12, 4 * g, 1024),
            (13, 4 * g, 1024),
            (13, 16 * g, 1024),
            (13, 32 * g, 2048),
            (13, 64 << 20, 256),
        ] {
            let levels =
                crate::recon::plan::levels(cube, depth, 1.0, 4.0, None, None, plan_budget(mem))
                    .unwrap();
            let (fine, top) = (&levels[0], levels.last().unwrap());
            let (h, n) = support_grid(fine, top, mem);
            assert_eq!(
                n,
                cells.max(top.coarse_cells()),
                "depth {depth}, --mem {mem}"
            );
            assert_eq!(h * n as f64, cube.size);
            assert!(Support::bytes(n) <= mem / SUPPORT_BUDGET_DIVISOR || n == top.coarse_cells());
        }
    }

    /// At the least budget of every depth the levels' top coarse solve and leaf pass fit
    /// their slices, and it is never below the floor.
    #[test]
    fn the_least_budget_plans_every_depth() {
        let cube = Cube {
            origin: [0.0; 3],
            size: 1.0,
        };
        for depth in 7..=13 {
            for screened in [false, true] {
                let least = least_mem(depth, screened);
                assert!(least >= MEM_FLOOR);
                let b = plan_budget(least);
                let alpha = if screened { 4.0 } else { 0.0 };
                let levels =
                    crate::recon::plan::levels(cube, depth, 1.0, alpha, None, None, b).unwrap();
                let top = levels.last().unwrap();
                let need = Plan::needs(top.depth, top.coarse_ratio, screened);
                assert!(
                    need.coarse <= b.coarse && need.leaf <= b.leaf,
                    "depth {depth}: {levels:?}"
                );
                assert_eq!(
                    top.coarse_field_bytes() + top.density_bytes() + top.leaf_scratch_bytes(),
                    need.leaf
                );
            }
        }
    }
}
