//! `filter`, `resample` and `spectrum`: accuracy against exact surfaces, the error bound, the
//! same bytes for any thread count and cell layout, resume, outputs and bad options.

use std::path::Path;

use scanflow::synth::Truth;

use super::common::*;

/// RMS and largest distance of the points of `path` to the exact surface, relative to its
/// bounding-box diagonal.
fn to_truth(path: &Path, truth: &Truth) -> (f64, f64) {
    let b = load(path);
    let diag = truth.bounding_box().diagonal();
    let (mut s, mut m) = (0.0, 0f64);
    for p in &b.pos {
        let d = truth.distance(*p).abs();
        s += d * d;
        m = m.max(d);
    }
    ((s / b.pos.len() as f64).sqrt() / diag, m / diag)
}

/// Synthesise `shape` with `n` points and `noise`; returns the point file and its truth.
fn synth(dir: &Path, shape: &str, n: u64, noise: f64) -> (std::path::PathBuf, Truth) {
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
    let truth = Truth::load(&dir.join(format!("{shape}.truth.json"))).unwrap();
    (ply, truth)
}

#[test]
fn wiener_and_lowpass_bring_noisy_points_closer_to_the_surface() {
    let d = tempfile::tempdir().unwrap();
    for shape in ["sphere", "bumpy"] {
        let (ply, truth) = synth(d.path(), shape, 60_000, 0.004);
        let (raw, _) = to_truth(&ply, &truth);
        for (name, args) in [
            ("wiener", vec!["--wiener"]),
            ("lowpass", vec!["--lowpass", "gauss:0.3"]),
        ] {
            let out = d.path().join(format!("{shape}_{name}.ply"));
            let mut a = vec!["filter", s(&ply), "-o", s(&out), "--progress", "none"];
            a.extend(args);
            let text = ok(&a);
            assert!(text.contains("Parseval error"), "{text}");
            let (rms, _) = to_truth(&out, &truth);
            assert!(
                rms < 0.6 * raw,
                "{shape} {name}: RMS to the surface {rms:.3e} against {raw:.3e} before"
            );
        }
    }
}

#[test]
fn resample_stays_within_the_error_bound_and_follows_the_detail() {
    let d = tempfile::tempdir().unwrap();
    let (ply, truth) = synth(d.path(), "bumpy", 200_000, 0.0);
    let out = d.path().join("r.ply");
    let e = 3e-4;
    ok(&[
        "resample",
        s(&ply),
        "-o",
        s(&out),
        "--max-error",
        &e.to_string(),
        "--progress",
        "none",
    ]);
    let (rms, max) = to_truth(&out, &truth);
    assert!(
        max < e,
        "largest distance {max:.3e} over the bound {e} (RMS {rms:.3e})"
    );
    eprintln!(
        "{} of {} points; distance to the surface RMS {rms:.3e}, max {max:.3e} of the diagonal",
        load(&out).pos.len(),
        200_000
    );
}

/// Write points with normals as a binary little-endian PLY.
fn write_oriented_ply(path: &Path, pos: &[[f64; 3]], nor: &[[f64; 3]]) {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n",
        pos.len()
    )
    .into_bytes();
    for (p, n) in pos.iter().zip(nor) {
        p.iter()
            .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
        n.iter()
            .for_each(|v| out.extend_from_slice(&(*v as f32).to_le_bytes()));
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn resample_puts_fewer_points_where_the_surface_is_flat() {
    // A sheet over [0, 2] × [0, 1]: flat for x < 1, a relief `a sin(k(x - 1)) sin(ky)`
    // beyond.
    let d = tempfile::tempdir().unwrap();
    let (a, k) = (0.01, 25.0);
    let (mut pos, mut nor) = (Vec::new(), Vec::new());
    let mut seed = 11u64;
    let mut r = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..120_000 {
        let (x, y) = (2.0 * r(), r());
        let (z, gx, gy) = if x < 1.0 {
            (0.0, 0.0, 0.0)
        } else {
            let (sx, cx) = (k * (x - 1.0)).sin_cos();
            let (sy, cy) = (k * y).sin_cos();
            (a * sx * sy, a * k * cx * sy, a * k * sx * cy)
        };
        let l = (1.0 + gx * gx + gy * gy).sqrt();
        pos.push([x, y, z]);
        nor.push([-gx / l, -gy / l, 1.0 / l]);
    }
    let ply = d.path().join("sheet.ply");
    write_oriented_ply(&ply, &pos, &nor);
    let out = d.path().join("r.ply");
    ok(&[
        "resample",
        s(&ply),
        "-o",
        s(&out),
        "--max-error",
        "2e-4",
        "--progress",
        "none",
    ]);
    let r = load(&out);
    let flat = r.pos.iter().filter(|p| p[0] < 0.9).count() as f64;
    let bumpy = r.pos.iter().filter(|p| p[0] > 1.1).count() as f64;
    eprintln!(
        "{} points: {flat} on the flat 0.9 of the sheet, {bumpy} on the bumpy 0.9",
        r.pos.len()
    );
    assert!(
        flat > 0.0 && bumpy > 2.0 * flat,
        "flat {flat}, bumpy {bumpy}"
    );
    // Away from the sheet's open edges and the crease at x = 1, the points follow the
    // surface within the bound.
    let diag = (4.0f64 + 1.0 + 4.0 * a * a).sqrt();
    let inside = |p: &&[f64; 3]| {
        p[1] > 0.05 && p[1] < 0.95 && p[0] > 0.05 && p[0] < 1.95 && (p[0] - 1.0).abs() > 0.1
    };
    let worst = r
        .pos
        .iter()
        .filter(inside)
        .map(|p| {
            let z = if p[0] < 1.0 {
                0.0
            } else {
                a * (k * (p[0] - 1.0)).sin() * (k * p[1]).sin()
            };
            (p[2] - z).abs()
        })
        .fold(0f64, f64::max);
    eprintln!("largest height error {:.3e} of the diagonal", worst / diag);
    assert!(worst < 2e-4 * diag, "largest height error {worst:.3e}");
}

#[test]
fn filter_gives_the_same_bytes_for_any_thread_count() {
    let d = tempfile::tempdir().unwrap();
    let (ply, _) = synth(d.path(), "torus", 40_000, 0.003);
    let store = d.path().join("store");
    // Small cells: patches reach across cell faces through the halo.
    ingest_in_cells(&ply, &store, 6000);
    let mut outs = Vec::new();
    for t in ["1", "2", "3"] {
        let out = d.path().join(format!("f{t}.ply"));
        ok(&[
            "filter",
            s(&store),
            "-o",
            s(&out),
            "--wiener",
            "--write-parseval",
            "--threads",
            t,
            "--progress",
            "none",
        ]);
        outs.push(std::fs::read(&out).unwrap());
    }
    assert!(
        outs[0] == outs[1] && outs[1] == outs[2],
        "bytes differ with --threads"
    );
    // And resampling.
    let mut rs = Vec::new();
    for t in ["1", "2"] {
        let out = d.path().join(format!("r{t}.ply"));
        ok(&[
            "resample",
            s(&store),
            "-o",
            s(&out),
            "--threads",
            t,
            "--progress",
            "none",
        ]);
        rs.push(std::fs::read(&out).unwrap());
    }
    assert!(rs[0] == rs[1], "resampled bytes differ with --threads");
}

#[test]
fn blending_hides_cell_boundaries() {
    // The same points filtered as one cell and as many: the filtered surfaces agree to a
    // small fraction of the noise, so cell faces leave no seam.
    let d = tempfile::tempdir().unwrap();
    let (ply, truth) = synth(d.path(), "sphere", 40_000, 0.004);
    let (raw, _) = to_truth(&ply, &truth);
    let mut rms = Vec::new();
    for cells in ["1000000", "5000"] {
        let store = d.path().join(format!("store{cells}"));
        ok(&[
            "ingest",
            s(&ply),
            "-o",
            s(&store),
            "--max-cell-points",
            cells,
            "--progress",
            "none",
        ]);
        let out = d.path().join(format!("f{cells}.ply"));
        ok(&[
            "filter",
            s(&store),
            "-o",
            s(&out),
            "--lowpass",
            "gauss:0.3",
            "--progress",
            "none",
        ]);
        rms.push(to_truth(&out, &truth));
    }
    let (one, many) = (rms[0], rms[1]);
    assert!(
        many.0 < 1.15 * one.0 && many.0 < 0.6 * raw,
        "one cell {one:?}, many cells {many:?}, raw {raw:.3e}"
    );
}

#[test]
fn parseval_scalar_and_attributes_are_written() {
    let d = tempfile::tempdir().unwrap();
    let (ply, _) = synth(d.path(), "sphere", 20_000, 0.003);
    let out = d.path().join("f.ply");
    ok(&[
        "filter",
        s(&ply),
        "-o",
        s(&out),
        "--lowpass",
        "ideal:0.5",
        "--write-parseval",
        "--progress",
        "none",
    ]);
    let bytes = std::fs::read(&out).unwrap();
    let head = String::from_utf8_lossy(&bytes[..400.min(bytes.len())]).to_string();
    assert!(head.contains("element vertex 20000"), "{head}");
    assert!(head.contains("property float nx"), "{head}");
    assert!(head.contains("property float parseval_error"), "{head}");
    if has_plyfile() {
        let o = std::process::Command::new("python3")
            .args([
                "-c",
                "import sys, plyfile; v = plyfile.PlyData.read(sys.argv[1])['vertex']; \
                 e = v['parseval_error']; print(len(v), float(e.min()), float(e.max()))",
                s(&out),
            ])
            .output()
            .unwrap();
        let t = String::from_utf8_lossy(&o.stdout);
        let f: Vec<f64> = t.split_whitespace().map(|x| x.parse().unwrap()).collect();
        assert_eq!(f[0], 20000.0, "{t}");
        assert!(f[1] >= 0.0 && f[2] > 0.0, "{t}");
    }
}

#[test]
fn spectrum_writes_layout_images_and_summary() {
    let d = tempfile::tempdir().unwrap();
    let (ply, _) = synth(d.path(), "bumpy", 30_000, 0.002);
    let out = d.path().join("spec");
    let text = ok(&[
        "spectrum",
        s(&ply),
        "-o",
        s(&out),
        "--images",
        "3",
        "--progress",
        "none",
    ]);
    assert!(text.contains("energy by band"), "{text}");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let patches = summary["stats"]["patches"].as_u64().unwrap();
    assert!(patches > 10, "{summary}");
    let energy: f64 = summary["band_energy"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .sum();
    assert!((energy - 1.0).abs() < 1e-9, "{summary}");
    let images = summary["images"].as_array().unwrap();
    assert_eq!(images.len(), 3, "{summary}");
    for im in images {
        let png = std::fs::read(out.join(im["file"].as_str().unwrap())).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    }
    let layout = load(&out.join("layout.ply"));
    assert_eq!(layout.pos.len(), 30_000);
    assert_eq!(layout.color.len(), 30_000);
    assert!(temp_files(d.path()).is_empty());
}

#[test]
fn resume_reuses_the_patches_of_the_same_run_only() {
    let d = tempfile::tempdir().unwrap();
    let (ply, _) = synth(d.path(), "sphere", 20_000, 0.003);
    let work = d.path().join("w");
    let a = d.path().join("a.ply");
    ok(&[
        "filter",
        s(&ply),
        "-o",
        s(&a),
        "--wiener",
        "--work-dir",
        s(&work),
        "--keep-work",
        "--progress",
        "none",
    ]);
    let b = d.path().join("b.ply");
    let text = ok(&[
        "filter",
        s(&ply),
        "-o",
        s(&b),
        "--wiener",
        "--work-dir",
        s(&work),
        "--resume",
        "--progress",
        "none",
    ]);
    assert!(text.contains("reused the patches"), "{text}");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert!(
        !work.exists(),
        "the work directory is removed after success"
    );
    // Another filter is another run: a resume refuses the work directory.
    ok(&[
        "filter",
        s(&ply),
        "-o",
        s(&a),
        "--wiener",
        "--work-dir",
        s(&work),
        "--keep-work",
        "--progress",
        "none",
    ]);
    let err = fails(&[
        "filter",
        s(&ply),
        "-o",
        s(&b),
        "--lowpass",
        "gauss:0.3",
        "--work-dir",
        s(&work),
        "--resume",
        "--progress",
        "none",
    ]);
    assert!(
        err.contains("cannot resume") && err.contains("filter"),
        "{err}"
    );
}

#[test]
fn bad_spectral_options_and_inputs_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let (ply, _) = synth(d.path(), "sphere", 2_000, 0.0);
    let out = d.path().join("o.ply");
    let (p, o) = (s(&ply), s(&out));
    for (args, want) in [
        (vec!["filter", p, "-o", o], "no filter"),
        (
            vec!["filter", p, "-o", o, "--wiener", "--lowpass", "gauss:0.3"],
            "one filter",
        ),
        (
            vec!["filter", p, "-o", o, "--lowpass", "gauss:0"],
            "out of range",
        ),
        (
            vec!["filter", p, "-o", o, "--lowpass", "box:0.3"],
            "unknown kind",
        ),
        (
            vec!["filter", p, "-o", o, "--lowpass", "gauss:x"],
            "not a number",
        ),
        (
            vec!["filter", p, "-o", o, "--bandstop", "0.2,0.5,2"],
            "[0, 1)",
        ),
        (
            vec!["filter", p, "-o", o, "--bandstop", "0.5,0.2,0"],
            "not below",
        ),
        (
            vec!["filter", p, "-o", o, "--enhance", "0.2,0.5,0.5"],
            "more than 1",
        ),
        (vec!["filter", p, "-o", o, "--enhance", "0.2,0.5"], "A,B,G"),
        (vec!["filter", p, "-o", o, "--wiener", "-3"], "positive"),
        (
            vec!["filter", p, "-o", o, "--wiener", "--patch-size", "5"],
            "--patch-size",
        ),
        (
            vec!["resample", p, "-o", o, "--max-error", "0"],
            "--max-error",
        ),
        (vec!["resample", p, "-o", o, "--points", "0"], "--points"),
        (vec!["filter", p, "-o", p, "--wiener"], p),
        (
            vec!["spectrum", p, "-o", d.path().to_str().unwrap()],
            "already exists",
        ),
    ] {
        let mut a = args.clone();
        a.extend(["--progress", "none"]);
        let err = usage(&a);
        assert!(err.contains(want), "{args:?}: {err}");
    }
    assert!(!out.exists());
    // Points without normals where the inputs' normals are required.
    let bare = d.path().join("bare.xyz");
    std::fs::write(&bare, "0 0 0\n1 0 0\n0 1 0\n1 1 0.1\n").unwrap();
    let err = fails(&[
        "filter",
        s(&bare),
        "-o",
        o,
        "--wiener",
        "--normals",
        "use",
        "--progress",
        "none",
    ]);
    assert!(err.contains("bare.xyz"), "{err}");
    assert!(!out.exists() && temp_files(d.path()).is_empty());
}

#[test]
fn filter_stays_under_mem_plus_margin_with_the_same_bytes() {
    // 600K points, two store cells and more: the waves, halos and caches are charged to the
    // budget. Measured: 1M points peaked at 76 MiB under --mem 64M, 115 MiB under 128M, and
    // 20M at 311 MiB under 256M.
    let d = tempfile::tempdir().unwrap();
    let (ply, _) = synth(d.path(), "bumpy", 600_000, 0.002);
    let mut outs = Vec::new();
    for mib in [64u64, 128] {
        let out = d.path().join(format!("f{mib}.ply"));
        let mem = format!("{mib}M");
        let err = ok_log(&[
            "filter",
            s(&ply),
            "-o",
            s(&out),
            "--lowpass",
            "gauss:0.2",
            "--mem",
            &mem,
            "--threads",
            "2",
            "--progress",
            "json",
        ]);
        let peak = peak_rss(&err);
        assert!(peak > 0, "no peak RSS reported: {err}");
        // The README's margin: 64 MiB over --mem.
        assert!(
            peak < (mib + 64) << 20,
            "--mem {mem}: peak RSS {} MiB",
            peak >> 20
        );
        outs.push(std::fs::read(&out).unwrap());
    }
    assert!(outs[0] == outs[1], "bytes differ with --mem");
}
