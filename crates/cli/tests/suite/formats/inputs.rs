//! Inputs that shape the mesh: an E57 of posed scans, per-sample confidence, samples per node.

use super::*;

/// An E57 file written by an independent tool (pye57, libE57Format) with six scans of a
/// sphere, each in its own frame with its pose, colour and intensity: ingested as one input
/// per scan with the scanner's position as its viewpoint, the poses put the points back on
/// the sphere, the estimated normals face out (positive volume), and the colours reach the
/// mesh.
#[test]
fn an_e57_of_six_posed_scans_reconstructs_the_sphere() {
    if !python_has("numpy, plyfile, pye57", "e57") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = d.join("sphere.ply");
    ok(&["synth", "sphere", "--points", "20000", "-o", s(&pts)]);
    let e57 = d.join("six.e57");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/e57_scans.py");
    let o = Command::new("python3")
        .arg(script)
        .arg(&pts)
        .arg(&e57)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), "6 20000");
    let info = ok(&["info", s(&e57)]);
    assert!(info.contains("E57") && info.contains("20000"), "{info}");
    assert!(info.contains("red green blue intensity"), "{info}");
    assert!(info.contains("e57         version 1.0"), "{info}");
    assert!(
        info.contains("scan 5") && info.contains("scanner at (0, 0, -50)"),
        "{info}"
    );
    assert!(
        info.contains("crs         (none recorded)") && !info.contains("warning"),
        "{info}"
    );
    // A projected CRS given to points that span two units about the origin: `info` says the
    // coordinates look like degrees, as it does for LAS.
    let crs = d.join("crs.e57");
    let o = Command::new("python3")
        .args([script, s(&pts), s(&crs), "EPSG:32610"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let info = ok(&["info", s(&crs)]);
    assert!(info.contains("crs         EPSG:32610"), "{info}");
    assert!(
        info.contains("warning     the CRS (projected EPSG:32610) is projected")
            && info.contains("degrees?"),
        "{info}"
    );
    let mesh = d.join("m.ply");
    recon(&e57, &mesh, &[]);
    let truth = d.join("sphere.truth.json");
    let rep = ok(&["check", s(&mesh), "--truth", s(&truth), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&rep).unwrap();
    assert_eq!(v["check"]["watertight"], true, "{rep}");
    let mean = v["comparison"]["absolute"]["to_reference"]["mean"]
        .as_f64()
        .unwrap();
    assert!(mean < 5e-4, "mean distance {mean}");
    let m = scanflow::io::mesh_read::read_mesh(&mesh).unwrap();
    let volume: f64 = m
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.vertices[i as usize]);
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
        .sum();
    let sphere = 4.0 / 3.0 * std::f64::consts::PI;
    assert!((volume / sphere - 1.0).abs() < 0.01, "volume {volume}");
    let head = std::fs::read(&mesh).unwrap();
    let head = String::from_utf8_lossy(&head[..700]);
    assert!(
        head.contains("property uchar red") && head.contains("scalar_intensity"),
        "{head}"
    );
    // A broken E57 is named.
    let broken = d.join("broken.e57");
    let bytes = std::fs::read(&e57).unwrap();
    std::fs::write(&broken, &bytes[..bytes.len() / 2]).unwrap();
    let e = super::super::common::fails(&["info", s(&broken)]);
    assert!(e.contains("broken.e57"), "{e}");
}

/// A sphere whose +x half also holds noisy samples (spread 0.03, scattered normals) of
/// confidence 0.05, beside the clean samples of confidence 1: at depth 8, `--confidence` brings the
/// surface closer to the exact sphere than the unweighted solve, whether the confidences are a
/// property or the normals' lengths. A file with neither is refused before any work.
#[test]
fn confidence_weighting_lets_trusted_samples_win() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clean = d.join("clean.ply");
    ok(&["synth", "sphere", "--points", "30000", "-o", s(&clean)]);
    let b = super::super::common::load(&clean);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let mut gauss = |sd: f64| {
        // Box-Muller.
        let (u, v): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
        sd * (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    };
    // The same samples twice: with a confidence property and unit normals, and with normals
    // as long as the confidence (PoissonRecon's convention) and no property.
    let (mut text, mut lengths) = (String::new(), String::new());
    let mut n = 0;
    let mut sample = |q: [f64; 3], m: [f64; 3], c: f64| {
        let l = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        let u = m.map(|x| x / l);
        text.push_str(&format!(
            "{} {} {} {} {} {} {c}\n",
            q[0], q[1], q[2], u[0], u[1], u[2]
        ));
        lengths.push_str(&format!(
            "{} {} {} {} {} {}\n",
            q[0],
            q[1],
            q[2],
            u[0] * c,
            u[1] * c,
            u[2] * c
        ));
        n += 1;
    };
    for (p, nn) in b.pos.iter().zip(&b.normal) {
        sample(*p, nn.map(f64::from), 1.0);
        if p[0] > 0.0 {
            let q = p.map(|x| x + gauss(0.03));
            let m = nn.map(|x| x as f64 + gauss(0.3));
            sample(q, m, 0.05);
        }
    }
    let pts = d.join("mixed.ply");
    oriented_ply(&pts, n, "property float confidence\n", &text);
    let long = d.join("lengths.ply");
    oriented_ply(&long, n, "", &lengths);
    let truth = d.join("clean.truth.json");
    let mean = |mesh: &Path| {
        let rep = ok(&["check", s(mesh), "--truth", s(&truth), "--json"]);
        let v: serde_json::Value = serde_json::from_str(&rep).unwrap();
        v["comparison"]["absolute"]["to_reference"]["mean"]
            .as_f64()
            .unwrap()
    };
    let (plain, weighted) = (d.join("plain.ply"), d.join("weighted.ply"));
    at_depth_8(&pts, &plain, &[]);
    at_depth_8(&pts, &weighted, &["--confidence"]);
    let (a, b) = (mean(&plain), mean(&weighted));
    eprintln!("mean distance to the sphere: unweighted {a:.3e}, weighted {b:.3e}");
    assert!(b < 0.7 * a, "unweighted {a:e}, weighted {b:e}");
    // Normal lengths as confidences: weighted as by the property; without --confidence the
    // lengths are ignored (every normal counts as unit), as for the unit normals.
    let (plain_l, weighted_l) = (d.join("plain_l.ply"), d.join("weighted_l.ply"));
    at_depth_8(&long, &plain_l, &[]);
    at_depth_8(&long, &weighted_l, &["--confidence"]);
    let (al, bl) = (mean(&plain_l), mean(&weighted_l));
    eprintln!("normal lengths as confidences: unweighted {al:.3e}, weighted {bl:.3e}");
    assert!((al / a - 1.0).abs() < 0.02, "unweighted {a:e} and {al:e}");
    assert!((bl / b - 1.0).abs() < 0.05, "weighted {b:e} and {bl:e}");
    // Estimated normals have unit length: with no property there is nothing to weigh by.
    let e = usage(&[
        "reconstruct",
        s(&clean),
        "-o",
        s(&d.join("x.ply")),
        "--confidence",
        "--normals",
        "estimate",
    ]);
    assert!(
        e.contains("clean.ply") && e.contains("confidence") && e.contains("no normals"),
        "{e}"
    );
}

/// `--samples-per-node` (PoissonRecon's `--samplesPerNode`): a noisy 30k-point sphere at
/// depth 8 averages under one sample per fine voxel of surface, so with S = 1 no leaf is
/// refined and the smoother coarse surface lies closer to the exact sphere than the refined
/// one; a small S refines as the default does.
#[test]
fn samples_per_node_keeps_sparse_parts_coarse() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = d.join("noisy.ply");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "30000",
        "--noise",
        "0.004",
        "-o",
        s(&pts),
    ]);
    let truth = d.join("noisy.truth.json");
    let run_at = |extra: &[&str]| -> (u64, f64) {
        let out = d.join("m.ply");
        let mut args = vec![
            "reconstruct",
            s(&pts),
            "-o",
            s(&out),
            "--depth",
            "8",
            "--progress",
            "none",
        ];
        args.extend_from_slice(extra);
        let summary = ok(&args);
        let refined: u64 = summary
            .split(" refined")
            .next()
            .and_then(|h| h.rsplit(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{summary}"));
        let rep = ok(&["check", s(&out), "--truth", s(&truth), "--json"]);
        let v: serde_json::Value = serde_json::from_str(&rep).unwrap();
        let mean = v["comparison"]["absolute"]["to_reference"]["mean"]
            .as_f64()
            .unwrap();
        (refined, mean)
    };
    let (r0, e0) = run_at(&[]);
    let (r1, e1) = run_at(&["--samplesPerNode", "1"]);
    let (r2, _) = run_at(&["--samples-per-node", "0.01"]);
    eprintln!("refined {r0}, {r1}, {r2}; mean distance {e0:.3e} (default), {e1:.3e} (S = 1)");
    assert!(r0 > 100 && r1 == 0 && r2 == r0, "{r0} {r1} {r2}");
    assert!(e1 < 0.8 * e0, "{e0:e} {e1:e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&d.join("x.ply")),
        "--samples-per-node",
        "0",
    ]);
    assert!(e.contains("--samples-per-node 0"), "{e}");
}
