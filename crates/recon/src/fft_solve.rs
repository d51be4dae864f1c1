//! The local Poisson solve by FFT (Kazhdan 2005, §4; Schall et al. 2006, §3).
//!
//! Given oriented samples, the indicator function χ of the solid satisfies
//! `Δχ = ∇·V`, where `V` is the (smoothed) field of outward normals. On a periodic grid of
//! `n³` nodes with spacing `h` the normals are splatted trilinearly onto nodes as a density
//! (`V_j = Σ_i n_i w_ij / h³`, so that grids of different spacing approximate the same
//! continuous field), the divergence is taken by central differences, and in the Fourier
//! domain
//!
//! ```text
//!     χ̂(k) = − G_σ(k) · (∇·V)^(k) / |k|²,      G_σ(k) = exp(−σ²|k|²/2),   χ̂(0) = 0,
//! ```
//!
//! with `k = 2π m / (n h)` for the signed frequency index `m`. With outward normals χ is
//! **lower inside** the surface. `σ` is given in voxels of the grid being solved (`σ = 1`:
//! measured on synthetic spheres, σ = 0.5 gave 1.8× the mean error and σ = 2 merged sheets
//! 2.5 voxels apart). The forward transform is unnormalised; the inverse divides by
//! `n³`. Node `i` of a grid sits at `origin + h·i` (values are node samples, never cell
//! centres: reading them as cell centres shifts the surface by half a voxel).
//!
//! **Scale.** Lengths in these formulas (`h`, `k`) are measured in the grid's `unit` (the
//! octree cube's edge for every grid of a run), not in input units: χ scales as
//! `1/length²`, so in input units an input a few 1e-30 across gives `1/h³` beyond float32
//! (NaN fields) and one 1e30 across gives zero. In cube units every input gives the same
//! numbers as its scaled copy, and all grids of a run still share one continuous field.
//! Positions enter only as offsets from a grid's origin, in input units.
//!
//! **Screening** (Kazhdan & Hoppe 2013, §4; [`super::screen`]). The screened solve
//! ([`Solver::solve_screened`]) minimises `∫|∇χ − V|² + Σ γ_a (χ(p_a) − c)²` on the same
//! grid: `(L + Sᵀ Γ S) χ = b + Sᵀ Γ c` with `L` the spectral Laplacian above (symbol `|k|²`,
//! so that with no screening it is exactly the solve above) and `S` the trilinear weights at
//! the (aggregated) samples. The FFT solve stays the fast inverse: it gives the first iterate
//! and preconditions the conjugate gradients, whose iteration count follows from the measured
//! residual ([`SCREEN_TOLERANCE`]).

use std::sync::Arc;

use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

pub use super::grid::{LocalGrid, SplatBox, add_boxes, splat, splat_box};
use super::screen::Screen;

/// Solve for the smoothed indicator on `grid` from points `pos` with outward unit normals
/// `nrm`; returns node values (x fastest). `sigma_vox` is the Gaussian width in voxels.
pub fn solve(grid: &LocalGrid, pos: &[[f64; 3]], nrm: &[[f32; 3]], sigma_vox: f64) -> Vec<f32> {
    Solver::new(grid, sigma_vox).solve(grid, pos, nrm)
}

/// Solve from splatted normals (consumed).
pub fn solve_splatted(grid: &LocalGrid, v: Vec<[f32; 3]>, sigma_vox: f64) -> Vec<f32> {
    Solver::new(grid, sigma_vox).solve_splatted(grid, v)
}

/// The factor by which a screened solve reduces its preconditioned residual norm. Measured on
/// a sphere of 1M points carrying a relief of 1% of its radius and 18 voxels' wavelength at
/// depth 9, without and with noise 0.001: 0.1 (about 4 and 6 iterations a leaf) gives the
/// mean distance to the exact surface of 0.001 (13 iterations) within 1%; 0.3 (2
/// iterations) is 17% farther.
pub const SCREEN_TOLERANCE: f64 = 0.1;

/// The preconditioner's shift `μ` as a share of the screening's mean diagonal `Σ γ / n³`:
/// the screening sits on the surface, a few percent of the nodes, so the mean overstates it
/// everywhere else. Measured on the same spheres at a tolerance of 0.01: 1/16 takes 7.4
/// iterations a leaf, 1 takes 9.7, 4 takes 12, 1/100 takes 8.2.
pub(crate) const PRECONDITIONER_SHIFT: f64 = 1.0 / 16.0;

/// Iterations a screened solve never exceeds, whatever its residual.
pub const SCREEN_MAX_ITERATIONS: u32 = 100;

/// How a screened solve ended.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Convergence {
    /// Conjugate-gradient iterations run.
    pub iterations: u32,
    /// Preconditioned residual norm at the end, relative to the start.
    pub residual: f64,
}

/// A multiplier of the spectrum by folded frequency indices `|mz|, |my|, kx` (each below
/// `h1 = n/2 + 1`), tabulated z fastest ([`table_index`]): the order in which
/// [`Solver::spectral`]'s z rows meet it.
fn tabulate(h1: usize, f: impl Fn(usize, usize, usize) -> f32) -> Vec<f32> {
    let mut t = Vec::with_capacity(h1 * h1 * h1);
    for fy in 0..h1 {
        for kx in 0..h1 {
            for fz in 0..h1 {
                t.push(f(fz, fy, kx));
            }
        }
    }
    t
}

/// Where [`tabulate`] puts the multiplier of `|mz|, |my|, kx`.
fn table_index(h1: usize, fz: usize, fy: usize, kx: usize) -> usize {
    (fy * h1 + kx) * h1 + fz
}

/// `Σ a_i b_i` in f64, summed per slab of `slab` values and then over slabs in order: the
/// same bits for any thread count.
fn dot(a: &[f32], b: &[f32], slab: usize) -> f64 {
    let parts: Vec<f64> = a
        .par_chunks(slab)
        .zip(b.par_chunks(slab))
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum())
        .collect();
    parts.iter().sum()
}

/// What every solve on grids of one size and spacing shares: the FFT plans and the filter
/// `−G_σ(k)/|k|²`, tabulated once over `|m|` per axis (`(n/2 + 1)³` values; the filter is
/// even in each frequency index). Build one per grid shape and reuse it across leaves.
///
/// The divergence is real and the filter real and even, so the solution is real: the
/// transform is real-to-complex along x (`n/2 + 1` frequencies a row, Hermitian symmetry
/// gives the rest), complex along y and z, which halves the work and the buffer of a
/// complex transform. The z transforms run on a transposed copy, one contiguous row per
/// `(y, kx)`, filtered and transformed back while the row is in cache.
pub struct Solver {
    n: usize,
    h: f64,
    unit: f64,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    fwd: Arc<dyn Fft<f32>>,
    inv: Arc<dyn Fft<f32>>,
    /// The filter by folded indices `a = min(m, n − m)`, laid out by [`tabulate`].
    filter: Vec<f32>,
    /// `|k|²` per axis by folded index (cube units): the Laplacian's symbol is their sum.
    k2: Vec<f32>,
}

impl Solver {
    /// Plans and filter for grids of `grid.n` nodes and spacing `grid.h`.
    pub fn new(grid: &LocalGrid, sigma_vox: f64) -> Solver {
        let n = grid.n;
        let mut planner = FftPlanner::<f32>::new();
        let fwd = planner.plan_fft_forward(n);
        let inv = planner.plan_fft_inverse(n);
        let mut real_planner = RealFftPlanner::<f32>::new();
        let r2c = real_planner.plan_fft_forward(n);
        let c2r = real_planner.plan_fft_inverse(n);
        let h_u = grid.h / grid.unit;
        let two_pi_over_l = 2.0 * std::f64::consts::PI / (n as f64 * h_u);
        let sigma = sigma_vox * h_u;
        let h1 = n / 2 + 1;
        // k² by folded index: m and n − m have the same |k|.
        let k2: Vec<f64> = (0..h1)
            .map(|m| {
                let k = m as f64 * two_pi_over_l;
                k * k
            })
            .collect();
        let filter = tabulate(h1, |fz, fy, kx| {
            let kk = k2[kx] + k2[fy] + k2[fz];
            if kk == 0.0 {
                return 0.0;
            }
            let g = (-(0.5 * sigma * sigma * kk)).exp() / kk;
            -(g as f32)
        });
        Solver {
            n,
            h: grid.h,
            unit: grid.unit,
            r2c,
            c2r,
            fwd,
            inv,
            filter,
            k2: k2.iter().map(|&k| k as f32).collect(),
        }
    }

    /// Splat `pos`/`nrm` onto `grid` (which must have this solver's size and spacing) and
    /// solve.
    pub fn solve(&self, grid: &LocalGrid, pos: &[[f64; 3]], nrm: &[[f32; 3]]) -> Vec<f32> {
        let mut v = vec![[0f32; 3]; grid.len()];
        splat(grid, pos, nrm, &mut v);
        self.solve_splatted(grid, v)
    }

    /// Splat `pos`/`nrm` onto `grid` and solve, screened by the samples themselves with weight
    /// `alpha` (0: unscreened).
    pub fn solve_points(
        &self,
        grid: &LocalGrid,
        pos: &[[f64; 3]],
        nrm: &[[f32; 3]],
        alpha: f64,
    ) -> (Vec<f32>, Convergence) {
        let mut v = vec![[0f32; 3]; grid.len()];
        splat(grid, pos, nrm, &mut v);
        self.solve_screened(grid, v, &Screen::from_points(grid, pos, alpha))
    }

    /// Solve from splatted normals (consumed) on `grid`, of this solver's size and spacing.
    pub fn solve_splatted(&self, grid: &LocalGrid, v: Vec<[f32; 3]>) -> Vec<f32> {
        assert!(
            grid.n == self.n && grid.h == self.h && grid.unit == self.unit,
            "a solver for {}³ nodes at spacing {} used on {}³ at {}",
            self.n,
            self.h,
            grid.n,
            grid.h
        );
        let div = self.divergence(grid, v);
        self.solve_divergence(&div)
    }

    /// Solve from the divergence of the splatted normals ([`Solver::divergence`]).
    pub fn solve_divergence(&self, div: &[f32]) -> Vec<f32> {
        self.spectral(div, true, &self.filter)
    }

    /// The divergence of splatted normals `v` (consumed) by central differences, in cube
    /// units: the right-hand side of the solve. The splat is dropped on return, so a solve
    /// peaks at the splat plus the divergence (16 bytes a node); the transform itself needs
    /// about 8.
    pub fn divergence(&self, grid: &LocalGrid, v: Vec<[f32; 3]>) -> Vec<f32> {
        let n = self.n;
        let len = grid.len();
        let half_inv_h = (0.5 * grid.unit / grid.h) as f32;
        let mut div = vec![0f32; len];
        div.par_chunks_mut(n * n).enumerate().for_each(|(z, slab)| {
            let zp = (z + 1) % n;
            let zm = (z + n - 1) % n;
            let row = |y: usize, z: usize| &v[(z * n + y) * n..(z * n + y + 1) * n];
            for y in 0..n {
                let yp = (y + 1) % n;
                let ym = (y + n - 1) % n;
                let (r, ryp, rym) = (row(y, z), row(yp, z), row(ym, z));
                let (rzp, rzm) = (row(y, zp), row(y, zm));
                for (x, out) in slab[y * n..(y + 1) * n].iter_mut().enumerate() {
                    let xp = if x + 1 == n { 0 } else { x + 1 };
                    let xm = if x == 0 { n - 1 } else { x - 1 };
                    let d =
                        (r[xp][0] - r[xm][0]) + (ryp[x][1] - rym[x][1]) + (rzp[x][2] - rzm[x][2]);
                    *out = d * half_inv_h;
                }
            }
        });
        div
    }

    /// Nodes per axis of the grids this solver solves.
    pub fn n(&self) -> usize {
        self.n
    }

    /// What a solve on the device needs of this solver: the nodes per axis, `|k|²` by
    /// folded index (`n/2 + 1` values) and the Poisson filter (`(n/2 + 1)³` values, at
    /// `(az·(n/2+1) + ay)·(n/2+1) + ax`).
    pub fn tables(&self) -> (usize, &[f32], Vec<f32>) {
        let h1 = self.n / 2 + 1;
        let filter = (0..h1 * h1 * h1)
            .map(|i| {
                let (z, y, x) = (i / (h1 * h1), (i / h1) % h1, i % h1);
                self.filter[table_index(h1, z, y, x)]
            })
            .collect();
        (self.n, &self.k2, filter)
    }

    /// The screened solve (see [`super::screen`]): `(L + Sᵀ Γ S) χ = b + Sᵀ Γ c` by
    /// conjugate gradients preconditioned with the FFT inverse of `L + μ`, `μ` a share
    /// (`PRECONDITIONER_SHIFT`) of the screening's mean diagonal `Σ γ / n³`, which also
    /// fixes the constant that `L` leaves free.
    /// Starts from the unscreened solution, whose residual is the screening term alone, and
    /// stops when the preconditioned residual `rᵀ M⁻¹ r` has fallen by [`SCREEN_TOLERANCE`]²
    /// (or after [`SCREEN_MAX_ITERATIONS`]). One transform pair an iteration: the Laplacian
    /// of the preconditioned residual is `r − μ z`, and that of the search direction follows
    /// from it by the same recurrence as the direction. Every sum runs in a fixed order, so
    /// the result is the same for any thread count. With no screening, the unscreened solve.
    pub fn solve_screened(
        &self,
        grid: &LocalGrid,
        v: Vec<[f32; 3]>,
        screen: &Screen,
    ) -> (Vec<f32>, Convergence) {
        self.solve_screened_to(grid, v, screen, SCREEN_TOLERANCE)
    }

    /// [`Solver::solve_screened`] stopping at relative residual `tolerance`.
    pub fn solve_screened_to(
        &self,
        grid: &LocalGrid,
        v: Vec<[f32; 3]>,
        screen: &Screen,
        tolerance: f64,
    ) -> (Vec<f32>, Convergence) {
        let x = self.solve_splatted(grid, v);
        self.screen_from(x, screen, tolerance)
    }

    /// [`Solver::solve_screened`] from the divergence of the splatted normals (what a device
    /// solve that failed leaves to the CPU).
    pub fn solve_screened_divergence(
        &self,
        div: &[f32],
        screen: &Screen,
    ) -> (Vec<f32>, Convergence) {
        self.screen_from(self.solve_divergence(div), screen, SCREEN_TOLERANCE)
    }

    /// The conjugate gradients of [`Solver::solve_screened`] from the unscreened solution `x`.
    fn screen_from(
        &self,
        mut x: Vec<f32>,
        screen: &Screen,
        tolerance: f64,
    ) -> (Vec<f32>, Convergence) {
        if screen.is_empty() {
            return (x, Convergence::default());
        }
        let n = self.n;
        let slab = n * n;
        let gamma = screen.gamma();
        let at = screen.gather(&x);
        let gsum = screen.gamma_sum();
        let c = gamma.iter().zip(&at).map(|(g, v)| g * v).sum::<f64>() / gsum;
        let mut r = vec![0f32; x.len()];
        let coef: Vec<f64> = gamma.iter().zip(&at).map(|(g, v)| -g * (v - c)).collect();
        screen.scatter_add(&coef, &mut r);
        let mu = (PRECONDITIONER_SHIFT * gsum / x.len() as f64) as f32;
        // The preconditioner's multipliers, tabulated once a solve in the filter's order
        // (a division per frequency of every transform was a twentieth of the leaf stage).
        let k2 = &self.k2;
        let inverse = tabulate(n / 2 + 1, |fz, fy, kx| {
            1.0 / (k2[fz] + k2[fy] + k2[kx] + mu)
        });
        let precondition = |r: &[f32]| self.spectral(r, false, &inverse);
        let mut z = precondition(&r);
        let mut p = z.clone();
        let mut lp: Vec<f32> = r.iter().zip(&z).map(|(r, z)| r - mu * z).collect();
        let mut rz = dot(&r, &z, slab);
        let rz0 = rz;
        let mut iterations = 0;
        let tol2 = tolerance * tolerance;
        while rz > tol2 * rz0 && iterations < SCREEN_MAX_ITERATIONS {
            let sp = screen.gather(&p);
            let pap =
                dot(&p, &lp, slab) + gamma.iter().zip(&sp).map(|(g, s)| g * s * s).sum::<f64>();
            if pap.is_nan() || pap <= 0.0 {
                break;
            }
            let a = rz / pap;
            let af = a as f32;
            x.par_chunks_mut(slab)
                .zip(p.par_chunks(slab))
                .for_each(|(x, p)| x.iter_mut().zip(p).for_each(|(x, p)| *x += af * p));
            r.par_chunks_mut(slab)
                .zip(lp.par_chunks(slab))
                .for_each(|(r, l)| r.iter_mut().zip(l).for_each(|(r, l)| *r -= af * l));
            let coef: Vec<f64> = gamma.iter().zip(&sp).map(|(g, s)| -a * g * s).collect();
            screen.scatter_add(&coef, &mut r);
            z = precondition(&r);
            let rz_new = dot(&r, &z, slab);
            let beta = (rz_new / rz) as f32;
            p.par_chunks_mut(slab)
                .zip(lp.par_chunks_mut(slab))
                .zip(z.par_chunks(slab).zip(r.par_chunks(slab)))
                .for_each(|((p, lp), (z, r))| {
                    for i in 0..p.len() {
                        p[i] = z[i] + beta * p[i];
                        lp[i] = (r[i] - mu * z[i]) + beta * lp[i];
                    }
                });
            rz = rz_new;
            iterations += 1;
        }
        let residual = if rz0 > 0.0 { (rz / rz0).sqrt() } else { 0.0 };
        (
            x,
            Convergence {
                iterations,
                residual,
            },
        )
    }

    /// Multiply the spectrum of the real grid `input` by the table `mul` ([`tabulate`], by
    /// folded frequency indices), zero the mean when `zero_mean`, and transform back.
    fn spectral(&self, input: &[f32], zero_mean: bool, mul: &[f32]) -> Vec<f32> {
        let n = self.n;
        let len = n * n * n;
        let h1 = n / 2 + 1;
        let zero = Complex32::new(0.0, 0.0);
        let lengths = "buffer lengths follow the plans";
        // x: real to complex, row by row, into spec[z][y][kx].
        let mut spec = vec![zero; n * n * h1];
        spec.par_chunks_mut(n * h1)
            .zip(input.par_chunks(n * n))
            .for_each_init(
                || (self.r2c.make_scratch_vec(), vec![0f32; n]),
                |(s, row), (out, inp)| {
                    for (o, i) in out.chunks_exact_mut(h1).zip(inp.chunks_exact(n)) {
                        // The transform uses its input as scratch: a copy of the row.
                        row.copy_from_slice(i);
                        self.r2c.process_with_scratch(row, o, s).expect(lengths);
                    }
                },
            );
        self.along_y(&mut spec, &self.fwd);
        // z: transposed to t[y][kx][z], transformed, filtered, transformed back, and
        // transposed home.
        let fold = |m: usize| if m <= n / 2 { m } else { n - m };
        let mut t = vec![zero; n * h1 * n];
        t.par_chunks_mut(h1 * n).enumerate().for_each(|(y, block)| {
            for z in 0..n {
                let row = &spec[(z * n + y) * h1..(z * n + y + 1) * h1];
                for (kx, &c) in row.iter().enumerate() {
                    block[kx * n + z] = c;
                }
            }
        });
        t.par_chunks_mut(h1 * n).enumerate().for_each_init(
            || vec![zero; self.fwd.get_inplace_scratch_len()],
            |s, (y, block)| {
                self.fwd.process_with_scratch(block, s);
                let fy = fold(y);
                for (kx, row) in block.chunks_exact_mut(n).enumerate() {
                    // Row z takes the multiplier of |mz| = min(z, n − z).
                    let at = table_index(h1, 0, fy, kx);
                    let m = &mul[at..at + h1];
                    let (lo, hi) = row.split_at_mut(h1);
                    for (c, &f) in lo.iter_mut().zip(m) {
                        *c *= f;
                    }
                    for (c, &f) in hi.iter_mut().zip(m[1..=n - h1].iter().rev()) {
                        *c *= f;
                    }
                }
                if y == 0 && zero_mean {
                    block[0] = zero;
                }
                self.inv.process_with_scratch(block, s);
            },
        );
        spec.par_chunks_mut(n * h1)
            .enumerate()
            .for_each(|(z, slab)| {
                for (y, row) in slab.chunks_exact_mut(h1).enumerate() {
                    for (kx, c) in row.iter_mut().enumerate() {
                        *c = t[(y * h1 + kx) * n + z];
                    }
                }
            });
        drop(t);
        self.along_y(&mut spec, &self.inv);
        // x: complex to real. The spectrum of a real row has real values at kx = 0 (and at
        // n/2 for even n); rounding leaves tiny imaginary parts there, which are dropped.
        let norm = 1.0 / len as f32;
        let mut out = vec![0f32; len];
        out.par_chunks_mut(n * n)
            .zip(spec.par_chunks_mut(n * h1))
            .for_each_init(
                || self.c2r.make_scratch_vec(),
                |s, (o, sp)| {
                    for (orow, srow) in o.chunks_exact_mut(n).zip(sp.chunks_exact_mut(h1)) {
                        srow[0].im = 0.0;
                        if n.is_multiple_of(2) {
                            srow[h1 - 1].im = 0.0;
                        }
                        self.c2r.process_with_scratch(srow, orow, s).expect(lengths);
                        for v in orow {
                            *v *= norm;
                        }
                    }
                },
            );
        out
    }

    /// Transform `spec[z][y][kx]` along y with `fft`, slab by slab (each slab gathered into
    /// contiguous columns and scattered back).
    fn along_y(&self, spec: &mut [Complex32], fft: &Arc<dyn Fft<f32>>) {
        let n = self.n;
        let h1 = n / 2 + 1;
        let zero = Complex32::new(0.0, 0.0);
        spec.par_chunks_mut(n * h1).for_each_init(
            || {
                (
                    vec![zero; n * h1],
                    vec![zero; fft.get_inplace_scratch_len()],
                )
            },
            |(cols, s), slab| {
                for (y, row) in slab.chunks_exact(h1).enumerate() {
                    for (kx, &c) in row.iter().enumerate() {
                        cols[kx * n + y] = c;
                    }
                }
                fft.process_with_scratch(cols, s);
                for (y, row) in slab.chunks_exact_mut(h1).enumerate() {
                    for (kx, c) in row.iter_mut().enumerate() {
                        *c = cols[kx * n + y];
                    }
                }
            },
        );
    }
}

#[cfg(test)]
mod tests;
