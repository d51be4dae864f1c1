//! Tests of the patch layout: partition, cone condition, sizes, compactness, determinism,
//! degenerate input, and a throughput measurement.

use super::*;
use crate::cone::enclosing_cone;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// `n` points on the unit sphere (Fibonacci spiral), normals = positions.
fn sphere(n: usize) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    let golden = PI * (3.0 - 5f64.sqrt());
    let pos: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let z = 1.0 - (2 * i + 1) as f64 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let t = golden * i as f64;
            [r * t.cos(), r * t.sin(), z]
        })
        .collect();
    let nrm = pos
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect();
    (pos, nrm)
}

/// A jittered `side × side` grid on the unit square, normals +z.
fn plane(side: usize, rng: &mut Pcg64) -> (Vec<[f64; 3]>, Vec<[f32; 3]>) {
    let h = 1.0 / side as f64;
    let pos: Vec<[f64; 3]> = (0..side * side)
        .map(|k| {
            let (i, j) = ((k % side) as f64, (k / side) as f64);
            [
                (i + rng.random_range(0.0..1.0)) * h,
                (j + rng.random_range(0.0..1.0)) * h,
                0.0,
            ]
        })
        .collect();
    (pos, vec![[0.0, 0.0, 1.0]; side * side])
}

/// Every index once, members ascending, patches ordered by smallest member, sizes bounded.
fn check_partition(patches: &[PatchSeed], n: usize, patch_max: usize) {
    let mut seen = vec![false; n];
    let mut last_first = None;
    for p in patches {
        assert!(!p.members.is_empty() && p.members.len() <= patch_max);
        assert!(p.members.windows(2).all(|w| w[0] < w[1]));
        assert!(last_first < Some(p.members[0]));
        last_first = Some(p.members[0]);
        for &i in &p.members {
            assert!(!seen[i as usize], "{i} twice");
            seen[i as usize] = true;
        }
    }
    assert!(seen.iter().all(|&s| s), "a point in no patch");
}

/// The exact cone of each patch's members satisfies the condition and is the one reported.
fn check_cones(patches: &[PatchSeed], normals: &[[f32; 3]], max_aperture: f64) {
    for p in patches {
        match enclosing_cone(normals, &p.members) {
            Some(c) => {
                assert!(
                    c.aperture() <= max_aperture + 1e-9,
                    "aperture {}",
                    c.aperture()
                );
                assert_eq!(c, p.cone);
            }
            None => assert_eq!(p.oriented, 0),
        }
    }
}

#[test]
fn layout_partitions_a_sphere_and_keeps_the_cone_condition() {
    let (pos, nrm) = sphere(20_000);
    let params = LayoutParams::default();
    let patches = layout(&pos, &nrm, &params);
    check_partition(&patches, pos.len(), params.patch_max);
    check_cones(&patches, &nrm, params.max_aperture);
    assert!(
        patches
            .iter()
            .all(|p| p.oriented as usize == p.members.len())
    );
}

#[test]
fn layout_patches_on_a_sphere_are_compact() {
    let n = 50_000;
    let (pos, nrm) = sphere(n);
    let params = LayoutParams::default();
    let patches = layout(&pos, &nrm, &params);
    let area_per_point = 4.0 * PI / n as f64;
    let mut worst: f64 = 0.0;
    for p in &patches {
        let m = p.members.len() as f64;
        let mut c = [0.0; 3];
        for &i in &p.members {
            for k in 0..3 {
                c[k] += pos[i as usize][k] / m;
            }
        }
        let far = p.members.iter().map(|&i| {
            let q = pos[i as usize];
            ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2) + (q[2] - c[2]).powi(2)).sqrt()
        });
        let far = far.fold(0.0, f64::max);
        // The radius of a disc of the patch's area.
        let disc = (m * area_per_point / PI).sqrt();
        worst = worst.max(far / disc.max(1e-12));
    }
    assert!(
        worst < 2.5,
        "a patch reaches {worst} times the radius of its disc"
    );
    let mean = n as f64 / patches.len() as f64;
    assert!(
        mean > 0.3 * params.patch_max as f64,
        "mean patch size {mean}"
    );
}

#[test]
fn layout_of_a_plane_fills_patches_near_patch_max() {
    let mut rng = Pcg64::seed_from_u64(4);
    let (pos, nrm) = plane(200, &mut rng);
    let params = LayoutParams {
        patch_max: 800,
        ..LayoutParams::default()
    };
    let patches = layout(&pos, &nrm, &params);
    check_partition(&patches, pos.len(), params.patch_max);
    let mean = pos.len() as f64 / patches.len() as f64;
    assert!(
        mean >= 0.5 * params.patch_max as f64,
        "mean patch size {mean}"
    );
    assert!(patches.iter().all(|p| p.cone.half_angle < 1e-6));
    // No patch under cluster_min is left over on a plane.
    assert!(
        patches
            .iter()
            .all(|p| p.members.len() >= params.cluster_min)
    );
}

#[test]
fn layout_is_deterministic() {
    let (pos, nrm) = sphere(10_000);
    let params = LayoutParams::default();
    let a = layout(&pos, &nrm, &params);
    let mut ws = Workspace::default();
    let _ = layout_with(&mut ws, &pos[..3000], &nrm[..3000], &params);
    let b = layout_with(&mut ws, &pos, &nrm, &params);
    assert_eq!(a, b);
}

#[test]
fn layout_of_duplicates_and_a_single_point() {
    let params = LayoutParams::default();
    let one = layout(&[[1.0, 2.0, 3.0]], &[[0.0, 1.0, 0.0]], &params);
    assert_eq!(one.len(), 1);
    assert_eq!(one[0].members, vec![0]);
    assert_eq!(one[0].cone.axis, [0.0, 1.0, 0.0]);
    assert!(layout(&[], &[], &params).is_empty());
    // 5000 copies of one point, with normals on two opposite sides: still terminates.
    let pos = vec![[0.5, 0.5, 0.5]; 5000];
    let nrm: Vec<[f32; 3]> = (0..5000)
        .map(|i| [0.0, 0.0, if i % 2 == 0 { 1.0 } else { -1.0 }])
        .collect();
    let patches = layout(&pos, &nrm, &params);
    check_partition(&patches, pos.len(), params.patch_max);
    check_cones(&patches, &nrm, params.max_aperture);
}

#[test]
fn layout_with_random_normals_still_partitions() {
    let mut rng = Pcg64::seed_from_u64(8);
    let (pos, _) = sphere(5000);
    let nrm: Vec<[f32; 3]> = (0..pos.len())
        .map(|_| {
            [
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ]
        })
        .collect();
    let params = LayoutParams::default();
    let patches = layout(&pos, &nrm, &params);
    check_partition(&patches, pos.len(), params.patch_max);
    check_cones(&patches, &nrm, params.max_aperture);
}

#[test]
fn layout_keeps_zero_normals_with_their_spatial_cluster() {
    let (pos, mut nrm) = sphere(8000);
    for (i, v) in nrm.iter_mut().enumerate() {
        if i % 7 == 0 || pos[i][2] > 0.9 {
            *v = [0.0; 3];
        }
    }
    let params = LayoutParams::default();
    let patches = layout(&pos, &nrm, &params);
    check_partition(&patches, pos.len(), params.patch_max);
    check_cones(&patches, &nrm, params.max_aperture);
    let oriented: usize = patches.iter().map(|p| p.oriented as usize).sum();
    assert_eq!(oriented, nrm.iter().filter(|v| **v != [0.0; 3]).count());
}

#[test]
fn layout_respects_a_small_patch_max_and_aperture() {
    let (pos, nrm) = sphere(6000);
    let params = LayoutParams {
        cluster_max: 40,
        cluster_min: 10,
        patch_max: 30,
        max_aperture: 0.2,
    };
    let patches = layout(&pos, &nrm, &params);
    check_partition(&patches, pos.len(), params.patch_max);
    check_cones(&patches, &nrm, params.max_aperture);
}

#[test]
fn layout_params_check_rejects_bad_values() {
    assert!(LayoutParams::default().check().is_ok());
    let zero = LayoutParams {
        patch_max: 0,
        ..LayoutParams::default()
    };
    assert!(zero.check().is_err());
    let nan = LayoutParams {
        max_aperture: f64::NAN,
        ..LayoutParams::default()
    };
    assert!(nan.check().is_err());
}

/// CPU time of this thread, ns (Linux: `/proc/thread-self/schedstat`), wall time elsewhere.
fn cpu_ns(wall: std::time::Instant) -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .unwrap_or_else(|| wall.elapsed().as_nanos() as f64)
}

/// Throughput on one store cell's worth of sphere points, in CPU time of this thread
/// (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn layout_speed_on_a_sphere_cell() {
    let (pos, nrm) = sphere(262_144);
    let params = LayoutParams::default();
    let lim = Limits::new(&params);
    let mut ws = Workspace::default();
    let _ = layout_with(&mut ws, &pos, &nrm, &params);
    let wall = std::time::Instant::now();
    let reps = 5;
    let mut t = [0.0; 4];
    for _ in 0..reps {
        let t0 = cpu_ns(wall);
        split(&mut ws, &pos, &nrm, &lim);
        let t1 = cpu_ns(wall);
        adjacency(&mut ws);
        let t2 = cpu_ns(wall);
        merge(&mut ws, &lim);
        let t3 = cpu_ns(wall);
        let _ = assemble(&mut ws, pos.len(), &nrm);
        let t4 = cpu_ns(wall);
        for (k, d) in [t1 - t0, t2 - t1, t3 - t2, t4 - t3].into_iter().enumerate() {
            t[k] += d / (reps * pos.len()) as f64;
        }
    }
    let total: f64 = t.iter().sum();
    let patches = layout_with(&mut ws, &pos, &nrm, &params);
    let sizes: Vec<usize> = patches.iter().map(|p| p.members.len()).collect();
    let widest = patches
        .iter()
        .map(|p| p.cone.aperture())
        .fold(0.0, f64::max);
    println!(
        "layout: {total:.1} ns/point ({:.2} M points/s): split {:.1}, adjacency {:.1}, merge {:.1}, assemble {:.1}",
        1e3 / total,
        t[0],
        t[1],
        t[2],
        t[3],
    );
    println!(
        "{} leaves, {} patches, sizes {}..{} (mean {:.0}), widest aperture {widest:.3} rad",
        ws.leaves.len(),
        patches.len(),
        sizes.iter().min().unwrap_or(&0),
        sizes.iter().max().unwrap_or(&0),
        pos.len() as f64 / patches.len().max(1) as f64
    );
    let mut rng = Pcg64::seed_from_u64(4);
    let (pos, nrm) = plane(512, &mut rng);
    let patches = layout_with(&mut ws, &pos, &nrm, &params);
    println!(
        "plane: {} points, {} patches, mean size {:.0}",
        pos.len(),
        patches.len(),
        pos.len() as f64 / patches.len().max(1) as f64
    );
}

/// Perimeter of an ellipse by numeric integration (independent of Ramanujan's formula).
fn ellipse_perimeter(a: f64, b: f64) -> f64 {
    let k = 100_000;
    (0..k)
        .map(|i| {
            let t = (i as f64 + 0.5) * 2.0 * PI / k as f64;
            (a * a * t.sin().powi(2) + b * b * t.cos().powi(2)).sqrt() * 2.0 * PI / k as f64
        })
        .sum()
}

#[test]
fn compactness_is_the_isoperimetric_quotient_of_the_covariance_ellipse() {
    // A w × h grid in a tilted plane through (5, -3, 2), the cone axis its normal.
    let normal = normalize([1.0, 2.0, 2.0]).expect("unit");
    let u = normalize(cross(normal, [0.0, 0.0, 1.0])).expect("unit");
    let v = cross(normal, u);
    for (w, h) in [(1.0, 1.0), (2.0, 1.0), (5.0, 1.0), (1.0, 0.0)] {
        let side = 201;
        let items: Vec<Item> = (0..side * side)
            .map(|k| {
                let s = w * ((k % side) as f64 / (side - 1) as f64 - 0.5);
                let t = h * ((k / side) as f64 / (side - 1) as f64 - 0.5);
                let p = [
                    5.0 + s * u[0] + t * v[0],
                    -3.0 + s * u[1] + t * v[1],
                    2.0 + s * u[2] + t * v[2],
                ];
                Item { p, i: k as u32 }
            })
            .collect();
        let cone = Cone {
            axis: normal,
            half_angle: 0.0,
        };
        let c = new_cluster(&items, [1.0, 1.0, 1.0], Some(cone));
        // A uniform grid's variances are proportional to w² and h², so the ellipse is w : h.
        let want = if h == 0.0 {
            0.0
        } else {
            4.0 * PI * PI * w * h / ellipse_perimeter(w, h).powi(2)
        };
        let got = compactness(&c);
        assert!((got - want).abs() < 1e-3, "{w} x {h}: {got} vs {want}");
    }
}
