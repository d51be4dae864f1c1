//! Frames as band-4 spherical harmonics (module docs of [`super`], "Representation", Huang
//! §3, Ray §3.1): the scaled real harmonics and their gradients, a frame's 9 coefficients and
//! their Jacobian under rotation, the SH distance, and the projection of a coefficient vector
//! onto the closest frame (Huang §5.1, Ray §4.2: the best of fixed candidate frames, then
//! Gauss–Newton on the rotation); with the unit-vector and 9-vector helpers they use.

use std::sync::OnceLock;

use crate::geom::vec::{add, cross, dot, norm, scale, sub};
use crate::mesh::Frame;

/// Scale of the polynomials in [`sh_basis`]: the harmonic's constant over `(3/16)√(1/π)`,
/// divided by `√336`, so that `Σₖ Y(aₖ)` of a frame has norm 1.
pub(super) const SH_SCALE: [f64; 9] = [
    1.290_994_448_735_805_6,
    0.912_870_929_175_276_9,
    0.487_950_036_474_266_66,
    0.345_032_779_671_177_1,
    0.054_554_472_558_998_1,
    0.345_032_779_671_177_1,
    0.243_975_018_237_133_33,
    0.912_870_929_175_276_9,
    0.322_748_612_183_951_4,
];

#[inline]
pub(super) fn unit3(a: [f64; 3]) -> [f64; 3] {
    scale(a, 1.0 / norm(a))
}

#[inline]
pub(super) fn dot9(a: &[f64; 9], b: &[f64; 9]) -> f64 {
    let mut s = 0.0;
    for m in 0..9 {
        s += a[m] * b[m];
    }
    s
}

#[inline]
pub(super) fn dist2_9(a: &[f64; 9], b: &[f64; 9]) -> f64 {
    let mut s = 0.0;
    for m in 0..9 {
        let d = a[m] - b[m];
        s += d * d;
    }
    s
}

/// `v` rotated by the rotation vector `w` (Rodrigues).
pub(super) fn rotate(v: [f64; 3], w: [f64; 3]) -> [f64; 3] {
    let th = norm(w);
    if th < 1e-300 {
        return v;
    }
    let k = scale(w, 1.0 / th);
    let (s, c) = th.sin_cos();
    let kv = cross(k, v);
    let kd = dot(k, v) * (1.0 - c);
    [
        v[0] * c + kv[0] * s + k[0] * kd,
        v[1] * c + kv[1] * s + k[1] * kd,
        v[2] * c + kv[2] * s + k[2] * kd,
    ]
}

/// Gram–Schmidt: a right-handed orthonormal frame close to `f`.
pub(super) fn orthonormalise(f: Frame) -> Frame {
    let a0 = unit3(f[0]);
    let a1 = unit3(sub(f[1], scale(a0, dot(a0, f[1]))));
    [a0, a1, cross(a0, a1)]
}

/// A right-handed `(t₁, t₂)` with `t₁ × t₂ = n` for a unit `n`.
pub(crate) fn tangents(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let helper = if n[0].abs() <= n[1].abs() && n[0].abs() <= n[2].abs() {
        [1.0, 0.0, 0.0]
    } else if n[1].abs() <= n[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let t1 = unit3(cross(helper, n));
    (t1, cross(n, t1))
}

/// The frame `[cos θ t₁ + sin θ t₂, −sin θ t₁ + cos θ t₂, n]`.
pub(super) fn frame_about(n: [f64; 3], t1: [f64; 3], t2: [f64; 3], theta: f64) -> Frame {
    let (s, c) = theta.sin_cos();
    [
        add(scale(t1, c), scale(t2, s)),
        add(scale(t1, -s), scale(t2, c)),
        n,
    ]
}

/// The 9 band-4 real spherical harmonics at the unit vector `d`, ordered `m = −4 … 4`, each
/// scaled by `1 / (√336 · (3/16)√(1/π))` (so that [`frame_to_sh`] has norm 1).
#[inline]
pub(super) fn sh_basis(d: [f64; 3]) -> [f64; 9] {
    let [x, y, z] = d;
    let (x2, y2, z2) = (x * x, y * y, z * z);
    [
        SH_SCALE[0] * (x2 - y2) * x * y,
        SH_SCALE[1] * (3.0 * x2 - y2) * y * z,
        SH_SCALE[2] * x * y * (6.0 * z2 - x2 - y2),
        SH_SCALE[3] * y * z * (4.0 * z2 - 3.0 * x2 - 3.0 * y2),
        SH_SCALE[4]
            * (8.0 * z2 * z2 + 3.0 * x2 * x2 + 3.0 * y2 * y2 + 6.0 * x2 * y2
                - 24.0 * x2 * z2
                - 24.0 * y2 * z2),
        SH_SCALE[5] * x * z * (4.0 * z2 - 3.0 * x2 - 3.0 * y2),
        SH_SCALE[6] * (x2 - y2) * (6.0 * z2 - x2 - y2),
        SH_SCALE[7] * (x2 - 3.0 * y2) * x * z,
        SH_SCALE[8] * (x2 * x2 - 6.0 * x2 * y2 + y2 * y2),
    ]
}

/// Gradients of the (homogeneous, harmonic) polynomials of [`sh_basis`].
#[inline]
pub(super) fn sh_basis_grad(d: [f64; 3]) -> [[f64; 3]; 9] {
    let [x, y, z] = d;
    let (x2, y2, z2) = (x * x, y * y, z * z);
    let g = [
        [3.0 * x2 * y - y2 * y, x2 * x - 3.0 * x * y2, 0.0],
        [
            6.0 * x * y * z,
            (3.0 * x2 - 3.0 * y2) * z,
            3.0 * x2 * y - y2 * y,
        ],
        [
            6.0 * y * z2 - 3.0 * x2 * y - y2 * y,
            6.0 * x * z2 - x2 * x - 3.0 * x * y2,
            12.0 * x * y * z,
        ],
        [
            -6.0 * x * y * z,
            4.0 * z2 * z - 3.0 * x2 * z - 9.0 * y2 * z,
            12.0 * y * z2 - 3.0 * x2 * y - 3.0 * y2 * y,
        ],
        [
            12.0 * x2 * x + 12.0 * x * y2 - 48.0 * x * z2,
            12.0 * y2 * y + 12.0 * x2 * y - 48.0 * y * z2,
            32.0 * z2 * z - 48.0 * x2 * z - 48.0 * y2 * z,
        ],
        [
            4.0 * z2 * z - 9.0 * x2 * z - 3.0 * y2 * z,
            -6.0 * x * y * z,
            12.0 * x * z2 - 3.0 * x2 * x - 3.0 * x * y2,
        ],
        [
            12.0 * x * z2 - 4.0 * x2 * x,
            4.0 * y2 * y - 12.0 * y * z2,
            12.0 * x2 * z - 12.0 * y2 * z,
        ],
        [
            (3.0 * x2 - 3.0 * y2) * z,
            -6.0 * x * y * z,
            x2 * x - 3.0 * x * y2,
        ],
        [
            4.0 * x2 * x - 12.0 * x * y2,
            4.0 * y2 * y - 12.0 * x2 * y,
            0.0,
        ],
    ];
    let mut out = [[0.0; 3]; 9];
    for m in 0..9 {
        out[m] = scale(g[m], SH_SCALE[m]);
    }
    out
}

/// The 9 band-4 spherical-harmonic coefficients of the frame `f` (the function
/// `Σₖ (f[k]·d)⁴`, i.e. `x⁴ + y⁴ + z⁴` rotated into the frame), ordered `m = −4 … 4`, of unit
/// norm; [`SH_IDENTITY`](super::SH_IDENTITY) for the identity. Equal for all 24 cube-symmetric versions of `f`.
/// `f` is expected orthonormal.
pub fn frame_to_sh(f: &Frame) -> [f64; 9] {
    let mut q = sh_basis(f[0]);
    for a in &f[1..] {
        let b = sh_basis(*a);
        for m in 0..9 {
            q[m] += b[m];
        }
    }
    q
}

/// `∂q/∂ωᵢ` of [`frame_to_sh`] under `f ← exp([ω]ₓ) f`, as `j[m][i]`.
pub(super) fn sh_jacobian(f: &Frame) -> [[f64; 3]; 9] {
    let mut j = [[0.0; 3]; 9];
    for a in f {
        let g = sh_basis_grad(*a);
        // eᵢ × a for i = 0, 1, 2.
        let e = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
        for m in 0..9 {
            for i in 0..3 {
                j[m][i] += dot(g[m], e[i]);
            }
        }
    }
    j
}

/// The SH distance `|q_a − q_b|` of two frames: 0 iff they agree up to a cube rotation,
/// invariant under cube rotations of either and under rotating both together; at most 2.
pub fn frame_distance(a: &Frame, b: &Frame) -> f64 {
    dist2_9(&frame_to_sh(a), &frame_to_sh(b)).sqrt()
}

/// The fixed starting frames of the projection with their coefficients.
pub(super) fn candidates() -> &'static [(Frame, [f64; 9])] {
    static C: OnceLock<Vec<(Frame, [f64; 9])>> = OnceLock::new();
    C.get_or_init(|| {
        let n = 400;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let mut out = Vec::new();
        for i in 0..n {
            let z = 1.0 - (2 * i + 1) as f64 / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let (s, c) = (i as f64 * golden).sin_cos();
            let d = [r * c, r * s, z];
            // One face cone of the cube (any axis can be the third), with a margin.
            if d[2] + 0.1 < d[0].abs().max(d[1].abs()) {
                continue;
            }
            let (t1, t2) = tangents(d);
            for a in 0..6 {
                let f = frame_about(d, t1, t2, a as f64 * std::f64::consts::PI / 12.0);
                out.push((f, frame_to_sh(&f)));
            }
        }
        out
    })
}

/// Solves the 3 × 3 symmetric system `h x = g` (Cramer's rule).
pub(super) fn solve3(h: [[f64; 3]; 3], g: [f64; 3]) -> [f64; 3] {
    let det = dot(h[0], cross(h[1], h[2]));
    if det.abs() < 1e-300 {
        return [0.0; 3];
    }
    // Columns replaced by g; h is symmetric so rows are columns.
    [
        dot(g, cross(h[1], h[2])) / det,
        dot(h[0], cross(g, h[2])) / det,
        dot(h[0], cross(h[1], g)) / det,
    ]
}

/// Gauss–Newton on `min |q(R) − qn|²` from `f` (`qn` of unit norm, so this is
/// `max ⟨q(R), qn⟩`); returns the frame and `|q(R) − qn|²`.
pub(super) fn refine(qn: &[f64; 9], f: Frame, max_iter: usize) -> (Frame, f64) {
    let mut f = f;
    let mut s = frame_to_sh(&f);
    let mut best = dist2_9(&s, qn);
    for _ in 0..max_iter {
        let j = sh_jacobian(&f);
        let mut g = [0.0; 3];
        let mut h = [[0.0; 3]; 3];
        for m in 0..9 {
            let r = qn[m] - s[m];
            for i in 0..3 {
                g[i] += j[m][i] * r;
                for k in 0..3 {
                    h[i][k] += j[m][i] * j[m][k];
                }
            }
        }
        for i in 0..3 {
            h[i][i] += 1e-12;
        }
        let mut delta = solve3(h, g);
        let mut accepted = false;
        for _ in 0..8 {
            let cand = orthonormalise(f.map(|a| rotate(a, delta)));
            let sc = frame_to_sh(&cand);
            let dc = dist2_9(&sc, qn);
            if dc <= best {
                f = cand;
                s = sc;
                best = dc;
                accepted = true;
                break;
            }
            delta = scale(delta, 0.5);
        }
        if !accepted || norm(delta) < 1e-14 {
            break;
        }
    }
    (f, best)
}

/// The frame closest to `q` in the SH metric, with `|q̂ − q(frame)|` (`q̂ = q/|q|`).
pub(super) fn project(q: &[f64; 9]) -> (Frame, f64) {
    let nq = dot9(q, q).sqrt();
    if !nq.is_finite() || nq <= 1e-300 {
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        return (id, dist2_9(&frame_to_sh(&id), &[0.0; 9]).sqrt());
    }
    let qn = q.map(|v| v / nq);
    let mut best = (0, f64::NEG_INFINITY);
    for (i, (_, s)) in candidates().iter().enumerate() {
        let d = dot9(s, &qn);
        if d > best.1 {
            best = (i, d);
        }
    }
    let (f, d2) = refine(&qn, candidates()[best.0].0, 30);
    (f, d2.sqrt())
}

/// The frame closest to `q` in the SH metric (after normalising `q`), right-handed and
/// orthonormal: the projection of Huang §5.1 / Ray §4.2 (best of ~480 fixed candidates, then
/// Gauss–Newton on the rotation; module docs). `sh_to_frame(frame_to_sh(f))` equals `f` up to
/// a cube rotation. A zero or non-finite `q` gives the identity.
pub fn sh_to_frame(q: &[f64; 9]) -> Frame {
    project(q).0
}
