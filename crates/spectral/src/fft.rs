//! 2D discrete Fourier transform of a patch's height grid (Pauly & Gross 2001, §4).
//!
//! A grid `h` of `nu × nv` real heights (u fastest, `h[j·nu + i]`) has the spectrum
//! `X(k, l) = Σ_{i,j} h(i, j)·e^{-2πi(ki/nu + lj/nv)}` (unnormalised forward transform, as
//! RustFFT). Because `h` is real, `X(-k, -l) = conj X(k, l)`, so only the half spectrum
//! `k = 0..=nu/2` is stored ([`Spectrum`], `(nu/2 + 1) × nv` coefficients, index
//! `[l·(nu/2 + 1) + k]`). The inverse divides by `nu·nv`, so `inverse(forward(h)) == h` up to
//! rounding, and Parseval reads `Σ|h|² = (1/(nu nv))·Σ_full |X|²`, where the full sum counts
//! every stored coefficient twice except the columns `k = 0` and, for even `nu`, `k = nu/2`
//! (see [`Spectrum::multiplicity`]).
//!
//! Rows are transformed with realfft (real to complex along u), then columns with rustfft
//! (complex along v). Patch grids have many sizes, so [`Fft2`] caches the plans of the sizes
//! it has seen in a small list (linear search, cleared when it grows past a bound) and keeps
//! its scratch buffers; keep one per worker thread.

use std::sync::Arc;

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

/// Most plan sets an [`Fft2`] keeps before it forgets them all and starts over.
const MAX_CACHED: usize = 64;

/// Half spectrum of a real `nu × nv` grid: `(nu/2 + 1) × nv` coefficients, index
/// `[j·(nu/2 + 1) + k]` (k along u, j along v), unnormalised (see the module docs).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Spectrum {
    /// Grid nodes along u.
    pub nu: usize,
    /// Grid nodes along v.
    pub nv: usize,
    /// Coefficients, k fastest.
    pub c: Vec<Complex<f64>>,
}

impl Spectrum {
    /// Stored coefficients per row: `nu/2 + 1`.
    pub fn half(&self) -> usize {
        self.nu / 2 + 1
    }

    /// How many coefficients of the full spectrum the stored `(k, ·)` stands for: 1 for
    /// `k = 0` and for `k = nu/2` with `nu` even (their mirror is in the same column), 2
    /// otherwise.
    #[inline]
    pub fn multiplicity(&self, k: usize) -> f64 {
        if k == 0 || (self.nu.is_multiple_of(2) && k == self.nu / 2) {
            1.0
        } else {
            2.0
        }
    }

    /// |frequency| of coefficient `(k, j)` relative to the Nyquist frequency:
    /// `sqrt((k/(nu/2))² + (j'/(nv/2))²)` with `j'` the signed index (`j - nv` for
    /// `j > nv/2`); 0 = DC, 1 = Nyquist on an axis, √2 at the corner.
    #[inline]
    pub fn radial(&self, k: usize, j: usize) -> f64 {
        let js = if j <= self.nv / 2 {
            j as f64
        } else {
            j as f64 - self.nv as f64
        };
        let a = k as f64 / (self.nu as f64 / 2.0);
        let b = js / (self.nv as f64 / 2.0);
        (a * a + b * b).sqrt()
    }

    /// Power `|X|²` of every coefficient of the full spectrum as an `nu × nv` image (row
    /// major, x fastest) centred on DC: pixel `(x, y)` is frequency
    /// `(x - nu/2, y - nv/2)`. Log scaling is left to the caller.
    pub fn power_image(&self) -> Vec<f64> {
        let (nu, nv, hk) = (self.nu, self.nv, self.half());
        let mut img = vec![0.0; nu * nv];
        for y in 0..nv {
            let ky = y as i64 - (nv / 2) as i64;
            for x in 0..nu {
                let kx = x as i64 - (nu / 2) as i64;
                // Negative kx: the conjugate of (-kx, -ky), which has the same power.
                let (k, l) = if kx >= 0 { (kx, ky) } else { (-kx, -ky) };
                let j = l.rem_euclid(nv as i64) as usize;
                img[y * nu + x] = self.c[j * hk + k as usize].norm_sqr();
            }
        }
        img
    }
}

/// The plans of one grid size.
struct Plans {
    nu: usize,
    nv: usize,
    r2c: Arc<dyn RealToComplex<f64>>,
    c2r: Arc<dyn ComplexToReal<f64>>,
    fwd: Arc<dyn Fft<f64>>,
    inv: Arc<dyn Fft<f64>>,
}

/// 2D real FFT with plans cached per `(nu, nv)` and reusable scratch; one per worker thread.
pub struct Fft2 {
    real: RealFftPlanner<f64>,
    complex: FftPlanner<f64>,
    plans: Vec<Plans>,
    row: Vec<f64>,
    col: Vec<Complex<f64>>,
    crow: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl Default for Fft2 {
    fn default() -> Self {
        Fft2::new()
    }
}

impl std::fmt::Debug for Fft2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fft2")
            .field("cached_sizes", &self.plans.len())
            .finish()
    }
}

impl Fft2 {
    /// No plans yet.
    pub fn new() -> Fft2 {
        Fft2 {
            real: RealFftPlanner::new(),
            complex: FftPlanner::new(),
            plans: Vec::new(),
            row: Vec::new(),
            col: Vec::new(),
            crow: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// Index of the plans for `(nu, nv)`, planning them on first use.
    fn plans(&mut self, nu: usize, nv: usize) -> usize {
        if let Some(at) = self.plans.iter().position(|p| p.nu == nu && p.nv == nv) {
            return at;
        }
        if self.plans.len() >= MAX_CACHED {
            self.plans.clear();
        }
        let r2c = self.real.plan_fft_forward(nu);
        let c2r = self.real.plan_fft_inverse(nu);
        let fwd = self.complex.plan_fft_forward(nv);
        let inv = self.complex.plan_fft_inverse(nv);
        let need = r2c
            .get_scratch_len()
            .max(c2r.get_scratch_len())
            .max(fwd.get_inplace_scratch_len())
            .max(inv.get_inplace_scratch_len());
        if self.scratch.len() < need {
            self.scratch.resize(need, Complex::new(0.0, 0.0));
        }
        self.plans.push(Plans {
            nu,
            nv,
            r2c,
            c2r,
            fwd,
            inv,
        });
        self.plans.len() - 1
    }

    /// Forward transform of the `nu × nv` grid `h` (u fastest) into `out` (resized).
    pub fn forward(&mut self, h: &[f64], nu: usize, nv: usize, out: &mut Spectrum) {
        self.forward_impl(h, nu, nv, out, false);
    }

    /// [`Fft2::forward`] of a grid that is even along v, row `j` equal to row `nv - 1 - j`
    /// (a mirror extension): only the first `ceil(nv/2)` rows are transformed, the others
    /// copy their mirror's result, so the output has the same bits as [`Fft2::forward`].
    pub fn forward_even(&mut self, h: &[f64], nu: usize, nv: usize, out: &mut Spectrum) {
        debug_assert!(
            (0..nv / 2).all(|j| h[j * nu..(j + 1) * nu] == h[(nv - 1 - j) * nu..(nv - j) * nu])
        );
        self.forward_impl(h, nu, nv, out, true);
    }

    fn forward_impl(&mut self, h: &[f64], nu: usize, nv: usize, out: &mut Spectrum, even: bool) {
        assert!(
            nu >= 1 && nv >= 1 && h.len() == nu * nv,
            "grid {nu} x {nv} has {} heights",
            h.len()
        );
        let at = self.plans(nu, nv);
        let hk = nu / 2 + 1;
        out.nu = nu;
        out.nv = nv;
        out.c.clear();
        out.c.resize(hk * nv, Complex::new(0.0, 0.0));
        self.row.resize(nu, 0.0);
        let p = &self.plans[at];
        let rows = if even { nv.div_ceil(2) } else { nv };
        for (src, dst) in h
            .chunks_exact(nu)
            .zip(out.c.chunks_exact_mut(hk))
            .take(rows)
        {
            self.row.copy_from_slice(src);
            let len = p.r2c.get_scratch_len();
            let res = p
                .r2c
                .process_with_scratch(&mut self.row, dst, &mut self.scratch[..len]);
            debug_assert!(res.is_ok(), "realfft forward sizes");
        }
        for j in rows..nv {
            out.c.copy_within((nv - 1 - j) * hk..(nv - j) * hk, j * hk);
        }
        columns(
            &*p.fwd,
            &mut out.c,
            hk,
            nv,
            &mut self.col,
            &mut self.scratch,
        );
    }

    /// Normalised inverse of [`Fft2::forward`]: `h` (length `nu·nv`) receives the grid.
    /// The imaginary parts of the self-conjugate coefficients (column `k = 0`, and
    /// `k = nu/2` for even `nu`, after the column transform) are taken as zero.
    pub fn inverse(&mut self, s: &Spectrum, h: &mut [f64]) {
        self.inverse_rows(s, h, s.nv);
    }

    /// [`Fft2::inverse`] restricted to the grid's first `rows` rows (`h` holds at least
    /// `rows·nu` values; the rest is left alone): the row transforms of the other rows are
    /// skipped, the written values are the same bits as [`Fft2::inverse`]'s.
    pub fn inverse_rows(&mut self, s: &Spectrum, h: &mut [f64], rows: usize) {
        let (nu, nv) = (s.nu, s.nv);
        assert!(
            rows <= nv && h.len() >= rows * nu && s.c.len() == s.half() * nv,
            "spectrum {nu} x {nv} sizes"
        );
        let at = self.plans(nu, nv);
        let hk = nu / 2 + 1;
        self.crow.clear();
        self.crow.extend_from_slice(&s.c);
        let p = &self.plans[at];
        columns(
            &*p.inv,
            &mut self.crow,
            hk,
            nv,
            &mut self.col,
            &mut self.scratch,
        );
        let norm = 1.0 / (nu * nv) as f64;
        for (src, dst) in self
            .crow
            .chunks_exact_mut(hk)
            .zip(h.chunks_exact_mut(nu))
            .take(rows)
        {
            src[0].im = 0.0;
            if nu.is_multiple_of(2) {
                src[hk - 1].im = 0.0;
            }
            let len = p.c2r.get_scratch_len();
            let res = p
                .c2r
                .process_with_scratch(src, dst, &mut self.scratch[..len]);
            debug_assert!(res.is_ok(), "realfft inverse sizes");
            dst.iter_mut().for_each(|x| *x *= norm);
        }
    }
}

/// Transform every column `k` of the `hk × nv` array `c` (k fastest) in place with `fft`.
fn columns(
    fft: &dyn Fft<f64>,
    c: &mut [Complex<f64>],
    hk: usize,
    nv: usize,
    col: &mut Vec<Complex<f64>>,
    scratch: &mut [Complex<f64>],
) {
    if nv == 1 {
        return;
    }
    col.resize(nv, Complex::new(0.0, 0.0));
    let len = fft.get_inplace_scratch_len();
    for k in 0..hk {
        for (j, x) in col.iter_mut().enumerate() {
            *x = c[j * hk + k];
        }
        fft.process_with_scratch(col, &mut scratch[..len]);
        for (j, x) in col.iter().enumerate() {
            c[j * hk + k] = *x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn random_grid(nu: usize, nv: usize, seed: u64) -> Vec<f64> {
        let mut rng = Pcg64::seed_from_u64(seed);
        (0..nu * nv).map(|_| rng.random::<f64>() - 0.5).collect()
    }

    /// Naive 2D DFT coefficient (k, l).
    fn dft(h: &[f64], nu: usize, nv: usize, k: usize, l: usize) -> Complex<f64> {
        let mut acc = Complex::new(0.0, 0.0);
        for j in 0..nv {
            for i in 0..nu {
                let ph = -2.0
                    * std::f64::consts::PI
                    * ((k * i) as f64 / nu as f64 + (l * j) as f64 / nv as f64);
                acc += Complex::from_polar(h[j * nu + i], ph);
            }
        }
        acc
    }

    #[test]
    fn forward_matches_a_naive_dft() {
        let mut f = Fft2::new();
        for &(nu, nv) in &[(8, 6), (7, 5), (2, 9), (13, 2)] {
            let h = random_grid(nu, nv, (nu * 100 + nv) as u64);
            let mut s = Spectrum::default();
            f.forward(&h, nu, nv, &mut s);
            for l in 0..nv {
                for k in 0..=nu / 2 {
                    let d = dft(&h, nu, nv, k, l);
                    assert!(
                        (s.c[l * s.half() + k] - d).norm() < 1e-10,
                        "{nu}x{nv} ({k},{l})"
                    );
                }
            }
        }
    }

    #[test]
    fn inverse_of_forward_is_identity_and_parseval_holds() {
        let mut f = Fft2::new();
        for &(nu, nv) in &[(30, 30), (17, 24), (2, 2), (31, 7)] {
            let h = random_grid(nu, nv, (nu * 7 + nv) as u64);
            let mut s = Spectrum::default();
            f.forward(&h, nu, nv, &mut s);
            let mut back = vec![0.0; nu * nv];
            f.inverse(&s, &mut back);
            let err = h
                .iter()
                .zip(&back)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-12, "{nu}x{nv}: {err}");
            let e_grid: f64 = h.iter().map(|x| x * x).sum();
            let mut e_spec = 0.0;
            for l in 0..nv {
                for k in 0..s.half() {
                    e_spec += s.multiplicity(k) * s.c[l * s.half() + k].norm_sqr();
                }
            }
            e_spec /= (nu * nv) as f64;
            assert!((e_grid - e_spec).abs() < 1e-10 * e_grid, "{nu}x{nv}");
        }
    }

    #[test]
    fn forward_even_and_inverse_rows_match_the_full_transforms() {
        let mut f = Fft2::new();
        for &(nu, nv) in &[(12usize, 10usize), (7, 9)] {
            let half = random_grid(nu, nv.div_ceil(2), 3);
            let mut h = vec![0.0; nu * nv];
            for j in 0..nv {
                let src = j.min(nv - 1 - j);
                h[j * nu..(j + 1) * nu].copy_from_slice(&half[src * nu..(src + 1) * nu]);
            }
            let (mut a, mut b) = (Spectrum::default(), Spectrum::default());
            f.forward(&h, nu, nv, &mut a);
            f.forward_even(&h, nu, nv, &mut b);
            assert_eq!(a, b);
            let mut full = vec![0.0; nu * nv];
            let mut part = vec![7.0; nu * nv];
            f.inverse(&a, &mut full);
            f.inverse_rows(&a, &mut part, 3);
            assert_eq!(full[..3 * nu], part[..3 * nu]);
            assert!(part[3 * nu..].iter().all(|&x| x == 7.0));
        }
    }

    #[test]
    fn radial_is_relative_to_nyquist() {
        let s = Spectrum {
            nu: 8,
            nv: 6,
            c: vec![],
        };
        assert_eq!(s.radial(0, 0), 0.0);
        assert!((s.radial(4, 0) - 1.0).abs() < 1e-15);
        assert!((s.radial(0, 3) - 1.0).abs() < 1e-15);
        assert!((s.radial(0, 5) - 1.0 / 3.0).abs() < 1e-15);
        assert!((s.radial(4, 3) - 2f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn power_image_puts_a_cosine_at_its_frequency() {
        let (nu, nv) = (8, 6);
        let mut h = vec![0.0; nu * nv];
        for j in 0..nv {
            for i in 0..nu {
                h[j * nu + i] =
                    (2.0 * std::f64::consts::PI * (2.0 * i as f64 / 8.0 + j as f64 / 6.0)).cos();
            }
        }
        let mut s = Spectrum::default();
        Fft2::new().forward(&h, nu, nv, &mut s);
        let img = s.power_image();
        let total: f64 = img.iter().sum();
        // Peaks at (+2, +1) and (-2, -1) around the centre (4, 3).
        let p1 = img[(3 + 1) * nu + 4 + 2];
        let p2 = img[(3 - 1) * nu + 4 - 2];
        assert!((p1 - 24.0 * 24.0).abs() < 1e-8 && (p2 - 24.0 * 24.0).abs() < 1e-8);
        assert!((total - p1 - p2).abs() < 1e-8);
    }
}
