//! [`TetError`]: why a tetrahedral mesh is not a valid single solid, one variant per check of
//! the module docs of [`super`], each naming the offending elements, and the vertex where a
//! problem lies.

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
