//! Nothing a user owns is lost and nothing wrong is reported as success: work directories,
//! outputs that are inputs, resume identity, options checked before any work, exit codes,
//! failed and killed runs.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use super::common::{bin, fails, ok, s, temp_files, usage};

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A small bumpy sphere of `points` points (with normals) at `path`.
fn synth(path: &Path, points: u32, seed: u32) {
    let (n, seed) = (points.to_string(), seed.to_string());
    ok(&[
        "synth",
        "bumpy",
        "--points",
        &n,
        "--seed",
        &seed,
        "-o",
        s(path),
        "--progress",
        "none",
    ]);
}

/// `reconstruct INPUT -o OUT` plus `extra` (`--depth 6` unless `extra` gives one).
fn recon_args<'a>(input: &'a Path, out: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec!["reconstruct", s(input), "-o", s(out), "--progress", "none"];
    if !extra.contains(&"--depth") {
        a.extend(["--depth", "6"]);
    }
    a.extend_from_slice(extra);
    a
}

#[test]
fn work_dir_naming_a_users_directory_never_removes_it() {
    let d = tempfile::tempdir().unwrap();
    let inputs = d.path().join("inputs");
    let outputs = d.path().join("outputs");
    std::fs::create_dir_all(&inputs).unwrap();
    std::fs::create_dir_all(&outputs).unwrap();
    let input = inputs.join("b.ply");
    synth(&input, 20_000, 1);
    std::fs::write(inputs.join("notes.txt"), b"field notes").unwrap();
    let before = names(&inputs);
    // The directory holding the input, the one receiving -o, and their parent.
    for (i, w) in [&inputs, &outputs, &d.path().to_path_buf()]
        .iter()
        .enumerate()
    {
        let out = outputs.join(format!("m{i}.ply"));
        ok(&recon_args(&input, &out, &["--work-dir", s(w)]));
        assert!(out.is_file(), "{} was not written", out.display());
        assert!(w.is_dir(), "{} was removed", w.display());
    }
    assert_eq!(names(&inputs), before);
    assert_eq!(
        std::fs::read(inputs.join("notes.txt")).unwrap(),
        b"field notes"
    );
    assert_eq!(names(&outputs), ["m0.ply", "m1.ply", "m2.ply"]);
    // --keep-work keeps the subdirectory made inside the user's directory, marked as ours.
    let out = outputs.join("k.ply");
    ok(&recon_args(
        &input,
        &out,
        &["--work-dir", s(&inputs), "--keep-work"],
    ));
    assert!(inputs.join("k.ply.work").join(".scanflow-work").is_file());
}

#[test]
fn output_that_is_an_input_is_refused_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join("scan.ply");
    synth(&input, 2_000, 1);
    let bytes = std::fs::read(&input).unwrap();
    let hard = d.path().join("hard.ply");
    std::fs::hard_link(&input, &hard).unwrap();
    let soft = d.path().join("soft.ply");
    std::os::unix::fs::symlink(&input, &soft).unwrap();
    for out in [&input, &hard, &soft] {
        let e = usage(&recon_args(&input, out, &[]));
        assert!(e.contains("never overwrites its inputs"), "{e}");
    }
    let store = d.path().join("store");
    ok(&["ingest", s(&input), "-o", s(&store), "--progress", "none"]);
    let e = usage(&recon_args(&store, &store.join("m.ply"), &[]));
    assert!(e.contains("inside the input"), "{e}");
    let e = usage(&["ingest", s(&input), "-o", s(&input)]);
    assert!(e.contains("already exists"), "{e}");
    assert_eq!(std::fs::read(&input).unwrap(), bytes);
    assert_eq!(
        names(d.path()),
        [
            "hard.ply",
            "scan.ply",
            "scan.truth.json",
            "soft.ply",
            "store"
        ]
    );
}

#[test]
fn resume_refuses_a_work_dir_made_for_other_inputs_or_options() {
    let d = tempfile::tempdir().unwrap();
    let a = d.path().join("a.ply");
    let b = d.path().join("b.ply");
    synth(&a, 20_000, 1);
    synth(&b, 20_000, 2);
    let w = d.path().join("w");
    let first = d.path().join("first.ply");
    ok(&recon_args(
        &a,
        &first,
        &["--work-dir", s(&w), "--keep-work"],
    ));
    let out = d.path().join("m.ply");
    let resume = ["--work-dir", s(&w), "--resume"];
    let e = fails(&recon_args(&b, &out, &resume));
    assert!(e.contains("cannot resume") && e.contains("input 1:"), "{e}");
    let e = fails(&recon_args(&a, &out, &[&resume[..], &["--trim"]].concat()));
    assert!(e.contains("--trim: false then, true now"), "{e}");
    let e = fails(&recon_args(&a, &out, &["--work-dir", s(&w)]));
    assert!(e.contains("pass --resume"), "{e}");
    assert!(!out.exists());
    // The same path with new contents (same size: another seed).
    std::fs::copy(&b, &a).unwrap();
    let e = fails(&recon_args(&a, &out, &resume));
    assert!(e.contains("input 1 content"), "{e}");
    // The genuine resume gives the first run's bytes.
    synth(&a, 20_000, 1);
    let e = fails(&recon_args(&a, &out, &resume));
    assert!(
        e.contains("input 1 content"),
        "a rewritten file is another input: {e}"
    );
    std::fs::remove_dir_all(&w).unwrap();
    ok(&recon_args(
        &a,
        &first,
        &["--work-dir", s(&w), "--keep-work"],
    ));
    ok(&recon_args(&a, &out, &resume));
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&first).unwrap());
    assert!(
        !w.exists(),
        "a successful resume removes its work directory"
    );
}

#[test]
fn options_and_output_paths_are_checked_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join("b.ply");
    synth(&input, 2_000, 1);
    let before = names(d.path());
    let out = d.path().join("m.ply");
    let missing = d.path().join("nonexistent");
    let m = s(&out);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--depth", "2"], "--depth 2"),
        (vec!["--tile", "100"], "--tile 100: expected a power of two"),
        (vec!["--threads", "100000"], "--threads 100000"),
        (vec!["--smooth", "0"], "--smooth 0"),
        (vec!["--viewpoint", "1,2"], "x,y,z"),
        (vec!["--work-dir", "nonexistent/w"], "does not exist"),
    ];
    for (extra, want) in &cases {
        let e = usage(&recon_args(&input, &out, extra));
        assert!(e.contains(want), "{extra:?}: {e}");
    }
    let bad_out = [
        (missing.join("y.ply"), "does not exist"),
        (d.path().join("x.off"), "name the output *.ply"),
        (d.path().to_path_buf(), "name the output *.ply"),
    ];
    for (o, want) in &bad_out {
        let e = usage(&recon_args(&input, o, &[]));
        assert!(e.contains(want), "{}: {e}", o.display());
    }
    let e = usage(&["synth", "cube", "--points", "10", "-o", m]);
    assert!(e.contains("unknown shape"), "{e}");
    let e = usage(&["synth", "sphere", "--points", "10", "-o", "y.xyz"]);
    assert!(e.contains("*.ply"), "{e}");
    assert!(!missing.exists(), "-o made a directory");
    assert_eq!(names(d.path()), before, "a refused command left files");
}

#[test]
fn failed_runs_remove_their_work_dir_and_name_the_input() {
    let d = tempfile::tempdir().unwrap();
    let cases: [(&str, String); 4] = [
        (
            "line.xyz",
            (0..40).map(|i| format!("{i} {i} {i}\n")).collect(),
        ),
        (
            "plane.xyz",
            (0..400)
                .map(|i| format!("{} {} 0\n", i % 20, i / 20))
                .collect(),
        ),
        ("same.xyz", "1 2 3\n".repeat(100)),
        ("three.xyz", "0 0 0\n1 0 0\n0 1 0\n".into()),
    ];
    for (name, text) in &cases {
        let input = d.path().join(name);
        std::fs::write(&input, text).unwrap();
        let out = d.path().join("m.ply");
        let e = fails(&recon_args(&input, &out, &[]));
        let first = e.lines().last().unwrap_or_default();
        assert!(
            first.starts_with(&format!("scanflow: error: {}: ", input.display())),
            "{name}: {e}"
        );
        assert!(
            !e.contains(".work"),
            "{name}: names the work directory: {e}"
        );
        assert!(!out.exists() && !d.path().join("m.ply.work").exists());
    }
}

#[test]
fn a_budget_below_what_the_depth_needs_is_refused_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join("b.ply");
    synth(&input, 20_000, 1);
    let out = d.path().join("m.ply");
    let work = d.path().join("m.ply.work");
    // Ingest would fit in 16M; a reconstruction cannot: refused before the ingest, naming
    // the floor, with nothing made.
    let e = usage(&recon_args(&input, &out, &["--depth", "9", "--mem", "16M"]));
    assert!(
        e.contains("--mem 16.00 MiB") && e.contains("--depth 9 needs at least 64.00 MiB"),
        "{e}"
    );
    assert!(!work.exists() && !out.exists());
    // At the floor the run completes (the depth-9 coarse solve does not fit it: a level of
    // leaves at depth 7 over a dense depth-5 solve).
    let o = ok(&recon_args(&input, &out, &["--depth", "9", "--mem", "64M"]));
    assert!(out.is_file() && !work.exists(), "{o}");
}

#[test]
fn stale_temp_files_of_the_output_are_removed_by_the_next_run() {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join("b.ply");
    synth(&input, 20_000, 1);
    // A pid above Linux's largest (2^22) belongs to no live process.
    let stale = [
        d.path().join("m.ply.tmp-99999999"),
        d.path().join("m.ply.tmp-99999999.faces"),
    ];
    let other = d.path().join("other.ply.tmp-99999999");
    for p in stale.iter().chain([&other]) {
        std::fs::write(p, b"partial").unwrap();
    }
    ok(&recon_args(&input, &d.path().join("m.ply"), &[]));
    assert!(stale.iter().all(|p| !p.exists()), "stale temp files stay");
    assert!(other.exists(), "another output's temp file was removed");
}

/// A tiny deterministic generator for the kill points.
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// Kill points: half SIGKILL, half SIGTERM.
const KILLS: usize = 12;

#[test]
fn killed_runs_resume_to_identical_bytes_and_leave_no_temp_files() {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join("k.ply");
    synth(&input, 60_000, 3);
    let reference = d.path().join("ref.ply");
    let t0 = Instant::now();
    ok(&recon_args(
        &input,
        &reference,
        &["--depth", "7", "--threads", "2"],
    ));
    let full = t0.elapsed().as_secs_f64();
    let want = std::fs::read(&reference).unwrap();
    let out = d.path().join("m.ply");
    let args = recon_args(&input, &out, &["--depth", "7", "--threads", "2"]);
    let mut state = 13;
    let (mut killed, mut interrupted) = (0, 0);
    for i in 0..KILLS {
        let sigterm = i % 2 == 1;
        let at = Duration::from_secs_f64(full * (0.05 + 0.9 * lcg(&mut state)));
        let child = bin()
            .args(&args)
            .args(["--resume"])
            .stderr(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(at);
        let pid = child.id().to_string();
        let sig = if sigterm { "-TERM" } else { "-KILL" };
        let _ = std::process::Command::new("kill")
            .args([sig, &pid])
            .status();
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{err}");
        match o.status.code() {
            Some(0) => std::fs::remove_file(&out).unwrap(), // finished before the signal
            Some(143) => {
                interrupted += 1;
                assert!(err.contains("interrupted by SIGTERM"), "{err}");
                assert!(err.contains("--resume"), "{err}");
                let t = temp_files(d.path());
                assert!(t.is_empty(), "SIGTERM left {t:?}");
                if out.exists() {
                    // Interrupted while removing the work directory: the output is complete.
                    assert!(std::fs::read(&out).unwrap() == want);
                    std::fs::remove_file(&out).unwrap();
                }
            }
            None => killed += 1,
            Some(c) => panic!("killed run exited {c}: {err}"),
        }
        ok(&[&args[..], &["--resume"]].concat());
        assert!(
            std::fs::read(&out).unwrap() == want,
            "kill {i} resumed to other bytes"
        );
        std::fs::remove_file(&out).unwrap();
        let t = temp_files(d.path());
        assert!(t.is_empty(), "resume after kill {i} left {t:?}");
        assert!(!d.path().join("m.ply.work").exists());
    }
    eprintln!("{killed} runs killed, {interrupted} interrupted of {KILLS}, full run {full:.2} s");
    assert!(
        killed + interrupted >= KILLS / 2,
        "too few runs were cut short"
    );
}
