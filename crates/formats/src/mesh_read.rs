//! Mesh reading, whatever the format: the [`Mesh`] every reader returns, and
//! [`read_any_mesh`], which picks the reader by extension ([`MeshFile::of`]): OBJ
//! ([`crate::obj`]), STL ([`crate::stl`]) or PLY ([`crate::ply`], whose mesh reader gives
//! [`read_mesh`], [`read_scan_mesh`] and [`ply_face_count`], re-exported here).

use std::path::Path;

use crate::error::Result;
pub use crate::ply::{ply_face_count, read_mesh, read_scan_mesh};

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
    /// [`read_mesh`] never returns such a mesh; hand-built ones may hold one.
    pub fn check_indices(&self) -> Option<(usize, u32)> {
        let n = self.vertices.len();
        self.triangles
            .iter()
            .enumerate()
            .find_map(|(t, tri)| tri.iter().find(|&&v| v as usize >= n).map(|&v| (t, v)))
    }
}

/// The mesh file formats scanflow reads, by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFile {
    /// PLY (any other extension too: PLY files are recognised by their content).
    Ply,
    /// Wavefront OBJ ([`crate::obj`]).
    Obj,
    /// STL, binary or ASCII ([`crate::stl`]).
    Stl,
}

impl MeshFile {
    /// The format of `path`: `.obj` and `.stl` (ASCII case ignored) by their extension, PLY
    /// otherwise.
    pub fn of(path: &Path) -> MeshFile {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if ext.eq_ignore_ascii_case("obj") {
            MeshFile::Obj
        } else if ext.eq_ignore_ascii_case("stl") {
            MeshFile::Stl
        } else {
            MeshFile::Ply
        }
    }
}

/// Read a triangle mesh in any format scanflow reads: OBJ and STL by their extension
/// ([`MeshFile::of`]), PLY otherwise ([`read_mesh`]).
pub fn read_any_mesh(path: &Path) -> Result<Mesh> {
    match MeshFile::of(path) {
        MeshFile::Obj => crate::obj::read_obj(path),
        MeshFile::Stl => crate::stl::read_stl(path),
        MeshFile::Ply => read_mesh(path),
    }
}

/// Whether `path` holds a mesh with faces: an OBJ or STL file by its extension, or a PLY
/// file with face records.
pub fn is_mesh_file(path: &Path) -> Result<bool> {
    match MeshFile::of(path) {
        MeshFile::Obj | MeshFile::Stl => Ok(true),
        MeshFile::Ply => Ok(ply_face_count(path)?.unwrap_or(0) > 0),
    }
}
