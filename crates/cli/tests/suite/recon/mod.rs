//! Reconstruction: closed manifold meshes on the synthetic shapes, seams, determinism, the
//! global-solve oracle, bad input.

use super::common::*;
use scanflow::io::mesh_read::read_mesh;
use scanflow::metrics::check_mesh;
use std::path::{Path, PathBuf};

mod budget;
mod gpu;
mod levels;
mod resume;
mod weights;

fn synth(dir: &Path, shape: &str, n: u32, noise: f64) -> std::path::PathBuf {
    let ply = dir.join(format!("{shape}.ply"));
    ok(&[
        "synth",
        shape,
        "--points",
        &n.to_string(),
        "--noise",
        &noise.to_string(),
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    ply
}

fn recon(input: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["reconstruct", s(input), "-o", s(out), "--progress", "none"];
    args.extend_from_slice(extra);
    ok(&args)
}

#[test]
fn shapes_are_closed_manifold_single_components() {
    let d = tempfile::tempdir().unwrap();
    for (shape, depth) in [("sphere", "7"), ("torus", "7"), ("bumpy", "8")] {
        let ply = synth(d.path(), shape, 60_000, 0.0005);
        let out = d.path().join(format!("{shape}_mesh.ply"));
        recon(&ply, &out, &["--depth", depth]);
        let m = read_mesh(&out).unwrap();
        let c = check_mesh(&m);
        assert!(
            c.watertight && c.edge_manifold && c.oriented,
            "{shape}: {c:?}"
        );
        assert_eq!(c.components, 1, "{shape}: {c:?}");
        let truth = d.path().join(format!("{shape}.truth.json"));
        let rep: serde_json::Value = serde_json::from_str(&ok(&[
            "check",
            s(&out),
            "--truth",
            s(&truth),
            "--samples",
            "20000",
            "--json",
        ]))
        .unwrap();
        // Distances relative to the diagonal, both ways. Measured (mean, max): sphere
        // 7.5e-5, 4.6e-4; torus 1.2e-4, 5.1e-4; bumpy 9.7e-5, 7.5e-4. A voxel is about
        // 5.5e-3 of the diagonal at depth 7.
        let rel = &rep["comparison"]["relative"];
        for side in ["to_reference", "from_reference"] {
            let mean = rel[side]["mean"].as_f64().unwrap();
            let max = rel[side]["max"].as_f64().unwrap();
            assert!(mean < 2.5e-4, "{shape} {side}: mean {mean}: {rep}");
            assert!(max < 2e-3, "{shape} {side}: max {max}: {rep}");
        }
    }
}

/// A mesh's triangles by their corners' bits, each rotated to start at its smallest corner
/// (orientation kept), sorted: the same for the same triangles in any vertex order.
fn canonical_triangles(p: &Path) -> Vec<[[u64; 3]; 3]> {
    let m = read_mesh(p).unwrap();
    let key = |i: u32| {
        let v = m.vertices[i as usize];
        [v[0].to_bits(), v[1].to_bits(), v[2].to_bits()]
    };
    let mut tris: Vec<_> = m
        .triangles
        .iter()
        .map(|t| {
            let mut k = [key(t[0]), key(t[1]), key(t[2])];
            let r = (0..3).min_by_key(|&i| k[i]).unwrap();
            k.rotate_left(r);
            k
        })
        .collect();
    tris.sort();
    tris
}

#[test]
fn seams_and_threads_do_not_change_the_mesh() {
    let d = tempfile::tempdir().unwrap();
    let ply = synth(d.path(), "torus", 40_000, 0.0);
    let a = d.path().join("a.ply");
    let b = d.path().join("b.ply");
    let c = d.path().join("c.ply");
    recon(
        &ply,
        &a,
        &["--depth", "7", "--tile", "32", "--threads", "1"],
    );
    recon(
        &ply,
        &b,
        &["--depth", "7", "--tile", "32", "--threads", "2"],
    );
    recon(
        &ply,
        &c,
        &["--depth", "7", "--tile", "128", "--threads", "2"],
    );
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "threads change the bytes"
    );
    // Tile size: the same triangles up to vertex order.
    let (ta, tc) = (canonical_triangles(&a), canonical_triangles(&c));
    assert!(ta.len() > 1000);
    assert_eq!(ta, tc, "tile size changes the mesh");
    let mc = check_mesh(&read_mesh(&a).unwrap());
    assert!(mc.watertight && mc.oriented && mc.components == 1, "{mc:?}");
}

#[test]
fn independent_reader_opens_the_mesh() {
    if !has_plyfile() {
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let ply = synth(d.path(), "sphere", 20_000, 0.0);
    let out = d.path().join("m.ply");
    recon(&ply, &out, &["--depth", "6"]);
    let m = read_mesh(&out).unwrap();
    let script = "import sys, plyfile\nd = plyfile.PlyData.read(sys.argv[1])\nprint(len(d['vertex']), len(d['face']))";
    let o = std::process::Command::new("python3")
        .args(["-c", script, s(&out)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = String::from_utf8_lossy(&o.stdout).trim().to_string();
    assert_eq!(got, format!("{} {}", m.vertices.len(), m.triangles.len()));
}

#[test]
fn bad_reconstruct_input() {
    let d = tempfile::tempdir().unwrap();
    // No normals.
    let xyz = d.path().join("plain.xyz");
    let mut t = String::new();
    for i in 0..200 {
        let a = i as f64 * 0.3;
        t += &format!("{} {} {}\n", a.sin(), a.cos(), (a * 0.7).sin());
    }
    std::fs::write(&xyz, &t).unwrap();
    let err = fails(&[
        "reconstruct",
        s(&xyz),
        "-o",
        s(&d.path().join("o1.ply")),
        "--normals",
        "use",
    ]);
    assert!(
        err.contains("no normals") && err.contains("nx ny nz") && err.contains("plain.xyz"),
        "{err}"
    );
    // A plane.
    let plane = d.path().join("plane.xyz");
    let mut t = String::new();
    for i in 0..30 {
        for j in 0..30 {
            t += &format!("{} {} 0.5 0 0 1\n", i as f64 / 30.0, j as f64 / 30.0);
        }
    }
    std::fs::write(&plane, &t).unwrap();
    let err = fails(&[
        "reconstruct",
        s(&plane),
        "-o",
        s(&d.path().join("o2.ply")),
        "--depth",
        "6",
    ]);
    assert!(err.contains("plane"), "{err}");
    // A line.
    let line = d.path().join("line.xyz");
    let t: String = (0..100)
        .map(|i| format!("{} {} {} 1 0 0\n", i, 2 * i, 3 * i))
        .collect();
    std::fs::write(&line, &t).unwrap();
    let err = fails(&[
        "reconstruct",
        s(&line),
        "-o",
        s(&d.path().join("o3.ply")),
        "--depth",
        "6",
    ]);
    assert!(err.contains("line"), "{err}");
    // Too few points.
    let few = d.path().join("few.xyz");
    std::fs::write(&few, "0 0 0 1 0 0\n1 0 0 1 0 0\n0 1 0 0 1 0\n").unwrap();
    let err = fails(&["reconstruct", s(&few), "-o", s(&d.path().join("o4.ply"))]);
    assert!(err.contains("at least 16"), "{err}");
    // Depth out of range.
    let ply = synth(d.path(), "sphere", 1000, 0.0);
    let err = usage(&[
        "reconstruct",
        s(&ply),
        "-o",
        s(&d.path().join("o5.ply")),
        "--depth",
        "30",
    ]);
    assert!(
        err.contains("--depth 30") && err.contains("5..=13"),
        "{err}"
    );
    for o in ["o1.ply", "o2.ply", "o3.ply", "o4.ply", "o5.ply"] {
        assert!(!d.path().join(o).exists());
    }
}

fn load_points(ply: &Path) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    let r = scanflow::io::open(ply).unwrap();
    let mut b = scanflow::types::PointBatch::default();
    for c in r.chunks(1 << 16).unwrap() {
        r.read_chunk(&c, false, &mut b).unwrap();
    }
    (b.pos, b.normal)
}
