//! The bumpy sphere: the radial graph `s(u) = r(u) u`,
//! `r(u) = R (1 + a sin(k u_x) sin(k u_y) sin(k u_z))`, its area element, bounding box and
//! the numerical distance to it (see [`crate::synth::Truth::distance`]).

use crate::geom::vec::{add, cross, dot, norm, scale, sub};

/// `r(u) = radius (1 + amplitude g(u))`, `g(u) = sin(k u_x) sin(k u_y) sin(k u_z)`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bumpy {
    radius: f64,
    amplitude: f64,
    k: f64,
}

/// Most directions sampled when looking for starting points of the distance search.
const MAX_DISTANCE_SAMPLES: f64 = 200_000.0;

impl Bumpy {
    /// The relief of base radius `radius`, relative amplitude `amplitude` and frequency `k`.
    pub(crate) fn new(radius: f64, amplitude: f64, k: f64) -> Bumpy {
        Bumpy {
            radius,
            amplitude,
            k,
        }
    }

    /// `r(u)` and the Euclidean gradient of `x ↦ radius (1 + a g(x))` at `u` (its tangential
    /// part is the gradient of `r` on the unit sphere).
    #[inline]
    pub(crate) fn radius_and_gradient(&self, u: [f64; 3]) -> (f64, [f64; 3]) {
        let k = self.k;
        let (sx, cx) = (k * u[0]).sin_cos();
        let (sy, cy) = (k * u[1]).sin_cos();
        let (sz, cz) = (k * u[2]).sin_cos();
        let g = sx * sy * sz;
        let ra = self.radius * self.amplitude;
        let f = ra * k;
        (
            self.radius + ra * g,
            [f * cx * sy * sz, f * sx * cy * sz, f * sx * sy * cz],
        )
    }

    /// `r(u)`.
    #[inline]
    pub(crate) fn radius_at(&self, u: [f64; 3]) -> f64 {
        let k = self.k;
        self.radius
            * (1.0 + self.amplitude * (k * u[0]).sin() * (k * u[1]).sin() * (k * u[2]).sin())
    }

    /// `r(u)` and the gradient of `r` on the unit sphere (tangent to it at `u`).
    #[inline]
    pub(crate) fn radius_and_surface_gradient(&self, u: [f64; 3]) -> (f64, [f64; 3]) {
        let (r, g) = self.radius_and_gradient(u);
        (r, sub(g, scale(u, dot(u, g))))
    }

    /// An upper bound of the area element per solid angle, `r sqrt(r² + |∇r|²)`.
    pub(crate) fn area_density_bound(&self) -> f64 {
        let r_max = self.radius * (1.0 + self.amplitude.abs());
        let grad_max = self.radius * self.amplitude.abs() * self.k;
        r_max * (r_max * r_max + grad_max * grad_max).sqrt()
    }

    /// `max_u r(u) u_x`, the half-width of the bounding cube.
    pub(crate) fn max_extent(&self) -> f64 {
        let a = self.amplitude.abs();
        if a == 0.0 || self.k == 0.0 {
            return self.radius;
        }
        // r(e_x) = R, so the maximum lies where u_x >= 1 / (1 + |a|).
        let t_max = (1.0 / (1.0 + a)).acos();
        let f = |t: f64, phi: f64| {
            let (st, ct) = t.sin_cos();
            let (sp, cp) = phi.sin_cos();
            self.radius_at([ct, st * cp, st * sp]) * ct
        };
        let n_t = ((t_max * self.k * 40.0).ceil() as usize).clamp(64, 2000);
        let n_p = ((std::f64::consts::TAU * t_max * self.k * 40.0).ceil() as usize).clamp(64, 4000);
        let dt = t_max / n_t as f64;
        let dp = std::f64::consts::TAU / n_p as f64;
        let (mut bt, mut bp, mut best) = (0.0, 0.0, f(0.0, 0.0));
        for i in 0..=n_t {
            let t = i as f64 * dt;
            for j in 0..n_p {
                let phi = j as f64 * dp;
                let v = f(t, phi);
                if v > best {
                    (bt, bp, best) = (t, phi, v);
                }
            }
        }
        // Pattern search around the best grid node.
        let (mut st, mut sp) = (dt, dp);
        while st > 1e-14 || sp > 1e-14 {
            let mut moved = false;
            for (ot, op) in [
                (st, 0.0),
                (-st, 0.0),
                (0.0, sp),
                (0.0, -sp),
                (st, sp),
                (st, -sp),
                (-st, sp),
                (-st, -sp),
            ] {
                let v = f(bt + ot, bp + op);
                if v > best {
                    (bt, bp, best) = (bt + ot, bp + op, v);
                    moved = true;
                    break;
                }
            }
            if !moved {
                st *= 0.5;
                sp *= 0.5;
            }
        }
        best
    }

    /// `½ |s(u) - p|²` with `u = normalise(u0 + α e1 + β e2)`, and its gradient in `(α, β)`.
    #[inline]
    fn objective(&self, p: [f64; 3], frame: &Frame, ab: [f64; 2]) -> (f64, [f64; 2]) {
        let w = add(frame.u, add(scale(frame.e1, ab[0]), scale(frame.e2, ab[1])));
        let nw = norm(w);
        let u = scale(w, 1.0 / nw);
        let (r, grad) = self.radius_and_gradient(u);
        let res = sub(scale(u, r), p);
        let h = 0.5 * dot(res, res);
        let mut g = [0.0; 2];
        for (gi, e) in g.iter_mut().zip([frame.e1, frame.e2]) {
            let du = scale(sub(e, scale(u, dot(u, e))), 1.0 / nw);
            let ds = add(scale(u, dot(grad, du)), scale(du, r));
            *gi = dot(res, ds);
        }
        (h, g)
    }

    /// `½ |s(u) - p|²`.
    #[inline]
    fn half_sq(&self, p: [f64; 3], u: [f64; 3]) -> f64 {
        let res = sub(scale(u, self.radius_at(u)), p);
        0.5 * dot(res, res)
    }

    /// Damped Newton descent of `½ |s(u) - p|²` from `u`; returns the value reached.
    fn descend(&self, p: [f64; 3], start: [f64; 3]) -> f64 {
        const FD: f64 = 1e-5;
        const MAX_STEP: f64 = 0.2;
        let mut u = start;
        let mut h = self.half_sq(p, u);
        for _ in 0..100 {
            let frame = Frame::at(u);
            let (h0, g) = self.objective(p, &frame, [0.0, 0.0]);
            h = h0;
            if g[0] == 0.0 && g[1] == 0.0 {
                break;
            }
            // Hessian by central differences of the exact gradient.
            let (_, gap) = self.objective(p, &frame, [FD, 0.0]);
            let (_, gam) = self.objective(p, &frame, [-FD, 0.0]);
            let (_, gbp) = self.objective(p, &frame, [0.0, FD]);
            let (_, gbm) = self.objective(p, &frame, [0.0, -FD]);
            let h00 = (gap[0] - gam[0]) / (2.0 * FD);
            let h11 = (gbp[1] - gbm[1]) / (2.0 * FD);
            let h01 = 0.25 * ((gap[1] - gam[1]) + (gbp[0] - gbm[0])) / FD;
            let half_tr = 0.5 * (h00 + h11);
            let disc = (0.25 * (h00 - h11) * (h00 - h11) + h01 * h01).sqrt();
            let (lmin, lmax) = (half_tr - disc, half_tr + disc);
            let size = lmin.abs().max(lmax.abs()).max(1e-12);
            // Shift to positive definite where the model is not convex.
            let mu = if lmin < 1e-3 * size {
                1e-3 * size - lmin + 0.05 * size
            } else {
                0.0
            };
            let (a, b, c) = (h00 + mu, h01, h11 + mu);
            let det = a * c - b * b;
            let mut step = [-(c * g[0] - b * g[1]) / det, -(a * g[1] - b * g[0]) / det];
            if !(step[0].is_finite() && step[1].is_finite()) {
                let gn = (g[0] * g[0] + g[1] * g[1]).sqrt();
                step = [-g[0] / gn * 1e-3, -g[1] / gn * 1e-3];
            }
            let len = step[0].hypot(step[1]);
            if len > MAX_STEP {
                step = [step[0] * MAX_STEP / len, step[1] * MAX_STEP / len];
            }
            let slope = g[0] * step[0] + g[1] * step[1];
            if slope >= 0.0 {
                break;
            }
            let mut t = 1.0;
            let mut accepted = None;
            for _ in 0..40 {
                let w = add(
                    frame.u,
                    add(scale(frame.e1, t * step[0]), scale(frame.e2, t * step[1])),
                );
                let un = scale(w, 1.0 / norm(w));
                let ht = self.half_sq(p, un);
                if ht <= h0 + 1e-4 * t * slope {
                    accepted = Some((un, ht));
                    break;
                }
                t *= 0.5;
                if t * len < 1e-17 {
                    break;
                }
            }
            match accepted {
                Some((un, ht)) => {
                    u = un;
                    h = ht;
                    if t * step[0].hypot(step[1]) < 1e-14 {
                        break;
                    }
                }
                None => break,
            }
        }
        h
    }

    /// Distance from `p` to the surface; see [`crate::synth::Truth::distance`].
    pub(crate) fn distance(&self, p: [f64; 3]) -> f64 {
        let rp = norm(p);
        let up = if rp > 0.0 {
            scale(p, 1.0 / rp)
        } else {
            [0.0, 0.0, 1.0]
        };
        // The radial point is on the surface: its distance bounds the answer.
        let d_radial = (rp - self.radius_at(up)).abs();
        let mut best_h = 0.5 * d_radial * d_radial;
        if self.amplitude == 0.0 || self.k == 0.0 {
            return d_radial;
        }

        // Sample the directions where the nearest point can lie.
        let mut spacing = (0.25 / self.k).min(0.03);
        let global = d_radial >= rp * 0.999 || (d_radial / rp).asin() > 1.0;
        let mut samples: Vec<([f64; 3], f64)> = Vec::new();
        if global {
            let mut n = (4.0 * std::f64::consts::PI / (spacing * spacing)).ceil();
            if n > MAX_DISTANCE_SAMPLES {
                n = MAX_DISTANCE_SAMPLES;
                spacing = (4.0 * std::f64::consts::PI / n).sqrt();
            }
            let n = n as usize;
            let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
            for i in 0..n {
                let z = 1.0 - (2 * i + 1) as f64 / n as f64;
                let rho = (1.0 - z * z).max(0.0).sqrt();
                let (s, c) = (golden * i as f64).sin_cos();
                let u = [rho * c, rho * s, z];
                samples.push((u, self.half_sq(p, u)));
            }
        } else {
            let theta_max = (d_radial / rp).asin() * 1.01 + 1e-12;
            let area = std::f64::consts::PI * theta_max * theta_max;
            if area / (spacing * spacing) > MAX_DISTANCE_SAMPLES {
                spacing = (area / MAX_DISTANCE_SAMPLES).sqrt();
            }
            let frame = Frame::at(up);
            let rings = (theta_max / spacing).ceil() as usize;
            for j in 1..=rings {
                let th = theta_max * j as f64 / rings as f64;
                let (st, ct) = th.sin_cos();
                let m = ((std::f64::consts::TAU * st / spacing).ceil() as usize).max(6);
                for i in 0..m {
                    let (sp, cp) = (std::f64::consts::TAU * (i as f64 + 0.5 * (j % 2) as f64)
                        / m as f64)
                        .sin_cos();
                    let u = add(
                        scale(frame.u, ct),
                        add(scale(frame.e1, st * cp), scale(frame.e2, st * sp)),
                    );
                    samples.push((u, self.half_sq(p, u)));
                }
            }
        }
        samples.sort_by(|a, b| a.1.total_cmp(&b.1));

        // Starts: the radial direction and the best samples, pairwise apart.
        const MAX_STARTS: usize = 8;
        let min_cos = (2.0 * spacing).cos();
        let mut starts: Vec<[f64; 3]> = vec![up];
        for (u, _) in &samples {
            if starts.len() > MAX_STARTS {
                break;
            }
            if starts.iter().all(|s| dot(*s, *u) < min_cos) {
                starts.push(*u);
            }
        }
        if let Some((_, h)) = samples.first() {
            best_h = best_h.min(*h);
        }
        for s in starts {
            best_h = best_h.min(self.descend(p, s));
        }
        (2.0 * best_h).sqrt()
    }
}

/// A unit vector and an orthonormal basis of its tangent plane.
struct Frame {
    u: [f64; 3],
    e1: [f64; 3],
    e2: [f64; 3],
}

impl Frame {
    fn at(u: [f64; 3]) -> Frame {
        // The axis least aligned with u.
        let a = [u[0].abs(), u[1].abs(), u[2].abs()];
        let axis = if a[0] <= a[1] && a[0] <= a[2] {
            [1.0, 0.0, 0.0]
        } else if a[1] <= a[2] {
            [0.0, 1.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        let t = sub(axis, scale(u, dot(u, axis)));
        let e1 = scale(t, 1.0 / norm(t));
        let e2 = cross(u, e1);
        Frame { u, e1, e2 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::sampler::uniform_direction;
    use crate::synth::{Shape, Truth};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn bumpy_bounding_box_is_tight() {
        let m = Bumpy::new(1.0, 0.05, 8.0);
        let b = m.max_extent();
        // Brute force over a fine grid of directions near +x, and the -x side.
        let mut best = f64::NEG_INFINITY;
        let mut least = f64::INFINITY;
        let n = 1500;
        for i in 0..=n {
            let t = 0.35 * i as f64 / n as f64;
            for j in 0..n {
                let ph = std::f64::consts::TAU * j as f64 / n as f64;
                let u = [t.cos(), t.sin() * ph.cos(), t.sin() * ph.sin()];
                best = best.max(m.radius_at(u) * u[0]);
                let v = [-u[0], u[1], u[2]];
                least = least.min(m.radius_at(v) * v[0]);
            }
        }
        assert!(b >= best - 1e-12 && b - best < 1e-5, "{b} vs {best}");
        assert!((least + b).abs() < 1e-5, "{least} vs {b}");
    }

    /// Brute force: dense directions in a cone around `p`'s direction, then repeated local
    /// grid refinement around the best few.
    fn brute_distance(m: &Bumpy, p: [f64; 3], cone: f64) -> f64 {
        let up = scale(p, 1.0 / norm(p));
        let f = Frame::at(up);
        let dir = |a: f64, b: f64| {
            let w = add(up, add(scale(f.e1, a), scale(f.e2, b)));
            scale(w, 1.0 / norm(w))
        };
        let n = 300;
        let step = 2.0 * cone / n as f64;
        let mut cands: Vec<(f64, f64, f64)> = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let (a, b) = (-cone + i as f64 * step, -cone + j as f64 * step);
                cands.push((m.half_sq(p, dir(a, b)), a, b));
            }
        }
        cands.sort_by(|x, y| x.0.total_cmp(&y.0));
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
            let (mut a, mut b, mut h) = (a0, b0, m.half_sq(p, dir(a0, b0)));
            let mut s = step;
            for _ in 0..12 {
                let (ca, cb) = (a, b);
                for i in -10..=10 {
                    for j in -10..=10 {
                        let (x, y) = (ca + i as f64 * s / 5.0, cb + j as f64 * s / 5.0);
                        let v = m.half_sq(p, dir(x, y));
                        if v < h {
                            (a, b, h) = (x, y, v);
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
    fn bumpy_distance_matches_brute_force() {
        let truth = Truth::standard(Shape::Bumpy);
        let m = Bumpy::new(1.0, 0.05, 8.0);
        let mut rng = Pcg64::seed_from_u64(99);
        for i in 0..40 {
            let u = uniform_direction(&mut rng);
            let s = scale(u, m.radius_at(u));
            let off = scale(uniform_direction(&mut rng), 0.1 * rng.random::<f64>());
            let p = if i < 5 { s } else { add(s, off) };
            let d = truth.distance(p);
            let brute = brute_distance(&m, p, 0.16);
            assert!(
                (d - brute).abs() <= 1e-9 * brute.max(1e-3),
                "{p:?}: {d} vs brute {brute}"
            );
        }
    }

    #[test]
    fn bumpy_distance_far_and_degenerate() {
        // Flat relief: the sphere's closed form.
        let flat = Truth::Bumpy {
            radius: 1.0,
            amplitude: 0.0,
            frequency: 8.0,
        };
        for p in [[0.3, -0.2, 0.1], [2.0, 1.0, -1.0], [0.0; 3]] {
            let e = (norm(p) - 1.0).abs();
            assert!((flat.distance(p) - e).abs() < 1e-15);
        }
        let truth = Truth::standard(Shape::Bumpy);
        let m = Bumpy::new(1.0, 0.05, 8.0);
        // The centre: the smallest radius.
        let mut rmin = f64::INFINITY;
        let n = 600;
        for i in 0..n {
            let t = std::f64::consts::PI * (i as f64 + 0.5) / n as f64;
            for j in 0..2 * n {
                let ph = std::f64::consts::PI * j as f64 / n as f64;
                rmin = rmin.min(m.radius_at([t.sin() * ph.cos(), t.sin() * ph.sin(), t.cos()]));
            }
        }
        let d0 = truth.distance([0.0; 3]);
        assert!(d0 <= rmin + 1e-12 && d0 > rmin - 1e-5, "{d0} vs {rmin}");
        // Far away: never more than the radial distance, close to |p| - 1.
        let p = [3.0, -2.0, 1.5];
        let d = truth.distance(p);
        assert!(d <= (norm(p) - m.radius_at(scale(p, 1.0 / norm(p)))).abs() + 1e-15);
        assert!((d - (norm(p) - 1.0)).abs() < 0.06);
    }
}
