//! Tests of the PLY point reader: binary files of either endianness with properties in any
//! order, ascii files with an element before `vertex`, and every prefix and header error.

use super::*;

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn read_all(r: &dyn PointReader, target: u64) -> PointBatch {
    let mut b = PointBatch::default();
    for c in r.chunks(target).unwrap() {
        r.read_chunk(&c, false, &mut b).unwrap();
    }
    b
}

fn binary_ply(be: bool, n: usize) -> Vec<u8> {
    let mut v = format!(
        "ply\nformat binary_{}_endian 1.0\nelement camera 1\nproperty float a\nproperty int b\nelement vertex {n}\nproperty uchar red\nproperty double z\nproperty float y\nproperty short x\nproperty uchar green\nproperty uchar blue\nproperty float confidence\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n",
        if be { "big" } else { "little" }
    )
    .into_bytes();
    let put = |v: &mut Vec<u8>, b: &[u8]| {
        if be {
            v.extend(b.iter().rev())
        } else {
            v.extend(b)
        }
    };
    put(&mut v, &1.5f32.to_le_bytes());
    put(&mut v, &7i32.to_le_bytes());
    for i in 0..n {
        v.push(255);
        put(&mut v, &(i as f64 * 0.5).to_le_bytes());
        put(&mut v, &(-(i as f32)).to_le_bytes());
        put(&mut v, &(i as i16).to_le_bytes());
        v.push(0);
        v.push(51);
        put(&mut v, &0.25f32.to_le_bytes());
    }
    for face in [[0i32, 1, 2], [2, 1, 0]] {
        v.push(3);
        for k in face {
            put(&mut v, &k.to_le_bytes());
        }
    }
    v
}

#[test]
fn binary_any_order_both_endians() {
    let d = tempfile::tempdir().unwrap();
    for be in [false, true] {
        let p = write(d.path(), "a.ply", &binary_ply(be, 10));
        let r = PlyReader::open(&p).unwrap();
        assert_eq!(r.len(), 10);
        assert!(r.attributes().color && r.attributes().confidence && !r.attributes().normal);
        let b = read_all(&r, 3);
        assert_eq!(b.len(), 10);
        assert_eq!(b.pos[4], [4.0, -4.0, 2.0]);
        assert_eq!(b.color[4], [65535, 0, 51 * 257, 65535]);
        assert_eq!(b.confidence[9], 0.25);
    }
}

#[test]
fn every_prefix_fails_cleanly() {
    let d = tempfile::tempdir().unwrap();
    let full = binary_ply(false, 4);
    for len in 0..full.len() {
        let p = write(d.path(), "t.ply", &full[..len]);
        let e = match crate::open(&p) {
            Ok(_) => panic!("prefix of {len} bytes opened"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("t.ply"), "{e}");
    }
    let p = write(d.path(), "t.ply", &full);
    assert!(crate::open(&p).is_ok());
}

#[test]
fn ascii_with_element_before_vertex() {
    let d = tempfile::tempdir().unwrap();
    let mut s = String::from(
        "ply\r\nformat ascii 1.0\r\ncomment hi\r\nelement cam 2\r\nproperty float a\r\nelement vertex 5\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nproperty float nx\r\nproperty float ny\r\nproperty float nz\r\nelement range_grid 3\r\nproperty list uchar int vertex_indices\r\nend_header\r\n1\r\n2\r\n",
    );
    for i in 0..5 {
        s += &format!("{i} 1 2 0 0 1\r\n");
    }
    s += "0\n1 3\n0\n";
    let p = write(d.path(), "a.ply", s.as_bytes());
    let r = PlyReader::open(&p).unwrap();
    assert_eq!(r.format(), Format::PlyAscii);
    let b = read_all(&r, 2);
    assert_eq!(b.len(), 5);
    assert_eq!(b.pos[3], [3.0, 1.0, 2.0]);
    assert_eq!(b.normal[3], [0.0, 0.0, 1.0]);
}

#[test]
fn ascii_nan_names_element_and_line() {
    let d = tempfile::tempdir().unwrap();
    let s = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 nan 0\n2 2 2\n";
    let p = write(d.path(), "n.ply", s.as_bytes());
    let r = PlyReader::open(&p).unwrap();
    let c = r.chunks(100).unwrap();
    let mut b = PointBatch::default();
    let e = r.read_chunk(&c[0], false, &mut b).unwrap_err().to_string();
    assert!(
        e.contains("element 1 (line 9)") && e.contains("y is NaN"),
        "{e}"
    );
    let mut b = PointBatch::default();
    let st = r.read_chunk(&c[0], true, &mut b).unwrap();
    assert_eq!((st.skipped_invalid, b.len()), (1, 2));
}

#[test]
fn header_errors() {
    let d = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str)] = &[
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
            "no end_header",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int x\nend_header\n",
            "list property",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
            "unknown property type",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n0 0\n",
            "no x property",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
            "promises 3 vertices",
        ),
        ("ply\nformat xml 1.0\nend_header\n", "unknown PLY format"),
        ("plx\n", "not a PLY"),
    ];
    for (text, want) in cases {
        let p = write(d.path(), "h.ply", text.as_bytes());
        let e = PlyReader::open(&p)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains(want) && e.contains("h.ply"), "{text:?}: {e}");
    }
}

#[test]
fn zero_vertices_is_empty() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "z.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    );
    let r = PlyReader::open(&p).unwrap();
    assert!(r.is_empty());
    assert!(r.chunks(10).unwrap().is_empty());
}
