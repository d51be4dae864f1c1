//! The noise statistics of the samples, which the screening weight ([`crate::weight`]) and
//! the vertex fit ([`crate::surface::fit`]) follow: the spread within fine voxels, the
//! residual about local quadrics and the spread between pairs of close samples, with the
//! limits they are read against (one set of constants, shared by the solver and the fit).
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

use crate::geom::{dot, plane_basis};
use crate::types::floor;

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

/// The factor noise `sigma` ([`NoiseStats::noise_voxels`]) beyond [`NOISE_LIMIT_VOXELS`]
/// lowers the weight by: `min(1, (σ_lim/σ)²)`; 1 where the noise was not measured, or where
/// the spread `within` fine voxels is under [`PRECISE_WITHIN_VOXELS`].
pub fn noise_limit(within: Option<f64>, sigma: Option<f64>) -> f64 {
    match sigma {
        Some(s) if s > NOISE_LIMIT_VOXELS && !precise(within) => (NOISE_LIMIT_VOXELS / s).powi(2),
        _ => 1.0,
    }
}

/// Whether samples whose spread `within` fine voxels was measured are precise (under
/// [`PRECISE_WITHIN_VOXELS`]).
pub(crate) fn precise(within: Option<f64>) -> bool {
    within.is_some_and(|w| w < PRECISE_WITHIN_VOXELS)
}

/// Samples whose noise ([`NoiseStats::fit_noise_voxels`]) reaches
/// this many fine voxels move no vertex. The smoothed field has then averaged as many
/// samples as the fit's [`crate::surface::fit::FIT_NEIGHBOURS`], or more, and the fit's own error only adds to
/// it. Measured at depth 9 (mean distance to the exact surface ·10⁻⁴, fitted → unfitted;
/// noise in voxels as read between close samples): a 1% relief of 12 voxels' wavelength at
/// noise 0.25: 4.98 → 4.82, 0.5: 6.24 → 5.92, 0.8: 8.23 → 7.89; of 8 voxels at 0.8: 11.3 →
/// 10.6; a plain sphere at 0.5: 3.500 → 3.494. The raw bunny scans (0.2 voxel at depth
/// 8) are fitted: two-sided distance to `bun_zipper` 8.70 and 4.52·10⁻⁵, unfitted 9.36 and
/// 5.46.
pub const FIT_NOISE_LIMIT_VOXELS: f64 = 0.35;

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
pub(crate) fn line(s: [f64; 5]) -> Option<(f64, f64)> {
    let [n, sx, sxx, sy, sxy] = s;
    let det = n * sxx - sx * sx;
    (n >= PAIR_MIN_COUNT && det > 1e-12 * n * sxx)
        .then(|| ((sxx * sy - sx * sxy) / det, (n * sxy - sx * sy) / det))
}

impl PairStats {
    pub(crate) fn add_pair(&mut self, x: f64, dh: f64) {
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

#[cfg(test)]
mod tests;
