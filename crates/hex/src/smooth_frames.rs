//! Smooth, boundary-aligned frame fields on tetrahedral meshes: the automatic input of
//! CubeCover (the paper takes constant frames or frames from a coarse hex meta-mesh, §3.2).
//!
//! The method is the spherical-harmonic one of Huang, Tong, Wei, Bao, "Boundary aligned smooth
//! 3D cross-frame field" (SIGGRAPH Asia 2011, §3–§5) in the practical form of Ray, Sokolov,
//! Lévy, "Practical 3D frame field generation" (SIGGRAPH Asia 2016, §3–§4).
//!
//! # Representation (Huang §3, Ray §3.1)
//!
//! A frame with axes `a₀ a₁ a₂` is the function `f(d) = Σₖ (aₖ·d)⁴` on the unit sphere,
//! which is `x⁴ + y⁴ + z⁴` rotated into the frame. It does not change under the 24 rotations of
//! the cube (permutations of the axes with signs, determinant +1), so it is a frame "up to cube
//! symmetry". Its band-0 part is a constant and its band-2 part vanishes (`Σ aₖaₖᵀ = I`), so a
//! frame is its 9 band-4 real spherical-harmonic coefficients `q ∈ ℝ⁹`.
//!
//! * Basis: the real spherical harmonics of degree 4, ordered `m = −4 … 4`, orthonormal on the
//!   sphere, with the usual (Wikipedia "Table of spherical harmonics") polynomials for `|d| = 1`:
//!   `xy(x²−y²)`, `(3x²−y²)yz`, `xy(7z²−1)`, `yz(7z²−3)`, `35z⁴−30z²+3`, `xz(7z²−3)`,
//!   `(x²−y²)(7z²−1)`, `(x²−3y²)xz`, `x⁴−6x²y²+y⁴` times `¾√(35/π)`, `¾√(35/2π)`, `¾√(5/π)`,
//!   `¾√(5/2π)`, `3/16 √(1/π)`, `¾√(5/2π)`, `⅜√(5/π)`, `¾√(35/2π)`, `3/16 √(35/π)`.
//!   `m < 0` is the `sin(|m|φ)` harmonic, `m > 0` the `cos(mφ)` one.
//! * By the Funk–Hecke theorem the band-4 part of `(a·d)⁴` is proportional to
//!   `Σₘ Yₘ(a) Yₘ(d)`, so [`frame_to_sh`] is simply `q = κ Σₖ Y(aₖ)` (the harmonics evaluated
//!   at the three axes and summed), with `κ` fixed by `|q| = 1`. No Wigner matrix is needed:
//!   rotating a frame rotates its axes. The identity frame is
//!   `q₀ = (0, 0, 0, 0, √(7/12), 0, 0, 0, √(5/12))` (the constant [`SH_IDENTITY`]); every
//!   frame has `|q| = 1` (the rotation acts orthogonally on the band).
//! * Distance: [`frame_distance`] is `|q_a − q_b|`, which is invariant under cube symmetries of
//!   either frame and under a common rotation of both (in `[0, 2]`; 0 iff same frame up to
//!   symmetry).
//!
//! # Boundary constraint (Huang §4.2, Ray §3.2)
//!
//! A tetrahedron with a boundary face of outward normal `n` must have an axis along `n`. The
//! frames with an axis `n` are `Fₙ(θ) = [cos θ t₁ + sin θ t₂, −sin θ t₁ + cos θ t₂, n]` for a
//! right-handed `(t₁, t₂, n)`, and their coefficients form the circle
//! `q(θ) = z₀ + cos 4θ c + sin 4θ d` with `z₀ = W(Rₙ) √(7/12) e₄` (the zonal harmonic about
//! `n`) and `c = W(Rₙ) √(5/12) e₈`, `d = ± W(Rₙ) √(5/12) e₀` (Ray's `Rₙ(√(7/12) e₄ + c₀ e₀ + c₈
//! e₈)`; here `z₀, c, d` are obtained by evaluating [`frame_to_sh`] at `θ = 0, π/8, π/4`).
//! Relaxed (Ray's linear form), the constraint is `q ∈ z₀ + span(c, d)`; it is imposed by the
//! penalty `λₜ |P⊥(q − z₀)|²` with `P⊥ = I − ĉĉᵀ − d̂d̂ᵀ`, which is Ray's free `(c₀, c₈)`
//! eliminated in closed form. The projection onto the constraint is exact:
//! `4θ = atan2(⟨d, q⟩, ⟨c, q⟩)`.
//!
//! * Normals: a tetrahedron's boundary faces are sorted by area. If two of them are more than
//!   [`SmoothParams::sharp_angle_deg`] apart (as lines), the frame is fixed from those two
//!   normals (symmetric orthonormalisation of the pair: exact at the edges and corners of a
//!   box); otherwise the area-weighted mean normal is the single constrained axis.
//! * `λₜ = boundary_weight · Σ_f A_f / h_f` over the tet's boundary faces (`A_f` area, `h_f`
//!   the centroid's distance to the face), the same scale as an interior face weight.
//!
//! # Energy (Huang §4.1, Ray §3.1)
//!
//! `E(q) = Σ_{interior faces s|t} w_st |q_s − q_t|²` with `w_st = A_st / |c_s − c_t|` (face
//! area over the distance between the centroids: the finite-volume discretisation of the
//! Dirichlet energy `∫|∇q|²`). The reported energies are of true frames (unit `q`).
//!
//! # Solve
//!
//! 1. Relaxed field (Ray §4.1): minimise `E(q) + Σ λₜ |P⊥ₜ(q − z₀ₜ)|² + λₜ |q − q_fixed|²`
//!    over `q ∈ ℝ⁹ᴺ`, dropping `|q| = 1`: a sparse SPD system `(L ⊗ I₉ + B) q = b` (`L` the
//!    weighted dual-graph Laplacian, `B` the 9 × 9 boundary blocks, plus `10⁻¹⁰·mean degree` on
//!    the diagonal). It is solved by preconditioned conjugate gradients whose preconditioner is
//!    the sparse Cholesky factor (faer through [`crate::sparse`], sequential, AMD ordering)
//!    of the *scalar* matrix `L + diag(λₜ)` applied to the 9 columns: the coupled 9N × 9N
//!    factor would hold 81 times the fill; this one is exact away from the boundary's two free
//!    directions per tet. Its symbolic analysis is kept for step 3's matrix, which has the
//!    same pattern.
//! 2. Projection (Huang §5.1, Ray §4.2): each `q` is normalised and replaced by the closest
//!    frame, [`sh_to_frame`]: the best of ~480 fixed candidate frames (axis on a Fibonacci
//!    sphere restricted to one face cone of the cube, six twists 15° apart, ≈10° apart in all),
//!    then Gauss–Newton on the three rotation angles (`R ← exp([δ]ₓ) R`, with the analytic
//!    Jacobian `∂q/∂ωᵢ = κ Σₖ ∇Y(aₖ)·(eᵢ × aₖ)` and step halving). Constrained tets use the
//!    closed-form projection onto their circle; fixed tets keep their frame.
//! 3. Proximal rounds (Ray's "solve relaxed, project, repeat"): minimise
//!    `E(q) + Σ (λₜ + μ Dₜ) |q − pₜ|²` (`pₜ` the projected frames, `Dₜ` the tet's weight
//!    degree, `μ` = [`SmoothParams::proximal_weight`]); this is `L + diag(λₜ + μDₜ)` on each of
//!    the 9 components (one scalar factorisation, reused), then project. A round is kept only
//!    if it lowers `E` of the projected field; the rounds stop at the first that does not.
//! 4. Local sweeps (Huang §5.2's local optimisation): block Gauss–Seidel in which a tet's frame
//!    becomes the frame maximising `⟨q, Σ w qₙ⟩` over its neighbours (the exact minimiser of its
//!    share of `E`; free tets by Gauss–Newton from the current frame, kept only if better,
//!    constrained tets in closed form). Tets are greedily coloured so that no two neighbours
//!    share a colour; a colour's tets are updated in parallel. Each sweep cannot raise `E`.
//!
//! Every parallel step maps tets independently and every sum runs in a fixed order, and faer
//! runs sequentially, so the frames' bits do not depend on the thread count.
//!
//! # Memory
//!
//! About [`STATE_BYTES_PER_TET`] bytes per tetrahedron of state (ten 9-vectors, the frames,
//! weights, colours), plus the scalar Cholesky factor: 16 bytes (value and row index) per
//! nonzero, reported as [`SmoothReport::factor_nonzeros`]; its fill grows like `N^{1/3}`
//! (≈ 30–80 nonzeros per tet at 10⁴–10⁵ tets), plus one copy of the scalar matrix (≈ 4
//! entries per tet).

use std::sync::OnceLock;

use rayon::prelude::*;

use super::mesh::{FACE_OPPOSITE, Frame, NO_TET, TetMesh};
use crate::geom::vec::{add, cross, dot, norm, scale, sub};
use crate::sparse::{LowerMatrix, NumericFactor, SymbolicFactor};

/// `√(7/12)`: the `m = 0` coefficient of the identity frame.
pub const SQRT_7_12: f64 = 0.763_762_615_825_973_4;
/// `√(5/12)`: the `m = 4` coefficient of the identity frame.
pub const SQRT_5_12: f64 = 0.645_497_224_367_902_8;

/// The band-4 coefficients of the identity frame (`x⁴ + y⁴ + z⁴`), ordered `m = −4 … 4`.
pub const SH_IDENTITY: [f64; 9] = [0.0, 0.0, 0.0, 0.0, SQRT_7_12, 0.0, 0.0, 0.0, SQRT_5_12];

/// Bytes of state per tetrahedron, without the scalar Cholesky factor (see the module docs).
pub const STATE_BYTES_PER_TET: usize = 10 * 72 + 72 + 32 + 4 * 8 + 16;

/// Scale of the polynomials in [`sh_basis`]: the harmonic's constant over `(3/16)√(1/π)`,
/// divided by `√336`, so that `Σₖ Y(aₖ)` of a frame has norm 1.
const SH_SCALE: [f64; 9] = [
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

/// Parameters of [`smooth_frames`].
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothParams {
    /// Proximal rounds after the relaxed solve (solve, project); 0 keeps the projected relaxed
    /// field.
    pub iterations: usize,
    /// Weight of the boundary penalty relative to an interior face (`λₜ`, module docs).
    pub boundary_weight: f64,
    /// `μ` of the proximal rounds: how strongly a round stays near the current frames,
    /// relative to a tet's weight degree.
    pub proximal_weight: f64,
    /// Local Gauss–Seidel sweeps at the end.
    pub local_sweeps: usize,
    /// Two boundary normals of one tet more than this many degrees apart (as lines) fix its
    /// frame from the pair; closer ones are averaged into one constrained axis.
    pub sharp_angle_deg: f64,
    /// Relative residual at which conjugate gradients stop.
    pub cg_tolerance: f64,
    /// Most conjugate-gradient iterations of the relaxed solve.
    pub cg_max_iterations: usize,
}

impl Default for SmoothParams {
    fn default() -> Self {
        SmoothParams {
            iterations: 4,
            boundary_weight: 100.0,
            proximal_weight: 0.05,
            local_sweeps: 8,
            sharp_angle_deg: 45.0,
            cg_tolerance: 1e-8,
            cg_max_iterations: 500,
        }
    }
}

/// What [`smooth_frames`] measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SmoothReport {
    /// Tetrahedra with one constrained axis (boundary faces of one normal direction).
    pub constrained_tets: usize,
    /// Tetrahedra whose frame is fixed by two sharp boundary normals.
    pub fixed_tets: usize,
    /// `E` of the projected relaxed field (the start).
    pub energy_initial: f64,
    /// `E` of the returned field.
    pub energy_final: f64,
    /// Largest angle, in degrees, between a boundary face's outward normal and the nearest
    /// axis of its tet's frame.
    pub boundary_misalignment_max_deg: f64,
    /// Largest `|q/|q| − q(frame)|` of the last kept projection (how far the relaxed field
    /// was from true frames; large near singularities).
    pub projection_residual_max: f64,
    /// Conjugate-gradient iterations of the relaxed solve.
    pub cg_iterations: usize,
    /// Relative residual the conjugate gradients reached.
    pub cg_residual: f64,
    /// Proximal rounds kept.
    pub iterations_run: usize,
    /// Nonzeros of the scalar Cholesky factor (16 bytes each).
    pub factor_nonzeros: usize,
}

/// Why [`smooth_frames`] failed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SmoothError {
    /// `neighbours` does not have one row per tetrahedron.
    #[error("{got} neighbour rows for {tets} tetrahedra")]
    NeighbourCount {
        /// Rows given.
        got: usize,
        /// Tetrahedra in the mesh.
        tets: usize,
    },
    /// A neighbour index is out of range or the neighbour does not point back.
    #[error("tetrahedron {0}: a neighbour is out of range or does not point back")]
    Neighbours(usize),
    /// A tetrahedron has a vertex index out of range, a non-finite vertex, or no positive
    /// volume.
    #[error("tetrahedron {0} is degenerate, negatively oriented or has a bad vertex")]
    BadTet(usize),
    /// The sparse factorisation failed.
    #[error("sparse Cholesky failed: {0}")]
    Factorization(String),
}

// ---------------------------------------------------------------------------------------------
// Vector helpers the shared `crate::geom::vec` set lacks (unit vectors, 9-vectors).

#[inline]
fn unit3(a: [f64; 3]) -> [f64; 3] {
    scale(a, 1.0 / norm(a))
}

#[inline]
fn dot9(a: &[f64; 9], b: &[f64; 9]) -> f64 {
    let mut s = 0.0;
    for m in 0..9 {
        s += a[m] * b[m];
    }
    s
}

#[inline]
fn dist2_9(a: &[f64; 9], b: &[f64; 9]) -> f64 {
    let mut s = 0.0;
    for m in 0..9 {
        let d = a[m] - b[m];
        s += d * d;
    }
    s
}

/// `v` rotated by the rotation vector `w` (Rodrigues).
fn rotate(v: [f64; 3], w: [f64; 3]) -> [f64; 3] {
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
fn orthonormalise(f: Frame) -> Frame {
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
fn frame_about(n: [f64; 3], t1: [f64; 3], t2: [f64; 3], theta: f64) -> Frame {
    let (s, c) = theta.sin_cos();
    [
        add(scale(t1, c), scale(t2, s)),
        add(scale(t1, -s), scale(t2, c)),
        n,
    ]
}

// ---------------------------------------------------------------------------------------------
// Spherical harmonics.

/// The 9 band-4 real spherical harmonics at the unit vector `d`, ordered `m = −4 … 4`, each
/// scaled by `1 / (√336 · (3/16)√(1/π))` (so that [`frame_to_sh`] has norm 1).
#[inline]
fn sh_basis(d: [f64; 3]) -> [f64; 9] {
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
fn sh_basis_grad(d: [f64; 3]) -> [[f64; 3]; 9] {
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
/// norm; [`SH_IDENTITY`] for the identity. Equal for all 24 cube-symmetric versions of `f`.
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
fn sh_jacobian(f: &Frame) -> [[f64; 3]; 9] {
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
fn candidates() -> &'static [(Frame, [f64; 9])] {
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
fn solve3(h: [[f64; 3]; 3], g: [f64; 3]) -> [f64; 3] {
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
fn refine(qn: &[f64; 9], f: Frame, max_iter: usize) -> (Frame, f64) {
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
fn project(q: &[f64; 9]) -> (Frame, f64) {
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

// ---------------------------------------------------------------------------------------------
// The field.

/// A constrained tet's axis and the circle of its admissible coefficients.
#[derive(Clone, Debug)]
struct Axis {
    n: [f64; 3],
    t1: [f64; 3],
    t2: [f64; 3],
    z0: [f64; 9],
    /// Unit directions of the circle's plane.
    c: [f64; 9],
    d: [f64; 9],
}

impl Axis {
    fn new(n: [f64; 3]) -> Axis {
        let (t1, t2) = tangents(n);
        let s0 = frame_to_sh(&frame_about(n, t1, t2, 0.0));
        let s8 = frame_to_sh(&frame_about(n, t1, t2, std::f64::consts::PI / 8.0));
        let s4 = frame_to_sh(&frame_about(n, t1, t2, std::f64::consts::PI / 4.0));
        let mut z0 = [0.0; 9];
        let mut c = [0.0; 9];
        let mut d = [0.0; 9];
        for m in 0..9 {
            z0[m] = 0.5 * (s0[m] + s4[m]);
            c[m] = (0.5 * (s0[m] - s4[m])) / SQRT_5_12;
            d[m] = (s8[m] - z0[m]) / SQRT_5_12;
        }
        Axis {
            n,
            t1,
            t2,
            z0,
            c,
            d,
        }
    }

    /// The frame with axis `n` closest to `q`.
    fn project(&self, q: &[f64; 9]) -> Frame {
        let (a, b) = (dot9(&self.c, q), dot9(&self.d, q));
        let theta = if a == 0.0 && b == 0.0 {
            0.0
        } else {
            0.25 * b.atan2(a)
        };
        frame_about(self.n, self.t1, self.t2, theta)
    }

    /// `P⊥ x`: `x` without its components along `c` and `d`.
    fn perp(&self, x: &[f64; 9]) -> [f64; 9] {
        let (a, b) = (dot9(&self.c, x), dot9(&self.d, x));
        let mut y = *x;
        for m in 0..9 {
            y[m] -= a * self.c[m] + b * self.d[m];
        }
        y
    }
}

#[derive(Clone, Debug)]
enum Kind {
    Free,
    Axis(Box<Axis>),
    Fixed(Frame),
}

/// Geometry and constraints of the mesh.
struct Setup {
    w: Vec<[f64; 4]>,
    deg: Vec<f64>,
    lambda: Vec<f64>,
    kind: Vec<Kind>,
    /// Boundary faces as (tet, outward unit normal).
    bfaces: Vec<(usize, [f64; 3])>,
    eps: f64,
}

fn setup(mesh: &TetMesh, nb: &[[u32; 4]], params: &SmoothParams) -> Result<Setup, SmoothError> {
    let n = mesh.tets.len();
    if nb.len() != n {
        return Err(SmoothError::NeighbourCount {
            got: nb.len(),
            tets: n,
        });
    }
    let nv = mesh.verts.len();
    let mut centroid = vec![[0.0; 3]; n];
    for (t, tet) in mesh.tets.iter().enumerate() {
        if tet.iter().any(|&v| v as usize >= nv) {
            return Err(SmoothError::BadTet(t));
        }
        let c = mesh.corners(t);
        if c.iter().flatten().any(|x| !x.is_finite())
            || mesh.volume(t).is_nan()
            || mesh.volume(t) <= 0.0
        {
            return Err(SmoothError::BadTet(t));
        }
        centroid[t] = scale(add(add(c[0], c[1]), add(c[2], c[3])), 0.25);
        for &u in &nb[t] {
            if u == NO_TET {
                continue;
            }
            let u = u as usize;
            if u >= n || u == t || !nb[u].contains(&(t as u32)) {
                return Err(SmoothError::Neighbours(t));
            }
        }
    }
    let cos_sharp = params.sharp_angle_deg.to_radians().cos();
    let mut w = vec![[0.0; 4]; n];
    let mut lambda = vec![0.0; n];
    let mut kind = vec![Kind::Free; n];
    let mut bfaces = Vec::new();
    for t in 0..n {
        let c = mesh.corners(t);
        let mut faces: Vec<([f64; 3], f64)> = Vec::new();
        for (i, f) in FACE_OPPOSITE.iter().enumerate() {
            let (a, b, cc) = (c[f[0]], c[f[1]], c[f[2]]);
            let nrm = cross(sub(b, a), sub(cc, a));
            let area = 0.5 * norm(nrm);
            if area.is_nan() || area <= 0.0 {
                return Err(SmoothError::BadTet(t));
            }
            let u = nb[t][i];
            if u == NO_TET {
                let nu = unit3(nrm);
                let h = dot(sub(a, centroid[t]), nu).abs();
                lambda[t] += params.boundary_weight * area / h;
                faces.push((nu, area));
                bfaces.push((t, nu));
            } else {
                let dist = norm(sub(centroid[u as usize], centroid[t]));
                if dist.is_nan() || dist <= 0.0 {
                    return Err(SmoothError::BadTet(t));
                }
                w[t][i] = area / dist;
            }
        }
        if faces.is_empty() {
            continue;
        }
        // Largest first; the sort is stable so ties keep the face order.
        faces.sort_by(|a, b| b.1.total_cmp(&a.1));
        let n1 = faces[0].0;
        let sharp = faces[1..]
            .iter()
            .find(|f| dot(f.0, n1).abs() < cos_sharp)
            .map(|f| f.0);
        kind[t] = match sharp {
            Some(n2) => {
                let v = if dot(n1, n2) < 0.0 {
                    scale(n2, -1.0)
                } else {
                    n2
                };
                let a = unit3(add(n1, v));
                let b = unit3(sub(n1, v));
                let s = std::f64::consts::FRAC_1_SQRT_2;
                let e1 = scale(add(a, b), s);
                let e2 = scale(sub(a, b), s);
                Kind::Fixed(orthonormalise([e1, e2, cross(e1, e2)]))
            }
            None => {
                let mut m = [0.0; 3];
                for f in &faces {
                    let sg = if dot(f.0, n1) < 0.0 { -1.0 } else { 1.0 };
                    m = add(m, scale(f.0, sg * f.1));
                }
                Kind::Axis(Box::new(Axis::new(unit3(m))))
            }
        };
    }
    let deg: Vec<f64> = w.iter().map(|r| r.iter().sum()).collect();
    let mean = deg.iter().chain(lambda.iter()).sum::<f64>() / n as f64;
    Ok(Setup {
        w,
        deg,
        lambda,
        kind,
        bfaces,
        eps: 1e-10 * mean.max(1e-300),
    })
}

/// The scalar matrix `L + diag(extra)`, lower triangle, in compressed columns.
fn scalar_matrix(nb: &[[u32; 4]], s: &Setup, extra: &[f64]) -> LowerMatrix {
    let n = nb.len();
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut rows = Vec::with_capacity(3 * n);
    let mut vals = Vec::with_capacity(3 * n);
    col_ptr.push(0usize);
    for t in 0..n {
        rows.push(t);
        vals.push(s.deg[t] + extra[t] + s.eps);
        let mut below: Vec<(usize, f64)> = (0..4)
            .filter(|&i| nb[t][i] != NO_TET && nb[t][i] as usize > t)
            .map(|i| (nb[t][i] as usize, -s.w[t][i]))
            .collect();
        below.sort_by_key(|e| e.0);
        for (r, v) in below {
            rows.push(r);
            vals.push(v);
        }
        col_ptr.push(rows.len());
    }
    LowerMatrix::from_columns(n, col_ptr, rows, vals)
}

/// Chunked sum, fixed order whatever the thread count.
fn par_dot(a: &[[f64; 9]], b: &[[f64; 9]]) -> f64 {
    const CHUNK: usize = 4096;
    let parts: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| dot9(p, q)).sum())
        .collect();
    parts.iter().sum()
}

/// `A x` of the relaxed system.
fn relaxed_apply(nb: &[[u32; 4]], s: &Setup, x: &[[f64; 9]]) -> Vec<[f64; 9]> {
    (0..x.len())
        .into_par_iter()
        .map(|t| {
            let mut y = x[t].map(|v| v * (s.deg[t] + s.eps));
            for i in 0..4 {
                if nb[t][i] != NO_TET {
                    let u = &x[nb[t][i] as usize];
                    for m in 0..9 {
                        y[m] -= s.w[t][i] * u[m];
                    }
                }
            }
            let b = match &s.kind[t] {
                Kind::Free => None,
                Kind::Axis(ax) => Some(ax.perp(&x[t])),
                Kind::Fixed(_) => Some(x[t]),
            };
            if let Some(b) = b {
                for m in 0..9 {
                    y[m] += s.lambda[t] * b[m];
                }
            }
            y
        })
        .collect()
}

/// Preconditioned conjugate gradients; returns (x, iterations, relative residual).
fn pcg(
    nb: &[[u32; 4]],
    s: &Setup,
    pre: &NumericFactor,
    b: &[[f64; 9]],
    tol: f64,
    max_iter: usize,
) -> (Vec<[f64; 9]>, usize, f64) {
    let n = b.len();
    let bnorm = par_dot(b, b).sqrt();
    let mut x = vec![[0.0; 9]; n];
    if bnorm == 0.0 {
        return (x, 0, 0.0);
    }
    let mut r = b.to_vec();
    let mut z = pre.solve(&r);
    let mut p = z.clone();
    let mut rz = par_dot(&r, &z);
    let mut it = 0;
    let mut rel = 1.0;
    while it < max_iter {
        let ap = relaxed_apply(nb, s, &p);
        let pap = par_dot(&p, &ap);
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        x.par_iter_mut()
            .zip(r.par_iter_mut())
            .zip(p.par_iter().zip(ap.par_iter()))
            .for_each(|((xi, ri), (pi, api))| {
                for m in 0..9 {
                    xi[m] += alpha * pi[m];
                    ri[m] -= alpha * api[m];
                }
            });
        it += 1;
        rel = par_dot(&r, &r).sqrt() / bnorm;
        if rel <= tol {
            break;
        }
        z = pre.solve(&r);
        let rz_new = par_dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut().zip(z.par_iter()).for_each(|(pi, zi)| {
            for m in 0..9 {
                pi[m] = zi[m] + beta * pi[m];
            }
        });
    }
    (x, it, rel)
}

/// `E` of a field given by its coefficients.
fn energy(nb: &[[u32; 4]], s: &Setup, q: &[[f64; 9]]) -> f64 {
    let mut e = 0.0;
    for t in 0..q.len() {
        for i in 0..4 {
            let u = nb[t][i];
            if u != NO_TET && (u as usize) > t {
                e += s.w[t][i] * dist2_9(&q[t], &q[u as usize]);
            }
        }
    }
    e
}

/// Projects every tet's coefficients onto its admissible frames; returns the frames and the
/// largest residual `|q̂ − q(frame)|` of the free tets.
fn project_all(s: &Setup, q: &[[f64; 9]]) -> (Vec<Frame>, f64) {
    let out: Vec<(Frame, f64)> = q
        .par_iter()
        .zip(s.kind.par_iter())
        .map(|(q, k)| match k {
            Kind::Free => project(q),
            Kind::Axis(ax) => (ax.project(q), 0.0),
            Kind::Fixed(f) => (*f, 0.0),
        })
        .collect();
    let res = out.iter().map(|o| o.1).fold(0.0, f64::max);
    (out.into_iter().map(|o| o.0).collect(), res)
}

/// Greedy colouring of the dual graph: no two neighbours share a colour.
fn colour_classes(nb: &[[u32; 4]]) -> Vec<Vec<usize>> {
    let n = nb.len();
    let mut colour = vec![u8::MAX; n];
    let mut classes: Vec<Vec<usize>> = Vec::new();
    for t in 0..n {
        let mut used = 0u32;
        for &u in &nb[t] {
            if u != NO_TET && colour[u as usize] != u8::MAX {
                used |= 1 << colour[u as usize];
            }
        }
        let c = used.trailing_ones() as usize;
        colour[t] = c as u8;
        if classes.len() <= c {
            classes.resize(c + 1, Vec::new());
        }
        classes[c].push(t);
    }
    classes
}

/// One block Gauss–Seidel sweep over the colour classes.
fn local_sweep(
    nb: &[[u32; 4]],
    s: &Setup,
    classes: &[Vec<usize>],
    frames: &mut [Frame],
    q: &mut [[f64; 9]],
) {
    for class in classes {
        let updates: Vec<Option<Frame>> = class
            .par_iter()
            .map(|&t| {
                let mut target = [0.0; 9];
                for i in 0..4 {
                    if nb[t][i] != NO_TET {
                        let u = &q[nb[t][i] as usize];
                        for m in 0..9 {
                            target[m] += s.w[t][i] * u[m];
                        }
                    }
                }
                match &s.kind[t] {
                    Kind::Fixed(_) => None,
                    Kind::Axis(ax) => Some(ax.project(&target)),
                    Kind::Free => {
                        let nt = dot9(&target, &target).sqrt();
                        if nt.is_nan() || nt <= 1e-300 {
                            return None;
                        }
                        let tn = target.map(|v| v / nt);
                        let cur = dist2_9(&q[t], &tn);
                        let (f, d2) = refine(&tn, frames[t], 10);
                        (d2 < cur).then_some(f)
                    }
                }
            })
            .collect();
        for (&t, up) in class.iter().zip(updates) {
            if let Some(f) = up {
                frames[t] = f;
                q[t] = frame_to_sh(&f);
            }
        }
    }
}

/// Largest angle (degrees) between a boundary face's normal and its tet's nearest axis.
fn misalignment_deg(s: &Setup, frames: &[Frame]) -> f64 {
    s.bfaces
        .iter()
        .map(|&(t, n)| {
            let c = frames[t]
                .iter()
                .map(|a| dot(*a, n).abs())
                .fold(0.0, f64::max)
                .min(1.0);
            c.acos().to_degrees()
        })
        .fold(0.0, f64::max)
}

/// The smooth boundary-aligned frame field of `mesh` (one right-handed orthonormal frame per
/// tetrahedron, `frame[k]` the k-th unit axis) with what was measured. `neighbours` is
/// [`super::mesh::tet_neighbours`] of `mesh`. Method, constants and memory: module docs.
/// Deterministic for any thread count.
pub fn smooth_frames(
    mesh: &TetMesh,
    neighbours: &[[u32; 4]],
    params: &SmoothParams,
) -> Result<(Vec<Frame>, SmoothReport), SmoothError> {
    let nb = neighbours;
    let s = setup(mesh, nb, params)?;
    let n = mesh.tets.len();
    let mut report = SmoothReport {
        constrained_tets: s.kind.iter().filter(|k| matches!(k, Kind::Axis(_))).count(),
        fixed_tets: s
            .kind
            .iter()
            .filter(|k| matches!(k, Kind::Fixed(_)))
            .count(),
        ..SmoothReport::default()
    };
    if n == 0 {
        return Ok((Vec::new(), report));
    }

    // 1. The relaxed field.
    let pre_matrix = scalar_matrix(nb, &s, &s.lambda);
    let sym = SymbolicFactor::new(&pre_matrix).map_err(SmoothError::Factorization)?;
    report.factor_nonzeros = sym.nonzeros();
    let rhs: Vec<[f64; 9]> = s
        .kind
        .iter()
        .zip(&s.lambda)
        .map(|(k, &l)| match k {
            Kind::Free => [0.0; 9],
            Kind::Axis(ax) => ax.z0.map(|v| l * v),
            Kind::Fixed(f) => frame_to_sh(f).map(|v| l * v),
        })
        .collect();
    let (q_relaxed, its, rel) = {
        let pre = sym
            .factor(&pre_matrix)
            .map_err(SmoothError::Factorization)?;
        pcg(
            nb,
            &s,
            &pre,
            &rhs,
            params.cg_tolerance,
            params.cg_max_iterations,
        )
    };
    drop(pre_matrix);
    report.cg_iterations = its;
    report.cg_residual = rel;

    // 2. Projection.
    let (mut frames, mut residual) = project_all(&s, &q_relaxed);
    drop(q_relaxed);
    let mut q: Vec<[f64; 9]> = frames.par_iter().map(frame_to_sh).collect();
    let mut e = energy(nb, &s, &q);
    report.energy_initial = e;

    // 3. Proximal rounds.
    if params.iterations > 0 {
        let pull: Vec<f64> = (0..n)
            .map(|t| s.lambda[t] + params.proximal_weight * s.deg[t])
            .collect();
        let m = scalar_matrix(nb, &s, &pull);
        let fac = sym.factor(&m).map_err(SmoothError::Factorization)?;
        drop(m);
        for _ in 0..params.iterations {
            let rhs: Vec<[f64; 9]> = q
                .par_iter()
                .zip(pull.par_iter())
                .map(|(p, &w)| p.map(|v| w * v))
                .collect();
            let x = fac.solve(&rhs);
            let (f_new, res_new) = project_all(&s, &x);
            let q_new: Vec<[f64; 9]> = f_new.par_iter().map(frame_to_sh).collect();
            let e_new = energy(nb, &s, &q_new);
            if e_new.is_nan() || e_new >= e {
                break;
            }
            frames = f_new;
            q = q_new;
            e = e_new;
            residual = res_new;
            report.iterations_run += 1;
        }
    }
    report.projection_residual_max = residual;

    // 4. Local sweeps.
    if params.local_sweeps > 0 {
        let classes = colour_classes(nb);
        for _ in 0..params.local_sweeps {
            local_sweep(nb, &s, &classes, &mut frames, &mut q);
        }
        e = energy(nb, &s, &q);
    }
    report.energy_final = e;
    report.boundary_misalignment_max_deg = misalignment_deg(&s, &frames);
    Ok((frames, report))
}

#[cfg(test)]
mod tests;
