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

use crate::mesh::HexMesh;
use crate::quality::{HEX_EDGES, hex_scaled_jacobian};
use crate::types::Aabb;
use crate::untangle::{Freedom, UntangleParams, UntangleReport, untangle_hexes};
use nalgebra::{Matrix3, Vector3};
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

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    a.map(|x| x * s)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

/// The unit cube's corners in VTK order, centred at the origin.
const CUBE: [[f64; 3]; 8] = [
    [-0.5, -0.5, -0.5],
    [0.5, -0.5, -0.5],
    [0.5, 0.5, -0.5],
    [-0.5, 0.5, -0.5],
    [-0.5, -0.5, 0.5],
    [0.5, -0.5, 0.5],
    [0.5, 0.5, 0.5],
    [-0.5, 0.5, 0.5],
];

/// `Σ |P_i|²` over [`CUBE`].
const CUBE_NORM2: f64 = 6.0;

/// The corners of the similarity image of the unit cube closest to `x` (module docs, step 1).
pub fn ideal_cube(x: &[[f64; 3]; 8]) -> [[f64; 3]; 8] {
    let mut mean = [0.0; 3];
    for p in x {
        mean = add(mean, *p);
    }
    mean = scale(mean, 1.0 / 8.0);
    let mut h = Matrix3::<f64>::zeros();
    let mut spread = 0.0;
    for (p, c) in x.iter().zip(CUBE.iter()) {
        let a = sub(*p, mean);
        spread += dot(a, a);
        h += Vector3::from(a) * Vector3::from(*c).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return *x;
    };
    let sigma = svd.singular_values;
    let mut d = Matrix3::<f64>::identity();
    let flip = (u * v_t).determinant() < 0.0;
    let smallest = (0..3)
        .min_by(|&a, &b| sigma[a].total_cmp(&sigma[b]))
        .unwrap_or(2);
    if flip {
        d[(smallest, smallest)] = -1.0;
    }
    let r = u * d * v_t;
    let mut s = (0..3).map(|k| sigma[k] * d[(k, k)]).sum::<f64>() / CUBE_NORM2;
    if s.is_nan() || s <= 0.0 {
        s = (spread / CUBE_NORM2).sqrt();
    }
    CUBE.map(|c| {
        let y = r * Vector3::from(c) * s;
        [y[0] + mean[0], y[1] + mean[1], y[2] + mean[2]]
    })
}

/// The closest point to `p` on triangle `a b c` (Ericson's region test).
pub fn closest_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return add(a, scale(ab, v));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return add(a, scale(ac, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return add(b, scale(sub(c, b), w));
    }
    let denom = va + vb + vc;
    let out = add(a, add(scale(ab, vb / denom), scale(ac, vc / denom)));
    if out.iter().all(|x| x.is_finite()) {
        out
    } else {
        // A degenerate triangle: its nearest corner.
        [a, b, c]
            .into_iter()
            .min_by(|x, y| dist2(*x, p).total_cmp(&dist2(*y, p)))
            .unwrap_or(a)
    }
}

/// A node of [`Bvh`]: a box and either two children (`count == 0`, children at `first` and
/// `first + 1`) or a leaf's triangles `order[first..first + count]`.
#[derive(Clone, Copy, Debug)]
struct BvhNode {
    lo: [f64; 3],
    hi: [f64; 3],
    first: u32,
    count: u32,
}

/// A bounding-volume hierarchy over a triangle soup for closest-point queries.
#[derive(Clone, Debug)]
pub struct Bvh {
    tris: Vec<[[f64; 3]; 3]>,
    order: Vec<u32>,
    nodes: Vec<BvhNode>,
}

const LEAF_SIZE: usize = 4;

impl Bvh {
    /// Builds the hierarchy of the triangles `tris` over `verts`.
    ///
    /// # Panics
    /// If a triangle names a vertex beyond `verts`.
    pub fn new(verts: &[[f64; 3]], tris: &[[u32; 3]]) -> Bvh {
        let tris: Vec<[[f64; 3]; 3]> = tris.iter().map(|t| t.map(|v| verts[v as usize])).collect();
        let centroid: Vec<[f64; 3]> = tris
            .iter()
            .map(|t| scale(add(add(t[0], t[1]), t[2]), 1.0 / 3.0))
            .collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = Vec::new();
        if tris.is_empty() {
            return Bvh { tris, order, nodes };
        }
        nodes.push(BvhNode {
            lo: [0.0; 3],
            hi: [0.0; 3],
            first: 0,
            count: 0,
        });
        // (node, start, end) still to fill in.
        let mut todo = vec![(0usize, 0usize, tris.len())];
        while let Some((node, start, end)) = todo.pop() {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            let mut clo = [f64::INFINITY; 3];
            let mut chi = [f64::NEG_INFINITY; 3];
            for &t in &order[start..end] {
                for p in &tris[t as usize] {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                let c = centroid[t as usize];
                for k in 0..3 {
                    clo[k] = clo[k].min(c[k]);
                    chi[k] = chi[k].max(c[k]);
                }
            }
            nodes[node].lo = lo;
            nodes[node].hi = hi;
            if end - start <= LEAF_SIZE {
                nodes[node].first = start as u32;
                nodes[node].count = (end - start) as u32;
                continue;
            }
            let axis = (0..3)
                .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
                .unwrap_or(0);
            let mid = (start + end) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                centroid[a as usize][axis]
                    .total_cmp(&centroid[b as usize][axis])
                    .then(a.cmp(&b))
            });
            let left = nodes.len();
            for _ in 0..2 {
                nodes.push(BvhNode {
                    lo: [0.0; 3],
                    hi: [0.0; 3],
                    first: 0,
                    count: 0,
                });
            }
            nodes[node].first = left as u32;
            todo.push((left, start, mid));
            todo.push((left + 1, mid, end));
        }
        Bvh { tris, order, nodes }
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    fn box_dist2(n: &BvhNode, p: [f64; 3]) -> f64 {
        Aabb {
            min: n.lo,
            max: n.hi,
        }
        .dist2(p)
    }

    /// The closest point to `p` on the triangles and its squared distance; `None` without
    /// triangles. Ties go to the triangle met first in a fixed traversal order.
    pub fn closest(&self, p: [f64; 3]) -> Option<([f64; 3], f64)> {
        self.closest_where(p, |_| true)
    }

    /// As [`Bvh::closest`], over the triangles whose normal (from their vertex order) makes
    /// an acute angle with `n`: the near side of a thin part, not its far side nor a
    /// neighbouring part's face turned towards it. `None` when no triangle faces `n`.
    pub fn closest_facing(&self, p: [f64; 3], n: [f64; 3]) -> Option<([f64; 3], f64)> {
        self.closest_where(p, |[a, b, c]| dot(cross(sub(*b, *a), sub(*c, *a)), n) > 0.0)
    }

    fn closest_where(
        &self,
        p: [f64; 3],
        keep: impl Fn(&[[f64; 3]; 3]) -> bool,
    ) -> Option<([f64; 3], f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best = ([0.0; 3], f64::INFINITY);
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i];
            if Self::box_dist2(n, p) >= best.1 {
                continue;
            }
            if n.count > 0 {
                let (a, b) = (n.first as usize, (n.first + n.count) as usize);
                for &t in &self.order[a..b] {
                    if !keep(&self.tris[t as usize]) {
                        continue;
                    }
                    let [x, y, z] = self.tris[t as usize];
                    let q = closest_on_triangle(p, x, y, z);
                    let d = dist2(p, q);
                    if d < best.1 {
                        best = (q, d);
                    }
                }
            } else {
                let (l, r) = (n.first as usize, n.first as usize + 1);
                let (dl, dr) = (
                    Self::box_dist2(&self.nodes[l], p),
                    Self::box_dist2(&self.nodes[r], p),
                );
                // Nearer child on top of the stack.
                if dl <= dr {
                    stack.push(r);
                    stack.push(l);
                } else {
                    stack.push(l);
                    stack.push(r);
                }
            }
        }
        best.1.is_finite().then_some(best)
    }
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

fn corners(verts: &[[f64; 3]], h: &[u32; 8]) -> [[f64; 3]; 8] {
    h.map(|v| verts[v as usize])
}

/// Root-mean-square distance of the corners to their fitted cubes' (summed in hexahedron
/// order).
fn misfit(verts: &[[f64; 3]], hexes: &[[u32; 8]]) -> f64 {
    if hexes.is_empty() {
        return 0.0;
    }
    let per: Vec<f64> = hexes
        .par_iter()
        .map(|h| {
            let x = corners(verts, h);
            let y = ideal_cube(&x);
            (0..8).map(|i| dist2(x[i], y[i])).sum()
        })
        .collect();
    (per.iter().sum::<f64>() / (8 * hexes.len()) as f64).sqrt()
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

    // Vertex → (hexahedron, corner) incidences, CSR.
    let mut off = vec![0usize; nv + 1];
    for h in &hex.hexes {
        for &v in h {
            off[v as usize + 1] += 1;
        }
    }
    for v in 0..nv {
        off[v + 1] += off[v];
    }
    let mut inc = vec![(0u32, 0u8); off[nv]];
    let mut fill = off.clone();
    for (k, h) in hex.hexes.iter().enumerate() {
        for (c, &v) in h.iter().enumerate() {
            inc[fill[v as usize]] = (k as u32, c as u8);
            fill[v as usize] += 1;
        }
    }

    // Boundary quadrilaterals: faces of exactly one hexahedron.
    let normals = hex.boundary_normals();
    let bvh = Bvh::new(boundary_verts, boundary_tris);
    let cos_feature = params.feature_angle_deg.to_radians().cos();
    let kind: Vec<Kind> = (0..nv)
        .map(|v| {
            if off[v + 1] == off[v] {
                Kind::Fixed
            } else if normals[v].is_empty() {
                Kind::Interior
            } else if bvh.is_empty() {
                Kind::Fixed
            } else {
                let ns = &normals[v];
                let bent = (0..ns.len())
                    .any(|a| (a + 1..ns.len()).any(|b| dot(ns[a], ns[b]) < cos_feature));
                if bent { Kind::Fixed } else { Kind::Surface }
            }
        })
        .collect();
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

    let sj_of = |verts: &[[f64; 3]], k: usize| hex_scaled_jacobian(&corners(verts, &hex.hexes[k]));
    let mut sj: Vec<f64> = (0..nh)
        .into_par_iter()
        .map(|k| sj_of(&hex.verts, k))
        .collect();
    let (min0, mean0, bad0) = summary(&sj);
    report.min_sj_before = min0;
    report.mean_sj_before = mean0;
    report.inverted_before = bad0;

    let mut edge_sum = 0.0;
    for h in &hex.hexes {
        for [a, b] in HEX_EDGES {
            edge_sum += dist2(hex.verts[h[a] as usize], hex.verts[h[b] as usize]).sqrt();
        }
    }
    let mean_edge = if nh > 0 {
        edge_sum / (12 * nh) as f64
    } else {
        0.0
    };
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
        let mut next = hex.verts.clone();
        let moved: Vec<u32> = (0..nv as u32)
            .filter(|&v| proposal[v as usize].is_some())
            .collect();
        let mut dirty = Vec::new();
        epoch += 1;
        for &v in &moved {
            next[v as usize] = proposal[v as usize].expect("moved");
            for &(k, _) in &inc[off[v as usize]..off[v as usize + 1]] {
                if mark[k as usize] != epoch {
                    mark[k as usize] = epoch;
                    dirty.push(k);
                }
            }
        }
        let mut is_moved = vec![false; nv];
        for &v in &moved {
            is_moved[v as usize] = true;
        }
        let mut put_back = vec![false; nv];
        let mut sj_next = sj.clone();
        while !dirty.is_empty() {
            dirty.sort_unstable();
            let vals: Vec<f64> = dirty
                .par_iter()
                .map(|&k| sj_of(&next, k as usize))
                .collect();
            let mut worse = Vec::new();
            for (&k, &val) in dirty.iter().zip(vals.iter()) {
                sj_next[k as usize] = val;
                if val.is_nan() || val < sj[k as usize].min(tau) {
                    worse.push(k);
                }
            }
            epoch += 1;
            dirty.clear();
            for k in worse {
                for &v in &hex.hexes[k as usize] {
                    let vi = v as usize;
                    if is_moved[vi] && !put_back[vi] {
                        put_back[vi] = true;
                        next[vi] = hex.verts[vi];
                        for &(h, _) in &inc[off[vi]..off[vi + 1]] {
                            if mark[h as usize] != epoch {
                                mark[h as usize] = epoch;
                                dirty.push(h);
                            }
                        }
                    }
                }
            }
        }
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

    // 5: hexahedra still inverted are untangled: first with the boundary held, then with
    // the surface vertices sliding in their tangent planes and projected back onto the
    // surface; a round is kept only when it leaves fewer hexahedra inverted.
    for round in 0..UNTANGLE_ROUNDS {
        let inverted = summary(&sj).2;
        if inverted == 0 {
            break;
        }
        let freedom: Vec<Freedom> = (0..nv)
            .map(|v| match kind[v] {
                Kind::Interior => Freedom::Free,
                Kind::Fixed => Freedom::Fixed,
                Kind::Surface if round == 0 => Freedom::Fixed,
                Kind::Surface => {
                    let n = normals[v].iter().fold([0.0; 3], |a, &b| add(a, b));
                    let l = dot(n, n).sqrt();
                    if l > 0.0 {
                        Freedom::Plane(scale(n, 1.0 / l))
                    } else {
                        Freedom::Fixed
                    }
                }
            })
            .collect();
        let before = hex.verts.clone();
        let r = untangle_hexes(
            &mut hex.verts,
            &hex.hexes,
            &freedom,
            &UntangleParams::default(),
        );
        for v in 0..nv {
            if kind[v] == Kind::Surface
                && hex.verts[v] != before[v]
                && let Some(q) = project(v, hex.verts[v])
            {
                hex.verts[v] = q;
            }
        }
        let untangled: Vec<f64> = (0..nh)
            .into_par_iter()
            .map(|k| sj_of(&hex.verts, k))
            .collect();
        let worse = summary(&untangled).2 >= inverted;
        report.untangle = Some(r);
        if worse {
            hex.verts = before;
            break;
        }
        sj = untangled;
    }

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
pub(crate) mod tests {
    use super::*;
    use crate::extract::{extract, fixtures};
    use rand::{Rng, SeedableRng};

    /// The `n³` grid of cubes of side `1/n` on the unit box, vertex `(i, j, k)` at index
    /// `i + (n+1)(j + (n+1)k)`.
    pub(crate) fn grid(n: usize) -> HexMesh {
        let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
        let h = 1.0 / n as f64;
        let mut verts = Vec::new();
        for k in 0..=n {
            for j in 0..=n {
                for i in 0..=n {
                    verts.push([i as f64 * h, j as f64 * h, k as f64 * h]);
                }
            }
        }
        let mut hexes = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    hexes.push([
                        id(i, j, k),
                        id(i + 1, j, k),
                        id(i + 1, j + 1, k),
                        id(i, j + 1, k),
                        id(i, j, k + 1),
                        id(i + 1, j, k + 1),
                        id(i + 1, j + 1, k + 1),
                        id(i, j + 1, k + 1),
                    ]);
                }
            }
        }
        HexMesh { verts, hexes }
    }

    /// The unit box's surface, each face an `m × m` grid of squares split in two triangles.
    fn box_surface(m: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let (mut verts, mut tris) = (Vec::new(), Vec::new());
        for axis in 0..3 {
            for side in [0.0, 1.0] {
                let base = verts.len() as u32;
                for b in 0..=m {
                    for a in 0..=m {
                        let mut p = [0.0; 3];
                        p[axis] = side;
                        p[(axis + 1) % 3] = a as f64 / m as f64;
                        p[(axis + 2) % 3] = b as f64 / m as f64;
                        verts.push(p);
                    }
                }
                let id = |a: usize, b: usize| base + (a + (m + 1) * b) as u32;
                for b in 0..m {
                    for a in 0..m {
                        tris.push([id(a, b), id(a + 1, b), id(a + 1, b + 1)]);
                        tris.push([id(a, b), id(a + 1, b + 1), id(a, b + 1)]);
                    }
                }
            }
        }
        (verts, tris)
    }

    /// Distance from `p` to the triangles, by brute force.
    fn brute_distance(p: [f64; 3], verts: &[[f64; 3]], tris: &[[u32; 3]]) -> f64 {
        tris.iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| verts[v as usize]);
                dist2(p, closest_on_triangle(p, a, b, c)).sqrt()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// A grid with interior vertices jittered in space and face vertices within their face.
    fn jittered(n: usize, amount: f64, seed: u64) -> HexMesh {
        let mut m = grid(n);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let h = 1.0 / n as f64;
        for p in m.verts.iter_mut() {
            let on = |c: f64| c.abs() < 1e-12 || (c - 1.0).abs() < 1e-12;
            let bound = p.iter().filter(|&&c| on(c)).count();
            if bound <= 1 {
                for c in p.iter_mut() {
                    if !on(*c) {
                        *c += rng.random_range(-amount..amount) * h;
                    }
                }
            }
        }
        m
    }

    fn all_sj(m: &HexMesh) -> Vec<f64> {
        (0..m.hexes.len())
            .map(|k| hex_scaled_jacobian(&corners(&m.verts, &m.hexes[k])))
            .collect()
    }

    #[test]
    fn ideal_cube_of_a_rotated_scaled_cube_is_itself() {
        let (a, b) = (0.7f64, -0.4f64);
        let r = [
            [a.cos() * b.cos(), -a.sin(), a.cos() * b.sin()],
            [a.sin() * b.cos(), a.cos(), a.sin() * b.sin()],
            [-b.sin(), 0.0, b.cos()],
        ];
        let x = CUBE.map(|c| [0, 1, 2].map(|i| 2.5 * dot(r[i], c) + [1.0, -2.0, 0.5][i]));
        let y = ideal_cube(&x);
        for i in 0..8 {
            assert!(dist2(x[i], y[i]) < 1e-24);
        }
        // An inverted cube (mirrored) is fitted by a positively oriented one.
        let mirrored = x.map(|p| [-p[0], p[1], p[2]]);
        assert!(hex_scaled_jacobian(&mirrored) < 0.0);
        assert!(hex_scaled_jacobian(&ideal_cube(&mirrored)) > 0.99);
    }

    #[test]
    fn bvh_closest_point_matches_brute_force() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let verts: Vec<[f64; 3]> = (0..300)
            .map(|_| [0; 3].map(|_: i32| rng.random_range(-1.0..1.0)))
            .collect();
        let tris: Vec<[u32; 3]> = (0..200)
            .map(|_| [0; 3].map(|_: i32| rng.random_range(0..300u32)))
            .collect();
        let bvh = Bvh::new(&verts, &tris);
        for _ in 0..300 {
            let p = [0; 3].map(|_: i32| rng.random_range(-1.5..1.5));
            let (q, d2) = bvh.closest(p).unwrap();
            let want = brute_distance(p, &verts, &tris);
            assert!((d2.sqrt() - want).abs() < 1e-12, "{} vs {want}", d2.sqrt());
            assert!((dist2(p, q).sqrt() - want).abs() < 1e-12);
        }
        assert!(Bvh::new(&verts, &[]).closest([0.0; 3]).is_none());
    }

    #[test]
    fn a_vertex_in_a_thin_slab_keeps_to_its_side() {
        // A slab 0.1 thick (top at z = 0.1 facing up, bottom at z = 0 facing down) and a
        // vertex just below the middle: the nearest face is the bottom, but a vertex whose
        // quadrilaterals face up goes to the top.
        let verts = vec![
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, -1.0, 0.1],
            [1.0, -1.0, 0.1],
            [1.0, 1.0, 0.1],
        ];
        let tris = vec![[0, 2, 1], [3, 4, 5]];
        let bvh = Bvh::new(&verts, &tris);
        let p = [0.5, 0.0, 0.04];
        let (q, _) = bvh.closest(p).unwrap();
        assert!(q[2].abs() < 1e-12, "{q:?}");
        let (q, d2) = bvh.closest_facing(p, [0.0, 0.0, 1.0]).unwrap();
        assert!(
            (q[2] - 0.1).abs() < 1e-12 && (d2 - 0.06 * 0.06).abs() < 1e-12,
            "{q:?}"
        );
        let (q, _) = bvh.closest_facing(p, [0.0, 0.0, -1.0]).unwrap();
        assert!(q[2].abs() < 1e-12, "{q:?}");
        // Nothing faces sideways.
        assert!(bvh.closest_facing(p, [1.0, 0.0, 0.0]).is_none());
    }

    #[test]
    fn a_regular_grid_is_a_fixed_point() {
        let mut m = grid(3);
        let before = m.clone();
        let (bv, bt) = box_surface(2);
        let rep = relax(&mut m, &bv, &bt, &RelaxParams::default());
        assert!(rep.converged && rep.iterations == 1, "{rep:?}");
        assert_eq!(m, before);
        assert!((rep.min_sj_after - 1.0).abs() < 1e-12);
    }

    #[test]
    fn jittered_grid_relaxes_with_boundary_on_the_surface() {
        let n = 4;
        let mut m = jittered(n, 0.3, 17);
        let start = m.clone();
        let sj0 = all_sj(&m);
        assert!(sj0.iter().all(|&s| s > 0.0));
        let (bv, bt) = box_surface(3);
        let params = RelaxParams {
            iterations: 60,
            ..RelaxParams::default()
        };
        let rep = relax(&mut m, &bv, &bt, &params);
        let sj1 = all_sj(&m);
        assert!(rep.min_sj_after > rep.min_sj_before + 0.1, "{rep:?}");
        assert!(rep.mean_sj_after > rep.mean_sj_before, "{rep:?}");
        assert!(
            rep.cube_misfit_after < 0.5 * rep.cube_misfit_before,
            "{rep:?}"
        );
        assert_eq!(rep.inverted_after, 0);
        assert!(sj1.iter().all(|&s| s > 0.0));
        let min1 = sj1.iter().copied().fold(f64::INFINITY, f64::min);
        assert_eq!(min1, rep.min_sj_after);
        // (n-1)² face vertices per face slide on the surface; edges and corners stay.
        assert_eq!(rep.surface_vertices, 6 * (n - 1) * (n - 1));
        assert_eq!(rep.interior_vertices, (n - 1).pow(3));
        let diag = 3f64.sqrt();
        for (v, p) in m.verts.iter().enumerate() {
            let on = p.iter().any(|&c| c.abs() < 1e-6 || (c - 1.0).abs() < 1e-6);
            let was_on = start.verts[v]
                .iter()
                .any(|&c| c.abs() < 1e-12 || (c - 1.0).abs() < 1e-12);
            assert_eq!(on, was_on, "vertex {v} at {p:?}");
            if was_on {
                assert!(brute_distance(*p, &bv, &bt) <= 1e-9 * diag);
            }
        }
        assert!(rep.max_surface_distance <= 1e-9 * diag);
        // Deterministic, for any thread count.
        let again = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| {
                let mut m2 = start.clone();
                let r2 = relax(&mut m2, &bv, &bt, &params);
                (m2, r2)
            });
        assert_eq!(again.0, m);
        assert_eq!(again.1, rep);
    }

    #[test]
    fn an_inverted_hex_does_not_spread() {
        let mut m = grid(3);
        // Push interior vertex (1, 1, 1) through its neighbours.
        let v = 1 + 4 * (1 + 4);
        m.verts[v] = [0.58, 0.55, 0.6];
        let sj0 = all_sj(&m);
        let bad0 = sj0.iter().filter(|&&s| s <= 0.0).count();
        assert!(bad0 > 0);
        let (bv, bt) = box_surface(1);
        let rep = relax(&mut m, &bv, &bt, &RelaxParams::default());
        assert_eq!(rep.inverted_before, bad0);
        assert!(rep.inverted_after <= bad0, "{rep:?}");
        // Here the fitted cubes pull the pushed vertex back: the mesh untangles.
        assert_eq!(rep.inverted_after, 0, "{rep:?}");
        assert!(rep.min_sj_after > 0.9, "{rep:?}");
        assert!(rep.min_sj_after >= rep.min_sj_before);
        // No hex that was valid is inverted now.
        let sj1 = all_sj(&m);
        for k in 0..sj0.len() {
            if sj0[k] > 0.0 {
                assert!(sj1[k] > 0.0, "hex {k}: {} -> {}", sj0[k], sj1[k]);
            }
        }
    }

    #[test]
    fn extracted_singular_prism_relaxes_on_its_surface() {
        let (mesh, map) = fixtures::singular_prism(3, 2.0, 2);
        let topo = crate::topology::check_tets(&mesh).unwrap();
        let tris = topo.boundary_triangles(&mesh);
        let (mut hex, _) = extract(&mesh, &map).unwrap();
        let rep = relax(&mut hex, &mesh.verts, &tris, &RelaxParams::default());
        // The smallest scaled Jacobian, sin 60° at the prism's fixed 60° edges, cannot
        // improve; the hexes get closer to cubes without any getting worse than it.
        assert!(rep.min_sj_after >= rep.min_sj_before, "{rep:?}");
        assert!(
            rep.cube_misfit_after < 0.95 * rep.cube_misfit_before,
            "{rep:?}"
        );
        assert_eq!(rep.inverted_after, 0);
        assert!(rep.surface_vertices > 0);
        assert!(rep.max_surface_distance <= 1e-9);
    }
}
