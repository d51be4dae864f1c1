//! A tensor-product B-spline surface, as the spline stage hands it to the writers.

/// A non-rational tensor-product B-spline surface `S(u, v) = Σ_ij c_ij N_i(u) M_j(v)` in world
/// coordinates (the input's units and frame).
///
/// `knots[0]` is the u knot vector (non-decreasing, `count[0] + degree[0] + 1` values),
/// `knots[1]` the v one. The surface's domain is `[knots[0][degree[0]], knots[0][count[0]]] ×
/// [knots[1][degree[1]], knots[1][count[1]]]`; the spline stage always writes clamped knot
/// vectors (end knots of multiplicity `degree + 1`), so the domain is the first and last knot.
/// Control points are stored with u fastest: `ctrl[i + count[0] * j]` is `c_ij`.
#[derive(Debug, Clone, PartialEq)]
pub struct TensorSurface {
    /// Polynomial degree along u and v (3 for the spline stage's bicubic surfaces).
    pub degree: [usize; 2],
    /// Knot vectors along u and v, in parameter units.
    pub knots: [Vec<f64>; 2],
    /// Number of control points along u and v.
    pub count: [usize; 2],
    /// Control points, u fastest, in world coordinates.
    pub ctrl: Vec<[f64; 3]>,
}

impl TensorSurface {
    /// The parameter domain as `[[u0, u1], [v0, v1]]`.
    pub fn domain(&self) -> [[f64; 2]; 2] {
        [0, 1].map(|d| [self.knots[d][self.degree[d]], self.knots[d][self.count[d]]])
    }

    /// Whether the sizes agree: knot counts, control-point count, degrees at least 1.
    pub fn is_consistent(&self) -> bool {
        (0..2).all(|d| {
            self.degree[d] >= 1
                && self.count[d] > self.degree[d]
                && self.knots[d].len() == self.count[d] + self.degree[d] + 1
                && self.knots[d].windows(2).all(|w| w[0] <= w[1])
        }) && self.ctrl.len() == self.count[0] * self.count[1]
    }
}

/// The B-spline basis along one direction at `t`: the span `s` (`knots[s] <= t <
/// knots[s + 1]`, the last nonempty span at the domain's end) and the `degree + 1` functions
/// `N_{s-degree..=s}` that do not vanish there, with their first derivatives.
///
/// Piegl & Tiller, *The NURBS Book*, A2.1 (span) and A2.2 (basis) run to degree `p - 1`; the
/// degree-`p` values and derivatives then follow from one step of the Cox–de Boor recursion,
/// `N_{i,p} = (t-u_i)/(u_{i+p}-u_i) N_{i,p-1} + (u_{i+p+1}-t)/(u_{i+p+1}-u_{i+1}) N_{i+1,p-1}`
/// and `N'_{i,p} = p/(u_{i+p}-u_i) N_{i,p-1} - p/(u_{i+p+1}-u_{i+1}) N_{i+1,p-1}`, a quotient
/// with a zero denominator counting as 0. `t` is clamped to the domain `[knots[degree],
/// knots[count]]`. Requires a consistent direction (see [`TensorSurface::is_consistent`]).
fn basis(knots: &[f64], degree: usize, count: usize, t: f64) -> (usize, Vec<f64>, Vec<f64>) {
    let p = degree;
    let (lo, hi) = (knots[p], knots[count]);
    let t = t.clamp(lo, hi);
    // Last span with knots[s] <= t, kept below the domain's end and nonempty.
    let mut s = p + knots[p..count]
        .partition_point(|&k| k <= t)
        .saturating_sub(1);
    while s > p && knots[s] == knots[s + 1] {
        s -= 1;
    }
    // A2.2 to degree p - 1: a[k] = N_{s-p+1+k, p-1}.
    let q = p - 1;
    let mut a = vec![0.0; q + 1];
    let (mut left, mut right) = (vec![0.0; q + 1], vec![0.0; q + 1]);
    a[0] = 1.0;
    for j in 1..=q {
        left[j] = t - knots[s + 1 - j];
        right[j] = knots[s + j] - t;
        let mut saved = 0.0;
        for r in 0..j {
            let den = right[r + 1] + left[j - r];
            let tmp = if den == 0.0 { 0.0 } else { a[r] / den };
            a[r] = saved + right[r + 1] * tmp;
            saved = left[j - r] * tmp;
        }
        a[j] = saved;
    }
    let lower = |i: usize| -> f64 {
        // N_{i,p-1}, nonzero only for i in s-p+1..=s.
        if i + p > s && i <= s {
            a[i + p - s - 1]
        } else {
            0.0
        }
    };
    let ratio = |num: f64, den: f64| if den == 0.0 { 0.0 } else { num / den };
    let (mut n, mut d) = (vec![0.0; p + 1], vec![0.0; p + 1]);
    for k in 0..=p {
        let i = s - p + k;
        let (l0, l1) = (lower(i), lower(i + 1));
        let (d0, d1) = (knots[i + p] - knots[i], knots[i + p + 1] - knots[i + 1]);
        n[k] = ratio(t - knots[i], d0) * l0 + ratio(knots[i + p + 1] - t, d1) * l1;
        d[k] = ratio(p as f64, d0) * l0 - ratio(p as f64, d1) * l1;
    }
    (s, n, d)
}

impl TensorSurface {
    /// The point `S(u, v)`; `(u, v)` is clamped to the [domain](TensorSurface::domain).
    /// Requires [`TensorSurface::is_consistent`].
    pub fn eval(&self, u: f64, v: f64) -> [f64; 3] {
        self.eval_derivs(u, v)[0]
    }

    /// `[S, ∂S/∂u, ∂S/∂v]` at `(u, v)` (clamped to the domain), by the basis and its first
    /// derivatives along each direction (Piegl & Tiller, *The NURBS Book*, A2.2 and the
    /// derivative recursion) summed over the `(degree[0] + 1) × (degree[1] + 1)` control points whose
    /// functions do not vanish there. At a knot the derivative is the one of the span to its
    /// right (of the last span at the domain's end). Any degree ≥ 1, clamped or not.
    /// Requires [`TensorSurface::is_consistent`].
    pub fn eval_derivs(&self, u: f64, v: f64) -> [[f64; 3]; 3] {
        let (su, nu, du) = basis(&self.knots[0], self.degree[0], self.count[0], u);
        let (sv, nv, dv) = basis(&self.knots[1], self.degree[1], self.count[1], v);
        let (iu, iv) = (su - self.degree[0], sv - self.degree[1]);
        let mut out = [[0.0; 3]; 3];
        for (l, (&bv, &bdv)) in nv.iter().zip(&dv).enumerate() {
            let row = (iv + l) * self.count[0] + iu;
            for (k, (&bu, &bdu)) in nu.iter().zip(&du).enumerate() {
                let c = self.ctrl[row + k];
                for x in 0..3 {
                    out[0][x] += bu * bv * c[x];
                    out[1][x] += bdu * bv * c[x];
                    out[2][x] += bu * bdv * c[x];
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Cox–de Boor by its definition: half-open intervals, 0/0 = 0.
    fn cox_de_boor(knots: &[f64], i: usize, p: usize, t: f64) -> f64 {
        if p == 0 {
            return f64::from(u8::from(knots[i] <= t && t < knots[i + 1]));
        }
        let r = |num: f64, den: f64| if den == 0.0 { 0.0 } else { num / den };
        r(t - knots[i], knots[i + p] - knots[i]) * cox_de_boor(knots, i, p - 1, t)
            + r(knots[i + p + 1] - t, knots[i + p + 1] - knots[i + 1])
                * cox_de_boor(knots, i + 1, p - 1, t)
    }

    /// The surface summed over every control point with the brute-force basis.
    fn brute(s: &TensorSurface, u: f64, v: f64) -> [f64; 3] {
        let mut out = [0.0; 3];
        for j in 0..s.count[1] {
            let bv = cox_de_boor(&s.knots[1], j, s.degree[1], v);
            for i in 0..s.count[0] {
                let b = cox_de_boor(&s.knots[0], i, s.degree[0], u) * bv;
                let c = s.ctrl[i + s.count[0] * j];
                for x in 0..3 {
                    out[x] += b * c[x];
                }
            }
        }
        out
    }

    /// A surface of degrees (3, 2), non-uniform knots (a double interior knot along u),
    /// clamped along u and not along v, pseudo-random control points.
    fn sample_surface() -> TensorSurface {
        let knots = [
            vec![0.0, 0.0, 0.0, 0.0, 0.3, 0.3, 0.5, 0.9, 1.0, 1.0, 1.0, 1.0],
            vec![-1.0, -0.5, 0.0, 0.25, 1.0, 1.5, 2.0, 3.5],
        ];
        let count = [8, 5];
        let mut state = 12345u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let ctrl = (0..count[0] * count[1])
            .map(|_| [rnd(), rnd(), rnd()])
            .collect();
        TensorSurface {
            degree: [3, 2],
            knots,
            count,
            ctrl,
        }
    }

    #[test]
    fn eval_matches_brute_force_cox_de_boor_sum() {
        let s = sample_surface();
        assert!(s.is_consistent());
        let [[u0, u1], [v0, v1]] = s.domain();
        assert_eq!([u0, u1, v0, v1], [0.0, 1.0, 0.0, 1.5]);
        for a in 0..23 {
            for b in 0..19 {
                // Strictly inside the domain (the brute force's half-open end), knots included.
                let u = u0 + (u1 - u0) * a as f64 / 23.0;
                let v = v0 + (v1 - v0) * b as f64 / 19.0;
                let (got, want) = (s.eval(u, v), brute(&s, u, v));
                for x in 0..3 {
                    assert!(
                        (got[x] - want[x]).abs() < 1e-14,
                        "({u}, {v}): {got:?} {want:?}"
                    );
                }
            }
        }
        for u in [0.3, 0.5, 0.9] {
            let (got, want) = (s.eval(u, 0.6), brute(&s, u, 0.6));
            assert!((0..3).all(|x| (got[x] - want[x]).abs() < 1e-14));
        }
    }

    #[test]
    fn eval_at_domain_end_is_the_limit_from_inside() {
        let s = sample_surface();
        let [[_, u1], [_, v1]] = s.domain();
        let end = s.eval(u1, v1);
        let near = brute(&s, u1 - 1e-12, v1 - 1e-12);
        assert!(
            (0..3).all(|x| (end[x] - near[x]).abs() < 1e-9),
            "{end:?} {near:?}"
        );
        // Clamped along u: the corner row's control point is interpolated.
        let c = s.eval(0.0, 0.75);
        let b = brute(&s, 0.0, 0.75);
        assert!((0..3).all(|x| (c[x] - b[x]).abs() < 1e-14));
        // Outside the domain is clamped.
        assert_eq!(s.eval(-5.0, 9.0), s.eval(0.0, v1));
    }

    #[test]
    fn eval_derivs_match_central_differences() {
        let s = sample_surface();
        let h = 1e-6;
        for (u, v) in [(0.1, 0.2), (0.41, 0.6), (0.7, 1.2), (0.95, 0.1)] {
            let d = s.eval_derivs(u, v);
            let (pu, mu) = (brute(&s, u + h, v), brute(&s, u - h, v));
            let (pv, mv) = (brute(&s, u, v + h), brute(&s, u, v - h));
            for x in 0..3 {
                assert!(
                    (d[1][x] - (pu[x] - mu[x]) / (2.0 * h)).abs() < 1e-6,
                    "{d:?}"
                );
                assert!(
                    (d[2][x] - (pv[x] - mv[x]) / (2.0 * h)).abs() < 1e-6,
                    "{d:?}"
                );
            }
        }
    }
}
