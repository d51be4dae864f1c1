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

mod boundary;
mod sh;
mod solve;

use rayon::prelude::*;

use super::mesh::{Frame, TetMesh};
use crate::sparse::SymbolicFactor;
use boundary::{Kind, setup};
pub(crate) use sh::tangents;
pub use sh::{frame_distance, frame_to_sh, sh_to_frame};
use solve::{
    colour_classes, energy, local_sweep, misalignment_deg, pcg, project_all, scalar_matrix,
};

/// `√(7/12)`: the `m = 0` coefficient of the identity frame.
pub const SQRT_7_12: f64 = 0.763_762_615_825_973_4;
/// `√(5/12)`: the `m = 4` coefficient of the identity frame.
pub const SQRT_5_12: f64 = 0.645_497_224_367_902_8;

/// The band-4 coefficients of the identity frame (`x⁴ + y⁴ + z⁴`), ordered `m = −4 … 4`.
pub const SH_IDENTITY: [f64; 9] = [0.0, 0.0, 0.0, 0.0, SQRT_7_12, 0.0, 0.0, 0.0, SQRT_5_12];

/// Bytes of state per tetrahedron, without the scalar Cholesky factor (see the module docs).
pub const STATE_BYTES_PER_TET: usize = 10 * 72 + 72 + 32 + 4 * 8 + 16;

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
