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

use nalgebra::{Matrix3, Rotation3, Vector3};
use rayon::prelude::*;

use super::mesh::{FACE_OPPOSITE, Frame, NO_TET, TetMesh};
use super::param::gradients;
use super::topology::Topology;
use crate::sparse::{CholeskyFactor, Triplets};

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

/// The rotation nearest `m` (polar decomposition, reflections removed).
fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        // Singular values come sorted, largest first: flip the weakest direction.
        let mut u = u;
        for row in 0..3 {
            u[(row, 2)] = -u[(row, 2)];
        }
        r = u * v_t;
    }
    r
}

/// A deformation gradient's stretches kept within `[lo, 1/lo]` (its singular values clamped;
/// a reflection stays): a target never asks a tetrahedron that is already squeezed to
/// shrink further, so the deformation does not stall on one nearly flat tetrahedron.
fn clamp_stretch(m: &Matrix3<f64>, lo: f64) -> Matrix3<f64> {
    // Most gradients are within the bounds: the eigenvalues of mᵀm (the squared stretches,
    // in closed form) say so without a singular value decomposition.
    let (min, max) = sym_eigen_range(&(m.transpose() * m));
    if min >= lo * lo && max <= 1.0 / (lo * lo) {
        return *m;
    }
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return *m;
    };
    let s = svd.singular_values.map(|x| x.clamp(lo, 1.0 / lo));
    u * Matrix3::from_diagonal(&s) * v_t
}

/// The smallest and largest eigenvalue of the symmetric `a`, in closed form (the
/// trigonometric solution of the characteristic cubic, Smith 1961).
fn sym_eigen_range(a: &Matrix3<f64>) -> (f64, f64) {
    let off = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    if off == 0.0 {
        let d = [a[(0, 0)], a[(1, 1)], a[(2, 2)]];
        return (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]));
    }
    let q = a.trace() / 3.0;
    let p2 =
        (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * off;
    let p = (p2 / 6.0).sqrt();
    let b = (a - Matrix3::identity() * q) / p;
    let phi = (b.determinant() / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    (smallest, largest)
}

/// Smallest stretch a deformation target keeps ([`clamp_stretch`]).
const STRETCH: f64 = 0.5;

/// Smallest step towards the solved positions the deformation takes; below it the
/// tetrahedra that would invert are stiffened.
const MIN_STEP: f64 = 1.0 / 64.0;

/// Factor by which a blocking tetrahedron's stiffness grows (its neighbours' by the root).
const STIFFEN: f64 = 8.0;

/// Most stiffening rounds per iteration before the deformation stops.
const STIFFEN_ROUNDS: usize = 4;

/// The signed axis (0..6: +x −x +y −y +z −z) nearest the unit vector `n`, and the axis.
fn label(n: &Vector3<f64>) -> (usize, Vector3<f64>) {
    let k = (0..3)
        .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .expect("three axes");
    let l = 2 * k + usize::from(n[k] < 0.0);
    (l, axis(l as u8))
}

/// The unit vector of signed axis `l` (0..6: +x −x +y −y +z −z).
fn axis(l: u8) -> Vector3<f64> {
    let mut a = Vector3::zeros();
    a[usize::from(l / 2)] = if l.is_multiple_of(2) { 1.0 } else { -1.0 };
    a
}

/// Deformation state: the input mesh, its per-tetrahedron gradients and volumes.
struct Deformation<'a> {
    mesh: &'a TetMesh,
    grads: Vec<[Vector3<f64>; 4]>,
    volumes: Vec<f64>,
}

impl Deformation<'_> {
    fn jacobian(&self, y: &[[f64; 3]], t: usize) -> Matrix3<f64> {
        let mut j = Matrix3::zeros();
        for (k, &v) in self.mesh.tets[t].iter().enumerate() {
            j += Vector3::from(y[v as usize]) * self.grads[t][k].transpose();
        }
        j
    }

    /// The vertex pinned in `K`.
    fn pinned(&self) -> usize {
        self.mesh.tets[0][0] as usize
    }

    /// `K = Σ w V Gᵀ G` for the weights `stiffness`, one vertex pinned; a tiny shift keeps
    /// unused vertices at rest. Returns the factor and the mean diagonal (the pin's weight).
    fn factor_k(&self, stiffness: &[f64]) -> Result<(CholeskyFactor, f64), PolycubeError> {
        let mesh = self.mesh;
        let (nt, nv) = (mesh.tets.len(), mesh.verts.len());
        let pinned = self.pinned();
        let mut k = Triplets::new(nv);
        let mut trace = 0.0;
        for t in 0..nt {
            let tet = mesh.tets[t];
            for a in 0..4 {
                for b in 0..4 {
                    let (va, vb) = (tet[a] as usize, tet[b] as usize);
                    if vb <= va {
                        let h = stiffness[t]
                            * self.volumes[t]
                            * self.grads[t][a].dot(&self.grads[t][b]);
                        k.push(va, vb, h);
                        if va == vb {
                            trace += h;
                        }
                    }
                }
            }
        }
        let mean = trace / nv.max(1) as f64;
        for v in 0..nv {
            k.push(v, v, 1e-10 * mean);
        }
        k.push(pinned, pinned, mean);
        Ok((
            CholeskyFactor::new(&mut k).map_err(PolycubeError::Solve)?,
            mean,
        ))
    }
}

/// Outward normal and area of boundary face `k` at positions `y`.
fn boundary_face(mesh: &TetMesh, topo: &Topology, y: &[[f64; 3]], k: usize) -> (Vector3<f64>, f64) {
    let (t, i) = topo.boundary[k];
    let f = FACE_OPPOSITE[i as usize].map(|j| Vector3::from(y[mesh.tets[t as usize][j] as usize]));
    let n = (f[1] - f[0]).cross(&(f[2] - f[0]));
    let a = n.norm();
    (if a > 0.0 { n / a } else { n }, a / 2.0)
}

/// Area-weighted mean deviation (degrees) of the boundary normals at `y` from their axes, the
/// fraction of area within 5° (the axes of `fixed` labels where given, else the nearest).
fn deviation(mesh: &TetMesh, topo: &Topology, y: &[[f64; 3]], fixed: Option<&[u8]>) -> (f64, f64) {
    let (mut sum, mut within, mut area) = (0.0, 0.0, 0.0);
    for k in 0..topo.boundary.len() {
        let (n, a) = boundary_face(mesh, topo, y, k);
        let axis = match fixed {
            Some(f) => axis(f[k]),
            None => label(&n).1,
        };
        let angle = n.dot(&axis).clamp(-1.0, 1.0).acos().to_degrees();
        sum += a * angle;
        area += a;
        if angle <= 5.0 {
            within += a;
        }
    }
    let area = area.max(f64::MIN_POSITIVE);
    (sum / area, within / area)
}

/// Passes of the label clean-up before it gives up (each pass only relabels).
const CLEANUP_PASSES: usize = 50;

/// Triangles a chart needs to stay a chart of its own.
const MIN_CHART: usize = 3;

/// An edge two triangles share, and the two triangles.
type SharedEdge = ([u32; 2], u32, u32);

/// The triangles across each triangle's edges, and the edges two triangles share (the edge,
/// the two triangles); an edge of one triangle only (an open patch) has no neighbour.
fn triangle_graph(tris: &[[u32; 3]]) -> (Vec<Vec<u32>>, Vec<SharedEdge>) {
    let mut edges: Vec<([u32; 2], u32)> = Vec::with_capacity(3 * tris.len());
    for (k, t) in tris.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.push(([a.min(b), a.max(b)], k as u32));
        }
    }
    edges.sort_unstable();
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); tris.len()];
    let mut shared = Vec::with_capacity(edges.len() / 2);
    let mut i = 0;
    while i < edges.len() {
        match edges.get(i + 1) {
            Some(&(e, b)) if e == edges[i].0 => {
                let a = edges[i].1;
                adj[a as usize].push(b);
                adj[b as usize].push(a);
                shared.push((e, a, b));
                i += 2;
            }
            _ => i += 1,
        }
    }
    (adj, shared)
}

/// The boundary faces' labels (`2 axis + [negative]`) from the deformed normals, cleaned up
/// (module docs): charts of fewer than [`MIN_CHART`] triangles take the label they share
/// the most edges with, and a triangle whose three vertices all lie on charts of another axis
/// (it would be flattened onto a line between two planes) takes that chart's label.
fn clean_labels(mesh: &TetMesh, topo: &Topology, y: &[[f64; 3]]) -> Vec<u8> {
    let nf = topo.boundary.len();
    let tris = topo.boundary_triangles(mesh);
    let mut lab: Vec<u8> = (0..nf)
        .map(|k| label(&boundary_face(mesh, topo, y, k).0).0 as u8)
        .collect();
    let (adj, shared) = triangle_graph(&tris);
    let mut relabelled = vec![false; nf];
    clean_up(&tris, &adj, &mut lab, &mut relabelled, mesh.verts.len());
    for _ in 0..4 {
        let mut turned = false;
        for _ in 0..TURN_PASSES {
            if !remove_turns(&tris, &adj, &shared, &mut lab, y) {
                break;
            }
            turned = true;
        }
        if !turned {
            break;
        }
        clean_up(&tris, &adj, &mut lab, &mut relabelled, mesh.verts.len());
    }
    lab
}

/// Passes that remove turning borders before the labels are taken as they are.
const TURN_PASSES: usize = 24;

/// The charts (connected runs of one label across edges) of the labelled triangles.
fn charts(adj: &[Vec<u32>], lab: &[u8]) -> Vec<u32> {
    let mut chart = vec![u32::MAX; lab.len()];
    let mut stack = Vec::new();
    for s in 0..lab.len() {
        if chart[s] != u32::MAX {
            continue;
        }
        chart[s] = s as u32;
        stack.push(s as u32);
        while let Some(f) = stack.pop() {
            for &g in &adj[f as usize] {
                if chart[g as usize] == u32::MAX && lab[g as usize] == lab[s] {
                    chart[g as usize] = s as u32;
                    stack.push(g);
                }
            }
        }
    }
    chart
}

/// A border between two charts that is convex along part of its length and concave along
/// the rest turns. Where one chart runs as a tongue between two levels of the other (a step
/// in a plane that fades out), no polycube has it: the parameterisation squeezes the tongue
/// flat and its tetrahedra invert. The tongue is the chart whose two border runs with the
/// other lie apart along the other's axis `a`; its triangles next to the shorter (minority)
/// run, and those reached from them within the tongue (between the runs' levels along `a`,
/// widened by half their distance, and within the minority run's extent along the border's
/// own axis), take the other chart's
/// label at once, when they are at most half their chart. Returns whether a label changed.
fn remove_turns(
    tris: &[[u32; 3]],
    adj: &[Vec<u32>],
    shared: &[SharedEdge],
    lab: &mut [u8],
    y: &[[f64; 3]],
) -> bool {
    let chart = charts(adj, lab);
    let p = |v: u32| Vector3::from(y[v as usize]);
    let centre = |k: u32| tris[k as usize].iter().map(|&v| p(v)).sum::<Vector3<f64>>() / 3.0;
    // Per border (chart pair, lower id first), per kind (0 convex, 1 concave): the edges, as
    // (triangle on the lower chart, triangle on the higher, midpoint).
    type Run = Vec<(u32, u32, Vector3<f64>, [u32; 2])>;
    let mut borders: std::collections::BTreeMap<(u32, u32), [Run; 2]> =
        std::collections::BTreeMap::new();
    for &(e, f, g) in shared {
        let (f, g) = if chart[f as usize] <= chart[g as usize] {
            (f, g)
        } else {
            (g, f)
        };
        if chart[f as usize] == chart[g as usize] || lab[f as usize] / 2 == lab[g as usize] / 2 {
            continue;
        }
        // Convex where each side lies behind the other's plane (the planes of the labels,
        // not of the triangles).
        let mid = (p(e[0]) + p(e[1])) / 2.0;
        let kind = usize::from(
            (centre(g) - mid).dot(&axis(lab[f as usize]))
                + (centre(f) - mid).dot(&axis(lab[g as usize]))
                >= 0.0,
        );
        borders
            .entry((chart[f as usize], chart[g as usize]))
            .or_default()[kind]
            .push((f, g, mid, e));
    }
    let mut size = vec![0usize; lab.len()];
    for &c in &chart {
        size[c as usize] += 1;
    }
    // Charts relabelled in this pass: their borders are stale until the next pass
    // recomputes the charts.
    let mut touched = std::collections::BTreeSet::new();
    for (&(c0, c1), runs) in &borders {
        if runs[0].is_empty()
            || runs[1].is_empty()
            || touched.contains(&c0)
            || touched.contains(&c1)
        {
            continue;
        }
        let minority = usize::from(runs[1].len() < runs[0].len());
        // How far the minority run lies from the majority run next to it, per axis: each
        // minority edge against its nearest majority edge (a long run's mean would mix in
        // levels far away).
        let near: Vec<Vector3<f64>> = runs[minority]
            .iter()
            .map(|x| {
                runs[1 - minority]
                    .iter()
                    .map(|m| m.2)
                    .min_by(|p, q| {
                        (p - x.2)
                            .norm_squared()
                            .total_cmp(&(q - x.2).norm_squared())
                    })
                    .expect("a border run is not empty")
            })
            .collect();
        let mean = |v: &mut dyn Iterator<Item = Vector3<f64>>| {
            let (sum, n) = v.fold((Vector3::zeros(), 0usize), |(s, n), p| (s + p, n + 1));
            sum / n.max(1) as f64
        };
        let level_min = mean(&mut runs[minority].iter().map(|x| x.2));
        let level_maj = mean(&mut near.iter().copied());
        let apart = mean(
            &mut runs[minority]
                .iter()
                .zip(&near)
                .map(|(x, m)| (x.2 - m).abs()),
        );
        let (f0, g0, _, _) = runs[minority][0];
        let (af, ag) = (
            usize::from(lab[f0 as usize] / 2),
            usize::from(lab[g0 as usize] / 2),
        );
        // The tongue is the chart whose runs lie apart along the other chart's axis.
        let (tongue_side, a) = if apart[af] >= apart[ag] {
            (1, af)
        } else {
            (0, ag)
        };
        let other_side =
            |x: &(u32, u32, Vector3<f64>, [u32; 2])| if tongue_side == 1 { x.0 } else { x.1 };
        let along = 3 - af - ag;
        let margin = apart[a] / 2.0;
        let (lo_a, hi_a) = (
            level_min[a].min(level_maj[a]) - margin,
            level_min[a].max(level_maj[a]) + margin,
        );
        let (lo_e, hi_e) = runs[minority]
            .iter()
            .flat_map(|x| x.3)
            .fold((f64::MAX, f64::MIN), |(lo, hi), v| {
                (lo.min(p(v)[along]), hi.max(p(v)[along]))
            });
        let tongue_of =
            |x: &(u32, u32, Vector3<f64>, [u32; 2])| if tongue_side == 1 { x.1 } else { x.0 };
        let tongue_chart = chart[tongue_of(&runs[minority][0]) as usize];
        let label = lab[other_side(&runs[minority][0]) as usize];
        let inside = |k: u32| {
            let c = centre(k);
            chart[k as usize] == tongue_chart
                && (lo_a..=hi_a).contains(&c[a])
                && (lo_e..=hi_e).contains(&c[along])
        };
        let mut seen = std::collections::BTreeSet::new();
        let mut stack: Vec<u32> = runs[minority]
            .iter()
            .map(tongue_of)
            .filter(|&k| inside(k))
            .collect();
        while let Some(k) = stack.pop() {
            if !seen.insert(k) {
                continue;
            }
            stack.extend(
                adj[k as usize]
                    .iter()
                    .copied()
                    .filter(|&g| !seen.contains(&g) && inside(g)),
            );
        }
        if seen.is_empty() || 2 * seen.len() > size[tongue_chart as usize] {
            continue;
        }
        for k in seen {
            lab[k as usize] = label;
        }
        touched.extend([c0, c1]);
    }
    !touched.is_empty()
}

/// The label clean-up passes of [`clean_labels`] (module docs): small charts, teeth and
/// triangles pinched between two planes.
fn clean_up(
    tris: &[[u32; 3]],
    adj: &[Vec<u32>],
    lab: &mut [u8],
    relabelled: &mut [bool],
    nv: usize,
) {
    let nf = lab.len();
    for _ in 0..CLEANUP_PASSES {
        let mut changed = false;
        // Small charts (relabelled in order of their first triangle, each seeing the labels
        // the charts before it were given).
        let chart = charts(adj, lab);
        let mut size = vec![0usize; nf];
        for &c in &chart {
            size[c as usize] += 1;
        }
        let mut small: Vec<Vec<u32>> = vec![Vec::new(); nf];
        for (k, &c) in chart.iter().enumerate() {
            if size[c as usize] < MIN_CHART {
                small[c as usize].push(k as u32);
            }
        }
        for (s, members) in small.iter().enumerate() {
            if members.is_empty() {
                continue;
            }
            let mut border = [0usize; 6];
            for &f in members {
                for &g in &adj[f as usize] {
                    if lab[g as usize] != lab[s] {
                        border[lab[g as usize] as usize] += 1;
                    }
                }
            }
            let best = (0..6).max_by_key(|&l| (border[l], std::cmp::Reverse(l)));
            if let Some(best) = best.filter(|&l| border[l] > 0) {
                for &f in members {
                    lab[f as usize] = best as u8;
                }
                changed = true;
            }
        }
        // Teeth: a triangle two of whose neighbours share another label takes it.
        for k in 0..nf {
            let n = &adj[k];
            for (i, &a) in n.iter().enumerate() {
                let l = lab[a as usize];
                if l != lab[k] && n[i + 1..].iter().any(|&b| lab[b as usize] == l) {
                    lab[k] = l;
                    changed = true;
                    break;
                }
            }
        }
        // Triangles on a line between two planes.
        let mut on = vec![0u8; nv];
        for (k, t) in tris.iter().enumerate() {
            for &v in t {
                on[v as usize] |= 1 << lab[k];
            }
        }
        for (k, t) in tris.iter().enumerate() {
            let common = t.iter().fold(0x3f, |m, &v| m & on[v as usize]);
            let axis = lab[k] / 2;
            if let Some(other) = (0..6u8).find(|&l| l / 2 != axis && common & (1 << l) != 0)
                && adj[k].iter().any(|&g| lab[g as usize] == other)
                && !relabelled[k]
            {
                lab[k] = other;
                relabelled[k] = true;
                for &v in t {
                    on[v as usize] |= 1 << other;
                }
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
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

/// The weights `λ A_f / Ā` of the boundary targets (module docs, step 2): each boundary
/// triangle's input area over their mean.
fn boundary_weights(mesh: &TetMesh, topo: &Topology, params: &PolycubeParams) -> Vec<f64> {
    let areas: Vec<f64> = (0..topo.boundary.len())
        .map(|f| boundary_face(mesh, topo, &mesh.verts, f).1)
        .collect();
    let mean_area = areas.iter().sum::<f64>() / areas.len().max(1) as f64;
    areas
        .iter()
        .map(|a| params.boundary_weight * a / mean_area.max(f64::MIN_POSITIVE))
        .collect()
}

/// `L`: the graph Laplacian of the tetrahedra across faces plus the boundary `weights` (and
/// a tiny shift on the diagonal), the matrix of step 2.
fn rotation_laplacian(topo: &Topology, weights: &[f64]) -> Triplets {
    let nt = topo.neighbours.len();
    let mut l = Triplets::new(nt);
    for t in 0..nt {
        for &s in &topo.neighbours[t] {
            if s != NO_TET && (s as usize) < t {
                l.push(t, t, 1.0);
                l.push(s as usize, s as usize, 1.0);
                l.push(t, s as usize, -1.0);
            }
        }
        l.push(t, t, 1e-10);
    }
    for (f, &(t, _)) in topo.boundary.iter().enumerate() {
        l.push(t as usize, t as usize, weights[f]);
    }
    l
}

/// The stiffness of step 3: the weights `w_t` and the factor of `K` for them, with its mean
/// diagonal (the weight pinning one vertex).
struct Stiffness {
    w: Vec<f64>,
    kf: CholeskyFactor,
    mean: f64,
}

/// What the deformation iterations share: the mesh's deformation state, the boundary
/// targets' weights and the factored Laplacian `L` of step 2.
struct Deformer<'a> {
    def: Deformation<'a>,
    topo: &'a Topology,
    weights: Vec<f64>,
    lf: CholeskyFactor,
    params: &'a PolycubeParams,
}

impl Deformer<'_> {
    /// One phase of the deformation (module docs): iterations from `y` until `limit` are
    /// run, the mean deviation from the axes (of the labels `fixed`, else the nearest) is
    /// below the tolerance, it has not fallen for ten iterations, or no step keeps every
    /// tetrahedron positive. `best` keeps the least deviation and its positions.
    fn phase(
        &self,
        k: &mut Stiffness,
        y: &mut Vec<[f64; 3]>,
        best: &mut (f64, Vec<[f64; 3]>),
        fixed: Option<&[u8]>,
        limit: usize,
        report: &mut PolycubeReport,
    ) -> Result<(), PolycubeError> {
        let (mesh, topo) = (self.def.mesh, self.topo);
        let mut stale = 0;
        while report.iterations < limit && report.mean_deviation > self.params.tolerance_degrees {
            let r = self.rotations(y, fixed);
            let Some(next) = self.deform(y, &r, k, report)? else {
                break;
            };
            *y = next;
            report.iterations += 1;
            let (dev, _) = deviation(mesh, topo, y, fixed);
            report.mean_deviation = dev;
            if dev < best.0 - 1e-3 {
                *best = (dev, y.clone());
                stale = 0;
            } else {
                stale += 1;
                if stale >= 10 {
                    break;
                }
            }
        }
        Ok(())
    }

    /// Steps 1–2: each boundary triangle's target rotation towards its axis (its `fixed`
    /// label's, else the nearest), spread over the tetrahedra by `L`.
    fn rotations(&self, y: &[[f64; 3]], fixed: Option<&[u8]>) -> Vec<Vector3<f64>> {
        let (mesh, topo) = (self.def.mesh, self.topo);
        let mut rhs = vec![[0.0; 3]; mesh.tets.len()];
        for (f, &(t, _)) in topo.boundary.iter().enumerate() {
            let (n, _) = boundary_face(mesh, topo, y, f);
            let a = match fixed {
                Some(l) => axis(l[f]),
                None => label(&n).1,
            };
            let axis = n.cross(&a);
            let s = axis.norm();
            if s > 1e-12 {
                let rho = axis * (s.atan2(n.dot(&a)) / s);
                for d in 0..3 {
                    rhs[t as usize][d] += self.weights[f] * rho[d];
                }
            }
        }
        self.lf.solve(&rhs).into_iter().map(Vector3::from).collect()
    }

    /// Step 3: rigid targets (the rotations `r` of the clamped gradients at `y`), solved for
    /// positions. A tetrahedron that blocks every step (it would turn inside out) is
    /// stiffened and the positions solved again, up to [`STIFFEN_ROUNDS`] times. Returns the
    /// next positions, or `None` when no step keeps every tetrahedron positive.
    fn deform(
        &self,
        y: &[[f64; 3]],
        r: &[Vector3<f64>],
        k: &mut Stiffness,
        report: &mut PolycubeReport,
    ) -> Result<Option<Vec<[f64; 3]>>, PolycubeError> {
        let def = &self.def;
        let mesh = def.mesh;
        let (nt, nv) = (mesh.tets.len(), mesh.verts.len());
        let pinned = def.pinned();
        let targets: Vec<Matrix3<f64>> = (0..nt)
            .into_par_iter()
            .map(|t| {
                let turn = Rotation3::new(r[t]).into_inner();
                turn * clamp_stretch(&def.jacobian(y, t), STRETCH)
            })
            .collect();
        let flipped_now: Vec<bool> = (0..nt)
            .into_par_iter()
            .map(|t| def.jacobian(y, t).determinant() <= 0.0)
            .collect();
        for _ in 0..=STIFFEN_ROUNDS {
            let pulls: Vec<[Vector3<f64>; 4]> = (0..nt)
                .into_par_iter()
                .map(|t| def.grads[t].map(|g| targets[t] * g * (k.w[t] * def.volumes[t])))
                .collect();
            let mut b = vec![[0.0; 3]; nv];
            for (tet, pull) in mesh.tets.iter().zip(&pulls) {
                for (&v, qg) in tet.iter().zip(pull) {
                    for d in 0..3 {
                        b[v as usize][d] += qg[d];
                    }
                }
            }
            for d in 0..3 {
                b[pinned][d] += k.mean * y[pinned][d];
            }
            let target = k.kf.solve(&b);
            let blocking = match self.step_towards(y, &target, &flipped_now) {
                Ok(next) => return Ok(Some(next)),
                Err(blocking) => blocking,
            };
            for t in blocking {
                k.w[t] *= STIFFEN;
                for &s in &self.topo.neighbours[t] {
                    if s != NO_TET {
                        k.w[s as usize] *= STIFFEN.sqrt();
                    }
                }
            }
            report.stiffened += 1;
            (k.kf, k.mean) = def.factor_k(&k.w)?;
        }
        Ok(None)
    }

    /// The step from `y` towards the solve's positions `target`, halved while a tetrahedron
    /// would turn inside out (one already flipped, `flipped_now`, does not count). `Err`:
    /// the tetrahedra that would still turn at a step of [`MIN_STEP`].
    fn step_towards(
        &self,
        y: &[[f64; 3]],
        target: &[[f64; 3]],
        flipped_now: &[bool],
    ) -> Result<Vec<[f64; 3]>, Vec<usize>> {
        let def = &self.def;
        let nt = def.mesh.tets.len();
        let mut step = 1.0;
        loop {
            let cand: Vec<[f64; 3]> = y
                .par_iter()
                .zip(target)
                .map(|(a, b)| std::array::from_fn(|d| a[d] + step * (b[d] - a[d])))
                .collect();
            let bad: Vec<usize> = (0..nt)
                .into_par_iter()
                .filter(|&t| !flipped_now[t] && def.jacobian(&cand, t).determinant() <= 0.0)
                .collect();
            if bad.is_empty() {
                return Ok(cand);
            }
            if step <= MIN_STEP {
                return Err(bad);
            }
            step *= 0.5;
        }
    }
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
