//! The malformed-input corpus (issue 13): over 120 broken PLY, XYZ, LAS/LAZ, `.conf` files,
//! FIFOs and devices, and damaged stores, generated here in a temp dir, each run through
//! `ingest`, `reconstruct`, `info`, `info --verify` or `check` under a time limit. Every run must exit
//! non-zero without a panic, name the offending file and, where the defect has one, its
//! location (line, element, byte or cell), and leave no output and no temporary file.
//!
//! Cases whose correct behaviour another change delivers are marked `pending`: they run and
//! their result is printed, but they do not fail the test until that change is in.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use super::common::*;
use super::store_verify::{cell_file, make_store, manifest, set_manifest};

mod options;
mod points;
mod store;

/// Longest a case may run before it counts as a hang.
const TIMEOUT: Duration = Duration::from_secs(60);
/// Threads running cases at once.
const THREADS: usize = 3;

/// Locations an error may give.
const LINE: &[&str] = &["line "];
const ELEMENT: &[&str] = &["element "];
const BYTE: &[&str] = &["byte "];
const ANY_LOC: &[&str] = &["line ", "element ", "byte "];
const CELL: &[&str] = &["cell "];
const NONE: &[&str] = &[];

/// One malformed input and the command run on it.
struct Case {
    name: String,
    args: Vec<String>,
    /// The file name the message must contain.
    file: String,
    /// The message must contain one of these (none: no location required).
    loc: &'static [&'static str],
    /// The output the command would write, which must not appear.
    out: Option<PathBuf>,
    /// Why the case is not yet expected to pass, when another change delivers it.
    pending: Option<&'static str>,
    /// The case's own directory, where no temporary file may be left.
    dir: PathBuf,
    /// The exit status: 1 for a bad input, 2 for a bad command line.
    code: i32,
}

/// Builds the cases, each in its own directory under `root`.
struct Corpus {
    root: PathBuf,
    cases: Vec<Case>,
}

/// Which command a case runs on its file.
#[derive(Clone, Copy)]
enum Cmd {
    Ingest,
    Reconstruct,
    Info,
    Verify,
}

/// No case is pending now: NaN, infinite and zero normals are ingest errors.
const PENDING_NORMALS: Option<&str> = None;

impl Corpus {
    /// A fresh directory for case `name`.
    fn dir(&self, name: &str) -> PathBuf {
        let d = self.root.join(name);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Write `bytes` as `file` in the case's directory.
    fn write(&self, name: &str, file: &str, bytes: &[u8]) -> PathBuf {
        let p = self.dir(name).join(file);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// Add a case running `cmd` on `input`; the message must name `input`'s file name.
    fn add(&mut self, name: &str, cmd: Cmd, input: &Path, loc: &'static [&'static str]) {
        self.add_named(name, cmd, input, input, loc, None);
    }

    /// As [`Corpus::add`], with the file the message must name given apart and a reason
    /// why it is pending.
    fn add_named(
        &mut self,
        name: &str,
        cmd: Cmd,
        input: &Path,
        named: &Path,
        loc: &'static [&'static str],
        pending: Option<&'static str>,
    ) {
        let dir = self.dir(name);
        let p = s(input).to_string();
        let (mut args, out) = match cmd {
            Cmd::Ingest => {
                let o = dir.join("out.store");
                (vec!["ingest".into(), p, "-o".into(), s(&o).into()], Some(o))
            }
            Cmd::Reconstruct => {
                let o = dir.join("out.ply");
                let a = vec!["reconstruct".into(), p, "-o".into(), s(&o).into()];
                (a, Some(o))
            }
            Cmd::Info => (vec!["info".into(), p], None),
            Cmd::Verify => (vec!["info".into(), p, "--verify".into()], None),
        };
        if matches!(cmd, Cmd::Reconstruct) {
            args.extend(["--depth".into(), "5".into()]);
        }
        args.extend([
            "--progress".into(),
            "none".into(),
            "--threads".into(),
            "1".into(),
        ]);
        self.cases.push(Case {
            name: name.into(),
            args,
            file: named.file_name().unwrap().to_string_lossy().into_owned(),
            loc,
            out,
            pending,
            dir,
            code: 1,
        });
    }

    /// A usage case: `reconstruct` of a good input with the options `extra`, which must exit
    /// 2 naming `named` (an option or a path) before any work.
    fn usage(&mut self, name: &str, input: &Path, out: &str, extra: &[&str], named: &str) {
        let dir = self.dir(name);
        let o = dir.join(out);
        let mut args: Vec<String> = vec!["reconstruct".into(), s(input).into(), "-o".into()];
        args.push(s(&o).into());
        args.extend(extra.iter().map(|a| a.to_string()));
        args.extend(["--progress".into(), "none".into()]);
        self.cases.push(Case {
            name: name.into(),
            args,
            file: named.into(),
            loc: NONE,
            out: Some(o),
            pending: None,
            dir,
            code: 2,
        });
    }

    /// A point file `file` in its own case run by `cmd`.
    fn file(
        &mut self,
        name: &str,
        file: &str,
        bytes: &[u8],
        cmd: Cmd,
        loc: &'static [&'static str],
    ) {
        let p = self.write(name, file, bytes);
        self.add(name, cmd, &p, loc);
    }
}

/// An ascii PLY header of `n` vertices with float properties `props`.
fn ascii_head(n: &str, props: &[&str]) -> String {
    let mut h = format!("ply\nformat ascii 1.0\nelement vertex {n}\n");
    for p in props {
        h += &format!("property float {p}\n");
    }
    h + "end_header\n"
}

/// A binary PLY of float `props`, `records` given as f32 values (byte order by `le`).
fn binary_ply(n: u64, props: &[&str], values: &[f32], le: bool) -> Vec<u8> {
    let fmt = if le {
        "binary_little_endian"
    } else {
        "binary_big_endian"
    };
    let mut h = format!("ply\nformat {fmt} 1.0\nelement vertex {n}\n");
    for p in props {
        h += &format!("property float {p}\n");
    }
    let mut b = (h + "end_header\n").into_bytes();
    for v in values {
        b.extend_from_slice(&if le { v.to_le_bytes() } else { v.to_be_bytes() });
    }
    b
}

/// Deterministic junk bytes.
fn junk(n: usize, seed: u64) -> Vec<u8> {
    let mut x = seed | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

const XYZ: [&str; 3] = ["x", "y", "z"];
const XYZN: [&str; 6] = ["x", "y", "z", "nx", "ny", "nz"];

/// Run one case; `Ok` holds its message, `Err` says what was wrong.
fn run_case(c: &Case) -> Result<String, String> {
    let t0 = Instant::now();
    let mut child = bin()
        .args(&c.args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run scanflow: {e}"))?;
    // Drain stderr on a thread so a chatty child cannot block on a full pipe.
    let mut err_pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut err_pipe, &mut s);
        s
    });
    let status = loop {
        if let Some(st) = child.try_wait().map_err(|e| e.to_string())? {
            break st;
        }
        if t0.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("hung: killed after {TIMEOUT:?}"));
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let err = reader.join().unwrap_or_default();
    let mut wrong = Vec::new();
    if status.code() != Some(c.code) {
        wrong.push(format!("exit status {status}, expected {}", c.code));
    }
    if err.contains("panicked") {
        wrong.push("panicked".into());
    }
    if !err.contains(&c.file) {
        wrong.push(format!("the message does not name {}", c.file));
    }
    if !c.loc.is_empty() && !c.loc.iter().any(|l| err.contains(l)) {
        wrong.push(format!(
            "the message gives no location ({})",
            c.loc.join("/")
        ));
    }
    if let Some(o) = &c.out
        && o.exists()
    {
        wrong.push(format!("output {} exists", o.display()));
    }
    if let Some(o) = &c.out {
        let mut w = o.as_os_str().to_owned();
        w.push(".work");
        if Path::new(&w).exists() {
            wrong.push(format!("work directory {} left", Path::new(&w).display()));
        }
    }
    let tmp = temp_files(&c.dir);
    if !tmp.is_empty() {
        wrong.push(format!("temporary files left: {tmp:?}"));
    }
    if wrong.is_empty() {
        Ok(err.trim().to_string())
    } else {
        Err(format!("{}\n    stderr: {}", wrong.join("; "), err.trim()))
    }
}

#[test]
fn malformed_inputs_fail_cleanly_naming_file_and_place() {
    let t0 = Instant::now();
    let d = tempfile::tempdir().unwrap();
    let mut c = Corpus {
        root: d.path().to_path_buf(),
        cases: Vec::new(),
    };
    points::ply_header_cases(&mut c);
    points::ply_data_cases(&mut c);
    points::ply_binary_cases(&mut c);
    points::ply_normal_cases(&mut c);
    points::xyz_cases(&mut c);
    points::las_cases(&mut c);
    points::conf_cases(&mut c);
    points::special_cases(&mut c);
    let base = make_store(&c.dir("store_base"));
    store::store_manifest_cases(&mut c, &base);
    store::store_file_cases(&mut c, &base);
    options::option_cases(&mut c);
    let cases = c.cases;
    assert!(cases.len() >= 60, "only {} cases", cases.len());
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Result<String, String>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..THREADS {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(case) = cases.get(i) else { break };
                    let r = run_case(case);
                    results.lock().unwrap().push((i, r));
                }
            });
        }
    });
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|r| r.0);
    let mut failed = Vec::new();
    // SCANFLOW_CORPUS_SHOW=1 prints every case's message.
    let show = std::env::var_os("SCANFLOW_CORPUS_SHOW").is_some();
    for (i, r) in results {
        let case = &cases[i];
        match (r, case.pending) {
            (Ok(_), Some(why)) => eprintln!("pending case {} now passes ({why})", case.name),
            (Ok(msg), None) => {
                if show {
                    eprintln!("{}: {msg}", case.name);
                }
            }
            (Err(e), Some(why)) => eprintln!("pending case {} fails ({why}): {e}", case.name),
            (Err(e), None) => failed.push(format!("{}: {e}", case.name)),
        }
    }
    eprintln!(
        "{} cases in {:.1} s",
        cases.len(),
        t0.elapsed().as_secs_f64()
    );
    assert!(
        failed.is_empty(),
        "{} of {} cases failed:\n{}",
        failed.len(),
        cases.len(),
        failed.join("\n")
    );
}
