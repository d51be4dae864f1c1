//! Relaxation of an extracted hexahedral mesh towards ideal cubes, the last geometric step of
//! CubeCover (Nieser, Reitebuch, Polthier, "CubeCover — parameterization of 3D volumes",
//! SGP 2011, end of §3.2): the extracted vertices sit where the piecewise-linear map puts
//! the integer grid, so hexahedra near singular edges and in stretched regions are
//! distorted; moving each vertex towards where its hexahedra "want" it evens them out.
//!
//! # Method
//!
//! Each iteration:
//!
//! 1. **Ideal cube per hexahedron.** The unit cube's corners in VTK order, centred,
//!    `P_i ∈ {±½}³`, are fitted to the hexahedron's corners `X_i` by a similarity (rotation
//!    `R`, uniform scale `s`, translation `t`) minimising `Σ |s R P_i + t − X_i|²`: the
//!    orthogonal Procrustes problem with scaling (Umeyama, "Least-squares estimation of
//!    transformation parameters between two point patterns", IEEE TPAMI 1991). With
//!    `t = X̄` (the centroid) and `H = Σ (X_i − X̄) P_iᵀ = U Σ Vᵀ` (SVD by `nalgebra`),
//!    `R = U D Vᵀ`, `D = diag(1, 1, sign det(U Vᵀ))` so that `R` is a proper rotation (an
//!    inverted hexahedron is fitted by a positively oriented cube, which pulls it back),
//!    and `s = tr(Σ D) / Σ |P_i|²`; when that is not positive (a badly inverted element)
//!    the root-mean-square size `s = √(Σ |X_i − X̄|² / Σ |P_i|²)` is used instead. Each
//!    corner's displacement is `s R P_i + X̄ − X_i`.
//! 2. **Average.** Each vertex's displacement is the mean of its corners' displacements over
//!    the hexahedra around it, scaled by the vertex's step factor (initially
//!    [`RelaxParams::step`]).
//! 3. **Boundary.** Vertices on the mesh's boundary (the quadrilaterals that belong to one
//!    hexahedron) move the same way and are then projected onto the input boundary surface,
//!    a triangle soup, by a closest-point query over a bounding-volume hierarchy of its
//!    triangles (axis-aligned boxes, median splits; the closest point on a triangle by
//!    Ericson's region test, "Real-Time Collision Detection", 2005, §5.1.5), among the
//!    triangles facing the way the vertex's quadrilaterals face (so that where the solid is
//!    thinner than the hexahedra a vertex keeps to its side; any triangle when none does).
//!    Boundary
//!    vertices where the boundary quadrilaterals around them bend by more than
//!    [`RelaxParams::feature_angle_deg`] (the mesh's corners and sharp edges) are held fixed,
//!    so that projection cannot round off features; so are all boundary vertices when no
//!    surface is given. A boundary vertex that starts off the surface (a mesh whose boundary
//!    was not aligned to it) is pulled onto it by its first accepted move, or stays where it
//!    is while that move would make a hexahedron worse than step 4 allows.
//! 4. **No inversion.** Let `m` be the smallest scaled Jacobian (Verdict's, see
//!    [`crate::quality`]) before the step and `τ = max(m, `[`RelaxParams::sj_floor`]`)`.
//!    A hexahedron around a moved vertex may not end below `min(its own previous value, τ)`:
//!    the moved vertices of every hexahedron that would are put back and their step factor
//!    halved, and the hexahedra around them are checked again until none is worse (each
//!    round puts back at least one vertex, so this ends). Hence the minimum scaled Jacobian
//!    never decreases, no hexahedron that was valid inverts, and an inverted one can only
//!    improve. Accepted vertices regain step (×1.5, up to [`RelaxParams::step`]).
//! 5. **Untangling.** Hexahedra still inverted when the iteration ends (the step rule only
//!    keeps them from getting worse) are untangled by their corner tetrahedra
//!    ([`crate::untangle::untangle_hexes`]): first with every boundary vertex held,
//!    then with the surface vertices sliding in their tangent planes (the mean of their
//!    quadrilaterals' normals) and projected back onto the surface, up to
//!    [`UNTANGLE_ROUNDS`] rounds; a round is kept only when it leaves fewer hexahedra
//!    inverted. Two hexahedra folded onto each other at a corner (sharing its three edges
//!    with opposite orientations) cannot be untangled and are reported
//!    ([`crate::untangle::UntangleReport::conflicts`]).
//!
//! The iteration stops after [`RelaxParams::iterations`] rounds or when the largest proposed
//! move is below [`RelaxParams::tolerance`] times the mean edge length. The update is a
//! Jacobi one (all displacements from the same positions), computed in parallel and
//! gathered in index order, so the result is the same for any thread count.
//!
//! # Where the steps live
//!
//! `cube.rs` (step 1), `bvh.rs` (the surface queries of step 3), `steps.rs` (the
//! incidences and vertex kinds, steps 4 and 5); [`relax`], here, runs the iteration.

mod bvh;
mod cube;
mod steps;

pub use bvh::{Bvh, closest_on_triangle};
pub use cube::ideal_cube;
use cube::{corners, misfit};
use steps::{apply_moves, incidences, mean_edge_length, sj_of, untangle_rounds, vertex_kinds};

use crate::geom::vec::{add, dot, scale, sub};
use crate::mesh::HexMesh;
use crate::untangle::UntangleReport;
use rayon::prelude::*;
use serde::Serialize;

/// Most rounds of untangling and projection onto the surface (module docs, step 5).
pub const UNTANGLE_ROUNDS: usize = 3;

/// The parameters of [`relax`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RelaxParams {
    /// The most iterations.
    pub iterations: usize,
    /// The initial (and largest) step factor, in `(0, 1]`: the fraction of the averaged
    /// displacement a vertex moves by.
    pub step: f64,
    /// Stop when the largest proposed move is below this times the mean edge length.
    pub tolerance: f64,
    /// A hexahedron may lose quality down to the larger of the mesh's previous minimum scaled
    /// Jacobian and this floor, never below (see the module docs).
    pub sj_floor: f64,
    /// Boundary vertices whose boundary quadrilaterals' normals differ by more than this
    /// angle (degrees) are features, held fixed.
    pub feature_angle_deg: f64,
}

impl Default for RelaxParams {
    fn default() -> Self {
        RelaxParams {
            iterations: 100,
            step: 0.5,
            tolerance: 1e-5,
            sj_floor: 0.05,
            feature_angle_deg: 30.0,
        }
    }
}

/// What [`relax`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RelaxReport {
    /// Iterations run.
    pub iterations: usize,
    /// Whether it stopped because the largest proposed move fell below the tolerance (see
    /// also [`RelaxReport::min_step_factor`]: a small one means moves were being rejected).
    pub converged: bool,
    /// The smallest vertex step factor at the end ([`RelaxParams::step`] unless moves were
    /// put back; each put-back halves it).
    pub min_step_factor: f64,
    /// Smallest scaled Jacobian before (NaN values left out; 0 with no hexahedra).
    pub min_sj_before: f64,
    /// Mean scaled Jacobian before.
    pub mean_sj_before: f64,
    /// Smallest scaled Jacobian after.
    pub min_sj_after: f64,
    /// Mean scaled Jacobian after.
    pub mean_sj_after: f64,
    /// Hexahedra with scaled Jacobian ≤ 0 before.
    pub inverted_before: usize,
    /// Hexahedra with scaled Jacobian ≤ 0 after.
    pub inverted_after: usize,
    /// Interior vertices (moved freely).
    pub interior_vertices: usize,
    /// Boundary vertices moved and projected onto the surface.
    pub surface_vertices: usize,
    /// Vertices held fixed: features, boundary vertices without a surface, unused vertices.
    pub fixed_vertices: usize,
    /// Vertex moves put back because a hexahedron got worse than allowed (summed over
    /// iterations).
    pub rejected_moves: usize,
    /// The largest proposed move in the last iteration.
    pub last_max_move: f64,
    /// The largest distance from a surface vertex to the surface at the end.
    pub max_surface_distance: f64,
    /// How far the hexahedra are from ideal cubes before: the root-mean-square distance of
    /// their corners to the fitted cubes' (step 1 of the module docs) over the mean edge
    /// length at the start; 0 for a mesh of cubes. This is what the iteration lowers.
    pub cube_misfit_before: f64,
    /// The same after (relative to the same initial mean edge length).
    pub cube_misfit_after: f64,
    /// The untangling of the hexahedra the relaxation left inverted, when it did (module
    /// docs, step 5).
    pub untangle: Option<UntangleReport>,
}

fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

/// How a vertex may move.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Interior,
    Surface,
    Fixed,
}

/// Smallest and mean scaled Jacobian (NaN left out) and the count ≤ 0 (NaN included).
fn summary(sj: &[f64]) -> (f64, f64, usize) {
    let (mut min, mut sum, mut n, mut bad) = (f64::INFINITY, 0.0, 0usize, 0usize);
    for &s in sj {
        if s.is_nan() {
            bad += 1;
            continue;
        }
        min = min.min(s);
        sum += s;
        n += 1;
        if s <= 0.0 {
            bad += 1;
        }
    }
    if n == 0 {
        (0.0, 0.0, bad)
    } else {
        (min, sum / n as f64, bad)
    }
}

/// Relaxes `hex` towards ideal cubes, keeping its boundary vertices on the surface
/// `boundary_verts`/`boundary_tris` (typically the tetrahedral mesh's boundary triangles);
/// see the module docs. With no triangles the boundary vertices are held fixed. Hexahedra
/// never get worse than the rule of the module docs allows, so none that was valid inverts.
/// Deterministic for any thread count.
///
/// # Panics
/// If a hexahedron names a vertex beyond `hex.verts` or a triangle one beyond
/// `boundary_verts`.
pub fn relax(
    hex: &mut HexMesh,
    boundary_verts: &[[f64; 3]],
    boundary_tris: &[[u32; 3]],
    params: &RelaxParams,
) -> RelaxReport {
    let nv = hex.verts.len();
    let nh = hex.hexes.len();
    let mut report = RelaxReport::default();

    let (off, inc) = incidences(hex);

    // Boundary quadrilaterals: faces of exactly one hexahedron.
    let normals = hex.boundary_normals();
    let bvh = Bvh::new(boundary_verts, boundary_tris);
    let kind = vertex_kinds(&off, &normals, &bvh, params);
    // A surface vertex goes to the nearest surface point facing its own quadrilaterals' way,
    // so that where the solid is thin it stays on its side (and off a neighbouring part).
    let outward: Vec<[f64; 3]> = normals
        .iter()
        .map(|ns| ns.iter().fold([0.0; 3], |a, &b| add(a, b)))
        .collect();
    let project = |v: usize, y: [f64; 3]| {
        bvh.closest_facing(y, outward[v])
            .or_else(|| bvh.closest(y))
            .map(|(q, _)| q)
    };
    report.interior_vertices = kind.iter().filter(|&&k| k == Kind::Interior).count();
    report.surface_vertices = kind.iter().filter(|&&k| k == Kind::Surface).count();
    report.fixed_vertices = nv - report.interior_vertices - report.surface_vertices;

    let mut sj: Vec<f64> = (0..nh)
        .into_par_iter()
        .map(|k| sj_of(&hex.hexes, &hex.verts, k))
        .collect();
    let (min0, mean0, bad0) = summary(&sj);
    report.min_sj_before = min0;
    report.mean_sj_before = mean0;
    report.inverted_before = bad0;

    let mean_edge = mean_edge_length(hex);
    let rel = |x: f64| if mean_edge > 0.0 { x / mean_edge } else { 0.0 };
    report.cube_misfit_before = rel(misfit(&hex.verts, &hex.hexes));
    let step = params.step.clamp(0.0, 1.0);
    let mut alpha = vec![step; nv];
    let mut mark = vec![u32::MAX; nh];
    let mut epoch = 0u32;

    for it in 0..params.iterations {
        let verts = &hex.verts;
        // 1–2: displacements towards the ideal cubes, averaged per vertex.
        let disp: Vec<[[f64; 3]; 8]> = (0..nh)
            .into_par_iter()
            .map(|k| {
                let x = corners(verts, &hex.hexes[k]);
                let y = ideal_cube(&x);
                [0, 1, 2, 3, 4, 5, 6, 7].map(|i| sub(y[i], x[i]))
            })
            .collect();
        // 3: proposals.
        let proposal: Vec<Option<[f64; 3]>> = (0..nv)
            .into_par_iter()
            .map(|v| {
                if kind[v] == Kind::Fixed {
                    return None;
                }
                let list = &inc[off[v]..off[v + 1]];
                let mut d = [0.0; 3];
                for &(k, c) in list {
                    d = add(d, disp[k as usize][c as usize]);
                }
                let d = scale(d, alpha[v] / list.len() as f64);
                let mut y = add(verts[v], d);
                if kind[v] == Kind::Surface
                    && let Some(q) = project(v, y)
                {
                    y = q;
                }
                (y != verts[v] && y.iter().all(|x| x.is_finite())).then_some(y)
            })
            .collect();
        let max_move = (0..nv)
            .filter_map(|v| proposal[v].map(|y| dist2(y, verts[v]).sqrt()))
            .fold(0.0, f64::max);
        report.iterations = it + 1;
        report.last_max_move = max_move;
        if max_move <= params.tolerance * mean_edge {
            report.converged = true;
            break;
        }
        // 4: apply, then put back the moves that make a hexahedron worse than allowed.
        let (global_min, _, _) = summary(&sj);
        let tau = global_min.max(params.sj_floor);
        let (next, sj_next, moved, put_back) = apply_moves(
            hex,
            &proposal,
            (&off, &inc),
            &sj,
            tau,
            (&mut mark, &mut epoch),
        );
        for &v in &moved {
            let vi = v as usize;
            if put_back[vi] {
                alpha[vi] *= 0.5;
                report.rejected_moves += 1;
            } else {
                alpha[vi] = (alpha[vi] * 1.5).min(step);
            }
        }
        hex.verts = next;
        sj = sj_next;
    }

    untangle_rounds(hex, &kind, &normals, &project, &mut sj, &mut report);

    let (min1, mean1, bad1) = summary(&sj);
    report.min_sj_after = min1;
    report.mean_sj_after = mean1;
    report.inverted_after = bad1;
    report.cube_misfit_after = rel(misfit(&hex.verts, &hex.hexes));
    report.min_step_factor = (0..nv)
        .filter(|&v| kind[v] != Kind::Fixed)
        .map(|v| alpha[v])
        .fold(step, f64::min);
    report.max_surface_distance = (0..nv)
        .filter(|&v| kind[v] == Kind::Surface)
        .filter_map(|v| bvh.closest(hex.verts[v]).map(|(_, d)| d.sqrt()))
        .fold(0.0, f64::max);
    report
}

#[cfg(test)]
pub(crate) mod tests;
