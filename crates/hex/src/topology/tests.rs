use super::stars::local;
use super::*;
use crate::mesh::{NO_TET, tet_volume};
use std::collections::HashMap;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Test helper (not the validator): swaps the last two vertices of negative tets.
fn orient(m: &mut TetMesh) {
    for t in 0..m.tets.len() {
        if m.volume(t) < 0.0 {
            m.tets[t].swap(2, 3);
        }
    }
}

/// Unit cubes at integer positions, each split into 6 tets around its (0,0,0)-(1,1,1)
/// diagonal (Kuhn), which is conforming between neighbours. Vertices shared.
fn voxels(cells: &[[i32; 3]]) -> TetMesh {
    let mut m = TetMesh::default();
    let mut ids: HashMap<[i32; 3], u32> = HashMap::new();
    let mut vid = |p: [i32; 3], m: &mut TetMesh| {
        *ids.entry(p).or_insert_with(|| {
            m.verts.push(p.map(f64::from));
            m.verts.len() as u32 - 1
        })
    };
    for &c in cells {
        for perm in [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ] {
            let mut p = c;
            let mut tet = [vid(p, &mut m), 0, 0, 0];
            for (s, &ax) in perm.iter().enumerate() {
                p[ax] += 1;
                tet[s + 1] = vid(p, &mut m);
            }
            m.tets.push(tet);
        }
    }
    orient(&mut m);
    m
}

const CUBE: [[f64; 3]; 8] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [1.0, 0.0, 1.0],
    [1.0, 1.0, 1.0],
    [0.0, 1.0, 1.0],
];

fn cube5() -> TetMesh {
    let mut m = TetMesh {
        verts: CUBE.to_vec(),
        tets: vec![
            [0, 1, 3, 4],
            [2, 3, 1, 6],
            [5, 4, 6, 1],
            [7, 6, 4, 3],
            [1, 3, 4, 6],
        ],
    };
    orient(&mut m);
    m
}

/// Edge `0 → 1` along +z (or −z when `flip`) surrounded by `n` tets over a ring of `n`
/// points at angles `2πk/n`, counter-clockwise seen from +z; `open` leaves out the last
/// wedge (a boundary edge).
fn bipyramid(n: usize, flip: bool, open: bool) -> TetMesh {
    let z = if flip { -1.0 } else { 1.0 };
    let mut m = TetMesh {
        verts: vec![[0.0, 0.0, -z], [0.0, 0.0, z]],
        tets: vec![],
    };
    for k in 0..n {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        m.verts.push([a.cos(), a.sin(), 0.0]);
    }
    let wedges = if open { n - 1 } else { n };
    for k in 0..wedges {
        m.tets.push([0, 1, 2 + k as u32, 2 + ((k + 1) % n) as u32]);
    }
    orient(&mut m);
    m
}

/// Checks every star against the geometry: consecutive tets share the face `(a, b,
/// d_k = c_{k+1})`, each wedge turns positively about `a → b`, boundary chains end on
/// boundary faces, and a cycle's wedges add up to one full turn.
fn assert_stars(m: &TetMesh, topo: &Topology) {
    assert_eq!(topo.star_offsets.len(), topo.edges.len() + 1);
    assert_eq!(topo.star_tets.len(), 6 * m.tets.len());
    for e in 0..topo.num_edges() {
        let [a, b] = topo.edges[e];
        assert!(a < b);
        let (pa, pb) = (m.verts[a as usize], m.verts[b as usize]);
        let ax = sub(pb, pa);
        let axn = ax.map(|x| x / dot(ax, ax).sqrt());
        let star = topo.star(e);
        let mut turn = 0.0;
        for k in 0..star.len() {
            let t = star[k] as usize;
            assert!(topo.tet_edges[t].contains(&(e as u32)));
            let [c, d] = topo.star_wedge(m, e, k);
            assert!(tet_volume(pa, pb, m.verts[c as usize], m.verts[d as usize]) > 0.0);
            let pc = sub(m.verts[c as usize], pa);
            let pd = sub(m.verts[d as usize], pa);
            let pc = sub(pc, axn.map(|x| x * dot(pc, axn)));
            let pd = sub(pd, axn.map(|x| x * dot(pd, axn)));
            let ang = dot(cross(pc, pd), axn).atan2(dot(pc, pd));
            assert!(ang > 0.0, "edge {e} tet {t}: wedge turns {ang}");
            turn += ang;
            let next = k + 1 < star.len();
            if next {
                assert_eq!(topo.star_wedge(m, e, k + 1)[0], d);
                let tet = m.tets[t];
                assert_eq!(topo.neighbours[t][local(&tet, c)], star[k + 1]);
            }
        }
        let (t0, tl) = (star[0] as usize, *star.last().unwrap() as usize);
        // Leaving the last tet through (a, b, d_last), entering the first through (a, b, c_0).
        let last_out =
            topo.neighbours[tl][local(&m.tets[tl], topo.star_wedge(m, e, star.len() - 1)[0])];
        let first_in = topo.neighbours[t0][local(&m.tets[t0], topo.star_wedge(m, e, 0)[1])];
        if topo.edge_on_boundary[e] {
            assert_eq!(last_out, NO_TET);
            assert_eq!(first_in, NO_TET);
            assert!(turn < std::f64::consts::TAU);
            assert!(topo.vertex_on_boundary[a as usize] && topo.vertex_on_boundary[b as usize]);
        } else {
            assert_eq!(last_out, star[0]);
            assert_eq!(first_in, *star.last().unwrap());
            assert!(
                (turn - std::f64::consts::TAU).abs() < 1e-9,
                "edge {e}: turn {turn}"
            );
            assert_eq!(star[0], *star.iter().min().unwrap());
        }
    }
}

#[test]
fn cubes_split_into_five_and_six_tets_are_valid() {
    for m in [cube5(), voxels(&[[0, 0, 0]])] {
        let topo = check_tets(&m).unwrap();
        assert_eq!(topo.boundary.len(), 12);
        assert_eq!(topo.num_edges(), 18 + (m.tets.len() == 6) as usize);
        assert_eq!(topo.num_boundary_vertices(), 8);
        assert_eq!(topo.boundary_surfaces.len(), 1);
        assert_eq!(topo.boundary_euler_characteristic(), 2);
        assert_eq!(topo.boundary_genus(), 0);
        assert_eq!(topo.unused_vertices, 0);
        assert_stars(&m, &topo);
        // Outward boundary: the boundary triangles enclose the unit volume.
        let vol: f64 = topo
            .boundary_triangles(&m)
            .iter()
            .map(|t| {
                tet_volume(
                    [0.0; 3],
                    m.verts[t[0] as usize],
                    m.verts[t[1] as usize],
                    m.verts[t[2] as usize],
                )
            })
            .sum();
        assert!((vol - 1.0).abs() < 1e-12);
    }
    // The Kuhn cube's diagonal 0-6 is the one interior edge, with a star of 6.
    let m = voxels(&[[0, 0, 0]]);
    let topo = check_tets(&m).unwrap();
    let interior: Vec<usize> = (0..topo.num_edges())
        .filter(|&e| !topo.edge_on_boundary[e])
        .collect();
    assert_eq!(interior.len(), 1);
    assert_eq!(topo.star(interior[0]).len(), 6);
}

#[test]
fn inverted_tet_is_named_not_fixed() {
    let mut m = cube5();
    m.tets[3].swap(0, 1);
    let err = check_tets(&m).unwrap_err();
    assert!(matches!(err, TetError::Inverted { tet: 3, volume, .. } if volume < 0.0));
    let msg = err.to_string();
    assert!(
        msg.starts_with("tetrahedron 3 (vertices ")
            && msg.contains("is inverted: volume -1.667e-1"),
        "{msg}"
    );
}

#[test]
fn input_errors_are_named() {
    assert!(matches!(
        check_tets(&TetMesh::default()),
        Err(TetError::NoTetrahedra)
    ));
    let mut m = cube5();
    m.tets[2][3] = 8;
    let err = check_tets(&m).unwrap_err();
    assert!(matches!(
        err,
        TetError::VertexOutOfRange {
            tet: 2,
            vertex: 8,
            vertex_count: 8,
            ..
        }
    ));
    let mut m = cube5();
    m.verts[5][1] = f64::NAN;
    assert!(matches!(
        check_tets(&m),
        Err(TetError::NonFiniteVertex { vertex: 5, .. })
    ));
    let mut m = cube5();
    m.tets[1][2] = m.tets[1][0];
    let err = check_tets(&m).unwrap_err();
    assert!(
        matches!(err, TetError::RepeatedVertex { tet: 1, .. }),
        "{err}"
    );
    let mut m = cube5();
    m.verts.push([0.5, 0.5, 0.0]);
    m.tets.push([0, 1, 2, 8]);
    let err = check_tets(&m).unwrap_err();
    assert!(matches!(err, TetError::Degenerate { tet: 5, .. }), "{err}");
    assert!(err.to_string().contains("is degenerate: volume "), "{err}");
}

#[test]
fn duplicate_tets_are_non_manifold_or_overlapping() {
    // Two tets sharing a face, one duplicated: that face is in three tets.
    let mut m = bipyramid(3, false, true);
    m.tets.truncate(2);
    m.tets.push(m.tets[0]);
    let err = check_tets(&m).unwrap_err();
    match &err {
        TetError::NonManifoldFace { face, tets } => {
            assert_eq!(face, &[0, 1, 3]);
            assert_eq!(tets, &[0, 1, 2]);
        }
        e => panic!("{e}"),
    }
    assert!(
        err.to_string().contains("shared by 3 tetrahedra (0 1 2)"),
        "{err}"
    );
    // A lone tet twice: each face in two tets on the same side.
    let m = TetMesh {
        verts: CUBE[..5].to_vec(),
        tets: vec![[0, 1, 3, 4], [0, 1, 3, 4]],
    };
    assert!(matches!(
        check_tets(&m),
        Err(TetError::OverlappingTets { tets: [0, 1], .. })
    ));
}

#[test]
fn tets_sharing_only_an_edge_or_a_vertex_are_non_manifold() {
    let edge = voxels(&[[0, 0, 0], [1, 1, 0]]);
    let err = check_tets(&edge).unwrap_err();
    match &err {
        TetError::NonManifoldBoundaryEdge { triangles, .. } => assert_eq!(triangles.len(), 4),
        e => panic!("{e}"),
    }
    let vertex = voxels(&[[0, 0, 0], [1, 1, 1]]);
    let err = check_tets(&vertex).unwrap_err();
    assert!(
        matches!(err, TetError::NonManifoldVertex { fans: 2, .. }),
        "{err}"
    );
    // Two single tets: apex to apex.
    let m = TetMesh {
        verts: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, -1.0],
        ],
        tets: vec![[0, 1, 2, 3], [0, 4, 5, 6]],
    };
    let mut m2 = m.clone();
    orient(&mut m2);
    let err = check_tets(&m2).unwrap_err();
    assert!(
        matches!(err, TetError::NonManifoldVertex { vertex: 0, fans: 2 }),
        "{err}"
    );
    // Two tets on a common edge 0-1, on opposite sides.
    let mut m = TetMesh {
        verts: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, -1.0],
        ],
        tets: vec![[0, 1, 2, 3], [0, 1, 4, 5]],
    };
    orient(&mut m);
    let err = check_tets(&m).unwrap_err();
    assert!(
        matches!(&err, TetError::NonManifoldBoundaryEdge { edge: [0, 1], triangles } if triangles.len() == 4),
        "{err}"
    );
}

#[test]
fn disjoint_solids_are_an_error() {
    let m = voxels(&[[0, 0, 0], [3, 0, 0]]);
    let err = check_tets(&m).unwrap_err();
    assert!(
        matches!(
            err,
            TetError::Disconnected {
                components: 2,
                second: 6
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("2 connected components"));
}

#[test]
fn stars_turn_positively_about_their_edge() {
    for n in [3, 4, 5] {
        for flip in [false, true] {
            let m = bipyramid(n, flip, false);
            let topo = check_tets(&m).unwrap();
            assert_stars(&m, &topo);
            let e = topo.edge_id(0, 1).unwrap() as usize;
            assert!(!topo.edge_on_boundary[e]);
            // Seen from vertex 1 towards 0 the star turns counter-clockwise: with 0 → 1
            // along +z that is the ring's order, along −z the reverse.
            let star = topo.star(e).to_vec();
            let expect: Vec<u32> = if flip {
                std::iter::once(0).chain((1..n as u32).rev()).collect()
            } else {
                (0..n as u32).collect()
            };
            assert_eq!(star, expect, "n {n} flip {flip}");
            // And by geometry: the tets' centroids turn positively about 0 → 1.
            let axis = sub(m.verts[1], m.verts[0]);
            let ang = |t: u32| {
                let c = m.corners(t as usize);
                let g = [0, 1, 2].map(|k| c.iter().map(|p| p[k]).sum::<f64>() / 4.0);
                let s = if axis[2] > 0.0 { 1.0 } else { -1.0 };
                (s * g[1]).atan2(g[0])
            };
            for k in 0..n {
                let d = (ang(star[(k + 1) % n]) - ang(star[k])).rem_euclid(std::f64::consts::TAU);
                assert!((d - std::f64::consts::TAU / n as f64).abs() < 1e-9);
            }
            // The spokes to the ring are on the boundary with a star of 2, the ring's
            // edges with a star of 1.
            let spoke = topo.edge_id(0, 2).unwrap() as usize;
            assert!(topo.edge_on_boundary[spoke]);
            assert_eq!(topo.star(spoke).len(), 2);
            let ring = topo.edge_id(2, 3).unwrap() as usize;
            assert!(topo.edge_on_boundary[ring]);
            assert_eq!(topo.star(ring).len(), 1);
            assert_eq!(topo.boundary_genus(), 0);
        }
    }
}

#[test]
fn boundary_edge_star_is_a_chain_between_boundary_faces() {
    for flip in [false, true] {
        let m = bipyramid(5, flip, true);
        let topo = check_tets(&m).unwrap();
        assert_stars(&m, &topo);
        let e = topo.edge_id(0, 1).unwrap() as usize;
        assert!(topo.edge_on_boundary[e]);
        let expect: Vec<u32> = if flip {
            (0..4).rev().collect()
        } else {
            (0..4).collect()
        };
        assert_eq!(topo.star(e), &expect[..]);
        // The chain starts at the boundary face (0, 1, c) and ends at (0, 1, d).
        let [c, _] = topo.star_wedge(&m, e, 0);
        let [_, d] = topo.star_wedge(&m, e, 3);
        assert_eq!((c, d), if flip { (6, 2) } else { (2, 6) });
    }
}

#[test]
fn a_ring_of_cubes_has_genus_one() {
    let cells: Vec<[i32; 3]> = (0..3)
        .flat_map(|x| (0..3).map(move |y| [x, y, 0]))
        .filter(|c| c != &[1, 1, 0])
        .collect();
    let m = voxels(&cells);
    let topo = check_tets(&m).unwrap();
    assert_stars(&m, &topo);
    assert_eq!(topo.boundary_surfaces.len(), 1);
    assert_eq!(topo.boundary_euler_characteristic(), 0);
    assert_eq!(topo.boundary_genus(), 1);
    // Unused vertices are counted, not rejected.
    let mut m2 = m.clone();
    m2.verts.push([9.0, 9.0, 9.0]);
    assert_eq!(check_tets(&m2).unwrap().unused_vertices, 1);
}

/// MEDIT ascii, test-only: `Vertices`, `Tetrahedra`, skipping other sections.
fn read_medit(text: &str) -> TetMesh {
    let mut tok = text
        .lines()
        .map(|l| l.split('#').next().unwrap())
        .flat_map(str::split_whitespace);
    let mut m = TetMesh::default();
    while let Some(kw) = tok.next() {
        let mut count = || tok.next().unwrap().parse::<usize>().unwrap();
        match kw {
            "MeshVersionFormatted" | "Dimension" => {
                count();
            }
            "Vertices" => {
                let n = count();
                for _ in 0..n {
                    let v: Vec<f64> = (0..4)
                        .map(|_| tok.next().unwrap().parse().unwrap())
                        .collect();
                    m.verts.push([v[0], v[1], v[2]]);
                }
            }
            "Tetrahedra" => {
                let n = count();
                for _ in 0..n {
                    let v: Vec<u32> = (0..5)
                        .map(|_| tok.next().unwrap().parse().unwrap())
                        .collect();
                    m.tets.push([v[0] - 1, v[1] - 1, v[2] - 1, v[3] - 1]);
                }
            }
            "Triangles" | "Edges" => {
                let n = count();
                let per = if kw == "Triangles" { 4 } else { 3 };
                for _ in 0..n * per {
                    tok.next().unwrap();
                }
            }
            "End" => break,
            other => panic!("unexpected MEDIT keyword {other}"),
        }
    }
    m
}

#[test]
fn octopus_low_validates() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/tetmesh/octopus-low.mesh");
    let Ok(text) = std::fs::read_to_string(&path) else {
        eprintln!("skipping: {} absent", path.display());
        return;
    };
    let m = read_medit(&text);
    let topo = check_tets(&m).unwrap();
    assert_stars(&m, &topo);
    let interior = topo.edge_on_boundary.iter().filter(|&&b| !b).count();
    eprintln!(
        "octopus-low: {} vertices ({} unused, {} on the boundary), {} tets, {} edges \
         ({} interior), {} boundary triangles, {} boundary surfaces, chi {}, genus {}",
        m.verts.len(),
        topo.unused_vertices,
        topo.num_boundary_vertices(),
        m.tets.len(),
        topo.num_edges(),
        interior,
        topo.boundary.len(),
        topo.boundary_surfaces.len(),
        topo.boundary_euler_characteristic(),
        topo.boundary_genus()
    );
    // Euler's formula for the solid (a ball-like 3-manifold with boundary): V - E + F - T.
    let faces = (4 * m.tets.len() + topo.boundary.len()) / 2;
    let v = m.verts.len() - topo.unused_vertices;
    let chi = v as i64 - topo.num_edges() as i64 + faces as i64 - m.tets.len() as i64;
    assert_eq!(2 * chi, topo.boundary_euler_characteristic());
}
