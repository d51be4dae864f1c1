//! Split runs: shards of one reconstruction run together against one work directory, `merge`
//! welds their tiles into the bytes one process writes; killed shards, mixed options and early
//! merges; and a real SLURM array job (scripts/slurm/ci_test.sh).

use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use super::common::{bin, fails, finish, ok, shared, spawn, usage};

/// A store of a synthetic torus of `points` points.
fn torus_store(dir: &Path, points: u32) -> PathBuf {
    let ply = dir.join("torus.ply");
    let p = points.to_string();
    ok(&[
        "synth",
        "torus",
        "--points",
        &p,
        "--noise",
        "0.001",
        "-o",
        ply.to_str().unwrap(),
        "--progress",
        "none",
    ]);
    store_of(dir, &[ply], &[])
}

/// The store of the point files `inputs` (ingest options `extra`).
fn store_of(dir: &Path, inputs: &[PathBuf], extra: &[&str]) -> PathBuf {
    let store = dir.join("store");
    let mut args = vec!["ingest"];
    args.extend(inputs.iter().map(|p| p.to_str().unwrap()));
    args.extend(["-o", store.to_str().unwrap(), "--progress", "none"]);
    args.extend(extra);
    ok(&args);
    store
}

/// The arguments of reconstructing `store` into `out` with `opts`.
fn recon<'a>(store: &'a Path, out: &'a Path, opts: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "reconstruct",
        store.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--progress",
        "none",
        "--mem",
        "256M",
    ];
    a.extend(opts);
    a
}

/// Start shard `i` of `n` of reconstructing `store` into `out`, with work directory `work`.
fn spawn_shard(store: &Path, out: &Path, work: &Path, i: u32, n: u32, opts: &[&str]) -> Child {
    let shard = format!("{i}/{n}");
    let mut args = recon(store, out, opts);
    args.extend(["--threads", "1", "--shard", &shard]);
    args.extend(["--work-dir", work.to_str().unwrap()]);
    spawn(&args)
}

/// The arguments of merging the work directory `work` into `out`.
fn merge<'a>(work: &'a Path, out: &'a Path) -> [&'a str; 6] {
    let (w, o) = (work.to_str().unwrap(), out.to_str().unwrap());
    ["merge", w, "-o", o, "--progress", "none"]
}

/// `n` shards run together, then merged; returns the merged bytes.
fn sharded(store: &Path, dir: &Path, n: u32, opts: &[&str]) -> Vec<u8> {
    let out = dir.join(format!("sharded-{n}.ply"));
    let work = dir.join(format!("work-{n}"));
    let children: Vec<Child> = (0..n)
        .map(|i| spawn_shard(store, &out, &work, i, n, opts))
        .collect();
    for c in children {
        let line = finish(c);
        assert!(line.contains("scanflow merge"), "{line}");
    }
    assert!(!out.exists(), "a shard wrote the mesh");
    let line = ok(&merge(&work, &out));
    assert!(line.contains("merged"), "{line}");
    assert!(!work.exists(), "merge left its work directory");
    std::fs::read(&out).unwrap()
}

#[test]
fn shards_merge_into_the_single_process_bytes() {
    let d = tempfile::tempdir().unwrap();
    let store = torus_store(d.path(), 60_000);
    let single = d.path().join("single.ply");
    ok(&recon(&store, &single, &["--depth", "7"]));
    let want = std::fs::read(&single).unwrap();
    for n in [1, 2, 5] {
        assert!(
            sharded(&store, d.path(), n, &["--depth", "7"]) == want,
            "{n} shards"
        );
    }
    // Another tile size (which orders the vertices otherwise): the same bytes as one
    // process with that tile size.
    let opts = ["--depth", "7", "--tile", "16"];
    ok(&recon(&store, &single, &opts));
    assert!(sharded(&store, d.path(), 3, &opts) == std::fs::read(&single).unwrap());
    // Levels of leaves (the recursive scheme): every shard solves its slice of each level,
    // and reads the levels above from the shared checkpoints.
    let opts = ["--depth", "8", "--coarse-depth", "4"];
    std::fs::remove_file(d.path().join("sharded-3.ply")).unwrap();
    ok(&recon(&store, &single, &opts));
    assert!(sharded(&store, d.path(), 3, &opts) == std::fs::read(&single).unwrap());
}

#[test]
fn shards_of_the_merged_bunny_scans_merge_into_the_single_process_bytes() {
    let Some(conf) = shared("bunny/bun.conf") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let store = d.path().join("store");
    ok(&[
        "ingest",
        "--conf",
        conf.to_str().unwrap(),
        "-o",
        store.to_str().unwrap(),
        "--progress",
        "none",
    ]);
    let single = d.path().join("single.ply");
    ok(&recon(&store, &single, &["--depth", "8"]));
    let want = std::fs::read(&single).unwrap();
    for n in [1, 2, 5] {
        assert!(
            sharded(&store, d.path(), n, &["--depth", "8"]) == want,
            "{n} shards"
        );
    }
}

/// The work items (leaf and tile checkpoints) in the work directory `work`, by name; temporary
/// files are not items.
fn items(work: &Path, sub: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(work.join(sub))
        .map(|rd| {
            rd.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| !n.contains(".tmp-"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn a_killed_shard_is_replaced_and_rerun_without_repeating_or_missing_work() {
    let d = tempfile::tempdir().unwrap();
    let store = torus_store(d.path(), 200_000);
    let single = d.path().join("single.ply");
    let opts = ["--depth", "8"];
    ok(&recon(&store, &single, &opts));
    let want = std::fs::read(&single).unwrap();
    let (out, work) = (d.path().join("m.ply"), d.path().join("w"));
    for kill_after in [1, 40] {
        // Shard 1 is killed outright once it holds `kill_after` claims: in the middle of its
        // claims and of writing their checkpoints.
        let survivor = spawn_shard(&store, &out, &work, 0, 2, &opts);
        let mut victim = spawn_shard(&store, &out, &work, 1, 2, &opts);
        let pid = victim.id().to_string();
        let t0 = Instant::now();
        let mine = |p: &Path| {
            std::fs::read_to_string(p)
                .map(|t| t.split_whitespace().nth(1) == Some(&pid))
                .unwrap_or(false)
        };
        loop {
            let held = std::fs::read_dir(work.join("claims"))
                .map(|rd| rd.flatten().filter(|e| mine(&e.path())).count())
                .unwrap_or(0);
            if held >= kill_after || victim.try_wait().unwrap().is_some() {
                break;
            }
            assert!(t0.elapsed() < Duration::from_secs(60), "no claim seen");
            std::thread::sleep(Duration::from_millis(2));
        }
        victim.kill().unwrap();
        let status = victim.wait().unwrap();
        let line = finish(survivor);
        eprintln!("killed after {kill_after} claims ({status}); {line}");
        // The survivor did the killed shard's work too: every leaf and tile is there, once.
        let desc: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(work.join("merge.json")).unwrap())
                .unwrap();
        let tiles = desc["tiles"].as_array().unwrap().len();
        assert_eq!(items(&work, "tiles").len(), tiles);
        let leaves = items(&work, "leaves");
        // Shard 1 run again (a requeue): it finds everything done and repeats nothing.
        let again = finish(spawn_shard(&store, &out, &work, 1, 2, &opts));
        assert!(
            again.contains(": 0 of ") && again.contains("leaves and 0 of"),
            "{again}"
        );
        assert_eq!(items(&work, "leaves"), leaves);
        ok(&merge(&work, &out));
        assert!(
            std::fs::read(&out).unwrap() == want,
            "after kill {kill_after}"
        );
        std::fs::remove_file(&out).unwrap();
        assert!(!work.exists());
    }
}

/// The number of chunks a shard's `kind` read of the coarse pass did itself, of how many,
/// from its log.
fn chunks_read_here(log: &str, kind: &str) -> (u32, u32) {
    let line = log
        .lines()
        .find(|l| l.contains(&format!("{kind}: ")) && l.contains("chunks of store cells"))
        .unwrap_or_else(|| panic!("no {kind} chunks in:\n{log}"));
    let after = line.split(&format!("{kind}: ")).nth(1).unwrap();
    let w: Vec<&str> = after.split_whitespace().collect();
    (w[0].parse().unwrap(), w[2].parse().unwrap())
}

#[test]
fn shards_share_the_coarse_pass_and_a_damaged_part_is_named() {
    // Store cells of 20k points: the coarse pass's chunks are work items like leaves.
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("torus.ply");
    let p = ply.to_str().unwrap();
    ok(&[
        "synth", "torus", "--points", "400000", "--noise", "0.001", "-o", p,
    ]);
    let store = d.path().join("store");
    super::common::ingest_in_cells(&ply, &store, 20_000);
    let single = d.path().join("single.ply");
    let opts = ["--depth", "7"];
    ok(&recon(&store, &single, &opts));
    let (out, work) = (d.path().join("m.ply"), d.path().join("w"));
    let shard = |i: u32| {
        let mut a = recon(&store, &out, &opts);
        let s = format!("{i}/2");
        a.extend(["--threads", "1", "--shard", &s, "--work-dir"]);
        a.push(work.to_str().unwrap());
        a.iter().map(|x| x.to_string()).collect::<Vec<String>>()
    };
    let run = |args: &[String], good: bool| {
        let a: Vec<&str> = args.iter().map(|x| x.as_str()).collect();
        if good {
            super::common::ok_log(&a)
        } else {
            fails(&a)
        }
    };
    // Shard 0 alone reads every chunk: its own slice, then the rest that nobody did.
    let log = run(&shard(0), true);
    let (here, all) = chunks_read_here(&log, "splat");
    assert!(all >= 3 && here == all, "{log}");
    assert_eq!(chunks_read_here(&log, "density"), (all, all));
    // Shard 1 after it (its coarse pass's results taken away) reads none: every chunk's
    // parts are there to read back.
    let leaves = work.join("leaves");
    std::fs::remove_file(leaves.join("coarse.zst")).unwrap();
    let splat1 = leaves.join("coarse-splat-000001.zst");
    let good = std::fs::read(&splat1).unwrap();
    std::fs::write(&splat1, &good[..good.len() / 2]).unwrap();
    let e = run(&shard(1), false);
    assert!(
        e.contains("coarse-splat-000001.zst") && e.contains("corrupt coarse pass part"),
        "{e}"
    );
    std::fs::remove_file(&splat1).unwrap();
    let log = run(&shard(1), true);
    assert_eq!(chunks_read_here(&log, "splat"), (1, all), "{log}");
    assert_eq!(chunks_read_here(&log, "density").0, 0, "{log}");
    ok(&merge(&work, &out));
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&single).unwrap());
}

#[test]
fn shards_refuse_mixed_runs_bad_numbers_and_point_files_and_merge_waits_for_them() {
    let d = tempfile::tempdir().unwrap();
    let store = torus_store(d.path(), 20_000);
    let (out, work) = (d.path().join("m.ply"), d.path().join("w"));
    let w = work.to_str().unwrap();
    // Numbers and environments.
    for bad in ["2/2", "0/0", "a/3", "3"] {
        let mut args = recon(&store, &out, &["--shard", bad]);
        args.extend(["--work-dir", w]);
        let e = usage(&args);
        assert!(e.contains(&format!("--shard {bad}")), "{e}");
    }
    let mut args = recon(&store, &out, &["--shard", "auto", "--work-dir", w]);
    args.extend(["--depth", "6"]);
    let o = bin()
        .args(&args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("SLURM_ARRAY_TASK_ID"), "{e}");
    // Point files are ingested once, before the shards.
    let ply = d.path().join("torus.ply");
    let e = usage(&[
        "reconstruct",
        ply.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--shard",
        "0/2",
    ]);
    assert!(e.contains("ingest"), "{e}");
    // A merge before any shard, or of a directory that is no work directory.
    let plain = d.path().join("plain");
    std::fs::create_dir(&plain).unwrap();
    let e = fails(&merge(&plain, &out));
    assert!(e.contains("not a scanflow work directory"), "{e}");
    // Shards of two different runs in one work directory: the second is refused.
    finish(spawn_shard(&store, &out, &work, 0, 2, &["--depth", "6"]));
    let o = spawn_shard(&store, &out, &work, 1, 2, &["--depth", "7"])
        .wait_with_output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("--depth: 6 then, 7 now"), "{e}");
    // A tile missing (its shard not finished): merge names it and writes nothing.
    let tiles = items(&work, "tiles");
    std::fs::remove_file(work.join("tiles").join(&tiles[0])).unwrap();
    let e = fails(&merge(&work, &out));
    assert!(e.contains("1 of ") && e.contains("have no mesh yet"), "{e}");
    assert!(!out.exists() && work.exists());
    // The shard run again fills the gap; the merge then succeeds.
    finish(spawn_shard(&store, &out, &work, 1, 2, &["--depth", "6"]));
    ok(&merge(&work, &out));
    assert!(out.exists() && !work.exists());
    // A directory of the user's, even empty, is never the work directory: the shards share
    // a subdirectory inside it, which merge removes, and the user's stays.
    let mine = d.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    let out2 = d.path().join("m2.ply");
    let shards: Vec<Child> = (0..2)
        .map(|i| spawn_shard(&store, &out2, &mine, i, 2, &["--depth", "6"]))
        .collect();
    let inside = mine.join("m2.ply.work");
    for c in shards {
        let line = finish(c);
        assert!(
            line.contains(&format!("merge {}", inside.display())),
            "{line}"
        );
    }
    ok(&merge(&inside, &out2));
    assert!(out2.exists() && mine.is_dir() && !inside.exists());
}

/// A real cluster: SLURM on localhost runs ingest, an array of 3 shards and the merge, then
/// again with a shard requeued mid-run; both merged meshes must be the single process's bytes.
#[test]
fn a_slurm_array_job_gives_the_single_process_bytes() {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/slurm/ci_test.sh");
    let o = std::process::Command::new("bash")
        .arg(&script)
        .arg(env!("CARGO_BIN_EXE_scanflow"))
        .output()
        .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    match o.status.code() {
        Some(0) => eprintln!("{out}{err}"),
        Some(77) => eprintln!("skipped: no SLURM cluster can be started here: {err}"),
        c => panic!("the SLURM test failed ({c:?}):\n{out}\n{err}"),
    }
}
