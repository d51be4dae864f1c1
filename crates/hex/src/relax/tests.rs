use super::cube::{CUBE, corners};
use super::*;
use crate::extract::{extract, fixtures};
use crate::quality::hex_scaled_jacobian;
use rand::{Rng, SeedableRng};

/// The `n³` grid of cubes of side `1/n` on the unit box, vertex `(i, j, k)` at index
/// `i + (n+1)(j + (n+1)k)`.
pub(crate) fn grid(n: usize) -> HexMesh {
    let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
    let h = 1.0 / n as f64;
    let mut verts = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                verts.push([i as f64 * h, j as f64 * h, k as f64 * h]);
            }
        }
    }
    let mut hexes = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                hexes.push([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i + 1, j + 1, k + 1),
                    id(i, j + 1, k + 1),
                ]);
            }
        }
    }
    HexMesh { verts, hexes }
}

/// The unit box's surface, each face an `m × m` grid of squares split in two triangles.
fn box_surface(m: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (mut verts, mut tris) = (Vec::new(), Vec::new());
    for axis in 0..3 {
        for side in [0.0, 1.0] {
            let base = verts.len() as u32;
            for b in 0..=m {
                for a in 0..=m {
                    let mut p = [0.0; 3];
                    p[axis] = side;
                    p[(axis + 1) % 3] = a as f64 / m as f64;
                    p[(axis + 2) % 3] = b as f64 / m as f64;
                    verts.push(p);
                }
            }
            let id = |a: usize, b: usize| base + (a + (m + 1) * b) as u32;
            for b in 0..m {
                for a in 0..m {
                    tris.push([id(a, b), id(a + 1, b), id(a + 1, b + 1)]);
                    tris.push([id(a, b), id(a + 1, b + 1), id(a, b + 1)]);
                }
            }
        }
    }
    (verts, tris)
}

/// Distance from `p` to the triangles, by brute force.
fn brute_distance(p: [f64; 3], verts: &[[f64; 3]], tris: &[[u32; 3]]) -> f64 {
    tris.iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| verts[v as usize]);
            dist2(p, closest_on_triangle(p, a, b, c)).sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

/// A grid with interior vertices jittered in space and face vertices within their face.
fn jittered(n: usize, amount: f64, seed: u64) -> HexMesh {
    let mut m = grid(n);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let h = 1.0 / n as f64;
    for p in m.verts.iter_mut() {
        let on = |c: f64| c.abs() < 1e-12 || (c - 1.0).abs() < 1e-12;
        let bound = p.iter().filter(|&&c| on(c)).count();
        if bound <= 1 {
            for c in p.iter_mut() {
                if !on(*c) {
                    *c += rng.random_range(-amount..amount) * h;
                }
            }
        }
    }
    m
}

fn all_sj(m: &HexMesh) -> Vec<f64> {
    (0..m.hexes.len())
        .map(|k| hex_scaled_jacobian(&corners(&m.verts, &m.hexes[k])))
        .collect()
}

#[test]
fn ideal_cube_of_a_rotated_scaled_cube_is_itself() {
    let (a, b) = (0.7f64, -0.4f64);
    let r = [
        [a.cos() * b.cos(), -a.sin(), a.cos() * b.sin()],
        [a.sin() * b.cos(), a.cos(), a.sin() * b.sin()],
        [-b.sin(), 0.0, b.cos()],
    ];
    let x = CUBE.map(|c| [0, 1, 2].map(|i| 2.5 * dot(r[i], c) + [1.0, -2.0, 0.5][i]));
    let y = ideal_cube(&x);
    for i in 0..8 {
        assert!(dist2(x[i], y[i]) < 1e-24);
    }
    // An inverted cube (mirrored) is fitted by a positively oriented one.
    let mirrored = x.map(|p| [-p[0], p[1], p[2]]);
    assert!(hex_scaled_jacobian(&mirrored) < 0.0);
    assert!(hex_scaled_jacobian(&ideal_cube(&mirrored)) > 0.99);
}

#[test]
fn bvh_closest_point_matches_brute_force() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let verts: Vec<[f64; 3]> = (0..300)
        .map(|_| [0; 3].map(|_: i32| rng.random_range(-1.0..1.0)))
        .collect();
    let tris: Vec<[u32; 3]> = (0..200)
        .map(|_| [0; 3].map(|_: i32| rng.random_range(0..300u32)))
        .collect();
    let bvh = Bvh::new(&verts, &tris);
    for _ in 0..300 {
        let p = [0; 3].map(|_: i32| rng.random_range(-1.5..1.5));
        let (q, d2) = bvh.closest(p).unwrap();
        let want = brute_distance(p, &verts, &tris);
        assert!((d2.sqrt() - want).abs() < 1e-12, "{} vs {want}", d2.sqrt());
        assert!((dist2(p, q).sqrt() - want).abs() < 1e-12);
    }
    assert!(Bvh::new(&verts, &[]).closest([0.0; 3]).is_none());
}

#[test]
fn a_vertex_in_a_thin_slab_keeps_to_its_side() {
    // A slab 0.1 thick (top at z = 0.1 facing up, bottom at z = 0 facing down) and a
    // vertex just below the middle: the nearest face is the bottom, but a vertex whose
    // quadrilaterals face up goes to the top.
    let verts = vec![
        [-1.0, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, -1.0, 0.1],
        [1.0, -1.0, 0.1],
        [1.0, 1.0, 0.1],
    ];
    let tris = vec![[0, 2, 1], [3, 4, 5]];
    let bvh = Bvh::new(&verts, &tris);
    let p = [0.5, 0.0, 0.04];
    let (q, _) = bvh.closest(p).unwrap();
    assert!(q[2].abs() < 1e-12, "{q:?}");
    let (q, d2) = bvh.closest_facing(p, [0.0, 0.0, 1.0]).unwrap();
    assert!(
        (q[2] - 0.1).abs() < 1e-12 && (d2 - 0.06 * 0.06).abs() < 1e-12,
        "{q:?}"
    );
    let (q, _) = bvh.closest_facing(p, [0.0, 0.0, -1.0]).unwrap();
    assert!(q[2].abs() < 1e-12, "{q:?}");
    // Nothing faces sideways.
    assert!(bvh.closest_facing(p, [1.0, 0.0, 0.0]).is_none());
}

#[test]
fn a_regular_grid_is_a_fixed_point() {
    let mut m = grid(3);
    let before = m.clone();
    let (bv, bt) = box_surface(2);
    let rep = relax(&mut m, &bv, &bt, &RelaxParams::default());
    assert!(rep.converged && rep.iterations == 1, "{rep:?}");
    assert_eq!(m, before);
    assert!((rep.min_sj_after - 1.0).abs() < 1e-12);
}

#[test]
fn jittered_grid_relaxes_with_boundary_on_the_surface() {
    let n = 4;
    let mut m = jittered(n, 0.3, 17);
    let start = m.clone();
    let sj0 = all_sj(&m);
    assert!(sj0.iter().all(|&s| s > 0.0));
    let (bv, bt) = box_surface(3);
    let params = RelaxParams {
        iterations: 60,
        ..RelaxParams::default()
    };
    let rep = relax(&mut m, &bv, &bt, &params);
    let sj1 = all_sj(&m);
    assert!(rep.min_sj_after > rep.min_sj_before + 0.1, "{rep:?}");
    assert!(rep.mean_sj_after > rep.mean_sj_before, "{rep:?}");
    assert!(
        rep.cube_misfit_after < 0.5 * rep.cube_misfit_before,
        "{rep:?}"
    );
    assert_eq!(rep.inverted_after, 0);
    assert!(sj1.iter().all(|&s| s > 0.0));
    let min1 = sj1.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(min1, rep.min_sj_after);
    // (n-1)² face vertices per face slide on the surface; edges and corners stay.
    assert_eq!(rep.surface_vertices, 6 * (n - 1) * (n - 1));
    assert_eq!(rep.interior_vertices, (n - 1).pow(3));
    let diag = 3f64.sqrt();
    for (v, p) in m.verts.iter().enumerate() {
        let on = p.iter().any(|&c| c.abs() < 1e-6 || (c - 1.0).abs() < 1e-6);
        let was_on = start.verts[v]
            .iter()
            .any(|&c| c.abs() < 1e-12 || (c - 1.0).abs() < 1e-12);
        assert_eq!(on, was_on, "vertex {v} at {p:?}");
        if was_on {
            assert!(brute_distance(*p, &bv, &bt) <= 1e-9 * diag);
        }
    }
    assert!(rep.max_surface_distance <= 1e-9 * diag);
    // Deterministic, for any thread count.
    let again = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| {
            let mut m2 = start.clone();
            let r2 = relax(&mut m2, &bv, &bt, &params);
            (m2, r2)
        });
    assert_eq!(again.0, m);
    assert_eq!(again.1, rep);
}

#[test]
fn an_inverted_hex_does_not_spread() {
    let mut m = grid(3);
    // Push interior vertex (1, 1, 1) through its neighbours.
    let v = 1 + 4 * (1 + 4);
    m.verts[v] = [0.58, 0.55, 0.6];
    let sj0 = all_sj(&m);
    let bad0 = sj0.iter().filter(|&&s| s <= 0.0).count();
    assert!(bad0 > 0);
    let (bv, bt) = box_surface(1);
    let rep = relax(&mut m, &bv, &bt, &RelaxParams::default());
    assert_eq!(rep.inverted_before, bad0);
    assert!(rep.inverted_after <= bad0, "{rep:?}");
    // Here the fitted cubes pull the pushed vertex back: the mesh untangles.
    assert_eq!(rep.inverted_after, 0, "{rep:?}");
    assert!(rep.min_sj_after > 0.9, "{rep:?}");
    assert!(rep.min_sj_after >= rep.min_sj_before);
    // No hex that was valid is inverted now.
    let sj1 = all_sj(&m);
    for k in 0..sj0.len() {
        if sj0[k] > 0.0 {
            assert!(sj1[k] > 0.0, "hex {k}: {} -> {}", sj0[k], sj1[k]);
        }
    }
}

#[test]
fn extracted_singular_prism_relaxes_on_its_surface() {
    let (mesh, map) = fixtures::singular_prism(3, 2.0, 2);
    let topo = crate::topology::check_tets(&mesh).unwrap();
    let tris = topo.boundary_triangles(&mesh);
    let (mut hex, _) = extract(&mesh, &map).unwrap();
    let rep = relax(&mut hex, &mesh.verts, &tris, &RelaxParams::default());
    // The smallest scaled Jacobian, sin 60° at the prism's fixed 60° edges, cannot
    // improve; the hexes get closer to cubes without any getting worse than it.
    assert!(rep.min_sj_after >= rep.min_sj_before, "{rep:?}");
    assert!(
        rep.cube_misfit_after < 0.95 * rep.cube_misfit_before,
        "{rep:?}"
    );
    assert_eq!(rep.inverted_after, 0);
    assert!(rep.surface_vertices > 0);
    assert!(rep.max_surface_distance <= 1e-9);
}
