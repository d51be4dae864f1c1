//! IGES output read back by independent readers (issue 15): OpenCascade reads the entity-128
//! surfaces scanflow writes with the same knots and poles (units not scaled), projects points
//! at known distances onto them and finds those distances, and gmsh loads the file without a
//! warning. Runs `scripts/iges_check.py`; skips when python3 cannot import OCP, gmsh or numpy.

use std::path::Path;
use std::process::Command;

use scanflow::spline::iges::{IgesMeta, IgesUnit, write_iges};
use scanflow::types::TensorSurface;

/// Whether python3 can import the checker's modules; prints why the caller skips otherwise.
pub(super) fn has_checker(test: &str) -> bool {
    let found = Command::new("python3")
        .args(["-c", "import OCP, gmsh, numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        eprintln!("skipped ({test}): python3 cannot import OCP, gmsh and numpy");
    }
    found
}

/// `scripts/iges_check.py IGES POINTS --json`, parsed.
pub(super) fn check(iges: &Path, points: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/iges_check.py");
    let o = Command::new("python3")
        .arg(script)
        .args([iges, points])
        .arg("--json")
        .output()
        .expect("python3 runs");
    assert!(
        o.status.success(),
        "iges_check.py failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("iges_check.py prints one JSON object")
}

/// The cubic B-spline coefficients of `t` and `t²` on clamped `knots` (blossoms: the mean of
/// the `p` knots after `i`, and the mean of their pairwise products).
fn linear_and_square(knots: &[f64], i: usize) -> (f64, f64) {
    let t = &knots[i + 1..i + 4];
    let lin = t.iter().sum::<f64>() / 3.0;
    let sq = (t[0] * t[1] + t[0] * t[2] + t[1] * t[2]) / 3.0;
    (lin, sq)
}

/// `z = x² + y²` over `[-1, 1]²` shifted by `(dx, 0, 0)`: bicubic, interior knots (uneven
/// along u), exactly `S(u, v) = (u + dx, v, u² + v²)`.
fn paraboloid(dx: f64) -> TensorSurface {
    let ku = vec![-1.0, -1.0, -1.0, -1.0, -0.6, -0.1, 0.5, 1.0, 1.0, 1.0, 1.0];
    let kv = vec![-1.0, -1.0, -1.0, -1.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    let count = [ku.len() - 4, kv.len() - 4];
    let mut ctrl = Vec::new();
    for j in 0..count[1] {
        let (y, y2) = linear_and_square(&kv, j);
        for i in 0..count[0] {
            let (x, x2) = linear_and_square(&ku, i);
            ctrl.push([x + dx, y, x2 + y2]);
        }
    }
    TensorSurface {
        degree: [3, 3],
        knots: [ku, kv],
        count,
        ctrl,
    }
}

/// `z = x y` as one bicubic Bézier patch over `[0, 2] × [0, 1]` shifted by `(0, dy, 0)`:
/// `S(u, v) = (2u, v + dy, 2uv)`.
fn saddle(dy: f64) -> TensorSurface {
    let mut ctrl = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            let (x, y) = (2.0 * i as f64 / 3.0, j as f64 / 3.0);
            ctrl.push([x, y + dy, x * y]);
        }
    }
    let bezier = vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    TensorSurface {
        degree: [3, 3],
        knots: [bezier.clone(), bezier],
        count: [4, 4],
        ctrl,
    }
}

/// Points at signed distances along the unit normal from surface points `(x, y, z(x, y))`,
/// `grad` the gradient of `z`; every distance below the surfaces' smallest radius of
/// curvature (0.5), so the foot of each offset point is the surface point it left.
fn offset(p: [f64; 3], grad: [f64; 2], d: f64) -> [f64; 3] {
    let n = [-grad[0], -grad[1], 1.0];
    let len = (n[0] * n[0] + n[1] * n[1] + 1.0).sqrt();
    [0, 1, 2].map(|k| p[k] + d * n[k] / len)
}

#[test]
fn opencascade_and_gmsh_read_back_what_scanflow_writes() {
    if !has_checker("iges") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (iges, pts) = (dir.path().join("two.igs"), dir.path().join("points.xyz"));
    let surfaces = [paraboloid(0.0), saddle(10.0)];
    let meta = IgesMeta::new("two.igs", 1_795_346_032);
    let stats = write_iges(&iges, &surfaces, &meta).unwrap();
    assert_eq!((stats.surfaces, stats.control_points), (2, 7 * 5 + 16));

    // Interior parameters (the foot of an offset must not fall beyond an edge), and the
    // distances cycled through them, so the expected max and RMS are known exactly.
    let dists = [0.0, 0.01, -0.02, 0.03, -0.04];
    let (mut text, mut expect) = (String::new(), Vec::new());
    let mut k = 0;
    for a in 1..20 {
        for b in 1..20 {
            let (s, t) = (a as f64 / 20.0, b as f64 / 20.0);
            let (x, y) = (2.0 * s - 1.0, 2.0 * t - 1.0);
            let on = paraboloid(0.0).eval(x, y);
            assert!(
                (on[2] - (x * x + y * y)).abs() < 1e-14,
                "eval against closed form"
            );
            let p1 = offset(on, [2.0 * x, 2.0 * y], dists[k % 5]);
            let on = saddle(10.0).eval(s, t);
            assert!(
                (on[2] - 2.0 * s * t).abs() < 1e-14,
                "eval against closed form"
            );
            let p2 = offset(on, [t, 2.0 * s], dists[(k + 2) % 5]);
            for p in [p1, p2] {
                text.push_str(&format!("{:?} {:?} {:?}\n", p[0], p[1], p[2]));
            }
            expect.extend([dists[k % 5], dists[(k + 2) % 5]]);
            k += 1;
        }
    }
    std::fs::write(&pts, text).unwrap();
    let r = check(&iges, &pts);

    let n = expect.len() as f64;
    let rms = (expect.iter().map(|d| d * d).sum::<f64>() / n).sqrt();
    let mean = expect.iter().map(|d| d.abs()).sum::<f64>() / n;
    assert_eq!(r["surfaces"], 2, "{r}");
    assert_eq!(r["points"].as_u64(), Some(expect.len() as u64));
    assert_eq!(r["no_projection"], 0, "{r}");
    assert_eq!(r["boundary_nearest"], 0, "{r}");
    let got = |k: &str| r[k].as_f64().unwrap();
    assert!((got("max") - 0.04).abs() < 1e-9, "max {}", got("max"));
    assert!(
        (got("rms") - rms).abs() < 1e-9,
        "rms {} vs {rms}",
        got("rms")
    );
    assert!(
        (got("mean") - mean).abs() < 1e-9,
        "mean {} vs {mean}",
        got("mean")
    );

    // OpenCascade's surfaces: our degrees, knots and poles (nothing scaled), to the last
    // bit but one: OpenCascade's own decimal parser rounds some numbers 1 ulp off.
    let occ = r["occ_bspline"].as_array().unwrap();
    let same = |a: &serde_json::Value, b: f64| {
        let a = a.as_f64().unwrap();
        (a - b).abs() <= 2.0 * f64::EPSILON * b.abs()
    };
    for (o, s) in occ.iter().zip(&surfaces) {
        assert_eq!(o["degree"], serde_json::json!(s.degree));
        assert_eq!(o["weights_one"], true);
        for d in 0..2 {
            assert_eq!(o["knots"][d].as_array().unwrap().len(), s.knots[d].len());
            for (a, &b) in o["knots"][d].as_array().unwrap().iter().zip(&s.knots[d]) {
                assert!(same(a, b), "knot {a} vs {b}");
            }
        }
        for j in 0..s.count[1] {
            for i in 0..s.count[0] {
                let (pole, c) = (&o["poles"][i][j], s.ctrl[i + s.count[0] * j]);
                assert!(
                    (0..3).all(|k| same(&pole[k], c[k])),
                    "({i}, {j}): {pole} vs {c:?}"
                );
            }
        }
    }

    // gmsh: loads cleanly, two surfaces, their corners where ours are.
    let g = &r["gmsh"];
    assert_eq!(g["ok"], true, "{g}");
    assert_eq!(g["warnings"], serde_json::json!([]), "{g}");
    assert_eq!(g["entities"], 2, "{g}");
    let mut want: Vec<[f64; 3]> = Vec::new();
    for s in &surfaces {
        let [[u0, u1], [v0, v1]] = s.domain();
        want.extend([(u0, v0), (u1, v0), (u0, v1), (u1, v1)].map(|(u, v)| s.eval(u, v)));
    }
    let corners: Vec<[f64; 3]> = g["corners"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|c| c.as_array().unwrap().clone())
        .map(|p| [0, 1, 2].map(|k| p[k].as_f64().unwrap()))
        .collect();
    for w in &want {
        let near = corners
            .iter()
            .any(|c| (0..3).all(|k| (c[k] - w[k]).abs() < 1e-9));
        assert!(near, "corner {w:?} not among gmsh's {corners:?}");
    }
}

#[test]
fn unit_flag_decides_opencascade_scaling_and_millimetres_scale_nothing() {
    if !has_checker("iges units") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pts = dir.path().join("one.xyz");
    // Beyond the edge u = 1, the curve (2, 10 + v, 2v): nearest at v = 0.5, 0.5 away.
    std::fs::write(&pts, "2.5 10.5 1.0\n").unwrap();
    let s = saddle(10.0);
    let corner = s.ctrl[15][0];
    for (unit, scale) in [
        (IgesUnit::Millimetre, 1.0),
        (IgesUnit::Inch, 25.4),
        (IgesUnit::Metre, 1000.0),
    ] {
        let iges = dir.path().join(format!("{unit:?}.igs"));
        let mut meta = IgesMeta::new(s_name(&iges), 0);
        meta.unit = unit;
        write_iges(&iges, std::slice::from_ref(&s), &meta).unwrap();
        let r = check(&iges, &pts);
        if unit == IgesUnit::Millimetre {
            // The point beyond the edge is caught by the clamped Newton search or the boundary
            // sample; the tree projection alone reports a farther local minimum.
            let caught =
                r["boundary_nearest"].as_u64().unwrap() + r["local_nearer"].as_u64().unwrap();
            assert!(caught >= 1, "{r}");
            let max = r["max"].as_f64().unwrap();
            assert!((max - 0.5).abs() < 1e-6, "beyond the edge: {max}");
        }
        let got = r["occ_bspline"][0]["poles"][3][3][0].as_f64().unwrap();
        assert!(
            (got - corner * scale).abs() < 1e-9 * scale,
            "{unit:?}: pole x {got}, expected {corner} x {scale}"
        );
    }
}

/// The file name of `p`.
fn s_name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}
