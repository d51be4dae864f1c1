use super::*;

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

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn map(c: &[[f64; 3]; 8], f: impl FnMut([f64; 3]) -> [f64; 3]) -> [[f64; 3]; 8] {
    c.map(f)
}

/// Exact trilinear volume by 2×2×2 Gauss quadrature of det J on [0,1]³.
fn gauss_volume(c: &[[f64; 3]; 8]) -> f64 {
    let g = [0.5 - 0.5 / 3f64.sqrt(), 0.5 + 0.5 / 3f64.sqrt()];
    let mut vol = 0.0;
    for &u in &g {
        for &v in &g {
            for &w in &g {
                let mut j = [[0.0; 3]; 3];
                for (i, p) in c.iter().enumerate() {
                    let r = CUBE[i];
                    let f = |x: f64, on: f64| if on > 0.0 { x } else { 1.0 - x };
                    let s = |on: f64| if on > 0.0 { 1.0 } else { -1.0 };
                    let d = [
                        s(r[0]) * f(v, r[1]) * f(w, r[2]),
                        f(u, r[0]) * s(r[1]) * f(w, r[2]),
                        f(u, r[0]) * f(v, r[1]) * s(r[2]),
                    ];
                    for a in 0..3 {
                        for k in 0..3 {
                            j[a][k] += d[a] * p[k];
                        }
                    }
                }
                vol += det(j[0], j[1], j[2]) / 8.0;
            }
        }
    }
    vol
}

#[test]
fn unit_cube_is_perfect() {
    let q = hex_quality(&CUBE);
    assert_eq!(q.min_scaled_jacobian, 1.0);
    assert_eq!(hex_jacobians(&CUBE), [1.0; 9]);
    assert!(close(q.dihedral_mean_deg, 90.0, 1e-12));
    assert!(close(q.dihedral_std_deg, 0.0, 1e-12));
    assert!(close(q.min_dihedral_deg, 90.0, 1e-12) && close(q.max_dihedral_deg, 90.0, 1e-12));
    assert_eq!(q.edge_ratio, 1.0);
    assert!(close(q.volume, 1.0, 1e-15));
    assert!(FACE_EDGE.iter().flatten().all(|&e| e < 12));
}

#[test]
fn similarity_transforms_keep_the_shape_measures() {
    // Rotation about (1, 2, 3) by 0.7 rad, scale 2.5, translation.
    let axis = [1.0, 2.0, 3.0].map(|x: f64| x / 14f64.sqrt());
    let (s, c) = 0.7f64.sin_cos();
    let rot = |p: [f64; 3]| {
        let k = axis;
        let kxp = cross(k, p);
        let kd = dot(k, p) * (1.0 - c);
        [0, 1, 2].map(|i| p[i] * c + kxp[i] * s + k[i] * kd)
    };
    let t = map(&CUBE, |p| add(rot(p).map(|x| 2.5 * x), [10.0, -3.0, 7.5]));
    let q = hex_quality(&t);
    assert!(close(q.min_scaled_jacobian, 1.0, 1e-12));
    assert!(close(q.dihedral_mean_deg, 90.0, 1e-9) && close(q.dihedral_std_deg, 0.0, 1e-6));
    assert!(close(q.edge_ratio, 1.0, 1e-12));
    assert!(close(q.volume, 2.5f64.powi(3), 1e-9));
}

#[test]
fn sheared_hex_scores_the_cosine_of_the_shear() {
    // x += z tan φ: every Jacobian is det(e_x, e_y, (tan φ, 0, 1)) / |(tan φ, 0, 1)| =
    // 1 / sqrt(1 + tan² φ) = cos φ; the faces x = 0, 1 meet the bottom at 90° ∓ φ.
    let phi = 30f64.to_radians();
    let t = map(&CUBE, |p| [p[0] + p[2] * phi.tan(), p[1], p[2]]);
    let q = hex_quality(&t);
    assert!(close(q.min_scaled_jacobian, phi.cos(), 1e-12));
    assert!(
        hex_jacobians(&t)
            .iter()
            .all(|&j| close(j, phi.cos(), 1e-12))
    );
    assert!(close(q.min_dihedral_deg, 60.0, 1e-9) && close(q.max_dihedral_deg, 120.0, 1e-9));
    // Four edges at 60 or 120, eight at 90: mean 90, std sqrt(4·30²/12).
    assert!(close(q.dihedral_mean_deg, 90.0, 1e-9));
    assert!(close(q.dihedral_std_deg, 300f64.sqrt(), 1e-9));
    assert!(close(q.volume, 1.0, 1e-12));
    assert!(close(q.edge_ratio, 1.0 / phi.cos(), 1e-12));
}

#[test]
fn frustum_volume_and_jacobians() {
    // The top face shrunk to half about the axis: corners see (±¼, ±¼, 1) sides, so
    // SJ = 1/sqrt(1 + 1/8); the centre's axes stay orthogonal (1). Volume of the
    // frustum: (1 + ¼ + ½) / 3.
    let t = map(&CUBE, |p| {
        if p[2] > 0.0 {
            [0.25 + 0.5 * p[0], 0.25 + 0.5 * p[1], 1.0]
        } else {
            p
        }
    });
    let j = hex_jacobians(&t);
    assert!(
        j[..8]
            .iter()
            .all(|&x| close(x, 1.0 / 1.125f64.sqrt(), 1e-12))
    );
    assert!(close(j[8], 1.0, 1e-12));
    assert!(close(hex_volume(&t), 1.75 / 3.0, 1e-12));
    // Longest: the slanted sides, sqrt(1.125); shortest: the top edges, ½.
    assert!(close(hex_edge_ratio(&t), 2.0 * 1.125f64.sqrt(), 1e-12));
}

#[test]
fn verdict_volume_is_the_exact_trilinear_volume() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    for _ in 0..50 {
        let t = map(&CUBE, |p| p.map(|x| x + rng.random_range(-0.3..0.3)));
        assert!(close(hex_volume(&t), gauss_volume(&t), 1e-12));
    }
}

#[test]
fn inverted_and_collapsed_hexes() {
    // Top and bottom swapped: every Jacobian is −1.
    let mut inv = CUBE;
    inv.rotate_left(4);
    let q = hex_quality(&inv);
    assert_eq!(q.min_scaled_jacobian, -1.0);
    assert!(close(q.volume, -1.0, 1e-15));
    // One corner pushed through the opposite faces: that corner's Jacobian is negative.
    let mut dent = CUBE;
    dent[6] = [0.2, 0.2, 0.2];
    assert!(hex_scaled_jacobian(&dent) < 0.0);
    // Flattened to the bottom plane (vertical edges of zero length): 0.
    let flat = map(&CUBE, |p| [p[0], p[1], 0.0]);
    assert_eq!(hex_scaled_jacobian(&flat), 0.0);
    assert_eq!(hex_volume(&flat), 0.0);
    assert_eq!(hex_edge_ratio(&flat), f64::INFINITY);
    // Flattened with every edge kept: the top face slid into the bottom plane.
    let slid = map(&CUBE, |p| [p[0] + p[2], p[1], 0.0]);
    assert_eq!(hex_scaled_jacobian(&slid), 0.0);
    // One vertical edge collapsed (v5 onto v1).
    let mut wedge = CUBE;
    wedge[5] = wedge[1];
    assert_eq!(hex_scaled_jacobian(&wedge), 0.0);
}

#[test]
fn regular_and_corner_tets() {
    let reg = [
        [1.0, -1.0, -1.0],
        [1.0, 1.0, 1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
    ];
    assert!(crate::mesh::tet_volume(reg[0], reg[1], reg[2], reg[3]) > 0.0);
    assert!(close(tet_scaled_jacobian(&reg), 1.0, 1e-12));
    let acos13 = (1.0f64 / 3.0).acos().to_degrees();
    assert!(close(acos13, 70.528779, 1e-6));
    assert!(
        tet_dihedral_angles(&reg)
            .iter()
            .all(|&a| close(a, acos13, 1e-9))
    );
    let (lo, hi) = tet_dihedral_range(&reg);
    assert!(close(lo, acos13, 1e-9) && close(hi, acos13, 1e-9));
    let mut flipped = reg;
    flipped.swap(0, 1);
    assert!(close(tet_scaled_jacobian(&flipped), -1.0, 1e-12));
    assert!(close(tet_dihedral_range(&flipped).0, acos13, 1e-9));
    // The corner of a cube: det 1, largest corner product 1·√2·√2 = 2, so √2/2; right
    // angles along the axes, acos(1/√3) along the slanted face.
    let corner = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    assert!(close(tet_scaled_jacobian(&corner), 0.5f64.sqrt(), 1e-12));
    let a = tet_dihedral_angles(&corner);
    let slant = (1.0 / 3f64.sqrt()).acos().to_degrees();
    for (k, &x) in a.iter().enumerate() {
        let expect = if k < 3 { 90.0 } else { slant };
        assert!(close(x, expect, 1e-9), "edge {k}: {x}");
    }
    assert_eq!(tet_scaled_jacobian(&[[1.0; 3]; 4]), 0.0);
}

fn grid(nx: usize) -> HexMesh {
    let mut m = HexMesh::default();
    for i in 0..=nx {
        for (y, z) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            m.verts.push([i as f64, y, z]);
        }
    }
    // Vertex 4i + k: k = 0 (y0 z0), 1 (y1 z0), 2 (y1 z1), 3 (y0 z1).
    for i in 0..nx as u32 {
        let (a, b) = (4 * i, 4 * i + 4);
        m.hexes
            .push([a, b, b + 1, a + 1, a + 3, b + 3, b + 2, a + 2]);
    }
    m
}

#[test]
fn mesh_quality_aggregates_deterministically() {
    let mut m = grid(12);
    // The top vertices at x = 11 slid by tan 40° (hexes 10 and 11 score cos 40° = 0.766),
    // hex 5 inverted.
    let phi = 40f64.to_radians();
    for v in [44usize + 3, 44 + 2] {
        m.verts[v][0] += phi.tan();
    }
    m.hexes[5].rotate_left(4);
    let q = mesh_quality(&m);
    assert_eq!(q.hexes, 12);
    assert_eq!(q.inverted, 1);
    assert_eq!(q.sj_histogram, [1, 0, 0, 0, 2, 9]);
    assert_eq!(q.min_sj, -1.0);
    assert_eq!(q.worst_hexes.len(), 10);
    assert_eq!(q.worst_hexes[0].hex, 5);
    assert!(q.worst_hexes[1].scaled_jacobian < 1.0 && q.worst_hexes[2].scaled_jacobian < 1.0);
    assert_eq!(q.worst_hexes[3].hex, 0);
    let mean = q.mean_sj;
    // Equal to the sequential per-hex figures.
    let per = hex_qualities(&m);
    let s: f64 = per.iter().map(|h| h.min_scaled_jacobian).sum();
    assert!(close(mean, s / 12.0, 1e-15));
    let all: Vec<f64> = m
        .hexes
        .iter()
        .flat_map(|h| hex_dihedral_angles(&h.map(|v| m.verts[v as usize])))
        .collect();
    let am = all.iter().sum::<f64>() / all.len() as f64;
    let asd = (all.iter().map(|a| (a - am).powi(2)).sum::<f64>() / all.len() as f64).sqrt();
    assert!(close(q.dihedral_mean_deg, am, 1e-9) && close(q.dihedral_std_deg, asd, 1e-9));
    assert!(close(q.total_volume, 10.0, 1e-12));
    // Deterministic across thread counts.
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    assert_eq!(one.install(|| mesh_quality(&m)), q);
    let json = serde_json::to_string(&q).unwrap();
    assert!(json.contains("\"sj_histogram\":[1,0,0,0,2,9]"), "{json}");
    let table = q.table();
    assert!(table.contains("hexahedra              12"), "{table}");
    assert!(table.contains("inverted (SJ <= 0)     1"), "{table}");
    assert!(table.contains("0.8 <= SJ <= 1"), "{table}");
    assert!(
        table.contains("worst hexahedra (SJ)   5 (-1.000)"),
        "{table}"
    );
    let empty = mesh_quality(&HexMesh::default());
    assert_eq!(empty.hexes, 0);
    assert_eq!(empty.table(), "hexahedra              0\n");
}
