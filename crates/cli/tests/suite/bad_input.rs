//! Bad input: each gives a message naming the file, what is wrong and where; exit 1; no
//! panic; and no store under the final name.

use super::common::*;
use std::path::Path;

fn ingest_fails(input: &Path, want: &[&str]) -> String {
    let out = input.with_extension("store");
    let err = fails(&["ingest", s(input), "-o", s(&out), "--progress", "none"]);
    let name = input.file_name().unwrap().to_str().unwrap();
    assert!(err.contains(name), "error does not name {name}: {err}");
    for w in want {
        assert!(err.contains(w), "error lacks \"{w}\": {err}");
    }
    assert!(!out.exists(), "a store appeared at {}", out.display());
    let leftovers: Vec<_> = std::fs::read_dir(input.parent().unwrap())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    err
}

const HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn missing_file() {
    let d = tempfile::tempdir().unwrap();
    ingest_fails(&d.path().join("nothere.ply"), &["No such file"]);
}

#[test]
fn empty_file() {
    let d = tempfile::tempdir().unwrap();
    ingest_fails(&write(d.path(), "empty.ply", b""), &["empty file"]);
}

#[test]
fn not_a_ply() {
    let d = tempfile::tempdir().unwrap();
    ingest_fails(
        &write(d.path(), "junk.ply", b"hello world\n1 2 3\n"),
        &["not a PLY", "byte 0"],
    );
}

#[test]
fn header_without_end_header() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "noend.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
    );
    ingest_fails(&p, &["no end_header"]);
}

#[test]
fn truncated_binary() {
    let d = tempfile::tempdir().unwrap();
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    b.extend(std::iter::repeat_n(0u8, 12 * 7 + 5));
    let p = write(d.path(), "short.ply", &b);
    ingest_fails(&p, &["truncated", "promises 10", "element 7"]);
}

#[test]
fn truncated_ascii() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "short_ascii.ply",
        format!("{HEAD}0 0 0\n").as_bytes(),
    );
    ingest_fails(&p, &["truncated", "promises 2 vertices"]);
}

#[test]
fn list_property_on_vertex() {
    let d = tempfile::tempdir().unwrap();
    let p = write(d.path(), "list.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty list uchar int idx\nend_header\n0 0 0 1 1\n");
    ingest_fails(&p, &["line 3", "list property"]);
}

#[test]
fn unknown_property_type() {
    let d = tempfile::tempdir().unwrap();
    let p = write(d.path(), "type.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty quad y\nproperty float z\nend_header\n0 0 0\n");
    ingest_fails(&p, &["line 5", "unknown property type \"quad\""]);
}

#[test]
fn no_x() {
    let d = tempfile::tempdir().unwrap();
    let p = write(d.path(), "nox.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float u\nproperty float y\nproperty float z\nend_header\n0 0 0\n");
    ingest_fails(&p, &["no x property"]);
}

#[test]
fn nan_coordinate_and_skip_invalid() {
    let d = tempfile::tempdir().unwrap();
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    let header = b.len();
    for i in 0..4 {
        let z = if i == 2 { f32::NAN } else { i as f32 };
        for v in [i as f32, 1.0, z] {
            b.extend(v.to_le_bytes());
        }
    }
    let p = write(d.path(), "nan.ply", &b);
    let byte = format!("byte {}", header + 24);
    ingest_fails(&p, &["element 2", &byte, "z is NaN", "--skip-invalid"]);
    let store = d.path().join("ok.store");
    let out = ok(&[
        "ingest",
        s(&p),
        "-o",
        s(&store),
        "--skip-invalid",
        "--progress",
        "none",
    ]);
    assert!(out.contains("ingested 3 points (1 skipped"), "{out}");
}

#[test]
fn big_endian_works() {
    let d = tempfile::tempdir().unwrap();
    let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty float y\nproperty int z\nend_header\n".to_vec();
    for i in 0..3i32 {
        b.extend((i as f64 * 2.0).to_be_bytes());
        b.extend((-(i as f32)).to_be_bytes());
        b.extend((i * 10).to_be_bytes());
    }
    let p = write(d.path(), "be.ply", &b);
    let store = d.path().join("be.store");
    ok(&["ingest", s(&p), "-o", s(&store), "--progress", "none"]);
    let st = scanflow::store::Store::open(&store).unwrap();
    assert_eq!(st.manifest.point_count, 3);
    assert_eq!(st.manifest.bounds.max, [4.0, 0.0, 20.0]);
    assert_eq!(st.manifest.bounds.min, [0.0, -2.0, 0.0]);
}

#[test]
fn zero_vertices() {
    let d = tempfile::tempdir().unwrap();
    let p = write(d.path(), "zero.ply", b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
    ingest_fails(&p, &["no points"]);
}

#[test]
fn conf_naming_a_missing_file() {
    let d = tempfile::tempdir().unwrap();
    let conf = write(d.path(), "scans.conf", b"bmesh gone.ply 0 0 0 0 0 0 1\n");
    let out = d.path().join("c.store");
    let err = fails(&["ingest", "--conf", s(&conf), "-o", s(&out)]);
    assert!(
        err.contains("scans.conf: line 1") && err.contains("gone.ply"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn output_directory_not_writable() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "fine.ply",
        format!("{HEAD}0 0 0\n1 1 1\n").as_bytes(),
    );
    // The parent of the output is a regular file, so nothing can be created under it.
    let blocker = write(d.path(), "blocker", b"x");
    let out = blocker.join("out.store");
    let err = usage(&["ingest", s(&p), "-o", s(&out), "--progress", "none"]);
    assert!(
        err.contains("out.store") && err.contains("blocker is not a directory"),
        "{err}"
    );
    // An existing store is not overwritten.
    let store = d.path().join("s.store");
    ok(&["ingest", s(&p), "-o", s(&store), "--progress", "none"]);
    let err = usage(&["ingest", s(&p), "-o", s(&store), "--progress", "none"]);
    assert!(err.contains("already exists"), "{err}");
}

#[test]
fn bad_options() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "fine.ply",
        format!("{HEAD}0 0 0\n1 1 1\n").as_bytes(),
    );
    let out = d.path().join("o.store");
    let err = usage(&["ingest", s(&p), "-o", s(&out), "--mem", "lots"]);
    assert!(err.contains("--mem \"lots\""), "{err}");
    let err = fails(&["info", s(&d.path().join("nothing.store"))]);
    assert!(err.contains("nothing.store"), "{err}");
    let err = usage(&[
        "synth",
        "cube",
        "--points",
        "10",
        "-o",
        s(&d.path().join("c.ply")),
    ]);
    assert!(err.contains("cube") && err.contains("sphere"), "{err}");
    let o = run(&["ingest"]);
    assert_eq!(o.status.code(), Some(2), "clap usage errors exit 2");
}

#[test]
fn store_of_another_version() {
    let d = tempfile::tempdir().unwrap();
    let st = d.path().join("old.store");
    std::fs::create_dir(&st).unwrap();
    std::fs::write(
        st.join("manifest.json"),
        b"{\"format\":\"scanflow-store\",\"version\":99}",
    )
    .unwrap();
    let err = fails(&["info", s(&st)]);
    assert!(err.contains("version 99"), "{err}");
}
