//! One patch, from its seed to its filtered height field and blending function (§3, §5, §7).
//!
//! **Frame.** The base plane's normal `n` is the axis of the patch's normal cone (the
//! smallest cap holding its normals, [`cone`](super::cone)); its origin is the centroid of the
//! patch's points. The members' projections `(u, v)` get their smallest enclosing rectangle
//! ([`rect`](crate::geom::rect)), whose sides become the `u` and `v` axes, so that the parameter box
//! wastes as little of the grid as possible. Every point is `origin + u·U + v·V + h·N`.
//!
//! **Overlap.** The parameter box is the members' rectangle grown by [`Overlap::fraction`]
//! (10%, as the paper) of each side, and by at least two point spacings. Any point of the
//! cell or its halo whose `(u, v)` lies in the box, whose height lies within the members'
//! height range grown by the same margin, and whose normal lies within the cone widened by
//! [`Overlap::widen`] (π/8, as the paper) joins the patch's height field: boundary points
//! make neighbouring patches agree where they blend.
//!
//! **Height field.** The admitted `(u, v, h)` are approximated on a regular grid of about
//! `κ·n` nodes by push-pull ([`sda`]); the grid's heights are then filtered in the
//! frequency domain ([`filter`]).
//!
//! **Blending function (§7).** The members are splatted onto the grid with bilinear weights,
//! convolved with a binomial approximation of a Gaussian (σ = 1 node), and divided by the
//! mean coverage of the nodes inside the members' rectangle, capped at 1; a separable
//! smoothstep window then takes it to zero at the box's edge. A point's final position is the
//! weighted mean of its projections onto every patch that admits it.

use super::cone::Cone;
use super::fft::Fft2;
use super::filter::{self, Filter, FilterWork};
use super::layout::PatchSeed;
use super::sda::{self, Grid, SdaWork};
use crate::geom::rect::min_area_rect;
use crate::geom::{cross, dot, plane_basis};

/// How far a patch reaches beyond its members.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Overlap {
    /// Growth of each side of the parameter box, as a fraction of that side.
    pub fraction: f64,
    /// Least growth, in point spacings (so that thin patches still overlap).
    pub min_spacings: f64,
    /// Widening of the normal cone for boundary points, radians.
    pub widen: f64,
}

impl Default for Overlap {
    fn default() -> Self {
        Overlap {
            fraction: 0.1,
            min_spacings: 2.0,
            widen: std::f64::consts::PI / 8.0,
        }
    }
}

/// A patch's local frame and the region it answers for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Origin (the members' centroid), world coordinates.
    pub origin: [f64; 3],
    /// Unit axes `U`, `V`, `N` (right-handed; `N` the cone axis).
    pub axes: [[f64; 3]; 3],
    /// The members' rectangle in `(u, v)`: `[u0, v0, u1, v1]`.
    pub core: [f64; 4],
    /// The parameter box (the rectangle grown by the overlap): `[u0, v0, u1, v1]`.
    pub bx: [f64; 4],
    /// Heights admitted: `[h0, h1]`.
    pub hrange: [f64; 2],
    /// Cosine of the widened cone's half angle: a point's normal must have at least this
    /// component along `N` to join.
    pub cos_admit: f64,
}

impl Frame {
    /// `(u, v, h)` of a world point.
    #[inline]
    pub fn local(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ];
        let a = &self.axes;
        [dot(d, a[0]), dot(d, a[1]), dot(d, a[2])]
    }

    /// The world point at `(u, v, h)`.
    #[inline]
    pub fn world(&self, u: f64, v: f64, h: f64) -> [f64; 3] {
        let (o, a) = (self.origin, &self.axes);
        [
            o[0] + u * a[0][0] + v * a[1][0] + h * a[2][0],
            o[1] + u * a[0][1] + v * a[1][1] + h * a[2][1],
            o[2] + u * a[0][2] + v * a[1][2] + h * a[2][2],
        ]
    }

    /// The world direction of a local vector.
    #[inline]
    pub fn world_dir(&self, l: [f64; 3]) -> [f64; 3] {
        let a = &self.axes;
        [
            l[0] * a[0][0] + l[1] * a[1][0] + l[2] * a[2][0],
            l[0] * a[0][1] + l[1] * a[1][1] + l[2] * a[2][1],
            l[0] * a[0][2] + l[1] * a[1][2] + l[2] * a[2][2],
        ]
    }

    /// Whether local `(u, v, h)` and world normal `n` pass the admission test (a zero normal
    /// passes the cone test: it carries no direction to refuse).
    #[inline]
    pub fn admits(&self, l: [f64; 3], n: [f32; 3]) -> bool {
        let b = &self.bx;
        if !(l[0] >= b[0] && l[0] <= b[2] && l[1] >= b[1] && l[1] <= b[3]) {
            return false;
        }
        if !(l[2] >= self.hrange[0] && l[2] <= self.hrange[1]) {
            return false;
        }
        let c = n[0] as f64 * self.axes[2][0]
            + n[1] as f64 * self.axes[2][1]
            + n[2] as f64 * self.axes[2][2];
        c >= self.cos_admit || n == [0.0; 3]
    }

    /// World bounds of the region the patch answers for (its box times its height range).
    pub fn world_bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &u in &[self.bx[0], self.bx[2]] {
            for &v in &[self.bx[1], self.bx[3]] {
                for &h in &self.hrange {
                    let p = self.world(u, v, h);
                    for a in 0..3 {
                        lo[a] = lo[a].min(p[a]);
                        hi[a] = hi[a].max(p[a]);
                    }
                }
            }
        }
        (lo, hi)
    }
}

/// A patch after filtering: its frame, filtered heights and blending weights on the grid,
/// and what was measured on the way.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// Frame, box and admission test.
    pub frame: Frame,
    /// Grid columns (along `u`) and rows.
    pub nu: u32,
    /// Grid rows (along `v`).
    pub nv: u32,
    /// Grid origin in `(u, v)` (the box's low corner).
    pub lo: [f64; 2],
    /// Node spacing.
    pub step: f64,
    /// Filtered heights, row-major (`v` rows of `nu`).
    pub h: Vec<f32>,
    /// Blending weights in `[0, 1]`, same layout.
    pub w: Vec<f32>,
    /// Members (the cell's own points this patch was seeded with).
    pub members: u32,
    /// Points in its height field (members and overlap).
    pub admitted: u32,
    /// Aperture of the members' normal cone (radians).
    pub aperture: f32,
    /// RMS of the height field's approximation error at its points (§3).
    pub sda_rms: f32,
    /// RMS change of the grid's heights made by the filter, from the spectra (Parseval).
    pub parseval_rms: f32,
    /// Wiener: estimated noise standard deviation in height units.
    pub noise_rms: f32,
    /// Points per unit area a resampling of this patch needs (§6); 0 when not resampling.
    pub rate: f32,
}

/// What a patch is built for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Treatment {
    /// Heights as approximated (analysis).
    Keep,
    /// Filtered.
    Filter(Filter),
    /// Band-limited so that no height changes by more than `max_err` (world units), with the
    /// sampling rate that band needs.
    BandLimit {
        /// Largest change of a height, world units.
        max_err: f64,
        /// Least band kept, relative to the grid's Nyquist frequency.
        min_band: f64,
    },
}

/// Per-thread scratch reused from patch to patch.
pub struct PatchWork {
    /// The layout's buffers.
    pub layout: crate::layout::Workspace,
    uv: Vec<[f64; 2]>,
    sda: SdaWork,
    /// The FFT plans and scratch.
    pub fft: Fft2,
    /// The filters' scratch.
    pub filt: FilterWork,
    cov: Vec<f64>,
    tmp: Vec<f64>,
    /// The grid of the last patch built, before filtering, when `keep_raw` (for spectra).
    pub raw: Grid,
    /// Keep each patch's grid before treatment in `raw` (off: filtering copies nothing).
    pub keep_raw: bool,
}

impl Default for PatchWork {
    fn default() -> Self {
        PatchWork {
            layout: Default::default(),
            uv: Vec::new(),
            sda: SdaWork::default(),
            fft: Fft2::default(),
            filt: FilterWork::default(),
            cov: Vec::new(),
            tmp: Vec::new(),
            raw: sda::grid_for(1, [0.0; 2], [1.0; 2], 1.0),
            keep_raw: false,
        }
    }
}

/// Patches with fewer members than this are too small to approximate: their points pass
/// through unchanged.
pub const MIN_MEMBERS: usize = 6;

/// The frame of a seed's members (see the [module docs](self)). `None` for a seed too small
/// to approximate.
pub fn frame(
    pos: &[[f64; 3]],
    seed: &PatchSeed,
    ov: &Overlap,
    work: &mut PatchWork,
) -> Option<Frame> {
    let m = &seed.members;
    if m.len() < MIN_MEMBERS || seed.oriented == 0 {
        return None;
    }
    let n = seed.cone.axis;
    let mut c = [0f64; 3];
    for &i in m {
        let p = pos[i as usize];
        for a in 0..3 {
            c[a] += p[a];
        }
    }
    let c = c.map(|x| x / m.len() as f64);
    let (u0, v0) = plane_basis(n);
    work.uv.clear();
    let mut h = [f64::INFINITY, f64::NEG_INFINITY];
    for &i in m {
        let p = pos[i as usize];
        let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        work.uv.push([dot(d, u0), dot(d, v0)]);
        let z = dot(d, n);
        h = [h[0].min(z), h[1].max(z)];
    }
    let r = min_area_rect(&work.uv);
    let (ax, ay) = (r.axis[0], r.axis[1]);
    let u = [
        ax * u0[0] + ay * v0[0],
        ax * u0[1] + ay * v0[1],
        ax * u0[2] + ay * v0[2],
    ];
    let v = cross(n, u);
    let core = [r.lo[0], r.lo[1], r.hi[0], r.hi[1]];
    let (s1, s2) = (core[2] - core[0], core[3] - core[1]);
    let spacing = (s1 * s2 / m.len() as f64)
        .sqrt()
        .max(s1.max(s2) / m.len() as f64);
    let mu = (ov.fraction * s1).max(ov.min_spacings * spacing);
    let mv = (ov.fraction * s2).max(ov.min_spacings * spacing);
    let mh = mu.max(mv);
    let half = (seed.cone.half_angle + ov.widen).min(std::f64::consts::FRAC_PI_2);
    Some(Frame {
        origin: c,
        axes: [u, v, n],
        core,
        bx: [core[0] - mu, core[1] - mv, core[2] + mu, core[3] + mv],
        hrange: [h[0] - mh, h[1] + mh],
        cos_admit: half.cos(),
    })
}

/// Build a patch: fit the height field to the admitted points `pts` (members first, then the
/// overlap points, each as `(u, v, h)`), treat it, and compute its blending weights from the
/// first `members` of them.
pub fn build(
    frame: Frame,
    cone: &Cone,
    pts: &[[f64; 3]],
    members: usize,
    treat: &Treatment,
    work: &mut PatchWork,
) -> Patch {
    let b = frame.bx;
    let mut grid = sda::grid_for(pts.len(), [b[0], b[1]], [b[2], b[3]], 1.0);
    sda::push_pull(&mut grid, pts, &mut work.sda);
    let sda_rms = sda::rms_error(&grid, pts);
    if work.keep_raw {
        work.raw.clone_from(&grid);
    }
    let (nu, nv) = (grid.nu, grid.nv);
    let (mut parseval, mut noise, mut rate) = (0.0, 0.0, 0.0);
    match *treat {
        Treatment::Keep => {}
        Treatment::Filter(f) => {
            let a = filter::filter_grid(&mut grid.h, nu, nv, &f, &mut work.fft, &mut work.filt);
            parseval = a.parseval_rms;
            noise = a.noise_rms.unwrap_or(0.0);
        }
        Treatment::BandLimit { max_err, min_band } => {
            let band = filter::band_limit_by(
                &grid.h,
                nu,
                nv,
                max_err,
                filter::Bound::Rms,
                &mut work.fft,
                &mut work.filt,
            )
            // Above the grid's Nyquist frequency the points carry nothing to resample.
            .clamp(min_band, 1.0);
            let cut = Filter::Ideal { cut: band };
            let a = filter::filter_grid(&mut grid.h, nu, nv, &cut, &mut work.fft, &mut work.filt);
            parseval = a.parseval_rms;
            // Sampling at twice the band (§6): the spacing is the grid step over the band.
            let spacing = grid.step / band;
            rate = 1.0 / (spacing * spacing);
        }
    }
    let w = weights(&grid, &frame, &pts[..members], work);
    Patch {
        frame,
        nu: nu as u32,
        nv: nv as u32,
        lo: grid.lo,
        step: grid.step,
        h: grid.h.iter().map(|&x| x as f32).collect(),
        w,
        members: members as u32,
        admitted: pts.len() as u32,
        aperture: (2.0 * cone.half_angle) as f32,
        sda_rms: sda_rms as f32,
        parseval_rms: parseval as f32,
        noise_rms: noise as f32,
        rate: rate as f32,
    }
}

/// The blending function on the grid (see the [module docs](self)).
fn weights(grid: &Grid, frame: &Frame, members: &[[f64; 3]], work: &mut PatchWork) -> Vec<f32> {
    let (nu, nv) = (grid.nu, grid.nv);
    let cov = &mut work.cov;
    cov.clear();
    cov.resize(nu * nv, 0.0);
    for p in members {
        let (i, j, fu, fv) = cell_of(grid, p[0], p[1]);
        cov[j * nu + i] += (1.0 - fu) * (1.0 - fv);
        cov[j * nu + i + 1] += fu * (1.0 - fv);
        cov[(j + 1) * nu + i] += (1.0 - fu) * fv;
        cov[(j + 1) * nu + i + 1] += fu * fv;
    }
    blur(cov, nu, nv, &mut work.tmp);
    // Mean coverage of the nodes inside the members' rectangle.
    let c = frame.core;
    let (mut sum, mut cnt) = (0.0, 0usize);
    for j in 0..nv {
        let v = grid.lo[1] + j as f64 * grid.step;
        for i in 0..nu {
            let u = grid.lo[0] + i as f64 * grid.step;
            if u >= c[0] && u <= c[2] && v >= c[1] && v <= c[3] {
                sum += cov[j * nu + i];
                cnt += 1;
            }
        }
    }
    let mean = if cnt > 0 && sum > 0.0 {
        sum / cnt as f64
    } else {
        cov.iter().sum::<f64>() / (nu * nv) as f64
    };
    let b = frame.bx;
    let mut w = Vec::with_capacity(nu * nv);
    for j in 0..nv {
        let v = grid.lo[1] + j as f64 * grid.step;
        let wv = window(v, b[1], c[1], c[3], b[3]);
        for i in 0..nu {
            let u = grid.lo[0] + i as f64 * grid.step;
            let wu = window(u, b[0], c[0], c[2], b[2]);
            let x = (cov[j * nu + i] / mean).min(1.0) * wu * wv;
            w.push(x as f32);
        }
    }
    w
}

/// 1 on `[c0, c1]`, smoothly to 0 at `b0` and `b1`.
#[inline]
fn window(x: f64, b0: f64, c0: f64, c1: f64, b1: f64) -> f64 {
    let t = if x < c0 {
        (x - b0) / (c0 - b0)
    } else if x > c1 {
        (b1 - x) / (b1 - c1)
    } else {
        1.0
    };
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Separable binomial blur `[1 4 6 4 1]/16` (a Gaussian of σ = 1 node), edges clamped.
fn blur(a: &mut [f64], nu: usize, nv: usize, tmp: &mut Vec<f64>) {
    const K: [f64; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    tmp.clear();
    tmp.resize(a.len(), 0.0);
    for j in 0..nv {
        for i in 0..nu {
            let mut s = 0.0;
            for (t, k) in K.iter().enumerate() {
                let ii = (i as isize + t as isize - 2).clamp(0, nu as isize - 1) as usize;
                s += k * a[j * nu + ii];
            }
            tmp[j * nu + i] = s;
        }
    }
    for j in 0..nv {
        for i in 0..nu {
            let mut s = 0.0;
            for (t, k) in K.iter().enumerate() {
                let jj = (j as isize + t as isize - 2).clamp(0, nv as isize - 1) as usize;
                s += k * tmp[jj * nu + i];
            }
            a[j * nu + i] = s;
        }
    }
}

/// The grid cell holding `(u, v)` (clamped into the grid) and the fractions within it.
#[inline]
fn cell_of(g: &Grid, u: f64, v: f64) -> (usize, usize, f64, f64) {
    locate(g.nu, g.nv, g.lo, g.step, u, v)
}

/// The cell of a grid of `nu × nv` nodes from `lo` at `step` holding `(u, v)`, clamped, and
/// the fractions within it.
#[inline]
pub fn locate(
    nu: usize,
    nv: usize,
    lo: [f64; 2],
    step: f64,
    u: f64,
    v: f64,
) -> (usize, usize, f64, f64) {
    let x = ((u - lo[0]) / step).clamp(0.0, (nu - 1) as f64);
    let y = ((v - lo[1]) / step).clamp(0.0, (nv - 1) as f64);
    // Truncation is the floor of these non-negative values (and no libm call).
    let i = (x as usize).min(nu - 2);
    let j = (y as usize).min(nv - 2);
    (i, j, x - i as f64, y - j as f64)
}

/// What a patch says at a point: its position on the patch's surface, unit normal, and
/// blending weight.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// The point on the patch's filtered surface at the same `(u, v)`.
    pub pos: [f64; 3],
    /// Unit normal there (world).
    pub normal: [f64; 3],
    /// Blending weight.
    pub weight: f64,
}

impl Patch {
    /// Bilinear height, weight and height gradient at `(u, v)`.
    #[inline]
    pub fn eval(&self, u: f64, v: f64) -> (f64, f64, [f64; 2]) {
        let nu = self.nu as usize;
        let (i, j, fu, fv) = locate(nu, self.nv as usize, self.lo, self.step, u, v);
        let k = j * nu + i;
        let (h00, h10, h01, h11) = (
            self.h[k] as f64,
            self.h[k + 1] as f64,
            self.h[k + nu] as f64,
            self.h[k + nu + 1] as f64,
        );
        let (w00, w10, w01, w11) = (
            self.w[k] as f64,
            self.w[k + 1] as f64,
            self.w[k + nu] as f64,
            self.w[k + nu + 1] as f64,
        );
        let h = (1.0 - fv) * ((1.0 - fu) * h00 + fu * h10) + fv * ((1.0 - fu) * h01 + fu * h11);
        let w = (1.0 - fv) * ((1.0 - fu) * w00 + fu * w10) + fv * ((1.0 - fu) * w01 + fu * w11);
        let du = ((1.0 - fv) * (h10 - h00) + fv * (h11 - h01)) / self.step;
        let dv = ((1.0 - fu) * (h01 - h00) + fu * (h11 - h10)) / self.step;
        (h, w, [du, dv])
    }

    /// The patch at world point `p` with normal `n`, when it admits it with a weight above 0.
    #[inline]
    pub fn sample(&self, p: [f64; 3], n: [f32; 3]) -> Option<Sample> {
        let l = self.frame.local(p);
        if !self.frame.admits(l, n) {
            return None;
        }
        Some(self.sample_at(l[0], l[1])).filter(|s| s.weight > 0.0)
    }

    /// The patch at parameters `(u, v)`.
    #[inline]
    pub fn sample_at(&self, u: f64, v: f64) -> Sample {
        let (h, w, g) = self.eval(u, v);
        let d = self.frame.world_dir([-g[0], -g[1], 1.0]);
        let l = dot(d, d).sqrt();
        Sample {
            pos: self.frame.world(u, v, h),
            normal: [d[0] / l, d[1] / l, d[2] / l],
            weight: w,
        }
    }

    /// The least-squares plane of the 3×3 nodes around `(u, v)`: its unit normal (world).
    /// The fallback where blended normals disagree (§7).
    pub fn ls_normal(&self, u: f64, v: f64) -> [f64; 3] {
        let (nu, nv) = (self.nu as usize, self.nv as usize);
        let (i, j, fu, fv) = locate(nu, nv, self.lo, self.step, u, v);
        let ci = (i + (fu >= 0.5) as usize).clamp(1, nu.saturating_sub(2).max(1));
        let cj = (j + (fv >= 0.5) as usize).clamp(1, nv.saturating_sub(2).max(1));
        // Plane h = a + b·x + c·y over the offsets x, y in {-1, 0, 1} (in steps): the
        // normal equations decouple on this symmetric stencil.
        let (mut sx, mut sy, mut xx, mut yy) = (0.0, 0.0, 0.0, 0.0);
        for dj in -1i64..=1 {
            for di in -1i64..=1 {
                let ii = (ci as i64 + di).clamp(0, nu as i64 - 1) as usize;
                let jj = (cj as i64 + dj).clamp(0, nv as i64 - 1) as usize;
                let h = self.h[jj * nu + ii] as f64;
                sx += di as f64 * h;
                sy += dj as f64 * h;
                xx += (di * di) as f64;
                yy += (dj * dj) as f64;
            }
        }
        let (gu, gv) = (sx / xx / self.step, sy / yy / self.step);
        let d = self.frame.world_dir([-gu, -gv, 1.0]);
        let l = dot(d, d).sqrt();
        [d[0] / l, d[1] / l, d[2] / l]
    }

    /// Bytes held.
    pub fn heap_bytes(&self) -> usize {
        (self.h.capacity() + self.w.capacity()) * 4 + std::mem::size_of::<Patch>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cone::enclosing_cone;

    /// A noisy, gently curved sheet: `(x, y, 0.05 sin(3x) + noise)` with normals up.
    pub(crate) fn sheet(n: usize, noise: f64, seed: u64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
        let mut s = seed;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let pos = (0..n)
            .map(|_| {
                let (x, y) = (r(), r());
                let g = (-2.0 * r().max(1e-12).ln()).sqrt() * (std::f64::consts::TAU * r()).cos();
                [x, y, 0.05 * (3.0 * x).sin() + noise * g]
            })
            .collect();
        (pos, vec![[0.0, 0.0, 1.0]; n])
    }

    fn built(treat: &Treatment) -> (Patch, Vec<f64>) {
        let (pos, nor) = sheet(900, 0.01, 3);
        let members: Vec<u32> = (0..pos.len() as u32).collect();
        let cone = enclosing_cone(&nor, &members).unwrap();
        let seed = PatchSeed {
            oriented: members.len() as u32,
            members,
            cone,
        };
        let mut w = PatchWork {
            keep_raw: true,
            ..PatchWork::default()
        };
        let f = frame(&pos, &seed, &Overlap::default(), &mut w).unwrap();
        let pts: Vec<[f64; 3]> = pos.iter().map(|p| f.local(*p)).collect();
        let p = build(f, &cone, &pts, pts.len(), treat, &mut w);
        (p, w.raw.h.clone())
    }

    #[test]
    fn parseval_error_is_the_rms_change_of_the_height_field() {
        for f in [
            Filter::Gauss { cut: 0.3 },
            Filter::Ideal { cut: 0.5 },
            Filter::Wiener { snr: None },
            Filter::BandStop {
                lo: 0.3,
                hi: 0.8,
                gain: 0.0,
            },
        ] {
            let (p, raw) = built(&Treatment::Filter(f));
            let n = raw.len() as f64;
            let measured =
                (p.h.iter()
                    .zip(&raw)
                    .map(|(&a, &b)| (a as f64 - b).powi(2))
                    .sum::<f64>()
                    / n)
                    .sqrt();
            let reported = p.parseval_rms as f64;
            assert!(
                (measured - reported).abs() <= 1e-4 * reported.max(1e-9) + 1e-6,
                "{f:?}: Parseval {reported:.6e}, measured {measured:.6e}"
            );
            assert!(reported > 0.0, "{f:?}");
        }
    }

    #[test]
    fn weights_are_one_inside_and_zero_at_the_box_edge() {
        let (p, _) = built(&Treatment::Keep);
        let (nu, nv) = (p.nu as usize, p.nv as usize);
        for j in 0..nv {
            for i in 0..nu {
                let w = p.w[j * nu + i];
                assert!((0.0..=1.0).contains(&w));
                if i == 0 || j == 0 || i == nu - 1 || j == nv - 1 {
                    assert!(w < 0.05, "edge node ({i}, {j}) weighs {w}");
                }
            }
        }
        let c = p.frame.core;
        let s = p.sample_at(0.5 * (c[0] + c[2]), 0.5 * (c[1] + c[3]));
        assert!(s.weight > 0.9, "{}", s.weight);
    }

    #[test]
    fn a_patch_reproduces_its_points_and_filtered_normals() {
        let (p, _) = built(&Treatment::Keep);
        let (q, _) = built(&Treatment::Filter(Filter::Gauss { cut: 0.3 }));
        let (pos, _) = sheet(900, 0.01, 3);
        let mut worst = 0f64;
        for x in &pos[..200] {
            let s = p.sample(*x, [0.0, 0.0, 1.0]).unwrap();
            worst = worst.max((s.pos[2] - x[2]).abs());
            // The sheet's slope is at most 0.15 (normals within 9° of up); a low-passed
            // height field's divided differences follow it.
            let f = q.sample(*x, [0.0, 0.0, 1.0]).unwrap();
            let want = 1.0 / (1.0 + (0.15 * (3.0 * x[0]).cos()).powi(2)).sqrt();
            assert!(
                (f.normal[2] - want).abs() < 0.05,
                "{:?} against {want}",
                f.normal
            );
        }
        // Within a few noise deviations (0.01): the approximation follows the points.
        assert!(worst < 0.06, "{worst}");
    }
}
