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

use super::frame::{Frame, pca_frame};
use super::graph::Graph;
use crate::error::{Error, Result, Setting};
use crate::geom::rect::min_area_rect;
use crate::geom::vec::{cross, dot};

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
        return Err(Error::Usage(format!(
            "the patch's graph has no boundary vertex: a closed surface is not a disc; use \
             {} to fit it in patches",
            Setting::Patches
        )));
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
mod tests;
