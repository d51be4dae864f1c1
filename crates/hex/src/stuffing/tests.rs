use super::cut_points::root;
use super::*;
use crate::mesh::{NO_TET, tet_neighbours};
use std::collections::HashMap;

fn sphere(r: f64) -> impl Fn([f64; 3]) -> f64 + Sync {
    move |p: [f64; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - r
}

/// Checks every invariant of a stuffed mesh; returns the boundary vertices.
fn check_mesh(m: &TetMesh, rep: &StuffingReport) -> Vec<u32> {
    assert_eq!(rep.tets, m.tets.len());
    assert_eq!(rep.vertices, m.verts.len());
    // Positive volumes.
    for t in 0..m.tets.len() {
        assert!(m.volume(t) > 0.0, "tet {t} volume {}", m.volume(t));
    }
    // Every vertex referenced, no repeated vertex within a tet.
    let mut used = vec![false; m.verts.len()];
    for t in &m.tets {
        for i in 0..4 {
            used[t[i] as usize] = true;
            for j in i + 1..4 {
                assert_ne!(t[i], t[j]);
            }
        }
    }
    assert!(used.iter().all(|&u| u), "unreferenced vertex");
    // No two vertices at the same place (merged by key).
    let mut pts: Vec<[u64; 3]> = m.verts.iter().map(|p| p.map(f64::to_bits)).collect();
    pts.sort_unstable();
    assert!(pts.windows(2).all(|w| w[0] != w[1]), "duplicate vertex");
    // Conforming: each face shared by at most two tets; boundary closed: every directed
    // boundary edge matched by its reverse.
    let nb = tet_neighbours(m).expect("a face shared by more than two tetrahedra");
    let mut edges: HashMap<(u32, u32), i64> = HashMap::new();
    let mut boundary = Vec::new();
    for (t, tet) in m.tets.iter().enumerate() {
        for (i, f) in crate::mesh::FACE_OPPOSITE.iter().enumerate() {
            if nb[t][i] != NO_TET {
                continue;
            }
            let tri = f.map(|j| tet[j]);
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
            }
            boundary.extend(tri);
        }
    }
    assert!(edges.values().all(|&c| c == 0), "boundary not closed");
    boundary.sort_unstable();
    boundary.dedup();
    boundary
}

fn run(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    lo: [f64; 3],
    hi: [f64; 3],
    h: f64,
) -> (TetMesh, StuffingReport) {
    stuff(f, lo, hi, &StuffingParams::new(h)).unwrap()
}

fn within_paper_bounds(rep: &StuffingReport) {
    assert!(
        rep.min_dihedral_deg >= 10.7 && rep.max_dihedral_deg <= 164.8,
        "dihedral angles {:.3}°–{:.3}° outside the paper's 10.7°–164.8°",
        rep.min_dihedral_deg,
        rep.max_dihedral_deg
    );
}

#[test]
fn bcc_lattice_has_twelve_positive_tets_per_cube() {
    // Everything inside: every lattice tet is output whole.
    let p = StuffingParams::new(1.0);
    let (m, rep) = stuff(&|_| -1.0, [0.0; 3], [2.0; 3], &p).unwrap();
    // 2 + 2 cubes per axis → n = 4; interior faces 3 · 4 · 4 · 3 = 144, 4 tets each.
    assert_eq!(rep.tets, 144 * 4);
    assert_eq!(rep.tets, 12 * 4 * 4 * 4 - 4 * 3 * 4 * 4);
    check_mesh(&m, &rep);
    let h3 = 1.0;
    for t in 0..m.tets.len() {
        assert!((m.volume(t) - h3 / 12.0).abs() < 1e-12);
    }
    assert!((rep.min_dihedral_deg - 60.0).abs() < 1e-9);
    assert!((rep.max_dihedral_deg - 90.0).abs() < 1e-9);
    assert_eq!(rep.warped_vertices, 0);
}

#[test]
fn sphere_volume_converges_and_surface_is_on_the_zero_set() {
    let f = sphere(1.0);
    let exact = 4.0 / 3.0 * std::f64::consts::PI;
    let mut prev = f64::INFINITY;
    for h in [0.25, 0.125, 0.0625] {
        let (m, rep) = run(&f, [-1.0; 3], [1.0; 3], h);
        let bnd = check_mesh(&m, &rep);
        within_paper_bounds(&rep);
        let err = (rep.volume - exact).abs() / exact;
        eprintln!(
            "sphere h={h}: {} tets, volume error {:.3}%, dihedral {:.2}°–{:.2}°, {} warped",
            rep.tets,
            err * 100.0,
            rep.min_dihedral_deg,
            rep.max_dihedral_deg,
            rep.warped_vertices
        );
        assert!(err < 0.03, "volume error {err}");
        assert!(err < prev);
        prev = err;
        for &v in &bnd {
            let d = f(m.verts[v as usize]).abs();
            assert!(d < 1e-5 * h, "boundary vertex {v} at distance {d}");
        }
        // Interior vertices lie inside.
        for (v, p) in m.verts.iter().enumerate() {
            if bnd.binary_search(&(v as u32)).is_err() {
                assert!(f(*p) < 0.0);
            }
        }
    }
}

#[test]
fn box_with_sharp_corners() {
    let a = [0.8, 0.5, 0.3];
    let f = move |p: [f64; 3]| {
        (0..3)
            .map(|k| p[k].abs() - a[k])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let exact = 8.0 * a[0] * a[1] * a[2];
    for (h, tol) in [(0.1, 0.05), (0.05, 0.025)] {
        let (m, rep) = run(&f, [-0.8, -0.5, -0.3], [0.8, 0.5, 0.3], h);
        check_mesh(&m, &rep);
        within_paper_bounds(&rep);
        let err = (rep.volume - exact).abs() / exact;
        eprintln!(
            "box h={h}: {} tets, volume error {:.3}%, dihedral {:.2}°–{:.2}°",
            rep.tets,
            err * 100.0,
            rep.min_dihedral_deg,
            rep.max_dihedral_deg
        );
        assert!(err < tol, "volume error {err}");
    }
    // A box whose faces lie on lattice planes: f = 0 exactly at lattice vertices.
    let g = move |p: [f64; 3]| {
        (0..3)
            .map(|k| p[k].abs() - 0.5)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (m, rep) = run(&g, [-0.5; 3], [0.5; 3], 0.25);
    check_mesh(&m, &rep);
    within_paper_bounds(&rep);
    assert!((rep.volume - 1.0).abs() < 1e-9, "{}", rep.volume);
}

#[test]
fn torus() {
    let (big, small) = (1.0, 0.35);
    let f = move |p: [f64; 3]| {
        let rho = (p[0] * p[0] + p[1] * p[1]).sqrt();
        ((rho - big).powi(2) + p[2] * p[2]).sqrt() - small
    };
    let exact = 2.0 * std::f64::consts::PI.powi(2) * big * small * small;
    let b = big + small;
    let (m, rep) = run(&f, [-b, -b, -small], [b, b, small], 0.07);
    let bnd = check_mesh(&m, &rep);
    within_paper_bounds(&rep);
    let err = (rep.volume - exact).abs() / exact;
    eprintln!(
        "torus: {} tets, volume error {:.3}%, dihedral {:.2}°–{:.2}°",
        rep.tets,
        err * 100.0,
        rep.min_dihedral_deg,
        rep.max_dihedral_deg
    );
    assert!(err < 0.03, "{err}");
    // Genus 1: the boundary surface has Euler characteristic 0.
    let faces = {
        let nb = tet_neighbours(&m).unwrap();
        nb.iter().flatten().filter(|&&x| x == NO_TET).count() as i64
    };
    let (v, f_, e) = (bnd.len() as i64, faces, 3 * faces / 2);
    assert_eq!(v - e + f_, 0);
}

/// A high-frequency smooth random field: every stencil appears, with cut points all over
/// their allowed ranges.
fn noise(seed: u64, freq: f64) -> impl Fn([f64; 3]) -> f64 + Sync {
    let mut x = seed;
    let mut next = move || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let waves: Vec<([f64; 3], f64, f64)> = (0..12)
        .map(|_| {
            let d = [next() - 0.5, next() - 0.5, next() - 0.5];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-9);
            (
                d.map(|c| c / n * freq * (0.5 + next())),
                next() * 6.3,
                0.5 + next(),
            )
        })
        .collect();
    move |p: [f64; 3]| {
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let s: f64 = waves
            .iter()
            .map(|(k, ph, a)| a * (k[0] * p[0] + k[1] * p[1] + k[2] * p[2] + ph).sin())
            .sum();
        // Positive near the box's boundary so that the solid stays inside.
        0.15 * s + (r - 0.8).max(-0.6) * 2.0
    }
}

#[test]
fn dihedral_bounds_on_random_fields() {
    let mut lo: f64 = 180.0;
    let mut hi: f64 = 0.0;
    let mut tets = 0;
    for seed in 0..6 {
        let f = noise(seed, 18.0 + seed as f64);
        let (m, rep) = run(&f, [-1.2; 3], [1.2; 3], 0.08);
        check_mesh(&m, &rep);
        within_paper_bounds(&rep);
        lo = lo.min(rep.min_dihedral_deg);
        hi = hi.max(rep.max_dihedral_deg);
        tets += rep.tets;
    }
    eprintln!("random fields: {tets} tets, dihedral angles {lo:.3}°–{hi:.3}°");
}

#[test]
fn dihedral_bounds_on_more_random_fields() {
    // Other seeds at one frequency: together with the test above, ten fields.
    let mut lo: f64 = 180.0;
    let mut hi: f64 = 0.0;
    for seed in 10..14 {
        let f = noise(seed, 20.0);
        let (m, rep) = run(&f, [-1.2; 3], [1.2; 3], 0.08);
        check_mesh(&m, &rep);
        within_paper_bounds(&rep);
        lo = lo.min(rep.min_dihedral_deg);
        hi = hi.max(rep.max_dihedral_deg);
    }
    eprintln!("more random fields: dihedral angles {lo:.3}°–{hi:.3}°");
}

#[test]
fn four_warped_corners_are_not_output() {
    // Where the surface curves around a BCC tetrahedron all four corners can warp onto
    // it; such a tetrahedron is dropped, so every output tetrahedron keeps a corner
    // strictly inside.
    let f = noise(0, 18.0);
    let (m, rep) = run(&f, [-1.2; 3], [1.2; 3], 0.08);
    check_mesh(&m, &rep);
    within_paper_bounds(&rep);
    eprintln!(
        "{} BCC tetrahedra with four warped corners dropped",
        rep.surface_tets_dropped
    );
    assert!(rep.surface_tets_dropped > 0);
    for (i, t) in m.tets.iter().enumerate() {
        assert!(
            t.iter().any(|&v| f(m.verts[v as usize]) < 0.0),
            "tetrahedron {i} has all four corners on the surface"
        );
    }
}

#[test]
fn deterministic_across_thread_counts() {
    let f = noise(3, 15.0);
    let go = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&f, [-1.2; 3], [1.2; 3], 0.1))
    };
    let (m1, r1) = go(1);
    let (m3, r3) = go(3);
    assert_eq!(m1, m3);
    assert_eq!(r1, r3);
}

#[test]
fn stuffing_a_closed_triangle_mesh_by_winding_number() {
    // End to end as the hex pipeline does it: a closed, outward-wound triangle mesh of the
    // unit sphere (5120 triangles), f = 0.5 − w, a target edge length h.
    let (v, t) = crate::winding::tests::icosphere(4, 1.0);
    let w = crate::winding::WindingNumber::new(&v, &t).unwrap();
    let f = |p: [f64; 3]| 0.5 - w.eval(p);
    let h = 0.1;
    let (m, rep) = run(&f, [-1.0; 3], [1.0; 3], h);
    let bnd = check_mesh(&m, &rep);
    within_paper_bounds(&rep);
    // Against the sphere: the volume within a few %, the boundary within h/10.
    let sphere = 4.0 / 3.0 * std::f64::consts::PI;
    let err = (rep.volume - sphere).abs() / sphere;
    let mut worst: f64 = 0.0;
    for &b in &bnd {
        let p = m.verts[b as usize];
        worst = worst.max(((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 1.0).abs());
    }
    // Against the polyhedron itself: the volume closer still.
    let poly: f64 = t
        .iter()
        .map(|tri| {
            tet_volume(
                [0.0; 3],
                v[tri[0] as usize],
                v[tri[1] as usize],
                v[tri[2] as usize],
            )
        })
        .sum();
    let err_poly = (rep.volume - poly).abs() / poly;
    // Edge lengths, in units of h.
    let (mut emin, mut emax) = (f64::INFINITY, 0.0f64);
    for tet in &m.tets {
        for i in 0..4 {
            for j in i + 1..4 {
                let (a, b) = (m.verts[tet[i] as usize], m.verts[tet[j] as usize]);
                let l = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt() / h;
                emin = emin.min(l);
                emax = emax.max(l);
            }
        }
    }
    eprintln!(
        "winding-number sphere, h = {h}: {} tets, volume error {:.3}% (sphere), {:.3}% \
         (polyhedron), boundary within {worst:.2e} of the sphere, dihedral {:.2}°–{:.2}°, \
         edges {emin:.3}h–{emax:.3}h",
        rep.tets,
        err * 100.0,
        err_poly * 100.0,
        rep.min_dihedral_deg,
        rep.max_dihedral_deg
    );
    assert!(err < 0.03, "volume {} against {sphere}", rep.volume);
    assert!(err_poly < 0.02, "volume {} against {poly}", rep.volume);
    assert!(worst < h / 10.0, "a boundary vertex {worst} off the sphere");
    // Interior vertices are inside, away from the surface.
    for (i, p) in m.verts.iter().enumerate() {
        if bnd.binary_search(&(i as u32)).is_err() {
            assert!(w.eval(*p) > 0.5, "interior vertex {i} at {p:?}");
        }
    }
}

#[test]
fn errors_instead_of_panics() {
    let f = sphere(1.0);
    let p = StuffingParams::new(0.1);
    let e = stuff(&f, [-1.0; 3], [1.0; 3], &StuffingParams::new(0.0)).unwrap_err();
    assert!(matches!(e, StuffingError::BadInput(_)), "{e}");
    let e = stuff(&f, [1.0; 3], [-1.0; 3], &p).unwrap_err();
    assert!(e.to_string().contains("box"), "{e}");
    let mut small = p.clone();
    small.max_lattice_vertices = 1000;
    let e = stuff(&f, [-1.0; 3], [1.0; 3], &small).unwrap_err();
    assert!(
        matches!(e, StuffingError::TooLarge { limit: 1000, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("bytes each"), "{e}");
    let e = stuff(&f, [-1e12; 3], [1e12; 3], &p).unwrap_err();
    assert!(matches!(e, StuffingError::TooLarge { .. }), "{e}");
    let e = stuff(&|_| 1.0, [-1.0; 3], [1.0; 3], &p).unwrap_err();
    assert!(matches!(e, StuffingError::NothingInside { .. }), "{e}");
    let e = stuff(&|_| f64::NAN, [-1.0; 3], [1.0; 3], &p).unwrap_err();
    assert!(e.to_string().contains("NaN"), "{e}");
    let mut a = p.clone();
    a.alpha_short = 0.6;
    assert!(stuff(&f, [-1.0; 3], [1.0; 3], &a).is_err());
}

#[test]
fn root_finder_meets_its_tolerance() {
    let f = |p: [f64; 3]| p[0] - 0.3141;
    let t = root(&f, [0.0; 3], [1.0, 0.0, 0.0], -0.3141, 0.6859, 1e-9, 64);
    assert!((t - 0.3141).abs() < 1e-9);
    // A jump (like 0.5 − winding number) converges by the bisection steps.
    let g = |p: [f64; 3]| if p[0] < 0.7 { -0.5 } else { 0.5 };
    let t = root(&g, [0.0; 3], [1.0, 0.0, 0.0], -0.5, 0.5, 1e-6, 64);
    assert!((t - 0.7).abs() < 2e-6, "{t}");
    // A zero at the start is the start.
    assert_eq!(
        root(&f, [0.3141, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, 1.0, 1e-6, 64),
        0.0
    );
}

#[test]
#[ignore]
fn speed() {
    let f = sphere(1.0);
    let t = std::time::Instant::now();
    let (_, rep) = run(&f, [-1.0; 3], [1.0; 3], 0.02);
    let dt = t.elapsed().as_secs_f64();
    eprintln!(
        "sphere h=0.02: {} tets, {} lattice vertices in {dt:.2}s: {:.0} tets/s ({} threads)",
        rep.tets,
        rep.lattice_vertices,
        rep.tets as f64 / dt,
        rayon::current_num_threads()
    );
}
