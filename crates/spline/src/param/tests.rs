use super::*;
use std::path::Path;

fn src() -> &'static Path {
    Path::new("patch.ply")
}

/// Two triangles per cell of a `w × h` vertex grid, counter-clockwise seen from +z.
fn grid_triangles(w: u32, h: u32) -> Vec<[u32; 3]> {
    let mut t = Vec::new();
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            let a = y * w + x;
            t.push([a, a + 1, a + w + 1]);
            t.push([a, a + w + 1, a + w]);
        }
    }
    t
}

/// A rigid motion of the plane z = 0 into a tilted plane far from the origin.
fn place(p: [f64; 2]) -> [f64; 3] {
    let (c, s) = (0.6f64, 0.8f64);
    [
        1000.0 + 0.28 * p[0] - 0.96 * c * p[1],
        -50.0 + 0.96 * p[0] + 0.28 * c * p[1],
        7.0 + s * p[1],
    ]
}

fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    dot(d, d).sqrt()
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Largest difference between parameter and world distances over all pairs.
fn rigid_error(pts: &[[f64; 3]], uv: &[[f64; 2]]) -> f64 {
    let mut worst: f64 = 0.0;
    for i in 0..pts.len() {
        for j in i + 1..pts.len() {
            worst = worst.max((dist3(pts[i], pts[j]) - dist2(uv[i], uv[j])).abs());
        }
    }
    worst
}

#[test]
fn planar_grid_maps_to_itself_under_chord_and_real_spring() {
    let (w, h) = (13u32, 9u32);
    let pts: Vec<[f64; 3]> = (0..w * h)
        .map(|i| place([(i % w) as f64 * 0.5, (i / w) as f64 * 0.5]))
        .collect();
    let g = Graph::from_triangles(src(), pts.len(), &grid_triangles(w, h)).unwrap();
    for m in [Method::chord(), Method::real_spring(), Method::uniform()] {
        let p = parameterise(&pts, &g, m).unwrap();
        assert!(rigid_error(&pts, &p.uv) < 1e-9, "{m:?}");
        assert!((p.size[0] - 6.0).abs() < 1e-9 && (p.size[1] - 4.0).abs() < 1e-9);
        assert_eq!((p.folds, p.unreachable), (0, 0));
        // The frame maps parameters back onto the points.
        for (q, uv) in pts.iter().zip(&p.uv) {
            let back = [0, 1, 2].map(|k| p.origin[k] + uv[0] * p.axes[0][k] + uv[1] * p.axes[1][k]);
            assert!(dist3(*q, back) < 1e-9);
        }
        let n = cross(p.axes[0], p.axes[1]);
        assert!(dist3(n, p.axes[2]) < 1e-12);
    }
}

/// A paraboloid cap z = x² + y² over a disc of radius 1: the grid points inside it,
/// triangles with all corners inside.
fn paraboloid(n: i32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut id = std::collections::BTreeMap::new();
    let mut pts = Vec::new();
    for y in -n..=n {
        for x in -n..=n {
            let (u, v) = (x as f64 / n as f64, y as f64 / n as f64);
            if u * u + v * v <= 1.0 {
                id.insert((x, y), pts.len() as u32);
                pts.push([u, v, u * u + v * v]);
            }
        }
    }
    let mut tris = Vec::new();
    for y in -n..n {
        for x in -n..n {
            let c = [(x, y), (x + 1, y), (x + 1, y + 1), (x, y + 1)].map(|k| id.get(&k).copied());
            if let [Some(a), Some(b), Some(c), Some(d)] = c {
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
    }
    (pts, tris)
}

#[test]
fn paraboloid_cap_has_no_fold_overs() {
    let (pts, tris) = paraboloid(15);
    let g = Graph::from_triangles(src(), pts.len(), &tris).unwrap();
    for m in [
        Method::uniform(),
        Method::chord(),
        Method::real_spring(),
        Method::Project,
    ] {
        let p = parameterise(&pts, &g, m).unwrap();
        assert_eq!(p.folds, 0, "{m:?}");
        assert!(
            p.uv.iter()
                .all(|q| (0.0..=p.size[0]).contains(&q[0]) && (0.0..=p.size[1]).contains(&q[1]))
        );
        // The normal is the paraboloid's axis (sign rule: positive largest component).
        assert!(dist3(p.axes[2], [0.0, 0.0, 1.0]) < 1e-9, "{:?}", p.axes[2]);
    }
    let p = parameterise(&pts, &g, Method::real_spring()).unwrap();
    assert!(
        p.iterations > 1 && p.iterations <= MAX_ITERATIONS,
        "{}",
        p.iterations
    );
}

#[test]
fn fold_over_is_counted() {
    // A fan around vertex 4 whose interior vertex is pushed outside by Project.
    let pts = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.5, 0.5, 0.0],
    ];
    let tris = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
    let g = Graph::from_triangles(src(), 5, &tris).unwrap();
    assert_eq!(g.boundary, [true, true, true, true, false]);
    let p = parameterise(&pts, &g, Method::Project).unwrap();
    assert_eq!(p.folds, 1);
    assert_eq!(
        count_folds(
            &tris,
            &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]]
        ),
        0
    );
}

/// Spread of `log(parameter length / world length)` over the edges: 0 for an isometry.
fn distortion(pts: &[[f64; 3]], g: &Graph, uv: &[[f64; 2]]) -> f64 {
    let logs: Vec<f64> = g
        .edges
        .iter()
        .map(|e| {
            let (i, j) = (e[0] as usize, e[1] as usize);
            (dist2(uv[i], uv[j]) / dist3(pts[i], pts[j])).ln()
        })
        .collect();
    let mean = logs.iter().sum::<f64>() / logs.len() as f64;
    (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / logs.len() as f64).sqrt()
}

#[test]
fn chord_and_real_spring_keep_distance_ratios_better_than_uniform() {
    // A gently curved sheet sampled densely on one side (x = t³ grading).
    let (w, h) = (25u32, 12u32);
    let pts: Vec<[f64; 3]> = (0..w * h)
        .map(|i| {
            let t = (i % w) as f64 / (w - 1) as f64;
            let x = 4.0 * t * t * t + 0.2 * t;
            let y = (i / w) as f64 * 0.3;
            [x, y, 0.1 * (x * 0.5).sin()]
        })
        .collect();
    let g = Graph::from_triangles(src(), pts.len(), &grid_triangles(w, h)).unwrap();
    let d = |m| distortion(&pts, &g, &parameterise(&pts, &g, m).unwrap().uv);
    let (uni, chord, real) = (
        d(Method::uniform()),
        d(Method::chord()),
        d(Method::real_spring()),
    );
    eprintln!("edge length distortion: uniform {uni:.4}, chord {chord:.4}, real spring {real:.4}");
    assert!(chord < 0.5 * uni, "{chord} {uni}");
    assert!(real < 0.5 * uni, "{real} {uni}");
}

#[test]
fn closed_component_is_fixed_by_projection() {
    let (w, h) = (6u32, 5u32);
    let mut pts: Vec<[f64; 3]> = (0..w * h)
        .map(|i| [(i % w) as f64, (i / w) as f64, 0.0])
        .collect();
    let mut tris = grid_triangles(w, h);
    // A tetrahedron (closed) beside the grid, and an isolated point.
    let base = pts.len() as u32;
    pts.extend([
        [8.0, 1.0, 0.1],
        [9.0, 1.0, 0.1],
        [8.5, 2.0, 0.1],
        [8.5, 1.5, 0.6],
        [7.0, 3.0, 0.0],
    ]);
    let b = base;
    tris.extend([
        [b, b + 1, b + 2],
        [b, b + 3, b + 1],
        [b + 1, b + 3, b + 2],
        [b + 2, b + 3, b],
    ]);
    let mut g = Graph::from_triangles(src(), pts.len(), &tris).unwrap();
    let p = parameterise(&pts, &g, Method::chord()).unwrap();
    assert_eq!(p.unreachable, 5);
    let proj = parameterise(&pts, &g, Method::Project).unwrap();
    for i in base as usize..pts.len() {
        assert!(dist2(p.uv[i], proj.uv[i]) < 1e-9);
    }
    g.boundary.fill(false);
    let e = parameterise(&pts, &g, Method::chord())
        .unwrap_err()
        .to_string();
    assert!(e.contains("no boundary") && e.contains("`patches`"), "{e}");
}

#[test]
fn degenerate_input_is_an_error() {
    let line: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 2.0 * i as f64, 0.0]).collect();
    let g = Graph::from_triangles(src(), 10, &[[0, 1, 2]]).unwrap();
    let e = parameterise(&line, &g, Method::Project)
        .unwrap_err()
        .to_string();
    assert!(e.contains("one line"), "{e}");
    assert!(parameterise(&line[..9], &g, Method::Project).is_err());
    let mut bad = line.clone();
    bad[4][2] = f64::INFINITY;
    assert!(parameterise(&bad, &g, Method::Project).is_err());
    let m = Method::Spring { alpha: 1.0, r: 1.0 };
    let mut ok = line.clone();
    ok[5][2] = 1.0;
    assert!(parameterise(&ok, &g, m).is_err());
}

#[test]
fn knn_chord_is_deterministic_and_fold_free_on_a_height_field() {
    let pts: Vec<[f64; 3]> = (0..2000u64)
        .map(|i| {
            let h = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let x = (h >> 11) as f64 / (1u64 << 53) as f64;
            let y = ((h.wrapping_mul(0xBF58_476D_1CE4_E5B9)) >> 11) as f64 / (1u64 << 53) as f64;
            [x * 2.0, y, 0.2 * (3.0 * x).sin() * y]
        })
        .collect();
    let g = Graph::from_knn(src(), &pts, super::super::graph::DEFAULT_K).unwrap();
    let a = parameterise(&pts, &g, Method::chord()).unwrap();
    let b = parameterise(&pts, &g, Method::chord()).unwrap();
    assert_eq!(a, b);
    assert!(
        (a.size[0] - 2.0).abs() < 0.1 && (a.size[1] - 1.0).abs() < 0.1,
        "{:?}",
        a.size
    );
}

/// The bunny's front scan, triangulated from its range grid: a disc with holes and loose
/// pixels, boundary not convex, so fold-overs are possible but must stay rare.
#[test]
fn bunny_range_scan_parameterises() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bunny/bun000.ply");
    if !p.is_file() {
        eprintln!("skipped: {} not found", p.display());
        return;
    }
    let m = scanflow_formats::mesh_read::read_scan_mesh(&p).unwrap();
    let g = Graph::from_triangles(&p, m.vertices.len(), &m.triangles).unwrap();
    // Measured: uniform 49 folds, chord 30, real spring 275 (not converged after 100
    // steps, 12 s in the test profile, so left out here); 11 loose pixels unreachable.
    let method = Method::chord();
    let q = parameterise(&m.vertices, &g, method).unwrap();
    eprintln!(
        "bun000 {method:?}: {} folds of {} triangles, {} unreachable, {} iterations, size {:?}, {} non-manifold edges",
        q.folds,
        m.triangles.len(),
        q.unreachable,
        q.iterations,
        q.size,
        g.non_manifold_edges
    );
    assert!(
        q.folds <= 30 && q.unreachable == 11,
        "{} {}",
        q.folds,
        q.unreachable
    );
}

/// 100K scattered points: kNN graph and chord parameterisation, timed.
/// `cargo test --release --lib spline::param -- --ignored --nocapture`
#[test]
#[ignore]
fn speed_100k_knn_chord() {
    let n = 100_000u64;
    let pts: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let h = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let x = (h >> 11) as f64 / (1u64 << 53) as f64;
            let y = ((h.wrapping_mul(0xBF58_476D_1CE4_E5B9)) >> 11) as f64 / (1u64 << 53) as f64;
            [x * 100.0, y * 100.0, 5.0 * (0.1 * x * 100.0).sin() * y]
        })
        .collect();
    let t = std::time::Instant::now();
    let g = Graph::from_knn(src(), &pts, super::super::graph::DEFAULT_K).unwrap();
    let tg = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let p = parameterise(&pts, &g, Method::chord()).unwrap();
    let tp = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let r = parameterise(&pts, &g, Method::real_spring()).unwrap();
    let tr = t.elapsed().as_secs_f64();
    eprintln!(
        "100K points: kNN graph {tg:.3} s ({} edges, {} boundary), chord {tp:.3} s, real spring {tr:.3} s ({} iterations), size {:?}",
        g.edges.len(),
        g.boundary.iter().filter(|&&b| b).count(),
        r.iterations,
        p.size
    );
}
