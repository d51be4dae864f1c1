//! PLY mesh reader: vertices and triangulated faces, for `scanflow check`, the spline stage's
//! parameterisation graph and tests.
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

use crate::PointReader;
use crate::error::{Error, IoContext, Location, Result};
use crate::ply::{Encoding, PlyHeader, PlyReader, parse_header};
use crate::types::PointBatch;
use faces::{
    FaceLayout, FaceSink, ListSink, Source, read_ascii_faces, read_binary_faces,
    skip_binary_element,
};

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

/// Bytes read to find the header.
const HEADER_BYTES: u64 = 1 << 20;
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
        .take(HEADER_BYTES)
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
        (None, Some(at)) => Some(range_grid::grid_size(path, &header.elements[at])?),
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
    drop(reader);
    let Some((at, layout)) = layout else {
        return Ok(Mesh {
            vertices,
            triangles: Vec::new(),
        });
    };
    let count = header.elements[at].count;
    let triangles = match grid {
        None => {
            let mut faces = FaceSink {
                n_vertices,
                triangles: Vec::new(),
                polygon: Vec::new(),
            };
            read_lists(path, &header, at, &layout, &mut faces)?;
            faces.triangles
        }
        Some(size) => {
            let mut pixels = range_grid::PixelSink::new(n_vertices, count);
            read_lists(path, &header, at, &layout, &mut pixels)?;
            range_grid::triangulate(size, &pixels.pixels, &vertices)
        }
    };
    Ok(Mesh {
        vertices,
        triangles,
    })
}

/// Read the index lists of element `at` of `header` into `sink`.
fn read_lists(
    path: &Path,
    header: &PlyHeader,
    at: usize,
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
    src.seek(header.data_start)?;
    match header.encoding {
        Encoding::Ascii => {
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
            let be = header.encoding == Encoding::BinaryBe;
            for e in &header.elements[..at] {
                skip_binary_element(&mut src, e, be)?;
            }
            read_binary_faces(&mut src, layout, el.count, be, sink)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn err(p: &Path) -> String {
        match read_mesh(p) {
            Ok(m) => panic!("{} read as a mesh: {m:?}", p.display()),
            Err(e) => e.to_string(),
        }
    }

    const ASCII: &str = "ply\nformat ascii 1.0\ncomment a quad and a triangle\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nelement face 2\nproperty uchar flags\nproperty list uchar int vertex_indices\nproperty float quality\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 2 1\n0 1\n7 4 0 1 2 3 0.5\n1 3 1 2 4 0.25\n";

    #[test]
    fn ascii_quad_is_fan_triangulated() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "q.ply", ASCII.as_bytes());
        let m = read_mesh(&p).unwrap();
        assert_eq!(m.vertices.len(), 5);
        assert_eq!(m.vertices[4], [2.0, 2.0, 1.0]);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [1, 2, 4]]);
        assert_eq!(m.check_indices(), None);
        assert_eq!(ply_face_count(&p).unwrap(), Some(2));
    }

    /// A binary mesh: a `camera` and a list element before `vertex`, a list element between
    /// `vertex` and `face`, face properties before and after the index list.
    fn binary(be: bool, count_ty: &str, index_ty: &str, faces: &[&[i64]]) -> Vec<u8> {
        let mut v = format!(
            "ply\nformat binary_{}_endian 1.0\nelement camera 1\nproperty double a\nelement strip 2\nproperty list uchar int vertex_indices\nelement vertex 5\nproperty float y\nproperty double x\nproperty float z\nproperty int flags\nelement tristrips 1\nproperty list int int vertex_indices\nelement face {}\nproperty int flags\nproperty list {count_ty} {index_ty} vertex_index\nproperty list uchar float texcoord\nproperty float quality\nelement other 1\nproperty float w\nend_header\n",
            if be { "big" } else { "little" },
            faces.len()
        )
        .into_bytes();
        let put = |v: &mut Vec<u8>, b: &[u8]| {
            if be {
                v.extend(b.iter().rev())
            } else {
                v.extend(b)
            }
        };
        let int = |v: &mut Vec<u8>, ty: &str, x: i64| match ty {
            "uchar" | "uint8" => v.push(x as u8),
            "char" => v.push(x as i8 as u8),
            "short" => put(v, &(x as i16).to_le_bytes()),
            "ushort" => put(v, &(x as u16).to_le_bytes()),
            "int" => put(v, &(x as i32).to_le_bytes()),
            "uint" => put(v, &(x as u32).to_le_bytes()),
            _ => panic!("{ty}"),
        };
        put(&mut v, &1.5f64.to_le_bytes());
        for n in [2, 0] {
            v.push(n);
            for k in 0..n {
                put(&mut v, &(k as i32).to_le_bytes());
            }
        }
        for i in 0..5 {
            put(&mut v, &(i as f32 * 2.0).to_le_bytes());
            put(&mut v, &(i as f64).to_le_bytes());
            put(&mut v, &(-(i as f32)).to_le_bytes());
            put(&mut v, &7i32.to_le_bytes());
        }
        put(&mut v, &3i32.to_le_bytes());
        for k in [0i32, 1, 2] {
            put(&mut v, &k.to_le_bytes());
        }
        for (i, f) in faces.iter().enumerate() {
            put(&mut v, &(i as i32).to_le_bytes());
            int(&mut v, count_ty, f.len() as i64);
            for &k in *f {
                int(&mut v, index_ty, k);
            }
            v.push(i as u8);
            for t in 0..i {
                put(&mut v, &(t as f32).to_le_bytes());
            }
            put(&mut v, &0.5f32.to_le_bytes());
        }
        put(&mut v, &9f32.to_le_bytes());
        v
    }

    #[test]
    fn binary_any_types_both_endians() {
        let d = tempfile::tempdir().unwrap();
        let faces: &[&[i64]] = &[&[0, 1, 2, 3], &[4, 3, 2], &[0, 1, 2, 3, 4]];
        for be in [false, true] {
            for (cty, ity) in [
                ("uchar", "int"),
                ("ushort", "uint"),
                ("int", "ushort"),
                ("char", "uchar"),
            ] {
                let p = write(d.path(), "b.ply", &binary(be, cty, ity, faces));
                let m = read_mesh(&p).unwrap_or_else(|e| panic!("{be} {cty} {ity}: {e}"));
                assert_eq!(m.vertices.len(), 5);
                assert_eq!(m.vertices[3], [3.0, 6.0, -3.0]);
                assert_eq!(
                    m.triangles,
                    vec![
                        [0, 1, 2],
                        [0, 2, 3],
                        [4, 3, 2],
                        [0, 1, 2],
                        [0, 2, 3],
                        [0, 3, 4]
                    ],
                    "{be} {cty} {ity}"
                );
            }
        }
    }

    #[test]
    fn every_binary_prefix_fails_cleanly() {
        let d = tempfile::tempdir().unwrap();
        let full = binary(false, "uchar", "int", &[&[0, 1, 2], &[2, 3, 4, 0]]);
        // The trailing `other` element (4 bytes) is not read by the mesh reader, but
        // `PlyReader::open` checks every element's extent.
        for len in 0..full.len() {
            let p = write(d.path(), "t.ply", &full[..len]);
            let e = err(&p);
            assert!(e.contains("t.ply"), "{len}: {e}");
        }
        let p = write(d.path(), "t.ply", &full);
        assert_eq!(read_mesh(&p).unwrap().triangles.len(), 3);
    }

    #[test]
    fn ascii_prefixes_fail_cleanly() {
        let d = tempfile::tempdir().unwrap();
        // Every prefix that ends before the last face line starts (a cut inside the last
        // line can leave a valid shorter line).
        let last = ASCII.trim_end().rfind('\n').unwrap() + 1;
        for len in 0..last {
            let p = write(d.path(), "t.ply", &ASCII.as_bytes()[..len]);
            let e = err(&p);
            assert!(e.contains("t.ply"), "{len}: {e}");
        }
        let p = write(d.path(), "t.ply", &ASCII.as_bytes()[..last]);
        let e = err(&p);
        assert!(e.contains("line 23") && e.contains("truncated"), "{e}");
    }

    #[test]
    fn bad_faces_name_face_and_place() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            d.path(),
            "r.ply",
            &binary(false, "uchar", "int", &[&[0, 1, 2], &[0, 1, 5]]),
        );
        let e = err(&p);
        assert!(
            e.contains("r.ply")
                && e.contains("face 1: vertex index 5 is out of range")
                && e.contains("byte "),
            "{e}"
        );
        let p = write(
            d.path(),
            "n.ply",
            &binary(true, "uchar", "int", &[&[0, -1, 2]]),
        );
        let e = err(&p);
        assert!(e.contains("face 0: vertex index -1"), "{e}");
        let p = write(
            d.path(),
            "s.ply",
            &binary(false, "uchar", "int", &[&[0, 1]]),
        );
        let e = err(&p);
        assert!(
            e.contains("face 0 has 2 vertices, expected at least 3"),
            "{e}"
        );

        let cases: &[(&str, &str, &str)] = &[
            (
                "7 4 0 1 2 3 0.5",
                "7 4 0 1 2 9 0.5",
                "line 22: face 0: vertex index 9 is out of range",
            ),
            (
                "1 3 1 2 4 0.25",
                "1 3 1 2 4",
                "line 23: face 1: the line ends where property 3",
            ),
            (
                "1 3 1 2 4 0.25",
                "1 3 1 2 4 0.25 8",
                "line 23: face 1: the line has more values",
            ),
            (
                "1 3 1 2 4 0.25",
                "1 3 1 x 4 0.25",
                "line 23: face 1: a vertex index \"x\" is not an integer",
            ),
            ("1 3 1 2 4 0.25", "1 -3 1 2 4 0.25", "negative list length"),
            (
                "1 3 1 2 4 0.25",
                "1 3 1 2",
                "line 23: face 1: the line ends where a vertex index",
            ),
            ("element face 2\n", "", "has no faces: expected a mesh"),
            (
                "list uchar int vertex_indices",
                "list uchar float vertex_indices",
                "expected an integer type",
            ),
            (
                "list uchar int vertex_indices",
                "list uchar int corners",
                "no list property \"vertex_indices\"",
            ),
        ];
        for (from, to, want) in cases {
            let mut text = ASCII.replace(from, to);
            if to.is_empty() {
                // Without a face element the face lines are just trailing data.
                text = text
                    .replace("property uchar flags\n", "")
                    .replace("property list uchar int vertex_indices\n", "")
                    .replace("property float quality\n", "");
            }
            let p = write(d.path(), "a.ply", text.as_bytes());
            let e = err(&p);
            assert!(e.contains("a.ply") && e.contains(want), "{to:?}: {e}");
        }
    }

    #[test]
    fn empty_face_element_gives_no_triangles() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            d.path(),
            "e.ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
        );
        assert_eq!(read_mesh(&p).unwrap(), Mesh::default());
        assert_eq!(ply_face_count(&p).unwrap(), Some(0));
        let x = write(d.path(), "x.xyz", b"0 0 0\n");
        assert_eq!(ply_face_count(&x).unwrap(), None);
    }

    /// A file of the shared data set, or `None` (with the reason printed) when absent.
    fn shared(rel: &str) -> Option<PathBuf> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
        if p.is_file() {
            Some(p)
        } else {
            eprintln!("skipped: {} not found", p.display());
            None
        }
    }

    #[test]
    fn bunny_res4() {
        let Some(p) = shared("../../../shared/data/bunny/reconstruction/bun_zipper_res4.ply")
        else {
            return;
        };
        let m = read_mesh(&p).unwrap();
        assert_eq!((m.vertices.len(), m.triangles.len()), (453, 948));
        assert_eq!(m.vertices[0], [-0.0312216, 0.126304, 0.00514924]);
    }

    #[test]
    fn face000_with_flags_and_quality() {
        let Some(p) = shared("../../../shared/data/scans/face000.ply") else {
            return;
        };
        let m = read_mesh(&p).unwrap();
        assert_eq!((m.vertices.len(), m.triangles.len()), (85_849, 166_259));
        assert_eq!(m.check_indices(), None);
    }

    /// Directed edges used twice: 0 for a consistently wound manifold triangulation.
    fn repeated_directed_edges(t: &[[u32; 3]]) -> usize {
        let mut e: Vec<(u32, u32)> = t
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .collect();
        e.sort_unstable();
        e.windows(2).filter(|w| w[0] == w[1]).count()
    }

    /// A 3 × 3 range grid with the centre-right pixel empty, ascii.
    const GRID: &str = "ply\nformat ascii 1.0\nobj_info num_cols 3\nobj_info num_rows 3\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\nelement range_grid 9\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n2 0 0\n0 -1 0\n1 -1 0\n0 -2 0\n1 -2 0\n2 -2 0\n1 0\n1 1\n1 2\n1 3\n1 4\n0\n1 5\n1 6\n1 7\n";

    #[test]
    fn range_grid_is_triangulated_with_one_winding() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "g.ply", GRID.as_bytes());
        let m = read_scan_mesh(&p).unwrap();
        assert_eq!(m.vertices.len(), 8);
        assert_eq!(m.triangles.len(), 6);
        assert_eq!(repeated_directed_edges(&m.triangles), 0);
        for t in &m.triangles {
            let [a, b, c] = t.map(|v| m.vertices[v as usize]);
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            // Clockwise in the image, rows going down in y.
            assert!(area < 0.0, "{t:?}");
        }
        // read_mesh still wants faces; a point file gives no triangles.
        assert!(err(&p).contains("has no faces"));
        let pts = GRID.replace(
            "element range_grid 9\nproperty list uchar int vertex_indices\n",
            "",
        );
        let pts = &pts[..pts.find("1 0\n1 1").unwrap()];
        let q = write(d.path(), "p.ply", pts.as_bytes());
        let m = read_scan_mesh(&q).unwrap();
        assert_eq!((m.vertices.len(), m.triangles.len()), (8, 0));
        // With a face element, the faces win.
        let m = read_scan_mesh(&write(d.path(), "q.ply", ASCII.as_bytes())).unwrap();
        assert_eq!(m.triangles.len(), 3);
    }

    #[test]
    fn bad_range_grids_name_file_and_place() {
        let d = tempfile::tempdir().unwrap();
        let cases: &[(&str, &str, &str)] = &[
            (
                "\n1 4\n0\n",
                "\n2 4 1\n0\n",
                "line 24: range_grid entry 4 lists more than one",
            ),
            (
                "\n1 4\n0\n",
                "\n1 9\n0\n",
                "line 24: range_grid entry 4: vertex index 9 is out of range",
            ),
            (
                "obj_info num_cols 3\n",
                "obj_info num_cols 4\n",
                "line 9: range_grid has 9 entries, but num_cols 4",
            ),
            (
                "obj_info num_rows 3\n",
                "",
                "line 8: the range_grid element needs the header lines",
            ),
            (
                "obj_info num_rows 3\n",
                "obj_info num_rows x\n",
                "line 4: obj_info num_rows \"x\" is not a count",
            ),
            (
                "1 6\n1 7\n",
                "1 6\n",
                "truncated: the header promises 9 range_grid entries",
            ),
        ];
        for (from, to, want) in cases {
            assert!(GRID.contains(from), "{from:?}");
            let p = write(d.path(), "r.ply", GRID.replacen(from, to, 1).as_bytes());
            let e = match read_scan_mesh(&p) {
                Ok(m) => panic!("{to:?} read: {m:?}"),
                Err(e) => e.to_string(),
            };
            assert!(e.contains("r.ply") && e.contains(want), "{to:?}: {e}");
        }
    }

    #[test]
    fn bunny_range_scan_triangulated_from_its_range_grid() {
        let Some(p) = shared("../../../shared/data/bunny/bun000.ply") else {
            return;
        };
        let m = read_scan_mesh(&p).unwrap();
        assert_eq!(m.vertices.len(), 40_256);
        assert_eq!(m.check_indices(), None);
        assert_eq!(repeated_directed_edges(&m.triangles), 0);
        // Which way the triangles face: towards +z, the side the scan bulges to, for all but a few.
        let up = m
            .triangles
            .iter()
            .filter(|t| {
                let [a, b, c] = t.map(|v| m.vertices[v as usize]);
                (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) > 0.0
            })
            .count();
        eprintln!("bun000: {} triangles, {up} facing +z", m.triangles.len());
        assert_eq!(m.triangles.len(), 79_312);
        assert_eq!(up, 79_312 - 76);
    }
}
