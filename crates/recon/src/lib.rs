//! Adaptive FFT surface reconstruction (ARCHITECTURE.md step 3): a coarse global solve and
//! per-leaf fine solves, blended into the field the tiles extract (steps 4 and 5).
//!
//! Sources: Kazhdan, "Reconstruction of solid models from oriented point sets" (2005) for the
//! FFT Poisson solve ([`fft_solve`]); Schall, Belyaev, Seidel, "Adaptive Fourier-based surface
//! reconstruction" (2006) for local solves on octree cells blended by a partition of unity
//! ([`pou`]). Measured before this code (a prototype on synthetic shapes with exact
//! samples, 4³ cells of E = 64 voxels against one global 256³ solve): the paper's plain
//! per-leaf blend loses about 8× accuracy (sphere mean error 0.051 voxel against 0.0065), and
//! also leaves spurious closing surfaces in empty cells and open holes larger than a leaf.
//! The **two-level scheme** below reproduced the global solve in every case (sphere 0.0065,
//! shell, near spheres) for r = 4 and 8, and closes holes as the global solve does; r = 16
//! with E = 64 doubled the error, hence **the coarse voxel is kept at or below `E/8`**. The
//! test `two_level_matches_one_global_solve` keeps checking it against [`global`]:
//!
//! 0. Every sample's **share of the surface**, from the sampling density on a grid at the
//!    coarse spacing ([`density`]; Kazhdan, Bolitho, Hoppe 2006 §4.3): its normal is scaled
//!    by it in every solve below, so that a part sampled 16 times more sparsely than the rest
//!    makes the field jump as much and sits at the same iso-value.
//! 1. A **coarse global solve** on the cube's `(N/r)³` coarse voxels (a Gaussian of σ coarse
//!    voxels, [`weight::Smoothing`]: every grid's own σ, at least 0.4 of the samples'
//!    spacing on it where they are sparse against it, [`weight::sparse_floor_voxels`]),
//!    padded on each side so that the periodic solve never wraps the surface: 4 coarse
//!    voxels, plus what rounding the grid up to a 5-smooth size for the FFT adds (so 4 to 56
//!    coarse voxels at the supported depths, [`Plan::coarse_pad`]). Coarse node `J`
//!    coincides with fine node `rJ`; it is upsampled trilinearly ([`coarse`]).
//! 2. Each **leaf** (an occupied octree cell of `E = 8r` fine voxels, so the coarse voxel is
//!    `E/8`) solves its points — those of the cell scaled by 1.3125 about its centre — on a
//!    periodic fine grid of `(1.5E)³` nodes (the cell padded by `E/4` beyond each face; the
//!    prototype padded by `E/2`, as Kazhdan and Hoppe's leaves are, and measured the same
//!    accuracy at half the padding, [`plan`]), and on the coarse grid of the same domain,
//!    aligned to the global coarse grid ([`leaf`]). Its **detail** is the difference, kept
//!    on the cell plus an overlap of `E/8` voxels.
//!    The coarse local solve takes the width the coarse field was solved with (in coarse
//!    voxels), the fine one its level's own.
//!    Details are spilled to the work directory (zstd, [`checkpoint`]) and are the
//!    checkpoint a resumed run reuses. A leaf whose samples lie within `--error` of the
//!    coarse surface, or with fewer than `--min-points` samples, keeps no detail
//!    ([`refine_leaf`]).
//! 3. The field at a fine node is the upsampled coarse solution plus the details blended by
//!    partition of unity ([`pou`], [`blend`]). Regions no leaf covers (holes, the unseen
//!    bottom of a scan) take the coarse solution, which closes them. The blend is exact
//!    fixed-point arithmetic ([`crate::extract::field`]), done on the CPU or, with `--gpu`,
//!    on the device from the leaf grids; both give the same bits.
//! 4. The iso-value is the mean of the field at the input samples (each leaf sums its own
//!    cell's samples). With outward normals the field is lower inside.
//!
//! **Levels** ([`plan::levels`]). The coarse grid grows as `N/r`: at depth 11 with `r = 4` it
//! is 520³ nodes, at 13 over 2000³. Rather than growing `r` (and the leaves with it, `E =
//! 8r`), the scheme recurses: the coarse field of the leaves at depth `D` is the field of
//! the two-level scheme at depth `D − 2` (its fine spacing is their coarse spacing), whose
//! own coarse field may again be a level, down to a dense solve of at most 256 cells an
//! edge. Each level's leaves are solved top down by the same code (step 2 at the level's
//! depth), and its detail is its fine minus its coarse local solve, so the sum of the dense
//! solve and every level's blended details telescopes to the finest local solves, as the
//! two-level sum does. A level is read by the one below as windows: the values on a small
//! block of its nodes, blended exactly in the run's fixed point from its coarse field and
//! the checkpoints of its leaves near the block ([`coarse::Level`]); those values are the
//! coarse nodes of the block below (step 3's trilinear upsampling is unchanged). Every grid
//! is then at most 264³ (the dense solve) or 48³ (a leaf solve), and leaf cost stays flat per
//! unit of surface. The leaves of a level above the finest read their store cells summed per
//! voxel of their lattice where the cells hold at least 5 points a voxel ([`voxel_sum`]:
//! the splat and the screening are sums of functions multilinear in a voxel, so 8 summed
//! normals, a count and an offset sum give both, on the fine and on the coarse local grid),
//! instead of every point 3.3 times over. The sampling density (step 0) and `--trim`'s
//! support are taken at the dense solve's spacing. The test `levels_of_leaves_match_one_global_solve_and_keep_the_contracts`
//! holds a level of leaves to the global solve as the two-level oracle does.
//!
//! Every solve of the scheme, the coarse global one and both of each leaf, is **screened**
//! (Kazhdan & Hoppe 2013, [`screen`]) with the weight `--point-weight` relative to its own
//! grid (by default and under `auto`, one weight per run chosen from the samples' measured
//! noise by the coarse pass, [`weight::PointWeight`]): the samples aggregated per voxel of that grid
//! pull the field to one value, which restores the short wavelengths the Gaussian and the
//! splat attenuate (about `exp(−2π²σ²/λ²)` for a wavelength of `λ` voxels). The coarse
//! global solve aggregates the samples as the splat pass streams them, one entry per
//! occupied coarse voxel; a leaf aggregates its own points on each of its two grids. The
//! detail is still the fine minus the coarse local solution, both screened, so the blend
//! keeps matching one global solve screened the same way (the test
//! `two_level_matches_one_global_solve` checks both).
//!
//! **Grid conventions** (written once, here; [`plan`]). The cube is the store's root cube (the
//! bounding box enlarged 10%, PoissonRecon's `--scale 1.1`). Depth `D` gives `N = 2^D` cells
//! per edge and spacing `h = size/N`; fine node `g = (i, j, k)`, `0 <= g <= N`, sits at
//! `origin + h·g`. Every local grid's origin is a global node, so blending never resamples.
//! Tiles are octree cells of `T` fine voxels (a multiple of `E`) visited in Morton order;
//! marching cubes runs on each tile's `(T+1)³` nodes, a vertex is keyed by the global grid
//! edge it lies on, and tiles share the vertices of their common faces through the welder's
//! frontier.
//!
//! The stage's functions take the points they solve as slices ([`LeafPoints`]); reading the
//! store, the waves and the work directory belong to the pipeline
//! (`scanflow::pipeline::reconstruct`).
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, exec, fs, geom, types};

pub mod blend;
pub mod checkpoint;
pub mod coarse;
pub mod density;
pub mod extract;
pub mod fft_solve;
pub mod global;
pub mod gpu_solve;
pub mod grid;
pub mod leaf;
pub mod noise;
pub mod plan;
pub mod pou;
pub mod screen;
pub mod surface;
pub mod voxel_sum;
pub mod weight;

pub use blend::leaves_near;
pub use coarse::{CoarseField, CoarseGrid, Level, Moments};
pub use coarse::{blend_block, tile_blend};
pub use global::{GlobalField, global_field};
pub use leaf::{LeafDetail, LeafPoints, LeafSolvers, coarse_error, coarse_only, solve_leaf};
pub use plan::{DEFAULT_ERROR, DEFAULT_MIN_POINTS, DEPTHS, Plan, PlanBudget};
pub use weight::{PointWeight, Smoothing};

use crate::types::CellKey;

/// When a leaf is refined by a fine solve.
#[derive(Debug, Clone, Copy)]
pub struct LeafRule {
    /// Mean distance of the cell's samples to the coarse surface above which the leaf is
    /// refined, in input units (`--error` times the bounding-box diagonal).
    pub tolerance: f64,
    /// Fewest samples in the cell for the leaf to be refined.
    pub min_points: u64,
}

/// Solve leaf `key` on its points `pts` when `rule` asks for it (enough samples, and the
/// coarse solution's surface farther than the tolerance from them, [`coarse_error`]);
/// otherwise leave it to the coarse solution. The coarse values around the cell are read
/// first ([`CoarseField::local`]: in the recursive scheme, a blend of the level above, which
/// fails only on that level's checkpoints).
pub fn refine_leaf(
    plan: &Plan,
    unit: f32,
    solvers: &LeafSolvers,
    key: CellKey,
    pts: &LeafPoints,
    coarse: &CoarseField,
    rule: &LeafRule,
) -> crate::error::Result<LeafDetail> {
    let lo = plan.leaf_node(key);
    let hi = lo.map(|v| v + plan.leaf_voxels as i64);
    let coarse = coarse.local(lo, hi)?;
    let refine = pts.own_count() >= rule.min_points && coarse_error(&coarse, pts) > rule.tolerance;
    Ok(if refine {
        solve_leaf(plan, unit, solvers, key, pts, &coarse)
    } else {
        coarse_only(pts, &coarse)
    })
}

/// Step 1's solve: the coarse global solution from the normals splatted on `plan`'s coarse
/// grid ([`fft_solve::splat`]), smoothed by `plan.sigma_vox` coarse voxels and screened by
/// `screen` (the samples aggregated on the coarse grid, [`screen::ScreenBuilder`]).
pub fn solve_coarse(
    plan: &Plan,
    splatted: Vec<[f32; 3]>,
    screen: &screen::Screen,
) -> (CoarseField, fft_solve::Convergence) {
    let grid = plan.coarse_grid();
    let (values, conv) =
        fft_solve::Solver::new(&grid, plan.sigma_vox).solve_screened(&grid, splatted, screen);
    (CoarseField::new(plan, values), conv)
}
