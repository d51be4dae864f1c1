//! `scanflow check` on a point file: distances of every point to the exact surface, read back
//! as the noise `synth` added, and the relief scale of the bumpy sphere.

use super::common::{fails, ok, s};

/// `scanflow check POINTS --truth T --json`, parsed.
fn check_json(points: &std::path::Path, truth: &std::path::Path) -> serde_json::Value {
    let out = ok(&["check", s(points), "--truth", s(truth), "--json"]);
    serde_json::from_str(out.trim()).expect("check --json prints one JSON object")
}

/// Synthesise `shape` with `points` points and `noise`; return the point and truth paths.
fn synth(
    dir: &std::path::Path,
    shape: &str,
    points: u32,
    noise: f64,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let p = dir.join(format!("{shape}_{noise}.ply"));
    ok(&[
        "synth",
        shape,
        "--points",
        &points.to_string(),
        "--noise",
        &noise.to_string(),
        "-o",
        s(&p),
    ]);
    let t = dir.join(format!("{shape}_{noise}.truth.json"));
    (p, t)
}

#[test]
fn point_cloud_rms_reads_back_synth_noise() {
    // synth adds N(0, σ²) to each coordinate, σ = noise · diagonal. The distance to the sphere
    // is, to first order in σ (curvature terms are σ/2 ≈ 0.35 % of it), the absolute normal
    // component, itself N(0, σ²): rms / diagonal = noise, mean = rms √(2/π). Standard error of
    // the RMS over 20000 points: noise / √40000 = 0.5 %.
    let d = tempfile::tempdir().unwrap();
    let (p, t) = synth(d.path(), "sphere", 20_000, 0.002);
    let j = check_json(&p, &t);
    assert_eq!(j["points"], 20_000);
    let rms_rel = j["rms_rel"].as_f64().unwrap();
    assert!((rms_rel / 0.002 - 1.0).abs() < 0.03, "{j}");
    let mean_rel = j["mean_rel"].as_f64().unwrap();
    assert!(
        (mean_rel / rms_rel - (2.0 / std::f64::consts::PI).sqrt()).abs() < 0.02,
        "{j}"
    );
    let (p99, max) = (j["p99"].as_f64().unwrap(), j["max"].as_f64().unwrap());
    assert!(p99 <= max && j["relief_scale"].is_null(), "{j}");

    // No noise: only float32 rounding of the positions (2^-24 of a unit radius).
    let (p, t) = synth(d.path(), "sphere", 20_000, 0.0);
    let j = check_json(&p, &t);
    assert!(j["max_rel"].as_f64().unwrap() < 1e-7, "{j}");

    // The text report names the surface.
    let text = ok(&["check", s(&p), "--truth", s(&t)]);
    assert!(
        text.contains("20000 points") && text.contains("exact sphere surface"),
        "{text}"
    );
}

#[test]
fn bumpy_points_keep_their_relief() {
    let d = tempfile::tempdir().unwrap();
    let (p, t) = synth(d.path(), "bumpy", 20_000, 0.0);
    let j = check_json(&p, &t);
    let relief = j["relief_scale"].as_f64().unwrap();
    assert!((relief - 1.0).abs() < 1e-3, "{j}");
    assert!(j["max_rel"].as_f64().unwrap() < 1e-6, "{j}");
    // The points against themselves as a reference: every distance is 0.
    let out = ok(&["check", s(&p), "--reference", s(&p), "--json"]);
    let j: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(j["max"].as_f64(), Some(0.0), "{j}");
}

#[test]
fn bad_point_file_is_a_clear_error() {
    let d = tempfile::tempdir().unwrap();
    let (_, t) = synth(d.path(), "sphere", 100, 0.0);
    let bad = d.path().join("garbage.ply");
    std::fs::write(&bad, "not a point file at all\n").unwrap();
    let err = fails(&["check", s(&bad), "--truth", s(&t)]);
    assert!(err.contains("garbage.ply"), "{err}");
    let missing = d.path().join("missing.ply");
    let err = fails(&["check", s(&missing), "--truth", s(&t)]);
    assert!(err.contains("missing.ply"), "{err}");
}
