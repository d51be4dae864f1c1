//! Polycube frames: a frame field with no interior singularity, read off a deformation of the
//! solid that turns every boundary normal towards a coordinate axis (Gregson, Sheffer, Zhang,
//! "All-hex mesh generation via volumetric polycube deformation", SGP 2011, §4).
//!
//! # The deformation (§4.1–4.2, rotation-driven)
//!
//! Starting from the input positions `y = x`, repeat:
//!
//! 1. **Targets.** Each boundary triangle `f` takes the signed coordinate axis `a_f` nearest its
//!    current normal `n_f` (its label); its target rotation is the shortest turn from `n_f` to
//!    `a_f`, as a rotation vector `ρ_f = θ (n_f × a_f)/|n_f × a_f|`, `cos θ = n_f · a_f`
//!    (`θ ≤ 54.7°`, since the nearest axis is never farther).
//! 2. **Spread.** A rotation vector `r_t` per tetrahedron minimises
//!    `Σ_{faces st} |r_s − r_t|² + λ Σ_f (A_f / Ā) |r_{t(f)} − ρ_f|²`: the graph Laplacian of
//!    the tetrahedra across faces plus the boundary targets (`A_f` the triangle's input area, `Ā`
//!    their mean). The matrix does not change between iterations: it is factored once (sparse
//!    Cholesky) and each iteration is three back-substitutions.
//! 3. **Deform.** New positions minimise `Σ_t w_t V_t |∇y|_t − exp(r_t) C(∇y_old|_t)|²` with
//!    linear elements on the input mesh (`V_t` its volumes): every tetrahedron is asked to
//!    turn by its rotation and keep its shape, and the least-squares fit spreads what cannot
//!    be kept. `C` clamps the gradient's stretches (singular values) to `[½, 2]`, so a
//!    squeezed tetrahedron is never asked to shrink further. The matrix
//!    `K = Σ_t w_t V_t G_tᵀ G_t` (the cotangent Laplacian, `w_t = 1` at first) is factored
//!    once, one vertex pinned.
//!    The step towards the new positions is halved while a tetrahedron would turn inside out;
//!    when even a 1/64 step would, the tetrahedra that block it are stiffened (their weight
//!    `w_t` in `Σ_t w_t V_t |…|²` times 8, their face neighbours' times √8), `K` is factored
//!    again and the positions solved again, up to four times per iteration. A tetrahedron
//!    squeezed nearly flat by its neighbours' targets otherwise stops the whole deformation
//!    (the fandisk stopped at 4.7° from its axes, the octopus at 25°; stiffened, they reach
//!    1.8° and 12.8°).
//!
//! until the area-weighted mean angle between the boundary normals and their axes falls below
//! the tolerance, stops falling for ten iterations, or no step keeps every tetrahedron
//! positive. Then a second phase (Gregson et al. fix the labels the same way before their
//! final solve): the labels are cleaned up (below) and, unless the boundary is already within
//! the tolerance of them, the iteration goes on with each triangle's target axis its cleaned-up
//! label instead of its nearest axis, up to [`PolycubeParams::label_iterations`] more times.
//! A relabelled tongue, a tooth or a pinched triangle is then turned onto its chart's plane
//! by the deformation rather than by the parameterisation (the fandisk: 84 tetrahedra of the
//! parameterisation inverted before rounding after the first phase, 17 after the second). Smoothing the rotations (step 2) instead of the positions is what makes the
//! boundary charts grow flat and the transitions between labels sharpen into the polycube's
//! edges over the iterations. (Gregson et al. smooth rotations of the surface normals the
//! same way; the clamped stretch and the step control are ours.)
//!
//! # Labels
//!
//! Each boundary triangle is labelled with the axis nearest its deformed normal, then cleaned
//! up: charts of fewer than three triangles join the label they share most edges with, a
//! triangle two of whose three neighbours share another label takes it (a tooth on a chart's
//! border), and a triangle whose three vertices all lie on charts of one other axis (it would
//! be flattened onto the line where two planes meet) takes that label once.
//!
//! A border between two charts must be a polycube edge: convex or concave along its whole
//! length. Where it is convex along part of it and concave along the rest (each side judged
//! behind or in front of the other's plane), one chart runs as a tongue between two levels of
//! the other: a step in a plane that fades out, which no polycube has (the parameterisation
//! would squeeze it flat and invert its tetrahedra). The fandisk's deformation leaves one,
//! a −z strip between two +y levels a hex edge apart. The tongue (the chart whose two border
//! runs lie apart along the other's axis) takes the other chart's label between the runs,
//! and the clean-up runs again. The parameterisation puts each triangle on an integer plane
//! of its label's axis.
//!
//! # Frames
//!
//! The frame of tetrahedron `t` is the rotation part of the final deformation's gradient:
//! `frame[k]` = row `k` of `P(∇y|_t)`, the direction in the input in which the deformed
//! coordinate `y_k` grows. The frames are one single-valued rotation field, so every
//! matching is the identity by construction and no interior edge is singular: the polycube
//! map's singularities are its convex and concave boundary edges, which boundary alignment
//! handles. (The matchings must not be recomputed as the nearest cube rotation: next to a
//! polycube edge neighbouring frames can differ by nearly a quarter turn.) Boundary alignment
//! puts each chart on an integer plane, and the parameterisation ([`super::param`]) is a
//! polycube map; the deformation's gradients ([`Polycube::gradients`]) are a second set of
//! targets for it, a map already nearly axis-aligned with no tetrahedron inverted. A
//! tetrahedron the deformation turns inside out (`det ∇y ≤ 0`, which the step control
//! prevents) is counted in the report.
//!
//! # Where the steps live
//!
//! `deform.rs` (the deformation), `labels.rs` (the labels, their clean-up and the
//! deviation); [`polycube_frames`], here, runs the two phases and reads the frames off.

mod deform;
mod labels;

use nalgebra::{Matrix3, Vector3};

use super::mesh::{Frame, TetMesh};
use super::param::gradients;
use super::topology::Topology;
use crate::sparse::CholeskyFactor;
use deform::{
    Deformation, Deformer, Stiffness, boundary_weights, nearest_rotation, rotation_laplacian,
};
use labels::{clean_labels, deviation};

/// Parameters of [`polycube_frames`].
#[derive(Clone, Debug, PartialEq)]
pub struct PolycubeParams {
    /// Most deformation iterations.
    pub iterations: usize,
    /// Stop when the area-weighted mean angle (degrees) between boundary normals and their
    /// axes is below this.
    pub tolerance_degrees: f64,
    /// Weight `λ` of the boundary targets against the smoothness of the rotations.
    pub boundary_weight: f64,
    /// Most iterations of the second phase, towards the cleaned-up labels (module docs).
    pub label_iterations: usize,
}

impl Default for PolycubeParams {
    fn default() -> Self {
        PolycubeParams {
            iterations: 200,
            tolerance_degrees: 1.0,
            boundary_weight: 1.0,
            label_iterations: 150,
        }
    }
}

/// What [`polycube_frames`] measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PolycubeReport {
    /// Deformation iterations run.
    pub iterations: usize,
    /// Area-weighted mean angle (degrees) between deformed boundary normals and their axes, at
    /// the start (nearest axes) and at the end (the cleaned-up labels' axes).
    pub mean_deviation_start: f64,
    /// As `mean_deviation_start`, at the end.
    pub mean_deviation: f64,
    /// Fraction of the deformed boundary area within 5° of its axis.
    pub aligned_fraction: f64,
    /// Boundary triangles per cleaned-up label `+x −x +y −y +z −z`.
    pub labels: [usize; 6],
    /// Tetrahedra the deformation turned inside out.
    pub flipped: usize,
    /// Times blocking tetrahedra were stiffened and the positions solved again.
    pub stiffened: usize,
    /// Iterations run before the second phase (towards the cleaned-up labels) began; all of
    /// them when there was none.
    pub second_phase_from: usize,
}

/// The deformation and the frames read off it.
#[derive(Clone, Debug)]
pub struct Polycube {
    /// Per tetrahedron, the rotation part of the deformation's gradient (module docs).
    pub frames: Vec<Frame>,
    /// Per tetrahedron, the deformation's gradient (rows `∇y₀`, `∇y₁`, `∇y₂`).
    pub gradients: Vec<Frame>,
    /// Per boundary face (in [`Topology::boundary`]'s order), the axis of its cleaned-up
    /// label: the plane it is put on.
    pub axes: Vec<u8>,
    /// The deformed vertex positions.
    pub deformed: Vec<[f64; 3]>,
    /// What was measured.
    pub report: PolycubeReport,
}

/// Why the frames could not be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PolycubeError {
    /// A sparse factorisation failed.
    #[error("the polycube deformation's linear system could not be solved: {0}")]
    Solve(String),
}

/// Polycube frames for the checked mesh (module docs), with the deformed positions.
pub fn polycube_frames(
    mesh: &TetMesh,
    topo: &Topology,
    params: &PolycubeParams,
) -> Result<Polycube, PolycubeError> {
    let nt = mesh.tets.len();
    let grads: Vec<[Vector3<f64>; 4]> = (0..nt)
        .map(|t| gradients(&mesh.corners(t)).map(Vector3::from))
        .collect();
    let volumes: Vec<f64> = (0..nt).map(|t| mesh.volume(t)).collect();
    let def = Deformation {
        mesh,
        grads,
        volumes,
    };
    let stiffness = vec![1.0; nt];
    let weights = boundary_weights(mesh, topo, params);
    let mut l = rotation_laplacian(topo, &weights);
    let centroids: Vec<[f64; 3]> = (0..nt)
        .map(|t| {
            let c = mesh.corners(t);
            [0, 1, 2].map(|k| (c[0][k] + c[1][k] + c[2][k] + c[3][k]) / 4.0)
        })
        .collect();
    // The two factorisations are independent: side by side.
    let (kf, lf) = rayon::join(
        || def.factor_k(&stiffness),
        || CholeskyFactor::with_points(&mut l, &centroids).map_err(PolycubeError::Solve),
    );
    let ((kf, mean), lf) = (kf?, lf?);
    let mut k = Stiffness {
        w: stiffness,
        kf,
        mean,
    };
    let d = Deformer {
        def,
        topo,
        weights,
        lf,
        params,
    };

    let mut y = mesh.verts.clone();
    let (start, _) = deviation(mesh, topo, &y, None);
    let mut report = PolycubeReport {
        mean_deviation_start: start,
        mean_deviation: start,
        ..PolycubeReport::default()
    };
    let mut best = (start, y.clone());
    let mut fixed: Option<Vec<u8>> = None;
    report.second_phase_from = usize::MAX;
    let mut limit = params.iterations;
    // First towards the nearest axes, then (second phase) towards the cleaned-up labels.
    loop {
        d.phase(
            &mut k,
            &mut y,
            &mut best,
            fixed.as_deref(),
            limit,
            &mut report,
        )?;
        if fixed.is_some() || params.label_iterations == 0 {
            break;
        }
        let l = clean_labels(mesh, topo, &best.1);
        let (dev, _) = deviation(mesh, topo, &best.1, Some(&l));
        fixed = Some(l);
        report.mean_deviation = dev;
        best.0 = dev;
        if dev <= params.tolerance_degrees {
            break;
        }
        y = best.1.clone();
        report.second_phase_from = report.iterations;
        limit = report.iterations + params.label_iterations;
    }
    if report.second_phase_from == usize::MAX {
        report.second_phase_from = report.iterations;
    }
    Ok(read_off(&d.def, topo, best.1, fixed, report))
}

/// The frames and gradients read off the final positions `y`, with the cleaned-up labels
/// (those of the second phase, `fixed`, or cleaned up now) and the report completed.
fn read_off(
    def: &Deformation,
    topo: &Topology,
    y: Vec<[f64; 3]>,
    fixed: Option<Vec<u8>>,
    mut report: PolycubeReport,
) -> Polycube {
    let mesh = def.mesh;
    let nt = mesh.tets.len();
    let (dev, within) = deviation(mesh, topo, &y, fixed.as_deref());
    report.mean_deviation = dev;
    report.aligned_fraction = within;
    let rows = |r: &Matrix3<f64>| [0, 1, 2].map(|row| [r[(row, 0)], r[(row, 1)], r[(row, 2)]]);
    let mut frames = Vec::with_capacity(nt);
    let mut gradients = Vec::with_capacity(nt);
    for t in 0..nt {
        let j = def.jacobian(&y, t);
        if j.determinant() <= 0.0 {
            report.flipped += 1;
        }
        frames.push(rows(&nearest_rotation(&j)));
        gradients.push(rows(&j));
    }
    let labels = match fixed {
        Some(l) => l,
        None => clean_labels(mesh, topo, &y),
    };
    for l in &labels {
        report.labels[*l as usize] += 1;
    }
    Polycube {
        axes: labels.iter().map(|l| l / 2).collect(),
        frames,
        gradients,
        deformed: y,
        report,
    }
}

#[cfg(test)]
mod tests;
