//! Helpers: run the binary, make fixtures in temp dirs.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The scanflow binary built for these tests.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_scanflow"))
}

/// Start scanflow with `args`, its output captured (a task running beside others).
pub fn spawn(args: &[&str]) -> std::process::Child {
    bin()
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the scanflow binary runs")
}

/// Wait for a process [`spawn`] started; require success; return its standard output.
pub fn finish(c: std::process::Child) -> String {
    let o = c.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "a task failed: {err}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Run scanflow with `args`; return the output.
pub fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("the scanflow binary runs")
}

/// Run and require success; return stdout.
pub fn ok(args: &[&str]) -> String {
    let o = run(args);
    assert!(
        o.status.success(),
        "scanflow {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Ingest `input` into the store `store` in cells of at most `max_cell_points` points.
pub fn ingest_in_cells(input: &Path, store: &Path, max_cell_points: u64) {
    ok(&[
        "ingest",
        s(input),
        "-o",
        s(store),
        "--max-cell-points",
        &max_cell_points.to_string(),
        "--progress",
        "none",
    ]);
}

/// Run and require success; return stderr (the log, warnings and progress lines).
pub fn ok_log(args: &[&str]) -> String {
    let o = run(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "scanflow {args:?} failed:\n{err}");
    err
}

/// Run, require a clean failure (exit 1, no panic), return stderr.
pub fn fails(args: &[&str]) -> String {
    let o = run(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(
        o.status.code(),
        Some(1),
        "scanflow {args:?} should fail with 1:\n{err}"
    );
    assert!(
        !err.contains("panicked"),
        "scanflow {args:?} panicked:\n{err}"
    );
    assert!(err.contains("scanflow: error:"), "{err}");
    err
}

/// Run, require a usage failure (exit 2: the command line is wrong; no panic), return stderr.
pub fn usage(args: &[&str]) -> String {
    let o = run(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "scanflow {args:?}:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("scanflow: error:"), "{err}");
    err
}

/// Path to shared test data, or None (with a printed reason) when absent.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} is not present", p.display());
        None
    }
}

/// A path as &str.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Every file under `dir` with its bytes, sorted by relative path.
pub fn tree_bytes(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// Peak RSS reported by the last JSON progress lines on stderr.
pub fn peak_rss(stderr: &str) -> u64 {
    stderr
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v.get("peak_rss_bytes").and_then(|x| x.as_u64()))
        .max()
        .unwrap_or(0)
}

/// True when python3 can import plyfile (the independent PLY reader `.ci/run` installs);
/// otherwise prints why the calling test skips.
pub fn has_plyfile() -> bool {
    let probe = std::process::Command::new("python3")
        .args(["-c", "import plyfile"])
        .output();
    let ok = matches!(probe, Ok(ref o) if o.status.success());
    if !ok {
        eprintln!("skipped: python3 with plyfile is not installed");
    }
    ok
}

/// Files and directories under `dir` whose names hold `.tmp-`.
pub fn temp_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if e.file_name().to_string_lossy().contains(".tmp-") {
                out.push(p.clone());
            }
            if e.file_type().map(|t| t.is_dir()).unwrap_or(false) {
                stack.push(p);
            }
        }
    }
    out
}

/// Read every point of a point file.
pub fn load(path: &Path) -> scanflow::types::PointBatch {
    let r = scanflow::io::open(path).unwrap();
    let mut b = scanflow::types::PointBatch::default();
    for c in r.chunks(1 << 16).unwrap() {
        r.read_chunk(&c, false, &mut b).unwrap();
    }
    b
}
