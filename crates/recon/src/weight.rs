//! The screening weight policy (Kazhdan & Hoppe 2013, §4): how the weight α of
//! [`crate::screen`] and the width of the Gaussian that smooths the normal field follow the
//! noise measured in [`crate::noise`] ([`PointWeight`], [`Smoothing`]).
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
//!   ([`crate::noise::FIT_NOISE_LIMIT_VOXELS`], 0.35 voxel) to 1 at
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
//!
//! All are one number per run, from every point in a fixed order: the coarse and the leaf
//! solves, and any thread count, tile size or shard, share it. Where nothing could be
//! measured (sparse samples) α = 4. The Gaussian that smooths the normal field is chosen
//! the same way, one width per run from the spread within voxels and the share of the
//! quadrics' residual that is noise ([`Smoothing`]): the screening pulls the surface to the
//! samples, the Gaussian decides how much of the normals' detail there is to pull to.

use crate::noise::*;

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

/// The weight the default takes for precise samples (under [`PRECISE_WITHIN_VOXELS`] within
/// fine voxels): twice the base, where `auto` goes to 32. Measured on the precise relief
/// spheres (1M points, depth 9, 1% amplitude, the measured smoothing of 0.35 voxel; mean
/// distance ·10⁻⁴, α = 4 → 8, PoissonRecon in brackets): 8 voxels' wavelength 5.84 → 5.40
/// (5.70), 12 voxels 2.44 → 2.28 (2.83), 18 voxels 0.98 → 0.95 (1.30), 30 voxels 0.29 →
/// 0.28 (0.48), for 5.3 conjugate-gradient steps a leaf against 4.9.
pub const PRECISE_POINT_WEIGHT: f64 = 8.0;

/// The noise across the surface ([`NoiseStats::noise_voxels`]), in fine voxels, from which
/// [`relief_weight`] takes the screening weight down to the relief's share in full; it
/// begins at [`crate::noise::FIT_NOISE_LIMIT_VOXELS`], the noise at which the vertex
/// fit stops. Measured (module docs): with 0.85, the plain sphere with noise of 0.8 voxel
/// (α = 0.33) came out at 2.8·10⁻⁴ against 2.3 (α = 0), the relief of 30 voxels'
/// wavelength at 0.5% amplitude at 3.2·10⁻⁴ against 2.7.
pub const NOISE_DOMINANT_VOXELS: f64 = 0.75;

/// The factor by which noise that outweighs the relief lowers the screening weight (module
/// docs): `1 − w·s`, with `s` the noise's share of the quadrics' residual
/// ([`NoiseStats::noise_share`]) and `w` rising linearly from 0 at
/// [`crate::noise::FIT_NOISE_LIMIT_VOXELS`] of noise ([`NoiseStats::noise_voxels`]) to
/// 1 at [`NOISE_DOMINANT_VOXELS`]; 1 where either figure is unmeasured.
pub fn relief_weight(noise: &NoiseStats) -> f64 {
    let (Some(sigma), Some(share)) = (noise.noise_voxels(), noise.noise_share()) else {
        return 1.0;
    };
    let from = crate::noise::FIT_NOISE_LIMIT_VOXELS;
    let w = ((sigma - from) / (NOISE_DOMINANT_VOXELS - from)).clamp(0.0, 1.0);
    1.0 - w * share
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

#[cfg(test)]
mod tests;
