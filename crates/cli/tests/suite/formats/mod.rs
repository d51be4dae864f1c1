//! Mesh outputs by extension (binary and ASCII PLY, OBJ, STL), vertex normals and sampling
//! densities, trimming by density, and OBJ/STL meshes as `check` inputs: read back by
//! independent readers (plyfile, trimesh, meshio), the same for any tile size, thread count
//! and shard count, and bad combinations refused before any work.

use std::path::Path;
use std::process::Command;

use super::common::{ok, s, usage};

mod inputs;
mod preview;

/// Whether python3 can import every module of `modules`; prints why the caller skips when not.
fn python_has(modules: &str, test: &str) -> bool {
    let found = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        eprintln!("skipped ({test}): python3 cannot import {modules}");
    }
    found
}

/// A 30k-point torus (major radius 1, minor 0.35) in `dir`.
fn torus(dir: &Path) -> std::path::PathBuf {
    let pts = dir.join("torus.ply");
    ok(&["synth", "torus", "--points", "30000", "-o", s(&pts)]);
    pts
}

/// Reconstruct `pts` at depth 6 into `out` with `extra` options.
fn recon(pts: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "reconstruct",
        s(pts),
        "-o",
        s(out),
        "--depth",
        "6",
        "--progress",
        "none",
    ];
    args.extend_from_slice(extra);
    ok(&args);
}

/// Reconstruct `pts` at depth 8 into `out` with `extra` options.
fn at_depth_8(pts: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec!["reconstruct", s(pts), "-o", s(out), "--depth", "8"];
    args.extend_from_slice(&["--progress", "none"]);
    args.extend_from_slice(extra);
    ok(&args);
}

/// Write `rows` (`n` lines `x y z nx ny nz`, then what `extra` declares) as an ASCII PLY of
/// oriented points, `extra` holding the header's further property lines.
fn oriented_ply(path: &Path, n: usize, extra: &str, rows: &str) {
    let head = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\n{extra}end_header\n"
    );
    std::fs::write(path, head + rows).unwrap();
}

/// Independent readers: every format holds the binary PLY's vertices and triangles; the
/// normals are unit and face out of the torus; the densities match the sampling (30k points
/// over the torus's area 4π²Rr).
#[test]
fn every_output_format_reads_back_in_independent_readers() {
    if !python_has("numpy, plyfile, trimesh, meshio", "formats") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pts = torus(dir.path());
    let d = dir.path();
    recon(&pts, &d.join("a.ply"), &[]);
    recon(
        &pts,
        &d.join("b.ply"),
        &["--ascii", "--out-normals", "--density"],
    );
    recon(&pts, &d.join("c.obj"), &["--out-normals"]);
    recon(&pts, &d.join("d.stl"), &[]);
    recon(&pts, &d.join("e.ply"), &["--out-normals", "--density"]);
    let script = r#"
import sys, numpy as np, plyfile, trimesh, meshio
d = sys.argv[1]
ref = plyfile.PlyData.read(d + '/a.ply')
rv = np.stack([ref['vertex'][k] for k in 'xyz'], 1).astype(np.float64)
rf = np.stack(ref['face']['vertex_indices']).astype(np.int64)
def torus_normals(p):
    rho = np.hypot(p[:, 0], p[:, 1])
    g = np.stack([p[:, 0] - p[:, 0] / rho, p[:, 1] - p[:, 1] / rho, p[:, 2]], 1)
    return g / np.linalg.norm(g, axis=1)[:, None]
def check_normals(name, p, n):
    assert np.abs(np.linalg.norm(n, axis=1) - 1).max() < 1e-5, name
    ang = np.degrees(np.arccos(np.clip((n * torus_normals(p)).sum(1), -1, 1)))
    assert ang.mean() < 5 and np.percentile(ang, 99) < 20, (name, ang.mean())
for name in ['b.ply', 'e.ply']:
    ply = plyfile.PlyData.read(d + '/' + name)
    v = ply['vertex']
    p = np.stack([v[k] for k in 'xyz'], 1).astype(np.float64)
    assert len(p) == len(rv) and np.abs(p - rv).max() < 1e-6, name
    f = np.stack(ply['face']['vertex_indices'])
    assert (f == rf).all(), name
    check_normals(name, p, np.stack([v[k] for k in ('nx', 'ny', 'nz')], 1))
    q = v['quality']
    expect = 30000 / (4 * np.pi ** 2 * 0.35)
    assert q.min() > 0 and abs(np.median(q) / expect - 1) < 0.3, (name, np.median(q), expect)
    print(name, 'ok', len(p), np.median(q) / expect)
m = trimesh.load(d + '/c.obj', process=False)
assert len(m.vertices) == len(rv) and np.abs(m.vertices - rv).max() < 1e-6
assert (m.faces == rf).all() and m.is_watertight
check_normals('c.obj', rv, np.asarray(m.vertex_normals))
mo = meshio.read(d + '/c.obj')
assert mo.points.shape == rv.shape and mo.cells[0].data.shape == rf.shape
print('c.obj ok')
ms = meshio.read(d + '/d.stl')
assert len(ms.cells[0].data) == len(rf)
corners = np.sort(ms.points[ms.cells[0].data].reshape(-1, 3), axis=0)
assert np.abs(corners - np.sort(rv[rf].reshape(-1, 3), axis=0)).max() < 1e-6
t = trimesh.load(d + '/d.stl')
assert len(t.faces) == len(rf) and t.is_watertight and t.volume > 0
fn = np.cross(rv[rf[:, 1]] - rv[rf[:, 0]], rv[rf[:, 2]] - rv[rf[:, 0]])
fn /= np.linalg.norm(fn, axis=1)[:, None]
assert np.abs(np.asarray(t.face_normals) - fn).max() < 1e-3
print('d.stl ok', t.volume, 2 * np.pi ** 2 * 0.35 ** 2)
"#;
    let o = Command::new("python3")
        .args(["-c", script])
        .arg(d)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    // Our own `check` reads OBJ and STL: the same counts and topology as the PLY.
    let counts = |p: &Path| {
        let out = ok(&["check", s(p)]);
        out.lines().nth(1).unwrap().to_string()
    };
    let want = counts(&d.join("a.ply"));
    assert!(want.contains("1 component"), "{want}");
    for f in ["b.ply", "c.obj", "d.stl"] {
        assert_eq!(counts(&d.join(f)), want, "{f}");
    }
    let stl = ok(&["check", s(&d.join("d.stl"))]);
    assert!(stl.contains("watertight: yes"), "{stl}");
}

/// The ASCII PLY's vertex lines (position, normal, density), sorted: the same set whatever
/// order the vertices come in.
fn vertex_lines(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let n: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    let body = text.split_once("end_header\n").unwrap().1;
    let mut v: Vec<String> = body.lines().take(n).map(str::to_string).collect();
    v.sort();
    v
}

/// Normals are summed from each triangle's own corner in sorted order, densities come from
/// exact neighbour searches: the same numbers for any tile size and thread count; and the
/// same bytes from two shards and `merge` as from one process.
#[test]
fn normals_and_densities_do_not_depend_on_tiles_threads_or_shards() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = torus(d);
    let opts = ["--ascii", "--out-normals", "--density"];
    let one = d.join("one.ply");
    recon(&pts, &one, &[&opts[..], &["--threads", "1"]].concat());
    let two = d.join("two.ply");
    recon(&pts, &two, &[&opts[..], &["--threads", "2"]].concat());
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap());
    let small = d.join("small.ply");
    recon(&pts, &small, &[&opts[..], &["--tile", "16"]].concat());
    let (a, b) = (vertex_lines(&one), vertex_lines(&small));
    assert_eq!(a.len(), b.len());
    assert!(a == b, "vertex lines differ with --tile 16");
    assert!(a[0].split(' ').count() == 7, "{}", a[0]);

    // Two shards and merge, into OBJ with normals: the single process's bytes.
    let store = d.join("store");
    ok(&["ingest", s(&pts), "-o", s(&store), "--progress", "none"]);
    let single = d.join("single.obj");
    let work = d.join("w");
    ok(&[
        "reconstruct",
        s(&store),
        "-o",
        s(&single),
        "--depth",
        "6",
        "--progress",
        "none",
        "--out-normals",
    ]);
    for i in ["0/2", "1/2"] {
        ok(&[
            "reconstruct",
            s(&store),
            "-o",
            s(&d.join("unused.obj")),
            "--depth",
            "6",
            "--progress",
            "none",
            "--shard",
            i,
            "--work-dir",
            s(&work),
        ]);
    }
    let merged = d.join("merged.obj");
    ok(&[
        "merge",
        s(&work),
        "-o",
        s(&merged),
        "--out-normals",
        "--progress",
        "none",
    ]);
    assert_eq!(
        std::fs::read(&single).unwrap(),
        std::fs::read(&merged).unwrap()
    );
    assert!(!d.join("unused.obj").exists());
}

/// A sphere sampled ten times more sparsely above z = 0.3 (ASCII PLY with normals): the
/// densities written follow the sampling, and `--trim-density` between the two densities
/// keeps the dense part and opens the surface where it was sparse.
#[test]
fn densities_follow_the_sampling_and_trim_by_a_threshold() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let full = d.join("sphere.ply");
    ok(&["synth", "sphere", "--points", "60000", "-o", s(&full)]);
    let b = super::common::load(&full);
    let mut text = String::new();
    let mut kept = 0usize;
    for (i, (p, n)) in b.pos.iter().zip(&b.normal).enumerate() {
        if p[2] > 0.3 && i % 10 != 0 {
            continue;
        }
        kept += 1;
        text.push_str(&format!(
            "{} {} {} {} {} {}\n",
            p[0], p[1], p[2], n[0], n[1], n[2]
        ));
    }
    let pts = d.join("uneven.ply");
    oriented_ply(&pts, kept, "", &text);
    let dens = d.join("dens.ply");
    recon(&pts, &dens, &["--ascii", "--density"]);
    let lines = vertex_lines(&dens);
    let (mut low, mut high) = (Vec::new(), Vec::new());
    for l in &lines {
        let v: Vec<f64> = l.split(' ').map(|x| x.parse().unwrap()).collect();
        if v[2] > 0.6 {
            low.push(v[3]);
        } else if v[2] < -0.3 {
            high.push(v[3]);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (lo, hi) = (median(&mut low), median(&mut high));
    // The unit sphere's 60k points: 60000 / 4π ≈ 4775 per square unit where dense.
    assert!((hi / 4775.0 - 1.0).abs() < 0.3, "dense part: {hi}");
    assert!((hi / lo - 10.0).abs() < 3.0, "dense {hi}, sparse {lo}");
    let trimmed = d.join("trimmed.ply");
    let threshold = (lo * hi).sqrt().to_string();
    recon(&pts, &trimmed, &["--trim-density", &threshold]);
    let rep = ok(&["check", s(&trimmed), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&rep).unwrap();
    let boundary = v["check"]["boundary_edges"].as_u64().unwrap();
    assert!(boundary > 0, "{rep}");
    let hi_z = v["check"]["bounds"]["max"][2].as_f64().unwrap();
    assert!(hi_z < 0.6, "kept a sparse part up to z = {hi_z}");
    let lo_z = v["check"]["bounds"]["min"][2].as_f64().unwrap();
    assert!(lo_z < -0.95, "lost the dense part: down to {lo_z}");
    // Without --density the trimmed mesh carries no density.
    let t = std::fs::read(&trimmed).unwrap();
    let head = String::from_utf8_lossy(&t[..600]);
    assert!(!head.contains("quality"), "{head}");
}

/// `--trim-islands` (PoissonRecon's `--aRatio`): a sphere beside a pebble a tenth its size,
/// sampled as densely, reconstructs as two pieces (the pebble 1.1% of the area); with pieces
/// under 2% of the area dropped, as the sphere
/// alone, in `reconstruct` and in `merge` of a sharded run, which write the same bytes.
/// trimesh (an independent reader) counts the pieces.
#[test]
fn small_islands_are_dropped_as_the_mesh_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sphere = d.join("sphere.ply");
    ok(&["synth", "sphere", "--points", "20000", "-o", s(&sphere)]);
    let b = super::common::load(&sphere);
    let mut text = String::new();
    for (p, n) in b.pos.iter().zip(&b.normal) {
        text.push_str(&format!(
            "{} {} {} {} {} {}\n",
            p[0], p[1], p[2], n[0], n[1], n[2]
        ));
    }
    // The pebble: radius 0.1 at (2.2, 0, 0), every 100th sample of the sphere shrunk there.
    for (p, n) in b.pos.iter().zip(&b.normal).step_by(100) {
        let q = [2.2 + 0.1 * p[0], 0.1 * p[1], 0.1 * p[2]];
        text.push_str(&format!(
            "{} {} {} {} {} {}\n",
            q[0], q[1], q[2], n[0], n[1], n[2]
        ));
    }
    let n = b.pos.len() + b.pos.len().div_ceil(100);
    let pts = d.join("pebble.ply");
    oriented_ply(&pts, n, "", &text);
    let pieces = |mesh: &Path| {
        let rep = ok(&["check", s(mesh), "--json"]);
        let v: serde_json::Value = serde_json::from_str(&rep).unwrap();
        (
            v["check"]["components"].as_u64().unwrap(),
            v["check"]["bounds"]["max"][0].as_f64().unwrap(),
        )
    };
    let (both, alone) = (d.join("both.ply"), d.join("alone.ply"));
    at_depth_8(&pts, &both, &[]);
    at_depth_8(&pts, &alone, &["--trim-islands", "0.02"]);
    let (k, right) = pieces(&both);
    assert!(k == 2 && right > 2.25, "{k} pieces up to x = {right}");
    let (k, right) = pieces(&alone);
    assert!(k == 1 && right < 1.01, "{k} pieces up to x = {right}");
    // From a store: one process, and two shards and a merge (given PoissonRecon's name for
    // the option), write the same bytes.
    let store = d.join("store");
    ok(&["ingest", s(&pts), "-o", s(&store), "--progress", "none"]);
    let (single, merged, work) = (d.join("single.ply"), d.join("merged.ply"), d.join("work"));
    let from_store = |out: &Path, extra: &[&str]| {
        let mut args = vec!["reconstruct", s(&store), "-o", s(out), "--depth", "8"];
        args.extend_from_slice(&["--progress", "none"]);
        args.extend_from_slice(extra);
        ok(&args);
    };
    from_store(&single, &["--trim-islands", "0.02"]);
    for shard in ["0/2", "1/2"] {
        from_store(&merged, &["--work-dir", s(&work), "--shard", shard]);
    }
    ok(&[
        "merge",
        s(&work),
        "-o",
        s(&merged),
        "--aRatio",
        "0.02",
        "--progress",
        "none",
    ]);
    assert_eq!(pieces(&single).0, 1);
    assert_eq!(
        std::fs::read(&merged).unwrap(),
        std::fs::read(&single).unwrap()
    );
    if python_has("trimesh", "trim-islands") {
        let o = Command::new("python3")
            .args([
                "-c",
                "import sys, trimesh\nfor f in sys.argv[1:]: print(len(trimesh.load(f, process=False).split(only_watertight=False)))",
                s(&both),
                s(&alone),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(String::from_utf8_lossy(&o.stdout), "2\n1\n");
    }
    for bad in ["1", "-0.1", "nan"] {
        let e = usage(&[
            "reconstruct",
            s(&pts),
            "-o",
            s(&d.join("x.ply")),
            "--trim-islands",
            bad,
        ]);
        assert!(e.contains("--trim-islands"), "{e}");
    }
}

/// Combinations no format can hold, and bad thresholds: usage errors naming the file or the
/// option, before any work.
#[test]
fn what_a_format_cannot_hold_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = d.join("missing-points.ply");
    let out = |n: &str| d.join(n);
    let e = usage(&["reconstruct", s(&pts), "-o", s(&out("m.off"))]);
    assert!(e.contains("m.off") && e.contains("*.stl"), "{e}");
    let e = usage(&["reconstruct", s(&pts), "-o", s(&out("m.obj")), "--ascii"]);
    assert!(e.contains("--ascii"), "{e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&out("m.stl")),
        "--out-normals",
    ]);
    assert!(e.contains("m.stl") && e.contains("--out-normals"), "{e}");
    let e = usage(&["reconstruct", s(&pts), "-o", s(&out("m.obj")), "--density"]);
    assert!(e.contains("--density") && e.contains("*.ply"), "{e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&out("m.ply")),
        "--trim-density",
        "-3",
    ]);
    assert!(e.contains("--trim-density -3"), "{e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&out("m.stl")),
        "--hex",
        s(&out("h.vtk")),
    ]);
    assert!(e.contains("--hex"), "{e}");
    let e = usage(&["merge", s(d), "-o", s(&out("m.stl")), "--out-normals"]);
    assert!(e.contains("--out-normals"), "{e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&out("m.ply")),
        "--preview",
        s(&out("p.jpg")),
    ]);
    assert!(e.contains("--preview") && e.contains("p.jpg"), "{e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&out("m.ply")),
        "--report",
        s(&out("r.txt")),
    ]);
    assert!(e.contains("--report") && e.contains("*.html"), "{e}");
    let e = usage(&[
        "reconstruct",
        s(&pts),
        "-o",
        s(&out("m.ply")),
        "--preview",
        s(&out("p.png")),
        "--shard",
        "0/2",
    ]);
    assert!(e.contains("--preview") && e.contains("merge"), "{e}");
    // Nothing was written.
    let left: Vec<_> = std::fs::read_dir(d).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}
