//! The checked tetrahedral mesh and the topology the later CubeCover stages need: neighbours
//! across faces, the boundary surface, the edges and, for every edge, its cyclically ordered
//! star of tetrahedra.
//!
//! [`check_tets`] validates a [`TetMesh`] and builds its [`Topology`], or names the first
//! problem it finds (see [`TetError`]). The checks run in this order and each reports the
//! first offending element (lowest index):
//!
//! 1. at least one tetrahedron (and fewer than `u32::MAX`);
//! 2. every vertex index below the vertex count;
//! 3. every vertex coordinate finite (all vertices, used or not);
//! 4. no tetrahedron repeats a vertex;
//! 5. every tetrahedron positively oriented and not flat: with `V` the signed volume
//!    `det(b − a, c − a, d − a) / 6` and `ε = 1e-12 · D³`, `D` the diagonal of the bounding
//!    box of the used vertices, `V < −ε` is *inverted* and `−ε ≤ V ≤ ε` *degenerate*.
//!    Orientation is never fixed silently;
//! 6. every face in at most two tetrahedra (non-manifold face), and the two tetrahedra of an
//!    interior face on opposite sides of it (the face appears with opposite orientations;
//!    otherwise the two overlap);
//! 7. the boundary triangles form a closed 2-manifold: every boundary edge in exactly two
//!    boundary triangles, and around every boundary vertex the boundary triangles form a
//!    single disc (one fan); a vertex where two parts of the solid touch has several;
//! 8. the tetrahedra around every edge form a single fan (a cycle for an interior edge, a
//!    chain for a boundary edge) when walked through shared faces;
//! 9. the mesh is one solid: its tetrahedra are connected through shared faces. **Several
//!    components are an error** ([`TetError::Disconnected`]): the CubeCover stage
//!    parameterises one solid. Cavities (several boundary surfaces of one solid) are allowed.
//!
//! Vertices used by no tetrahedron are allowed and counted ([`Topology::unused_vertices`]).
//! Interior vertices are not checked for a spherical link.
//!
//! # Conventions
//!
//! * Local edges of a tetrahedron follow [`TET_EDGES`]: `01 02 03 12 13 23`; local edge `k`
//!   and `5 − k` are opposite.
//! * Edges are sorted vertex pairs `[a, b]`, `a < b`, and [`Topology::edges`] is sorted.
//! * **Star orientation**: the star of edge `[a, b]` lists its tetrahedra in the order of a
//!   positive (right-hand) rotation about the directed edge `a → b`: counter-clockwise seen
//!   from `b` looking towards `a`. Each tetrahedron of the star spans a wedge from `c` to `d`,
//!   where `(a, b, c, d)` is positively oriented ([`star_wedge`]); consecutive tetrahedra `t_k`,
//!   `t_{k+1}` share the face `(a, b, d_k)` and `d_k = c_{k+1}`. An interior edge's star is a
//!   closed cycle starting at its lowest-numbered tetrahedron (the face `(a, b, d_last)` is
//!   shared with the first). A boundary edge's star is a chain from the tetrahedron whose face
//!   `(a, b, c_0)` is on the boundary to the one whose face `(a, b, d_last)` is.
//!
//! # Where the checks live
//!
//! `checks.rs` (checks 1–5, the orientation half of 6, and 9), `boundary.rs` (check 7 and
//! the boundary's components), `stars.rs` (check 8 and the edge stars), `error.rs`
//! ([`TetError`]); [`check_tets`], here, runs them in order (the neighbour search of 6
//! among them) and assembles the [`Topology`].

mod boundary;
mod checks;
mod error;
mod stars;

use crate::mesh::{FACE_OPPOSITE, TetMesh, tet_neighbours};
use boundary::boundary_surfaces;
use checks::{check_indices, check_one_solid, check_orientation, check_volumes};
pub use error::TetError;
use stars::{EdgeStars, edge_stars};

/// The local vertex pairs of a tetrahedron's six edges, in the order of
/// [`Topology::tet_edges`]: `01 02 03 12 13 23`. Edge `k` and edge `5 − k` are opposite.
pub const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

/// A tetrahedron is degenerate when `|volume| ≤ DEGENERATE_VOLUME · D³`, `D` the diagonal of
/// the bounding box of the used vertices.
pub const DEGENERATE_VOLUME: f64 = 1e-12;

/// One connected component of the boundary surface (a closed orientable surface).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct BoundarySurface {
    /// Number of triangles `F`.
    pub triangles: usize,
    /// Number of edges `E = 3F / 2`.
    pub edges: usize,
    /// Number of vertices `V`.
    pub vertices: usize,
    /// `χ = V − E + F` (2 for a sphere).
    pub euler_characteristic: i64,
    /// `g = (2 − χ) / 2`: 0 for a sphere, 1 for a torus.
    pub genus: i64,
    /// Its lowest-numbered triangle (an index into [`Topology::boundary`]).
    pub first_triangle: usize,
}

/// The topology of a checked tetrahedral mesh, built by [`check_tets`]. See the module docs
/// for the conventions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Topology {
    /// For each tetrahedron and local vertex `i`, the tetrahedron across the face opposite `i`
    /// ([`FACE_OPPOSITE`]), or [`NO_TET`](crate::mesh::NO_TET) on the boundary.
    pub neighbours: Vec<[u32; 4]>,
    /// The boundary faces as `(tetrahedron, local vertex opposite the face)`, in tetrahedron
    /// order; their outward triangles are [`Topology::boundary_triangles`].
    pub boundary: Vec<(u32, u8)>,
    /// The edges as sorted vertex pairs `[a, b]`, `a < b`, sorted.
    pub edges: Vec<[u32; 2]>,
    /// For each tetrahedron, the ids (into [`Topology::edges`]) of its six edges in the
    /// local order [`TET_EDGES`].
    pub tet_edges: Vec<[u32; 6]>,
    /// CSR offsets of the edge stars: the star of edge `e` is
    /// `star_tets[star_offsets[e]..star_offsets[e + 1]]`.
    pub star_offsets: Vec<usize>,
    /// The tetrahedra around each edge in rotation order (see the module docs).
    pub star_tets: Vec<u32>,
    /// Whether each edge lies on the boundary (its star is a chain, not a cycle).
    pub edge_on_boundary: Vec<bool>,
    /// Whether each vertex lies on the boundary surface.
    pub vertex_on_boundary: Vec<bool>,
    /// The connected components of the boundary surface, ordered by their first triangle.
    pub boundary_surfaces: Vec<BoundarySurface>,
    /// Vertices used by no tetrahedron.
    pub unused_vertices: usize,
}

impl Topology {
    /// Number of edges.
    pub fn num_edges(&self) -> usize {
        self.edges.len()
    }

    /// The tetrahedra around edge `e`, in rotation order.
    pub fn star(&self, e: usize) -> &[u32] {
        &self.star_tets[self.star_offsets[e]..self.star_offsets[e + 1]]
    }

    /// The id of the edge between vertices `a` and `b` (either order), if there is one.
    pub fn edge_id(&self, a: u32, b: u32) -> Option<u32> {
        let key = [a.min(b), a.max(b)];
        self.edges.binary_search(&key).ok().map(|e| e as u32)
    }

    /// The outward boundary triangle `k` (of [`Topology::boundary`]): its counter-clockwise
    /// normal points out of the solid.
    pub fn boundary_triangle(&self, mesh: &TetMesh, k: usize) -> [u32; 3] {
        let (t, i) = self.boundary[k];
        let tet = mesh.tets[t as usize];
        FACE_OPPOSITE[i as usize].map(|j| tet[j])
    }

    /// All boundary triangles, outward, in the order of [`Topology::boundary`].
    pub fn boundary_triangles(&self, mesh: &TetMesh) -> Vec<[u32; 3]> {
        (0..self.boundary.len())
            .map(|k| self.boundary_triangle(mesh, k))
            .collect()
    }

    /// Euler characteristic of the whole boundary surface (the sum over its components).
    pub fn boundary_euler_characteristic(&self) -> i64 {
        self.boundary_surfaces
            .iter()
            .map(|s| s.euler_characteristic)
            .sum()
    }

    /// Total genus of the boundary surface (the sum over its components).
    pub fn boundary_genus(&self) -> i64 {
        self.boundary_surfaces.iter().map(|s| s.genus).sum()
    }

    /// The interior edges whose two ends lie on the boundary (chords through the solid). A
    /// map that flattens boundary charts onto planes flattens a tetrahedron whose vertices
    /// are all on one chart; splitting the chords ([`TetMesh::split_edges`]) leaves every
    /// tetrahedron an interior vertex or a boundary edge.
    pub fn boundary_chords(&self) -> Vec<[u32; 2]> {
        self.edges
            .iter()
            .zip(&self.edge_on_boundary)
            .filter(|&(&[a, b], &on)| {
                !on && self.vertex_on_boundary[a as usize] && self.vertex_on_boundary[b as usize]
            })
            .map(|(&e, _)| e)
            .collect()
    }

    /// Number of vertices on the boundary.
    pub fn num_boundary_vertices(&self) -> usize {
        self.vertex_on_boundary.iter().filter(|&&b| b).count()
    }

    /// For the `k`-th tetrahedron of edge `e`'s star, the other two vertices `[c, d]` in
    /// rotation order: `(a, b, c, d)` is positively oriented, and `d` is the `c` of the next
    /// tetrahedron of the star.
    pub fn star_wedge(&self, mesh: &TetMesh, e: usize, k: usize) -> [u32; 2] {
        let [a, b] = self.edges[e];
        star_wedge(mesh.tets[self.star(e)[k] as usize], a, b)
    }
}

/// For tetrahedron `tet` (positively oriented) and two of its vertices `a`, `b`, the other
/// two vertices `[c, d]` ordered so that `(a, b, c, d)` is an even permutation of `tet`, i.e.
/// positively oriented: the tetrahedron spans the wedge from `c` to `d` in a positive
/// rotation about `a → b`.
///
/// # Panics
/// If `a` or `b` is not a vertex of `tet`.
pub fn star_wedge(tet: [u32; 4], a: u32, b: u32) -> [u32; 2] {
    let i = tet.iter().position(|&v| v == a).expect("a in tet");
    let j = tet.iter().position(|&v| v == b).expect("b in tet");
    let mut rest = (0..4).filter(|&x| x != i && x != j);
    let (k, l) = (rest.next().unwrap(), rest.next().unwrap());
    let p = [i, j, k, l];
    let mut inversions = 0;
    for x in 0..4 {
        for y in x + 1..4 {
            if p[x] > p[y] {
                inversions += 1;
            }
        }
    }
    if inversions % 2 == 0 {
        [tet[k], tet[l]]
    } else {
        [tet[l], tet[k]]
    }
}

/// Union-find: the root of `x`, halving the path.
pub(crate) fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[parent[x as usize] as usize];
        parent[x as usize] = p;
        x = p;
    }
    x
}

/// Union-find: joins the sets of `a` and `b` under the lower root.
pub(crate) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}

/// Validates `mesh` and builds its [`Topology`]; see the module docs for the checks, their
/// order and the conventions. The mesh is not modified (an inverted tetrahedron is an error,
/// never reoriented).
pub fn check_tets(mesh: &TetMesh) -> Result<Topology, TetError> {
    check_indices(mesh)?;
    let used = check_volumes(mesh)?;
    // Faces: manifold and consistently oriented.
    let neighbours = tet_neighbours(mesh).map_err(|e| TetError::NonManifoldFace {
        face: e.vertices,
        tets: e.tets,
    })?;
    check_orientation(mesh, &neighbours)?;
    let (boundary, vertex_on_boundary, boundary_surfaces) = boundary_surfaces(mesh, &neighbours)?;
    let EdgeStars {
        edges,
        tet_edges,
        star_offsets,
        star_tets,
        edge_on_boundary,
    } = edge_stars(mesh, &neighbours)?;
    check_one_solid(&neighbours)?;

    Ok(Topology {
        neighbours,
        boundary,
        edges,
        tet_edges,
        star_offsets,
        star_tets,
        edge_on_boundary,
        vertex_on_boundary,
        boundary_surfaces,
        unused_vertices: used.iter().filter(|&&u| !u).count(),
    })
}

#[cfg(test)]
mod tests;
