use super::boundary::Axis;
use super::sh::{
    SH_SCALE, dist2_9, dot9, frame_about, project, rotate, sh_basis, sh_basis_grad, sh_jacobian,
};
use super::*;
use crate::geom::vec::{add, cross, dot, norm, scale, sub};
use crate::mesh::{NO_TET, tet_neighbours, tet_volume};
use rand::{Rng, SeedableRng};
use std::collections::HashSet;

const ID: Frame = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The 24 rotations of the cube, as frames (signed permutations with determinant +1).
fn cube_rotations() -> Vec<Frame> {
    let perms = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut out = Vec::new();
    for p in perms {
        for sg in 0..8 {
            let mut f = [[0.0; 3]; 3];
            for k in 0..3 {
                f[k][p[k]] = if sg >> k & 1 == 1 { -1.0 } else { 1.0 };
            }
            if dot(cross(f[0], f[1]), f[2]) > 0.0 {
                out.push(f);
            }
        }
    }
    out
}

/// `f`'s axes expressed through the rotation `r`: the frame `R F`.
fn rotate_frame(r: &Frame, f: &Frame) -> Frame {
    // Axis k of f, components in world; apply R whose columns are r[0], r[1], r[2].
    f.map(|a| add(add(scale(r[0], a[0]), scale(r[1], a[1])), scale(r[2], a[2])))
}

fn random_frame(rng: &mut rand_pcg::Pcg64) -> Frame {
    // Uniform quaternion.
    let (u1, u2, u3): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
    let tau = std::f64::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    let (w, x, y, z) = (
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
        b * (tau * u3).cos(),
    );
    let m = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    // Columns as axes.
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}

#[test]
fn constants_match_their_definitions() {
    assert!((SQRT_7_12 - (7.0f64 / 12.0).sqrt()).abs() < 1e-16);
    assert!((SQRT_5_12 - (5.0f64 / 12.0).sqrt()).abs() < 1e-16);
    let pi = std::f64::consts::PI;
    let base = 3.0 / 16.0 / pi.sqrt();
    let true_consts = [
        0.75 * (35.0 / pi).sqrt(),
        0.75 * (35.0 / (2.0 * pi)).sqrt(),
        0.75 * (5.0 / pi).sqrt(),
        0.75 * (5.0 / (2.0 * pi)).sqrt(),
        base,
        0.75 * (5.0 / (2.0 * pi)).sqrt(),
        0.375 * (5.0 / pi).sqrt(),
        0.75 * (35.0 / (2.0 * pi)).sqrt(),
        3.0 / 16.0 * (35.0 / pi).sqrt(),
    ];
    for m in 0..9 {
        let want = true_consts[m] / base / 336f64.sqrt();
        assert!((SH_SCALE[m] - want).abs() < 1e-15, "m = {m}");
    }
    let q = frame_to_sh(&ID);
    for m in 0..9 {
        assert!((q[m] - SH_IDENTITY[m]).abs() < 1e-15);
    }
}

#[test]
fn the_basis_is_orthonormal_on_the_sphere() {
    // Product rule: the midpoint rule in cos θ with 4000 nodes (error ~1e-6 for these
    // degree-8 polynomials) and 32 equal steps in φ (exact for trigonometric degree < 32).
    let (nt, np) = (4000, 32);
    let mut g = [[0.0; 9]; 9];
    let norm = 336f64.sqrt() * 3.0 / 16.0 / std::f64::consts::PI.sqrt();
    for i in 0..nt {
        let z = -1.0 + (2 * i + 1) as f64 / nt as f64;
        let r = (1.0 - z * z).sqrt();
        for j in 0..np {
            let ph = std::f64::consts::TAU * j as f64 / np as f64;
            let y = sh_basis([r * ph.cos(), r * ph.sin(), z]).map(|v| v * norm);
            let wgt = (2.0 / nt as f64) * (std::f64::consts::TAU / np as f64);
            for a in 0..9 {
                for b in 0..9 {
                    g[a][b] += wgt * y[a] * y[b];
                }
            }
        }
    }
    for a in 0..9 {
        for b in 0..9 {
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((g[a][b] - want).abs() < 1e-5, "{a} {b}: {}", g[a][b]);
        }
    }
}

#[test]
fn gradients_and_jacobian_match_finite_differences() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    for _ in 0..20 {
        let f = random_frame(&mut rng);
        let d = f[0];
        let g = sh_basis_grad(d);
        let h = 1e-6;
        for k in 0..3 {
            let mut dp = d;
            let mut dm = d;
            dp[k] += h;
            dm[k] -= h;
            let (yp, ym) = (sh_basis(dp), sh_basis(dm));
            for m in 0..9 {
                assert!(((yp[m] - ym[m]) / (2.0 * h) - g[m][k]).abs() < 1e-6);
            }
        }
        let j = sh_jacobian(&f);
        for i in 0..3 {
            let mut w = [0.0; 3];
            w[i] = h;
            let qp = frame_to_sh(&f.map(|a| rotate(a, w)));
            let qm = frame_to_sh(&f.map(|a| rotate(a, scale(w, -1.0))));
            for m in 0..9 {
                assert!(((qp[m] - qm[m]) / (2.0 * h) - j[m][i]).abs() < 1e-6);
            }
        }
    }
}

#[test]
fn cube_rotations_share_one_sh_vector_and_rotations_keep_unit_norm() {
    let rots = cube_rotations();
    assert_eq!(rots.len(), 24);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
    for _ in 0..10 {
        let f = random_frame(&mut rng);
        let q = frame_to_sh(&f);
        assert!((dot9(&q, &q) - 1.0).abs() < 1e-13);
        for r in &rots {
            // The same frame with its axes permuted and signed.
            let g = rotate_frame(&f, r);
            let qg = frame_to_sh(&g);
            assert!(dist2_9(&q, &qg).sqrt() < 1e-13);
            assert!(frame_distance(&f, &g) < 1e-13);
        }
    }
    for r in &rots {
        assert!(dist2_9(&frame_to_sh(r), &SH_IDENTITY).sqrt() < 1e-14);
    }
    // A generic rotation is far.
    let f = random_frame(&mut rng);
    assert!(frame_distance(&f, &ID) > 0.1);
}

#[test]
fn projection_recovers_random_frames_and_denoises() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(42);
    let mut worst: f64 = 0.0;
    for _ in 0..2000 {
        let f = random_frame(&mut rng);
        let g = sh_to_frame(&frame_to_sh(&f));
        assert!((dot(cross(g[0], g[1]), g[2]) - 1.0).abs() < 1e-12);
        worst = worst.max(frame_distance(&f, &g));
    }
    assert!(worst < 1e-9, "worst {worst}");
    // Noisy and scaled coefficients project back near the frame.
    for _ in 0..200 {
        let f = random_frame(&mut rng);
        let mut q = frame_to_sh(&f);
        for v in q.iter_mut() {
            *v = 0.3 * (*v + 0.05 * (rng.random::<f64>() - 0.5));
        }
        assert!(frame_distance(&f, &sh_to_frame(&q)) < 0.1);
    }
    // The projection is a global optimum among many random frames.
    for _ in 0..50 {
        let q: [f64; 9] = std::array::from_fn(|_| rng.random::<f64>() - 0.5);
        let (f, _) = project(&q);
        let best = dot9(&frame_to_sh(&f), &q);
        for _ in 0..200 {
            let g = random_frame(&mut rng);
            assert!(dot9(&frame_to_sh(&g), &q) <= best + 1e-12);
        }
    }
}

#[test]
fn axis_circle_is_the_set_of_frames_with_that_axis() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    for _ in 0..20 {
        let n = random_frame(&mut rng)[0];
        let ax = Axis::new(n);
        assert!((dot9(&ax.c, &ax.c) - 1.0).abs() < 1e-13);
        assert!((dot9(&ax.d, &ax.d) - 1.0).abs() < 1e-13);
        assert!(dot9(&ax.c, &ax.d).abs() < 1e-13);
        assert!(dot9(&ax.c, &ax.z0).abs() < 1e-13);
        assert!((dot9(&ax.z0, &ax.z0) - 7.0 / 12.0).abs() < 1e-13);
        for k in 0..8 {
            let th = 0.3 + k as f64 * 0.37;
            let f = frame_about(n, ax.t1, ax.t2, th);
            let q = frame_to_sh(&f);
            let (a, b) = ((4.0 * th).cos(), (4.0 * th).sin());
            for m in 0..9 {
                let want = ax.z0[m] + SQRT_5_12 * (a * ax.c[m] + b * ax.d[m]);
                assert!((q[m] - want).abs() < 1e-13);
            }
            assert!(frame_distance(&ax.project(&q), &f) < 1e-12);
            assert!(dot9(&ax.perp(&q), &ax.c).abs() < 1e-14);
        }
    }
}

// ----- meshes -----

/// A grid of `nx × ny × nz` cells, `pos` mapping grid points, each cell split into the 6
/// Kuhn tets, reflected in x (y) for cells whose centre has `x < 0` (`y < 0`) when
/// `mirror`; orientation fixed by the mapped volume.
fn grid_mesh(
    nx: usize,
    ny: usize,
    nz: usize,
    mirror: bool,
    pos: impl Fn(usize, usize, usize) -> [f64; 3],
) -> TetMesh {
    let id = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as u32;
    let mut verts = Vec::new();
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                verts.push(pos(i, j, k));
            }
        }
    }
    let perms = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut tets = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let fx = mirror && 2 * i + 1 < nx;
                let fy = mirror && 2 * j + 1 < ny;
                for p in perms {
                    let mut c = [0usize; 3];
                    let mut tet = [0u32; 4];
                    for s in 0..4 {
                        if s > 0 {
                            c[p[s - 1]] = 1;
                        }
                        let a = if fx { 1 - c[0] } else { c[0] };
                        let b = if fy { 1 - c[1] } else { c[1] };
                        tet[s] = id(i + a, j + b, k + c[2]);
                    }
                    let v = tet.map(|x| verts[x as usize]);
                    if tet_volume(v[0], v[1], v[2], v[3]) < 0.0 {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    let m = TetMesh { verts, tets };
    for t in 0..m.tets.len() {
        assert!(m.volume(t) > 0.0, "tet {t} not positive");
    }
    m
}

fn box_mesh(n: usize, size: [f64; 3]) -> TetMesh {
    grid_mesh(n, n, n, false, |i, j, k| {
        [
            size[0] * i as f64 / n as f64,
            size[1] * j as f64 / n as f64,
            size[2] * k as f64 / n as f64,
        ]
    })
}

/// A cylinder of radius 1 and height `h` around the z axis: the square prism
/// `[−1, 1]² × [0, h]` mapped by the elliptical square-to-disc map.
fn cylinder_mesh(n: usize, layers: usize, h: f64) -> TetMesh {
    grid_mesh(n, n, layers, true, |i, j, k| {
        let x = -1.0 + 2.0 * i as f64 / n as f64;
        let y = -1.0 + 2.0 * j as f64 / n as f64;
        [
            x * (1.0 - 0.5 * y * y).sqrt(),
            y * (1.0 - 0.5 * x * x).sqrt(),
            h * k as f64 / layers as f64,
        ]
    })
}

/// The closest cube rotation `P` with `b ≈ a P` (columns: axes), as a signed permutation
/// matrix `p[i][j]` (axis j of b ≈ Σᵢ p[i][j] axis i of a).
fn matching(a: &Frame, b: &Frame) -> [[i32; 3]; 3] {
    let mut p = [[0i32; 3]; 3];
    let mut used = [false; 3];
    for j in 0..3 {
        let (mut bi, mut bv) = (0, -1.0);
        for i in 0..3 {
            let v = dot(a[i], b[j]).abs();
            if !used[i] && v > bv {
                bi = i;
                bv = v;
            }
        }
        used[bi] = true;
        p[bi][j] = if dot(a[bi], b[j]) < 0.0 { -1 } else { 1 };
    }
    p
}

fn mat_mul(a: [[i32; 3]; 3], b: [[i32; 3]; 3]) -> [[i32; 3]; 3] {
    let mut c = [[0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                c[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    c
}

/// Interior edges whose matching rotations around their tet star do not compose to the
/// identity, as (edge `p < q`, class): the star is walked counter-clockwise about `q − p`
/// and the holonomy `H = P₀₁ P₁₂ ⋯` (the continuously carried frame comes back as
/// `F₀ Hᵀ`) classified as index `+1` (`Hᵀ` turns +90° about the edge: a valence-3 line),
/// `-1` (−90°: valence 5), `2` (180° about the edge) or `0` (anything else).
fn singular_edges(m: &TetMesh, nb: &[[u32; 4]], frames: &[Frame]) -> Vec<([u32; 2], i32)> {
    let identity = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for t0 in 0..m.tets.len() {
        for a in 0..4 {
            for b in a + 1..4 {
                let (va, vb) = (m.tets[t0][a], m.tets[t0][b]);
                let key = [va.min(vb), va.max(vb)];
                if !seen.insert(key) {
                    continue;
                }
                let [p, q] = key.map(|v| m.verts[v as usize]);
                let e = sub(q, p);
                let mut others: Vec<usize> = (0..4).filter(|&i| i != a && i != b).collect();
                let (c, d) = (
                    m.verts[m.tets[t0][others[0]] as usize],
                    m.verts[m.tets[t0][others[1]] as usize],
                );
                if dot(e, cross(sub(c, p), sub(d, p))) < 0.0 {
                    others.swap(0, 1);
                }
                // Leave t through the face opposite `back` (it holds the edge and `front`).
                let mut t = t0;
                let mut back = others[0];
                let mut hol = identity;
                let mut interior = true;
                loop {
                    let u = nb[t][back];
                    if u == NO_TET {
                        interior = false;
                        break;
                    }
                    let u = u as usize;
                    hol = mat_mul(hol, matching(&frames[t], &frames[u]));
                    let front = (0..4)
                        .map(|i| m.tets[t][i])
                        .find(|&v| v != va && v != vb && v != m.tets[t][back])
                        .unwrap();
                    back = (0..4).find(|&i| m.tets[u][i] == front).unwrap();
                    t = u;
                    if t == t0 {
                        break;
                    }
                }
                if !interior || hol == identity {
                    continue;
                }
                let tr = hol[0][0] + hol[1][1] + hol[2][2];
                // sin θ · axis of H in t0's frame, then in space.
                let v = [
                    (hol[2][1] - hol[1][2]) as f64 / 2.0,
                    (hol[0][2] - hol[2][0]) as f64 / 2.0,
                    (hol[1][0] - hol[0][1]) as f64 / 2.0,
                ];
                let f = &frames[t0];
                let w = add(add(scale(f[0], v[0]), scale(f[1], v[1])), scale(f[2], v[2]));
                let along = dot(w, e) / norm(e);
                let class = if tr == 1 && along < -0.7 {
                    1
                } else if tr == 1 && along > 0.7 {
                    -1
                } else if tr == -1 {
                    2
                } else {
                    0
                };
                out.push((key, class));
            }
        }
    }
    out
}

fn angle_to_identity(f: &Frame) -> f64 {
    // Smallest rotation angle from the identity up to cube symmetry.
    let mut best = f64::MAX;
    for r in cube_rotations() {
        let g = rotate_frame(f, &r);
        let tr = g[0][0] + g[1][1] + g[2][2];
        best = best.min(((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos());
    }
    best
}

#[test]
fn a_box_gets_the_constant_axis_aligned_field() {
    let m = box_mesh(5, [1.0, 1.5, 0.8]);
    let nb = tet_neighbours(&m).unwrap();
    let (frames, rep) = smooth_frames(&m, &nb, &SmoothParams::default()).unwrap();
    eprintln!("box: {rep:?}");
    for f in &frames {
        assert!(angle_to_identity(f) < 1e-3, "{f:?}");
    }
    assert!(rep.boundary_misalignment_max_deg < 1e-6);
    assert!(rep.energy_final < 1e-10);
    assert!(singular_edges(&m, &nb, &frames).is_empty());
}

#[test]
fn a_rotated_box_gets_the_rotated_field() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let r = random_frame(&mut rng);
    let mut m = box_mesh(4, [1.0, 1.0, 1.0]);
    for v in m.verts.iter_mut() {
        *v = add(add(scale(r[0], v[0]), scale(r[1], v[1])), scale(r[2], v[2]));
    }
    let nb = tet_neighbours(&m).unwrap();
    let (frames, rep) = smooth_frames(&m, &nb, &SmoothParams::default()).unwrap();
    for f in &frames {
        assert!(frame_distance(f, &r) < 1e-6);
    }
    assert!(rep.boundary_misalignment_max_deg < 1e-5);
}

#[test]
fn a_cylinder_gets_a_boundary_aligned_field_turning_about_its_axis() {
    let m = cylinder_mesh(8, 8, 2.0);
    let nb = tet_neighbours(&m).unwrap();
    let t = std::time::Instant::now();
    let (frames, rep) = smooth_frames(&m, &nb, &SmoothParams::default()).unwrap();
    eprintln!(
        "cylinder: {} tets, {:.3} s, {rep:?}",
        m.tets.len(),
        t.elapsed().as_secs_f64()
    );
    assert!(rep.boundary_misalignment_max_deg < 5.0, "{rep:?}");
    assert!(rep.energy_final <= rep.energy_initial);
    // The field turns with the angle: tets near the side at angle φ have an axis close to
    // the radial direction (cos φ, sin φ, 0), and an axis along z in the middle.
    let mut worst_radial: f64 = 0.0;
    for (t, f) in frames.iter().enumerate() {
        let c = m.corners(t);
        let p = scale(add(add(c[0], c[1]), add(c[2], c[3])), 0.25);
        let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
        if r > 0.8 && p[2] > 0.5 && p[2] < 1.5 {
            let radial = [p[0] / r, p[1] / r, 0.0];
            let best = f.iter().map(|a| dot(*a, radial).abs()).fold(0.0, f64::max);
            worst_radial = worst_radial.max(best.min(1.0).acos().to_degrees());
        }
    }
    eprintln!("cylinder: worst radial deviation near the side {worst_radial:.2}°");
    assert!(worst_radial < 15.0);
    let sing = singular_edges(&m, &nb, &frames);
    let mut by_class = std::collections::BTreeMap::new();
    for (key, class) in &sing {
        let e = sub(m.verts[key[1] as usize], m.verts[key[0] as usize]);
        let dir = if e[2].abs() > 0.9 * norm(e) {
            "along z"
        } else {
            "other"
        };
        *by_class.entry((*class, dir)).or_insert(0) += 1;
    }
    eprintln!(
        "cylinder: {} singular edges (class, direction): {by_class:?}",
        sing.len()
    );
}

#[test]
fn frames_do_not_depend_on_the_thread_count() {
    let m = cylinder_mesh(6, 4, 1.0);
    let nb = tet_neighbours(&m).unwrap();
    let run = |k: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap()
            .install(|| smooth_frames(&m, &nb, &SmoothParams::default()).unwrap())
    };
    let (a, ra) = run(1);
    let (b, rb) = run(2);
    assert_eq!(a, b);
    assert_eq!(ra, rb);
}

#[test]
fn bad_inputs_are_errors() {
    let m = box_mesh(1, [1.0; 3]);
    let nb = tet_neighbours(&m).unwrap();
    assert_eq!(
        smooth_frames(&m, &nb[1..], &SmoothParams::default()).unwrap_err(),
        SmoothError::NeighbourCount { got: 5, tets: 6 }
    );
    let mut flipped = m.clone();
    flipped.tets[2].swap(0, 1);
    assert_eq!(
        smooth_frames(&flipped, &nb, &SmoothParams::default()).unwrap_err(),
        SmoothError::BadTet(2)
    );
    let empty = TetMesh::default();
    let (f, _) = smooth_frames(&empty, &[], &SmoothParams::default()).unwrap();
    assert!(f.is_empty());
}

#[test]
#[ignore]
fn tune_experiment() {
    let m = cylinder_mesh(12, 12, 2.0);
    let nb = tet_neighbours(&m).unwrap();
    for (mu, its, sw) in [
        (0.05, 0, 0),
        (0.05, 10, 0),
        (0.01, 10, 0),
        (0.2, 10, 0),
        (1.0, 10, 0),
        (0.05, 0, 8),
        (0.05, 0, 30),
        (0.05, 10, 30),
        (0.05, 0, 100),
    ] {
        let p = SmoothParams {
            proximal_weight: mu,
            iterations: its,
            local_sweeps: sw,
            ..SmoothParams::default()
        };
        let t = std::time::Instant::now();
        let (f, rep) = smooth_frames(&m, &nb, &p).unwrap();
        let sing = singular_edges(&m, &nb, &f);
        eprintln!(
            "mu {mu} its {its} sweeps {sw}: E {:.4} -> {:.4}, kept {}, sing {} ({:?}), {:.2}s",
            rep.energy_initial,
            rep.energy_final,
            rep.iterations_run,
            sing.len(),
            sing.iter().map(|s| s.1).sum::<i32>(),
            t.elapsed().as_secs_f64()
        );
    }
}

#[test]
#[ignore = "timing: cargo test --release --lib hex::smooth_frames -- --ignored --nocapture"]
fn timing_per_ten_thousand_tets() {
    for n in [12, 20, 28] {
        let m = cylinder_mesh(n, n, 2.0);
        let nb = tet_neighbours(&m).unwrap();
        let t = std::time::Instant::now();
        let (_, rep) = smooth_frames(&m, &nb, &SmoothParams::default()).unwrap();
        let s = t.elapsed().as_secs_f64();
        eprintln!(
            "{} tets: {:.3} s ({:.3} s per 10K), factor nnz/tet {:.1}, {rep:?}",
            m.tets.len(),
            s,
            s * 1e4 / m.tets.len() as f64,
            rep.factor_nonzeros as f64 / m.tets.len() as f64
        );
    }
}
