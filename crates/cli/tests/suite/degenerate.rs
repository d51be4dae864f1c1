//! Degenerate data is an error, not an empty success (issue 13, case 4): NaN, infinite and
//! zero normals are refused at ingest naming the element (or dropped and counted with
//! `--skip-invalid`); inputs at extreme magnitudes reconstruct; a reconstruction that finds no
//! surface fails instead of writing an empty mesh.

use std::path::{Path, PathBuf};

use scanflow::io::mesh_read::read_mesh;

use super::common::*;

/// A binary float32 PLY of `pos` with normals `nrm`; returns its path and header length.
fn write_oriented(path: &Path, pos: &[[f64; 3]], nrm: &[[f64; 3]]) -> (PathBuf, usize) {
    let head = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n",
        pos.len()
    );
    let mut out = head.clone().into_bytes();
    for (p, n) in pos.iter().zip(nrm) {
        for v in p.iter().chain(n) {
            out.extend_from_slice(&(*v as f32).to_le_bytes());
        }
    }
    std::fs::write(path, out).unwrap();
    (path.to_path_buf(), head.len())
}

/// `n` points of a unit sphere (a Fibonacci lattice) with outward normals.
fn sphere(n: usize) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut pos = Vec::with_capacity(n);
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        pos.push([r * a.cos(), r * a.sin(), z]);
    }
    (pos.clone(), pos)
}

fn ingest(input: &Path, store: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["ingest", s(input), "-o", s(store), "--progress", "none"];
    args.extend_from_slice(extra);
    run(&args)
}

#[test]
fn nan_normals_are_rejected_at_ingest() {
    let d = tempfile::tempdir().unwrap();
    let (pos, mut nrm) = sphere(400);
    nrm[12][0] = f64::NAN;
    let (ply, head) = write_oriented(&d.path().join("scan.ply"), &pos, &nrm);
    let err = fails(&[
        "ingest",
        s(&ply),
        "-o",
        s(&d.path().join("st")),
        "--progress",
        "none",
    ]);
    let want = format!("scan.ply: element 12 (byte {}): nx is NaN", head + 12 * 24);
    assert!(err.contains(&want), "{err}");
    assert!(err.contains("--skip-invalid"), "{err}");
    // Reconstruct refuses it too, and writes nothing.
    let out = d.path().join("mesh.ply");
    let err = fails(&["reconstruct", s(&ply), "-o", s(&out), "--progress", "none"]);
    assert!(err.contains(&want), "{err}");
    assert!(!out.exists());
    // Normals that are estimated ignore the file's, bad ones included.
    let st = d.path().join("est");
    ok(&[
        "ingest",
        s(&ply),
        "-o",
        s(&st),
        "--normals",
        "estimate",
        "--progress",
        "none",
    ]);
    // An infinite normal in a text file names the element and its line.
    let xyz = d.path().join("scan.xyz");
    let mut text = String::new();
    for (i, p) in pos.iter().enumerate().take(20) {
        let nz = if i == 3 {
            "inf".to_string()
        } else {
            p[2].to_string()
        };
        text.push_str(&format!(
            "{} {} {} {} {} {nz}\n",
            p[0], p[1], p[2], p[0], p[1]
        ));
    }
    std::fs::write(&xyz, text).unwrap();
    let err = fails(&[
        "ingest",
        s(&xyz),
        "-o",
        s(&d.path().join("st2")),
        "--progress",
        "none",
    ]);
    assert!(
        err.contains("scan.xyz: element 3 (line 4): nz is inf"),
        "{err}"
    );
}

#[test]
fn zero_normals_are_rejected_at_ingest() {
    let d = tempfile::tempdir().unwrap();
    let (pos, _) = sphere(400);
    let zero = vec![[0.0; 3]; pos.len()];
    let (ply, head) = write_oriented(&d.path().join("flat.ply"), &pos, &zero);
    let out = d.path().join("mesh.ply");
    let err = fails(&["reconstruct", s(&ply), "-o", s(&out), "--progress", "none"]);
    let want = format!("flat.ply: element 0 (byte {head}): normal is zero");
    assert!(err.contains(&want), "{err}");
    assert!(!out.exists());
}

#[test]
fn skip_invalid_drops_and_counts_invalid_normals() {
    let d = tempfile::tempdir().unwrap();
    let (pos, mut nrm) = sphere(400);
    nrm[5] = [0.0; 3];
    nrm[6][1] = f64::INFINITY;
    nrm[7][2] = f64::NAN;
    let mut pos = pos;
    pos[8][0] = f64::NAN;
    let (ply, _) = write_oriented(&d.path().join("scan.ply"), &pos, &nrm);
    let store = d.path().join("st");
    let o = ingest(&ply, &store, &["--skip-invalid"]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("(4 skipped as invalid)"), "{stdout}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(store.join("manifest.json")).unwrap())
            .unwrap();
    assert_eq!(manifest["skipped_invalid"], 4);
    assert_eq!(manifest["point_count"], 396);
}

/// Reconstruct the unit sphere scaled by `scale`, with its normals or estimating them; the mesh
/// must be the unit sphere's, scaled: nonempty, finite, the right size.
fn reconstructs_at(scale: f64, with_normals: bool) {
    let d = tempfile::tempdir().unwrap();
    let (pos, nrm) = sphere(4000);
    let pos: Vec<[f64; 3]> = pos.iter().map(|p| p.map(|v| v * scale)).collect();
    let ply = d.path().join("scaled.ply");
    if with_normals {
        write_oriented(&ply, &pos, &nrm);
    } else {
        let mut out = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nend_header\n",
            pos.len()
        )
        .into_bytes();
        for v in pos.iter().flatten() {
            out.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(&ply, out).unwrap();
    }
    let out = d.path().join("mesh.ply");
    ok(&[
        "reconstruct",
        s(&ply),
        "-o",
        s(&out),
        "--depth",
        "6",
        "--progress",
        "none",
    ]);
    let m = read_mesh(&out).unwrap();
    assert!(m.triangles.len() > 1000, "{} triangles", m.triangles.len());
    for v in &m.vertices {
        assert!(v.iter().all(|c| c.is_finite()));
        let r = v.iter().map(|c| (c / scale).powi(2)).sum::<f64>().sqrt();
        assert!((r - 1.0).abs() < 0.05, "vertex {v:?} at radius {r}");
    }
}

#[test]
fn extreme_magnitudes_reconstruct_instead_of_giving_nan() {
    // Extents near 1e-30: the solve works in units of the cube, never 1/h³ in input units, and
    // normal estimation in units of each cell's edge.
    reconstructs_at(1e-30, true);
    reconstructs_at(1e-30, false);
    // Coordinates near 1e30.
    reconstructs_at(1e30, true);
    reconstructs_at(1e30, false);
}

#[test]
fn reconstruction_without_a_surface_is_an_error() {
    let d = tempfile::tempdir().unwrap();
    // Every point twice, with opposite normals: they cancel, and the field is flat.
    let (pos, nrm) = sphere(2000);
    let mut p2 = Vec::new();
    let mut n2 = Vec::new();
    for (p, n) in pos.iter().zip(&nrm) {
        p2.extend([*p, *p]);
        n2.extend([*n, n.map(|v| -v)]);
    }
    let (ply, _) = write_oriented(&d.path().join("cancel.ply"), &p2, &n2);
    let out = d.path().join("mesh.ply");
    let err = fails(&["reconstruct", s(&ply), "-o", s(&out), "--progress", "none"]);
    assert!(err.contains("no surface"), "{err}");
    assert!(!out.exists());
}
