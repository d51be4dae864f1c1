//! Evaluation of a bicubic [`TensorSurface`] with derivatives, and the orthogonal projection
//! of a point onto it.
//!
//! Evaluation follows Piegl & Tiller, *The NURBS Book* (2nd ed.), A2.1 (the knot span by
//! binary search) and A2.3 (the nonzero basis functions and their derivatives). Projection is
//! Newton's method on `f(u, v) = ½ |S(u, v) - p|²` (gradient `(S_u·r, S_v·r)`, Hessian
//! `[S_a·S_b + S_ab·r]` with `r = S - p`), kept inside the domain and backed by halving the
//! step whenever the distance grows, so it converges to the foot point nearest the start. The
//! fitting loop starts it from the point's own parameter; that foot point is the one an
//! independent reader (OpenCascade's `GeomAPI_ProjectPointOnSurf`) reports as the lower
//! distance whenever the surface does not fold back to within that distance of the point.

use crate::types::TensorSurface;

/// The index `k` of the knot span `[t_k, t_{k+1})` holding `u`, for `count` control points of
/// degree `p` (the last span for `u` at the domain's end).
pub fn find_span(t: &[f64], p: usize, count: usize, u: f64) -> usize {
    let n = count - 1;
    if u >= t[n + 1] {
        return n;
    }
    if u <= t[p] {
        return p;
    }
    // The last k with t[k] <= u, within [p, n].
    let k = t[..=n + 1].partition_point(|&x| x <= u) - 1;
    k.clamp(p, n)
}

/// The four nonzero cubic basis functions at `u` on span `k` and their first and second
/// derivatives (`[[N], [N'], [N'']]`, functions `k - 3, …, k`).
pub fn cubic_ders(t: &[f64], k: usize, u: f64) -> [[f64; 4]; 3] {
    const P: usize = 3;
    let mut ndu = [[0.0f64; 4]; 4];
    let mut left = [0.0f64; 4];
    let mut right = [0.0f64; 4];
    ndu[0][0] = 1.0;
    for j in 1..=P {
        left[j] = u - t[k + 1 - j];
        right[j] = t[k + j] - u;
        let mut saved = 0.0;
        for r in 0..j {
            ndu[j][r] = right[r + 1] + left[j - r];
            let temp = if ndu[j][r] != 0.0 {
                ndu[r][j - 1] / ndu[j][r]
            } else {
                0.0
            };
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    let mut ders = [[0.0f64; 4]; 3];
    for j in 0..=P {
        ders[0][j] = ndu[j][P];
    }
    let mut a = [[0.0f64; 4]; 2];
    for r in 0..=P {
        let (mut s1, mut s2) = (0usize, 1usize);
        a[0][0] = 1.0;
        for kk in 1..=2usize {
            let mut d = 0.0;
            let rk = r as isize - kk as isize;
            let pk = P - kk;
            if r >= kk {
                let rk = rk as usize;
                a[s2][0] = if ndu[pk + 1][rk] != 0.0 {
                    a[s1][0] / ndu[pk + 1][rk]
                } else {
                    0.0
                };
                d = a[s2][0] * ndu[rk][pk];
            }
            let j1 = if rk >= -1 { 1 } else { (-rk) as usize };
            let j2 = if r as isize - 1 <= pk as isize {
                kk - 1
            } else {
                P - r
            };
            for j in j1..=j2 {
                let idx = (rk + j as isize) as usize;
                a[s2][j] = if ndu[pk + 1][idx] != 0.0 {
                    (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][idx]
                } else {
                    0.0
                };
                d += a[s2][j] * ndu[idx][pk];
            }
            if r <= pk {
                a[s2][kk] = if ndu[pk + 1][r] != 0.0 {
                    -a[s1][kk - 1] / ndu[pk + 1][r]
                } else {
                    0.0
                };
                d += a[s2][kk] * ndu[r][pk];
            }
            ders[kk][r] = d;
            std::mem::swap(&mut s1, &mut s2);
        }
    }
    ders[1].iter_mut().for_each(|x| *x *= 3.0);
    ders[2].iter_mut().for_each(|x| *x *= 6.0);
    ders
}

/// `(S, S_u, S_v, S_uu, S_uv, S_vv)` of a bicubic surface at `uv` (clamped into the domain).
pub fn eval(s: &TensorSurface, uv: [f64; 2]) -> [[f64; 3]; 6] {
    let dom = s.domain();
    let u = uv[0].clamp(dom[0][0], dom[0][1]);
    let v = uv[1].clamp(dom[1][0], dom[1][1]);
    let ku = find_span(&s.knots[0], 3, s.count[0], u);
    let kv = find_span(&s.knots[1], 3, s.count[1], v);
    let bu = cubic_ders(&s.knots[0], ku, u);
    let bv = cubic_ders(&s.knots[1], kv, v);
    let mut out = [[0.0; 3]; 6];
    for (b, row) in (kv - 3..=kv).enumerate() {
        for (a, col) in (ku - 3..=ku).enumerate() {
            let c = s.ctrl[col + s.count[0] * row];
            let w = [
                bu[0][a] * bv[0][b],
                bu[1][a] * bv[0][b],
                bu[0][a] * bv[1][b],
                bu[2][a] * bv[0][b],
                bu[1][a] * bv[1][b],
                bu[0][a] * bv[2][b],
            ];
            for k in 0..6 {
                for x in 0..3 {
                    out[k][x] += w[k] * c[x];
                }
            }
        }
    }
    out
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The foot point of `p` on `s` nearest the start `uv0`, and its distance (module docs).
pub fn project(s: &TensorSurface, p: [f64; 3], uv0: [f64; 2]) -> ([f64; 2], f64) {
    let dom = s.domain();
    let clamp = |uv: [f64; 2]| {
        [
            uv[0].clamp(dom[0][0], dom[0][1]),
            uv[1].clamp(dom[1][0], dom[1][1]),
        ]
    };
    let scale = (dom[0][1] - dom[0][0]).max(dom[1][1] - dom[1][0]);
    let mut uv = clamp(uv0);
    let mut d = eval(s, uv);
    let mut r = sub(d[0], p);
    let mut f = dot(r, r);
    for _ in 0..30 {
        let g = [dot(d[1], r), dot(d[2], r)];
        let h = [
            dot(d[1], d[1]) + dot(d[3], r),
            dot(d[1], d[2]) + dot(d[4], r),
            dot(d[2], d[2]) + dot(d[5], r),
        ];
        let det = h[0] * h[2] - h[1] * h[1];
        let mut step = if det > 0.0 && h[0] > 0.0 {
            [
                -(h[2] * g[0] - h[1] * g[1]) / det,
                -(h[0] * g[1] - h[1] * g[0]) / det,
            ]
        } else {
            // Gauss–Newton: the first fundamental form alone is positive semi-definite.
            let (a, b, c) = (dot(d[1], d[1]), dot(d[1], d[2]), dot(d[2], d[2]));
            let det = a * c - b * b;
            if det <= 0.0 {
                break;
            }
            [-(c * g[0] - b * g[1]) / det, -(a * g[1] - b * g[0]) / det]
        };
        let mut accepted = false;
        for _ in 0..30 {
            let cand = clamp([uv[0] + step[0], uv[1] + step[1]]);
            let dc = eval(s, cand);
            let rc = sub(dc[0], p);
            let fc = dot(rc, rc);
            if fc <= f {
                let moved = (cand[0] - uv[0]).abs().max((cand[1] - uv[1]).abs());
                uv = cand;
                d = dc;
                r = rc;
                f = fc;
                accepted = moved > 1e-15 * scale;
                break;
            }
            step = [step[0] * 0.5, step[1] * 0.5];
        }
        if !accepted {
            break;
        }
    }
    (uv, f.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::cox_de_boor;

    fn surface() -> TensorSurface {
        let knots = vec![0.0, 0.0, 0.0, 0.0, 0.7, 1.0, 2.5, 3.0, 3.0, 3.0, 3.0];
        let kv = vec![0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 2.0, 2.0, 2.0];
        let count = [knots.len() - 4, kv.len() - 4];
        let ctrl = (0..count[0] * count[1])
            .map(|k| {
                let (i, j) = ((k % count[0]) as f64, (k / count[0]) as f64);
                [i, j, (i * 1.3 + j * 0.7).sin()]
            })
            .collect();
        TensorSurface {
            degree: [3, 3],
            knots: [knots, kv],
            count,
            ctrl,
        }
    }

    fn brute(s: &TensorSurface, uv: [f64; 2]) -> [f64; 3] {
        let mut out = [0.0; 3];
        for j in 0..s.count[1] {
            for i in 0..s.count[0] {
                let w = cox_de_boor(&s.knots[0][i..i + 5], uv[0])
                    * cox_de_boor(&s.knots[1][j..j + 5], uv[1]);
                for x in 0..3 {
                    out[x] += w * s.ctrl[i + s.count[0] * j][x];
                }
            }
        }
        out
    }

    #[test]
    fn eval_matches_cox_de_boor_and_finite_differences() {
        let s = surface();
        for k in 0..50 {
            let uv = [
                0.01 + 2.97 * (k as f64 * 0.37).fract(),
                0.01 + 1.97 * (k as f64 * 0.61).fract(),
            ];
            let d = eval(&s, uv);
            let b = brute(&s, uv);
            for x in 0..3 {
                assert!((d[0][x] - b[x]).abs() < 1e-13);
            }
            let e = 1e-6;
            let du = sub(
                eval(&s, [uv[0] + e, uv[1]])[0],
                eval(&s, [uv[0] - e, uv[1]])[0],
            );
            let dv = sub(
                eval(&s, [uv[0], uv[1] + e])[0],
                eval(&s, [uv[0], uv[1] - e])[0],
            );
            let duv = sub(
                eval(&s, [uv[0], uv[1] + e])[1],
                eval(&s, [uv[0], uv[1] - e])[1],
            );
            for x in 0..3 {
                assert!((du[x] / (2.0 * e) - d[1][x]).abs() < 1e-6);
                assert!((dv[x] / (2.0 * e) - d[2][x]).abs() < 1e-6);
                assert!((duv[x] / (2.0 * e) - d[4][x]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn projection_of_an_offset_point_recovers_its_foot_and_distance() {
        let s = surface();
        for k in 0..30 {
            let uv = [
                0.3 + 2.4 * (k as f64 * 0.37).fract(),
                0.3 + 1.4 * (k as f64 * 0.61).fract(),
            ];
            let d = eval(&s, uv);
            let n = [
                d[1][1] * d[2][2] - d[1][2] * d[2][1],
                d[1][2] * d[2][0] - d[1][0] * d[2][2],
                d[1][0] * d[2][1] - d[1][1] * d[2][0],
            ];
            let len = dot(n, n).sqrt();
            let off = 0.01;
            let p = [0, 1, 2].map(|x| d[0][x] + off * n[x] / len);
            let start = [uv[0] + 0.05, uv[1] - 0.04];
            let (foot, dist) = project(&s, p, start);
            assert!((dist - off).abs() < 1e-10, "{dist}");
            assert!((foot[0] - uv[0]).abs() < 1e-7 && (foot[1] - uv[1]).abs() < 1e-7);
        }
    }
}
