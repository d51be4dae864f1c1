use super::chart::{context, half};
use super::fixtures::*;
use super::walk::WalkEnd;
use super::*;
use crate::mesh::{NO_TET, tet_neighbours};
use crate::quality::hex_scaled_jacobian;
use crate::rotation::Rot;
use rand::{Rng, SeedableRng};

fn hex_corners(h: &HexMesh, k: usize) -> [[f64; 3]; 8] {
    h.hexes[k].map(|v| h.verts[v as usize])
}

/// Each hexahedron as its sorted corner positions (rounded), the list sorted.
fn canonical(h: &HexMesh) -> Vec<Vec<[i64; 3]>> {
    let mut out: Vec<Vec<[i64; 3]>> = (0..h.hexes.len())
        .map(|k| {
            let mut c: Vec<[i64; 3]> = hex_corners(h, k)
                .iter()
                .map(|p| p.map(|x| (x * 1e6).round() as i64))
                .collect();
            c.sort_unstable();
            c
        })
        .collect();
    out.sort_unstable();
    out
}

#[test]
fn identity_map_of_a_box_gives_the_grid() {
    for (n, k) in [(2usize, 2.0f64), (3, 1.0), (2, 1.5)] {
        let mesh = box_tets(n, 1.0);
        let map = map_of(&mesh, |x| x.map(|c| k * c));
        let (hex, rep) = extract(&mesh, &map).unwrap();
        let cells = (k * n as f64).round() as usize;
        // Walks through the cube diagonals (tet edges) and tet vertices need no retry.
        assert_eq!(rep.retried_walks, 0);
        assert_eq!(hex.hexes.len(), cells.pow(3), "n {n} k {k}: {rep:?}");
        assert_eq!(hex.verts.len(), (cells + 1).pow(3));
        assert_eq!(rep.grid_vertices, (cells + 1).pow(3));
        assert_eq!(rep.cube_centres, cells.pow(3));
        assert_eq!(
            (rep.partial_cubes, rep.failed_walks, rep.collapsed_cubes),
            (0, 0, 0)
        );
        assert_eq!((rep.duplicate_cubes, rep.unmatched_face_points), (0, 0));
        for h in 0..hex.hexes.len() {
            let c = hex_corners(&hex, h);
            assert!((hex_scaled_jacobian(&c) - 1.0).abs() < 1e-9);
            // Corner 0 is the cube's lowest corner, corner 6 its highest.
            let side = 1.0 / k;
            for a in 0..3 {
                assert!((c[6][a] - c[0][a] - side).abs() < 1e-9);
            }
        }
        for p in &hex.verts {
            for &x in p {
                let g = x * k;
                assert!((g - g.round()).abs() < 1e-9, "vertex {p:?} off the grid");
            }
        }
    }
}

#[test]
fn randomly_rotated_and_shifted_charts_give_the_same_mesh() {
    let mesh = box_tets(2, 1.0);
    let k = 2.0;
    let reference = extract(&mesh, &map_of(&mesh, |x| x.map(|c| k * c))).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
    let uvw: Vec<[[f64; 3]; 4]> = (0..mesh.tets.len())
        .map(|t| {
            let r = Rot(rng.random_range(0..24u8));
            let s = [0; 3].map(|_: i32| f64::from(rng.random_range(-5..=5i32)));
            mesh.corners(t).map(|x| {
                let y = r.apply(x.map(|c| k * c));
                [y[0] + s[0], y[1] + s[1], y[2] + s[2]]
            })
        })
        .collect();
    let map = with_transitions(&mesh, uvw);
    assert!(map.transitions.iter().flatten().any(|t| t.rot != Rot::ID));
    let (hex, rep) = extract(&mesh, &map).unwrap();
    assert_eq!(rep.hexes, 64);
    assert_eq!(rep.failed_walks, 0);
    assert_eq!(canonical(&hex), canonical(&reference.0));
    for h in 0..hex.hexes.len() {
        assert!((hex_scaled_jacobian(&hex_corners(&hex, h)) - 1.0).abs() < 1e-9);
    }
}

#[test]
fn sheared_map_keeps_the_cubes_inside_and_reports_the_cut_ones() {
    let n = 2;
    let mesh = box_tets(n, 1.0);
    let k = 2.5;
    let a = [[k, 0.31 * k, 0.17 * k], [0.0, k, 0.23 * k], [0.0, 0.0, k]];
    let apply = |x: [f64; 3]| [0, 1, 2].map(|r| (0..3).map(|c| a[r][c] * x[c]).sum::<f64>());
    // A⁻¹ of the upper-triangular A by back substitution.
    let inv = |y: [f64; 3]| {
        let z = y[2] / a[2][2];
        let yy = (y[1] - a[1][2] * z) / a[1][1];
        let x = (y[0] - a[0][1] * yy - a[0][2] * z) / a[0][0];
        [x, yy, z]
    };
    let inside = |y: [f64; 3]| {
        inv(y)
            .iter()
            .all(|&c| (-1e-9..=n as f64 + 1e-9).contains(&c))
    };
    let map = map_of(&mesh, apply);
    let (hex, rep) = extract(&mesh, &map).unwrap();
    // Brute force over the image's bounding box.
    let hi = apply([n as f64; 3]).map(|c| c.ceil() as i64 + 1);
    let (mut full, mut centred) = (0, 0);
    for i in -1..hi[0] {
        for j in -1..hi[1] {
            for l in -1..hi[2] {
                let o = [i, j, l].map(|c| c as f64);
                if !inside([o[0] + 0.5, o[1] + 0.5, o[2] + 0.5]) {
                    continue;
                }
                centred += 1;
                if CUBE_CORNERS
                    .iter()
                    .all(|c| inside([0, 1, 2].map(|d| o[d] + 0.5 + 0.5 * c[d] as f64)))
                {
                    full += 1;
                }
            }
        }
    }
    assert!(full > 0 && centred > full);
    assert_eq!(rep.hexes, full, "{rep:?}");
    assert_eq!(rep.cube_centres, centred);
    assert_eq!(rep.partial_cubes, centred - full);
    assert_eq!(rep.failed_walks, 0);
    // Every hex is the image of a unit cube: its vertices map to integer points and its
    // scaled Jacobian is that of A⁻¹'s parallelepiped.
    let sj0 = hex_scaled_jacobian(&hex_corners(&hex, 0));
    for h in 0..hex.hexes.len() {
        let c = hex_corners(&hex, h);
        assert!((hex_scaled_jacobian(&c) - sj0).abs() < 1e-9);
        for p in c {
            let q = apply(p);
            assert!(q.iter().all(|x| (x - x.round()).abs() < 1e-9));
        }
    }
    assert!(sj0 > 0.5 && sj0 < 1.0);
}

#[test]
fn singular_edges_of_valence_three_and_five_are_surrounded_by_as_many_hexes() {
    for (sides, m, layers) in [(3usize, 2.0, 2usize), (5, 2.0, 1), (4, 3.0, 1), (3, 1.0, 3)] {
        singular_prism_case(sides, m, layers);
    }
}

fn singular_prism_case(sides: usize, m: f64, layers: usize) {
    let (mesh, map) = singular_prism(sides, m, layers);
    crate::topology::check_tets(&mesh).unwrap();
    // The transitions across the quadrilaterals' shared edges are quarter turns about w.
    let turns = map
        .transitions
        .iter()
        .flatten()
        .filter(|t| t.rot.axis_turn().is_some_and(|(a, q)| a == 2 && q != 2))
        .count();
    assert!(turns > 0);
    let (hex, rep) = extract(&mesh, &map).unwrap();
    let mi = m as usize;
    let w = mi * layers;
    assert_eq!(rep.hexes, sides * mi * mi * w, "{sides}: {rep:?}");
    assert_eq!(rep.vertices, (sides * mi * mi + sides * mi + 1) * (w + 1));
    assert_eq!((rep.partial_cubes, rep.failed_walks), (0, 0));
    for h in 0..hex.hexes.len() {
        assert!(hex_scaled_jacobian(&hex_corners(&hex, h)) > 0.2);
    }
    // Along the axis, each hex edge has `sides` hexes around it.
    let axis: Vec<u32> = (0..hex.verts.len() as u32)
        .filter(|&v| {
            let p = hex.verts[v as usize];
            p[0].abs() < 1e-9 && p[1].abs() < 1e-9
        })
        .collect();
    assert_eq!(axis.len(), w + 1);
    for pair in axis.windows(2) {
        let around = hex
            .hexes
            .iter()
            .filter(|h| h.contains(&pair[0]) && h.contains(&pair[1]))
            .count();
        assert_eq!(around, sides);
    }
}

#[test]
fn a_flipped_tet_on_a_walk_is_a_named_error() {
    let mesh = box_tets(2, 1.0);
    let k = 2.0;
    let centre = 13; // vertex (1, 1, 1)
    assert_eq!(mesh.verts[centre], [1.0, 1.0, 1.0]);
    let uvw: Vec<[[f64; 3]; 4]> = (0..mesh.tets.len())
        .map(|t| {
            let mut c = mesh.corners(t).map(|x| x.map(|c| k * c));
            for (j, &v) in mesh.tets[t].iter().enumerate() {
                if v as usize == centre {
                    c[j] = [2.0 + 1.7, 2.0 + 0.1, 2.0 - 0.3];
                }
            }
            c
        })
        .collect();
    let map = with_transitions(&mesh, uvw);
    match extract(&mesh, &map) {
        Err(ExtractError::InvalidTetCrossed {
            tet, param_volume, ..
        }) => {
            assert!(param_volume <= 0.0);
            assert!(mesh.tets[tet].contains(&(centre as u32)));
        }
        other => panic!("expected a flipped tet, got {other:?}"),
    }
    // The flipped tets are those around the moved vertex on its +u side.
    let ctx = context(&mesh, &map).unwrap();
    assert!(ctx.charts.iter().any(|c| !c.valid));
}

#[test]
fn bad_input_is_named() {
    let mesh = box_tets(1, 1.0);
    let mut map = map_of(&mesh, |x| x);
    map.uvw.pop();
    assert!(matches!(
        extract(&mesh, &map),
        Err(ExtractError::SizeMismatch { .. })
    ));
    let mut map = map_of(&mesh, |x| x);
    let nb = tet_neighbours(&mesh).unwrap();
    let (t, i) = (0..mesh.tets.len())
        .flat_map(|t| (0..4).map(move |i| (t, i)))
        .find(|&(t, i)| nb[t][i] != NO_TET)
        .unwrap();
    map.transitions[t][i].shift = [1, 0, 0];
    assert!(matches!(
        extract(&mesh, &map),
        Err(ExtractError::InconsistentTransition { tet, face, .. }) if tet == t && face == i
    ));
    let mut map = map_of(&mesh, |x| x);
    map.uvw[3][1][2] = f64::NAN;
    assert_eq!(
        extract(&mesh, &map),
        Err(ExtractError::NonFiniteParam { tet: 3 })
    );
}

#[test]
fn irregular_tets_with_rotated_charts_give_the_exact_grid() {
    let n = 3;
    let mut mesh = box_tets(n, 1.0);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    for p in mesh.verts.iter_mut() {
        if p.iter().all(|&c| c > 0.0 && c < n as f64) {
            for c in p.iter_mut() {
                *c += rng.random_range(-0.2..0.2);
            }
        }
    }
    assert!((0..mesh.tets.len()).all(|t| mesh.volume(t) > 0.0));
    for (k, cells) in [(5.0 / 3.0, 5usize), (1.0, 3), (2.0, 6)] {
        let uvw: Vec<[[f64; 3]; 4]> = (0..mesh.tets.len())
            .map(|t| {
                let r = Rot(rng.random_range(0..24u8));
                let s = [0; 3].map(|_: i32| f64::from(rng.random_range(-3..=3i32)));
                mesh.corners(t).map(|x| {
                    let y = r.apply(x.map(|c| k * c));
                    [y[0] + s[0], y[1] + s[1], y[2] + s[2]]
                })
            })
            .collect();
        let map = with_transitions(&mesh, uvw);
        let (hex, rep) = extract(&mesh, &map).unwrap();
        assert_eq!(rep.retried_walks, 0);
        assert_eq!(rep.hexes, cells.pow(3), "k {k}: {rep:?}");
        assert_eq!((rep.failed_walks, rep.partial_cubes), (0, 0), "{rep:?}");
        for h in 0..hex.hexes.len() {
            let c = hex_corners(&hex, h);
            assert!((hex_scaled_jacobian(&c) - 1.0).abs() < 1e-6);
            assert!(
                c.iter()
                    .flatten()
                    .all(|x| (x * k - (x * k).round()).abs() < 1e-6)
            );
        }
    }
}

#[test]
fn a_two_leg_walk_reaches_the_same_vertex() {
    let mesh = box_tets(2, 1.0);
    let map = map_of(&mesh, |x| [1.5 * x[1], -1.5 * x[0], 1.5 * x[2]]);
    let ctx = context(&mesh, &map).unwrap();
    let verts = ctx.classes(0).unwrap();
    let centres = ctx.classes(1).unwrap();
    let mut checked = 0;
    for &k in &centres.rep {
        let k = k as usize;
        let (t, c) = (centres.tet[k] as usize, centres.pts[k]);
        for off in CUBE_CORNERS {
            let target = [0, 1, 2].map(|j| c[j] + off[j]);
            let mut steps = 0;
            let direct = ctx.walk(t, half(c), half(target), Some(target), None, &mut steps);
            let m = [0, 1, 2].map(|j| half(c)[j] + 0.3 * off[j] as f64);
            let WalkEnd::Arrived {
                t: t1,
                p: m1,
                carry: Some(tg),
                ..
            } = ctx.walk(t, half(c), m, None, Some(target), &mut steps)
            else {
                continue;
            };
            let legs = ctx.walk(t1, m1, half(tg), Some(tg), None, &mut steps);
            let vertex = |e: WalkEnd| match e {
                WalkEnd::Arrived {
                    t, target: Some(d), ..
                } => verts.find(t, d).map(|j| verts.class_of[j]),
                _ => None,
            };
            if let Some(v) = vertex(direct) {
                assert_eq!(vertex(legs), Some(v));
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 27 * 8);
}

#[test]
fn output_is_the_same_for_any_thread_count() {
    let mesh = box_tets(2, 1.0);
    let map = map_of(&mesh, |x| {
        [2.2 * x[0] + 0.3 * x[1], 2.2 * x[1], 2.2 * x[2] + 0.1 * x[0]]
    });
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| extract(&mesh, &map).unwrap());
    let many = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap()
        .install(|| extract(&mesh, &map).unwrap());
    assert_eq!(one, many);
    assert!(one.1.hexes > 0);
}
