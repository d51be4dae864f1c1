//! The screening term of the screened Poisson equation (Kazhdan & Hoppe, "Screened Poisson
//! surface reconstruction", 2013, §4): the samples, aggregated per voxel of the grid being
//! solved, as the point-evaluation operator `S` and its weights `γ`.
//!
//! The unscreened solve minimises `∫|∇χ − V|²`, which fixes χ only up to its gradient: the
//! Gaussian that smooths `V` and the trilinear splat both attenuate short wavelengths of the
//! surface, and nothing pulls the level set back to the samples. The screened energy adds
//! the values at the samples,
//!
//! ```text
//!     E(χ) = ∫|∇χ − V|² + Σ_a γ_a (χ(p_a) − c)²,
//! ```
//!
//! whose normal equations on the grid are `(L + Sᵀ Γ S) χ = b + Sᵀ Γ c`, with `L = −Δ` (the
//! spectral Laplacian of [`super::fft_solve`]), `b = −∇·V` and `S` trilinear interpolation
//! at the samples. `c` is the value the samples are pulled to; any constant gives the same
//! level set, and the solver takes the mean of the unscreened field at the samples so that
//! screening moves the surface, not the gauge.
//!
//! **Aggregates.** As PoissonRecon does at its coarser depths, the samples in one voxel are
//! replaced by one at their mean position, weighted by their count `w_a`: the operator then
//! has at most one row per occupied voxel whatever the number of points, which bounds the
//! memory of the coarse global solve by its grid, not by the scan.
//!
//! **Weights.** `γ_a = α · w_a / w̄ / h²`, with `w̄` the mean count per occupied voxel and
//! `h` the grid's spacing in cube units: the paper normalises its sum by the samples'
//! density (`Area(P)/Σ w`), and here every occupied voxel holds on average `α/h²`, the
//! same share of the Laplacian's diagonal (`6/h²`) at every depth and for any sampling
//! density. A surface undulation of `λ` voxels along the surface is then held to the samples
//! where `α λ / 2π` is large against 1: with α = 4 every wavelength the grid resolves
//! (PoissonRecon's default `--pointWeight 4` scales with the depth in the same way).
//!
//! **The weight follows the noise.** Screening pulls the surface through the samples, which
//! is what precise scans want and what noisy ones must not get. Two measured regimes:
//!
//! - *Noise across the surface of a voxel or more* breaks the default α = 4. The samples
//!   then occupy a shell several voxels thick, every occupied voxel pulls χ to `c`, and the
//!   sparse voxels at the shell's fringe (a sample or two, two or three σ out) become small
//!   closed surfaces of their own. On a 2.5M-point sphere at depth 9 (mean two-sided
//!   distance to the exact sphere; pieces of the mesh):
//!
//!   | noise σ (voxels) | α = 0 | α = 1 | α = 2 | α = 4 |
//!   |---|---|---|---|---|
//!   | 0.8 | 1.8·10⁻⁴, 1 | 3.3·10⁻⁴, 1 | 4.2·10⁻⁴, 1 | 5.6·10⁻⁴, 1 |
//!   | 1.0 | 2.1·10⁻⁴, 1 | 3.9·10⁻⁴, 1 | 5.2·10⁻⁴, 1 | 6.9·10⁻⁴, 2 |
//!   | 1.2 | 2.4·10⁻⁴, 1 | 4.9·10⁻⁴, 1 | 7.2·10⁻⁴, 1 | 9.3·10⁻⁴, 5 |
//!   | 1.6 | 3.0·10⁻⁴, 1 | 6.5·10⁻⁴, 1 | 9.6·10⁻⁴, 1 | 1.7·10⁻³, 151 |
//!   | 2.4 | | | | 3.6·10⁻³, 1319 |
//!
//!   (PoissonRecon, screened with 4, at σ = 1.6: 1.0·10⁻³ in 2 pieces.) So the weight is
//!   kept up to [`NOISE_LIMIT_VOXELS`] and falls as the precision `1/σ²` beyond:
//!   `α = 4 · min(1, (σ_lim/σ)²)`, with σ the noise read between close samples
//!   ([`NoiseStats::noise_voxels`], below), which reads noise beyond a voxel. With this
//!   limit alone every sphere above is one piece (σ = 1.0: α = 3.1, 6.1·10⁻⁴; 1.2: 2.0,
//!   7.3·10⁻⁴; 1.6: 1.2, 7.0·10⁻⁴; 2.4: 0.66, 8.4·10⁻⁴); the default
//!   (`--point-weight standard`) also takes the next rule, which solves these plain spheres
//!   unscreened (σ = 1.6: one piece, 2.6·10⁻⁴).
//! - *Noise that outweighs the relief* takes the weight down further, to the relief's share.
//!   Screening pulls the surface through the samples' noise as much as through their relief,
//!   and where the quadrics read no more than the noise (a plain noisy surface, or relief
//!   of long wavelength) the smoothed normals miss nothing that the pull could restore: it
//!   only prints the noise. So `α` is multiplied by `1 − w·s` ([`relief_weight`]), with
//!   `s = σ_pair²/σ_jet²` the noise's share of the quadrics' residual ([`NoiseStats::noise_share`],
//!   below) and `w` rising from 0 at the noise where the vertex fit stops
//!   ([`crate::surface::fit::FIT_NOISE_LIMIT_VOXELS`], 0.35 voxel) to 1 at
//!   [`NOISE_DOMINANT_VOXELS`]. On 1M-point spheres at depth 9 with noise of 0.8 voxel
//!   (mean two-sided distance to the exact surface ·10⁻⁴; fixed α, then the rule's α and
//!   its result; PoissonRecon):
//!
//!   | relief (amplitude, wavelength) | `s` | α = 0 | 1 | 2 | 4 | rule | PoissonRecon |
//!   |---|---|---|---|---|---|---|---|
//!   | 1%, 8 voxels | 0.27 | 13.4 | 12.1 | 11.4 | 10.6 | 2.91: 10.9 | 11.2 |
//!   | 2%, 12 voxels | 0.18 | 11.4 | 9.42 | 8.83 | 8.97 | 3.27: 8.84 | 9.08 |
//!   | 1%, 12 voxels | 0.52 | 8.87 | 7.97 | 7.68 | 7.90 | 1.92: 7.68 | 8.00 |
//!   | 2%, 18 voxels | 0.47 | 7.18 | 6.99 | 7.17 | 7.86 | 2.10: 7.21 | 7.54 |
//!   | 0.5%, 8 voxels | 0.66 | 8.89 | 8.64 | 8.54 | 8.49 | 1.36: 8.58 | 8.72 |
//!   | 0.5%, 30 voxels | 0.99 | 2.63 | | | 5.52 | 0.02: 2.66 | 6.62 |
//!   | none | 1 | | | | 5.4 | 0: 2.28 | 6.6 |
//!
//!   Short relief keeps most of the weight, long relief and plain noise lose it all. The
//!   samples of noise under the fit's limit keep their weight (the raw bunny scans, 0.171
//!   voxel); `autzen_trim.las` (1.10 voxel, `s` 0.29) goes from 2.39 to 1.70, a smoother
//!   ground (area-weighted mean |n_z| 0.9498 against 0.9445) in 62 pieces against 47. A
//!   relief that folds within a voxel (2% amplitude at 8 voxels' wavelength) needs the
//!   pairs' cut (below): read through its folds as noise of 1.28 voxel, it lost the weight
//!   and the narrow Gaussian it needs (α = 1.34, one voxel: 2.2·10⁻³ against
//!   PoissonRecon's 1.3·10⁻³); cut, it reads 0.77 and takes α = 3.64 over 0.37 voxel,
//!   1.23·10⁻³.
//! - *Precise samples* can take more than 4: on a 1M-point sphere carrying a relief of 1%
//!   amplitude at depth 9, α = 32 brings a relief of 8 voxels' wavelength from 9.7·10⁻⁴ to
//!   5.0·10⁻⁴ (no vertex fit), while with noise of 0.23 voxel it prints the noise into the
//!   surface (6.7·10⁻⁴ at α = 4, 1.1·10⁻³ at α = 16). `--point-weight auto` raises the
//!   weight as the precision measured within fine voxels ([`NoiseStats::sigma_voxels`]: the
//!   offsets along the mean normal of the samples sharing a fine voxel, pooled over the scan
//!   with one degree of freedom lost per voxel): `α = 4 · clamp((σ_ref/σ)², 1, 8)`
//!   ([`auto_point_weight`]) up to 32, at and below [`NOISE_REFERENCE_VOXELS`], and lowers
//!   it for noise beyond a voxel as the default does. It is not the default: on real scans
//!   the spread within a voxel takes structure for precision (airborne LiDAR's vegetation
//!   returns read 0.09 voxel and took α = 20, a rougher terrain than at 4).
//!
//! **Telling relief from noise.** Three figures are measured, each blind somewhere. The
//! spread within fine voxels cannot exceed a voxel's own (`1/√12`). The residual about
//! local quadrics on discs of 1.5 voxels reads noise beyond a voxel, but also every relief
//! a quadric cannot follow: a 1% relief of 8 voxels' wavelength, noise-free, reads 0.89
//! voxel, and with noise of 0.8 voxel 1.52, which lowered its weight to 1.25 (1.37 times
//! PoissonRecon's mean distance). The third reads the noise alone: for pairs of samples
//! `i, j` on the quadrics' discs, the half squared height difference along their mean
//! normal `m = n_i + n_j`,
//!
//! ```text
//!     y_ij = ½ ((p_j − p_i)·m̂)²,   x_ij = |p_j − p_i|² − ((p_j − p_i)·m̂)²,
//! ```
//!
//! against their squared distance across it. Along the mean of two normals the height
//! difference of a smooth surface is of third order in the distance (the curvature terms
//! of the two ends cancel), and a tilt of the normals adds `|g|² x / 2` for a slope `g`:
//! so `E[y] = σ² + c x + O(x²)`, a line whose intercept, the variogram's nugget at zero
//! distance, is the noise `σ²` whatever the relief. It is fitted by least squares over the
//! pairs under [`PAIR_MAX_VOXELS`] apart, pooled over the scan ([`PairStats`]). On the
//! relief spheres of 1M points at depth 9 (voxels; within voxels, between close samples,
//! about quadrics): noise-free 8 voxels' wavelength 0.025, 0.00, 0.89; with noise of 0.8
//! voxel at 8, 12, 18, 30 voxels 0.275/0.79/1.52, 0.274/0.77/1.06, 0.274/0.79/0.83,
//! 0.274/0.81/0.81; a plain sphere with noise 0.8: 0.273/0.81/0.80, with noise 1.6:
//! 0.286/1.58/1.56. It needs normals that follow the relief (a scan's estimated ones do
//! where the relief is wider than their neighbourhood) and samples closer than
//! [`PAIR_MAX_VOXELS`]; where under [`PAIR_MIN_COUNT`] pairs are found the quadrics' figure
//! stands in.
//!
//! **Folds and volumes.** Where a relief folds within a disc (a curvature radius under a
//! voxel), the disc holds two sheets of it, and pairs of samples close across their mean
//! normal lie on different sheets, several voxels apart along it, at any distance across:
//! their height differences raise the line's intercept, not its slope. The 2% relief of 8
//! voxels' wavelength reads 0.98 voxel noise-free and 1.28 with noise of 0.8. So the line
//! is fitted to the pairs whose height difference lies within [`PAIR_TRIM_SIGMAS`] = 2.5
//! standard deviations of the spread the line itself gives at their distance,
//! `√(2(σ² + c x))`, and its intercept divided by the share of a normal variance within
//! that cut (0.911, [`trimmed_variance_share`]). The cut starts from a hundredth of a
//! voxel and widens round by round to the first spread that reads itself back
//! ([`PairStats::nugget`]): normal noise then keeps 98.8% of its pairs and reads as
//! before (a plain sphere with noise 0.8: 0.812 against 0.808 uncut; 1.6: 1.587 against
//! 1.575), the folded relief 89%, read as 0.77 voxel. A second sheet nearer than about
//! four standard deviations of the noise merges with it. Airborne LiDAR's vegetation,
//! returns scattered through the metres above the ground, is no fold: cut, a third of
//! `autzen_trim.las`'s pairs lie beyond and the ground reads 0.05 voxel, which would
//! weigh and sharpen every canopy into a surface. Where more than [`PAIR_SHEETS_SHARE`]
//! (15–25%) of the pairs lie beyond the cut, the line through all of them stands, and the
//! vegetation reads as noise (0.099 within voxels, 1.10 between close samples, 2.06 about
//! quadrics at depth 9), so its weight still falls (to 1.70, where the quadrics alone gave
//! 0.68). The raw bunny scans leave 8% beyond, their misregistered overlaps, and read
//! 0.171 voxel against 0.215 uncut. Noise-free, nearly every pair of the folded relief
//! lies beyond a cut near zero, so its uncut 0.98 stands too; its samples read precise
//! within voxels, and the rules for precise samples take no figure from the pairs.
//!
//! All are one number per run, from every point in a fixed order: the coarse and the leaf
//! solves, and any thread count, tile size or shard, share it. Where nothing could be
//! measured (sparse samples) α = 4. The Gaussian that smooths the normal field is chosen
//! the same way, one width per run from the spread within voxels and the share of the
//! quadrics' residual that is noise ([`Smoothing`]): the screening pulls the surface to the
//! samples, the Gaussian decides how much of the normals' detail there is to pull to.

use rayon::prelude::*;

use super::fft_solve::LocalGrid;
use super::voxel_sum::{OnLattice, VoxelSum, screen_voxel};
use crate::geom::{dot, plane_basis};
use crate::types::{KeyMap, floor, wrap};

/// The screening weight for samples of no known noise: PoissonRecon's default `--pointWeight`.
pub const BASE_POINT_WEIGHT: f64 = 4.0;

/// The largest factor [`auto_point_weight`] raises [`BASE_POINT_WEIGHT`] by, for precise
/// samples: α = 32 (module docs).
pub const MAX_PRECISION_GAIN: f64 = 8.0;

/// The spread across the surface, in fine voxels, at and above which `auto` keeps
/// [`BASE_POINT_WEIGHT`]; below it the weight grows as the precision `1/σ²`. Measured on
/// the relief spheres of 18 voxels' wavelength (module docs): noise of 0.1 voxel did best
/// with α = 32 (α = 4: 1.4× the mean error), 0.2 voxel with α = 8 (of 4, 8, 16, 32).
pub const NOISE_REFERENCE_VOXELS: f64 = 0.2;

/// The noise across the surface ([`NoiseStats::noise_voxels`]), in fine voxels, beyond
/// which the weight falls as `1/σ²` (module docs): the relief spheres with noise of 0.8
/// voxel read 0.77–0.81 between close samples and keep α = 4; the plain sphere with noise
/// of 1.0 voxel breaks into two pieces at α = 4 and takes 3 or less.
pub const NOISE_LIMIT_VOXELS: f64 = 0.85;

/// The spread within fine voxels under which the samples are taken as precise whatever the
/// quadrics read ([`noise_limit`]): noise beyond [`NOISE_LIMIT_VOXELS`] reads 0.27 voxel
/// within voxels (the voxel's own spread nearly), so a residual beyond the limit about
/// quadrics is then relief they cannot follow (the precise relief of 8 voxels' wavelength
/// reads 0.025 within voxels and 0.89 about quadrics, and lost a tenth of its weight to
/// it). Noise-free samples read 0.006–0.03. Not higher: airborne LiDAR's vegetation returns
/// read 0.099 within voxels and 2.06 about quadrics, and taken as precise they give a
/// rougher ground (`autzen_trim.las` at depth 9: area-weighted mean |n_z| 0.923 against
/// 0.949, 86 pieces against 61).
pub const PRECISE_WITHIN_VOXELS: f64 = 0.05;

/// The weight the default takes for precise samples (under [`PRECISE_WITHIN_VOXELS`] within
/// fine voxels): twice the base, where `auto` goes to 32. Measured on the precise relief
/// spheres (1M points, depth 9, 1% amplitude, the measured smoothing of 0.35 voxel; mean
/// distance ·10⁻⁴, α = 4 → 8, PoissonRecon in brackets): 8 voxels' wavelength 5.84 → 5.40
/// (5.70), 12 voxels 2.44 → 2.28 (2.83), 18 voxels 0.98 → 0.95 (1.30), 30 voxels 0.29 →
/// 0.28 (0.48), for 5.3 conjugate-gradient steps a leaf against 4.9.
pub const PRECISE_POINT_WEIGHT: f64 = 8.0;

/// The factor noise `sigma` ([`NoiseStats::noise_voxels`]) beyond [`NOISE_LIMIT_VOXELS`]
/// lowers the weight by: `min(1, (σ_lim/σ)²)`; 1 where the noise was not measured, or where
/// the spread `within` fine voxels is under [`PRECISE_WITHIN_VOXELS`].
pub fn noise_limit(within: Option<f64>, sigma: Option<f64>) -> f64 {
    match sigma {
        Some(s) if s > NOISE_LIMIT_VOXELS && !precise(within) => (NOISE_LIMIT_VOXELS / s).powi(2),
        _ => 1.0,
    }
}

/// The noise across the surface ([`NoiseStats::noise_voxels`]), in fine voxels, from which
/// [`relief_weight`] takes the screening weight down to the relief's share in full; it
/// begins at [`crate::surface::fit::FIT_NOISE_LIMIT_VOXELS`], the noise at which the vertex
/// fit stops. Measured (module docs): with 0.85, the plain sphere with noise of 0.8 voxel
/// (α = 0.33) came out at 2.8·10⁻⁴ against 2.3 (α = 0), the relief of 30 voxels'
/// wavelength at 0.5% amplitude at 3.2·10⁻⁴ against 2.7.
pub const NOISE_DOMINANT_VOXELS: f64 = 0.75;

/// The factor by which noise that outweighs the relief lowers the screening weight (module
/// docs): `1 − w·s`, with `s` the noise's share of the quadrics' residual
/// ([`NoiseStats::noise_share`]) and `w` rising linearly from 0 at
/// [`crate::surface::fit::FIT_NOISE_LIMIT_VOXELS`] of noise ([`NoiseStats::noise_voxels`]) to
/// 1 at [`NOISE_DOMINANT_VOXELS`]; 1 where either figure is unmeasured.
pub fn relief_weight(noise: &NoiseStats) -> f64 {
    let (Some(sigma), Some(share)) = (noise.noise_voxels(), noise.noise_share()) else {
        return 1.0;
    };
    let from = crate::surface::fit::FIT_NOISE_LIMIT_VOXELS;
    let w = ((sigma - from) / (NOISE_DOMINANT_VOXELS - from)).clamp(0.0, 1.0);
    1.0 - w * share
}

/// Whether samples whose spread `within` fine voxels was measured are precise (under
/// [`PRECISE_WITHIN_VOXELS`]).
fn precise(within: Option<f64>) -> bool {
    within.is_some_and(|w| w < PRECISE_WITHIN_VOXELS)
}

/// The screening weight `auto` takes for a spread `sigma` of the samples within fine voxels
/// (`None`: not measurable), before [`noise_limit`]: `4 · clamp((σ_ref/σ)², 1, 8)`.
pub fn auto_point_weight(sigma: Option<f64>) -> f64 {
    let gain = match sigma {
        Some(s) if s > 0.0 => (NOISE_REFERENCE_VOXELS / s).powi(2),
        Some(_) => MAX_PRECISION_GAIN,
        None => 1.0,
    };
    BASE_POINT_WEIGHT * gain.clamp(1.0, MAX_PRECISION_GAIN)
}

/// `--point-weight`: the default (4, lowered for noise beyond a voxel), `auto` (also raised
/// for precise samples), or a fixed α.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PointWeight {
    /// [`BASE_POINT_WEIGHT`] times [`noise_limit`] and [`relief_weight`];
    /// [`PRECISE_POINT_WEIGHT`] for precise
    /// samples (under [`PRECISE_WITHIN_VOXELS`] within fine voxels).
    Standard,
    /// [`auto_point_weight`] times [`noise_limit`] and [`relief_weight`].
    Auto,
    /// The given α (0: the unscreened solve), whatever the noise.
    Fixed(f64),
}

impl PointWeight {
    /// The α to solve with, for samples of the measured `noise`
    /// ([`NoiseStats::default`] where nothing is measured yet).
    pub fn alpha(self, noise: &NoiseStats) -> f64 {
        match self {
            PointWeight::Standard => {
                let within = noise.sigma_voxels();
                if precise(within) {
                    PRECISE_POINT_WEIGHT
                } else {
                    BASE_POINT_WEIGHT
                        * noise_limit(within, noise.noise_voxels())
                        * relief_weight(noise)
                }
            }
            PointWeight::Auto => {
                auto_point_weight(noise.sigma_voxels())
                    * noise_limit(noise.sigma_voxels(), noise.noise_voxels())
                    * relief_weight(noise)
            }
            PointWeight::Fixed(a) => a,
        }
    }
}

impl std::fmt::Display for PointWeight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PointWeight::Standard => f.write_str("standard"),
            PointWeight::Auto => f.write_str("auto"),
            PointWeight::Fixed(a) => write!(f, "{a}"),
        }
    }
}

/// The Gaussian's width for samples of unknown or coarse noise, in voxels of each grid:
/// Kazhdan's (2005) one voxel, the width the noisy relief spheres and the plain noisy sphere
/// still want (module docs of [`Smoothing`]).
pub const SMOOTH_NOISY_VOXELS: f64 = 1.0;

/// The narrowest Gaussian the measured smoothing takes, for precise samples: about where the
/// trilinear splat's own spread (a tent, variance 1/6 voxel² per axis) takes over. On the
/// precise relief sphere of 8 voxels' wavelength (α = 4), 0.5 voxel left a mean distance of
/// 6.1·10⁻⁴, 0.35 5.8, 0.25 5.7, 0.2 5.7 (PoissonRecon 5.7).
pub const SMOOTH_PRECISE_VOXELS: f64 = 0.35;

/// `--smooth`: the Gaussian's width measured from the samples' precision (the default), or
/// a fixed width in voxels.
///
/// The Gaussian of width σ on the normal field attenuates a surface wave of `λ` voxels by
/// `exp(−2π²σ²/λ²)` and averages the samples' noise over an area growing as σ². Precise
/// samples need no averaging, and one voxel flattens fine relief; noisy ones need it.
/// Measured on 1M-point spheres at depth 9 carrying a relief of 1% amplitude (mean two-sided
/// distance to the exact surface ·10⁻⁴, α = 4; PoissonRecon in brackets):
///
/// | relief | σ = 1 | 0.7 | 0.5 | 0.35 |
/// |---|---|---|---|---|
/// | 8 voxels, precise | 7.8 | 6.6 | 6.1 | 5.8 (5.7) |
/// | 12 voxels, precise | 2.8 | | 2.5 | 2.4 (2.8) |
/// | 18 voxels, precise | 1.04 | | 1.00 | 0.98 (1.30) |
/// | 30 voxels, precise | 0.31 | | | 0.29 (0.48) |
/// | 8 voxels, noise 0.8 voxel | 13.5 | 12.1 | 11.5 | 11.3 (11.2) |
/// | 12 voxels, noise 0.8 voxel | 8.6 | 8.1 | 8.1 | 8.2 (8.0) |
/// | 18 voxels, noise 0.8 voxel | 6.6 | 6.7 | 7.0 | 7.2 (6.9) |
/// | 30 voxels, noise 0.8 voxel | 6.1 | 6.5 | | (6.7) |
/// | none, noise 0.8 voxel | 5.9 | | 6.6 | 6.9 (6.6) |
///
/// Every precise row wants the narrowest width; the noisy rows want one voxel, or more
/// (the plain noisy sphere: 5.5 at 1.5 voxels), except where the relief is as short as 8 to
/// 12 voxels. So the width follows the spread measured within fine voxels
/// ([`NoiseStats::sigma_voxels`]), which tells precise samples from noisy ones without
/// mistaking relief for noise: `σ = clamp(σ_w / σ_ref, 0.35, 1)` voxel with `σ_ref` =
/// [`NOISE_REFERENCE_VOXELS`], the spread at and above which `auto` stops raising the
/// screening weight; and one voxel wherever the noise lowers the weight (noise beyond a
/// voxel, or structure like LiDAR's vegetation returns, which read 0.099 within voxels but
/// 1.10 between close samples: 0.5 voxel gave `autzen_trim.las` at depth 9 112 pieces
/// against 61). Noise-free scans read 0.006–0.03 voxel and take 0.35; the raw bunny scans
/// (0.14) about 0.7 (two-sided mean distance to `bun_zipper` at depth 8 1.737·10⁻⁴ against
/// 1.722 with one voxel, from the input points 3.73·10⁻⁴ against 3.80, Open3D 1.94 and
/// 3.55); noise of 0.8 voxel reads 0.27 and would keep 1.
///
/// That width is then narrowed by the share of the quadrics' squared residual that is
/// noise ([`NoiseStats::noise_share`]: the noise read between close samples over the
/// residual about quadrics, squared), down to 0.35 voxel. What the quadrics read beyond the
/// noise is relief too fine for a disc of 1.5 voxels, which the one-voxel Gaussian would
/// flatten: the noisy rows above want 0.35 at 8 voxels' wavelength (share 0.27) and 0.5 at
/// 12 (0.52), and one voxel from 18 on (0.90 and more) and on the plain sphere (1). They now
/// get 0.35, 0.52, 0.90 and 1 (mean distance ·10⁻⁴ with the default vertex fit, which moves
/// nothing at that noise, at α = 4: 10.6, 7.9, 6.7, 5.8, plain 5.4; with the weight lowered
/// to the relief's share ([`relief_weight`]): 10.9, 7.7, 6.0, 3.4, plain 2.3; PoissonRecon
/// 11.2, 8.0, 6.9, 6.7, 6.6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Smoothing {
    /// From the measured precision: [`smoothing_voxels`].
    Measured,
    /// The given width in voxels.
    Fixed(f64),
}

impl Smoothing {
    /// The width to solve a grid with, in its voxels, for samples of the measured `noise`
    /// lying `spacing` of its voxels apart ([`crate::density::DensityGrid::sample_spacing`];
    /// `None`: unknown): [`smoothing_voxels`], or [`SMOOTH_NOISY_VOXELS`] where the noise
    /// beyond a voxel lowers the screening weight ([`noise_limit`] under 1); at least
    /// [`sparse_floor_voxels`] of the spacing.
    pub fn voxels(self, noise: &NoiseStats, spacing: Option<f64>) -> f64 {
        match self {
            Smoothing::Measured => {
                let within = noise.sigma_voxels();
                let measured = if noise_limit(within, noise.noise_voxels()) < 1.0 {
                    SMOOTH_NOISY_VOXELS
                } else {
                    let relief = noise.noise_share().unwrap_or(1.0);
                    (smoothing_voxels(within) * relief).max(SMOOTH_PRECISE_VOXELS)
                };
                measured.max(sparse_floor_voxels(spacing))
            }
            Smoothing::Fixed(s) => s,
        }
    }
}

/// The Gaussian's narrowest width, in the samples' spacing, for samples sparse against the
/// grid ([`sparse_floor_voxels`]).
pub const SPARSE_SPACINGS: f64 = 0.4;

/// The widest [`sparse_floor_voxels`] goes, in voxels: an eighth of a leaf's grid, two
/// of whose four overlap voxels the Gaussian's `2σ` then reaches (samples farther apart
/// than 10 voxels ask for a shallower depth).
pub const SPARSE_MAX_VOXELS: f64 = 4.0;

/// The width sparse samples need, in voxels of a grid on which they lie `spacing` voxels
/// apart: `min(0.4 spacing, 4)` ([`SPARSE_SPACINGS`], [`SPARSE_MAX_VOXELS`]); 0 where the
/// spacing is unknown.
///
/// A Gaussian much narrower than the gaps between samples leaves the normal field a set of
/// separate bumps: on a lattice of spacing `s` the sum of Gaussians of width `σ` ripples
/// by about `2 exp(−2π²σ²/s²)` of its mean (34% at `σ = 0.3 s`, 8.5% at `0.4 s`, 1.4% at
/// `0.5 s`), and the surface follows the ripple between samples, or, where the samples are
/// noisy, breaks into specks. This is the case of a depth finer than the sampling:
/// PoissonRecon stops refining its octree where a node holds fewer than `--samplesPerNode`
/// samples; here the Gaussian widens instead, on each grid by its own spacing. Measured on
/// spheres of 200,000 points (mean distance to the exact sphere ·10⁻⁵; the samples 1.9,
/// 3.7 and 7.4 voxels apart at depths 9, 10 and 11):
///
/// | samples | depth | σ = 0.35 | 0.7 | 1 | 1.5 | 2 | 2.5 | 3 | 4 | PoissonRecon |
/// |---|---|---|---|---|---|---|---|---|---|---|
/// | precise | 9 | 0.62 | 0.55 | | | | | | | |
/// | precise | 10 | 3.3 | 2.3 | 1.5 | 0.83 | 0.53 | | | | 3.35 |
/// | precise | 11 | 6.7 | | 7.2 | 3.3 | | 1.56 | | | 3.35 |
/// | noise 0.0005 | 9 | | | 40 | 36 | | | | | 44 |
/// | noise 0.0005 | 10 | | | 51 | 46 | 41 | | | | |
/// | noise 0.0005 | 11 | | | 69, 309 pieces | | 55 | | 45 | 39 | 48 |
///
/// A plain sphere rewards any smoothing; relief pays for it. A precise 200,000-point
/// sphere carrying a relief of 1% amplitude and 24 voxels' wavelength (6.5 spacings) at
/// depth 10: 3.5·10⁻⁴ at 0.35 voxel, 3.9 at 1.1 (0.3 spacing), 5.5 at 1.85 (0.5 spacing),
/// PoissonRecon 9.6. At 0.4 spacing the noisy sphere is level with PoissonRecon in one
/// piece, the precise one 2–4 times closer than at 0.35 voxel, and relief of 6.5 spacings
/// keeps most of its lead.
pub fn sparse_floor_voxels(spacing: Option<f64>) -> f64 {
    spacing.map_or(0.0, |s| (SPARSE_SPACINGS * s).min(SPARSE_MAX_VOXELS))
}

impl std::fmt::Display for Smoothing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Smoothing::Measured => f.write_str("measured"),
            Smoothing::Fixed(s) => write!(f, "{s}"),
        }
    }
}

/// The Gaussian's width for samples whose spread within fine voxels is `sigma` (`None`:
/// not measured): `clamp(σ / σ_ref, 0.35, 1)` voxel ([`Smoothing`]).
pub fn smoothing_voxels(sigma: Option<f64>) -> f64 {
    match sigma {
        Some(s) => (s / NOISE_REFERENCE_VOXELS).clamp(SMOOTH_PRECISE_VOXELS, SMOOTH_NOISY_VOXELS),
        None => SMOOTH_NOISY_VOXELS,
    }
}

/// Bytes a point takes while [`NoiseStats::of`] sorts a batch: its fine voxel key and index.
pub const NOISE_KEY_BYTES: u64 = 16;

/// The spread of samples across the surface, pooled over fine voxels: for every voxel holding
/// `m ≥ 2` samples, the squared offsets `((p_i − p̄)·n̄)²` from their mean along their mean
/// normal, and its `m − 1` degrees of freedom.
///
/// Beside it, the spread that a voxel cannot hold: the residuals of local quadric (jet)
/// fits over a tangential disc of [`JET_RADII_VOXELS`] around a few voxels of each batch
/// ([`NoiseStats::jet_sigma_voxels`]). The in-voxel spread is exact for noise well under a
/// voxel but cannot exceed `1/√12` voxel (a voxel's own spread), so it cannot tell a scan
/// of noise 0.5 voxel from one of 2; the jet residual reads noise up to about two voxels
/// while a quadric absorbs the surface's own curvature and relief down to a wavelength of
/// about 8 voxels.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NoiseStats {
    /// `Σ ((p_i − p̄)·n̄)²`, in squared fine voxels.
    pub sum_sq: f64,
    /// `Σ (m − 1)`.
    pub dof: u64,
    /// The jet fits on the narrow and on the wide disc ([`JET_RADII_VOXELS`]).
    pub jets: [JetStats; 2],
    /// The height differences of sample pairs on the narrow discs.
    pub pairs: PairStats,
}

/// Pairs of samples on a jet fit's narrow disc, pooled: the least-squares sums of the
/// half squared height difference `y = ½((p_j − p_i)·m)²` along the pair's mean normal `m`
/// against their squared distance across it, `x` (in fine voxels), for pairs under
/// [`PAIR_MAX_VOXELS`] apart across `m`, kept apart by distance and by height difference
/// `|Δh|` ([`pair_bin`]) so that the estimate can leave out the pairs of two sheets of a
/// fold ([`PairStats::nugget`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairStats {
    /// Per bin of `x` ([`PAIR_X_BINS`] equal ones up to [`PAIR_MAX_VOXELS`]`²`) and of
    /// `|Δh|` ([`pair_bin`]): `[Σ1, Σx, Σx², Σy, Σxy]`.
    pub bins: [[[f64; 5]; PAIR_BINS]; PAIR_X_BINS],
}

impl Default for PairStats {
    fn default() -> Self {
        PairStats {
            bins: [[[0.0; 5]; PAIR_BINS]; PAIR_X_BINS],
        }
    }
}

/// The farthest apart across their mean normal two samples of a pair are taken, in fine
/// voxels ([`NoiseStats::pair_sigma_voxels`]).
pub const PAIR_MAX_VOXELS: f64 = 0.75;

/// The most samples of one disc whose pairs are taken: beyond, every so many (a dense scan
/// still leaves some 18 a voxel of area on the disc).
pub const PAIR_MAX_SAMPLES: usize = 128;

/// Fewest pairs [`NoiseStats::pair_sigma_voxels`] reads.
pub const PAIR_MIN_COUNT: f64 = 1000.0;

/// Bins of the pairs' squared distance across their normal ([`PairStats`]): the spread of
/// their height difference grows with it, and each bin is cut at its own.
pub const PAIR_X_BINS: usize = 6;

/// Bins of the pairs' height difference ([`pair_bin`]): six an octave from
/// [`PAIR_BIN_FIRST_VOXELS`], the last one from 12.9 voxels on, farther than two samples
/// of a disc lie apart (12.4 at most: twice [`JET_HEIGHT_VOXELS`] along its normal, twice
/// the narrow radius across), so that it holds only what no cut keeps.
pub const PAIR_BINS: usize = 64;

/// The first bin's upper edge, in fine voxels ([`pair_bin`]).
pub const PAIR_BIN_FIRST_VOXELS: f64 = 0.01;

/// Bins of [`PairStats`] an octave of the height difference spans.
const PAIR_BINS_PER_OCTAVE: f64 = 6.0;

/// The bin of a height difference `|Δh|` (fine voxels): 0 under [`PAIR_BIN_FIRST_VOXELS`],
/// then `i` for `|Δh|` in `[e(i − 1), e(i))`, `e(i) = first · 2^(i/6)` ([`pair_bin_edge`]),
/// the last bin holding all beyond.
pub fn pair_bin(dh: f64) -> usize {
    if dh.is_nan() || dh < PAIR_BIN_FIRST_VOXELS {
        return 0;
    }
    let i = (PAIR_BINS_PER_OCTAVE * (dh / PAIR_BIN_FIRST_VOXELS).log2()).floor() as usize + 1;
    i.min(PAIR_BINS - 1)
}

/// The upper edge of bin `i` ([`pair_bin`]), in fine voxels.
pub fn pair_bin_edge(i: usize) -> f64 {
    PAIR_BIN_FIRST_VOXELS * (i as f64 / PAIR_BINS_PER_OCTAVE).exp2()
}

/// The bin of a squared distance `x` (squared fine voxels, at most [`PAIR_MAX_VOXELS`]`²`).
fn pair_x_bin(x: f64) -> usize {
    let i = (x.max(0.0) / (PAIR_MAX_VOXELS * PAIR_MAX_VOXELS) * PAIR_X_BINS as f64) as usize;
    i.min(PAIR_X_BINS - 1)
}

/// Where the estimate of the pairs' noise cuts their height differences, in their standard
/// deviation at their distance ([`PairStats::nugget`]).
pub const PAIR_TRIM_SIGMAS: f64 = 2.5;

/// The share of the pairs beyond the cut ([`PairStats::nugget`]) up to which they are
/// taken for the sheets of a fold and left out, and from which for a volume of returns
/// and kept, linearly in between. Normal noise leaves 1.2% beyond; on the 1M-point sphere
/// carrying a relief of 2% amplitude at 8 voxels' wavelength with noise of 0.8 voxel, 11%
/// lie beyond; on `autzen_trim.las` (airborne LiDAR, returns stacked in its vegetation)
/// 33%, whose cut reading (0.05 voxel) would take the vegetation for surfaces.
pub const PAIR_SHEETS_SHARE: [f64; 2] = [0.15, 0.25];

/// Rounds of the trimmed estimate at most ([`PairStats::nugget`]); it settles in a few.
const PAIR_TRIM_ROUNDS: usize = 100;

/// The share of a normal distribution's variance within `±k` standard deviations,
/// `E[z² | |z| ≤ k] = 1 − 2kφ(k)/(2Φ(k) − 1)`, by Simpson's rule on both integrals.
pub fn trimmed_variance_share(k: f64) -> f64 {
    let steps = 2000;
    let dz = k / steps as f64;
    let (mut mass, mut second) = (0.0, 0.0);
    for i in 0..=steps {
        let z = i as f64 * dz;
        let w = if i == 0 || i == steps {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let phi = (-0.5 * z * z).exp();
        mass += w * phi;
        second += w * z * z * phi;
    }
    second / mass
}

/// The least-squares line `y = a + c x` through sums `[Σ1, Σx, Σx², Σy, Σxy]` as
/// `(a, c)`, or `None` under [`PAIR_MIN_COUNT`] pairs or where they all lie equally far
/// apart.
fn line(s: [f64; 5]) -> Option<(f64, f64)> {
    let [n, sx, sxx, sy, sxy] = s;
    let det = n * sxx - sx * sx;
    (n >= PAIR_MIN_COUNT && det > 1e-12 * n * sxx)
        .then(|| ((sxx * sy - sx * sxy) / det, (n * sxy - sx * sy) / det))
}

impl PairStats {
    fn add_pair(&mut self, x: f64, dh: f64) {
        let y = 0.5 * dh * dh;
        let b = &mut self.bins[pair_x_bin(x)][pair_bin(dh.abs())];
        for (s, v) in b.iter_mut().zip([1.0, x, x * x, y, x * y]) {
            *s += v;
        }
    }

    fn add(&mut self, other: PairStats) {
        let sums = self.bins.iter_mut().flatten().flatten();
        for (s, v) in sums.zip(other.bins.iter().flatten().flatten()) {
            *s += v;
        }
    }

    /// The sums over the pairs whose height difference is under `cut(x̄)` (fine voxels),
    /// `x̄` the mean squared distance of each distance bin's pairs: whole bins below it,
    /// and of the bin it falls in the share under it (linear in `|Δh|`, so that the sums,
    /// and the estimate, move continuously with the cut).
    fn below(&self, cut: impl Fn(f64) -> f64) -> [f64; 5] {
        let mut sum = [0.0; 5];
        for xb in &self.bins {
            let n: f64 = xb.iter().map(|b| b[0]).sum();
            if n == 0.0 {
                continue;
            }
            let t = cut(xb.iter().map(|b| b[1]).sum::<f64>() / n);
            for (i, b) in xb.iter().enumerate() {
                let lo = if i == 0 { 0.0 } else { pair_bin_edge(i - 1) };
                let hi = pair_bin_edge(i);
                let share = if i + 1 == PAIR_BINS {
                    if t >= f64::MAX { 1.0 } else { 0.0 }
                } else {
                    ((t - lo) / (hi - lo)).clamp(0.0, 1.0)
                };
                if share == 0.0 {
                    break;
                }
                for (s, v) in sum.iter_mut().zip(b) {
                    *s += share * v;
                }
            }
        }
        sum
    }

    /// The noise `σ²` the pairs read: the intercept of the line `y = σ² + c x` fitted to
    /// the pairs whose height difference lies within [`PAIR_TRIM_SIGMAS`] of its spread
    /// at their distance, `√(2(σ² + c x))`, divided by the share of a normal variance so
    /// kept ([`trimmed_variance_share`]). The cut starts at [`PAIR_BIN_FIRST_VOXELS`] of
    /// noise and is repeated until it settles: from below, each round widens it (for
    /// normal noise by about 2.3 times in `σ²` while far under it), and it stops at the
    /// narrowest spread that reads itself back, the noise's, before the pairs across two
    /// sheets of a fold. Where the pairs beyond the cut are more than a fold's
    /// ([`PAIR_SHEETS_SHARE`]) they are a volume of returns, and the line through all
    /// pairs stands (module docs). `None` under [`PAIR_MIN_COUNT`] pairs or where they
    /// all lie equally far apart.
    pub fn nugget(&self) -> Option<f64> {
        let all = self.below(|_| f64::MAX);
        let (whole, _) = line(all)?;
        let share = trimmed_variance_share(PAIR_TRIM_SIGMAS);
        let (mut a, mut c) = (PAIR_BIN_FIRST_VOXELS * PAIR_BIN_FIRST_VOXELS, 0.0);
        let cut =
            |a: f64, c: f64| move |x: f64| PAIR_TRIM_SIGMAS * (2.0 * (a + c * x).max(0.0)).sqrt();
        for _ in 0..PAIR_TRIM_ROUNDS {
            let Some((na, nc)) = line(self.below(cut(a, c))) else {
                // Too few pairs under the cut: widen it.
                a *= 2.0;
                continue;
            };
            let (na, nc) = (na / share, nc / share);
            let settled = (na - a).abs() <= 1e-12 * a && (nc - c).abs() <= 1e-12 * c.abs();
            (a, c) = (na, nc);
            if settled || a <= 0.0 {
                break;
            }
        }
        let beyond = 1.0 - self.below(cut(a, c))[0] / all[0];
        let [from, to] = PAIR_SHEETS_SHARE;
        let t = ((beyond - from) / (to - from)).clamp(0.0, 1.0);
        Some((1.0 - t) * a + t * whole)
    }
}

/// Jet fits pooled: their residuals, degrees of freedom and number.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JetStats {
    /// Summed squared residuals, in squared fine voxels.
    pub sum_sq: f64,
    /// `Σ (m − 6)`.
    pub dof: u64,
    /// Fits.
    pub fits: u64,
}

impl JetStats {
    fn add(&mut self, other: JetStats) {
        self.sum_sq += other.sum_sq;
        self.dof += other.dof;
        self.fits += other.fits;
    }
}

/// Narrow fits a run needs for [`NoiseStats::jet_sigma_voxels`] to read them rather than
/// the wide ones.
pub const JET_MIN_FITS: u64 = 64;

/// The tangential radii of a jet fit's disc, in fine voxels (see [`NoiseStats`]): the
/// narrow one holds some 25 samples at 4 per voxel of area, and a quadric on it follows a
/// relief of 12 voxels' wavelength (its residual there reads 0.02 voxel without noise); the
/// wide one serves samples too sparse for it (about one per voxel of area).
pub const JET_RADII_VOXELS: [f64; 2] = [1.5, 3.0];

/// How far along the normal a jet fit gathers, in fine voxels: the residuals are cut here
/// (noise of 1.6 voxels reads 1.53, of 2.4 about 2).
pub const JET_HEIGHT_VOXELS: f64 = 6.0;

/// A jet fit is centred on every this many occupied fine voxels of a batch (a store cell), in
/// key order, or on more where that would leave the batch under [`JET_MIN_FITS`] fits. Its
/// cost (perf, a 10M-point sphere with noise of 1.6 voxels at depth 10, 2 cores): all of
/// [`NoiseStats::of`], the sort and the fits, is under 1 CPU-second, about 1% of the run.
pub const JET_VOXELS_PER_FIT: usize = 64;

/// Up to this many points a run measures its noise on every store cell. Beyond, the
/// statistics would grow with the points while the pooled figures, of millions of voxels and
/// tens of thousands of fits, are long since precise: a 100M-point sphere at depth 11 spent
/// 60% of its coarse pass, some 17 s on 2 cores, in 190,000 jet fits, and with the fits
/// thinned, a sixth of it still sorting every point by voxel.
pub const NOISE_FULL_RATE_POINTS: u64 = 10_000_000;

/// Store cells apart whose noise a run of `points` samples measures ([`NoiseStats::of`] on
/// cells `0, k, 2k, …` in store order): 1, or the number of [`NOISE_FULL_RATE_POINTS`] the
/// run holds (rounded up), so the measured samples stop growing past that many points. A
/// function of the run alone (its point count), so every thread count, shard and resume
/// reads the same statistics.
pub fn noise_cell_stride(points: u64) -> usize {
    points.div_ceil(NOISE_FULL_RATE_POINTS).max(1) as usize
}

/// Fewest samples a jet fit takes (six unknowns).
pub const JET_MIN_SAMPLES: u64 = 16;

impl NoiseStats {
    /// The statistics of one batch of samples (`pos`, unit normals `nrm`) on the fine voxels
    /// of spacing `h` from `origin`. Voxels are visited in key order and samples in input
    /// order, so the sums depend only on the batch. Jet fits are at most
    /// [`JET_VOXELS_PER_FIT`] voxels apart.
    pub fn of(pos: &[[f64; 3]], nrm: &[[f32; 3]], origin: [f64; 3], h: f64) -> NoiseStats {
        let mut keys: Vec<(u64, u32)> = pos
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let v = [0, 1, 2].map(|a| voxel_index((p[a] - origin[a]) / h));
                (voxel_key(v), i as u32)
            })
            .collect();
        keys.sort_unstable();
        let mut st = NoiseStats::default();
        for run in keys.chunk_by(|a, b| a.0 == b.0) {
            if run.len() < 2 {
                continue;
            }
            let Some((c, n, len)) = voxel_mean(run, pos, nrm) else {
                continue;
            };
            for &(_, i) in run {
                let p = pos[i as usize];
                let d: f64 = (0..3).map(|a| (p[a] - c[a]) * n[a] / len).sum::<f64>() / h;
                st.sum_sq += d * d;
            }
            st.dof += run.len() as u64 - 1;
        }
        st.add_jets(pos, nrm, &keys, origin, h);
        st
    }

    /// The jet fits of [`NoiseStats::of`] over a batch whose `(key, index)` pairs `keys`
    /// are sorted: centred on voxels at an even stride (at most [`JET_VOXELS_PER_FIT`]), each
    /// fit in the frame of its centre voxel's mean sample and normal, on both discs.
    fn add_jets(
        &mut self,
        pos: &[[f64; 3]],
        nrm: &[[f32; 3]],
        keys: &[(u64, u32)],
        origin: [f64; 3],
        h: f64,
    ) {
        // Counted first, so that the pass holds nothing beyond the keys.
        let voxels = keys.chunk_by(|a, b| a.0 == b.0).count();
        let stride = (voxels / JET_MIN_FITS as usize).clamp(1, JET_VOXELS_PER_FIT);
        for run in keys.chunk_by(|a, b| a.0 == b.0).step_by(stride) {
            let Some((c, n, len)) = voxel_mean(run, pos, nrm) else {
                continue;
            };
            // The fit's frame, in fine voxels from `origin`.
            let c = [0, 1, 2].map(|a| (c[a] - origin[a]) / h);
            let n = n.map(|x| x / len);
            let (t1, t2) = plane_basis(n);
            // The voxels of the widest cylinder's bounding box.
            let wide = JET_RADII_VOXELS[1];
            let mut lo = [0u64; 3];
            let mut hi = [0u64; 3];
            for a in 0..3 {
                let e = wide * (1.0 - n[a] * n[a]).max(0.0).sqrt() + JET_HEIGHT_VOXELS * n[a].abs();
                lo[a] = voxel_index(c[a] - e);
                hi[a] = voxel_index(c[a] + e);
            }
            // Normal equations of w = a + b u + c v + d u² + e uv + f v², on each disc.
            let mut fits = [Jet::default(); 2];
            let mut near: Vec<([f64; 3], [f64; 3])> = Vec::new();
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    let (first, last) = (voxel_key([x, y, lo[2]]), voxel_key([x, y, hi[2]]));
                    let from = keys.partition_point(|k| k.0 < first);
                    for &(k, i) in &keys[from..] {
                        if k > last {
                            break;
                        }
                        let p = pos[i as usize];
                        let d = [0, 1, 2].map(|a| (p[a] - origin[a]) / h - c[a]);
                        let w = dot(d, n);
                        let (u, v) = (dot(d, t1), dot(d, t2));
                        let facing = dot(nrm[i as usize].map(f64::from), n);
                        if w.abs() > JET_HEIGHT_VOXELS || facing <= 0.0 {
                            continue;
                        }
                        for (fit, r) in fits.iter_mut().zip(JET_RADII_VOXELS) {
                            if u * u + v * v <= r * r {
                                fit.add(u, v, w);
                            }
                        }
                        if u * u + v * v <= JET_RADII_VOXELS[0] * JET_RADII_VOXELS[0] {
                            let m = nrm[i as usize].map(f64::from);
                            let l = dot(m, m).sqrt();
                            near.push((d, m.map(|x| x / l)));
                        }
                    }
                }
            }
            // Every so many samples of a dense disc, so that a fit costs at most
            // PAIR_MAX_SAMPLES² / 2 pairs.
            let near: Vec<_> = near
                .iter()
                .step_by(near.len().div_ceil(PAIR_MAX_SAMPLES).max(1))
                .collect();
            for (i, a) in near.iter().enumerate() {
                for b in &near[i + 1..] {
                    let m = [0, 1, 2].map(|k| a.1[k] + b.1[k]);
                    let l2 = dot(m, m);
                    if l2 <= 0.0 {
                        continue;
                    }
                    let e = [0, 1, 2].map(|k| b.0[k] - a.0[k]);
                    let dh = dot(e, m) / l2.sqrt();
                    let x = dot(e, e) - dh * dh;
                    if x <= PAIR_MAX_VOXELS * PAIR_MAX_VOXELS {
                        self.pairs.add_pair(x, dh);
                    }
                }
            }
            for (pooled, fit) in self.jets.iter_mut().zip(&fits) {
                if let Some((sum_sq, dof)) = fit.residual() {
                    pooled.add(JetStats {
                        sum_sq,
                        dof,
                        fits: 1,
                    });
                }
            }
        }
    }

    /// Pool `other` into `self`.
    pub fn add(&mut self, other: NoiseStats) {
        self.sum_sq += other.sum_sq;
        self.dof += other.dof;
        for (a, b) in self.jets.iter_mut().zip(other.jets) {
            a.add(b);
        }
        self.pairs.add(other.pairs);
    }

    /// The spread `σ` in fine voxels, or `None` where no voxel held two samples.
    pub fn sigma_voxels(&self) -> Option<f64> {
        (self.dof > 0).then(|| (self.sum_sq / self.dof as f64).sqrt())
    }

    /// The samples' noise in fine voxels read from pairs of close samples: the nugget of
    /// their height differences along their mean normal (`½E[Δh²]` extrapolated to pairs no
    /// distance apart, [`PairStats`]), `None` where too few pairs were found.
    pub fn pair_sigma_voxels(&self) -> Option<f64> {
        self.pairs.nugget().map(|s2| s2.max(0.0).sqrt())
    }

    /// The noise the vertex fit allows for, in fine voxels
    /// ([`crate::surface::fit`]): the spread within fine voxels for precise samples (under
    /// [`PRECISE_WITHIN_VOXELS`]), else the larger of it and [`Self::pair_sigma_voxels`]
    /// (the spread within voxels cannot exceed `1/√12` of one); `None` where no fine voxel
    /// held two samples (the fit then takes the samples as precise).
    pub fn fit_noise_voxels(&self) -> Option<f64> {
        let within = self.sigma_voxels()?;
        if precise(Some(within)) {
            return Some(within);
        }
        Some(self.pair_sigma_voxels().map_or(within, |p| p.max(within)))
    }

    /// The samples' noise across the surface in fine voxels: [`Self::pair_sigma_voxels`],
    /// else [`Self::jet_sigma_voxels`].
    pub fn noise_voxels(&self) -> Option<f64> {
        self.pair_sigma_voxels().or_else(|| self.jet_sigma_voxels())
    }

    /// The share of the quadrics' squared residual that is noise: `σ_pair²/σ_jet²` (at most
    /// 1), `None` where either is unmeasured.
    pub fn noise_share(&self) -> Option<f64> {
        let (p, j) = (self.pair_sigma_voxels()?, self.jet_sigma_voxels()?);
        (j > 0.0).then(|| (p * p / (j * j)).min(1.0))
    }

    /// The jet fits' residual spread in fine voxels: over the narrow discs where the run
    /// made [`JET_MIN_FITS`] of them (dense samples), else over the wide ones; `None` where
    /// no fit found enough samples.
    pub fn jet_sigma_voxels(&self) -> Option<f64> {
        let [narrow, wide] = self.jets;
        let jets = if narrow.fits >= JET_MIN_FITS {
            narrow
        } else {
            wide
        };
        (jets.dof > 0).then(|| (jets.sum_sq / jets.dof as f64).sqrt())
    }
}

/// The normal equations of one jet fit, `w = a + b u + c v + d u² + e uv + f v²`.
#[derive(Clone, Copy, Default)]
struct Jet {
    ata: nalgebra::Matrix6<f64>,
    atb: nalgebra::Vector6<f64>,
    btb: f64,
    count: u64,
}

impl Jet {
    fn add(&mut self, u: f64, v: f64, w: f64) {
        let r = nalgebra::Vector6::new(1.0, u, v, u * u, u * v, v * v);
        self.ata += r * r.transpose();
        self.atb += r * w;
        self.btb += w * w;
        self.count += 1;
    }

    /// The least-squares fit's residual sum of squares `wᵀw − cᵀAᵀw` and its degrees of
    /// freedom, or `None` under [`JET_MIN_SAMPLES`] or for a singular system.
    fn residual(&self) -> Option<(f64, u64)> {
        if self.count < JET_MIN_SAMPLES {
            return None;
        }
        let coef = self.ata.cholesky()?.solve(&self.atb);
        Some(((self.btb - coef.dot(&self.atb)).max(0.0), self.count - 6))
    }
}

/// Bits of a fine voxel's index per axis in [`NoiseStats::of`]'s keys.
const KEY_BITS: u32 = 21;

/// The fine voxel holding offset `u` (in voxels from the origin) along one axis, clamped to
/// the keys' range.
fn voxel_index(u: f64) -> u64 {
    floor(u).clamp(0.0, ((1u64 << KEY_BITS) - 1) as f64) as u64
}

/// The key of the fine voxel `v`: `x, y, z` from the most significant bits down, so that
/// keys sort by `x`, then `y`, then `z` (a column of `z` is one key range).
fn voxel_key(v: [u64; 3]) -> u64 {
    (((v[0] << KEY_BITS) | v[1]) << KEY_BITS) | v[2]
}

/// The mean position of the samples `run` of one voxel, the sum of their unit normals and its
/// length; `None` where the normals nearly cancel: samples of opposite sides in one voxel
/// (a thin sheet) say nothing of the noise.
fn voxel_mean(
    run: &[(u64, u32)],
    pos: &[[f64; 3]],
    nrm: &[[f32; 3]],
) -> Option<([f64; 3], [f64; 3], f64)> {
    let m = run.len() as f64;
    let mut c = [0f64; 3];
    let mut n = [0f64; 3];
    for &(_, i) in run {
        // Directions only: a normal's length may carry a confidence (PoissonRecon's
        // convention), which weighs the solve where asked, never the noise's geometry.
        let d = nrm[i as usize].map(f64::from);
        let l = dot(d, d).sqrt();
        for a in 0..3 {
            c[a] += pos[i as usize][a] / m;
            if l > 0.0 {
                n[a] += d[a] / l;
            }
        }
    }
    let len = dot(n, n).sqrt();
    (len >= 0.5 * m).then_some((c, n, len))
}

/// A voxel's aggregate: the sum of its samples' offsets in it (in voxels) and their count.
pub type Aggregate = ([f64; 3], u64);

/// One batch's aggregates kept apart from any builder ([`ScreenBuilder::part`]): per voxel
/// (`(z·n + y)·n + x`, ascending) the sum over the batch's samples in their order. The coarse
/// pass aggregates each store cell into its own part and adds the parts in cell order
/// ([`ScreenBuilder::add_parts`]), so that cells aggregated by other threads or shards give
/// the same operator (as [`super::fft_solve::SplatBox`] does for the splat).
pub type ScreenPart = Vec<(u64, Aggregate)>;

/// Bytes of one entry of a [`ScreenPart`].
pub const SCREEN_PART_ENTRY_BYTES: u64 = 40;

/// Samples gathered per voxel of a grid, before [`ScreenBuilder::finish`] weighs them.
pub struct ScreenBuilder {
    grid: LocalGrid,
    /// Per z-slab of the grid's voxels (`per` planes each, the last maybe fewer), per wrapped
    /// voxel (`(z·n + y)·n + x`): its [`Aggregate`]. Slabs take their samples in parallel
    /// ([`ScreenBuilder::add_parts`]).
    slabs: Vec<KeyMap<u64, Aggregate>>,
    per: usize,
    /// Instead of the maps, for a leaf's grid ([`ScreenBuilder::dense`]): the aggregates in
    /// the order their voxels were first met, and per voxel its aggregate's place plus one
    /// (0: none yet).
    dense: Option<DenseIndex>,
}

/// A dense builder's aggregates, in the order their voxels were first met, and per voxel of
/// the grid its aggregate's place plus one (0: none yet).
type DenseIndex = (Vec<(u64, Aggregate)>, Vec<u32>);

/// The wrapped voxel of `grid` holding `p` (world frame), as `(z·n + y)·n + x`, and `p`'s
/// offset in it (in voxels); `None` when the voxel lies outside planes `z0 .. z1` (known
/// from `z` alone, before the other axes are computed).
#[inline]
fn voxel_in(g: &LocalGrid, p: &[f64; 3], (z0, z1): (u64, u64)) -> Option<(u64, [f64; 3])> {
    let n = g.n as i64;
    let mut key = 0u64;
    let mut off = [0f64; 3];
    for a in (0..3).rev() {
        let u = (p[a] - g.origin[a]) / g.h;
        let fl = floor(u);
        off[a] = u - fl;
        let i = wrap(fl as i64, n) as u64;
        if a == 2 && (i < z0 || i >= z1) {
            return None;
        }
        key = key * g.n as u64 + i;
    }
    Some((key, off))
}

/// Every plane of a grid.
const ALL_PLANES: (u64, u64) = (0, u64::MAX);

/// Add a sample at offset `off` (`count` of them, their offsets summed) to `e`.
#[inline]
fn aggregate(e: &mut Aggregate, off: [f64; 3], count: u64) {
    for a in 0..3 {
        e.0[a] += off[a];
    }
    e.1 += count;
}

/// One map of a [`ScreenBuilder`]: the samples of `pos` whose voxel lies in planes
/// `z0 .. z1` added to `map`.
fn add_samples(
    g: &LocalGrid,
    map: &mut KeyMap<u64, Aggregate>,
    pos: &[[f64; 3]],
    (z0, z1): (u64, u64),
) {
    for p in pos {
        if let Some((key, off)) = voxel_in(g, p, (z0, z1)) {
            aggregate(map.entry(key).or_insert(([0.0; 3], 0)), off, 1);
        }
    }
}

/// The aggregate of voxel `key` in a dense builder's `list` (`slot`: its place plus one).
#[inline]
fn dense_entry<'a>(
    list: &'a mut Vec<(u64, Aggregate)>,
    slot: &mut [u32],
    key: u64,
) -> &'a mut Aggregate {
    let s = &mut slot[key as usize];
    if *s == 0 {
        list.push((key, ([0.0; 3], 0)));
        *s = list.len() as u32;
    }
    &mut list[*s as usize - 1].1
}

impl ScreenBuilder {
    /// No samples yet, on `grid`.
    pub fn new(grid: &LocalGrid) -> ScreenBuilder {
        ScreenBuilder::with_slabs(grid, 1)
    }

    /// No samples yet, on `grid`, its voxels split into `slabs` z-slabs that
    /// [`ScreenBuilder::add_parts`] fills in parallel (the same operator for any count).
    pub fn with_slabs(grid: &LocalGrid, slabs: usize) -> ScreenBuilder {
        let per = grid.n.div_ceil(slabs.clamp(1, grid.n.max(1)));
        ScreenBuilder {
            grid: *grid,
            slabs: (0..grid.n.div_ceil(per).max(1))
                .map(|_| KeyMap::default())
                .collect(),
            per,
            dense: None,
        }
    }

    /// No samples yet, on `grid`, gathered through an index of every voxel (4 bytes a node)
    /// instead of a hash map: for a leaf's grids, where the index is smaller than the splat
    /// beside it (12 bytes a node) and is dropped before the solve, which peaks higher. The
    /// hash map's lookups were a thirteenth of the leaf stage (100M points, depth 11). The
    /// same aggregates, summed in the same order, as [`ScreenBuilder::new`].
    pub fn dense(grid: &LocalGrid) -> ScreenBuilder {
        ScreenBuilder {
            dense: Some((Vec::new(), vec![0; grid.len()])),
            ..ScreenBuilder::with_slabs(grid, 1)
        }
    }

    /// The planes `z0 .. z1` of slab `s`, `per` planes a slab.
    fn planes(per: usize, s: usize) -> (u64, u64) {
        ((s * per) as u64, ((s + 1) * per) as u64)
    }

    /// Add the samples at `pos` (world frame).
    pub fn add(&mut self, pos: &[[f64; 3]]) {
        if let Some((list, slot)) = &mut self.dense {
            for p in pos {
                if let Some((key, off)) = voxel_in(&self.grid, p, ALL_PLANES) {
                    aggregate(dense_entry(list, slot, key), off, 1);
                }
            }
            return;
        }
        for (s, map) in self.slabs.iter_mut().enumerate() {
            add_samples(&self.grid, map, pos, Self::planes(self.per, s));
        }
    }

    /// The aggregates of the samples at `pos` (world frame) on `grid`, apart from any
    /// builder ([`ScreenPart`]).
    pub fn part(grid: &LocalGrid, pos: &[[f64; 3]]) -> ScreenPart {
        let mut map = KeyMap::default();
        add_samples(grid, &mut map, pos, ALL_PLANES);
        let mut part: ScreenPart = map.into_iter().collect();
        part.sort_unstable_by_key(|e| e.0);
        part
    }

    /// Add the parts `parts` ([`ScreenBuilder::part`], on this builder's grid) in order, the
    /// slabs in parallel (on the pool it runs in): each voxel takes the parts' aggregates in
    /// the parts' order, whatever the slabs.
    pub fn add_parts(&mut self, parts: &[&[(u64, Aggregate)]]) {
        if let Some((list, slot)) = &mut self.dense {
            for &(key, (sum, count)) in parts.iter().copied().flatten() {
                aggregate(dense_entry(list, slot, key), sum, count);
            }
            return;
        }
        let (plane, per) = ((self.grid.n * self.grid.n) as u64, self.per);
        self.slabs.par_iter_mut().enumerate().for_each(|(s, map)| {
            let (z0, z1) = Self::planes(per, s);
            for part in parts {
                // Keys ascend, and a slab's keys are a range of them.
                let from = part.partition_point(|e| e.0 < z0 * plane);
                let to = part.partition_point(|e| e.0 < z1.saturating_mul(plane));
                for &(key, (sum, count)) in &part[from..to] {
                    aggregate(map.entry(key).or_insert(([0.0; 3], 0)), sum, count);
                }
            }
        });
    }

    /// Add the samples summed per voxel of a level's lattice ([`VoxelSum`]), this builder's
    /// grid placed on it by `on`: the same aggregates as their points give, up to rounding.
    pub fn add_voxels(&mut self, on: OnLattice, voxels: &[VoxelSum]) {
        let n = self.grid.n as u64;
        for s in voxels {
            let (v, off) = screen_voxel(self.grid.n, on, s);
            let key = (v[2] as u64 * n + v[1] as u64) * n + v[0] as u64;
            let e = match &mut self.dense {
                Some((list, slot)) => dense_entry(list, slot, key),
                None => self.slabs[v[2] / self.per]
                    .entry(key)
                    .or_insert(([0.0; 3], 0)),
            };
            aggregate(e, off, s.count as u64);
        }
    }

    /// Bytes the builder holds: one map entry per occupied voxel.
    pub fn bytes(&self) -> u64 {
        match &self.dense {
            Some((list, slot)) => {
                list.capacity() as u64 * VOXEL_ENTRY_BYTES + 4 * slot.len() as u64
            }
            None => self.slabs.iter().map(|m| m.capacity() as u64).sum::<u64>() * VOXEL_ENTRY_BYTES,
        }
    }

    /// The screening operator with weight `alpha` (see the module docs).
    pub fn finish(self, alpha: f64) -> Screen {
        let g = self.grid;
        let mut voxels: Vec<(u64, Aggregate)> = match self.dense {
            Some((list, _)) => list,
            None => self.slabs.into_iter().flatten().collect(),
        };
        voxels.sort_unstable_by_key(|v| v.0);
        let total: u64 = voxels.iter().map(|v| v.1.1).sum();
        let mut s = Screen {
            nodes: Vec::with_capacity(voxels.len()),
            weights: Vec::with_capacity(voxels.len()),
            gamma: Vec::with_capacity(voxels.len()),
        };
        if total == 0 || alpha <= 0.0 {
            return s;
        }
        let h_u = g.h / g.unit;
        // γ_a = α · w_a / w̄ / h², w̄ = total / occupied.
        let per_sample = alpha * voxels.len() as f64 / total as f64 / (h_u * h_u);
        let n = g.n as u64;
        for (key, (sum, count)) in voxels {
            let v = [key % n, (key / n) % n, key / (n * n)];
            let mut at = [[0usize; 2]; 3];
            let mut w = [[0f32; 2]; 3];
            for a in 0..3 {
                let f = (sum[a] / count as f64) as f32;
                at[a] = [v[a] as usize, ((v[a] + 1) % n) as usize];
                w[a] = [1.0 - f, f];
            }
            let mut nodes = [0u32; 8];
            let mut weights = [0f32; 8];
            for c in 0..8usize {
                let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
                nodes[c] = ((at[2][dz] * g.n + at[1][dy]) * g.n + at[0][dx]) as u32;
                weights[c] = w[0][dx] * w[1][dy] * w[2][dz];
            }
            s.nodes.push(nodes);
            s.weights.push(weights);
            s.gamma.push(per_sample * count as f64);
        }
        s
    }
}

/// Bytes of one occupied voxel in a [`ScreenBuilder`]'s map (key, sums, count, and the map's
/// own overhead), and then in a [`Screen`].
pub const VOXEL_ENTRY_BYTES: u64 = 64;

/// The screening operator: per aggregate, its 8 grid nodes, their trilinear weights and its
/// weight `γ_a`.
#[derive(Debug, Default)]
pub struct Screen {
    nodes: Vec<[u32; 8]>,
    weights: Vec<[f32; 8]>,
    gamma: Vec<f64>,
}

impl Screen {
    /// The operator of the samples `pos` on `grid` with weight `alpha`.
    pub fn from_points(grid: &LocalGrid, pos: &[[f64; 3]], alpha: f64) -> Screen {
        let mut b = ScreenBuilder::new(grid);
        if alpha > 0.0 {
            b.add(pos);
        }
        b.finish(alpha)
    }

    /// True when nothing is screened (no samples, or a zero weight).
    pub fn is_empty(&self) -> bool {
        self.gamma.is_empty()
    }

    /// Number of aggregates.
    pub fn len(&self) -> usize {
        self.gamma.len()
    }

    /// `Σ γ_a`.
    pub fn gamma_sum(&self) -> f64 {
        self.gamma.iter().sum()
    }

    /// The weights `γ_a`.
    pub fn gamma(&self) -> &[f64] {
        &self.gamma
    }

    /// Each aggregate's 8 grid nodes.
    pub fn nodes(&self) -> &[[u32; 8]] {
        &self.nodes
    }

    /// Each aggregate's trilinear weights, by node.
    pub fn weights(&self) -> &[[f32; 8]] {
        &self.weights
    }

    /// `S v`: the grid values `v` interpolated at each aggregate.
    pub fn gather(&self, v: &[f32]) -> Vec<f64> {
        self.nodes
            .iter()
            .zip(&self.weights)
            .map(|(nodes, w)| {
                nodes
                    .iter()
                    .zip(w)
                    .map(|(&j, &wj)| wj as f64 * v[j as usize] as f64)
                    .sum()
            })
            .collect()
    }

    /// `out += Sᵀ coef`: each aggregate's `coef` spread over its nodes by its weights, in
    /// aggregate order (the same sums for any thread count).
    pub fn scatter_add(&self, coef: &[f64], out: &mut [f32]) {
        for ((nodes, w), &c) in self.nodes.iter().zip(&self.weights).zip(coef) {
            for (&j, &wj) in nodes.iter().zip(w) {
                out[j as usize] += (c * wj as f64) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> LocalGrid {
        LocalGrid {
            n: 8,
            h: 0.5,
            origin: [-2.0; 3],
            unit: 4.0,
        }
    }

    #[test]
    fn samples_of_one_voxel_become_one_aggregate_at_their_mean() {
        let g = grid();
        // Two samples in voxel (4, 4, 4) and one in voxel (1, 4, 4).
        let pos = [[0.1, 0.1, 0.1], [0.3, 0.2, 0.4], [-1.4, 0.2, 0.2]];
        let s = Screen::from_points(&g, &pos, 2.0);
        assert_eq!(s.len(), 2);
        // A linear function is interpolated exactly at the aggregates' mean positions.
        let f = |i: usize| {
            let (x, y, z) = (i % 8, (i / 8) % 8, i / 64);
            (x + 2 * y + 3 * z) as f32
        };
        let v: Vec<f32> = (0..512).map(f).collect();
        let at = s.gather(&v);
        let u =
            |p: [f64; 3]| (p[0] + 2.0) / 0.5 + 2.0 * (p[1] + 2.0) / 0.5 + 3.0 * (p[2] + 2.0) / 0.5;
        let mean = [0.2, 0.15, 0.25];
        assert!((at[0] - u([-1.4, 0.2, 0.2])).abs() < 1e-5, "{at:?}");
        assert!((at[1] - u(mean)).abs() < 1e-5, "{at:?}");
        // Weights: α/h² (cube units) per sample over the mean count, so the sum is
        // α/h² per occupied voxel.
        let h_u = 0.5 / 4.0;
        assert!((s.gamma_sum() - 2.0 * 2.0 / (h_u * h_u)).abs() < 1e-9);
        assert!((s.gamma()[1] / s.gamma()[0] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn the_dense_index_gathers_what_the_maps_gather() {
        let g = grid();
        // Points inside the grid and beyond it (wrapped), some sharing voxels; then voxel
        // sums on the grid's own lattice, one in a voxel the points hold.
        let pos: Vec<[f64; 3]> = (0..300)
            .map(|i| {
                let t = i as f64 * 0.618_033_988_7;
                [
                    -3.0 + 6.0 * t.fract(),
                    -2.0 + (t * 3.1).fract() * 3.0,
                    (t * 7.3).fract(),
                ]
            })
            .collect();
        let sums: Vec<VoxelSum> = [[1i64, 2, 3], [5, 5, 2], [1, 2, 3]]
            .iter()
            .enumerate()
            .map(|(i, &at)| VoxelSum {
                at,
                corner: [[0.0; 3]; 8],
                offset: [0.3 * i as f64, 0.5, 0.25],
                mean: [0.0; 3],
                count: 2 + i as u32,
            })
            .collect();
        let on = OnLattice {
            origin: [0; 3],
            step: 1,
        };
        let build = |mut b: ScreenBuilder| {
            b.add(&pos[..200]);
            b.add_voxels(on, &sums);
            b.add_parts(&[
                &ScreenBuilder::part(&g, &pos[200..250]),
                &ScreenBuilder::part(&g, &pos[250..]),
            ]);
            b.finish(2.0)
        };
        let (maps, dense) = (
            build(ScreenBuilder::new(&g)),
            build(ScreenBuilder::dense(&g)),
        );
        assert!(maps.len() > 50);
        assert_eq!(maps.nodes(), dense.nodes());
        assert_eq!(maps.weights(), dense.weights());
        assert_eq!(maps.gamma(), dense.gamma());
    }

    #[test]
    fn scatter_is_the_transpose_of_gather() {
        let g = grid();
        let pos: Vec<[f64; 3]> = (0..40)
            .map(|i| {
                let t = i as f64 * 0.37;
                [t.sin() * 1.7, (1.3 * t).cos() * 1.7, (0.7 * t).sin() * 1.9]
            })
            .collect();
        let s = Screen::from_points(&g, &pos, 1.0);
        let u: Vec<f32> = (0..512).map(|i| ((i * 37) % 19) as f32 - 9.0).collect();
        let c: Vec<f64> = (0..s.len()).map(|a| (a as f64 * 0.61).sin()).collect();
        // ⟨S u, c⟩ = ⟨u, Sᵀ c⟩.
        let lhs: f64 = s.gather(&u).iter().zip(&c).map(|(a, b)| a * b).sum();
        let mut st = vec![0f32; 512];
        s.scatter_add(&c, &mut st);
        let rhs: f64 = u.iter().zip(&st).map(|(a, b)| *a as f64 * *b as f64).sum();
        assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} {rhs}");
    }

    #[test]
    fn noise_is_read_back_from_samples_of_a_plane() {
        // 40K samples on the plane through the middle of a layer of fine voxels (h = 0.01)
        // with offsets of known spread s along z, normals up: the estimate reads s back (a
        // spread near a voxel is read low, cut by the voxels' faces).
        use rand::{Rng, SeedableRng};
        use rand_distr::StandardNormal;
        let h = 0.01;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(12345);
        for s in [0.0, 0.05, 0.15] {
            let mut pos = Vec::new();
            for _ in 0..40_000 {
                let g: f64 = rng.sample(StandardNormal);
                let (x, y) = (0.5 * rng.random::<f64>(), 0.5 * rng.random::<f64>());
                pos.push([x, y, 0.5 + (0.5 + s * g) * h]);
            }
            let nrm = vec![[0.0, 0.0, 1.0]; pos.len()];
            let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
            let got = st.sigma_voxels().unwrap();
            assert!((got - s).abs() <= 0.1 * s + 1e-9, "{s}: {got}");
            // The weight: 4 for noise at the reference, up to 32 for precise samples.
            let w = auto_point_weight(Some(got));
            assert!((BASE_POINT_WEIGHT..=32.0).contains(&w));
        }
        assert_eq!(auto_point_weight(None), BASE_POINT_WEIGHT);
        assert_eq!(auto_point_weight(Some(0.0)), 32.0);
        assert_eq!(auto_point_weight(Some(1.0)), BASE_POINT_WEIGHT);
        assert!((auto_point_weight(Some(0.1)) - 16.0).abs() < 1e-12);
    }

    /// `n` samples of the plane `z = 0.5 + s·h·g` over `[0, 0.5]²` (normals up), `g`
    /// standard normal.
    fn noisy_plane(n: usize, s: f64, h: f64, seed: u64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
        use rand::{Rng, SeedableRng};
        use rand_distr::StandardNormal;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let pos: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                let g: f64 = rng.sample(StandardNormal);
                [
                    0.5 * rng.random::<f64>(),
                    0.5 * rng.random::<f64>(),
                    0.5 + s * h * g,
                ]
            })
            .collect();
        (pos, vec![[0.0, 0.0, 1.0]; n])
    }

    #[test]
    fn jets_read_the_noise_a_voxel_cannot_hold() {
        // 20K samples on 2,500 voxels of a plane (8 a voxel): within a voxel the spread is
        // cut at 1/√12 voxel, about quadrics it is read back up to 1.6 voxels.
        let h = 0.01;
        for (seed, s) in [(1, 0.0), (2, 0.5), (3, 1.0), (4, 1.6)] {
            let (pos, nrm) = noisy_plane(20_000, s, h, seed);
            let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
            let jet = st.jet_sigma_voxels().unwrap();
            assert!((jet - s).abs() <= 0.1 * s + 1e-9, "{s}: {jet}");
            if s >= 1.0 {
                assert!(st.sigma_voxels().unwrap() < 0.3, "{s}: {st:?}");
            }
            assert!(st.jets[0].fits >= JET_MIN_FITS, "{st:?}");
        }
    }

    /// `n` samples of the relief `z = 0.5 + a h sin(2πx/λh) sin(2πy/λh)` over a 0.5-wide
    /// square (`λ` and `a` in voxels of `h`), with its exact normals, moved by noise of `s`
    /// voxels along each axis (as `scanflow synth` draws it: `s` across the surface
    /// wherever it faces).
    fn relief(n: usize, a: f64, lambda: f64, s: f64, h: f64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
        use rand::{Rng, SeedableRng};
        use rand_distr::StandardNormal;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let k = std::f64::consts::TAU / (lambda * h);
        (0..n)
            .map(|_| {
                let (x, y): (f64, f64) = (0.5 * rng.random::<f64>(), 0.5 * rng.random::<f64>());
                let g: [f64; 3] = [0; 3].map(|_| rng.sample(StandardNormal));
                let z = 0.5 + a * h * (k * x).sin() * (k * y).sin() + s * h * g[2];
                let gx = a * h * k * (k * x).cos() * (k * y).sin();
                let gy = a * h * k * (k * x).sin() * (k * y).cos();
                let l = (1.0 + gx * gx + gy * gy).sqrt();
                (
                    [x + s * h * g[0], y + s * h * g[1], z],
                    [(-gx / l) as f32, (-gy / l) as f32, (1.0 / l) as f32],
                )
            })
            .unzip()
    }

    #[test]
    fn pairs_read_the_noise_and_not_the_relief() {
        // 40K samples on 2,500 voxels (16 a voxel) of a relief of 1.5 voxels' amplitude and
        // 5 voxels' wavelength, tighter than a quadric on 1.5 voxels follows: the quadrics
        // read it as noise (1.01 voxel noise-free, 1.25 and 1.58 with noise of 0.5 and 1),
        // the pairs of close samples do not (0.00, 0.49, 1.02).
        let h = 0.01;
        for s in [0.0, 0.5, 1.0] {
            let (pos, nrm) = relief(40_000, 1.5, 5.0, s, h);
            let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
            let pairs = st.pair_sigma_voxels().unwrap();
            let jet = st.jet_sigma_voxels().unwrap();
            assert!((pairs - s).abs() <= 0.08 * s + 0.03, "{s}: pairs {pairs}");
            assert!(jet > s + 0.2, "{s}: jet {jet}");
            assert_eq!(st.noise_voxels(), Some(pairs));
            let share = st.noise_share().unwrap();
            assert!(
                (share - (pairs / jet).powi(2)).abs() < 1e-12 && share < 0.9,
                "{share}"
            );
        }
        // On a plane the pairs and the quadrics agree.
        let (pos, nrm) = noisy_plane(20_000, 0.8, h, 9);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let pairs = st.pair_sigma_voxels().unwrap();
        assert!((pairs - 0.8).abs() < 0.06, "{pairs}");
        assert!(st.noise_share().unwrap() > 0.9, "{st:?}");
        // 64 samples a voxel of area: every fourth of a disc's 450 is paired, and they read
        // the same noise.
        let (pos, nrm) = noisy_plane(160_000, 0.8, h, 12);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let dense = st.pair_sigma_voxels().unwrap();
        assert!((dense - 0.8).abs() < 0.06, "{dense}");
        // Too few samples for the pairs: the quadrics' figure stands in.
        let (pos, nrm) = noisy_plane(300, 0.8, h, 10);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        assert_eq!(st.pair_sigma_voxels(), None);
        assert_eq!(st.noise_voxels(), st.jet_sigma_voxels());
    }

    #[test]
    fn pairs_of_two_sheets_of_a_fold_do_not_read_as_noise() {
        // Two noisy planes 5 voxels apart, both facing up, as the sheets of a relief that
        // folds within a disc, the second with a fifteenth of the samples (as a fold's
        // far sheet holds a minority of a disc's): the pairs across the sheets differ by 5
        // voxels, and read as noise they would nearly double it. Cut at 2.5 standard deviations,
        // the estimate reads the noise of one sheet.
        let h = 0.01;
        for s in [0.3, 0.5, 0.7] {
            let (mut pos, mut nrm) = noisy_plane(20_000, s, h, 21);
            let (upper, up_nrm) = noisy_plane(1_300, s, h, 22);
            pos.extend(upper.iter().map(|p| [p[0], p[1], p[2] + 5.0 * h]));
            nrm.extend(up_nrm);
            let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
            let pairs = st.pair_sigma_voxels().unwrap();
            assert!((pairs - s).abs() < 0.06 * s, "{s}: {pairs}");
            let all = line(st.pairs.below(|_| f64::MAX)).unwrap().0.sqrt();
            assert!(all > 1.8 * s, "{s}: untrimmed {all}");
        }
    }

    #[test]
    fn a_volume_of_returns_reads_as_noise() {
        // A precise ground (0.05 voxel) under as many returns again scattered through the
        // 5 voxels above it, as airborne LiDAR over vegetation: most pairs lie beyond any
        // cut near the ground's noise, and the line through all of them stands.
        let h = 0.01;
        let (mut pos, mut nrm) = noisy_plane(20_000, 0.05, h, 23);
        let (canopy, up) = noisy_plane(20_000, 0.0, h, 24);
        let mut z = 0.0f64;
        pos.extend(canopy.iter().map(|p| {
            z = (z + 0.618_033_988_749_895) % 1.0;
            [p[0], p[1], p[2] + 5.0 * h * z]
        }));
        nrm.extend(up);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        let all = line(st.pairs.below(|_| f64::MAX)).unwrap().0.sqrt();
        let pairs = st.pair_sigma_voxels().unwrap();
        assert!(all > 1.0, "{all}");
        assert!((pairs - all).abs() < 1e-9 * all, "{pairs} against {all}");
    }

    #[test]
    fn the_trimmed_share_of_a_normal_variance() {
        // 1 − 2kφ(k)/(2Φ(k) − 1), from scipy.stats.norm.
        assert!((trimmed_variance_share(2.5) - 0.911_256_360_935_392).abs() < 1e-9);
        assert!((trimmed_variance_share(3.0) - 0.973_336_924_662_541_5).abs() < 1e-9);
        assert!((trimmed_variance_share(12.0) - 1.0).abs() < 1e-9);
        // The bins: each height difference in the bin whose edges hold it.
        for dh in [0.0, 0.009, 0.01, 0.0101, 0.3, 1.0, 4.7, 11.0] {
            let i = pair_bin(dh);
            let lo = if i == 0 { 0.0 } else { pair_bin_edge(i - 1) };
            assert!(lo <= dh && dh < pair_bin_edge(i), "{dh}: bin {i}");
        }
        assert_eq!(pair_bin(1e6), PAIR_BINS - 1);
        assert_eq!(pair_bin(f64::NAN), 0);
    }

    #[test]
    fn the_fit_allows_for_the_pairs_noise_where_samples_are_not_precise() {
        let h = 0.01;
        // Noise of 0.8 voxel: the spread within voxels stops near 0.29, the pairs read it.
        let (pos, nrm) = noisy_plane(20_000, 0.8, h, 11);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        assert!(st.sigma_voxels().unwrap() < 0.3);
        assert_eq!(st.fit_noise_voxels(), st.pair_sigma_voxels());
        // Precise samples keep the spread within voxels (the fit's reach asks for it).
        let (pos, nrm) = relief(40_000, 1.5, 8.0, 0.0, h);
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        assert!(st.sigma_voxels().unwrap() < PRECISE_WITHIN_VOXELS);
        assert_eq!(st.fit_noise_voxels(), st.sigma_voxels());
    }

    #[test]
    fn past_ten_million_points_a_share_of_the_cells_reads_the_same_noise() {
        assert_eq!(noise_cell_stride(0), 1);
        assert_eq!(noise_cell_stride(NOISE_FULL_RATE_POINTS), 1);
        assert_eq!(noise_cell_stride(NOISE_FULL_RATE_POINTS + 1), 2);
        assert_eq!(noise_cell_stride(100_000_000), 10);
        // 250K samples on 62,500 voxels of a plane (4 a voxel), noise of one voxel, in 50
        // stripes of 5,000 (store cells): every tenth stripe reads the spread of them all.
        let h = 0.002;
        let (mut pos, nrm) = noisy_plane(250_000, 1.0, h, 5);
        // Stripes along x, as a store's cells are boxes.
        pos.sort_by(|a, b| a[0].total_cmp(&b[0]));
        let mut full = NoiseStats::default();
        let mut thin = NoiseStats::default();
        for (j, (p, n)) in pos.chunks(5_000).zip(nrm.chunks(5_000)).enumerate() {
            let st = NoiseStats::of(p, n, [0.0; 3], h);
            if j % noise_cell_stride(100_000_000) == 0 {
                thin.add(st);
            }
            full.add(st);
        }
        let (a, b) = (full.jets[0].fits, thin.jets[0].fits);
        assert!(a >= 9 * b && b >= JET_MIN_FITS, "{a} {b}");
        for st in [&full, &thin] {
            let jet = st.jet_sigma_voxels().unwrap();
            assert!((jet - 1.0).abs() <= 0.1, "{jet}: {st:?}");
            let within = st.sigma_voxels().unwrap();
            assert!((0.25..0.3).contains(&within), "{within}: {st:?}");
        }
    }

    #[test]
    fn jets_follow_curvature() {
        // A noise-free sphere of radius 20 voxels, 8 samples a voxel of its area: the
        // quadrics leave almost nothing; a plane's fit would leave r²/(2R) ≈ 0.06 voxel.
        use rand::{Rng, SeedableRng};
        use rand_distr::StandardNormal;
        let (h, r) = (0.01, 0.2);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
        let mut pos = Vec::new();
        let mut nrm = Vec::new();
        for _ in 0..40_000 {
            let d: [f64; 3] = [0; 3].map(|_| rng.sample(StandardNormal));
            let l = dot(d, d).sqrt();
            let n = d.map(|x| x / l);
            pos.push([0, 1, 2].map(|a| 0.5 + r * n[a]));
            nrm.push(n.map(|x| x as f32));
        }
        let st = NoiseStats::of(&pos, &nrm, [0.0; 3], h);
        assert!(st.jet_sigma_voxels().unwrap() < 0.01, "{st:?}");
    }

    /// Pairs of close samples whose nugget is `sigma²` (squared voxels), on a line of slope
    /// 0.5 in the squared distance: one height difference at each distance, scaled by the
    /// share of a normal variance the trimmed estimate keeps, so that it reads `sigma`
    /// exactly (for `sigma` of 0.3 voxel or more, whose pairs all lie within its cut).
    fn pairs_reading(sigma: f64) -> PairStats {
        let share = trimmed_variance_share(PAIR_TRIM_SIGMAS);
        let mut p = PairStats::default();
        for i in 0..PAIR_MIN_COUNT as usize {
            let x = (i % 10) as f64 * 0.05;
            p.add_pair(x, (2.0 * share * (sigma * sigma + 0.5 * x)).sqrt());
        }
        p
    }

    /// Statistics reading `within` fine voxels, `jet` about quadrics (narrow and wide fits
    /// alike) and `pairs` between close samples.
    fn reading(within: f64, jet: f64, pairs: PairStats) -> NoiseStats {
        NoiseStats {
            sum_sq: within * within,
            dof: 1,
            jets: [JetStats {
                sum_sq: jet * jet,
                dof: 1,
                fits: JET_MIN_FITS,
            }; 2],
            pairs,
        }
    }

    #[test]
    fn the_weight_falls_with_noise_beyond_the_limit() {
        let noise = |sigma: f64, jet: f64| reading(sigma, jet, PairStats::default());
        let unmeasured = NoiseStats::default();
        assert_eq!(PointWeight::Standard.alpha(&unmeasured), BASE_POINT_WEIGHT);
        assert_eq!(PointWeight::Auto.alpha(&unmeasured), BASE_POINT_WEIGHT);
        // Up to the limit the default is 4 whatever the noise within voxels, beyond the
        // precise.
        assert_eq!(PointWeight::Standard.alpha(&noise(0.05, 0.8)), 4.0);
        assert_eq!(
            PointWeight::Standard.alpha(&noise(0.28, NOISE_LIMIT_VOXELS)),
            4.0
        );
        // Beyond it, 1/σ²: twice the limit, a quarter of the weight.
        let twice = noise(0.28, 2.0 * NOISE_LIMIT_VOXELS);
        assert!((PointWeight::Standard.alpha(&twice) - 1.0).abs() < 1e-12);
        // `auto` raises for precision within voxels and lowers for noise beyond them.
        assert!((PointWeight::Auto.alpha(&noise(0.1, 0.5)) - 16.0).abs() < 1e-12);
        assert!((PointWeight::Auto.alpha(&noise(0.1, 1.7)) - 4.0).abs() < 1e-12);
        // Precise within voxels, the quadrics' residual is relief they miss, not noise, and
        // the default doubles the weight.
        assert_eq!(
            PointWeight::Standard.alpha(&noise(0.02, 1.7)),
            PRECISE_POINT_WEIGHT
        );
        assert_eq!(PointWeight::Auto.alpha(&noise(0.02, 1.7)), 32.0);
        // Where pairs of close samples read the noise, they decide: a relief the quadrics
        // misread (1.7) under noise of 0.8 is not lowered as noise beyond the limit, only
        // to the relief's share of their residual ([`relief_weight`]); noise of twice the
        // limit, read by both, is all the residual, and is solved unscreened.
        let relief = NoiseStats {
            pairs: pairs_reading(0.8),
            ..noise(0.28, 1.7)
        };
        assert!((relief.noise_voxels().unwrap() - 0.8).abs() < 1e-9);
        let share = 0.8f64.powi(2) / 1.7f64.powi(2);
        assert!((PointWeight::Standard.alpha(&relief) - 4.0 * (1.0 - share)).abs() < 1e-9);
        let noisy = NoiseStats {
            pairs: pairs_reading(2.0 * NOISE_LIMIT_VOXELS),
            ..noise(0.28, 1.7)
        };
        assert!(PointWeight::Standard.alpha(&noisy).abs() < 1e-9);
        // A given weight is the weight.
        assert_eq!(PointWeight::Fixed(4.0).alpha(&twice), 4.0);
        assert_eq!(PointWeight::Fixed(0.0).alpha(&twice), 0.0);
    }

    #[test]
    fn noise_that_outweighs_the_relief_takes_the_weight_down_to_the_reliefs_share() {
        // Noise `pair` between close samples, `jet` about quadrics, 0.28 within voxels.
        let read = |pair: f64, jet: f64| reading(0.28, jet, pairs_reading(pair));
        let limit = crate::surface::fit::FIT_NOISE_LIMIT_VOXELS;
        // Up to the vertex fit's limit, the weight stays whatever the share.
        assert_eq!(relief_weight(&read(0.9 * limit, 0.9 * limit)), 1.0);
        assert!((PointWeight::Standard.alpha(&read(limit, limit)) - 4.0).abs() < 1e-9);
        // From the dominant noise on, all of the noise's share comes off: a plain noisy
        // surface (the pairs read the quadrics' residual) is solved unscreened, a relief
        // the quadrics miss keeps its part.
        let d = NOISE_DOMINANT_VOXELS;
        assert!(relief_weight(&read(d, d)).abs() < 1e-9);
        assert!((relief_weight(&read(d, 2.0 * d)) - 0.75).abs() < 1e-9);
        // In between, a linear share of it: halfway, half.
        let mid = 0.5 * (limit + d);
        assert!((relief_weight(&read(mid, mid)) - 0.5).abs() < 1e-9);
        assert!((PointWeight::Auto.alpha(&read(mid, mid)) - 2.0).abs() < 1e-9);
        // More relief, more weight: the weight grows as the quadrics read more.
        let w: Vec<f64> = [0.8, 1.0, 1.5, 3.0]
            .iter()
            .map(|&j| PointWeight::Standard.alpha(&read(0.8, j)))
            .collect();
        assert!(w.windows(2).all(|p| p[0] < p[1]), "{w:?}");
        // Unmeasured pairs or quadrics leave it; precise samples and a given weight ignore it.
        let no_pairs = NoiseStats {
            pairs: PairStats::default(),
            ..read(d, d)
        };
        assert_eq!(relief_weight(&no_pairs), 1.0);
        let precise = NoiseStats {
            sum_sq: 0.01 * 0.01,
            ..read(d, d)
        };
        assert_eq!(PointWeight::Standard.alpha(&precise), PRECISE_POINT_WEIGHT);
        assert_eq!(PointWeight::Fixed(4.0).alpha(&read(d, d)), 4.0);
    }

    #[test]
    fn the_smoothing_follows_the_precision() {
        let within = |sigma: f64| NoiseStats {
            sum_sq: sigma * sigma,
            dof: 1,
            ..NoiseStats::default()
        };
        // Unmeasured: Kazhdan's voxel.
        assert_eq!(
            Smoothing::Measured.voxels(&NoiseStats::default(), None),
            1.0
        );
        // Precise samples take the narrowest, noise at the reference and beyond one voxel,
        // in between the spread over the reference.
        assert_eq!(
            Smoothing::Measured.voxels(&within(0.0), None),
            SMOOTH_PRECISE_VOXELS
        );
        assert_eq!(
            Smoothing::Measured.voxels(&within(0.02), None),
            SMOOTH_PRECISE_VOXELS
        );
        assert!((Smoothing::Measured.voxels(&within(0.14), None) - 0.7).abs() < 1e-12);
        assert_eq!(Smoothing::Measured.voxels(&within(0.2), None), 1.0);
        assert_eq!(Smoothing::Measured.voxels(&within(0.29), None), 1.0);
        // Noise beyond the limit about quadrics keeps one voxel, unless precise within.
        let rough = |sigma: f64| NoiseStats {
            jets: [JetStats {
                sum_sq: 4.0,
                dof: 1,
                fits: JET_MIN_FITS,
            }; 2],
            ..within(sigma)
        };
        assert_eq!(Smoothing::Measured.voxels(&rough(0.099), None), 1.0);
        // Under the limit, the width narrows by the share of the quadrics' residual that
        // pairs of close samples read as noise: 0.8 of 1.0 (0.64), 0.8 of 2.0 (0.16, so
        // the narrowest); all of it where the pairs read as much as the quadrics.
        let relief = |pairs: f64| NoiseStats {
            pairs: pairs_reading(pairs),
            ..rough(0.28)
        };
        let share = |jet: f64| NoiseStats {
            jets: [JetStats {
                sum_sq: jet * jet,
                dof: 1,
                fits: JET_MIN_FITS,
            }; 2],
            ..relief(0.8)
        };
        assert!((Smoothing::Measured.voxels(&share(1.0), None) - 0.64).abs() < 1e-9);
        assert_eq!(
            Smoothing::Measured.voxels(&share(2.0), None),
            SMOOTH_PRECISE_VOXELS
        );
        assert!((Smoothing::Measured.voxels(&share(0.7), None) - 1.0).abs() < 1e-9);
        // Pairs reading noise beyond the limit: one voxel.
        assert_eq!(Smoothing::Measured.voxels(&relief(1.9), None), 1.0);
        assert_eq!(
            Smoothing::Measured.voxels(&rough(0.02), None),
            SMOOTH_PRECISE_VOXELS
        );
        // A given width is the width.
        assert_eq!(Smoothing::Fixed(2.5).voxels(&within(0.0), None), 2.5);
        // Sparse samples widen the measured width to 0.4 of their spacing, up to 4 voxels;
        // dense ones keep it; a given width stays.
        assert_eq!(
            Smoothing::Measured.voxels(&within(0.0), Some(0.5)),
            SMOOTH_PRECISE_VOXELS
        );
        assert_eq!(Smoothing::Measured.voxels(&within(0.2), Some(2.0)), 1.0);
        assert!((Smoothing::Measured.voxels(&within(0.0), Some(7.5)) - 3.0).abs() < 1e-12);
        assert!((Smoothing::Measured.voxels(&within(0.2), Some(5.0)) - 2.0).abs() < 1e-12);
        assert_eq!(
            Smoothing::Measured.voxels(&within(0.0), Some(40.0)),
            SPARSE_MAX_VOXELS
        );
        assert_eq!(Smoothing::Fixed(0.5).voxels(&within(0.0), Some(7.5)), 0.5);
        assert_eq!(Smoothing::Measured.to_string(), "measured");
    }

    #[test]
    fn noise_stats_need_two_samples_in_a_voxel() {
        let pos = [[0.05, 0.05, 0.05], [0.15, 0.05, 0.05]];
        let st = NoiseStats::of(&pos, &[[0.0, 0.0, 1.0]; 2], [0.0; 3], 0.1);
        assert_eq!(st.sigma_voxels(), None);
        // Opposite normals in one voxel: a thin sheet, not noise.
        let pos = [[0.05, 0.05, 0.04], [0.05, 0.05, 0.06]];
        let st = NoiseStats::of(&pos, &[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], [0.0; 3], 0.1);
        assert_eq!(st.sigma_voxels(), None);
    }

    #[test]
    fn a_zero_weight_screens_nothing() {
        assert!(Screen::from_points(&grid(), &[[0.0; 3]], 0.0).is_empty());
    }
}
