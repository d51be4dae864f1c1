//! The memory budget: store reads, peak memory and thread counts under a tight budget.

use super::*;

/// The store cells each pass read, from the log lines "STAGE: N store cells read (...)".
fn cell_reads(stderr: &str) -> Vec<(String, usize)> {
    stderr
        .lines()
        .filter_map(|l| {
            let (stage, rest) = l.strip_prefix("scanflow: info: ")?.split_once(": ")?;
            let n = rest
                .strip_suffix(" MiB")?
                .split_once(" store cells read")?
                .0;
            Some((stage.to_string(), n.parse().ok()?))
        })
        .collect()
}

#[test]
fn no_pass_reads_a_store_cell_twice_where_the_cache_holds_the_store() {
    // 2M points in cells of at most 25,000 (72 MB sorted) under --mem 1G: the point cache
    // holds the store, so the leaves read every cell once and the tiles (which read only
    // for the vertices they fit: none here) each at most once, however the waves split their reads into
    // runs. (A cache that lets cells go reads a 100M-point store many times over: 9 times in
    // the finest leaves, 15 in the tiles, before the passes grew it; no store small enough
    // for the tests passes the plan's 128 MiB.)
    let d = tempfile::tempdir().unwrap();
    let ply = synth(d.path(), "sphere", 2_000_000, 0.0005);
    let store = d.path().join("s");
    ingest_in_cells(&ply, &store, 25000);
    let cells = scanflow::store::Store::open(&store)
        .unwrap()
        .manifest
        .cells
        .len();
    let out = d.path().join("m.ply");
    let err = ok_log(&[
        "reconstruct",
        s(&store),
        "-o",
        s(&out),
        "--depth",
        "8",
        "--mem",
        "1G",
        "--threads",
        "2",
        "--progress",
        "none",
    ]);
    let reads = cell_reads(&err);
    let of = |stage: &str| reads.iter().find(|r| r.0 == stage).map(|r| r.1);
    assert_eq!(of("leaves"), Some(cells), "{err}");
    let tiles = of("tiles").unwrap_or_else(|| panic!("no tiles' reads logged: {err}"));
    assert!(tiles <= cells, "{tiles} of {cells}: {err}");
}

#[test]
fn reconstruct_stays_under_mem_plus_margin() {
    // The demo's input (a 1M-point bumpy sphere, noise 0.001) at depth 9 on 2 threads, with
    // one malloc arena (main.rs), ingest into the work directory included; with glibc's
    // per-thread arenas 185 to 223 MiB under --mem 128M were measured (before levels).
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("b.ply");
    ok(&[
        "synth",
        "bumpy",
        "--points",
        "1000000",
        "--noise",
        "0.001",
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    // Under 64M (the floor) and 128M the depth-9 coarse solve does not fit: a level of
    // leaves at depth 7 over a dense depth-5 solve instead. Measured peaks (release build):
    // 74 MiB under 64M, 104 MiB under 128M, 137 MiB under 256M (one level).
    for mib in [64u64, 128, 256] {
        let out = d.path().join(format!("b_mesh_{mib}.ply"));
        let mem = format!("{mib}M");
        let err = ok_log(&[
            "reconstruct",
            s(&ply),
            "-o",
            s(&out),
            "--depth",
            "9",
            "--mem",
            &mem,
            "--threads",
            "2",
            "--progress",
            "json",
        ]);
        let peak = peak_rss(&err);
        assert!(peak > 0, "no peak RSS reported: {err}");
        // The README states the margin: 64 MiB over --mem.
        assert!(
            peak < (mib + 64) << 20,
            "--mem {mem}: peak RSS {} MiB",
            peak >> 20
        );
        let c = check_mesh(&read_mesh(&out).unwrap());
        assert!(c.watertight && c.components == 1, "{c:?}");
    }
}

#[test]
fn same_mesh_for_any_thread_count_under_a_tight_budget() {
    // Under a tight --mem the ingest chunks shrink with the thread count; the cube (and so
    // the mesh) must not follow them (8 threads once gave another cube origin here).
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("b.ply");
    ok(&[
        "synth",
        "bumpy",
        "--points",
        "400000",
        "--seed",
        "5",
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    let mut meshes = Vec::new();
    for t in ["1", "8"] {
        let out = d.path().join(format!("m{t}.ply"));
        recon(
            &ply,
            &out,
            &["--depth", "7", "--threads", t, "--mem", "64M"],
        );
        meshes.push(std::fs::read(&out).unwrap());
    }
    assert!(meshes[0] == meshes[1], "the mesh depends on --threads");
    // Under 2G the allocator follows the thread count (exec::alloc): mimalloc for 2 workers,
    // glibc for 8; the budget, and so the mesh, does not.
    use scanflow::exec::alloc::{reserve_bytes, slack_bytes};
    assert!(slack_bytes(2) <= reserve_bytes(2 << 30) && slack_bytes(8) > reserve_bytes(2 << 30));
    for t in ["2", "8"] {
        let out = d.path().join(format!("a{t}.ply"));
        recon(&ply, &out, &["--depth", "7", "--threads", t, "--mem", "2G"]);
        assert!(
            std::fs::read(&out).unwrap() == meshes[0],
            "the mesh depends on the allocator ({t} threads under 2G)"
        );
    }
}
