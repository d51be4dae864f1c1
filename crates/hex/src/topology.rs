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

use crate::mesh::{FACE_OPPOSITE, NO_TET, TetMesh, tet_neighbours};

/// The local vertex pairs of a tetrahedron's six edges, in the order of
/// [`Topology::tet_edges`]: `01 02 03 12 13 23`. Edge `k` and edge `5 − k` are opposite.
pub const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

/// A tetrahedron is degenerate when `|volume| ≤ DEGENERATE_VOLUME · D³`, `D` the diagonal of
/// the bounding box of the used vertices.
pub const DEGENERATE_VOLUME: f64 = 1e-12;

fn verts_str(v: &[u32]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

fn tris_str(t: &[[u32; 3]]) -> String {
    t.iter()
        .map(|t| format!("({})", verts_str(t)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Why a tetrahedral mesh is not a valid single solid. Indices are 0-based; the caller adds
/// the file name.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TetError {
    /// The mesh has no tetrahedra.
    #[error("expected at least one tetrahedron, found none")]
    NoTetrahedra,
    /// More tetrahedra than `u32` indices can name.
    #[error("expected fewer than 4294967295 tetrahedra, found {count}")]
    TooManyTetrahedra {
        /// The number of tetrahedra.
        count: usize,
    },
    /// A tetrahedron names a vertex beyond the vertex count.
    #[error(
        "tetrahedron {tet} (vertices {}) names vertex {vertex}, but there are only \
         {vertex_count} vertices (expected indices below {vertex_count})",
        verts_str(verts)
    )]
    VertexOutOfRange {
        /// The tetrahedron.
        tet: usize,
        /// Its vertices.
        verts: [u32; 4],
        /// The offending index.
        vertex: u32,
        /// The number of vertices.
        vertex_count: usize,
    },
    /// A vertex has a NaN or infinite coordinate.
    #[error("vertex {vertex} has non-finite coordinates {coords:?}; expected finite numbers")]
    NonFiniteVertex {
        /// The vertex.
        vertex: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// A tetrahedron lists the same vertex twice.
    #[error(
        "tetrahedron {tet} (vertices {}) repeats vertex {vertex}; expected 4 distinct vertices",
        verts_str(verts)
    )]
    RepeatedVertex {
        /// The tetrahedron.
        tet: usize,
        /// Its vertices.
        verts: [u32; 4],
        /// The repeated vertex.
        vertex: u32,
    },
    /// A tetrahedron with negative volume (vertices in the wrong order).
    #[error(
        "tetrahedron {tet} (vertices {}) is inverted: volume {volume:.3e}; expected a positive \
         volume det(b - a, c - a, d - a) / 6 (reorder its vertices)",
        verts_str(verts)
    )]
    Inverted {
        /// The tetrahedron.
        tet: usize,
        /// Its vertices.
        verts: [u32; 4],
        /// Its signed volume.
        volume: f64,
    },
    /// A flat tetrahedron: `|volume|` at most `1e-12 · (bounding-box diagonal)³`.
    #[error(
        "tetrahedron {tet} (vertices {}) is degenerate: volume {volume:.3e}; expected more than \
         {min_volume:.3e} (1e-12 x bounding-box diagonal cubed)",
        verts_str(verts)
    )]
    Degenerate {
        /// The tetrahedron.
        tet: usize,
        /// Its vertices.
        verts: [u32; 4],
        /// Its signed volume.
        volume: f64,
        /// The smallest volume accepted.
        min_volume: f64,
    },
    /// A face shared by more than two tetrahedra.
    #[error(
        "face ({}) is shared by {} tetrahedra ({}); expected at most 2 (non-manifold face)",
        verts_str(face),
        tets.len(),
        verts_str(tets)
    )]
    NonManifoldFace {
        /// The face's sorted vertices.
        face: [u32; 3],
        /// The tetrahedra that contain it.
        tets: Vec<u32>,
    },
    /// Two tetrahedra on the same side of their shared face.
    #[error(
        "tetrahedra {} and {} lie on the same side of their shared face ({}), so they overlap; \
         expected them on opposite sides (the face in opposite orientations)",
        tets[0],
        tets[1],
        verts_str(face)
    )]
    OverlappingTets {
        /// The face's sorted vertices.
        face: [u32; 3],
        /// The two tetrahedra.
        tets: [u32; 2],
    },
    /// A boundary edge in a number of boundary triangles other than two.
    #[error(
        "boundary edge ({} {}) is in {} boundary triangles ({}); expected exactly 2 for a \
         closed 2-manifold boundary",
        edge[0],
        edge[1],
        triangles.len(),
        tris_str(triangles)
    )]
    NonManifoldBoundaryEdge {
        /// The edge's sorted vertices.
        edge: [u32; 2],
        /// The outward boundary triangles that contain it.
        triangles: Vec<[u32; 3]>,
    },
    /// A boundary vertex whose boundary triangles form several fans.
    #[error(
        "boundary vertex {vertex} has {fans} separate fans of boundary triangles (parts of the \
         solid touch there); expected a single disc (non-manifold vertex)"
    )]
    NonManifoldVertex {
        /// The vertex.
        vertex: u32,
        /// The number of fans.
        fans: usize,
    },
    /// The tetrahedra around an edge do not form a single fan.
    #[error(
        "edge ({} {}) is in {tets} tetrahedra, but walking through shared faces from \
         tetrahedron {start} reaches {walked}; expected a single fan (non-manifold edge)",
        edge[0],
        edge[1]
    )]
    NonManifoldEdge {
        /// The edge's sorted vertices.
        edge: [u32; 2],
        /// How many tetrahedra contain it.
        tets: usize,
        /// The tetrahedron the walk started from.
        start: u32,
        /// How many the walk reached.
        walked: usize,
    },
    /// The tetrahedra form several solids.
    #[error(
        "the mesh has {components} connected components (tetrahedron {second} is not connected \
         to tetrahedron 0 through shared faces); expected one solid"
    )]
    Disconnected {
        /// The number of components (through shared faces).
        components: usize,
        /// The lowest-numbered tetrahedron outside tetrahedron 0's component.
        second: u32,
    },
}

impl TetError {
    /// A vertex where the problem lies, for errors that have one (to give its position where
    /// the indices mean nothing to the user, as in a mesh the tool stuffed itself).
    pub fn vertex(&self) -> Option<u32> {
        match self {
            TetError::NoTetrahedra
            | TetError::TooManyTetrahedra { .. }
            | TetError::Disconnected { .. } => None,
            TetError::NonFiniteVertex { vertex, .. } => u32::try_from(*vertex).ok(),
            TetError::VertexOutOfRange { verts, vertex, .. } => {
                verts.iter().copied().find(|v| v != vertex)
            }
            TetError::RepeatedVertex { vertex, .. } => Some(*vertex),
            TetError::Inverted { verts, .. } | TetError::Degenerate { verts, .. } => Some(verts[0]),
            TetError::NonManifoldFace { face, .. } | TetError::OverlappingTets { face, .. } => {
                Some(face[0])
            }
            TetError::NonManifoldBoundaryEdge { edge, .. }
            | TetError::NonManifoldEdge { edge, .. } => Some(edge[0]),
            TetError::NonManifoldVertex { vertex, .. } => Some(*vertex),
        }
    }
}

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
    /// ([`FACE_OPPOSITE`]), or [`NO_TET`] on the boundary.
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

fn local(tet: &[u32; 4], v: u32) -> usize {
    tet.iter().position(|&x| x == v).expect("vertex in tet")
}

/// Whether `b` is a cyclic rotation of `a` (the same oriented triangle).
fn same_cycle(a: [u32; 3], b: [u32; 3]) -> bool {
    b == a || b == [a[1], a[2], a[0]] || b == [a[2], a[0], a[1]]
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

/// The face of tetrahedron `t` opposite its corner `i`, oriented outwards.
fn face_of(mesh: &TetMesh, t: usize, i: usize) -> [u32; 3] {
    FACE_OPPOSITE[i].map(|j| mesh.tets[t][j])
}

/// Counts, vertex indices in range, finite coordinates, no repeated vertex in a
/// tetrahedron: the first checks of the module docs.
fn check_indices(mesh: &TetMesh) -> Result<(), TetError> {
    let nt = mesh.tets.len();
    let nv = mesh.verts.len();
    if nt == 0 {
        return Err(TetError::NoTetrahedra);
    }
    if nt >= NO_TET as usize {
        return Err(TetError::TooManyTetrahedra { count: nt });
    }
    for (t, tet) in mesh.tets.iter().enumerate() {
        if let Some(&v) = tet.iter().find(|&&v| v as usize >= nv) {
            return Err(TetError::VertexOutOfRange {
                tet: t,
                verts: *tet,
                vertex: v,
                vertex_count: nv,
            });
        }
    }
    for (i, p) in mesh.verts.iter().enumerate() {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(TetError::NonFiniteVertex {
                vertex: i,
                coords: *p,
            });
        }
    }
    for (t, tet) in mesh.tets.iter().enumerate() {
        for x in 0..4 {
            if tet[x + 1..].contains(&tet[x]) {
                return Err(TetError::RepeatedVertex {
                    tet: t,
                    verts: *tet,
                    vertex: tet[x],
                });
            }
        }
    }
    Ok(())
}

/// Volumes against the bounding box of the used vertices: no inverted or degenerate
/// tetrahedron. Returns which vertices the tetrahedra use.
fn check_volumes(mesh: &TetMesh) -> Result<Vec<bool>, TetError> {
    let nt = mesh.tets.len();
    let nv = mesh.verts.len();
    let mut used = vec![false; nv];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for tet in &mesh.tets {
        for &v in tet {
            if !used[v as usize] {
                used[v as usize] = true;
                let p = mesh.verts[v as usize];
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
    }
    let diag = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let min_volume = DEGENERATE_VOLUME * diag.powi(3);
    for t in 0..nt {
        let volume = mesh.volume(t);
        if volume < -min_volume {
            return Err(TetError::Inverted {
                tet: t,
                verts: mesh.tets[t],
                volume,
            });
        }
        if volume.is_nan() || volume <= min_volume {
            return Err(TetError::Degenerate {
                tet: t,
                verts: mesh.tets[t],
                volume,
                min_volume,
            });
        }
    }
    Ok(used)
}

/// Faces: manifold (checked by the neighbour search) and consistently oriented, i.e. no two
/// tetrahedra on the same side of a shared face.
fn check_orientation(mesh: &TetMesh, neighbours: &[[u32; 4]]) -> Result<(), TetError> {
    let nt = mesh.tets.len();
    for t in 0..nt {
        for i in 0..4 {
            let n = neighbours[t][i];
            if n == NO_TET || (n as usize) < t {
                continue;
            }
            let f = face_of(mesh, t, i);
            let ntet = &mesh.tets[n as usize];
            let j = (0..4)
                .find(|&j| !f.contains(&ntet[j]))
                .expect("shared face");
            if same_cycle(f, face_of(mesh, n as usize, j)) {
                let mut face = f;
                face.sort_unstable();
                return Err(TetError::OverlappingTets {
                    face,
                    tets: [t as u32, n],
                });
            }
        }
    }
    Ok(())
}

/// Boundary surface: a closed 2-manifold. Returns the boundary faces (tetrahedron, corner
/// opposite), which vertices lie on it and its components.
#[allow(clippy::type_complexity)]
fn boundary_surfaces(
    mesh: &TetMesh,
    neighbours: &[[u32; 4]],
) -> Result<(Vec<(u32, u8)>, Vec<bool>, Vec<BoundarySurface>), TetError> {
    let nv = mesh.verts.len();
    let mut boundary = Vec::new();
    for (t, nb) in neighbours.iter().enumerate() {
        for (i, &n) in nb.iter().enumerate() {
            if n == NO_TET {
                boundary.push((t as u32, i as u8));
            }
        }
    }
    let tris: Vec<[u32; 3]> = boundary
        .iter()
        .map(|&(t, i)| face_of(mesh, t as usize, i as usize))
        .collect();
    let mut bedges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * tris.len());
    for (k, tri) in tris.iter().enumerate() {
        for x in 0..3 {
            let (a, b) = (tri[x], tri[(x + 1) % 3]);
            bedges.push((a.min(b), a.max(b), k as u32));
        }
    }
    bedges.sort_unstable();
    let mut tri_parent: Vec<u32> = (0..tris.len() as u32).collect();
    let mut s = 0;
    while s < bedges.len() {
        let mut e = s + 1;
        while e < bedges.len() && bedges[e].0 == bedges[s].0 && bedges[e].1 == bedges[s].1 {
            e += 1;
        }
        if e - s != 2 {
            return Err(TetError::NonManifoldBoundaryEdge {
                edge: [bedges[s].0, bedges[s].1],
                triangles: bedges[s..e].iter().map(|x| tris[x.2 as usize]).collect(),
            });
        }
        union(&mut tri_parent, bedges[s].2, bedges[s + 1].2);
        s = e;
    }
    // Fans: corners (3k + x) joined across the boundary edges at their vertex.
    let mut spokes: Vec<(u32, u32, u32)> = Vec::with_capacity(6 * tris.len());
    for (k, tri) in tris.iter().enumerate() {
        for x in 0..3 {
            let corner = (3 * k + x) as u32;
            spokes.push((tri[x], tri[(x + 1) % 3], corner));
            spokes.push((tri[x], tri[(x + 2) % 3], corner));
        }
    }
    spokes.sort_unstable();
    let mut corner_parent: Vec<u32> = (0..3 * tris.len() as u32).collect();
    for pair in spokes.chunks_exact(2) {
        debug_assert_eq!((pair[0].0, pair[0].1), (pair[1].0, pair[1].1));
        union(&mut corner_parent, pair[0].2, pair[1].2);
    }
    let mut fans: Vec<(u32, u32)> = Vec::with_capacity(3 * tris.len());
    for (k, tri) in tris.iter().enumerate() {
        for x in 0..3 {
            fans.push((tri[x], find(&mut corner_parent, (3 * k + x) as u32)));
        }
    }
    fans.sort_unstable();
    fans.dedup();
    let mut vertex_on_boundary = vec![false; nv];
    let mut s = 0;
    while s < fans.len() {
        let mut e = s + 1;
        while e < fans.len() && fans[e].0 == fans[s].0 {
            e += 1;
        }
        if e - s > 1 {
            return Err(TetError::NonManifoldVertex {
                vertex: fans[s].0,
                fans: e - s,
            });
        }
        vertex_on_boundary[fans[s].0 as usize] = true;
        s = e;
    }
    // Boundary components: F, E = 3F/2, V (each boundary vertex in one component).
    let mut comp_of_root = std::collections::HashMap::new();
    let mut boundary_surfaces: Vec<BoundarySurface> = Vec::new();
    let mut tri_comp = vec![0usize; tris.len()];
    for k in 0..tris.len() {
        let r = find(&mut tri_parent, k as u32);
        let c = *comp_of_root.entry(r).or_insert_with(|| {
            boundary_surfaces.push(BoundarySurface {
                triangles: 0,
                edges: 0,
                vertices: 0,
                euler_characteristic: 0,
                genus: 0,
                first_triangle: k,
            });
            boundary_surfaces.len() - 1
        });
        tri_comp[k] = c;
        boundary_surfaces[c].triangles += 1;
    }
    let mut vertex_seen = vec![false; nv];
    for (k, tri) in tris.iter().enumerate() {
        for &v in tri {
            if !vertex_seen[v as usize] {
                vertex_seen[v as usize] = true;
                boundary_surfaces[tri_comp[k]].vertices += 1;
            }
        }
    }
    for s in &mut boundary_surfaces {
        s.edges = 3 * s.triangles / 2;
        s.euler_characteristic = s.vertices as i64 - s.edges as i64 + s.triangles as i64;
        s.genus = (2 - s.euler_characteristic) / 2;
    }
    Ok((boundary, vertex_on_boundary, boundary_surfaces))
}

/// The unique edges with their stars, as [`Topology`] holds them.
struct EdgeStars {
    edges: Vec<[u32; 2]>,
    tet_edges: Vec<[u32; 6]>,
    star_offsets: Vec<usize>,
    star_tets: Vec<u32>,
    edge_on_boundary: Vec<bool>,
}

/// Edges and their stars: each edge's tetrahedra, walked around it in order; an edge whose
/// walk does not reach all its tetrahedra is non-manifold.
fn edge_stars(mesh: &TetMesh, neighbours: &[[u32; 4]]) -> Result<EdgeStars, TetError> {
    let nt = mesh.tets.len();
    let mut inc: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(6 * nt);
    for (t, tet) in mesh.tets.iter().enumerate() {
        for (k, &[i, j]) in TET_EDGES.iter().enumerate() {
            let (a, b) = (tet[i], tet[j]);
            inc.push((a.min(b), a.max(b), t as u32, k as u8));
        }
    }
    inc.sort_unstable();
    let mut edges: Vec<[u32; 2]> = Vec::new();
    let mut tet_edges = vec![[0u32; 6]; nt];
    let mut star_offsets = vec![0usize];
    let mut star_tets: Vec<u32> = Vec::with_capacity(6 * nt);
    let mut edge_on_boundary = Vec::new();
    let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
    let mut s = 0;
    while s < inc.len() {
        let mut e = s + 1;
        while e < inc.len() && inc[e].0 == inc[s].0 && inc[e].1 == inc[s].1 {
            e += 1;
        }
        let id = edges.len() as u32;
        let (a, b) = (inc[s].0, inc[s].1);
        edges.push([a, b]);
        for x in &inc[s..e] {
            tet_edges[x.2 as usize][x.3 as usize] = id;
        }
        let m = e - s;
        let start = inc[s].2;
        fwd.clear();
        bwd.clear();
        fwd.push(start);
        let mut t = start;
        let mut closed = false;
        loop {
            let tet = &mesh.tets[t as usize];
            let [c, _] = star_wedge(*tet, a, b);
            let n = neighbours[t as usize][local(tet, c)];
            if n == NO_TET {
                break;
            }
            if n == start {
                closed = true;
                break;
            }
            fwd.push(n);
            t = n;
            if fwd.len() > m {
                break;
            }
        }
        if !closed {
            let mut t = start;
            loop {
                let tet = &mesh.tets[t as usize];
                let [_, d] = star_wedge(*tet, a, b);
                let p = neighbours[t as usize][local(tet, d)];
                if p == NO_TET || p == start || fwd.len() + bwd.len() > m {
                    break;
                }
                bwd.push(p);
                t = p;
            }
        }
        let walked = fwd.len() + bwd.len();
        if walked != m {
            return Err(TetError::NonManifoldEdge {
                edge: [a, b],
                tets: m,
                start,
                walked,
            });
        }
        star_tets.extend(bwd.iter().rev());
        star_tets.extend(&fwd);
        star_offsets.push(star_tets.len());
        edge_on_boundary.push(!closed);
        s = e;
    }
    Ok(EdgeStars {
        edges,
        tet_edges,
        star_offsets,
        star_tets,
        edge_on_boundary,
    })
}

/// One solid: the tetrahedra are face-connected.
fn check_one_solid(neighbours: &[[u32; 4]]) -> Result<(), TetError> {
    let nt = neighbours.len();
    let mut comp = vec![u32::MAX; nt];
    let mut components = 0usize;
    let mut second = None;
    let mut queue = Vec::new();
    for seed in 0..nt {
        if comp[seed] != u32::MAX {
            continue;
        }
        if components == 1 {
            second = Some(seed as u32);
        }
        comp[seed] = components as u32;
        queue.push(seed as u32);
        while let Some(t) = queue.pop() {
            for &n in &neighbours[t as usize] {
                if n != NO_TET && comp[n as usize] == u32::MAX {
                    comp[n as usize] = components as u32;
                    queue.push(n);
                }
            }
        }
        components += 1;
    }
    if let Some(second) = second {
        return Err(TetError::Disconnected { components, second });
    }
    Ok(())
}

#[cfg(test)]
mod tests;
