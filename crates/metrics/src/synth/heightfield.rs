//! The height field: the graph `z = h(x, y)` over the square `[-L, L]²`,
//!
//! `h(x, y) = t_x x + t_y y + Σ_i a_i exp(-((x - c_xi)² + (y - c_yi)²) / (2 w_i²))`,
//!
//! a plane tilt plus a sum of Gaussian bumps (centre `c_i`, width `w_i` the standard deviation,
//! signed height `a_i`). This file holds its value and derivatives, its bounding box and the
//! exact distance to it (see [`crate::synth::Truth::distance`]).
//!
//! # Distance
//!
//! The nearest point of the graph to `p` minimises `f(x, y) = ½ |p - (x, y, h(x, y))|²` over
//! the closed square. The vertical projection `c` of `p` clamped to the square is a point of
//! the surface, so `D = |p - (c, h(c))|` bounds the distance and the minimiser lies within `D`
//! of `(p_x, p_y)` in the plane. That disc (clipped to the square) is sampled on a grid finer
//! than a quarter of the narrowest bump, and projected Newton iterations (exact gradient
//! `g = (x - p_x + r h_x, y - p_y + r h_y)`, `r = h - p_z`, and exact Hessian
//! `I + ∇h ∇hᵀ + r ∇²h`, shifted where not positive definite; a coordinate at a side of the
//! square whose gradient points outward is held, so edges and corners are handled as the
//! active set of the bound constraints) run from `c` and from the best samples that are
//! pairwise apart. The smallest value found is the answer.

use serde::{Deserialize, Serialize};

/// One Gaussian bump `height · exp(-|q - centre|² / (2 width²))` of the height field.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bump {
    /// Centre `(x, y)` in the plane.
    pub centre: [f64; 2],
    /// Width: the standard deviation of the Gaussian (positive).
    pub width: f64,
    /// Signed height at the centre.
    pub height: f64,
}

/// Number of bumps of a height field.
pub const HEIGHTFIELD_BUMPS: usize = 8;

/// The standard height field `synth` samples: widths 0.08 to 0.4, heights ±0.05 to ±0.25.
pub(crate) const STANDARD_BUMPS: [Bump; HEIGHTFIELD_BUMPS] = [
    bump(-0.45, -0.35, 0.40, 0.25),
    bump(0.50, 0.40, 0.30, -0.20),
    bump(0.10, 0.55, 0.20, 0.15),
    bump(-0.60, 0.45, 0.15, -0.12),
    bump(0.55, -0.50, 0.12, 0.10),
    bump(0.05, -0.05, 0.10, -0.08),
    bump(-0.20, 0.10, 0.08, 0.06),
    bump(0.80, 0.05, 0.09, -0.05),
];

/// The standard plane tilt `(t_x, t_y)`.
pub(crate) const STANDARD_TILT: [f64; 2] = [0.05, -0.03];

const fn bump(x: f64, y: f64, width: f64, height: f64) -> Bump {
    Bump {
        centre: [x, y],
        width,
        height,
    }
}

/// Most grid samples looked at when searching for the starts of the distance search.
const MAX_SIDE_SAMPLES: usize = 256;

/// Most Newton starts besides the vertical projection.
const MAX_STARTS: usize = 8;

/// `h` and its first and second derivatives at a point.
#[derive(Debug, Clone, Copy)]
struct Jet {
    h: f64,
    hx: f64,
    hy: f64,
    hxx: f64,
    hxy: f64,
    hyy: f64,
}

/// The height field `h` over `[-half_width, half_width]²`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeightField {
    half_width: f64,
    tilt: [f64; 2],
    bumps: [Bump; HEIGHTFIELD_BUMPS],
}

impl HeightField {
    /// The field over `[-half_width, half_width]²` with plane tilt `tilt` and `bumps`.
    pub(crate) fn new(half_width: f64, tilt: [f64; 2], bumps: [Bump; HEIGHTFIELD_BUMPS]) -> Self {
        HeightField {
            half_width,
            tilt,
            bumps,
        }
    }

    /// Half the side of the square.
    pub(crate) fn half_width(&self) -> f64 {
        self.half_width
    }

    /// `h(x, y)`: the one formula every position and distance uses.
    #[inline]
    pub(crate) fn value(&self, x: f64, y: f64) -> f64 {
        let mut h = self.tilt[0] * x + self.tilt[1] * y;
        for b in &self.bumps {
            let (dx, dy) = (x - b.centre[0], y - b.centre[1]);
            h += b.height * (-(dx * dx + dy * dy) / (2.0 * b.width * b.width)).exp();
        }
        h
    }

    /// `h` and its gradient `(h_x, h_y)`.
    #[inline]
    pub(crate) fn value_and_gradient(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        let j = self.jet(x, y);
        (self.value(x, y), [j.hx, j.hy])
    }

    /// The unit upward normal `(-h_x, -h_y, 1) / |…|` at `(x, y)`.
    pub(crate) fn normal(&self, x: f64, y: f64) -> [f64; 3] {
        let (_, [hx, hy]) = self.value_and_gradient(x, y);
        let l = (hx * hx + hy * hy + 1.0).sqrt();
        [-hx / l, -hy / l, 1.0 / l]
    }

    /// An upper bound of `|∇h|` over the plane: `|t| + Σ |a_i| / (w_i √e)` (the largest slope
    /// of a Gaussian bump is `|a| / (w √e)`, at distance `w` from its centre).
    pub(crate) fn slope_bound(&self) -> f64 {
        let e = std::f64::consts::E.sqrt();
        self.tilt[0].hypot(self.tilt[1])
            + self
                .bumps
                .iter()
                .map(|b| b.height.abs() / (b.width * e))
                .sum::<f64>()
    }

    /// `h` with its first and second derivatives.
    fn jet(&self, x: f64, y: f64) -> Jet {
        let mut j = Jet {
            h: self.tilt[0] * x + self.tilt[1] * y,
            hx: self.tilt[0],
            hy: self.tilt[1],
            hxx: 0.0,
            hxy: 0.0,
            hyy: 0.0,
        };
        for b in &self.bumps {
            let (dx, dy) = (x - b.centre[0], y - b.centre[1]);
            let iw2 = 1.0 / (b.width * b.width);
            let e = b.height * (-(dx * dx + dy * dy) * 0.5 * iw2).exp();
            j.h += e;
            j.hx -= e * dx * iw2;
            j.hy -= e * dy * iw2;
            j.hxx += e * (dx * dx * iw2 - 1.0) * iw2;
            j.hyy += e * (dy * dy * iw2 - 1.0) * iw2;
            j.hxy += e * dx * dy * iw2 * iw2;
        }
        j
    }

    /// `(min h, max h)` over the square, to about 1e-13: the best nodes of a grid finer than a
    /// fifth of the narrowest bump, refined by a pattern search clamped to the square.
    pub(crate) fn height_range(&self) -> (f64, f64) {
        let lo = self.extreme(-1.0);
        let hi = self.extreme(1.0);
        (-lo, hi)
    }

    /// `max sign · h` over the square.
    fn extreme(&self, sign: f64) -> f64 {
        let l = self.half_width;
        let f = |x: f64, y: f64| sign * self.value(x.clamp(-l, l), y.clamp(-l, l));
        let n = ((2.0 * l / (0.2 * self.min_width())).ceil() as usize).clamp(64, 2000);
        let step = 2.0 * l / n as f64;
        let (mut bx, mut by, mut best) = (-l, -l, f(-l, -l));
        for i in 0..=n {
            let x = -l + i as f64 * step;
            for k in 0..=n {
                let y = -l + k as f64 * step;
                let v = f(x, y);
                if v > best {
                    (bx, by, best) = (x, y, v);
                }
            }
        }
        let mut s = step;
        while s > 1e-15 * l {
            let mut moved = false;
            for (ox, oy) in [
                (s, 0.0),
                (-s, 0.0),
                (0.0, s),
                (0.0, -s),
                (s, s),
                (s, -s),
                (-s, s),
                (-s, -s),
            ] {
                let (x, y) = ((bx + ox).clamp(-l, l), (by + oy).clamp(-l, l));
                let v = f(x, y);
                if v > best {
                    (bx, by, best) = (x, y, v);
                    moved = true;
                    break;
                }
            }
            if !moved {
                s *= 0.5;
            }
        }
        best
    }

    /// The narrowest bump's width (the half-width of the square when there is none narrower).
    fn min_width(&self) -> f64 {
        self.bumps
            .iter()
            .map(|b| b.width)
            .fold(self.half_width, f64::min)
    }

    /// `½ |p - (q, h(q))|²`.
    #[inline]
    fn half_sq(&self, p: [f64; 3], q: [f64; 2]) -> f64 {
        let (dx, dy, dz) = (q[0] - p[0], q[1] - p[1], self.value(q[0], q[1]) - p[2]);
        0.5 * (dx * dx + dy * dy + dz * dz)
    }

    /// Projected Newton descent of `½ |p - (q, h(q))|²` over the square from `start`; returns
    /// the value reached.
    fn descend(&self, p: [f64; 3], start: [f64; 2]) -> f64 {
        const MAX_STEP: f64 = 0.25;
        let l = self.half_width;
        let clamp = |q: [f64; 2]| [q[0].clamp(-l, l), q[1].clamp(-l, l)];
        let mut q = clamp(start);
        let mut f = self.half_sq(p, q);
        for _ in 0..100 {
            let j = self.jet(q[0], q[1]);
            let r = j.h - p[2];
            let g = [q[0] - p[0] + r * j.hx, q[1] - p[1] + r * j.hy];
            // Held coordinates: at a side, with the descent direction pointing out.
            let free = [0, 1].map(|i| !((q[i] >= l && g[i] < 0.0) || (q[i] <= -l && g[i] > 0.0)));
            let h00 = 1.0 + j.hx * j.hx + r * j.hxx;
            let h11 = 1.0 + j.hy * j.hy + r * j.hyy;
            let h01 = j.hx * j.hy + r * j.hxy;
            let mut step = match free {
                [true, true] => newton_2x2(h00, h01, h11, g),
                [true, false] => [-g[0] / positive(h00), 0.0],
                [false, true] => [0.0, -g[1] / positive(h11)],
                [false, false] => break,
            };
            if !(step[0].is_finite() && step[1].is_finite()) {
                break;
            }
            let len = step[0].hypot(step[1]);
            if len == 0.0 {
                break;
            }
            if len > MAX_STEP {
                step = [step[0] * MAX_STEP / len, step[1] * MAX_STEP / len];
            }
            if g[0] * step[0] + g[1] * step[1] >= 0.0 {
                break;
            }
            let mut t = 1.0;
            let mut accepted = None;
            for _ in 0..60 {
                let qn = clamp([q[0] + t * step[0], q[1] + t * step[1]]);
                let fnew = self.half_sq(p, qn);
                let decrease = g[0] * (qn[0] - q[0]) + g[1] * (qn[1] - q[1]);
                if fnew <= f + 1e-4 * decrease.min(0.0) {
                    accepted = Some((qn, fnew));
                    break;
                }
                t *= 0.5;
            }
            let Some((qn, fnew)) = accepted else { break };
            let moved = (qn[0] - q[0]).hypot(qn[1] - q[1]);
            q = qn;
            f = fnew;
            if moved <= 1e-15 * l.max(1.0) {
                break;
            }
        }
        f
    }

    /// Distance from `p` to the graph over the square; see the module docs.
    pub(crate) fn distance(&self, p: [f64; 3]) -> f64 {
        let l = self.half_width;
        let c = [p[0].clamp(-l, l), p[1].clamp(-l, l)];
        let mut best = self.half_sq(p, c);
        if best == 0.0 {
            return 0.0;
        }
        let reach = (2.0 * best).sqrt();
        let lo = [(p[0] - reach).max(-l), (p[1] - reach).max(-l)];
        let hi = [(p[0] + reach).min(l), (p[1] + reach).min(l)];
        let spacing = 0.25 * self.min_width();
        let count = |i: usize| {
            ((((hi[i] - lo[i]) / spacing).ceil() as usize) + 1).clamp(2, MAX_SIDE_SAMPLES)
        };
        let (nx, ny) = (count(0), count(1));
        let node =
            |i: usize, k: usize, n: usize| lo[i] + (hi[i] - lo[i]) * k as f64 / (n - 1) as f64;
        let mut samples: Vec<(f64, [f64; 2])> = Vec::with_capacity(nx * ny);
        for a in 0..nx {
            for b in 0..ny {
                let q = [node(0, a, nx), node(1, b, ny)];
                samples.push((self.half_sq(p, q), q));
            }
        }
        samples.sort_by(|u, v| u.0.total_cmp(&v.0).then(u.1[0].total_cmp(&v.1[0])));
        let apart = 2.0 * spacing;
        let mut starts = vec![c];
        for (_, q) in &samples {
            if starts.len() > MAX_STARTS {
                break;
            }
            if starts
                .iter()
                .all(|s| (s[0] - q[0]).hypot(s[1] - q[1]) > apart)
            {
                starts.push(*q);
            }
        }
        if let Some((v, _)) = samples.first() {
            best = best.min(*v);
        }
        for s in starts {
            best = best.min(self.descend(p, s));
        }
        (2.0 * best).sqrt()
    }
}

/// `v` if positive and not tiny, else a small positive curvature (a gradient step).
fn positive(v: f64) -> f64 {
    if v > 1e-3 { v } else { 1.0 }
}

/// The Newton step `-H⁻¹ g` for `H = [[a, b], [b, c]]`, shifted to positive definite where it
/// is not.
fn newton_2x2(a: f64, b: f64, c: f64, g: [f64; 2]) -> [f64; 2] {
    let half_tr = 0.5 * (a + c);
    let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (lmin, lmax) = (half_tr - disc, half_tr + disc);
    let size = lmin.abs().max(lmax.abs()).max(1e-12);
    let mu = if lmin < 1e-3 * size {
        1e-3 * size - lmin + 0.05 * size
    } else {
        0.0
    };
    let (a, c) = (a + mu, c + mu);
    let det = a * c - b * b;
    [-(c * g[0] - b * g[1]) / det, -(a * g[1] - b * g[0]) / det]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn standard() -> HeightField {
        HeightField::new(1.0, STANDARD_TILT, STANDARD_BUMPS)
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let m = standard();
        let mut rng = Pcg64::seed_from_u64(3);
        let e = 1e-5;
        for _ in 0..50 {
            let (x, y) = (
                2.0 * rng.random::<f64>() - 1.0,
                2.0 * rng.random::<f64>() - 1.0,
            );
            let j = m.jet(x, y);
            assert!((j.h - m.value(x, y)).abs() < 1e-15);
            let dx = |f: &dyn Fn(f64, f64) -> f64| (f(x + e, y) - f(x - e, y)) / (2.0 * e);
            let dy = |f: &dyn Fn(f64, f64) -> f64| (f(x, y + e) - f(x, y - e)) / (2.0 * e);
            let h = |a: f64, b: f64| m.value(a, b);
            let hx = |a: f64, b: f64| m.jet(a, b).hx;
            let hy = |a: f64, b: f64| m.jet(a, b).hy;
            assert!((dx(&h) - j.hx).abs() < 1e-6, "hx");
            assert!((dy(&h) - j.hy).abs() < 1e-6, "hy");
            assert!((dx(&hx) - j.hxx).abs() < 1e-4, "hxx");
            assert!((dy(&hy) - j.hyy).abs() < 1e-4, "hyy");
            assert!((dy(&hx) - j.hxy).abs() < 1e-4, "hxy");
            assert!((dx(&hy) - j.hxy).abs() < 1e-4, "hyx");
        }
    }

    #[test]
    fn heightfield_range_and_slope_bound_hold_on_a_dense_grid() {
        let m = standard();
        let (lo, hi) = m.height_range();
        let n = 1500;
        let (mut glo, mut ghi, mut slope) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for i in 0..=n {
            for k in 0..=n {
                let (x, y) = (
                    -1.0 + 2.0 * i as f64 / n as f64,
                    -1.0 + 2.0 * k as f64 / n as f64,
                );
                let (h, g) = m.value_and_gradient(x, y);
                glo = glo.min(h);
                ghi = ghi.max(h);
                slope = slope.max(g[0].hypot(g[1]));
            }
        }
        assert!(hi >= ghi - 1e-13 && hi - ghi < 1e-5, "{hi} vs {ghi}");
        assert!(lo <= glo + 1e-13 && glo - lo < 1e-5, "{lo} vs {glo}");
        // The bound adds every bump's steepest slope: safe, about four times the true maximum.
        assert!(
            slope <= m.slope_bound() && slope > 0.2 * m.slope_bound(),
            "{slope}"
        );
        // The standard relief spans the requested heights.
        assert!(hi > 0.2 && lo < -0.15, "{lo} {hi}");
    }

    /// Brute force: a dense grid over the square `[p ± reach]` clipped to the domain, then
    /// repeated grid refinement (clamped to the domain) around the best few nodes.
    fn brute_distance(m: &HeightField, p: [f64; 3], reach: f64) -> f64 {
        let l = m.half_width();
        let cl = |v: f64| v.clamp(-l, l);
        let (x0, x1) = (cl(p[0] - reach), cl(p[0] + reach));
        let (y0, y1) = (cl(p[1] - reach), cl(p[1] + reach));
        let n = 400;
        let mut cands: Vec<(f64, f64, f64)> = Vec::new();
        for i in 0..=n {
            for k in 0..=n {
                let x = x0 + (x1 - x0) * i as f64 / n as f64;
                let y = y0 + (y1 - y0) * k as f64 / n as f64;
                cands.push((m.half_sq(p, [x, y]), x, y));
            }
        }
        cands.sort_by(|a, b| a.0.total_cmp(&b.0));
        let step = (x1 - x0).max(y1 - y0) / n as f64;
        let mut best = f64::INFINITY;
        let mut picked: Vec<(f64, f64)> = Vec::new();
        for &(_, a0, b0) in &cands {
            if picked.len() == 6 {
                break;
            }
            if picked.iter().any(|&(a, b)| (a - a0).hypot(b - b0) < 0.05) {
                continue;
            }
            picked.push((a0, b0));
            let (mut a, mut b, mut h) = (a0, b0, m.half_sq(p, [a0, b0]));
            let mut s = step;
            for _ in 0..14 {
                let (ca, cb) = (a, b);
                for i in -10..=10 {
                    for k in -10..=10 {
                        let q = [cl(ca + i as f64 * s / 5.0), cl(cb + k as f64 * s / 5.0)];
                        let v = m.half_sq(p, q);
                        if v < h {
                            (a, b, h) = (q[0], q[1], v);
                        }
                    }
                }
                s /= 5.0;
            }
            best = best.min(h);
        }
        (2.0 * best).sqrt()
    }

    #[test]
    fn heightfield_distance_matches_brute_force() {
        let m = standard();
        let mut rng = Pcg64::seed_from_u64(17);
        let mut points = Vec::new();
        // Near the surface, inside the square: offsets of all sizes in every direction.
        for i in 0..30 {
            let (x, y) = (
                2.0 * rng.random::<f64>() - 1.0,
                2.0 * rng.random::<f64>() - 1.0,
            );
            let s = [x, y, m.value(x, y)];
            let d = [
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            ];
            let k = 0.3 * rng.random::<f64>() / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            points.push(if i < 3 {
                s
            } else {
                [s[0] + k * d[0], s[1] + k * d[1], s[2] + k * d[2]]
            });
        }
        // Beyond the sides and corners, and high above the surface.
        points.extend([
            [1.2, 0.3, 0.1],
            [-1.05, -1.1, -0.2],
            [0.99, -1.3, 0.4],
            [0.2, 0.1, 2.0],
            [-0.45, -0.35, -0.6],
            [3.0, 2.0, -1.0],
        ]);
        for p in points {
            let d = m.distance(p);
            let l = m.half_width();
            let c = [p[0].clamp(-l, l), p[1].clamp(-l, l)];
            let reach = (2.0 * m.half_sq(p, c)).sqrt();
            let brute = brute_distance(&m, p, reach);
            assert!(
                (d - brute).abs() <= 1e-12 * brute.max(1e-3),
                "{p:?}: {d} vs brute {brute}"
            );
        }
    }

    #[test]
    fn heightfield_distance_is_exact_for_offsets_along_the_normal() {
        // A point moved along the normal by less than the radius of curvature has that offset
        // as its distance wherever the surface is locally convex toward it: check the vertical
        // projection's bound and the closed form at a bump's top, where h is a Gaussian cap.
        let m = HeightField::new(
            1.0,
            [0.0, 0.0],
            [bump(0.0, 0.0, 0.5, 0.2); HEIGHTFIELD_BUMPS],
        );
        // Eight equal bumps at the origin: h = 1.6 exp(-r²/0.5), curvature 6.4 at the top.
        for t in [1e-3, 0.01, 0.1] {
            let d = m.distance([0.0, 0.0, 1.6 + t]);
            assert!((d - t).abs() < 1e-15, "{t}: {d}");
        }
        // Below the top by less than the radius of curvature (1 / 6.4): the nearest point
        // is still the top.
        let d = m.distance([0.0, 0.0, 1.6 - 0.1]);
        assert!((d - 0.1).abs() < 1e-15, "{d}");
        // Below it by more: the nearest points leave the axis and the distance drops.
        let d = m.distance([0.0, 0.0, 1.6 - 0.5]);
        assert!(d < 0.5 - 1e-3, "{d}");
    }
}
