//! Mesh reading, whatever the format: [`read_any_mesh`], returning the [`Mesh`] of
//! [`crate::mesh`] (re-exported here), which picks the reader by extension ([`MeshFile::of`]): OBJ
//! ([`crate::obj`]), STL ([`crate::stl`]) or PLY ([`crate::ply`], whose mesh reader gives
//! [`read_mesh`], [`read_scan_mesh`] and [`ply_face_count`], re-exported here).

use std::path::Path;

use crate::error::Result;
pub use crate::mesh::Mesh;
pub use crate::ply::{ply_face_count, read_mesh, read_scan_mesh};

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
