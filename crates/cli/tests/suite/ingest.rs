//! Ingest: counts, determinism, splitting, memory, reading back.

use super::common::*;
use scanflow::store::Store;

#[test]
fn sphere_round_trip_and_info() {
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("s.ply");
    let store = d.path().join("s.store");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "100000",
        "--seed",
        "3",
        "-o",
        s(&ply),
    ]);
    assert!(d.path().join("s.truth.json").exists());
    ingest_in_cells(&ply, &store, 4000);
    let st = Store::open(&store).unwrap();
    assert_eq!(st.manifest.point_count, 100_000);
    assert!(st.manifest.attributes.normal);
    assert!(st.manifest.cells.iter().all(|c| c.count <= 4000));
    assert!(st.manifest.cells.len() >= 25);
    // Every point comes back, inside its cell's box, with a unit outward normal.
    let mut n = 0;
    for i in 0..st.manifest.cells.len() {
        let b = st.read_cell(i).unwrap();
        let bx = st.manifest.cube.cell_box(st.manifest.cells[i].key);
        for (p, nn) in b.pos.iter().zip(&b.normal) {
            for k in 0..3 {
                assert!(p[k] >= bx.min[k] - 1e-9 && p[k] <= bx.max[k] + 1e-9);
            }
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - 1.0).abs() < 1e-6);
            let dot = (p[0] * nn[0] as f64 + p[1] * nn[1] as f64 + p[2] * nn[2] as f64) / r;
            assert!(dot > 0.999);
        }
        n += b.len();
    }
    assert_eq!(n, 100_000);
    let info: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&store), "--json"])).unwrap();
    assert_eq!(info["points"], 100_000);
    let text = ok(&["info", s(&ply), "--progress", "none"]);
    assert!(
        text.contains("100000") && text.contains("nx ny nz"),
        "{text}"
    );
}

#[test]
fn same_bytes_for_any_thread_count() {
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("t.ply");
    ok(&[
        "synth",
        "torus",
        "--points",
        "60000",
        "--noise",
        "0.002",
        "-o",
        s(&ply),
    ]);
    let mut trees = Vec::new();
    for t in ["1", "2", "3"] {
        let store = d.path().join(format!("t{t}.store"));
        ok(&[
            "ingest",
            s(&ply),
            "-o",
            s(&store),
            "--threads",
            t,
            "--max-cell-points",
            "3000",
            "--mem",
            "64M",
            "--progress",
            "none",
        ]);
        trees.push(tree_bytes(&store));
    }
    assert!(trees[0].len() > 10);
    assert_eq!(trees[0], trees[1]);
    assert_eq!(trees[0], trees[2]);
}

#[test]
fn dense_cluster_is_split_again() {
    // 20000 points in a tiny cluster plus two far points: the counting grid puts the cluster
    // in one grid cell, which must be counted again and split.
    let d = tempfile::tempdir().unwrap();
    let xyz = d.path().join("c.xyz");
    let mut text = String::from("0 0 0\n1000 1000 1000\n");
    for i in 0..20000u32 {
        let a = i as f64 * 0.618;
        text += &format!(
            "{} {} {}\n",
            500.0 + a.sin(),
            500.0 + a.cos(),
            500.0 + ((i % 97) as f64) * 1e-2
        );
    }
    std::fs::write(&xyz, text).unwrap();
    let mut trees = Vec::new();
    for t in ["1", "2"] {
        let store = d.path().join(format!("c{t}.store"));
        ok(&[
            "ingest",
            s(&xyz),
            "-o",
            s(&store),
            "--max-cell-points",
            "1000",
            "--threads",
            t,
            "--progress",
            "none",
        ]);
        let st = Store::open(&store).unwrap();
        assert_eq!(st.manifest.point_count, 20002);
        assert!(
            st.manifest.cells.iter().all(|c| c.count <= 1000),
            "{:?}",
            st.manifest
                .cells
                .iter()
                .map(|c| c.count)
                .collect::<Vec<_>>()
        );
        assert!(st.manifest.cells.iter().any(|c| c.level > 8));
        let total: usize = (0..st.manifest.cells.len())
            .map(|i| st.read_cell(i).unwrap().len())
            .sum();
        assert_eq!(total, 20002);
        trees.push(tree_bytes(&store));
    }
    assert_eq!(trees[0], trees[1]);
}

#[test]
fn two_million_points_under_256m() {
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("s.ply");
    let store = d.path().join("s.store");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "2000000",
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    // Ingest into `out` with `extra`: the store's point count checked, the peak RSS reported.
    let peak_of = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec!["ingest", s(&ply), "-o", s(out), "--progress", "json"];
        args.extend_from_slice(extra);
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        assert_eq!(Store::open(out).unwrap().manifest.point_count, 2_000_000);
        let peak = peak_rss(&err);
        assert!(peak > 0, "no peak RSS reported: {err}");
        peak
    };
    let peak = peak_of(&store, &["--mem", "256M"]);
    // The README states the margin: 64 MiB over --mem.
    assert!(peak < (256 + 64) << 20, "peak RSS {} MiB", peak >> 20);
    // A split ingest's task, under a quarter of that budget.
    let split = d.path().join("split.store");
    let peak = peak_of(&split, &["--shard", "0/1", "--mem", "64M"]);
    assert!(peak < (64 + 64) << 20, "peak RSS {} MiB", peak >> 20);
}

#[test]
fn corrupt_cell_is_detected() {
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("s.ply");
    let store = d.path().join("s.store");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "5000",
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    ok(&["ingest", s(&ply), "-o", s(&store), "--progress", "none"]);
    let st = Store::open(&store).unwrap();
    let p = st.cell_path(0);
    let mut bytes = std::fs::read(&p).unwrap();
    let k = bytes.len() / 2;
    bytes[k] ^= 0x55;
    std::fs::write(&p, bytes).unwrap();
    let e = st.read_cell(0).unwrap_err().to_string();
    assert!(
        e.contains(&st.manifest.cells[0].file) && e.contains("corrupt"),
        "{e}"
    );
}

#[test]
fn independent_reader_agrees() {
    // plyfile (Python) reads what synth writes; .ci/run installs it.
    if !has_plyfile() {
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("b.ply");
    ok(&[
        "synth",
        "bumpy",
        "--points",
        "12345",
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    let script = "import sys, plyfile, numpy as np\nv = plyfile.PlyData.read(sys.argv[1])['vertex']\nn = np.stack([v['nx'], v['ny'], v['nz']], 1)\nprint(len(v), ' '.join(v.data.dtype.names), float(np.abs(np.linalg.norm(n, axis=1) - 1).max()))";
    let o = std::process::Command::new("python3")
        .args(["-c", script, s(&ply)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    let f: Vec<&str> = out.split_whitespace().collect();
    assert_eq!(f[0], "12345");
    assert_eq!(&f[1..7], &["x", "y", "z", "nx", "ny", "nz"]);
    assert!(f[7].parse::<f64>().unwrap() < 1e-5);
}

#[test]
fn identical_points_stay_in_one_finest_cell() {
    // 3000 copies of one point cannot be split below the finest level: kept, with a warning.
    let d = tempfile::tempdir().unwrap();
    let xyz = d.path().join("same.xyz");
    let mut text = String::from("10 10 10\n");
    text += &"1 2 3\n".repeat(3000);
    std::fs::write(&xyz, text).unwrap();
    let store = d.path().join("same.store");
    let err = ok_log(&[
        "ingest",
        s(&xyz),
        "-o",
        s(&store),
        "--max-cell-points",
        "100",
        "--progress",
        "none",
    ]);
    assert!(err.contains("3000 points within one finest cell"), "{err}");
    let st = Store::open(&store).unwrap();
    assert_eq!(st.manifest.point_count, 3001);
    assert_eq!(st.manifest.cells.iter().map(|c| c.count).max(), Some(3000));
}

/// The library's two-step ingest: the staged store is invisible until committed, dropping it
/// leaves nothing behind, and the pipeline's ingest gives the same store as the CLI.
#[test]
fn staged_store_appears_only_on_commit() {
    use scanflow::exec::Ctx;
    use scanflow::exec::progress::{Mode, Progress};
    use scanflow::io::InputSpec;
    use scanflow::pipeline::ingest::{IngestParams, ingest};
    use scanflow::store::{StoreParams, stage};

    let d = tempfile::tempdir().unwrap();
    let ply = d.path().join("b.ply");
    ok(&["synth", "bumpy", "--points", "20000", "-o", s(&ply)]);
    let ctx = Ctx::new(2, 256 << 20, Progress::new(Mode::Quiet)).unwrap();
    let inputs = [InputSpec::plain(&ply)];
    let out = d.path().join("b.store");
    let names = || -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };

    // Estimating normals: staged without them, dropped uncommitted.
    let params = StoreParams {
        max_cell_points: 3000,
        normals: scanflow::store::NormalsMode::Estimate,
        ..Default::default()
    };
    let staged = stage(&inputs, &out, &params, &ctx).unwrap();
    assert!(staged.wants_normals() && !staged.layout().attrs.normal);
    assert!(staged.cells().len() > 3 && staged.dir().is_dir());
    assert!(!out.exists());
    drop(staged);
    assert_eq!(names(), ["b.ply", "b.truth.json"]);

    // Inputs' normals: committed as they are, identical to the CLI's store.
    let staged = stage(&inputs, &out, &StoreParams::default(), &ctx).unwrap();
    assert!(!staged.wants_normals());
    let est = scanflow::store::manifest::EstimatedNormals {
        k: 20,
        k_max: 20,
        robust: false,
        degenerate: 0,
        by_viewpoint: 0,
        by_propagation: 0,
        components: 0,
    };
    assert!(staged.commit(Some((est, 0.0))).is_err());
    assert_eq!(names(), ["b.ply", "b.truth.json"]);
    let st = ingest(&inputs, &out, &IngestParams::default(), &ctx).unwrap();
    assert_eq!(st.points, 20_000);
    assert!(st.normals.is_none());
    let cli = d.path().join("cli.store");
    ok(&["ingest", s(&ply), "-o", s(&cli), "--progress", "none"]);
    assert_eq!(tree_bytes(&out), tree_bytes(&cli));
    let err = ingest(&inputs, &out, &IngestParams::default(), &ctx).unwrap_err();
    assert!(err.to_string().contains("already exists"), "{err}");
}
