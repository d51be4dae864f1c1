//! Element quality of hexahedral (and tetrahedral) meshes, with the definitions of the Verdict
//! library: C. Stimpson, C. Ernst, P. Knupp, P. Pébay, D. Thompson, "The Verdict Geometric
//! Quality Library", Sandia report SAND2007-1751 (2007), and its source (`V_HexMetric.cpp`,
//! `V_TetMetric.cpp`). Corners are in VTK order (see [`crate::mesh`]); for the unit cube
//! `v0 = (0,0,0)`, `v1 = (1,0,0)`, `v2 = (1,1,0)`, `v3 = (0,1,0)` and `v4 … v7` above them.
//!
//! # Hexahedron
//!
//! * **Scaled Jacobian** ([`hex_scaled_jacobian`], Verdict's `hex_scaled_jacobian`): the
//!   minimum of nine normalised Jacobian determinants, `det(x̂, ŷ, ẑ)` with `x̂ = x / |x|`.
//!   At each corner `i` the three edge vectors leaving it, in the order that makes the unit
//!   cube's determinant +1 ([`HEX_CORNER_EDGES`]: corner 0 uses `v1 − v0`, `v3 − v0`,
//!   `v4 − v0`; corner 1 uses `v2 − v1`, `v0 − v1`, `v5 − v1`; …); at the centre the principal
//!   axes `X1 = (v1 − v0) + (v2 − v3) + (v5 − v4) + (v6 − v7)`,
//!   `X2 = (v2 − v0) + (v3 − v1) + (v6 − v4) + (v7 − v5)`,
//!   `X3 = (v4 − v0) + (v5 − v1) + (v6 − v2) + (v7 − v3)` (Verdict's `calc_hex_efg`). The
//!   value lies in `[−1, 1]` (Hadamard's inequality; no clamping is needed), 1 for a cube or
//!   any cuboid, `cos φ` for a parallelepiped sheared by `φ`, ≤ 0 for an inverted element.
//!   *Deviation*: where one of the three vectors has zero length Verdict returns
//!   `VERDICT_DBL_MAX` for the whole element; here that determinant counts as 0, so a
//!   collapsed hexahedron scores 0.
//! * **Volume** ([`hex_volume`], Verdict's `hex_volume` for 8 nodes): the hexahedron is split
//!   into 24 tetrahedra, each joining an edge of a face to the face's centroid and the
//!   element's centroid, and their signed volumes `det(·) / 6` are summed. This equals the
//!   exact volume of the trilinear element, `∫_{[0,1]³} det J(u, v, w) du dv dw`, which the
//!   tests check against 2×2×2 Gauss quadrature (exact for `det J`, of degree 2 in each
//!   parameter).
//! * **Dihedral angles** ([`hex_dihedral_angles`]): along each of the 12 edges
//!   ([`HEX_EDGES`]), the interior angle between its two faces,
//!   `θ = 180° − ∠(n₁, n₂)`, `∠` computed as `atan2(|n₁ × n₂|, n₁ · n₂)`, where `nᵢ` is the
//!   outward normal of face `i`'s bilinear patch at the edge's midpoint: for a face
//!   `q0 q1 q2 q3` (counter-clockwise seen from outside) and its edge `q0 q1`,
//!   `n = (q1 − q0) × ((q3 − q0) + (q2 − q1))`, i.e. `∂p/∂s × ∂p/∂t` at `(s, t) = (½, 0)`.
//!   90° for every edge of a cube. The angle is unsigned (`[0°, 180°]`); use the scaled
//!   Jacobian to detect inversion. A face collapsed at the edge (zero normal) counts as flat
//!   (180°). [`HexQuality`] keeps their mean, population standard deviation, min and max.
//! * **Edge ratio** ([`hex_edge_ratio`], Verdict's `hex_edge_ratio`): longest over shortest
//!   of the 12 edge lengths; `+∞` when an edge has zero length (Verdict: `VERDICT_DBL_MAX`).
//!
//! # Tetrahedron
//!
//! * **Scaled Jacobian** ([`tet_scaled_jacobian`], Verdict's `tet_scaled_jacobian`):
//!   `√2 · det(v1 − v0, v2 − v0, v3 − v0) / L`, where `L` is the largest, over the four
//!   corners, of the product of the lengths of the three edges at that corner (and at least
//!   `|det|`). `√2` makes the regular tetrahedron score 1; the corner of a cube scores
//!   `1/√2`. *Deviation*: `L = 0` gives 0 (Verdict: `VERDICT_DBL_MAX`).
//! * **Dihedral angles** ([`tet_dihedral_angles`]): along each edge ([`TET_EDGES`] order), the
//!   interior angle `180° − ∠(n₁, n₂)` between the outward normals of the two faces that
//!   contain it. 70.53° (`acos(1/3)`) for all six of a regular tetrahedron.
//!
//! # Mesh
//!
//! [`mesh_quality`] evaluates every hexahedron in parallel and folds the results in index
//! order, so the figures do not depend on the thread count; [`MeshQuality::table`] renders
//! them for a reader, and both structures serialise to JSON.

use crate::geom::vec::{add, cross, dot, norm, sub};
pub use crate::mesh::HEX_FACES;
use crate::mesh::{FACE_OPPOSITE, HexMesh};
use crate::topology::TET_EDGES;
use rayon::prelude::*;
use serde::Serialize;

/// The 12 edges of a hexahedron as corner pairs, in Verdict's order (`make_hex_edges`): the
/// bottom ring `01 12 23 30`, the top ring `45 56 67 74`, then the verticals `04 15 26 37`.
pub const HEX_EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [2, 3],
    [3, 0],
    [4, 5],
    [5, 6],
    [6, 7],
    [7, 4],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// For each corner `i`, `[i, p, q, r]`: the Jacobian at corner `i` is
/// `det(v_p − v_i, v_q − v_i, v_r − v_i)` (Verdict's order; +1 at every corner of the unit
/// cube).
pub const HEX_CORNER_EDGES: [[usize; 4]; 8] = [
    [0, 1, 3, 4],
    [1, 2, 0, 5],
    [2, 3, 1, 6],
    [3, 0, 2, 7],
    [4, 7, 5, 0],
    [5, 4, 6, 1],
    [6, 5, 7, 2],
    [7, 6, 4, 3],
];

/// Lower bounds of the scaled-Jacobian histogram bins after the first: the bins are
/// `SJ ≤ 0`, `0 < SJ < 0.2`, `0.2 ≤ SJ < 0.4`, `0.4 ≤ SJ < 0.6`, `0.6 ≤ SJ < 0.8`,
/// `0.8 ≤ SJ ≤ 1`.
pub const SJ_BIN_LOWER: [f64; 4] = [0.2, 0.4, 0.6, 0.8];

/// Labels of the six histogram bins of [`MeshQuality::sj_histogram`].
pub const SJ_BIN_LABELS: [&str; 6] = [
    "SJ <= 0",
    "0 < SJ < 0.2",
    "0.2 <= SJ < 0.4",
    "0.4 <= SJ < 0.6",
    "0.6 <= SJ < 0.8",
    "0.8 <= SJ <= 1",
];

/// How many of the worst hexahedra [`MeshQuality`] lists.
pub const WORST_COUNT: usize = 10;

/// For face `f` and its local edge `i` (`HEX_FACES[f][i]` to `HEX_FACES[f][i + 1]`), the
/// index into [`HEX_EDGES`].
const FACE_EDGE: [[usize; 4]; 6] = face_edges();

const fn face_edges() -> [[usize; 4]; 6] {
    let mut out = [[usize::MAX; 4]; 6];
    let mut f = 0;
    while f < 6 {
        let mut i = 0;
        while i < 4 {
            let a = HEX_FACES[f][i];
            let b = HEX_FACES[f][(i + 1) % 4];
            let mut e = 0;
            while e < 12 {
                let [p, q] = HEX_EDGES[e];
                if (p == a && q == b) || (p == b && q == a) {
                    out[f][i] = e;
                }
                e += 1;
            }
            i += 1;
        }
        f += 1;
    }
    out
}

fn det(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    dot(a, cross(b, c))
}

/// `det(x̂, ŷ, ẑ)` of the normalised vectors, 0 when one has zero length.
fn normalised_det(x: [f64; 3], y: [f64; 3], z: [f64; 3]) -> f64 {
    let (lx, ly, lz) = (norm(x), norm(y), norm(z));
    if lx <= f64::MIN_POSITIVE || ly <= f64::MIN_POSITIVE || lz <= f64::MIN_POSITIVE {
        return 0.0;
    }
    det(x.map(|v| v / lx), y.map(|v| v / ly), z.map(|v| v / lz))
}

/// Minimum that propagates NaN.
fn nan_min(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.min(b)
    }
}

/// The interior angle in degrees between two faces with outward normals `n1`, `n2`:
/// `180° − ∠(n1, n2)`.
fn interior_angle_deg(n1: [f64; 3], n2: [f64; 3]) -> f64 {
    180.0 - norm(cross(n1, n2)).atan2(dot(n1, n2)).to_degrees()
}

/// The principal axes `X1, X2, X3` of a hexahedron (Verdict's `calc_hex_efg(1..3)`).
fn principal_axes(c: &[[f64; 3]; 8]) -> [[f64; 3]; 3] {
    let comb = |plus: [usize; 4], minus: [usize; 4]| {
        let mut v = [0.0; 3];
        for k in 0..4 {
            v = add(v, sub(c[plus[k]], c[minus[k]]));
        }
        v
    };
    [
        comb([1, 2, 5, 6], [0, 3, 4, 7]),
        comb([2, 3, 6, 7], [0, 1, 4, 5]),
        comb([4, 5, 6, 7], [0, 1, 2, 3]),
    ]
}

/// The nine normalised Jacobian determinants of a hexahedron: the 8 corners
/// ([`HEX_CORNER_EDGES`]) then the centre (principal axes). See the module docs.
pub fn hex_jacobians(c: &[[f64; 3]; 8]) -> [f64; 9] {
    let mut out = [0.0; 9];
    for (i, &[o, p, q, r]) in HEX_CORNER_EDGES.iter().enumerate() {
        out[i] = normalised_det(sub(c[p], c[o]), sub(c[q], c[o]), sub(c[r], c[o]));
    }
    let [x1, x2, x3] = principal_axes(c);
    out[8] = normalised_det(x1, x2, x3);
    out
}

/// Verdict's hexahedral scaled Jacobian: the minimum of [`hex_jacobians`], in `[−1, 1]`;
/// 1 for a cube, ≤ 0 when inverted, 0 when collapsed. See the module docs.
pub fn hex_scaled_jacobian(c: &[[f64; 3]; 8]) -> f64 {
    hex_jacobians(c).into_iter().fold(f64::INFINITY, nan_min)
}

/// Verdict's hexahedral volume (signed): 24 tetrahedra from each face edge to the face
/// centroid and the element centroid; equal to the exact trilinear volume. See the module
/// docs.
pub fn hex_volume(c: &[[f64; 3]; 8]) -> f64 {
    let mut centre = [0.0; 3];
    for p in c {
        centre = add(centre, *p);
    }
    let centre = centre.map(|x| x / 8.0);
    let mut volume = 0.0;
    for face in &HEX_FACES {
        let mut fc = [0.0; 3];
        for &v in face {
            fc = add(fc, c[v]);
        }
        let fc = fc.map(|x| x / 4.0);
        let to_centre = sub(centre, fc);
        let side = face.map(|v| sub(centre, c[v]));
        for j in 0..4 {
            volume += det(to_centre, side[(j + 1) % 4], side[j]) / 6.0;
        }
    }
    volume
}

/// The 12 interior dihedral angles in degrees, one per edge of [`HEX_EDGES`], from the two
/// faces' bilinear-patch normals at the edge midpoint. See the module docs.
pub fn hex_dihedral_angles(c: &[[f64; 3]; 8]) -> [f64; 12] {
    let mut normals = [[[0.0; 3]; 2]; 12];
    let mut filled = [0usize; 12];
    for (f, face) in HEX_FACES.iter().enumerate() {
        for i in 0..4 {
            let q = [0, 1, 2, 3].map(|k| c[face[(i + k) % 4]]);
            let n = cross(sub(q[1], q[0]), add(sub(q[3], q[0]), sub(q[2], q[1])));
            let e = FACE_EDGE[f][i];
            normals[e][filled[e]] = n;
            filled[e] += 1;
        }
    }
    normals.map(|[n1, n2]| interior_angle_deg(n1, n2))
}

/// Verdict's hexahedral edge ratio: longest over shortest of the 12 edges (`+∞` when an edge
/// has zero length).
pub fn hex_edge_ratio(c: &[[f64; 3]; 8]) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for [a, b] in HEX_EDGES {
        let l = norm(sub(c[b], c[a]));
        lo = lo.min(l);
        hi = hi.max(l);
    }
    if lo > 0.0 { hi / lo } else { f64::INFINITY }
}

/// The quality of one hexahedron; see the module docs for each definition.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct HexQuality {
    /// Verdict's scaled Jacobian: minimum over the 8 corners and the centre, in `[−1, 1]`.
    pub min_scaled_jacobian: f64,
    /// Mean of the 12 interior dihedral angles, degrees (90 for a cube).
    pub dihedral_mean_deg: f64,
    /// Population standard deviation of the 12 dihedral angles, degrees (0 for a cube).
    pub dihedral_std_deg: f64,
    /// Smallest dihedral angle, degrees.
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle, degrees.
    pub max_dihedral_deg: f64,
    /// Longest over shortest edge (1 for a cube).
    pub edge_ratio: f64,
    /// Signed volume of the trilinear element.
    pub volume: f64,
}

/// All measures of one hexahedron (corners in VTK order).
pub fn hex_quality(corners: &[[f64; 3]; 8]) -> HexQuality {
    let angles = hex_dihedral_angles(corners);
    let mean = angles.iter().sum::<f64>() / 12.0;
    let var = angles.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / 12.0;
    HexQuality {
        min_scaled_jacobian: hex_scaled_jacobian(corners),
        dihedral_mean_deg: mean,
        dihedral_std_deg: var.sqrt(),
        min_dihedral_deg: angles.iter().copied().fold(f64::INFINITY, nan_min),
        max_dihedral_deg: angles.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        edge_ratio: hex_edge_ratio(corners),
        volume: hex_volume(corners),
    }
}

/// The six interior dihedral angles of a tetrahedron in degrees, one per edge in
/// [`TET_EDGES`] order (independent of the tetrahedron's orientation).
pub fn tet_dihedral_angles(c: &[[f64; 3]; 4]) -> [f64; 6] {
    let normal = |i: usize| {
        let [p, q, r] = FACE_OPPOSITE[i];
        cross(sub(c[q], c[p]), sub(c[r], c[p]))
    };
    let n = [0, 1, 2, 3].map(normal);
    // The faces along edge k are those opposite the two vertices of the opposite edge 5 − k.
    [0, 1, 2, 3, 4, 5].map(|k| {
        let [i, j] = TET_EDGES[5 - k];
        interior_angle_deg(n[i], n[j])
    })
}

/// The smallest and largest of the six dihedral angles of a tetrahedron, degrees.
pub fn tet_dihedral_range(corners: &[[f64; 3]; 4]) -> (f64, f64) {
    let a = tet_dihedral_angles(corners);
    (
        a.iter().copied().fold(f64::INFINITY, nan_min),
        a.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    )
}

/// Verdict's tetrahedral scaled Jacobian: `√2 · det(v1 − v0, v2 − v0, v3 − v0) / L`, `L` the
/// largest corner product of edge lengths (at least `|det|`); 1 for the regular tetrahedron,
/// negative when inverted, 0 when all edges vanish. See the module docs.
pub fn tet_scaled_jacobian(corners: &[[f64; 3]; 4]) -> f64 {
    let c = corners;
    let l2 = |a: usize, b: usize| dot(sub(c[b], c[a]), sub(c[b], c[a]));
    let (e01, e12, e20) = (l2(0, 1), l2(1, 2), l2(2, 0));
    let (e03, e13, e23) = (l2(0, 3), l2(1, 3), l2(2, 3));
    let jacobi = det(sub(c[1], c[0]), sub(c[2], c[0]), sub(c[3], c[0]));
    let products = [
        e01 * e20 * e03,
        e01 * e12 * e13,
        e12 * e20 * e23,
        e03 * e13 * e23,
    ];
    let mut length_product = products.into_iter().fold(0.0, f64::max).sqrt();
    if length_product < jacobi.abs() {
        length_product = jacobi.abs();
    }
    if length_product.is_nan() || length_product < f64::MIN_POSITIVE {
        return if length_product.is_nan() {
            f64::NAN
        } else {
            0.0
        };
    }
    std::f64::consts::SQRT_2 * jacobi / length_product
}

/// One of the worst hexahedra of a mesh.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct WorstHex {
    /// Its index in [`HexMesh::hexes`].
    pub hex: usize,
    /// Its scaled Jacobian.
    pub scaled_jacobian: f64,
}

/// The quality of a hexahedral mesh: the per-hexahedron measures of [`HexQuality`]
/// aggregated. Sums run in hexahedron order, so the figures are the same for any thread
/// count. With no hexahedra every figure is 0.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeshQuality {
    /// Number of hexahedra.
    pub hexes: usize,
    /// Hexahedra with scaled Jacobian ≤ 0 (or NaN): inverted or collapsed.
    pub inverted: usize,
    /// Smallest scaled Jacobian (NaN values left out).
    pub min_sj: f64,
    /// Mean scaled Jacobian (NaN values left out).
    pub mean_sj: f64,
    /// Counts of hexahedra per scaled-Jacobian bin: [`SJ_BIN_LABELS`].
    pub sj_histogram: [usize; 6],
    /// Mean of all dihedral angles (12 per hexahedron), degrees.
    pub dihedral_mean_deg: f64,
    /// Population standard deviation of all dihedral angles, degrees.
    pub dihedral_std_deg: f64,
    /// Smallest dihedral angle, degrees.
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle, degrees.
    pub max_dihedral_deg: f64,
    /// Up to [`WORST_COUNT`] hexahedra with the smallest scaled Jacobian, worst first (ties by
    /// index; NaN first).
    pub worst_hexes: Vec<WorstHex>,
    /// Largest edge ratio.
    pub max_edge_ratio: f64,
    /// Sum of the signed volumes.
    pub total_volume: f64,
}

fn corners(mesh: &HexMesh, h: usize) -> [[f64; 3]; 8] {
    mesh.hexes[h].map(|v| mesh.verts[v as usize])
}

/// [`hex_quality`] of every hexahedron, in parallel, in index order.
///
/// # Panics
/// If a hexahedron names a vertex beyond `mesh.verts`.
pub fn hex_qualities(mesh: &HexMesh) -> Vec<HexQuality> {
    (0..mesh.hexes.len())
        .into_par_iter()
        .map(|h| hex_quality(&corners(mesh, h)))
        .collect()
}

/// The quality of a whole hexahedral mesh (see [`MeshQuality`]).
///
/// # Panics
/// If a hexahedron names a vertex beyond `mesh.verts`.
pub fn mesh_quality(mesh: &HexMesh) -> MeshQuality {
    summarise(&hex_qualities(mesh))
}

/// [`MeshQuality`] from the qualities of every hexahedron ([`hex_qualities`]), in index
/// order: for a caller that keeps the per-hexahedron figures too.
pub fn summarise(per_hex: &[HexQuality]) -> MeshQuality {
    let n = per_hex.len();
    let mut q = MeshQuality {
        hexes: n,
        inverted: 0,
        min_sj: 0.0,
        mean_sj: 0.0,
        sj_histogram: [0; 6],
        dihedral_mean_deg: 0.0,
        dihedral_std_deg: 0.0,
        min_dihedral_deg: 0.0,
        max_dihedral_deg: 0.0,
        worst_hexes: Vec::new(),
        max_edge_ratio: 0.0,
        total_volume: 0.0,
    };
    if n == 0 {
        return q;
    }
    let (mut sj_sum, mut sj_count, mut min_sj) = (0.0, 0usize, f64::INFINITY);
    // Chan et al.'s pairwise update of (count, mean, sum of squared deviations), merging
    // each hexahedron's 12 angles in order.
    let (mut count, mut mean, mut m2) = (0.0f64, 0.0f64, 0.0f64);
    let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
    for h in per_hex {
        let sj = h.min_scaled_jacobian;
        let bin = if sj > 0.0 {
            1 + SJ_BIN_LOWER.iter().filter(|&&lo| sj >= lo).count()
        } else {
            q.inverted += 1;
            0
        };
        q.sj_histogram[bin] += 1;
        if !sj.is_nan() {
            sj_sum += sj;
            sj_count += 1;
            min_sj = min_sj.min(sj);
        }
        let (nb, mb, m2b) = (12.0, h.dihedral_mean_deg, 12.0 * h.dihedral_std_deg.powi(2));
        let total = count + nb;
        let delta = mb - mean;
        mean += delta * nb / total;
        m2 += m2b + delta * delta * count * nb / total;
        count = total;
        dmin = dmin.min(h.min_dihedral_deg);
        dmax = dmax.max(h.max_dihedral_deg);
        q.max_edge_ratio = q.max_edge_ratio.max(h.edge_ratio);
        q.total_volume += h.volume;
    }
    if sj_count > 0 {
        q.min_sj = min_sj;
        q.mean_sj = sj_sum / sj_count as f64;
    }
    q.dihedral_mean_deg = mean;
    q.dihedral_std_deg = (m2 / count).sqrt();
    q.min_dihedral_deg = dmin;
    q.max_dihedral_deg = dmax;
    let key = |i: usize| {
        let s = per_hex[i].min_scaled_jacobian;
        if s.is_nan() { f64::NEG_INFINITY } else { s }
    };
    let cmp = |a: &usize, b: &usize| key(*a).total_cmp(&key(*b)).then(a.cmp(b));
    let mut order: Vec<usize> = (0..n).collect();
    let k = WORST_COUNT.min(n);
    if k < n {
        order.select_nth_unstable_by(k, cmp);
        order.truncate(k);
    }
    order.sort_unstable_by(cmp);
    q.worst_hexes = order
        .into_iter()
        .map(|h| WorstHex {
            hex: h,
            scaled_jacobian: per_hex[h].min_scaled_jacobian,
        })
        .collect();
    q
}

impl MeshQuality {
    /// The quality table a user reads: counts, scaled Jacobian (min, mean, histogram),
    /// dihedral angles (mean ± std, range), largest edge ratio, total volume, worst elements.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(s, "hexahedra              {}", self.hexes);
        if self.hexes == 0 {
            return s;
        }
        let pct = |c: usize| 100.0 * c as f64 / self.hexes as f64;
        let _ = writeln!(
            s,
            "inverted (SJ <= 0)     {} ({:.2}%)",
            self.inverted,
            pct(self.inverted)
        );
        let _ = writeln!(
            s,
            "scaled Jacobian        min {:.4}  mean {:.4}",
            self.min_sj, self.mean_sj
        );
        for (label, &c) in SJ_BIN_LABELS.iter().zip(&self.sj_histogram) {
            let _ = writeln!(s, "  {label:<20} {c:>10}  {:>6.2}%", pct(c));
        }
        let _ = writeln!(
            s,
            "dihedral angle         {:.2} ± {:.2} deg (min {:.2}, max {:.2})",
            self.dihedral_mean_deg,
            self.dihedral_std_deg,
            self.min_dihedral_deg,
            self.max_dihedral_deg
        );
        let _ = writeln!(s, "edge ratio (max)       {:.4}", self.max_edge_ratio);
        let _ = writeln!(s, "total volume           {:.6e}", self.total_volume);
        let worst: Vec<String> = self
            .worst_hexes
            .iter()
            .map(|w| format!("{} ({:.3})", w.hex, w.scaled_jacobian))
            .collect();
        let _ = writeln!(s, "worst hexahedra (SJ)   {}", worst.join(", "));
        s
    }
}

#[cfg(test)]
mod tests;
