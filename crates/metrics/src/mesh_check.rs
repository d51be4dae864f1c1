//! Topology of a triangle mesh: boundary, non-manifold and inconsistent edges, degenerate
//! triangles, components; the conventions are in the [module docs](super).

use rayon::prelude::*;
use serde::Serialize;

use super::{corners, double_area};
use crate::geom::vec::{dot, sub};
use crate::io::mesh_read::Mesh;
use crate::types::Aabb;

/// Topology and extent of a mesh; see the module docs for the conventions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshCheck {
    /// Number of vertices.
    pub vertices: usize,
    /// Number of triangles.
    pub triangles: usize,
    /// Connected components of triangles sharing a vertex.
    pub components: usize,
    /// Edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Vertices whose triangles form more than one fan (triangles around the vertex joined
    /// through the edges at it): e.g. two closed surfaces touching at a point.
    pub non_manifold_vertices: usize,
    /// Edges used by two triangles in the same direction (orientation flips).
    pub inconsistent_edges: usize,
    /// Triangles with a repeated index or zero area (up to rounding).
    pub degenerate_triangles: usize,
    /// Triangles with an index not below the vertex count (ignored by every other count).
    pub invalid_triangles: usize,
    /// Vertices no triangle uses.
    pub unreferenced_vertices: usize,
    /// No boundary and no non-manifold edge.
    pub watertight: bool,
    /// No non-manifold edge.
    pub edge_manifold: bool,
    /// No non-manifold vertex.
    pub vertex_manifold: bool,
    /// No inconsistent edge.
    pub oriented: bool,
    /// Bounds of all vertices, in the mesh's units.
    pub bounds: Aabb,
    /// Diagonal of `bounds`, in the mesh's units (0 for an empty mesh).
    pub diagonal: f64,
}

/// One directed use of an edge, packed so that sorting groups the uses of an edge: the
/// smaller index, then the larger one, then a direction bit (1 when the triangle goes from the
/// smaller index to the larger).
trait PackedEdge: Copy + Ord + Send + Sync {
    fn pack(a: u32, b: u32) -> Self;
    fn edge(self) -> Self;
    fn forward(self) -> bool;
}

/// For meshes with fewer than 2^31 vertices: 32 + 31 + 1 bits.
impl PackedEdge for u64 {
    #[inline]
    fn pack(a: u32, b: u32) -> u64 {
        let (lo, hi) = (a.min(b) as u64, a.max(b) as u64);
        (lo << 32) | (hi << 1) | u64::from(a < b)
    }
    #[inline]
    fn edge(self) -> u64 {
        self & !1
    }
    #[inline]
    fn forward(self) -> bool {
        self & 1 == 1
    }
}

/// For larger meshes.
impl PackedEdge for u128 {
    #[inline]
    fn pack(a: u32, b: u32) -> u128 {
        let (lo, hi) = (a.min(b) as u128, a.max(b) as u128);
        (lo << 33) | (hi << 1) | u128::from(a < b)
    }
    #[inline]
    fn edge(self) -> u128 {
        self & !1
    }
    #[inline]
    fn forward(self) -> bool {
        self & 1 == 1
    }
}

/// Boundary, non-manifold and inconsistent edge counts.
fn count_edges<K: PackedEdge>(m: &Mesh) -> (usize, usize, usize) {
    let n = m.vertices.len();
    let mut keys: Vec<K> = m
        .triangles
        .par_iter()
        .filter(|t| proper(t, n))
        .flat_map_iter(|t| {
            [
                K::pack(t[0], t[1]),
                K::pack(t[1], t[2]),
                K::pack(t[2], t[0]),
            ]
        })
        .collect();
    keys.par_sort_unstable();
    let (mut boundary, mut non_manifold, mut inconsistent) = (0, 0, 0);
    for run in keys.chunk_by(|a, b| a.edge() == b.edge()) {
        match run.len() {
            1 => boundary += 1,
            2 => {
                if run[0].forward() == run[1].forward() {
                    inconsistent += 1;
                }
            }
            _ => non_manifold += 1,
        }
    }
    (boundary, non_manifold, inconsistent)
}

/// Whether triangle `t` has three distinct indices, all below `n`: the triangles that take part
/// in edge and fan counts.
#[inline]
fn proper(t: &[u32; 3], n: usize) -> bool {
    t.iter().all(|&v| (v as usize) < n) && t[0] != t[1] && t[1] != t[2] && t[2] != t[0]
}

/// Vertices whose proper triangles form more than one fan. Around vertex `v`, each triangle
/// `(v, a, b)` is an edge `a–b` of `v`'s *link*; the fans are the link's connected components
/// (two triangles are in one fan when they share an edge at `v`). The triangles at each
/// vertex are listed by a counting sort (`I`: a triangle index type wide enough).
fn count_non_manifold_vertices<I>(m: &Mesh) -> usize
where
    I: Copy + Send + Sync + TryFrom<usize> + Into<u64>,
{
    let n = m.vertices.len();
    let mut start = vec![0usize; n + 1];
    for t in m.triangles.iter().filter(|t| proper(t, n)) {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let Ok(zero) = I::try_from(0) else { return 0 };
    let mut at = vec![zero; start[n]];
    let mut fill = start.clone();
    for (ti, t) in m.triangles.iter().enumerate().filter(|(_, t)| proper(t, n)) {
        let Ok(i) = I::try_from(ti) else { continue };
        for &v in t {
            at[fill[v as usize]] = i;
            fill[v as usize] += 1;
        }
    }
    drop(fill);
    (0..n)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(nodes, parent): &mut (Vec<u32>, Vec<usize>), v| {
                let tris = &at[start[v]..start[v + 1]];
                let link = |i: &I| {
                    let t = m.triangles[(*i).into() as usize];
                    let k = t.iter().position(|&x| x as usize == v).unwrap_or(0);
                    (t[(k + 1) % 3], t[(k + 2) % 3])
                };
                nodes.clear();
                nodes.extend(tris.iter().flat_map(|i| {
                    let (a, b) = link(i);
                    [a, b]
                }));
                nodes.sort_unstable();
                nodes.dedup();
                parent.clear();
                parent.extend(0..nodes.len());
                let mut fans = nodes.len();
                for i in tris {
                    let (a, b) = link(i);
                    let (Ok(a), Ok(b)) = (nodes.binary_search(&a), nodes.binary_search(&b)) else {
                        continue;
                    };
                    let (ra, rb) = (root(parent, a), root(parent, b));
                    if ra != rb {
                        parent[ra.max(rb)] = ra.min(rb);
                        fans -= 1;
                    }
                }
                usize::from(fans > 1)
            },
        )
        .sum()
}

/// Union-find root of `i` in a small forest.
fn root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Union-find root of `v`, halving paths.
#[inline]
fn find(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let g = parent[parent[v as usize] as usize];
        parent[v as usize] = g;
        v = g;
    }
    v
}

/// Check the topology of `m`; see the module docs for the conventions. Memory: about
/// 24 bytes a triangle (edge keys, then the triangles at each vertex) and 17 bytes a vertex.
pub fn check_mesh(m: &Mesh) -> MeshCheck {
    let n = m.vertices.len();
    let (boundary_edges, non_manifold_edges, inconsistent_edges) = if n <= 1 << 31 {
        count_edges::<u64>(m)
    } else {
        count_edges::<u128>(m)
    };
    let non_manifold_vertices = if m.triangles.len() <= u32::MAX as usize {
        count_non_manifold_vertices::<u32>(m)
    } else {
        count_non_manifold_vertices::<u64>(m)
    };

    let (degenerate_triangles, invalid_triangles) = m
        .triangles
        .par_iter()
        .map(|&t| match corners(m, t) {
            None => (0, 1),
            Some(c) => {
                let repeated = t[0] == t[1] || t[1] == t[2] || t[2] == t[0];
                let longest = [sub(c[1], c[0]), sub(c[2], c[1]), sub(c[0], c[2])]
                    .map(|e| dot(e, e))
                    .into_iter()
                    .fold(0.0, f64::max);
                let flat = double_area(&c) <= 1e-12 * longest;
                (usize::from(repeated || flat), 0)
            }
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));

    // Components and referenced vertices. Vertex indices fit u32 (at most 2^32 vertices are
    // addressable by triangles; later ones are unreferenced by construction).
    let mut parent: Vec<u32> = (0..n.min(1 << 32) as u64).map(|v| v as u32).collect();
    let mut referenced = vec![false; n];
    for &t in &m.triangles {
        if t.iter().any(|&v| v as usize >= n) {
            continue;
        }
        for v in t {
            referenced[v as usize] = true;
        }
        for &v in &t[1..] {
            let (ra, rb) = (find(&mut parent, t[0]), find(&mut parent, v));
            // Link the larger root under the smaller: deterministic.
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        }
    }
    let mut components = 0;
    let mut unreferenced_vertices = 0;
    for v in 0..n {
        if !referenced[v] {
            unreferenced_vertices += 1;
        } else if find(&mut parent, v as u32) == v as u32 {
            components += 1;
        }
    }

    let bounds = m
        .vertices
        .par_iter()
        .fold(
            || Aabb::EMPTY,
            |mut b, &p| {
                b.add(p);
                b
            },
        )
        .reduce(|| Aabb::EMPTY, |a, b| a.union(&b));
    let diagonal = if bounds.is_empty() {
        0.0
    } else {
        bounds.diagonal()
    };
    MeshCheck {
        vertices: n,
        triangles: m.triangles.len(),
        components,
        boundary_edges,
        non_manifold_edges,
        non_manifold_vertices,
        inconsistent_edges,
        degenerate_triangles,
        invalid_triangles,
        unreferenced_vertices,
        watertight: boundary_edges == 0 && non_manifold_edges == 0,
        edge_manifold: non_manifold_edges == 0,
        vertex_manifold: non_manifold_vertices == 0,
        oriented: inconsistent_edges == 0,
        bounds,
        diagonal,
    }
}

// ---------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{mesh, octahedron, signed_volume};
    use crate::geom::vec::add;

    #[test]
    fn octahedron_is_closed_and_oriented() {
        let m = octahedron();
        assert!(signed_volume(&m) > 0.0);
        let c = check_mesh(&m);
        assert_eq!((c.vertices, c.triangles, c.components), (6, 8, 1));
        assert_eq!(
            (c.boundary_edges, c.non_manifold_edges, c.inconsistent_edges),
            (0, 0, 0)
        );
        assert_eq!((c.degenerate_triangles, c.unreferenced_vertices), (0, 0));
        assert!(c.watertight && c.edge_manifold && c.oriented);
        assert_eq!(c.bounds.min, [-1.0; 3]);
        assert!((c.diagonal - 12f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn missing_face_leaves_three_boundary_edges() {
        let mut m = octahedron();
        m.triangles.remove(5);
        let c = check_mesh(&m);
        assert_eq!(c.boundary_edges, 3);
        assert!(!c.watertight && c.edge_manifold && c.oriented);
        assert_eq!(c.components, 1);
    }

    #[test]
    fn flipped_face_is_inconsistent() {
        let mut m = octahedron();
        m.triangles[3].swap(0, 1);
        let c = check_mesh(&m);
        assert_eq!(c.inconsistent_edges, 3);
        assert!(c.watertight && !c.oriented);
    }

    #[test]
    fn two_tetrahedra_are_two_components() {
        let mut v = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        v.extend(v.clone().iter().map(|p| add(*p, [5.0, 0.0, 0.0])));
        v.push([9.0, 9.0, 9.0]);
        let tet = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let mut t: Vec<[u32; 3]> = tet.to_vec();
        t.extend(tet.iter().map(|f| f.map(|i| i + 4)));
        let m = mesh(&v, &t);
        assert!(signed_volume(&m) > 0.0);
        let c = check_mesh(&m);
        assert_eq!((c.components, c.unreferenced_vertices), (2, 1));
        assert!(c.watertight && c.oriented);
    }

    #[test]
    fn tetrahedra_sharing_one_vertex_make_it_non_manifold() {
        // Two closed tetrahedra with vertex 0 in common: watertight and edge-manifold, but
        // the triangles at vertex 0 form two fans.
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, -1.0],
        ];
        let t = [
            [0, 2, 1],
            [0, 1, 3],
            [1, 2, 3],
            [0, 3, 2],
            [0, 5, 4],
            [0, 4, 6],
            [4, 5, 6],
            [0, 6, 5],
        ];
        let c = check_mesh(&mesh(&v, &t));
        assert!(c.watertight && c.edge_manifold && c.oriented, "{c:?}");
        assert_eq!((c.non_manifold_vertices, c.components), (1, 1));
        assert!(!c.vertex_manifold);
        // Closed and open single fans are manifold.
        let c = check_mesh(&octahedron());
        assert_eq!(c.non_manifold_vertices, 0);
        let mut m = octahedron();
        m.triangles.remove(5);
        assert_eq!(check_mesh(&m).non_manifold_vertices, 0);
        // Two triangles touching at a vertex only.
        let c = check_mesh(&mesh(&v, &[[0, 1, 2], [0, 4, 5]]));
        assert_eq!(c.non_manifold_vertices, 1);
    }

    #[test]
    fn non_manifold_degenerate_and_invalid() {
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [2.0, 0.0, 0.0],
        ];
        // Three fins on edge {0, 1}; a repeated index; a collinear triangle; a bad index.
        let t = [
            [0, 1, 2],
            [1, 0, 3],
            [0, 1, 4],
            [2, 2, 4],
            [0, 1, 5],
            [0, 1, 9],
        ];
        let c = check_mesh(&mesh(&v, &t));
        assert_eq!(c.non_manifold_edges, 1);
        assert_eq!(c.degenerate_triangles, 2);
        assert_eq!(c.invalid_triangles, 1);
        assert!(!c.edge_manifold && !c.watertight);
        // Edges {1,5} and {5,0} of the collinear triangle are boundary, and the fins' others.
        assert_eq!(c.boundary_edges, 2 + 6);
    }
}
