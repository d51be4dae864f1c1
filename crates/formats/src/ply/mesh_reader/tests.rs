//! Tests of the PLY mesh reader: ascii and binary faces of any count and index type, fan
//! triangulation, every prefix, errors naming the face and its place, range grids, and the
//! meshes of the shared data set (when present).

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
    let Some(p) = shared("../../../shared/data/bunny/reconstruction/bun_zipper_res4.ply") else {
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
