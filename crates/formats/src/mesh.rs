//! The triangle mesh every mesh reader returns ([`crate::mesh_read`] picks the reader; OBJ,
//! STL and PLY each fill one) and the writers and tools take: shared vertices and
//! vertex-index triples. It sits below the readers so that none of them imports the
//! dispatcher that calls it.

/// A triangle mesh: positions and vertex-index triples, wound as stored.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions, in the file's units and frame.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices`, in file order (a polygon's fan in order).
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// The octahedron with corners ±e_i, faces wound outward: the smallest closed mesh,
    /// a fixture for the tests of meshes and pictures.
    pub fn octahedron() -> Mesh {
        let v = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let t = [
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        Mesh {
            vertices: v.to_vec(),
            triangles: t.to_vec(),
        }
    }

    /// The first triangle with an index not below the vertex count, as `(triangle, index)`.
    /// [`crate::mesh_read::read_mesh`] never returns such a mesh; hand-built ones may hold one.
    pub fn check_indices(&self) -> Option<(usize, u32)> {
        let n = self.vertices.len();
        self.triangles
            .iter()
            .enumerate()
            .find_map(|(t, tri)| tri.iter().find(|&&v| v as usize >= n).map(|&v| (t, v)))
    }
}
