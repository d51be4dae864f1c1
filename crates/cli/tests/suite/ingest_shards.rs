//! Split ingests: tasks of `ingest --shard I/N` run together against one work directory and
//! leave the store one process writes (the same cells, points, normals and order); killed
//! tasks, mixed options and a store already there.

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use scanflow::store::Store;

use super::common::{bin, fails, finish, ok, shared, spawn, usage};

/// Write `points` samples of the synthetic `shape` to `dir/NAME.ply`.
fn synth(dir: &Path, shape: &str, points: u32, seed: u32) -> PathBuf {
    let ply = dir.join(format!("{shape}-{seed}.ply"));
    let (p, s) = (points.to_string(), seed.to_string());
    ok(&[
        "synth",
        shape,
        "--points",
        &p,
        "--noise",
        "0.001",
        "--seed",
        &s,
        "-o",
        ply.to_str().unwrap(),
        "--progress",
        "none",
    ]);
    ply
}

/// The arguments of ingesting `inputs` into `out` with `opts`.
fn ingest_args<'a>(inputs: &'a [PathBuf], out: &'a Path, opts: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec!["ingest"];
    a.extend(inputs.iter().map(|p| p.to_str().unwrap()));
    a.extend(["-o", out.to_str().unwrap(), "--progress", "none"]);
    a.extend(opts);
    a
}

/// Start task `i` of `n` of the split ingest of `inputs` into `out`.
fn spawn_task(inputs: &[PathBuf], out: &Path, work: &Path, i: u32, n: u32, opts: &[&str]) -> Child {
    let shard = format!("{i}/{n}");
    // Tasks on nodes with different free memory: any --mem from 256 MiB sizes alike.
    let mem = format!("{}M", 256 + 64 * i);
    let mut args = ingest_args(inputs, out, opts);
    args.extend(["--threads", "1", "--mem", &mem, "--shard", &shard]);
    args.extend(["--work-dir", work.to_str().unwrap()]);
    spawn(&args)
}

/// Require the two stores to hold the same cells with the same points (positions, normals,
/// every attribute, in the same order) and the same description, frames aside.
fn same_store(a: &Path, b: &Path) {
    let (x, y) = (Store::open(a).unwrap(), Store::open(b).unwrap());
    let (m, n) = (&x.manifest, &y.manifest);
    assert_eq!(m.point_count, n.point_count);
    assert_eq!((m.cube, m.bounds), (n.cube, n.bounds));
    assert_eq!(m.attributes, n.attributes);
    assert_eq!(m.estimated_normals, n.estimated_normals);
    assert_eq!(m.cells.len(), n.cells.len());
    for (i, (c, d)) in m.cells.iter().zip(&n.cells).enumerate() {
        assert_eq!(
            (c.key, c.count, c.bounds),
            (d.key, d.count, d.bounds),
            "cell {i}"
        );
        let (p, q) = (x.read_cell(i).unwrap(), y.read_cell(i).unwrap());
        assert!(
            p.pos == q.pos && p.normal == q.normal,
            "cell {i}'s points differ"
        );
        assert!(p.color == q.color && p.source == q.source, "cell {i}");
    }
}

#[test]
fn split_ingests_store_the_points_of_one_process() {
    let d = tempfile::tempdir().unwrap();
    // Two oriented inputs (normals read); one unoriented (normals estimated, small cells).
    let oriented = vec![
        synth(d.path(), "torus", 50_000, 1),
        synth(d.path(), "bumpy", 30_000, 2),
    ];
    let bumpy = vec![synth(d.path(), "bumpy", 60_000, 3)];
    let estimate = ["--normals", "estimate", "--max-cell-points", "4000"];
    // A far point the bounds' sample misses (in the second of 244 windows, the sample reading
    // one in three): the count is repeated on the exact cube, by every task alike.
    let outlier = vec![synth(d.path(), "sphere", 1_000_000, 7)];
    let mut bytes = std::fs::read(&outlier[0]).unwrap();
    let data = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let at = data + (4096 + 5) * 24;
    bytes[at..at + 4].copy_from_slice(&100f32.to_le_bytes());
    std::fs::write(&outlier[0], &bytes).unwrap();
    // A LiDAR tile: 8-bit colours in 16-bit fields (scaled by what every task's count saw),
    // normals estimated facing the sky.
    let lidar: Vec<PathBuf> = shared("lidar/autzen_trim.las").into_iter().collect();
    let small = ["--max-cell-points", "20000"];
    for (k, (inputs, opts)) in [
        (&oriented, &[][..]),
        (&bumpy, &estimate[..]),
        (&lidar, &small[..]),
        (&outlier, &[][..]),
    ]
    .into_iter()
    .enumerate()
    .filter(|(_, (i, _))| !i.is_empty())
    {
        let single = d.path().join(format!("single-{k}"));
        let line = ok(&ingest_args(inputs, &single, opts));
        if inputs == &outlier {
            let m = Store::open(&single).unwrap().manifest;
            assert!(m.bounds.max[0] == 100.0, "{line}");
        }
        for n in [1, 2, 3] {
            let (out, work) = (
                d.path().join(format!("s{k}-{n}")),
                d.path().join(format!("w{k}-{n}")),
            );
            let tasks: Vec<Child> = (0..n)
                .map(|i| spawn_task(inputs, &out, &work, i, n, opts))
                .collect();
            let lines: Vec<String> = tasks.into_iter().map(finish).collect();
            // One task writes the store; the others find it written.
            let wrote = lines.iter().filter(|l| l.contains("ingested")).count();
            assert_eq!(wrote, 1, "{lines:?}");
            assert!(!work.exists(), "the work directory was left");
            same_store(&single, &out);
            // A task run again (a requeue) finds the store complete and changes nothing.
            let again = finish(spawn_task(inputs, &out, &work, n - 1, n, opts));
            assert!(again.contains("is complete"), "{again}");
            same_store(&single, &out);
            assert!(!work.exists());
        }
    }
}

/// The claims that the process `pid` holds in the split ingest's work directory `work`.
fn claims_of(work: &Path, pid: u32) -> usize {
    let pid = pid.to_string();
    std::fs::read_dir(work.join("ingest/claims"))
        .map(|rd| {
            rd.flatten()
                .filter(|e| {
                    std::fs::read_to_string(e.path())
                        .map(|t| t.split_whitespace().nth(1) == Some(&pid))
                        .unwrap_or(false)
                })
                .count()
        })
        .unwrap_or(0)
}

#[test]
fn a_killed_ingest_task_is_rerun_to_the_store_of_one_process() {
    let d = tempfile::tempdir().unwrap();
    let inputs = vec![synth(d.path(), "bumpy", 150_000, 4)];
    let opts = ["--normals", "estimate", "--max-cell-points", "6000"];
    let single = d.path().join("single");
    ok(&ingest_args(&inputs, &single, &opts));
    for kill_after in [1, 12, 20, 24] {
        let (out, work) = (
            d.path().join(format!("s{kill_after}")),
            d.path().join(format!("w{kill_after}")),
        );
        // Task 0 alone, killed outright once it holds `kill_after` claims: in the middle of a
        // stage's items and of writing their checkpoints (counts, packs, cells, normals).
        let mut victim = spawn_task(&inputs, &out, &work, 0, 2, &opts);
        let t0 = Instant::now();
        while claims_of(&work, victim.id()) < kill_after && victim.try_wait().unwrap().is_none() {
            assert!(t0.elapsed() < Duration::from_secs(60), "no claim seen");
            std::thread::sleep(Duration::from_millis(1));
        }
        victim.kill().unwrap();
        let status = victim.wait().unwrap();
        // 5 count, 5 scatter, 7 assembly items, then the normals' (0.7 s of the task's 0.8):
        // every kill lands before the store is written.
        assert!(
            !status.success() && !out.exists(),
            "after {kill_after} claims"
        );
        // Both tasks then (task 0 requeued): the store is the one process's.
        let tasks = [
            spawn_task(&inputs, &out, &work, 0, 2, &opts),
            spawn_task(&inputs, &out, &work, 1, 2, &opts),
        ];
        for t in tasks {
            finish(t);
        }
        same_store(&single, &out);
        assert!(!work.exists(), "after kill {kill_after}");
    }
}

#[test]
fn split_ingests_refuse_mixed_options_and_other_stores() {
    let d = tempfile::tempdir().unwrap();
    let inputs = vec![synth(d.path(), "torus", 20_000, 5)];
    let (out, work) = (d.path().join("s"), d.path().join("w"));
    let (o, w) = (out.to_str().unwrap(), work.to_str().unwrap());
    let task = |i: &str, extra: &[&str]| {
        let mut a = ingest_args(&inputs, &out, extra);
        a.extend(["--shard", i, "--work-dir", w, "--mem", "300M"]);
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    // A task of another run in the same work directory: refused, naming the difference.
    let first = task("0/2", &["--max-cell-points", "5000"]);
    let second = task("1/2", &["--max-cell-points", "7000"]);
    let mut a = bin()
        .args(&first)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Let the first task make the work directory, then start the second.
    let t0 = Instant::now();
    while !work.join("run.json").exists() && a.try_wait().unwrap().is_none() {
        assert!(t0.elapsed() < Duration::from_secs(30));
        std::thread::sleep(Duration::from_millis(1));
    }
    // Refused, naming the difference, whether the first task is still running (the work
    // directory's description differs) or has already made the store alone (the store's
    // manifest differs).
    let e = fails(&second.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        e.contains("--max-cell-points") && (e.contains(w) || e.contains(o)),
        "{e}"
    );
    assert!(a.wait().unwrap().success());
    let e = fails(&second.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        e.contains("--max-cell-points 5000 there, 7000 here") && e.contains(o),
        "{e}"
    );
    // The options a store's manifest records beside them: the cells' zstd level and
    // --skip-invalid.
    for (extra, want) in [
        (&["--zstd-level", "3"][..], "--zstd-level -1 there, 3 here"),
        (
            &["--skip-invalid"][..],
            "--skip-invalid not given there, given here",
        ),
    ] {
        let mut opts = vec!["--max-cell-points", "5000"];
        opts.extend(extra);
        let e = fails(
            &task("1/2", &opts)
                .iter()
                .map(String::as_str)
                .collect::<Vec<_>>(),
        );
        assert!(e.contains(want) && e.contains(o), "{e}");
    }
    assert!(Store::open(&out).is_ok());
    // A store from other inputs under the name: refused, kept.
    let other = vec![synth(d.path(), "torus", 20_000, 6)];
    let mut args = ingest_args(&other, &out, &["--shard", "0/1"]);
    args.extend(["--work-dir", w]);
    let e = fails(&args);
    assert!(e.contains(o) && e.contains("other inputs"), "{e}");
    assert!(Store::open(&out).is_ok());
    // --work-dir without --shard, a bad shard.
    let e = usage(&ingest_args(
        &inputs,
        &d.path().join("x"),
        &["--work-dir", w],
    ));
    assert!(e.contains("--shard"), "{e}");
    let e = usage(&ingest_args(
        &inputs,
        &d.path().join("x"),
        &["--shard", "2/2"],
    ));
    assert!(e.contains("--shard 2/2"), "{e}");
}
