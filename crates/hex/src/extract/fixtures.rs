use super::*;
use crate::mesh::{FACE_OPPOSITE, NO_TET, tet_neighbours};
use crate::param::Transition;
use crate::rotation;

/// The `n × n × n` grid of unit cubes scaled by `h`, each split into the 6 tetrahedra
/// around its main diagonal (Kuhn), positively oriented.
pub fn box_tets(n: usize, h: f64) -> TetMesh {
    let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
    let mut verts = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                verts.push([i as f64 * h, j as f64 * h, k as f64 * h]);
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
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                for p in perms {
                    let mut c = [i, j, k];
                    let mut tet = [id(c[0], c[1], c[2]); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] += 1;
                        tet[s + 1] = id(c[0], c[1], c[2]);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    orient(TetMesh { verts, tets })
}

/// Swaps two corners of every negatively oriented tetrahedron.
pub fn orient(mut m: TetMesh) -> TetMesh {
    for t in 0..m.tets.len() {
        if m.volume(t) < 0.0 {
            m.tets[t].swap(2, 3);
        }
    }
    m
}

/// The map with charts `uvw` whose transitions are solved from the shared corners: for
/// each interior face, the cube rotation and integer shift carrying the face's three
/// corners from one chart to the other (panics when there is none).
pub fn with_transitions(mesh: &TetMesh, uvw: Vec<[[f64; 3]; 4]>) -> GridMap {
    let nb = tet_neighbours(mesh).unwrap();
    let mut transitions = vec![[Transition::ID; 4]; mesh.tets.len()];
    for t in 0..mesh.tets.len() {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET {
                continue;
            }
            let s = s as usize;
            let pairs: Vec<([f64; 3], [f64; 3])> = FACE_OPPOSITE[i]
                .iter()
                .map(|&a| {
                    let v = mesh.tets[t][a];
                    let b = mesh.tets[s].iter().position(|&w| w == v).unwrap();
                    (uvw[t][a], uvw[s][b])
                })
                .collect();
            let found = rotation::all().find_map(|r| {
                let x = r.apply(pairs[0].0);
                let shift = [0, 1, 2].map(|k| (pairs[0].1[k] - x[k]).round() as i32);
                let tr = Transition { rot: r, shift };
                pairs
                    .iter()
                    .all(|(a, b)| {
                        let y = tr.apply(*a);
                        (0..3).all(|k| (y[k] - b[k]).abs() < 1e-9)
                    })
                    .then_some(tr)
            });
            transitions[t][i] = found.expect("a cube rotation and integer shift fit the face");
        }
    }
    GridMap { uvw, transitions }
}

/// The map `uvw = f(x)` on every tetrahedron.
pub fn map_of(mesh: &TetMesh, f: impl Fn([f64; 3]) -> [f64; 3]) -> GridMap {
    let uvw = (0..mesh.tets.len())
        .map(|t| mesh.corners(t).map(&f))
        .collect();
    with_transitions(mesh, uvw)
}

/// A prism over a regular polygon with `sides` corners (centroid at the origin) whose
/// cross-section is cut into `sides` quadrilaterals from the centroid to the edge
/// midpoints, each mapped to the square `[0, m]²`, and whose `layers` layers of height ½
/// map to `w ∈ [0, m·layers]`: the prism's axis is an edge of valence `sides` (singular
/// unless `sides == 4`; the transitions between the quadrilaterals are quarter turns
/// about `w`). Returns the mesh and the map.
pub fn singular_prism(sides: usize, m: f64, layers: usize) -> (TetMesh, GridMap) {
    let n = sides;
    let tri: Vec<[f64; 2]> = (0..n)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            [a.cos(), a.sin()]
        })
        .collect();
    let mid = |a: usize, b: usize| [0.5 * (tri[a][0] + tri[b][0]), 0.5 * (tri[a][1] + tri[b][1])];
    // 2D vertices: 0 centroid, 1..=n corners, n+1..=2n midpoints of (k, k+1).
    let mut v2 = vec![[0.0, 0.0]];
    v2.extend(tri.iter().copied());
    for k in 0..n {
        v2.push(mid(k, (k + 1) % n));
    }
    // Quad k: centroid, midpoint (k-1, k), corner k, midpoint (k, k+1), mapped to
    // (0,0), (m,0), (m,m), (0,m).
    let mut tris2: Vec<([usize; 3], usize, [[f64; 2]; 3])> = Vec::new();
    for k in 0..n {
        let (ma, c, mb) = (n + 1 + (k + n - 1) % n, 1 + k, n + 1 + k);
        tris2.push(([0, ma, c], k, [[0.0, 0.0], [m, 0.0], [m, m]]));
        tris2.push(([0, c, mb], k, [[0.0, 0.0], [m, m], [0.0, m]]));
    }
    let nv2 = v2.len();
    let mut verts = Vec::new();
    for l in 0..=layers {
        for p in &v2 {
            verts.push([p[0], p[1], l as f64 * 0.5]);
        }
    }
    let mut tets = Vec::new();
    let mut uvw = Vec::new();
    for l in 0..layers {
        for (t2, _, par) in &tris2 {
            // Sort the triangle's corners by id; split the prism consistently.
            let mut o = [0usize, 1, 2];
            o.sort_by_key(|&i| t2[i]);
            let bot = |i: usize| (l * nv2 + t2[o[i]], par[o[i]], l as f64);
            let top = |i: usize| ((l + 1) * nv2 + t2[o[i]], par[o[i]], (l + 1) as f64);
            for tet in [
                [bot(0), bot(1), bot(2), top(0)],
                [bot(1), bot(2), top(0), top(1)],
                [bot(2), top(0), top(1), top(2)],
            ] {
                tets.push(tet.map(|(v, _, _)| v as u32));
                uvw.push(tet.map(|(_, p, w)| [p[0], p[1], m * w]));
            }
        }
    }
    let mut mesh = TetMesh { verts, tets };
    for t in 0..mesh.tets.len() {
        if mesh.volume(t) < 0.0 {
            mesh.tets[t].swap(2, 3);
            uvw[t].swap(2, 3);
        }
    }
    let map = with_transitions(&mesh, uvw);
    (mesh, map)
}
