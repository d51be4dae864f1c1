//! Volume meshes: tetrahedra read for the hex stage, hexahedra (and tetrahedra) written.
//!
//! # Reading ([`read`], chosen by extension, case-insensitive)
//!
//! * `.mesh`: MEDIT / INRIA ASCII (`medit.rs`). The file is a stream of whitespace-separated
//!   tokens (keywords and numbers may be split across lines any way), `#` starts a comment to
//!   the end of its line, reading stops at `End` or at the end of the file. Keywords:
//!   `MeshVersionFormatted` (1 to 4), `Dimension` (must be 3: a volume mesh), `Vertices`
//!   (x y z ref), `Tetrahedra` (4 + ref), `Hexahedra` (8 + ref), `Triangles` (3 + ref) are
//!   kept; `Edges` (2 + ref), `Quadrilaterals` (4 + ref), `Prisms` (6 + ref), `Pyramids`
//!   (5 + ref), `Corners`, `Ridges`, `RequiredVertices`, `RequiredEdges`,
//!   `RequiredTriangles`, `RequiredQuadrilaterals`, `RequiredTetrahedra`,
//!   `RequiredHexahedra` (1 each), `Normals`, `Tangents` (3 each), `NormalAtVertices` (2),
//!   `NormalAtTriangleVertices`, `NormalAtQuadrilateralVertices`, `TangentAtEdgeVertices`,
//!   `TangentAtEdges` (3 each) are skipped and counted. Higher-order element keywords
//!   (`TetrahedraP2`, `HexahedraQ2`, ...) are an error saying so; any other keyword is an
//!   error too (the size of its entries is unknown). Indices are 1-based. Without `End`, the
//!   file must end with whitespace (a line end) after its last number: a number touching
//!   the end of the file is taken for a cut one (a truncated file whose last number still
//!   reads as a number) and is an error. Binary `.meshb` is refused.
//! * `.msh`: gmsh MSH 4.1 (ASCII and binary, either endianness, data size 8) and MSH 2.x
//!   (2.0 to 2.2, ASCII and binary) (`msh/`). `$MeshFormat`, `$Nodes` and `$Elements` are
//!   read; every other section (`$Entities`, `$PhysicalNames`, `$NodeData`, ...) is skipped
//!   to its `$End…` line. Node tags may be sparse: they are mapped to 0-based indices in file
//!   order. Element types 4 (tetrahedron), 5 (hexahedron) and 2 (triangle) are kept, other
//!   linear or lower-dimensional types (lines, points, quadrangles, prisms, pyramids,
//!   higher-order surface and line elements) are skipped and counted; higher-order
//!   tetrahedra and hexahedra (types 11, 12, 17, 29–31, 92, 93) are an error, since only
//!   linear volume elements are supported. An element type gmsh does not define is skipped
//!   and counted in ASCII files and an error in binary ones (its record size is unknown).
//!   Every section must end with its `$End…` line, so a cut file is an error. MSH 4.0, 3.0
//!   and 1.0 are refused.
//! * `.vtk`: VTK legacy `DATASET UNSTRUCTURED_GRID`, ASCII and BINARY (big-endian), file
//!   versions up to 4.x (`CELLS n size`, counts inline) and 5.x (`CELLS` followed by
//!   `OFFSETS` and `CONNECTIVITY` arrays of `vtktypeint64` or `vtktypeint32`, as meshio and
//!   VTK 9 write) (`vtk.rs`). `POINTS n type` (any numeric type), `CELLS`, `CELL_TYPES` are
//!   read; cell types 10 (tetrahedron), 12 (hexahedron) and 5 (triangle) are kept, 11
//!   (`VTK_VOXEL`) is kept as a hexahedron (its points reordered to VTK order), other
//!   linear types are skipped and counted, quadratic, Lagrange and Bézier tetrahedra and
//!   hexahedra are an error. `FIELD` and `METADATA` blocks are skipped; reading stops at
//!   `POINT_DATA` or `CELL_DATA`. Indices are 0-based. An ASCII file that ends (without
//!   `POINT_DATA` or `CELL_DATA`) on a number touching the end of the file is taken for a
//!   cut one, as for MEDIT.
//!
//! Every error names the file and the place (a line in text, a byte in binary data, counted
//! from the start of the file), what was expected and what was found; every vertex index is
//! checked against the vertex count; no input makes a reader panic. The result is a
//! [`VolumeMesh`] with 0-based indices in the vertex order of [`crate::mesh`] (which
//! all three formats share), turned into a [`TetMesh`] or [`HexMesh`] by
//! [`VolumeMesh::into_tet_mesh`] / [`VolumeMesh::into_hex_mesh`].
//!
//! # Writing ([`write_hex`], [`write_tet`], chosen by extension)
//!
//! * `.vtk`: VTK legacy 4.2 BINARY (big-endian): `POINTS n double`, `CELLS`, `CELL_TYPES`
//!   (12 or 10) and, when given, `CELL_DATA` with one `SCALARS name double 1` per field.
//! * `.mesh`: MEDIT ASCII, `MeshVersionFormatted 2`, `Dimension 3`, `Vertices` (shortest
//!   round-trip decimal), `Hexahedra` or `Tetrahedra` (1-based), every reference 0, `End`.
//!   Cell data is not written.
//! * `.msh`: gmsh MSH 4.1 ASCII: one volume entity (tag 1) with its bounding box in
//!   `$Entities`, all nodes in one block (tags 1..n), all elements in one block of type 5 or
//!   4 (tags 1..m), and one `$ElementData` per field.
//!
//! Writers stream through a `BufWriter` over an [`AtomicFile`], so their memory is
//! independent of the mesh's size and nothing partial appears under the final name. They
//! refuse (before creating anything) a vertex index beyond the vertices, a coordinate that
//! is not finite, more vertices or cells than the formats' 32-bit counts hold, and cell data
//! whose length is not the number of cells or whose name is empty or holds whitespace or a
//! quote. Every reader reads back exactly what the writers write: the same vertices (bit
//! for bit) and cells.

mod medit;
mod msh;
mod scan;
mod vtk;

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Error, IoContext, Result};
use crate::fs::atomic::AtomicFile;
use crate::mesh::{HexMesh, TetMesh};

/// A volume mesh as read from a file: the kinds of cells the hex stage uses, 0-based.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VolumeMesh {
    /// Vertex positions.
    pub verts: Vec<[f64; 3]>,
    /// Tetrahedra (vertex order as in [`crate::mesh`]).
    pub tets: Vec<[u32; 4]>,
    /// Hexahedra (VTK order).
    pub hexes: Vec<[u32; 8]>,
    /// Triangles the file lists (usually its boundary or surface), kept for callers.
    pub triangles: Vec<[u32; 3]>,
    /// Other entries the file holds and the reader skipped (edges, corners, quadrangles,
    /// points, prisms, ...): a name for the kind, as the format calls it, and how many. Only
    /// kinds with at least one entry are listed, each once, in the order first met.
    pub skipped: Vec<(String, usize)>,
}

impl VolumeMesh {
    /// Count `n` skipped entries of kind `name`.
    fn skip(&mut self, name: &str, n: usize) {
        if n == 0 {
            return;
        }
        match self.skipped.iter_mut().find(|(k, _)| k == name) {
            Some((_, c)) => *c += n,
            None => self.skipped.push((name.to_string(), n)),
        }
    }

    /// The cells held, in words, for messages ("2 hexahedra and 6 triangles").
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        for (n, one, many) in [
            (self.tets.len(), "tetrahedron", "tetrahedra"),
            (self.hexes.len(), "hexahedron", "hexahedra"),
            (self.triangles.len(), "triangle", "triangles"),
        ] {
            if n > 0 {
                parts.push(format!("{n} {}", if n == 1 { one } else { many }));
            }
        }
        for (k, n) in &self.skipped {
            parts.push(format!("{n} {k} (skipped)"));
        }
        if parts.is_empty() {
            format!("{} vertices and no cells", self.verts.len())
        } else {
            format!("{} vertices, {}", self.verts.len(), parts.join(", "))
        }
    }

    /// The tetrahedral mesh: the vertices and tetrahedra. An error naming `path` (the file it
    /// was read from) when it holds no tetrahedra, or hexahedra besides them.
    pub fn into_tet_mesh(self, path: &Path) -> Result<TetMesh> {
        if self.tets.is_empty() || !self.hexes.is_empty() {
            let what = if self.tets.is_empty() {
                "holds no tetrahedra"
            } else {
                "holds hexahedra besides its tetrahedra"
            };
            return Err(Error::input(
                path,
                format!(
                    "{what}: expected a tetrahedral mesh, found {}",
                    self.describe()
                ),
            ));
        }
        Ok(TetMesh {
            verts: self.verts,
            tets: self.tets,
        })
    }

    /// The hexahedral mesh: the vertices and hexahedra. An error naming `path` when it holds
    /// no hexahedra, or tetrahedra besides them.
    pub fn into_hex_mesh(self, path: &Path) -> Result<HexMesh> {
        if self.hexes.is_empty() || !self.tets.is_empty() {
            let what = if self.hexes.is_empty() {
                "holds no hexahedra"
            } else {
                "holds tetrahedra besides its hexahedra"
            };
            return Err(Error::input(
                path,
                format!(
                    "{what}: expected a hexahedral mesh, found {}",
                    self.describe()
                ),
            ));
        }
        Ok(HexMesh {
            verts: self.verts,
            hexes: self.hexes,
        })
    }
}

/// The three formats, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Medit,
    Msh,
    Vtk,
}

const FORMATS: &str = ".mesh (MEDIT ASCII), .msh (gmsh) or .vtk (VTK legacy)";

/// The format of `path` by its extension, or an error listing the three.
fn format_of(path: &Path, reading: bool) -> Result<Format> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "mesh" => Ok(Format::Medit),
        "msh" => Ok(Format::Msh),
        "vtk" => Ok(Format::Vtk),
        "meshb" => Err(Error::input(
            path,
            "binary MEDIT (.meshb) is not supported: convert it to ASCII .mesh \
             (for example `meshio convert IN.meshb OUT.mesh`)",
        )),
        "vtu" => Err(Error::input(
            path,
            format!(
                "VTK XML (.vtu) is not supported: expected {FORMATS} \
                 (for example `meshio convert IN.vtu OUT.vtk`)"
            ),
        )),
        _ => Err(Error::input(
            path,
            format!(
                "unknown volume mesh format{}: expected {FORMATS}",
                if reading { "" } else { " to write" }
            ),
        )),
    }
}

/// Read a volume mesh, choosing the format by extension (`.mesh`, `.msh`, `.vtk`,
/// case-insensitive); see the [module docs](self) for what each reader takes and skips.
pub fn read(path: &Path) -> Result<VolumeMesh> {
    let format = format_of(path, true)?;
    crate::io::regular_file(path, "a volume mesh")?;
    let data = std::fs::read(path).with_path(path)?;
    if data.is_empty() {
        return Err(Error::input(path, "empty file (0 bytes)"));
    }
    match format {
        Format::Medit => medit::read(path, &data),
        Format::Msh => msh::read(path, &data),
        Format::Vtk => vtk::read(path, &data),
    }
}

/// The kind of cell a writer writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Cell {
    Tet,
    Hex,
}

impl Cell {
    /// Plural noun.
    fn plural(self) -> &'static str {
        match self {
            Cell::Tet => "tetrahedra",
            Cell::Hex => "hexahedra",
        }
    }
}

/// Write a hexahedral mesh, choosing the format by extension (`.vtk`, `.mesh`, `.msh`; see
/// the [module docs](self)). `cell_data` holds named per-hexahedron fields (one value per
/// hexahedron each), written to `.vtk` and `.msh` and ignored for `.mesh`.
pub fn write_hex(path: &Path, mesh: &HexMesh, cell_data: &[(&str, &[f64])]) -> Result<()> {
    write_cells(path, &mesh.verts, &mesh.hexes, Cell::Hex, cell_data)
}

/// Write a tetrahedral mesh, as [`write_hex`] does a hexahedral one.
pub fn write_tet(path: &Path, mesh: &TetMesh, cell_data: &[(&str, &[f64])]) -> Result<()> {
    write_cells(path, &mesh.verts, &mesh.tets, Cell::Tet, cell_data)
}

/// Check, then write, `cells` of kind `kind`.
fn write_cells<const K: usize>(
    path: &Path,
    verts: &[[f64; 3]],
    cells: &[[u32; K]],
    kind: Cell,
    cell_data: &[(&str, &[f64])],
) -> Result<()> {
    let format = format_of(path, false)?;
    check_for_write(path, verts, cells, kind, cell_data)?;
    let mut file = AtomicFile::create(path)?;
    let tmp = file.tmp_path().to_path_buf();
    {
        let mut w = BufWriter::with_capacity(1 << 16, file.file());
        match format {
            Format::Vtk => vtk::write(&mut w, verts, cells, kind, cell_data),
            Format::Medit => medit::write(&mut w, verts, cells, kind),
            Format::Msh => msh::write(&mut w, verts, cells, kind, cell_data),
        }
        .with_path(&tmp)?;
        w.flush().with_path(&tmp)?;
    }
    file.commit()
}

/// What a writer refuses: an index beyond the vertices, a coordinate that is not finite, more
/// vertices or cells than the formats' 32-bit integers hold, cell data of the wrong length or
/// with an unusable name.
fn check_for_write<const K: usize>(
    path: &Path,
    verts: &[[f64; 3]],
    cells: &[[u32; K]],
    kind: Cell,
    cell_data: &[(&str, &[f64])],
) -> Result<()> {
    if verts.len() > i32::MAX as usize || cells.len() > (i32::MAX as usize) / (K + 1) {
        return Err(Error::input(
            path,
            format!(
                "not written: {} vertices and {} {} are more than the formats' 32-bit counts hold",
                verts.len(),
                cells.len(),
                kind.plural()
            ),
        ));
    }
    if let Some((i, p)) = verts
        .iter()
        .enumerate()
        .find(|(_, p)| p.iter().any(|c| !c.is_finite()))
    {
        return Err(Error::input(
            path,
            format!(
                "not written: vertex {i} is ({}, {}, {}), expected finite coordinates",
                p[0], p[1], p[2]
            ),
        ));
    }
    for (c, cell) in cells.iter().enumerate() {
        if let Some(&v) = cell.iter().find(|&&v| v as usize >= verts.len()) {
            return Err(Error::input(
                path,
                format!(
                    "not written: cell {c} of the {}: vertex {v} is beyond the {} vertices",
                    kind.plural(),
                    verts.len()
                ),
            ));
        }
    }
    for (name, values) in cell_data {
        if values.len() != cells.len() {
            return Err(Error::input(
                path,
                format!(
                    "not written: cell data {name:?} has {} values, expected one per cell ({} {})",
                    values.len(),
                    cells.len(),
                    kind.plural()
                ),
            ));
        }
        if name.is_empty() || name.chars().any(|c| c.is_whitespace() || c == '"') {
            return Err(Error::input(
                path,
                format!(
                    "not written: cell data name {name:?} must be non-empty, without whitespace or quotes"
                ),
            ));
        }
    }
    Ok(())
}

/// `x` in the shortest decimal that reads back as the same `f64`, in plain notation for
/// moderate magnitudes and scientific notation otherwise (Rust's `{}` never uses an
/// exponent, which would spell 1e300 with 301 digits).
fn fmt_f64(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-5..1e16).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

#[cfg(test)]
mod tests;
