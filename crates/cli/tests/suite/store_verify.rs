//! Stores are verified (issue 13, case 5): a manifest that lists a cell twice, miscounts its
//! points or names a file outside the store is refused when the store is opened; `info`
//! checks that every cell file is there with its size; `info --verify` reads every cell;
//! `reconstruct` on a damaged store fails naming the cell. Each error names the store and the
//! cell, exits 1, and never panics.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::common::*;

/// An oriented unit sphere of `n` points (x y z nx ny nz) as XYZ text.
pub fn write_sphere_xyz(path: &Path, n: usize) {
    let mut t = String::new();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let (s, c) = (golden * i as f64).sin_cos();
        let p = [r * c, r * s, z];
        writeln!(t, "{} {} {} {} {} {}", p[0], p[1], p[2], p[0], p[1], p[2]).unwrap();
    }
    std::fs::write(path, t).unwrap();
}

/// A store of a 4000-point sphere in cells of at most 400 points, made in `dir`.
pub fn make_store(dir: &Path) -> PathBuf {
    let xyz = dir.join("sphere.xyz");
    write_sphere_xyz(&xyz, 4000);
    let st = dir.join("sphere.store");
    ingest_in_cells(&xyz, &st, 400);
    std::fs::remove_file(&xyz).unwrap();
    st
}

/// The manifest as JSON.
pub fn manifest(store: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(store.join("manifest.json")).unwrap()).unwrap()
}

/// Replace the manifest.
pub fn set_manifest(store: &Path, v: &Value) {
    std::fs::write(
        store.join("manifest.json"),
        serde_json::to_vec_pretty(v).unwrap(),
    )
    .unwrap();
}

/// The file of cell `i`.
pub fn cell_file(store: &Path, i: usize) -> PathBuf {
    let m = manifest(store);
    store
        .join("cells")
        .join(m["cells"][i]["file"].as_str().unwrap())
}

/// A fresh copy of a good store in a temp dir, with its manifest edited by `edit`.
fn damaged(edit: impl FnOnce(&Path, &mut Value)) -> (tempfile::TempDir, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let st = make_store(d.path());
    let mut m = manifest(&st);
    assert!(m["cells"].as_array().unwrap().len() >= 4, "{m}");
    edit(&st, &mut m);
    set_manifest(&st, &m);
    (d, st)
}

/// `info STORE` fails; the message names the store and contains each of `want`.
fn info_fails(st: &Path, extra: &[&str], want: &[&str]) -> String {
    let mut args = vec!["info", s(st), "--progress", "none"];
    args.extend_from_slice(extra);
    let err = fails(&args);
    assert!(
        err.contains("sphere.store"),
        "does not name the store: {err}"
    );
    for w in want {
        assert!(err.contains(w), "lacks \"{w}\": {err}");
    }
    err
}

#[test]
fn manifest_listing_a_cell_twice_is_refused() {
    let (_d, st) = damaged(|_, m| {
        let c = m["cells"][1].clone();
        m["cells"].as_array_mut().unwrap().insert(2, c);
    });
    info_fails(
        &st,
        &[],
        &["manifest.json", "cell 2", "listed twice", "cell 1"],
    );
    let e = scanflow::store::Store::open(&st).unwrap_err().to_string();
    assert!(e.contains("listed twice"), "{e}");
}

#[test]
fn wrong_point_count_is_refused() {
    // The total disagrees with the cells.
    let (_d, st) = damaged(|_, m| {
        let n = m["point_count"].as_u64().unwrap();
        m["point_count"] = (n + 1).into();
    });
    info_fails(&st, &[], &["manifest.json", "point_count"]);
    // A cell's count changed with the total: the inputs no longer add up.
    let (_d, st) = damaged(|_, m| {
        let n = m["point_count"].as_u64().unwrap();
        m["point_count"] = (n - 1).into();
        let c = m["cells"][0]["count"].as_u64().unwrap();
        m["cells"][0]["count"] = (c - 1).into();
    });
    info_fails(&st, &[], &["manifest.json", "inputs hold"]);
    // Counts and inputs edited to agree: the cell read finds the difference.
    let (_d, st) = damaged(|_, m| {
        let n = m["point_count"].as_u64().unwrap();
        m["point_count"] = (n - 1).into();
        let c = m["cells"][0]["count"].as_u64().unwrap();
        m["cells"][0]["count"] = (c - 1).into();
        let p = m["inputs"][0]["points"].as_u64().unwrap();
        m["inputs"][0]["points"] = (p - 1).into();
    });
    ok(&["info", s(&st), "--progress", "none"]);
    info_fails(&st, &["--verify"], &["cells", "manifest lists"]);
}

#[test]
fn cell_path_escaping_the_store_is_refused() {
    for bad in [
        "../../../../etc/passwd",
        "/etc/passwd",
        "..",
        "sub/x.zst",
        "ffffffffffffffff.zst",
    ] {
        let (_d, st) = damaged(|_, m| m["cells"][0]["file"] = bad.into());
        let err = info_fails(&st, &[], &["manifest.json", "cell 0", bad]);
        assert!(!err.contains("root:"), "{err}");
    }
}

#[cfg(unix)]
#[test]
fn cell_symlinked_out_of_the_store_is_refused() {
    let (d, st) = damaged(|_, _| {});
    let cell = cell_file(&st, 2);
    let outside = d.path().join("outside.zst");
    std::fs::rename(&cell, &outside).unwrap();
    std::os::unix::fs::symlink(&outside, &cell).unwrap();
    info_fails(&st, &[], &["cell 2", "symbolic link"]);
}

#[test]
fn info_reports_deleted_and_truncated_cells() {
    let (_d, st) = damaged(|_, _| {});
    ok(&["info", s(&st), "--progress", "none"]);
    let cell = cell_file(&st, 3);
    let bytes = std::fs::read(&cell).unwrap();
    std::fs::write(&cell, &bytes[..bytes.len() / 2]).unwrap();
    info_fails(&st, &[], &["cell 3", "truncated"]);
    std::fs::remove_file(&cell).unwrap();
    info_fails(&st, &[], &["cell 3", "missing"]);
}

#[test]
fn info_verify_reads_every_cell_and_reports_corrupt_ones() {
    let (_d, st) = damaged(|_, _| {});
    let out = ok(&["info", s(&st), "--verify", "--progress", "none"]);
    assert!(
        out.contains("verified") && out.contains("CRC-32s match"),
        "{out}"
    );
    let json = ok(&["info", s(&st), "--verify", "--json", "--progress", "none"]);
    let v: Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["verified"]["points"], v["points"], "{v}");
    // Same size, one byte flipped in the middle: only reading finds it.
    let cell = cell_file(&st, 1);
    let mut bytes = std::fs::read(&cell).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&cell, &bytes).unwrap();
    ok(&["info", s(&st), "--progress", "none"]);
    let name = cell.file_name().unwrap().to_str().unwrap();
    let err = info_fails(&st, &["--verify"], &[name, "corrupt cell file"]);
    assert!(!err.contains("failed verification"), "{err}");
    // Two bad cells: both logged, the error counts them.
    let cell = cell_file(&st, 2);
    let mut bytes = std::fs::read(&cell).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0xff;
    std::fs::write(&cell, &bytes).unwrap();
    info_fails(&st, &["--verify"], &["2 of", "failed verification"]);
}

#[test]
fn reconstruct_fails_clearly_on_a_corrupt_cell() {
    let (d, st) = damaged(|_, _| {});
    let cell = cell_file(&st, 0);
    let mut bytes = std::fs::read(&cell).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&cell, &bytes).unwrap();
    let out = d.path().join("mesh.ply");
    let err = fails(&[
        "reconstruct",
        s(&st),
        "-o",
        s(&out),
        "--depth",
        "5",
        "--progress",
        "none",
    ]);
    let name = cell.file_name().unwrap().to_str().unwrap();
    assert!(
        err.contains("sphere.store") && err.contains(name) && err.contains("corrupt"),
        "{err}"
    );
    assert!(!out.exists());
}
