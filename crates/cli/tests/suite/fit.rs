//! `fit`: hierarchical B-spline surfaces written as IGES; OpenCascade reads them back with the
//! deviations scanflow reports, interpolation, the same bytes for any thread count, terrain
//! tiles that meet along their seams, closed objects patch by patch, real scans, and bad input.

use std::path::{Path, PathBuf};

use super::common::*;
use super::iges::{check, has_checker};

/// Synthesise the height field with `n` points and `noise`.
fn heightfield(dir: &Path, n: u64, noise: f64) -> PathBuf {
    let ply = dir.join(format!("hf{n}.ply"));
    ok(&[
        "synth",
        "heightfield",
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

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn f(v: &serde_json::Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"))
}

#[test]
fn opencascade_reads_back_the_deviations_scanflow_reports() {
    let d = tempfile::tempdir().unwrap();
    let ply = heightfield(d.path(), 20_000, 0.0001);
    let igs = d.path().join("hf.igs");
    let rep = d.path().join("hf.json");
    let prev = d.path().join("hf_preview.ply");
    let text = ok(&[
        "fit",
        s(&ply),
        "-o",
        s(&igs),
        "--tolerance",
        "0.1%",
        "--param",
        "project",
        "--report",
        s(&rep),
        "--preview",
        s(&prev),
        "--progress",
        "none",
    ]);
    assert!(text.contains("control points"), "{text}");
    let r = report(&rep);
    let diag = f(&r, "diagonal");
    assert!(r["met"].as_bool().unwrap(), "{r}");
    assert!(f(&r, "max_deviation") <= 1e-3 * diag);
    // Hierarchical: more than one level, fewer control points than points.
    assert!(r["levels"].as_array().unwrap().len() > 1, "{r}");
    assert!((r["control_points"].as_u64().unwrap()) < 20_000);
    assert!(prev.exists());
    if !has_checker("fit_occ") {
        return;
    }
    let c = check(&igs, &ply);
    assert_eq!(c["surfaces"].as_u64(), Some(1), "{c}");
    assert_eq!(c["no_projection"].as_u64(), Some(0), "{c}");
    let (occ_max, occ_rms) = (f(&c, "max"), f(&c, "rms"));
    assert!(
        (occ_max - f(&r, "max_deviation")).abs() < 1e-6 * diag,
        "max: OpenCascade {occ_max}, scanflow {}",
        f(&r, "max_deviation")
    );
    assert!(
        (occ_rms - f(&r, "rms_deviation")).abs() < 1e-6 * diag,
        "rms: OpenCascade {occ_rms}, scanflow {}",
        f(&r, "rms_deviation")
    );
    assert_eq!(c["gmsh"]["ok"].as_bool(), Some(true), "{c}");
    assert!(c["gmsh"]["warnings"].as_array().unwrap().is_empty(), "{c}");
}

#[test]
fn interpolation_hits_every_point_and_bytes_do_not_depend_on_threads() {
    let d = tempfile::tempdir().unwrap();
    let ply = heightfield(d.path(), 1500, 0.0);
    let mut bytes = Vec::new();
    for t in ["1", "2"] {
        // The same file name: the IGES global section records it.
        let dir = d.path().join(format!("t{t}"));
        std::fs::create_dir(&dir).unwrap();
        let igs = dir.join("i.igs");
        let rep = dir.join("i.json");
        ok(&[
            "fit",
            s(&ply),
            "-o",
            s(&igs),
            "--tolerance",
            "1e-7%",
            "--interpolate",
            "--threads",
            t,
            "--report",
            s(&rep),
            "--progress",
            "none",
        ]);
        let r = report(&rep);
        let res = r["surfaces_detail"][0]["max_residual"].as_f64().unwrap();
        assert!(res <= 1e-9 * f(&r, "diagonal"), "{r}");
        bytes.push(std::fs::read(&igs).unwrap());
    }
    assert!(
        bytes[0] == bytes[1],
        "the IGES file differs between 1 and 2 threads"
    );
}

#[test]
fn terrain_tiles_meet_along_their_seams() {
    let d = tempfile::tempdir().unwrap();
    let ply = heightfield(d.path(), 40_000, 0.0003);
    let igs = d.path().join("t.igs");
    let rep = d.path().join("t.json");
    ok(&[
        "fit",
        s(&ply),
        "-o",
        s(&igs),
        "--tolerance",
        "0.2%",
        "--tiles",
        "--tile-points",
        "10000",
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    let r = report(&rep);
    let diag = f(&r, "diagonal");
    assert!(r["surfaces"].as_u64().unwrap() >= 4, "{r}");
    assert!(r["met"].as_bool().unwrap(), "{r}");
    assert!(f(&r, "seam_max_gap") < 1e-9 * diag, "{r}");
    if !has_checker("fit_tiles_occ") {
        return;
    }
    let c = check(&igs, &ply);
    assert_eq!(c["surfaces"].as_u64(), r["surfaces"].as_u64(), "{c}");
    assert!(
        f(&c, "max") <= f(&r, "max_deviation") + 1e-6 * diag,
        "{c} {r}"
    );
}

/// The largest gap over a report's `patch_gaps`.
fn largest_patch_gap(r: &serde_json::Value) -> f64 {
    r["patch_gaps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| f(g, "max_gap"))
        .fold(0.0, f64::max)
}

#[test]
fn closed_objects_are_fitted_patch_by_patch_and_read_back_alike() {
    let d = tempfile::tempdir().unwrap();
    let sphere = d.path().join("sphere.ply");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "8000",
        "--noise",
        "0.0002",
        "-o",
        s(&sphere),
        "--progress",
        "none",
    ]);
    let mut bytes = Vec::new();
    let mut last = None;
    for t in ["1", "2"] {
        // The same file name: the IGES global section records it.
        let dir = d.path().join(format!("t{t}"));
        std::fs::create_dir(&dir).unwrap();
        let igs = dir.join("s.igs");
        let rep = dir.join("s.json");
        let text = ok(&[
            "fit",
            s(&sphere),
            "--patches",
            "-o",
            s(&igs),
            "--tolerance",
            "0.1%",
            "--threads",
            t,
            "--report",
            s(&rep),
            "--progress",
            "none",
        ]);
        assert!(text.contains("neighbouring patches"), "{text}");
        bytes.push(std::fs::read(&igs).unwrap());
        last = Some((igs, report(&rep)));
    }
    assert!(
        bytes[0] == bytes[1],
        "the IGES file differs between 1 and 2 threads"
    );
    // A budget that holds the points but not one patch's fit stops with a message at once
    // (a wait would never end: this thread holds the permits that would have to free).
    let small = d.path().join("small.igs");
    let e = usage(&[
        "fit",
        s(&sphere),
        "--patches",
        "-o",
        s(&small),
        "--tolerance",
        "0.5%",
        "--mem",
        "2M",
        "--progress",
        "none",
    ]);
    assert!(e.contains("patch") && e.contains("--mem"), "{e}");
    assert!(!small.exists());
    let (igs, r) = last.unwrap();
    let diag = f(&r, "diagonal");
    let tol = f(&r, "tolerance");
    // A sphere is no disc: several patches, every one within the tolerance, and every point
    // counted once in the deviation although the overlaps fit some twice.
    let n = r["surfaces"].as_u64().unwrap();
    assert!(n >= 6, "{r}");
    assert!(r["met"].as_bool().unwrap(), "{r}");
    assert_eq!(r["input_points"].as_u64(), Some(8000), "{r}");
    assert!(r["points"].as_u64().unwrap() > 8000, "{r}");
    assert!(f(&r, "max_deviation") <= tol, "{r}");
    // Neighbours share their overlap rings, and there the two surfaces are within two
    // tolerances of each other: each is within one of the same points.
    let gaps = r["patch_gaps"].as_array().unwrap();
    assert!(gaps.len() as u64 >= n, "{r}");
    assert!(largest_patch_gap(&r) <= 2.0 * tol, "{r}");
    if !has_checker("fit_patches_occ") {
        return;
    }
    let c = check(&igs, &sphere);
    assert_eq!(c["surfaces"].as_u64(), Some(n), "{c}");
    assert_eq!(c["no_projection"].as_u64(), Some(0), "{c}");
    let occ_max = f(&c, "max");
    assert!(
        (occ_max - f(&r, "max_deviation")).abs() < 1e-6 * diag,
        "max: OpenCascade {occ_max}, scanflow {}",
        f(&r, "max_deviation")
    );
    assert!(
        (f(&c, "rms") - f(&r, "rms_deviation")).abs() < 1e-6 * diag,
        "{c} {r}"
    );
    assert_eq!(c["gmsh"]["ok"].as_bool(), Some(true), "{c}");
    assert!(c["gmsh"]["warnings"].as_array().unwrap().is_empty(), "{c}");
}

#[test]
fn a_closed_scan_and_a_store_fit_by_patches() {
    let Some(zip) = shared("bunny/reconstruction/bun_zipper.ply") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let store = d.path().join("store");
    ingest_in_cells(&zip, &store, 5000);
    for (input, name) in [(&zip, "file"), (&store, "store")] {
        let igs = d.path().join(format!("{name}.igs"));
        let rep = d.path().join(format!("{name}.json"));
        ok(&[
            "fit",
            s(input),
            "--patches",
            "-o",
            s(&igs),
            "--tolerance",
            "0.3%",
            "--report",
            s(&rep),
            "--progress",
            "none",
        ]);
        let r = report(&rep);
        let tol = f(&r, "tolerance");
        assert!(r["met"].as_bool().unwrap(), "{name}: {r}");
        assert_eq!(r["input_points"].as_u64(), Some(35_947), "{name}: {r}");
        assert!(r["surfaces"].as_u64().unwrap() >= 10, "{name}: {r}");
        assert!(largest_patch_gap(&r) <= 2.0 * tol, "{name}: {r}");
        // A fit, not a copy: fewer control points than points.
        assert!(
            r["tensor_control_points"].as_u64().unwrap() < 35_947 / 2,
            "{name}: {r}"
        );
    }
}

#[test]
fn range_scan_uses_its_grid_and_meets_the_tolerance() {
    let Some(bun) = shared("bunny/bun000.ply") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let igs = d.path().join("bun.igs");
    let rep = d.path().join("bun.json");
    ok(&[
        "fit",
        s(&bun),
        "-o",
        s(&igs),
        "--tolerance",
        "0.2%",
        "--report",
        s(&rep),
        "--progress",
        "none",
    ]);
    let r = report(&rep);
    assert!(r["met"].as_bool().unwrap(), "{r}");
    assert_eq!(r["surfaces_detail"][0]["graph"].as_str(), Some("triangles"));
}

#[test]
fn bad_input_and_options_are_reported_before_or_without_a_hang() {
    let d = tempfile::tempdir().unwrap();
    // A closed sphere is not a disc.
    let sphere = d.path().join("sphere.ply");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "3000",
        "-o",
        s(&sphere),
        "--progress",
        "none",
    ]);
    let e = fails(&[
        "fit",
        s(&sphere),
        "-o",
        s(&d.path().join("x.igs")),
        "--tolerance",
        "0.1%",
        "--progress",
        "none",
    ]);
    assert!(e.contains("sphere.ply") && e.contains("--patches"), "{e}");
    let hf = heightfield(d.path(), 2000, 0.0);
    for (args, want) in [
        (vec!["--tolerance", "abc"], "--tolerance abc"),
        (vec!["--tolerance", "-1"], "positive"),
        (vec!["--tolerance", "0.1%", "--omega", "0"], "--omega"),
        (
            vec!["--tolerance", "0.1%", "--max-level", "99"],
            "--max-level",
        ),
        (
            vec!["--tolerance", "0.1%", "--patches", "--patch-points", "10"],
            "--patch-points",
        ),
        (
            vec!["--tolerance", "0.1%", "--patches", "--patch-angle", "200"],
            "--patch-angle",
        ),
    ] {
        let mut a = vec!["fit", s(&hf), "-o", "x.igs"];
        a.extend(args);
        let e = usage(&a);
        assert!(e.contains(want), "{e}");
    }
    // Clap's own conflict: exit 2, both options named.
    let o = run(&[
        "fit",
        s(&hf),
        "-o",
        "x.igs",
        "--tolerance",
        "1",
        "--patches",
        "--tiles",
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--patches") && e.contains("--tiles"), "{e}");
    let e = usage(&[
        "fit",
        s(&hf),
        "-o",
        s(&d.path().join("x.ply")),
        "--tolerance",
        "1",
    ]);
    assert!(e.contains("IGES"), "{e}");
    // A tolerance that cannot be met within --max-level: the regions are named, exit 1.
    let igs = d.path().join("unmet.igs");
    let e = fails(&[
        "fit",
        s(&hf),
        "-o",
        s(&igs),
        "--tolerance",
        "1e-9",
        "--max-level",
        "1",
        "--progress",
        "none",
    ]);
    assert!(e.contains("not met") && e.contains("points in"), "{e}");
    // A factorisation larger than --mem allows is refused before it is computed, naming the
    // bytes; no file appears.
    let igs = d.path().join("big.igs");
    let e = fails(&[
        "fit",
        s(&hf),
        "-o",
        s(&igs),
        "--tolerance",
        "1e-7%",
        "--interpolate",
        "--mem",
        "8M",
        "--progress",
        "none",
    ]);
    assert!(
        e.contains("hf2000.ply") && e.contains("MiB") && e.contains("--mem"),
        "{e}"
    );
    assert!(!igs.exists());
    // Too few points.
    let tiny = d.path().join("tiny.xyz");
    std::fs::write(&tiny, "0 0 0\n1 0 0\n").unwrap();
    let e = fails(&[
        "fit",
        s(&tiny),
        "-o",
        s(&d.path().join("t.igs")),
        "--tolerance",
        "1",
        "--progress",
        "none",
    ]);
    assert!(e.contains("tiny.xyz") && e.contains("at least 3"), "{e}");
}
