use super::*;
use crate::frames::{constant_frames, matchings, singularities};
use crate::rotation::all;
use crate::topology::check_tets;

fn run(mesh: &TetMesh, frames: &[Frame], scale: f64) -> (GridMap, ParamReport) {
    let topo = check_tets(mesh).unwrap();
    let m = matchings(frames, &topo);
    let sing = singularities(mesh, &topo, frames, &m);
    assert!(sing.invalid.is_empty(), "{:?}", sing.invalid);
    parameterise(
        mesh,
        &topo,
        frames,
        &m,
        &sing.edges,
        &ParamParams {
            scale,
            ..ParamParams::default()
        },
    )
    .unwrap()
}

/// Every corner's parameters minus its position / scale is one constant vector.
fn is_scaled_identity(mesh: &TetMesh, map: &GridMap, scale: f64) {
    let t0 = mesh.tets[0][0] as usize;
    let off = sub(map.uvw[0][0], mesh.verts[t0].map(|x| x / scale));
    for (t, tet) in mesh.tets.iter().enumerate() {
        for j in 0..4 {
            let want = mesh.verts[tet[j] as usize].map(|x| x / scale);
            for r in 0..3 {
                assert!(
                    (map.uvw[t][j][r] - want[r] - off[r]).abs() < 1e-8,
                    "tet {t} corner {j}: {:?} vs {:?}",
                    map.uvw[t][j],
                    want
                );
            }
        }
    }
    for r in 0..3 {
        assert!((off[r] - off[r].round()).abs() < 1e-8, "{off:?}");
    }
}

#[test]
fn a_box_with_constant_frames_maps_to_the_scaled_grid() {
    let mesh = TetMesh::grid_box([3, 2, 2], 0.5);
    let frames = constant_frames(mesh.tets.len());
    let (map, rep) = run(&mesh, &frames, 0.5);
    assert_eq!(rep.cut_faces, 0, "{rep:?}");
    assert_eq!(rep.flipped_final, 0);
    assert!(rep.energy_final < 1e-16, "{rep:?}");
    is_scaled_identity(&mesh, &map, 0.5);
    assert!(
        map.transitions
            .iter()
            .flatten()
            .all(|t| *t == Transition::ID)
    );
}

#[test]
fn frames_permuted_per_tet_glue_back_to_one_chart() {
    // The same field written with a random cube rotation per tetrahedron: the matchings
    // are not the identity, their holonomies are, and the cut glues shut.
    let mesh = TetMesh::grid_box([2, 2, 2], 1.0);
    let rots: Vec<Rot> = all().collect();
    let mut seed = 12345u64;
    let frames: Vec<Frame> = (0..mesh.tets.len())
        .map(|_| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = rots[(seed >> 33) as usize % 24].matrix();
            [0, 1, 2].map(|a| [0, 1, 2].map(|x| f64::from(r[a][x])))
        })
        .collect();
    let (map, rep) = run(&mesh, &frames, 0.5);
    assert_eq!(rep.cut_faces, 0, "{rep:?}");
    assert_eq!(rep.flipped_final, 0);
    assert!(rep.energy_final < 1e-16, "{rep:?}");
    // Each chart is a cube rotation of the global one: volumes are preserved.
    for t in 0..mesh.tets.len() {
        let v = param_volume(&map.uvw[t]);
        assert!((v - mesh.volume(t) * 8.0).abs() < 1e-7, "{v}");
    }
}

#[test]
fn a_sheared_box_rounds_its_planes_to_integers() {
    // A box of 2.3 × 1.6 × 1.2 at scale 0.5: the planes land on integers (5, 3, 2 cells).
    let mut mesh = TetMesh::grid_box([4, 3, 2], 1.0);
    for p in &mut mesh.verts {
        *p = [p[0] * 2.3 / 4.0, p[1] * 1.6 / 3.0, p[2] * 0.6];
    }
    let frames = constant_frames(mesh.tets.len());
    let (map, rep) = run(&mesh, &frames, 0.5);
    assert_eq!(rep.flipped_final, 0);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for c in map.uvw.iter().flatten() {
        for r in 0..3 {
            lo[r] = lo[r].min(c[r]);
            hi[r] = hi[r].max(c[r]);
        }
    }
    let cells: Vec<f64> = (0..3).map(|r| hi[r] - lo[r]).collect();
    for r in 0..3 {
        assert!((cells[r] - cells[r].round()).abs() < 1e-8, "{cells:?}");
    }
    assert_eq!(
        cells.iter().map(|c| c.round() as i64).collect::<Vec<_>>(),
        [5, 3, 2]
    );
    assert!(rep.rounds >= 1 && rep.integer_unknowns >= 3, "{rep:?}");
}

#[test]
fn rounding_on_one_factorisation_matches_refactoring_after_each_unknown() {
    // A warped bar with constant frames: its boundary planes are integer unknowns that
    // do not sit on integers. Rounding them one at a time on one factorisation (the
    // Schur complement of the fixed unknowns) must give the paper's greedy rounding with
    // a factorisation after each unknown: the same integers, the same map.
    let mut mesh = TetMesh::grid_box([6, 4, 3], 1.0);
    for p in &mut mesh.verts {
        let [x, y, z] = *p;
        *p = [
            x + 0.15 * (2.0 * y).sin(),
            y + 0.1 * (1.5 * z).sin(),
            z + 0.1 * (1.7 * x).sin(),
        ];
    }
    let frames = constant_frames(mesh.tets.len());
    let topo = check_tets(&mesh).unwrap();
    let m = matchings(&frames, &topo);
    let sing = singularities(&mesh, &topo, &frames, &m);
    let solve = |one_at_a_time: usize| {
        let params = ParamParams {
            scale: 0.37,
            batch: 0.0,
            one_at_a_time,
            ..ParamParams::default()
        };
        parameterise(&mesh, &topo, &frames, &m, &sing.edges, &params).unwrap()
    };
    let (fast, rf) = solve(128);
    let (slow, rs) = solve(0);
    assert!(rf.integer_unknowns >= 3, "{rf:?}");
    assert_eq!(rf.redirected, 0, "{rf:?}");
    assert_eq!(rf.rounds, rs.rounds, "{rf:?} {rs:?}");
    assert_eq!(rf.flipped_final, rs.flipped_final);
    assert!((rf.energy_final - rs.energy_final).abs() < 1e-9 * rs.energy_final.max(1.0));
    for (a, b) in fast.uvw.iter().flatten().zip(slow.uvw.iter().flatten()) {
        for r in 0..3 {
            assert!((a[r] - b[r]).abs() < 1e-7, "{a:?} {b:?}");
        }
    }
    assert_eq!(fast.transitions, slow.transitions);
}
