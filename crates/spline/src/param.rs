//! Parameterisation of a patch's points over a rectangle (Greiner & Hormann 1997, §4).
//!
//! # The plane
//!
//! The best-fit plane of the points by principal components: through their centroid, spanned
//! by the eigenvectors of the two largest eigenvalues of their covariance, normal along the
//! smallest. Sign rule, so that the frame does not depend on the eigen solver: the largest
//! component (in absolute value, the first on ties) of the first axis and of the normal is
//! positive, and the second axis is `normal × first`, a right-handed frame.
//!
//! # The spring model (§4)
//!
//! Boundary vertices of the [`Graph`] are fixed at their projections onto the plane. Every
//! edge `(i, j)` is a spring of stiffness `k_ij = 1 / |P_i − P_j|^r` and rest length
//! `L_ij = α |P_i − P_j|`, and the interior parameters `u_i` minimise
//! `Σ_edges k_ij (|u_i − u_j| − L_ij)²`:
//!
//! * `α = 0`: the energy is the quadratic `Σ k_ij |u_i − u_j|²`, minimised by the weighted
//!   Laplacian system `Σ_j k_ij (u_i − u_j) = 0` for every interior `i`, fixed neighbours moved
//!   to the right-hand side: one sparse symmetric positive definite system, two right-hand
//!   sides (`u` and `v`), solved by sparse Cholesky (faer). `r = 0` is the uniform (Tutte)
//!   parameterisation, `r = 1` the chord-length one; with a convex boundary Tutte's theorem
//!   guarantees a triangulation without fold-overs.
//! * `α > 0`: the energy is not quadratic. Stress majorisation (a local-global iteration)
//!   replaces `−|u_i − u_j|` by its linear minorant at the current `z`,
//!   `−(u_i − u_j)·(z_i − z_j)/|z_i − z_j|`, and solves the same Laplacian system with the
//!   right-hand side `Σ_j k_ij L_ij (z_i − z_j)/|z_i − z_j|` added, reusing one
//!   factorisation; each step cannot increase the energy. It starts from the `α = 0` solution
//!   with the same stiffnesses and stops when no parameter moves by more than `1e-9` of the
//!   longer side of the projections' bounding box, or after [`MAX_ITERATIONS`] steps.
//!
//! An edge shorter than `1e-12` of the points' bounding-box diagonal (repeated points) takes
//! the stiffness of that length, so that no weight is infinite.
//!
//! **Components without a boundary vertex** (a vertex without edges, or a closed piece of a
//! triangulation) would make the system singular: their vertices are fixed at their
//! projections like boundary vertices and counted in [`Param::unreachable`].
//!
//! [`Method::Project`] skips the springs: every point is its projection (height fields).
//!
//! # The rectangle
//!
//! The parameter domain is the smallest-area rectangle enclosing the `(u, v)`
//! ([`crate::geom::rect`]): the parameters are rotated so that its longer side lies along `u`
//! and shifted so that its lower corner is the origin, so `uv ∈ [0, size[0]] × [0, size[1]]`
//! in world length units. [`Param::axes`] are the plane's world directions after that rotation
//! and [`Param::origin`] the world point of the corner, so the plane point of `(u, v)` is
//! `origin + u axes[0] + v axes[1]`.
//!
//! # Fold-overs
//!
//! For a graph with triangles, [`Param::folds`] counts the triangles whose signed area in the
//! parameter plane has the sign opposite to the sum of all signed areas (a consistently wound
//! disc maps to one orientation; a flipped triangle is a fold-over).

use faer::prelude::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};

use super::graph::{Graph, dot};
use crate::error::{Error, Result};
use crate::geom::rect::min_area_rect;

/// Most stress-majorisation steps for `α > 0`.
pub const MAX_ITERATIONS: usize = 100;

/// Relative change (of the projections' longer extent) below which the iteration stops.
const CONVERGED: f64 = 1e-9;

/// How the interior points are placed in the plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Every point at its orthogonal projection onto the best-fit plane (height fields).
    Project,
    /// The spring model of §4.
    Spring {
        /// Rest length as a fraction of the 3D edge length (`0 <= alpha < 1`).
        alpha: f64,
        /// Stiffness exponent: `k = 1 / length^r`.
        r: f64,
    },
}

impl Method {
    /// Uniform springs (`α = 0, r = 0`): Tutte's barycentric mapping.
    pub fn uniform() -> Method {
        Method::Spring { alpha: 0.0, r: 0.0 }
    }

    /// Chord-length springs (`α = 0, r = 1`).
    pub fn chord() -> Method {
        Method::Spring { alpha: 0.0, r: 1.0 }
    }

    /// "Real" springs (`α = 0.5, r = 1`): rest length half the 3D length.
    pub fn real_spring() -> Method {
        Method::Spring { alpha: 0.5, r: 1.0 }
    }
}

/// A patch's parameters over its rectangle.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// World position of the rectangle's lower corner `(0, 0)`, on the best-fit plane.
    pub origin: [f64; 3],
    /// World unit directions: `u`, `v` (the rectangle's sides, `u` along the longer one) and
    /// the plane's normal `u × v`.
    pub axes: [[f64; 3]; 3],
    /// Per point, its parameters in world length units, inside `[0, size[0]] × [0, size[1]]`.
    pub uv: Vec<[f64; 2]>,
    /// The rectangle's side lengths, world units, `size[0] >= size[1] > 0`.
    pub size: [f64; 2],
    /// Triangles whose parameter orientation is flipped (0 for a graph without triangles).
    pub folds: usize,
    /// Points in graph components without a boundary vertex, fixed at their projections.
    pub unreachable: usize,
    /// Stress-majorisation steps taken (0 for `α = 0` and [`Method::Project`]).
    pub iterations: usize,
}

/// An orthonormal frame through a centroid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Frame {
    /// The points' centroid.
    pub(super) centroid: [f64; 3],
    /// First axis, second axis, normal (right-handed).
    pub(super) axes: [[f64; 3]; 3],
}

/// Make the largest component of `v` (the first on ties) positive.
fn sign_rule(v: [f64; 3]) -> [f64; 3] {
    let mut k = 0;
    for c in 1..3 {
        if v[c].abs() > v[k].abs() {
            k = c;
        }
    }
    if v[k] < 0.0 { [-v[0], -v[1], -v[2]] } else { v }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The principal-component frame of `n` points (the module docs' sign rule).
pub(super) fn pca_frame(points: impl Iterator<Item = [f64; 3]> + Clone, n: usize) -> Frame {
    let inv = 1.0 / n.max(1) as f64;
    let mut c = [0.0; 3];
    for p in points.clone() {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    c = c.map(|v| v * inv);
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = nalgebra::Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        m += d * d.transpose();
    }
    let e = nalgebra::SymmetricEigen::new(m * inv);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| {
        e.eigenvalues[b]
            .total_cmp(&e.eigenvalues[a])
            .then(a.cmp(&b))
    });
    let col = |k: usize| {
        let v = e.eigenvectors.column(order[k]);
        [v[0], v[1], v[2]]
    };
    let first = sign_rule(col(0));
    let normal = sign_rule(col(2));
    let second = cross(normal, first);
    Frame {
        centroid: c,
        axes: [first, second, normal],
    }
}

/// The frame of [`pca_frame`] turned to the plane normal to `normal` (unit): the first axis is
/// the principal one projected into that plane (any perpendicular when it is parallel to
/// `normal`), the second `normal × first`.
fn facing_frame(pca: Frame, normal: [f64; 3]) -> Frame {
    let along = |v: [f64; 3]| {
        let d = dot(v, normal);
        [
            v[0] - d * normal[0],
            v[1] - d * normal[1],
            v[2] - d * normal[2],
        ]
    };
    let unit = |v: [f64; 3]| {
        let l = dot(v, v).sqrt();
        (l > 1e-6).then(|| v.map(|x| x / l))
    };
    let first = unit(along(pca.axes[0]))
        .or_else(|| unit(along(pca.axes[1])))
        .or_else(|| unit(along([1.0, 0.0, 0.0])))
        .or_else(|| unit(along([0.0, 1.0, 0.0])))
        .unwrap_or([1.0, 0.0, 0.0]);
    Frame {
        centroid: pca.centroid,
        axes: [first, cross(normal, first), normal],
    }
}

/// Parameterise `points` over a rectangle in their best-fit plane by `method` (module docs).
///
/// Errors: `graph` not of `points.len()` vertices (a caller's bug), fewer than 3 points, a
/// coordinate that is not finite, points on one line, a spring method with `α` outside
/// `[0, 1)` or `r` not finite, or a graph without a boundary vertex.
pub fn parameterise(points: &[[f64; 3]], graph: &Graph, method: Method) -> Result<Param> {
    parameterise_facing(points, graph, method, None)
}

/// [`parameterise`] over the plane normal to `normal` (a unit vector, e.g. the mean normal of
/// a patch whose normals lie in a cone about it, over which it is a height field) instead of
/// the best-fit plane; `None` is the best-fit plane. A strongly curved patch (a cap wrapped
/// around a rim) can have a best-fit plane that it folds over when projected; the plane
/// normal to the cone's axis never does where the normals stay within 90° of the axis.
pub fn parameterise_facing(
    points: &[[f64; 3]],
    graph: &Graph,
    method: Method,
    normal: Option<[f64; 3]>,
) -> Result<Param> {
    if graph.len() != points.len() {
        return Err(Error::Internal(format!(
            "parameterise: a graph of {} vertices for {} points",
            graph.len(),
            points.len()
        )));
    }
    if points.len() < 3 {
        return Err(Error::Usage(format!(
            "a patch of {} points cannot be parameterised: at least 3 are needed",
            points.len()
        )));
    }
    if let Some(i) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(Error::Usage(format!(
            "point {i} of the patch has a coordinate that is not finite"
        )));
    }
    let pca = pca_frame(points.iter().copied(), points.len());
    let frame = match normal {
        Some(n) if n.iter().all(|x| x.is_finite()) && (dot(n, n) - 1.0).abs() < 1e-6 => {
            facing_frame(pca, n)
        }
        _ => pca,
    };
    let proj: Vec<[f64; 2]> = points
        .iter()
        .map(|p| {
            let d = [
                p[0] - frame.centroid[0],
                p[1] - frame.centroid[1],
                p[2] - frame.centroid[2],
            ];
            [dot(d, frame.axes[0]), dot(d, frame.axes[1])]
        })
        .collect();
    let (uv, unreachable, iterations) = match method {
        Method::Project => (proj, 0, 0),
        Method::Spring { alpha, r } => {
            if !(0.0..1.0).contains(&alpha) || !r.is_finite() {
                return Err(Error::Usage(format!(
                    "spring parameterisation: alpha = {alpha} must lie in [0, 1) and r = {r} be finite"
                )));
            }
            springs(points, graph, &proj, alpha, r)?
        }
    };
    let folds = count_folds(&graph.triangles, &uv);
    let rect = rectangle(&frame, uv);
    let size = rect.size;
    if size[1] <= 1e-12 * size[0] {
        return Err(Error::Usage(format!(
            "the patch's {} points lie on one line (parameter rectangle {} × {}): no surface \
             can be fitted",
            points.len(),
            size[0],
            size[1]
        )));
    }
    Ok(Param {
        folds,
        unreachable,
        iterations,
        ..rect
    })
}

/// The rectangle of the module docs: origin, axes, the parameters in its frame, its size (the
/// counts left 0).
fn rectangle(frame: &Frame, mut uv: Vec<[f64; 2]>) -> Param {
    let rect = min_area_rect(&uv);
    let size = rect.size();
    let [a0, a1] = rect.axis;
    let [e1, e2, n] = frame.axes;
    let u_axis = [0, 1, 2].map(|k| a0 * e1[k] + a1 * e2[k]);
    let v_axis = [0, 1, 2].map(|k| -a1 * e1[k] + a0 * e2[k]);
    let origin =
        [0, 1, 2].map(|k| frame.centroid[k] + rect.lo[0] * u_axis[k] + rect.lo[1] * v_axis[k]);
    for p in &mut uv {
        let q = rect.to_frame(*p);
        *p = [
            (q[0] - rect.lo[0]).clamp(0.0, size[0]),
            (q[1] - rect.lo[1]).clamp(0.0, size[1]),
        ];
    }
    Param {
        origin,
        axes: [u_axis, v_axis, n],
        uv,
        size,
        folds: 0,
        unreachable: 0,
        iterations: 0,
    }
}

/// Triangles whose signed parameter area has the sign opposite to the total.
fn count_folds(triangles: &[[u32; 3]], uv: &[[f64; 2]]) -> usize {
    let area = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| uv[i as usize]);
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let total: f64 = triangles.iter().map(area).sum();
    triangles
        .iter()
        .filter(|t| {
            let a = area(t);
            (a > 0.0 && total < 0.0) || (a < 0.0 && total > 0.0)
        })
        .count()
}

/// Union-find root with path halving.
fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[parent[i as usize] as usize];
        parent[i as usize] = p;
        i = p;
    }
    i
}

/// Which vertices are fixed: boundary ones and those of components without a boundary
/// vertex; the count of the latter.
fn fixed_vertices(graph: &Graph) -> (Vec<bool>, usize) {
    let n = graph.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for e in &graph.edges {
        let (a, b) = (root(&mut parent, e[0]), root(&mut parent, e[1]));
        if a != b {
            parent[a.max(b) as usize] = a.min(b);
        }
    }
    let mut anchored = vec![false; n];
    for i in 0..n {
        if graph.boundary[i] {
            let r = root(&mut parent, i as u32);
            anchored[r as usize] = true;
        }
    }
    let mut fixed = graph.boundary.clone();
    let mut unreachable = 0;
    for i in 0..n {
        let r = root(&mut parent, i as u32);
        if !anchored[r as usize] {
            fixed[i] = true;
            unreachable += 1;
        }
    }
    (fixed, unreachable)
}

/// The spring model: parameters, unreachable count, iterations.
fn springs(
    points: &[[f64; 3]],
    graph: &Graph,
    proj: &[[f64; 2]],
    alpha: f64,
    r: f64,
) -> Result<(Vec<[f64; 2]>, usize, usize)> {
    if !graph.boundary.contains(&true) {
        return Err(Error::Usage(
            "the patch's graph has no boundary vertex: a closed surface is not a disc; use \
             --patches to fit it in patches"
                .to_string(),
        ));
    }
    let (fixed, unreachable) = fixed_vertices(graph);
    let mut slot = vec![usize::MAX; points.len()];
    let mut m = 0;
    for (i, f) in fixed.iter().enumerate() {
        if !f {
            slot[i] = m;
            m += 1;
        }
    }
    let mut uv = proj.to_vec();
    if m == 0 {
        return Ok((uv, unreachable, 0));
    }
    let (lo, hi) = points
        .iter()
        .fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), p| {
            (
                [0, 1, 2].map(|k| lo[k].min(p[k])),
                [0, 1, 2].map(|k| hi[k].max(p[k])),
            )
        });
    let diag = dot(
        [0, 1, 2].map(|k| hi[k] - lo[k]),
        [0, 1, 2].map(|k| hi[k] - lo[k]),
    )
    .sqrt();
    let shortest = 1e-12 * diag;
    // Per edge: stiffness and rest length.
    let springs: Vec<(f64, f64)> = graph
        .edges
        .iter()
        .map(|e| {
            let (p, q) = (points[e[0] as usize], points[e[1] as usize]);
            let d = [0, 1, 2].map(|k| p[k] - q[k]);
            let len = dot(d, d).sqrt();
            let k = if r == 0.0 {
                1.0
            } else {
                len.max(shortest).powf(-r)
            };
            (k, alpha * len)
        })
        .collect();
    let mut diagonal = vec![0.0; m];
    let mut triplets = Vec::with_capacity(m + 2 * graph.edges.len());
    let mut rhs = vec![[0.0; 2]; m];
    for (e, &(k, _)) in graph.edges.iter().zip(&springs) {
        let (i, j) = (e[0] as usize, e[1] as usize);
        match (slot[i], slot[j]) {
            (usize::MAX, usize::MAX) => {}
            (si, usize::MAX) => {
                diagonal[si] += k;
                rhs[si] = [rhs[si][0] + k * uv[j][0], rhs[si][1] + k * uv[j][1]];
            }
            (usize::MAX, sj) => {
                diagonal[sj] += k;
                rhs[sj] = [rhs[sj][0] + k * uv[i][0], rhs[sj][1] + k * uv[i][1]];
            }
            (si, sj) => {
                diagonal[si] += k;
                diagonal[sj] += k;
                triplets.push(Triplet::new(si.max(sj), si.min(sj), -k));
            }
        }
    }
    triplets.extend(
        diagonal
            .iter()
            .enumerate()
            .map(|(i, &d)| Triplet::new(i, i, d)),
    );
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(m, m, &triplets)
        .map_err(|e| Error::Internal(format!("spring system: {e:?}")))?;
    drop(triplets);
    let llt = a
        .sp_cholesky(Side::Lower)
        .map_err(|e| Error::Internal(format!("spring system not positive definite: {e:?}")))?;
    let mut x = Mat::<f64>::from_fn(m, 2, |i, c| rhs[i][c]);
    llt.solve_in_place(x.as_mut());
    let store = |uv: &mut [[f64; 2]], x: &Mat<f64>| -> f64 {
        let mut moved: f64 = 0.0;
        for (i, s) in slot.iter().enumerate() {
            if *s != usize::MAX {
                let new = [x[(*s, 0)], x[(*s, 1)]];
                moved = moved.max((new[0] - uv[i][0]).abs().max((new[1] - uv[i][1]).abs()));
                uv[i] = new;
            }
        }
        moved
    };
    store(&mut uv, &x);
    if alpha == 0.0 {
        return Ok((uv, unreachable, 0));
    }
    let extent = proj
        .iter()
        .fold([f64::MAX, f64::MIN, f64::MAX, f64::MIN], |b, p| {
            [
                b[0].min(p[0]),
                b[1].max(p[0]),
                b[2].min(p[1]),
                b[3].max(p[1]),
            ]
        });
    let tol = CONVERGED * (extent[1] - extent[0]).max(extent[3] - extent[2]);
    let mut iterations = 0;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        for s in 0..m {
            x[(s, 0)] = rhs[s][0];
            x[(s, 1)] = rhs[s][1];
        }
        for (e, &(k, rest)) in graph.edges.iter().zip(&springs) {
            let (i, j) = (e[0] as usize, e[1] as usize);
            let d = [uv[i][0] - uv[j][0], uv[i][1] - uv[j][1]];
            let len = d[0].hypot(d[1]);
            if len == 0.0 {
                continue;
            }
            let f = k * rest / len;
            if slot[i] != usize::MAX {
                x[(slot[i], 0)] += f * d[0];
                x[(slot[i], 1)] += f * d[1];
            }
            if slot[j] != usize::MAX {
                x[(slot[j], 0)] -= f * d[0];
                x[(slot[j], 1)] -= f * d[1];
            }
        }
        llt.solve_in_place(x.as_mut());
        if store(&mut uv, &x) < tol {
            break;
        }
    }
    Ok((uv, unreachable, iterations))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn src() -> &'static Path {
        Path::new("patch.ply")
    }

    /// Two triangles per cell of a `w × h` vertex grid, counter-clockwise seen from +z.
    fn grid_triangles(w: u32, h: u32) -> Vec<[u32; 3]> {
        let mut t = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let a = y * w + x;
                t.push([a, a + 1, a + w + 1]);
                t.push([a, a + w + 1, a + w]);
            }
        }
        t
    }

    /// A rigid motion of the plane z = 0 into a tilted plane far from the origin.
    fn place(p: [f64; 2]) -> [f64; 3] {
        let (c, s) = (0.6f64, 0.8f64);
        [
            1000.0 + 0.28 * p[0] - 0.96 * c * p[1],
            -50.0 + 0.96 * p[0] + 0.28 * c * p[1],
            7.0 + s * p[1],
        ]
    }

    fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
        let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        dot(d, d).sqrt()
    }

    fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    /// Largest difference between parameter and world distances over all pairs.
    fn rigid_error(pts: &[[f64; 3]], uv: &[[f64; 2]]) -> f64 {
        let mut worst: f64 = 0.0;
        for i in 0..pts.len() {
            for j in i + 1..pts.len() {
                worst = worst.max((dist3(pts[i], pts[j]) - dist2(uv[i], uv[j])).abs());
            }
        }
        worst
    }

    #[test]
    fn planar_grid_maps_to_itself_under_chord_and_real_spring() {
        let (w, h) = (13u32, 9u32);
        let pts: Vec<[f64; 3]> = (0..w * h)
            .map(|i| place([(i % w) as f64 * 0.5, (i / w) as f64 * 0.5]))
            .collect();
        let g = Graph::from_triangles(src(), pts.len(), &grid_triangles(w, h)).unwrap();
        for m in [Method::chord(), Method::real_spring(), Method::uniform()] {
            let p = parameterise(&pts, &g, m).unwrap();
            assert!(rigid_error(&pts, &p.uv) < 1e-9, "{m:?}");
            assert!((p.size[0] - 6.0).abs() < 1e-9 && (p.size[1] - 4.0).abs() < 1e-9);
            assert_eq!((p.folds, p.unreachable), (0, 0));
            // The frame maps parameters back onto the points.
            for (q, uv) in pts.iter().zip(&p.uv) {
                let back =
                    [0, 1, 2].map(|k| p.origin[k] + uv[0] * p.axes[0][k] + uv[1] * p.axes[1][k]);
                assert!(dist3(*q, back) < 1e-9);
            }
            let n = cross(p.axes[0], p.axes[1]);
            assert!(dist3(n, p.axes[2]) < 1e-12);
        }
    }

    /// A paraboloid cap z = x² + y² over a disc of radius 1: the grid points inside it,
    /// triangles with all corners inside.
    fn paraboloid(n: i32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut id = std::collections::BTreeMap::new();
        let mut pts = Vec::new();
        for y in -n..=n {
            for x in -n..=n {
                let (u, v) = (x as f64 / n as f64, y as f64 / n as f64);
                if u * u + v * v <= 1.0 {
                    id.insert((x, y), pts.len() as u32);
                    pts.push([u, v, u * u + v * v]);
                }
            }
        }
        let mut tris = Vec::new();
        for y in -n..n {
            for x in -n..n {
                let c =
                    [(x, y), (x + 1, y), (x + 1, y + 1), (x, y + 1)].map(|k| id.get(&k).copied());
                if let [Some(a), Some(b), Some(c), Some(d)] = c {
                    tris.push([a, b, c]);
                    tris.push([a, c, d]);
                }
            }
        }
        (pts, tris)
    }

    #[test]
    fn paraboloid_cap_has_no_fold_overs() {
        let (pts, tris) = paraboloid(15);
        let g = Graph::from_triangles(src(), pts.len(), &tris).unwrap();
        for m in [
            Method::uniform(),
            Method::chord(),
            Method::real_spring(),
            Method::Project,
        ] {
            let p = parameterise(&pts, &g, m).unwrap();
            assert_eq!(p.folds, 0, "{m:?}");
            assert!(p.uv.iter().all(|q| (0.0..=p.size[0]).contains(&q[0]) && (0.0..=p.size[1]).contains(&q[1])));
            // The normal is the paraboloid's axis (sign rule: positive largest component).
            assert!(dist3(p.axes[2], [0.0, 0.0, 1.0]) < 1e-9, "{:?}", p.axes[2]);
        }
        let p = parameterise(&pts, &g, Method::real_spring()).unwrap();
        assert!(
            p.iterations > 1 && p.iterations <= MAX_ITERATIONS,
            "{}",
            p.iterations
        );
    }

    #[test]
    fn fold_over_is_counted() {
        // A fan around vertex 4 whose interior vertex is pushed outside by Project.
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.5, 0.5, 0.0],
        ];
        let tris = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        let g = Graph::from_triangles(src(), 5, &tris).unwrap();
        assert_eq!(g.boundary, [true, true, true, true, false]);
        let p = parameterise(&pts, &g, Method::Project).unwrap();
        assert_eq!(p.folds, 1);
        assert_eq!(
            count_folds(
                &tris,
                &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]]
            ),
            0
        );
    }

    /// Spread of `log(parameter length / world length)` over the edges: 0 for an isometry.
    fn distortion(pts: &[[f64; 3]], g: &Graph, uv: &[[f64; 2]]) -> f64 {
        let logs: Vec<f64> = g
            .edges
            .iter()
            .map(|e| {
                let (i, j) = (e[0] as usize, e[1] as usize);
                (dist2(uv[i], uv[j]) / dist3(pts[i], pts[j])).ln()
            })
            .collect();
        let mean = logs.iter().sum::<f64>() / logs.len() as f64;
        (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / logs.len() as f64).sqrt()
    }

    #[test]
    fn chord_and_real_spring_keep_distance_ratios_better_than_uniform() {
        // A gently curved sheet sampled densely on one side (x = t³ grading).
        let (w, h) = (25u32, 12u32);
        let pts: Vec<[f64; 3]> = (0..w * h)
            .map(|i| {
                let t = (i % w) as f64 / (w - 1) as f64;
                let x = 4.0 * t * t * t + 0.2 * t;
                let y = (i / w) as f64 * 0.3;
                [x, y, 0.1 * (x * 0.5).sin()]
            })
            .collect();
        let g = Graph::from_triangles(src(), pts.len(), &grid_triangles(w, h)).unwrap();
        let d = |m| distortion(&pts, &g, &parameterise(&pts, &g, m).unwrap().uv);
        let (uni, chord, real) = (
            d(Method::uniform()),
            d(Method::chord()),
            d(Method::real_spring()),
        );
        eprintln!(
            "edge length distortion: uniform {uni:.4}, chord {chord:.4}, real spring {real:.4}"
        );
        assert!(chord < 0.5 * uni, "{chord} {uni}");
        assert!(real < 0.5 * uni, "{real} {uni}");
    }

    #[test]
    fn closed_component_is_fixed_by_projection() {
        let (w, h) = (6u32, 5u32);
        let mut pts: Vec<[f64; 3]> = (0..w * h)
            .map(|i| [(i % w) as f64, (i / w) as f64, 0.0])
            .collect();
        let mut tris = grid_triangles(w, h);
        // A tetrahedron (closed) beside the grid, and an isolated point.
        let base = pts.len() as u32;
        pts.extend([
            [8.0, 1.0, 0.1],
            [9.0, 1.0, 0.1],
            [8.5, 2.0, 0.1],
            [8.5, 1.5, 0.6],
            [7.0, 3.0, 0.0],
        ]);
        let b = base;
        tris.extend([
            [b, b + 1, b + 2],
            [b, b + 3, b + 1],
            [b + 1, b + 3, b + 2],
            [b + 2, b + 3, b],
        ]);
        let mut g = Graph::from_triangles(src(), pts.len(), &tris).unwrap();
        let p = parameterise(&pts, &g, Method::chord()).unwrap();
        assert_eq!(p.unreachable, 5);
        let proj = parameterise(&pts, &g, Method::Project).unwrap();
        for i in base as usize..pts.len() {
            assert!(dist2(p.uv[i], proj.uv[i]) < 1e-9);
        }
        g.boundary.fill(false);
        let e = parameterise(&pts, &g, Method::chord())
            .unwrap_err()
            .to_string();
        assert!(e.contains("no boundary") && e.contains("--patches"), "{e}");
    }

    #[test]
    fn degenerate_input_is_an_error() {
        let line: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 2.0 * i as f64, 0.0]).collect();
        let g = Graph::from_triangles(src(), 10, &[[0, 1, 2]]).unwrap();
        let e = parameterise(&line, &g, Method::Project)
            .unwrap_err()
            .to_string();
        assert!(e.contains("one line"), "{e}");
        assert!(parameterise(&line[..9], &g, Method::Project).is_err());
        let mut bad = line.clone();
        bad[4][2] = f64::INFINITY;
        assert!(parameterise(&bad, &g, Method::Project).is_err());
        let m = Method::Spring { alpha: 1.0, r: 1.0 };
        let mut ok = line.clone();
        ok[5][2] = 1.0;
        assert!(parameterise(&ok, &g, m).is_err());
    }

    #[test]
    fn knn_chord_is_deterministic_and_fold_free_on_a_height_field() {
        let pts: Vec<[f64; 3]> = (0..2000u64)
            .map(|i| {
                let h = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
                let x = (h >> 11) as f64 / (1u64 << 53) as f64;
                let y =
                    ((h.wrapping_mul(0xBF58_476D_1CE4_E5B9)) >> 11) as f64 / (1u64 << 53) as f64;
                [x * 2.0, y, 0.2 * (3.0 * x).sin() * y]
            })
            .collect();
        let g = Graph::from_knn(src(), &pts, super::super::graph::DEFAULT_K).unwrap();
        let a = parameterise(&pts, &g, Method::chord()).unwrap();
        let b = parameterise(&pts, &g, Method::chord()).unwrap();
        assert_eq!(a, b);
        assert!(
            (a.size[0] - 2.0).abs() < 0.1 && (a.size[1] - 1.0).abs() < 0.1,
            "{:?}",
            a.size
        );
    }

    /// The bunny's front scan, triangulated from its range grid: a disc with holes and loose
    /// pixels, boundary not convex, so fold-overs are possible but must stay rare.
    #[test]
    fn bunny_range_scan_parameterises() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bunny/bun000.ply");
        if !p.is_file() {
            eprintln!("skipped: {} not found", p.display());
            return;
        }
        let m = scanflow_formats::mesh_read::read_scan_mesh(&p).unwrap();
        let g = Graph::from_triangles(&p, m.vertices.len(), &m.triangles).unwrap();
        // Measured: uniform 49 folds, chord 30, real spring 275 (not converged after 100
        // steps, 12 s in the test profile, so left out here); 11 loose pixels unreachable.
        let method = Method::chord();
        let q = parameterise(&m.vertices, &g, method).unwrap();
        eprintln!(
            "bun000 {method:?}: {} folds of {} triangles, {} unreachable, {} iterations, size {:?}, {} non-manifold edges",
            q.folds,
            m.triangles.len(),
            q.unreachable,
            q.iterations,
            q.size,
            g.non_manifold_edges
        );
        assert!(
            q.folds <= 30 && q.unreachable == 11,
            "{} {}",
            q.folds,
            q.unreachable
        );
    }

    /// 100K scattered points: kNN graph and chord parameterisation, timed.
    /// `cargo test --release --lib spline::param -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn speed_100k_knn_chord() {
        let n = 100_000u64;
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let h = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
                let x = (h >> 11) as f64 / (1u64 << 53) as f64;
                let y =
                    ((h.wrapping_mul(0xBF58_476D_1CE4_E5B9)) >> 11) as f64 / (1u64 << 53) as f64;
                [x * 100.0, y * 100.0, 5.0 * (0.1 * x * 100.0).sin() * y]
            })
            .collect();
        let t = std::time::Instant::now();
        let g = Graph::from_knn(src(), &pts, super::super::graph::DEFAULT_K).unwrap();
        let tg = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let p = parameterise(&pts, &g, Method::chord()).unwrap();
        let tp = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let r = parameterise(&pts, &g, Method::real_spring()).unwrap();
        let tr = t.elapsed().as_secs_f64();
        eprintln!(
            "100K points: kNN graph {tg:.3} s ({} edges, {} boundary), chord {tp:.3} s, real spring {tr:.3} s ({} iterations), size {:?}",
            g.edges.len(),
            g.boundary.iter().filter(|&&b| b).count(),
            r.iterations,
            p.size
        );
    }
}
