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

use crate::geom::vec::{add, cross, dot, scale, sub};
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

/// Vertex → (hexahedron, corner) incidences, CSR: vertex `v`'s are
/// `inc[off[v]..off[v + 1]]`, in hexahedron order.
fn incidences(hex: &HexMesh) -> (Vec<usize>, Vec<(u32, u8)>) {
    let nv = hex.verts.len();
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
    (off, inc)
}

/// Each vertex's kind: unused and feature vertices (and all boundary vertices when there
/// is no surface to project onto) are fixed.
fn vertex_kinds(
    off: &[usize],
    normals: &[Vec<[f64; 3]>],
    bvh: &Bvh,
    params: &RelaxParams,
) -> Vec<Kind> {
    let nv = off.len() - 1;
    let cos_feature = params.feature_angle_deg.to_radians().cos();
    (0..nv)
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
        .collect()
}

/// The scaled Jacobian of hexahedron `k` at the positions `verts`.
fn sj_of(hexes: &[[u32; 8]], verts: &[[f64; 3]], k: usize) -> f64 {
    hex_scaled_jacobian(&corners(verts, &hexes[k]))
}

/// The mean edge length, summed hexahedron by hexahedron (shared edges counted once per
/// hexahedron); 0 without hexahedra.
fn mean_edge_length(hex: &HexMesh) -> f64 {
    let nh = hex.hexes.len();
    let mut edge_sum = 0.0;
    for h in &hex.hexes {
        for [a, b] in HEX_EDGES {
            edge_sum += dist2(hex.verts[h[a] as usize], hex.verts[h[b] as usize]).sqrt();
        }
    }
    if nh > 0 {
        edge_sum / (12 * nh) as f64
    } else {
        0.0
    }
}

/// Step 4 of the module docs: applies the proposals, then puts back the moves that make a
/// hexahedron worse than its own scaled Jacobian or `tau` (whichever is lower), until none
/// does. `(off, inc)` are the incidences; `(mark, epoch)` the per-hexahedron visit marks.
/// Returns the new positions, their scaled Jacobians, the moved vertices in order and which
/// of them were put back.
fn apply_moves(
    hex: &HexMesh,
    proposal: &[Option<[f64; 3]>],
    (off, inc): (&[usize], &[(u32, u8)]),
    sj: &[f64],
    tau: f64,
    (mark, epoch): (&mut [u32], &mut u32),
) -> (Vec<[f64; 3]>, Vec<f64>, Vec<u32>, Vec<bool>) {
    let nv = hex.verts.len();
    let mut next = hex.verts.clone();
    let moved: Vec<u32> = (0..nv as u32)
        .filter(|&v| proposal[v as usize].is_some())
        .collect();
    let mut dirty = Vec::new();
    *epoch += 1;
    for &v in &moved {
        next[v as usize] = proposal[v as usize].expect("moved");
        for &(k, _) in &inc[off[v as usize]..off[v as usize + 1]] {
            if mark[k as usize] != *epoch {
                mark[k as usize] = *epoch;
                dirty.push(k);
            }
        }
    }
    let mut is_moved = vec![false; nv];
    for &v in &moved {
        is_moved[v as usize] = true;
    }
    let mut put_back = vec![false; nv];
    let mut sj_next = sj.to_vec();
    while !dirty.is_empty() {
        dirty.sort_unstable();
        let vals: Vec<f64> = dirty
            .par_iter()
            .map(|&k| sj_of(&hex.hexes, &next, k as usize))
            .collect();
        let mut worse = Vec::new();
        for (&k, &val) in dirty.iter().zip(vals.iter()) {
            sj_next[k as usize] = val;
            if val.is_nan() || val < sj[k as usize].min(tau) {
                worse.push(k);
            }
        }
        *epoch += 1;
        dirty.clear();
        for k in worse {
            for &v in &hex.hexes[k as usize] {
                let vi = v as usize;
                if is_moved[vi] && !put_back[vi] {
                    put_back[vi] = true;
                    next[vi] = hex.verts[vi];
                    for &(h, _) in &inc[off[vi]..off[vi + 1]] {
                        if mark[h as usize] != *epoch {
                            mark[h as usize] = *epoch;
                            dirty.push(h);
                        }
                    }
                }
            }
        }
    }
    (next, sj_next, moved, put_back)
}

/// Step 5 of the module docs: hexahedra still inverted are untangled: first with the
/// boundary held, then with the surface vertices sliding in their tangent planes and
/// projected back onto the surface; a round is kept only when it leaves fewer hexahedra
/// inverted. `sj` holds the scaled Jacobians at the current positions and is kept up to date.
fn untangle_rounds(
    hex: &mut HexMesh,
    kind: &[Kind],
    normals: &[Vec<[f64; 3]>],
    project: &impl Fn(usize, [f64; 3]) -> Option<[f64; 3]>,
    sj: &mut Vec<f64>,
    report: &mut RelaxReport,
) {
    let (nv, nh) = (hex.verts.len(), hex.hexes.len());
    for round in 0..UNTANGLE_ROUNDS {
        let inverted = summary(sj).2;
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
            .map(|k| sj_of(&hex.hexes, &hex.verts, k))
            .collect();
        let worse = summary(&untangled).2 >= inverted;
        report.untangle = Some(r);
        if worse {
            hex.verts = before;
            break;
        }
        *sj = untangled;
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
