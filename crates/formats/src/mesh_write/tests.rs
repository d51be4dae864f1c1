//! Tests of the streamed mesh writer: each format read back, normals, islands, failures.

use super::ply::header;
use super::*;
use crate::PointReader;
use crate::ply::PlyReader;
use crate::types::PointBatch;

const TETRA: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
];
/// Outward (counter-clockwise seen from outside).
const TETRA_FACES: [[u64; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

fn ply_header_bytes(color: bool) -> usize {
    header_bytes(VertexFormat {
        color,
        ..VertexFormat::default()
    })
}

fn write_tetra(path: &Path, color: bool) -> MeshWriteStats {
    let mut w = MeshWriter::ply(path, color).unwrap();
    for (i, p) in TETRA.iter().enumerate() {
        let c = [10 * i as u8, 100, 255 - i as u8];
        w.vertex(*p, Some(c)).unwrap();
    }
    for t in TETRA_FACES {
        w.triangle(t).unwrap();
    }
    assert_eq!((w.vertices(), w.triangles()), (4, 4));
    w.finish().unwrap()
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn tetrahedron_round_trips() {
    for color in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let stats = write_tetra(&path, color);
        assert_eq!(names(dir.path()), vec!["t.ply".to_string()]);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(stats.vertices, 4);
        assert_eq!(stats.faces, 4);
        assert_eq!(stats.bytes, bytes.len() as u64);

        let hb = ply_header_bytes(color);
        let text = std::str::from_utf8(&bytes[..hb]).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let mut want = vec![
            "ply",
            "format binary_little_endian 1.0",
            "comment written by scanflow",
            lines[3],
            "element vertex 4",
            "property float x",
            "property float y",
            "property float z",
        ];
        if color {
            want.extend([
                "property uchar red",
                "property uchar green",
                "property uchar blue",
            ]);
        }
        want.extend([
            "element face 4",
            "property list uchar int vertex_indices",
            "end_header",
        ]);
        assert_eq!(lines, want);
        assert!(lines[3].starts_with("comment ") && lines[3].trim() == "comment");
        assert!(text.ends_with("end_header\n"));

        let stride = if color { 15 } else { 12 };
        let faces = &bytes[hb + 4 * stride..];
        assert_eq!(faces.len(), 4 * 13);
        for (f, t) in faces.chunks(13).zip(TETRA_FACES) {
            assert_eq!(f[0], 3);
            for k in 0..3 {
                let i = i32::from_le_bytes(f[1 + 4 * k..5 + 4 * k].try_into().unwrap());
                assert_eq!(i as u64, t[k]);
            }
        }
        if color {
            assert_eq!(&bytes[hb + 12..hb + 15], &[0, 100, 255]);
            assert_eq!(&bytes[hb + 3 * 15 + 12..hb + 4 * 15], &[30, 100, 252]);
        }

        // Our own reader: it walks the face lists at open, then reads the vertices.
        let r = PlyReader::open(&path).unwrap();
        assert_eq!(r.len(), 4);
        assert_eq!(r.header().elements[1].name, "face");
        assert_eq!(r.header().elements[1].count, 4);
        assert_eq!(r.header().data_start as usize, hb);
        let mut batch = PointBatch::default();
        for c in r.chunks(1000).unwrap() {
            r.read_chunk(&c, false, &mut batch).unwrap();
        }
        assert_eq!(batch.pos, TETRA.to_vec());
        if color {
            assert_eq!(batch.color[1][0], 10 * 257);
        }
        plyfile_check(&path, 4, 4);
    }
}

/// Read `path` with Python's plyfile, when installed, and compare the counts.
fn plyfile_check(path: &Path, vertices: usize, faces: usize) {
    let probe = std::process::Command::new("python3")
        .args(["-c", "import plyfile"])
        .output();
    match probe {
        Ok(o) if o.status.success() => {}
        _ => {
            eprintln!("skipping the plyfile check: python3 with plyfile is not available");
            return;
        }
    }
    let script = "import sys, plyfile\n\
                  d = plyfile.PlyData.read(sys.argv[1])\n\
                  f = d['face']['vertex_indices']\n\
                  assert all(len(t) == 3 for t in f)\n\
                  print(len(d['vertex']), len(f))";
    let out = std::process::Command::new("python3")
        .args(["-c", script])
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "plyfile failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = String::from_utf8(out.stdout).unwrap();
    assert_eq!(s.trim(), format!("{vertices} {faces}"));
}

#[test]
fn utm_coordinates_are_written_as_doubles_with_scalar_intensity() {
    // A 40 m cube at UTM-sized coordinates: float32 steps by 0.5 m there.
    let utm = VertexFormat::for_cube([5.0e6, 5.0e6, 100.0], 40.0, true, true);
    assert!(utm.double && utm.color && utm.intensity);
    // Near the origin float32 keeps far more than the extent needs.
    assert!(!VertexFormat::for_cube([-1.1, -1.1, -1.1], 2.2, false, false).double);
    assert!(!VertexFormat::for_cube([1e-30; 3], 1e-30, false, false).double);
    assert!(VertexFormat::for_cube([1e30; 3], 1.0, false, false).double);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("utm.ply");
    let mut w = MeshWriter::create(&path, MeshFormat::Ply, utm).unwrap();
    let ps = [
        [5.0e6 + 0.123456, 5.0e6 + 1.0, 100.25],
        [5.0e6 + 2.0, 5.0e6 + 0.000001, 101.0],
        [5.0e6, 5.0e6 + 3.5, 102.0],
    ];
    for (i, p) in ps.iter().enumerate() {
        w.vertex_with(*p, Some([i as u8, 2, 3]), Some(0.5 * i as f32), None)
            .unwrap();
    }
    w.triangle([0, 1, 2]).unwrap();
    let stats = w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let hb = header_bytes(utm);
    assert_eq!(stats.bytes as usize, hb + 3 * utm.stride() + 13);
    let text = std::str::from_utf8(&bytes[..hb]).unwrap();
    assert!(text.contains("property double x\nproperty double y\nproperty double z\n"));
    assert!(text.contains("property float scalar_intensity\n"));
    assert!(!text.contains(" intensity"));
    let m = crate::mesh_read::read_mesh(&path).unwrap();
    assert_eq!(m.vertices, ps.to_vec());
    plyfile_check(&path, 3, 1);
}

#[test]
fn empty_mesh_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("e.ply");
    let stats = MeshWriter::ply(&path, false).unwrap().finish().unwrap();
    assert_eq!(stats.bytes, ply_header_bytes(false) as u64);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("element vertex 0\n") && text.contains("element face 0\n"));
    plyfile_check(&path, 0, 0);
}

#[test]
fn header_size_is_fixed_and_index_type_follows_the_count() {
    for color in [false, true] {
        let n = ply_header_bytes(color);
        for (v, f) in [(0, 0), (4, 4), (1 << 31, 7), (u64::MAX, u64::MAX)] {
            let fmt = |intensity, double| VertexFormat {
                color,
                intensity,
                double,
                ..VertexFormat::default()
            };
            let h = header(v, f, fmt(false, false));
            for (i, d) in [(true, false), (false, true), (true, true)] {
                assert_eq!(header(v, f, fmt(i, d)).len(), header_bytes(fmt(i, d)));
            }
            assert_eq!(h.len(), n, "{v} {f}");
            let want = if v <= i32::MAX as u64 {
                " int "
            } else {
                " uint "
            };
            assert!(h.contains(&format!("property list uchar{want}vertex_indices")));
        }
        let f = VertexFormat {
            color,
            ..VertexFormat::default()
        };
        assert!(header(i32::MAX as u64, 1, f).contains("uchar int"));
        assert!(header(i32::MAX as u64 + 1, 1, f).contains("uchar uint"));
    }
}

#[test]
fn bad_triangles_and_vertices_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b.ply");
    let mut w = MeshWriter::ply(&path, true).unwrap();
    let e = w.vertex([0.0; 3], None).unwrap_err();
    assert!(matches!(e, Error::Usage(_)), "{e}");
    let e = w.vertex([0.0, f64::NAN, 0.0], Some([0; 3])).unwrap_err();
    assert!(e.to_string().contains("y is NaN"), "{e}");
    let e = w.vertex([1e300, 0.0, 0.0], Some([0; 3])).unwrap_err();
    assert!(matches!(e, Error::Usage(_)), "{e}");
    w.vertex([0.0; 3], Some([1, 2, 3])).unwrap();
    w.vertex([1.0; 3], Some([1, 2, 3])).unwrap();
    let e = w.triangle([0, 1, 2]).unwrap_err();
    assert!(matches!(e, Error::Internal(_)), "{e}");
    assert!(e.to_string().contains("vertex 2"), "{e}");
    w.vertex([2.0; 3], Some([1, 2, 3])).unwrap();
    w.triangle([0, 1, 2]).unwrap();
    let s = w.finish().unwrap();
    assert_eq!((s.vertices, s.faces), (3, 1));
    assert_eq!(names(dir.path()), vec!["b.ply".to_string()]);
}

#[test]
fn drop_without_finish_removes_both_temporary_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("d.ply");
    std::fs::write(&path, b"old").unwrap();
    {
        let mut w = MeshWriter::ply(&path, false).unwrap();
        w.vertex([0.0; 3], None).unwrap();
        w.triangle([0, 0, 0]).unwrap();
        assert_eq!(names(dir.path()).len(), 4);
    }
    assert_eq!(names(dir.path()), vec!["d.ply".to_string()]);
    assert_eq!(std::fs::read(&path).unwrap(), b"old");
}

#[test]
fn missing_directory_is_an_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no/such/m.ply");
    let e = MeshWriter::ply(&path, false).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
}

#[test]
fn larger_mesh_spans_buffers() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("l.ply");
    let mut w = MeshWriter::ply(&path, false).unwrap();
    let n = 100_000u64;
    for i in 0..n {
        w.vertex([i as f64, 0.0, -(i as f64)], None).unwrap();
    }
    for i in 0..n - 2 {
        w.triangle([i, i + 1, i + 2]).unwrap();
    }
    let s = w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(s.bytes as usize, bytes.len());
    let hb = ply_header_bytes(false);
    let last = &bytes[bytes.len() - 13..];
    assert_eq!(last[0], 3);
    assert_eq!(
        u32::from_le_bytes(last[9..13].try_into().unwrap()) as u64,
        n - 1
    );
    let v = hb + (n as usize - 1) * 12;
    assert_eq!(
        f32::from_le_bytes(bytes[v..v + 4].try_into().unwrap()),
        (n - 1) as f32
    );
    plyfile_check(&path, n as usize, n as usize - 2);
}

/// The tetrahedron in `format`, with normals given last-first and colours and densities.
fn write_tetra_as(path: &Path, format: MeshFormat, vf: VertexFormat) -> MeshWriteStats {
    let mut w = MeshWriter::create(path, format, vf).unwrap();
    for (i, p) in TETRA.iter().enumerate() {
        let c = [10 * i as u8, 100, 255 - i as u8];
        w.vertex_with(*p, Some(c), Some(i as f32), Some(0.25 + i as f32))
            .unwrap();
    }
    for t in TETRA_FACES {
        w.triangle(t).unwrap();
    }
    // Vertex 0 gets (0, 0, -1), the others their own direction.
    for i in (0..4u64).rev() {
        let p = TETRA[i as usize];
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let n = if l > 0.0 {
            p.map(|x| (x / l) as f32)
        } else {
            [0.0, 0.0, -1.0]
        };
        w.normal(i, n).unwrap();
    }
    w.finish().unwrap()
}

/// A tetrahedron a hundredth the size (vertices 0–3), the unit one (4–7), a lone vertex
/// (8): with islands under 1% of the area dropped, every format holds exactly the unit
/// tetrahedron, renumbered from 0, with its own normals and colours.
#[test]
fn dropped_islands_leave_every_format_with_the_large_piece() {
    let dir = tempfile::tempdir().unwrap();
    let vf = VertexFormat {
        color: true,
        normals: true,
        ..VertexFormat::default()
    };
    for (name, format) in [
        ("a.ply", MeshFormat::Ply),
        ("b.ply", MeshFormat::PlyAscii),
        ("c.obj", MeshFormat::Obj),
        ("d.stl", MeshFormat::Stl),
    ] {
        let path = dir.path().join(name);
        let vf = VertexFormat {
            normals: format != MeshFormat::Stl,
            ..vf
        };
        let mut w = MeshWriter::create(&path, format, vf).unwrap();
        w.drop_islands(0.01);
        let small = TETRA.map(|p| p.map(|x| 5.0 + 0.01 * x));
        for (k, p) in small.iter().chain(&TETRA).enumerate() {
            w.vertex(*p, Some([k as u8, 0, 0])).unwrap();
        }
        w.vertex([9.0; 3], Some([8, 0, 0])).unwrap();
        for base in [0, 4] {
            for t in TETRA_FACES {
                w.triangle(t.map(|i| i + base)).unwrap();
            }
        }
        if vf.normals {
            for i in 0..9 {
                w.normal(i, [0.0, 0.0, i as f32]).unwrap();
            }
        }
        let st = w.finish().unwrap();
        assert_eq!(st.bytes, std::fs::metadata(&path).unwrap().len(), "{name}");
        assert_eq!(st.faces, 4, "{name}");
        let m = crate::mesh_read::read_any_mesh(&path).unwrap();
        if format == MeshFormat::Stl {
            // STL's reader numbers corners as they come.
            let corners: Vec<[f64; 3]> = m
                .triangles
                .iter()
                .flat_map(|t| t.map(|i| m.vertices[i as usize]))
                .collect();
            let want: Vec<[f64; 3]> = TETRA_FACES
                .iter()
                .flat_map(|t| t.map(|i| TETRA[i as usize]))
                .collect();
            assert_eq!(corners, want);
            continue;
        }
        assert_eq!(m.vertices, TETRA.to_vec(), "{name}");
        assert_eq!(
            m.triangles,
            TETRA_FACES.map(|t| t.map(|i| i as u32)).to_vec(),
            "{name}"
        );
        if format == MeshFormat::Ply {
            assert_eq!(st.vertices, 4);
            let bytes = std::fs::read(&path).unwrap();
            let hb = header_bytes(vf);
            assert!(
                std::str::from_utf8(&bytes[..hb])
                    .unwrap()
                    .contains("element vertex 4\n")
            );
            // The first vertex written is staged vertex 4: its normal and colour.
            let rec = &bytes[hb..hb + vf.stride()];
            assert_eq!(f32::from_le_bytes(rec[20..24].try_into().unwrap()), 4.0);
            assert_eq!(rec[24], 4);
            plyfile_check(&path, 4, 4);
        }
    }
    assert_eq!(names(dir.path()), ["a.ply", "b.ply", "c.obj", "d.stl"]);
}

#[test]
fn islands_that_leave_nothing_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.ply");
    let mut w = MeshWriter::ply(&path, false).unwrap();
    w.drop_islands(0.6);
    for base in [0.0, 3.0] {
        for p in TETRA {
            w.vertex(p.map(|x| x + base), None).unwrap();
        }
    }
    for base in [0, 4] {
        for t in TETRA_FACES {
            w.triangle(t.map(|i| i + base)).unwrap();
        }
    }
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains("n.ply") && e.contains("2 pieces"), "{e}");
    assert!(names(dir.path()).is_empty());
}

#[test]
fn every_format_holds_the_tetrahedron() {
    let dir = tempfile::tempdir().unwrap();
    let all = VertexFormat {
        color: true,
        intensity: true,
        normals: true,
        density: true,
        double: false,
    };
    // Binary PLY with everything: the records in the header's order.
    let path = dir.path().join("a.ply");
    let s = write_tetra_as(&path, MeshFormat::Ply, all);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(s.bytes as usize, bytes.len());
    let hb = header_bytes(all);
    let text = std::str::from_utf8(&bytes[..hb]).unwrap();
    assert!(
        text.contains(
            "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"
        )
    );
    assert!(text.ends_with("property float scalar_intensity\nproperty float quality\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"));
    assert_eq!(all.stride(), 12 + 12 + 3 + 4 + 4);
    let v1 = &bytes[hb + all.stride()..hb + 2 * all.stride()];
    assert_eq!(f32::from_le_bytes(v1[0..4].try_into().unwrap()), 1.0);
    assert_eq!(f32::from_le_bytes(v1[12..16].try_into().unwrap()), 1.0);
    assert_eq!(&v1[24..27], &[10, 100, 254]);
    assert_eq!(f32::from_le_bytes(v1[27..31].try_into().unwrap()), 1.0);
    assert_eq!(f32::from_le_bytes(v1[31..35].try_into().unwrap()), 1.25);
    let m = crate::mesh_read::read_mesh(&path).unwrap();
    assert_eq!(m.vertices, TETRA.to_vec());
    plyfile_check(&path, 4, 4);

    // ASCII PLY: the same mesh, read back by our own reader.
    let path = dir.path().join("b.ply");
    write_tetra_as(&path, MeshFormat::PlyAscii, all);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("ply\nformat ascii 1.0\n"), "{text}");
    assert!(
        text.contains("\n1.0 0.0 0.0 1.0 0.0 0.0 10 100 254 1.0 1.25\n"),
        "{text}"
    );
    assert!(text.ends_with("\n3 1 2 3\n"), "{text}");
    let m = crate::mesh_read::read_mesh(&path).unwrap();
    assert_eq!(m.vertices, TETRA.to_vec());
    assert_eq!(m.triangles.len(), 4);
    plyfile_check(&path, 4, 4);

    // OBJ: colours in [0, 1], normals as `vn`, 1-based faces; no intensity or density.
    let path = dir.path().join("c.obj");
    let obj = VertexFormat {
        density: false,
        ..all
    };
    write_tetra_as(&path, MeshFormat::Obj, obj);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("\nv 1.0 0.0 0.0 0.039215688 0.39215687 0.99607843\n"),
        "{text}"
    );
    assert!(text.contains("\nvn 0.0 1.0 0.0\n"), "{text}");
    assert!(text.ends_with("f 2//2 3//3 4//4\n"), "{text}");
    let m = crate::obj::read_obj(&path).unwrap();
    assert_eq!(m.vertices, TETRA.to_vec());
    assert_eq!(
        m.triangles,
        TETRA_FACES.map(|t| t.map(|i| i as u32)).to_vec()
    );

    // STL: 80 + 4 + 50 bytes a triangle, outward unit normals, corners in order.
    let path = dir.path().join("d.stl");
    let stl = VertexFormat {
        normals: false,
        density: false,
        ..all
    };
    let s = write_tetra_as(&path, MeshFormat::Stl, stl);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes.len(), 84 + 4 * 50);
    assert_eq!(s.bytes as usize, bytes.len());
    assert!(!bytes.starts_with(b"solid"));
    assert_eq!(u32::from_le_bytes(bytes[80..84].try_into().unwrap()), 4);
    let f = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    // The first face, (0, 2, 1), lies in z = 0 and faces -z.
    assert_eq!([f(84), f(88), f(92)], [0.0, 0.0, -1.0]);
    assert_eq!([f(108), f(112), f(116)], [0.0, 1.0, 0.0]);
    let s3 = 1.0 / 3f32.sqrt();
    let last = 84 + 3 * 50;
    for k in 0..3 {
        assert!((f(last + 4 * k) - s3).abs() < 1e-6);
    }
    assert_eq!(names(dir.path()), ["a.ply", "b.ply", "c.obj", "d.stl"]);
}

#[test]
fn formats_follow_the_extension_and_refuse_what_they_cannot_hold() {
    let f = |p: &str, ascii| MeshFormat::for_path(Path::new(p), ascii);
    assert_eq!(f("x.ply", false).unwrap(), MeshFormat::Ply);
    assert_eq!(f("x.PLY", true).unwrap(), MeshFormat::PlyAscii);
    assert_eq!(f("x.Obj", false).unwrap(), MeshFormat::Obj);
    assert_eq!(f("x.stl", false).unwrap(), MeshFormat::Stl);
    let e = f("x.off", false).unwrap_err().to_string();
    assert!(e.contains("x.off") && e.contains("*.stl"), "{e}");
    let e = f("x.obj", true).unwrap_err().to_string();
    assert!(e.contains("`ascii`"), "{e}");
    let p = Path::new("m.stl");
    let e = MeshFormat::Stl
        .carries(p, true, false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("m.stl") && e.contains("`out_normals`"), "{e}");
    let e = MeshFormat::Obj
        .carries(p, false, true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("`density`"), "{e}");
    MeshFormat::Obj.carries(p, true, false).unwrap();
    MeshFormat::PlyAscii.carries(p, true, true).unwrap();
}

#[test]
fn missing_or_extra_normals_are_internal_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.ply");
    let vf = VertexFormat {
        normals: true,
        ..VertexFormat::default()
    };
    let mut w = MeshWriter::create(&path, MeshFormat::Ply, vf).unwrap();
    w.vertex([0.0; 3], None).unwrap();
    w.vertex([1.0; 3], None).unwrap();
    let e = w.normal(2, [0.0; 3]).unwrap_err();
    assert!(matches!(e, Error::Internal(_)), "{e}");
    w.normal(1, [0.0, 0.0, 1.0]).unwrap();
    let e = w.finish().unwrap_err();
    assert!(
        e.to_string().contains("1 normals given for 2 vertices"),
        "{e}"
    );
    assert!(names(dir.path()).is_empty());
}

#[test]
fn many_normals_in_scattered_order_land_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.ply");
    let vf = VertexFormat {
        normals: true,
        ..VertexFormat::default()
    };
    let mut w = MeshWriter::create(&path, MeshFormat::Ply, vf).unwrap();
    let n = 3 * NORMAL_BATCH as u64 + 7;
    for i in 0..n {
        w.vertex([i as f64, 0.0, 0.0], None).unwrap();
    }
    // A permutation of the vertices: i -> i * 7919 mod n (n is not a multiple of 7919).
    for k in 0..n {
        let i = k * 7919 % n;
        w.normal(i, [i as f32, 1.0, 2.0]).unwrap();
    }
    w.triangle([0, 1, 2]).unwrap();
    w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let hb = header_bytes(vf);
    for i in [0, 1, 12345, n - 1] {
        let o = hb + i as usize * 24 + 12;
        let nx = f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        assert_eq!(nx, i as f32);
    }
}
