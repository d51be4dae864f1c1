//! The PLY mesh reader: vertices and triangulated faces, for `scanflow check`, the spline
//! stage's parameterisation graph and tests (reached through [`crate::mesh_read`], which also
//! reads OBJ and STL).
//!
//! [`read_mesh`] wants a `face` element; [`read_scan_mesh`] takes the triangles of a scan from
//! its `face` element, else from its `range_grid` element (Stanford range scans, triangulated
//! by `range_grid.rs`), else gives none. The `range_grid` entries are read by the same record
//! readers as faces (`faces.rs`, through its `ListSink`), so their errors name the entry and
//! its byte or line the same way.
//!
//! Vertices come through [`PlyReader`] (any property order and scalar type, ascii or binary
//! of either endianness). Faces come from the `face` element's list property
//! `vertex_indices` (or `vertex_index`): any integer count and index types; polygons with
//! more than three corners are fan-triangulated, `(v0, v1, v2, v3)` giving `(v0, v1, v2)` and
//! `(v0, v2, v3)`, which keeps their winding. Other face properties (`flags`, `quality`, other
//! lists), before or after the index list, are skipped by size; elements other than `vertex`
//! and `face` are skipped.
//!
//! Ascii files hold one record per line, as [`PlyReader`] assumes too; a face line with fewer
//! or more values than its properties call for is an error. Errors name the file, the face
//! (0-based) and its byte (binary) or line (ascii), counted from the start of the file.
//!
//! The whole mesh is held in memory (24 bytes a vertex, 12 a triangle); the file is streamed
//! through a buffered reader.
//!
//! `faces.rs` reads the `face` element (and any element of index lists), `range_grid.rs`
//! triangulates a range grid; this file reads the vertices and drives them.

mod faces;
mod range_grid;

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use super::header::HEADER_LIMIT;
use super::{Encoding, PlyHeader, PlyReader, parse_header};
use crate::PointReader;
use crate::error::{Error, IoContext, Location, Result};
use crate::mesh::Mesh;
use crate::types::PointBatch;
use faces::{FaceLayout, FaceSink, ListSink, Source, read_ascii_faces, read_binary_faces};

/// Vertices per chunk when reading them through [`PlyReader`].
const VERTEX_CHUNK: u64 = 1 << 20;
/// Buffer of the face reader.
const BUF_BYTES: usize = 1 << 20;

/// Number of records of the `face` element of a PLY file: `None` when the file is not a PLY
/// (does not start with `ply`) or declares no `face` element.
pub fn ply_face_count(path: &Path) -> Result<Option<u64>> {
    crate::regular_file(path, "a PLY file")?;
    let mut f = File::open(path).with_path(path)?;
    let mut head = Vec::new();
    (&mut f)
        .take(HEADER_LIMIT as u64)
        .read_to_end(&mut head)
        .with_path(path)?;
    if !head.starts_with(b"ply") {
        return Ok(None);
    }
    let header = parse_header(path, &head)?;
    Ok(header
        .elements
        .iter()
        .find(|e| e.name == "face")
        .map(|e| e.count))
}

/// Read a PLY mesh: its vertices and its faces, fan-triangulated.
///
/// A file without a `face` element is an error ("has no faces: expected a mesh"); one whose
/// `face` element has no record gives a mesh without triangles. Face indices must be
/// non-negative and below the vertex count, and every face must have at least 3 corners.
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    let reader = PlyReader::open(path)?;
    if !reader.header().elements.iter().any(|e| e.name == "face") {
        return Err(Error::input(
            path,
            "has no faces: expected a mesh (the PLY header declares no \"face\" element)",
        ));
    }
    read_scan_mesh_from(path, reader)
}

/// Read a scan's PLY as a mesh: its vertices, and triangles from its `face` element when it
/// has one (as [`read_mesh`]), else from its `range_grid` element (Stanford range scans, see
/// `range_grid.rs`: two triangles per 2×2 block of present pixels, one where three are
/// present), else none.
pub fn read_scan_mesh(path: &Path) -> Result<Mesh> {
    read_scan_mesh_from(path, PlyReader::open(path)?)
}

/// [`read_scan_mesh`] on an opened reader.
fn read_scan_mesh_from(path: &Path, reader: PlyReader) -> Result<Mesh> {
    let header = reader.header().clone();
    let n_vertices = reader.len();
    if n_vertices > u64::from(u32::MAX) + 1 {
        return Err(Error::input(
            path,
            format!(
                "has {n_vertices} vertices, more than the 2^32 that 32-bit triangle indices can address"
            ),
        ));
    }
    let face_at = header.elements.iter().position(|e| e.name == "face");
    let grid_at = header.elements.iter().position(|e| e.name == "range_grid");
    // Check the element's layout before reading the vertices.
    let layout = match (face_at, grid_at) {
        (Some(at), _) => Some((at, FaceLayout::new(path, &header.elements[at])?)),
        (None, Some(at)) => Some((
            at,
            FaceLayout::of(
                path,
                &header.elements[at],
                "range_grid entry",
                "range_grid entries",
            )?,
        )),
        (None, None) => None,
    };
    let grid = match (face_at, grid_at) {
        (None, Some(at)) => Some(range_grid::grid_size(path, &header, &header.elements[at])?),
        _ => None,
    };

    let mut vertices = Vec::with_capacity(n_vertices as usize);
    let mut batch = PointBatch::default();
    for chunk in reader.chunks(VERTEX_CHUNK)? {
        batch.clear();
        reader.read_chunk(&chunk, false, &mut batch)?;
        vertices.extend_from_slice(&batch.pos);
    }
    drop(batch);
    let Some((at, layout)) = layout else {
        return Ok(Mesh {
            vertices,
            triangles: Vec::new(),
        });
    };
    let start = reader.element_start(at);
    drop(reader);
    let count = header.elements[at].count;
    let triangles = match grid {
        None => {
            let mut faces = FaceSink {
                n_vertices,
                triangles: Vec::new(),
                polygon: Vec::new(),
            };
            read_lists(path, &header, at, start, &layout, &mut faces)?;
            faces.triangles
        }
        Some(size) => {
            let mut pixels = range_grid::PixelSink::new(n_vertices, count);
            read_lists(path, &header, at, start, &layout, &mut pixels)?;
            range_grid::triangulate(size, &pixels.pixels, &vertices)
        }
    };
    Ok(Mesh {
        vertices,
        triangles,
    })
}

/// Read the index lists of element `at` of `header` into `sink`. In a binary file its records
/// start at `start` ([`PlyReader::element_start`]); in an ascii one the lines before them are
/// counted.
fn read_lists(
    path: &Path,
    header: &PlyHeader,
    at: usize,
    start: Option<u64>,
    layout: &FaceLayout,
    sink: &mut impl ListSink,
) -> Result<()> {
    let el = &header.elements[at];
    let file = File::open(path).with_path(path)?;
    let file_len = file.metadata().with_path(path)?.len();
    let mut src = Source {
        path,
        r: BufReader::with_capacity(BUF_BYTES, file),
        pos: 0,
        file_len,
    };
    match header.encoding {
        Encoding::Ascii => {
            src.seek(header.data_start)?;
            let skip = header.elements[..at]
                .iter()
                .fold(0u64, |s, e| s.saturating_add(e.count));
            let mut line = header.lines;
            for _ in 0..skip {
                if !src.skip_line()? {
                    return Err(Error::format(
                        path,
                        Location::Line(line + 1),
                        format!(
                            "truncated: the file ends after {} data lines, before the {} \"{}\" lines the header promises",
                            line - header.lines,
                            el.count,
                            el.name
                        ),
                    ));
                }
                line += 1;
            }
            read_ascii_faces(&mut src, layout, el.count, line, sink)
        }
        Encoding::BinaryLe | Encoding::BinaryBe => {
            let be = header.encoding.big_endian();
            src.seek(start.expect("a binary file's element starts are found when it is opened"))?;
            read_binary_faces(&mut src, layout, el.count, be, sink)
        }
    }
}

#[cfg(test)]
mod tests;
