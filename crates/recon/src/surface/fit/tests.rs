use super::*;
use rand::{Rng, SeedableRng};

/// Precise points on the plane `z = slope·x`, about the origin.
fn plane_points(slope: f64) -> Vec<Neighbour> {
    let mut nb: Vec<Neighbour> = Vec::new();
    for i in 0..5 {
        for j in 0..4 {
            let (x, y) = (i as f64 * 0.004 - 0.008, j as f64 * 0.004 - 0.006);
            let p = [x, y, slope * x];
            nb.push((x * x + y * y + p[2] * p[2], p, [0; 3], 0.0));
        }
    }
    nb.sort_by(|a, b| a.0.total_cmp(&b.0));
    nb
}

#[test]
fn sparse_samples_are_followed_and_holes_are_not() {
    // Samples on z = 0 six voxels apart, none within two voxels of the vertex (0.3 voxel
    // above the plane, on a z edge): fitted, at the samples' spacing.
    let h = 0.01;
    let edge = [-0.005, 0.005];
    let lattice = |x0: f64| -> Vec<[f64; 3]> {
        (0..8)
            .flat_map(|i| {
                (0..8).map(move |j| [x0 + (i as f64 - 3.5) * 0.06, (j as f64 - 3.5) * 0.06, 0.0])
            })
            .collect()
    };
    let v = [0.0, 0.0, 0.003];
    let got = project(v, 2, edge, &nearest(&lattice(0.0), v), h, 0.0);
    assert!(got[2].abs() < 1e-9, "{got:?}");
    // The same samples 40 voxels to the side: the vertex lies over a hole, left alone.
    let side = lattice(0.6);
    assert_eq!(project(v, 2, edge, &nearest(&side, v), h, 0.0), v);
}

#[test]
fn projection_follows_precise_points_and_ignores_noise() {
    let h = 0.01;
    let edge = [-0.005, 0.005];
    // Precise points on z = 0: a vertex 0.3 voxel above, on a z edge, moves onto the plane.
    let nb = plane_points(0.0);
    let v = project([0.0, 0.0, 0.003], 2, edge, &nb, h, 0.0);
    assert!(v[2].abs() < 1e-9, "{v:?}");
    // Too far from every point (more than two voxels): left alone.
    let far: Vec<_> = nb.iter().map(|x| (x.0 + 1.0, x.1, x.2, x.3)).collect();
    assert_eq!(
        project([0.0, 0.0, 0.003], 2, edge, &far, h, 0.0),
        [0.0, 0.0, 0.003]
    );
    // Noisy points (a checkerboard of ±0.4 voxel about z = 0): an offset within the
    // plane's error is not followed.
    let noisy: Vec<_> = nb
        .iter()
        .map(|x| {
            let cell = ((x.1[0] / 0.004).round() + (x.1[1] / 0.004).round()) as i64;
            let z = if cell % 2 == 0 { 0.004 } else { -0.004 };
            (x.0, [x.1[0], x.1[1], z], x.2, x.3)
        })
        .collect();
    let v = project([0.0, 0.0, 0.0015], 2, edge, &noisy, h, 0.0);
    assert!(v[2] > 0.0015 * 0.5, "{v:?}");
}

/// [`plane_points`] on `z = a·cos(2πx/λ)·cos(2πy/λ)`, `a` 0.4 and `λ` 1.6 voxels of 0.01,
/// nearest the origin first: a relief no quadratic over them follows.
fn tight_relief() -> Vec<Neighbour> {
    let (a, lambda) = (0.004, 0.016);
    let w = std::f64::consts::TAU / lambda;
    let mut nb: Vec<Neighbour> = plane_points(0.0)
        .into_iter()
        .map(|x| {
            let (px, py) = (x.1[0], x.1[1]);
            let z = a * (w * px).cos() * (w * py).cos();
            (px * px + py * py + z * z, [px, py, z], x.2, x.3)
        })
        .collect();
    nb.sort_by(|p, q| p.0.total_cmp(&q.0));
    nb
}

#[test]
fn a_relief_the_jet_cannot_follow_holds_the_vertex_unless_noise_explains_it() {
    // Precise points on z = a·cos(2πx/λ)·cos(2πy/λ) with λ = 1.6 voxels across a
    // neighbourhood of 1.6 × 1.2 voxels: no quadratic follows it, and the residuals are
    // misfit. The vertex, 0.3 voxel above, then moves less than the jet's offset; where
    // measured noise of the residuals' size (0.3 voxel, under the fit's noise limit)
    // explains them, it moves by nearly all of it.
    let h = 0.01;
    let nb = tight_relief();
    let edge = [0.0, 0.01];
    let v0 = [0.0, 0.0, 0.003];
    let held = project(v0, 2, edge, &nb, h, 0.0)[2] - v0[2];
    let free = project(v0, 2, edge, &nb, h, 0.003)[2] - v0[2];
    assert!(free.abs() > 0.0, "{free}");
    assert!(held.abs() < 0.5 * free.abs(), "held {held}, free {free}");
}

#[test]
fn noisy_samples_count_half_their_excess_residual_as_misfit() {
    // The relief no quadratic follows (above), its residuals far beyond either noise:
    // read as precise (0.04 voxel, under PRECISE_WITHIN_VOXELS) all of the excess holds
    // the vertex, read as noisy (0.06 voxel) half of it does, so the vertex moves more.
    let h = 0.01;
    let nb = tight_relief();
    let (edge, v0) = ([0.0, 0.01], [0.0, 0.0, 0.003]);
    assert!(precise(0.04 * h, h) && !precise(0.06 * h, h));
    let as_precise = project(v0, 2, edge, &nb, h, 0.04 * h)[2] - v0[2];
    let as_noisy = project(v0, 2, edge, &nb, h, 0.06 * h)[2] - v0[2];
    assert!(
        as_noisy.abs() > 1.5 * as_precise.abs() && as_noisy.abs() > 0.0,
        "precise {as_precise}, noisy {as_noisy}"
    );
}

#[test]
fn samples_noisier_than_the_fit_limit_move_no_vertex() {
    // Precise points on z = 0, the vertex 0.3 voxel above: followed where the measured
    // noise is under FIT_NOISE_LIMIT_VOXELS, kept (only within its edge) from it on.
    let h = 0.01;
    let nb = plane_points(0.0);
    let edge = [0.0, 0.01];
    let v0 = [0.0, 0.0, 0.003];
    let under = project(v0, 2, edge, &nb, h, 0.9 * FIT_NOISE_LIMIT_VOXELS * h);
    assert!(under[2] < 0.001, "{under:?}");
    let at = project(v0, 2, edge, &nb, h, FIT_NOISE_LIMIT_VOXELS * h);
    assert_eq!(at, v0);
}

#[test]
fn a_curved_surface_is_followed_by_the_jet_not_cut_by_the_plane() {
    // Precise points on a sphere of radius 2 voxels touching z = 0 from above: their
    // plane lies about 0.07 voxel above the sphere's lowest point, the jet through it.
    let (h, r) = (0.01, 0.02);
    let edge = [-0.005, 0.005];
    let nb: Vec<Neighbour> = plane_points(0.0)
        .into_iter()
        .map(|x| {
            let (px, py) = (x.1[0], x.1[1]);
            let z = r - (r * r - px * px - py * py).sqrt();
            (px * px + py * py + z * z, [px, py, z], x.2, x.3)
        })
        .collect();
    let mean_z = nb.iter().map(|x| x.1[2]).sum::<f64>() / nb.len() as f64;
    assert!(mean_z > 0.05 * h, "{mean_z}");
    let v = project([0.0, 0.0, 0.003], 2, edge, &nb, h, 0.0);
    assert!(v[2].abs() < 0.01 * h, "{v:?}");
    // Along an x edge at y = 0, z = 0.2 voxel: the sphere is at x = −√(2rz − z²), where
    // the plane, nearly parallel to the edge, would send the vertex to the edge's end.
    let z = 0.002;
    let want = -(2.0 * r * z - z * z).sqrt();
    let v = project([-0.005, 0.0, z], 0, [-0.015, -0.005], &nb, h, 0.0);
    assert!((v[0] - want).abs() < 0.02 * h, "{v:?} {want}");
}

#[test]
fn fitted_vertex_moves_along_its_edge_to_the_plane() {
    let h = 0.01;
    // Plane z = x/2; the x edge at y = 0, z = 0.001 meets it at x = 0.002.
    let nb = plane_points(0.5);
    let v = project([-0.003, 0.0, 0.001], 0, [-0.005, 0.005], &nb, h, 0.0);
    assert!((v[0] - 0.002).abs() < 1e-9, "{v:?}");
    assert_eq!((v[1], v[2]), (0.0, 0.001));
    // A plane parallel to the edge: the vertex stops short of the edge's end.
    let nb = plane_points(0.0);
    let v = project([0.001, 0.0, -0.002], 0, [-0.005, 0.005], &nb, h, 0.0);
    assert!(v[0].abs() <= 0.005 - EDGE_MARGIN * h, "{v:?}");
    assert_eq!((v[1], v[2]), (0.0, -0.002));
}

/// The 20 nearest of `pts` to `v`, as neighbours.
fn nearest(pts: &[[f64; 3]], v: [f64; 3]) -> Vec<Neighbour> {
    let mut nb: Vec<Neighbour> = pts
        .iter()
        .map(|p| {
            let d2 = (0..3).map(|a| (p[a] - v[a]).powi(2)).sum();
            (d2, *p, [0; 3], 0.0)
        })
        .collect();
    nb.sort_by(|a, b| a.0.total_cmp(&b.0));
    nb.truncate(FIT_NEIGHBOURS);
    nb
}

#[test]
fn long_slide_is_fitted_again_where_the_vertex_went() {
    // Precise points on a cylinder of radius 20 voxels about the y axis, top at z = 0; an
    // x edge below the top meets it at a grazing angle, far from where the vertex starts:
    // the plane of the points near the start misses the curve there.
    let (h, r) = (0.01, 0.2);
    let mut pts = Vec::new();
    for i in -40..=40 {
        for j in -4..=4 {
            let t = i as f64 * 0.0025 / r;
            pts.push([r * t.sin(), j as f64 * 0.0025, r * t.cos() - r]);
        }
    }
    let z = -0.006;
    let want = (r * r - (z + r) * (z + r)).sqrt();
    let edge = [0.04, 0.05];
    let v = [0.0401, 0.0, z];
    let (p1, first) = project_plane(v, 0, edge, &nearest(&pts, v), h, 0.0);
    let (plane, kept) = first.expect("the vertex moves");
    assert!((p1[0] - v[0]).abs() > REFIT_VOXELS * h, "{p1:?}");
    let p2 = refit(p1, 0, edge, &nearest(&pts, p1), h, &plane, kept);
    let (e1, e2) = ((p1[0] - want).abs(), (p2[0] - want).abs());
    assert!(e2 < 0.25 * e1, "first {e1}, again {e2}");
    assert_eq!((p2[1], p2[2]), (0.0, z));
}

#[test]
fn fitted_vertex_never_leaves_its_edge() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(15);
    let h = 0.01;
    for _ in 0..2000 {
        let slope = rng.random_range(-20.0..20.0);
        let nb = plane_points(slope);
        let axis = rng.random_range(0..3usize);
        let lo = rng.random_range(-0.02..0.01);
        let edge = [lo, lo + h];
        let mut v = [0.0; 3].map(|_: f64| rng.random_range(-0.01..0.01));
        // On the edge, ends included (marching cubes may put a vertex on a node).
        v[axis] = lo + h * rng.random_range(0.0..=1.0);
        let p = project(v, axis, edge, &nb, h, 0.0);
        let m = EDGE_MARGIN * h;
        assert!(p[axis] >= lo + m && p[axis] <= lo + h - m, "{v:?} -> {p:?}");
        for a in (0..3).filter(|&a| a != axis) {
            assert_eq!(p[a], v[a]);
        }
    }
}

#[test]
fn edge_margin_covers_float32_rounding_far_from_the_origin() {
    // Feet near 6e5: float32 steps are 1/16, more than 1% of a 2-foot edge.
    let edge = [600_000.0, 600_002.0];
    let m = edge_margin(edge);
    assert!(m >= 2.0 * 0.0625, "{m}");
    let (a, b) = (clamp_to_edge(-1e300, edge), clamp_to_edge(1e300, edge));
    assert!((edge[0] as f32) < a as f32 && (b as f32) < edge[1] as f32);
    // Near the origin the margin is EDGE_MARGIN of the edge.
    assert_eq!(edge_margin([0.0, 0.01]), EDGE_MARGIN * 0.01);
    // An edge shorter than float32 can resolve: its middle.
    assert_eq!(clamp_to_edge(7.0, [1e7, 1e7 + 0.1]), 1e7 + 0.05);
}

/// Twice the area of the triangle `c` in f64.
fn double_area(c: [[f64; 3]; 3]) -> f64 {
    let (u, w) = (
        [0, 1, 2].map(|a| c[1][a] - c[0][a]),
        [0, 1, 2].map(|a| c[2][a] - c[0][a]),
    );
    let x = [
        u[1] * w[2] - u[2] * w[1],
        u[2] * w[0] - u[0] * w[2],
        u[0] * w[1] - u[1] * w[0],
    ];
    (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt()
}

#[test]
fn triangles_on_three_edges_of_a_cell_never_collapse_in_float32() {
    // Marching cubes puts a triangle's corners on three distinct edges of one cell; kept
    // inside their edges, as written in float32, they are never collinear.
    let mut rng = rand_pcg::Pcg64::seed_from_u64(13);
    let edges: Vec<([f64; 3], usize)> = (0..3)
        .flat_map(|axis| {
            (0..4).map(move |k| {
                let mut o = [0.0; 3];
                let others: Vec<usize> = (0..3).filter(|&a| a != axis).collect();
                o[others[0]] = (k & 1) as f64;
                o[others[1]] = (k >> 1) as f64;
                (o, axis)
            })
        })
        .collect();
    for (origin, h) in [
        ([0.3, -0.7, 0.1], 0.004),
        ([637_000.0, 851_000.0, 400.0], 2.0),
    ] {
        for _ in 0..20_000 {
            let mut pick = [0usize; 3];
            while pick[0] == pick[1] || pick[1] == pick[2] || pick[0] == pick[2] {
                pick = pick.map(|_| rng.random_range(0..12));
            }
            let c = pick.map(|e| {
                let (o, axis) = edges[e];
                let ends = [
                    origin[axis] + h * o[axis],
                    origin[axis] + h * (o[axis] + 1.0),
                ];
                let t = [0.0, 1.0, rng.random_range(0.0..1.0)][rng.random_range(0..3)];
                let x = clamp_to_edge(ends[0] + t * h, ends);
                [0, 1, 2].map(|a| {
                    let p = if a == axis { x } else { origin[a] + h * o[a] };
                    p as f32 as f64
                })
            });
            // `scanflow check`'s rule: flat when `2·area ≤ 1e-12·ℓ²`, `ℓ` the longest edge.
            let longest = (0..3)
                .map(|i| (0..3).map(|a| (c[i][a] - c[(i + 1) % 3][a]).powi(2)).sum())
                .fold(0.0, f64::max);
            assert!(double_area(c) > 1e-12 * longest, "{c:?}");
        }
    }
}
