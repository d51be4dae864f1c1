//! Inputs by kind (issue 13, cases 12 and 13): LAZ gets the LAS rules, and a FIFO, a device
//! or a directory given as a point file is named as such, without hanging.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use super::common::*;

/// Rolling terrain of `n * n` points without normals, as LAS or LAZ (by extension).
fn write_terrain(path: &Path, n: usize) {
    let mut b = las::Builder::default();
    b.version = las::Version::new(1, 2);
    b.point_format = las::point::Format::new(0).unwrap();
    let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
            let z = 0.8 * (x * 0.3).sin() * (y * 0.25).cos();
            w.write_point(las::Point {
                x,
                y,
                z,
                ..Default::default()
            })
            .unwrap();
        }
    }
    w.close().unwrap();
}

#[test]
fn laz_without_viewpoint_faces_up_like_las() {
    let d = tempfile::tempdir().unwrap();
    let mut cells = Vec::new();
    for name in ["terrain.las", "terrain.laz"] {
        let input = d.path().join(name);
        write_terrain(&input, 40);
        let st = d.path().join(format!("{name}.store"));
        ok(&["ingest", s(&input), "-o", s(&st), "--progress", "none"]);
        let store = scanflow::store::Store::open(&st).unwrap();
        let m = &store.manifest;
        let e = m.estimated_normals.as_ref().unwrap();
        assert_eq!(e.by_viewpoint, m.point_count, "{name}: {e:?}");
        for i in 0..m.cells.len() {
            let b = store.read_cell(i).unwrap();
            assert!(
                b.normal.iter().all(|n| n[2] > 0.0),
                "{name}: a normal faces down"
            );
        }
        cells.push(tree_bytes(&st.join("cells")));
    }
    assert!(cells[0] == cells[1], "LAS and LAZ stores differ");
}

/// Run scanflow; fail if it runs longer than 30 s (a FIFO opened for reading blocks).
fn fails_promptly(args: &[&str]) -> String {
    let mut child = bin()
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(30) {
            child.kill().unwrap();
            panic!("scanflow {args:?} hung");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[cfg(unix)]
#[test]
fn fifo_device_and_directory_inputs_are_named_by_type() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("out.store");
    let fifo = d.path().join("pipe.ply");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if matches!(made, Ok(st) if st.success()) {
        let mesh = d.path().join("out.ply");
        for (cmd, out) in [("ingest", &out), ("reconstruct", &mesh)] {
            let err = fails_promptly(&[cmd, s(&fifo), "-o", s(out), "--progress", "none"]);
            assert!(
                err.contains("pipe.ply: not a regular file (a FIFO)"),
                "{err}"
            );
            assert!(!err.contains("empty"), "{err}");
        }
        let err = fails_promptly(&["info", s(&fifo)]);
        assert!(err.contains("(a FIFO)"), "{err}");
    } else {
        eprintln!("skipped the FIFO: mkfifo is not available");
    }
    if Path::new("/dev/zero").exists() {
        let err = fails_promptly(&["ingest", "/dev/zero", "-o", s(&out), "--progress", "none"]);
        assert!(
            err.contains("/dev/zero: not a regular file (a character device)"),
            "{err}"
        );
    }
    let dir = d.path().join("scans");
    std::fs::create_dir(&dir).unwrap();
    let err = fails_promptly(&["ingest", s(&dir), "-o", s(&out), "--progress", "none"]);
    assert!(err.contains("scans: is a directory"), "{err}");
    let conf = d.path().join("a.conf");
    std::fs::write(&conf, "bmesh scans 0 0 0 0 0 0 1\n").unwrap();
    let err = fails_promptly(&[
        "ingest",
        "--conf",
        s(&conf),
        "-o",
        s(&out),
        "--progress",
        "none",
    ]);
    assert!(
        err.contains("a.conf: line 1") && err.contains("is a directory"),
        "{err}"
    );
    assert!(!err.contains("does not exist"), "{err}");
    assert!(!out.exists());
}
