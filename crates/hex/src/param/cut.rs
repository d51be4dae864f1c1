//! The cut of §3.1 (module docs of [`super`], "Transitions and the cut"): the spanning tree
//! of the tetrahedra, the chart rotations that make its faces' matchings the identity, the
//! faces glued on top of it around regular edges, and the cut vertices, the copies of the
//! mesh's vertices that the faces left cut split off.

use std::collections::VecDeque;

use crate::frames::{edge_holonomy, face_index};
use crate::mesh::{FACE_OPPOSITE, NO_TET, TetMesh};
use crate::rotation::Rot;
use crate::topology::{Topology, find, union};

/// The cut: a spanning tree of tetrahedra across faces, the chart rotations that make its
/// faces' matchings the identity, and the faces glued on top of it.
pub(super) struct Cut {
    /// Chart rotation of each tetrahedron: aligned chart `x' = R x`.
    pub(super) chart: Vec<Rot>,
    /// Matchings between aligned charts.
    pub(super) aligned: Vec<[Rot; 4]>,
    /// Whether each (tet, face) is glued (identity transition, zero gap).
    pub(super) glued: Vec<[bool; 4]>,
}

pub(super) fn build_cut(mesh: &TetMesh, topo: &Topology, m: &[[Rot; 4]]) -> Cut {
    let nt = mesh.tets.len();
    let nb = &topo.neighbours;
    let mut chart = vec![Rot::ID; nt];
    let mut glued = vec![[false; 4]; nt];
    let mut seen = vec![false; nt];
    let mut queue = VecDeque::from([0usize]);
    seen[0] = true;
    while let Some(t) = queue.pop_front() {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET || seen[s as usize] {
                continue;
            }
            let s = s as usize;
            seen[s] = true;
            // R_s = R_t m_ts⁻¹ makes the aligned matching R_s m_ts R_t⁻¹ the identity.
            chart[s] = chart[t].compose(m[t][i].inverse());
            glued[t][i] = true;
            glued[s][face_index(nb, s, t as u32)] = true;
            queue.push_back(s);
        }
    }
    let aligned: Vec<[Rot; 4]> = (0..nt)
        .map(|t| {
            std::array::from_fn(|i| {
                let s = nb[t][i];
                if s == NO_TET {
                    Rot::ID
                } else {
                    chart[s as usize]
                        .compose(m[t][i])
                        .compose(chart[t].inverse())
                }
            })
        })
        .collect();
    // Glue faces hanging off regular interior edges: around such an edge the matchings
    // compose to the identity, so when all other faces are glued the last one is forced to
    // the identity with zero gap.
    let ne = topo.num_edges();
    let regular: Vec<bool> = (0..ne)
        .map(|e| !topo.edge_on_boundary[e] && edge_holonomy(topo, m, e) == Rot::ID)
        .collect();
    let face_edges = |t: usize, i: usize| -> [u32; 3] {
        let f = FACE_OPPOSITE[i].map(|j| mesh.tets[t][j]);
        [(0, 1), (1, 2), (2, 0)].map(|(a, b)| topo.edge_id(f[a], f[b]).expect("face edge"))
    };
    let mut cuts = vec![0u32; ne];
    for e in 0..ne {
        if !regular[e] {
            continue;
        }
        let star = topo.star(e);
        for k in 0..star.len() {
            let (t, s) = (star[k] as usize, star[(k + 1) % star.len()]);
            if !glued[t][face_index(nb, t, s)] {
                cuts[e] += 1;
            }
        }
    }
    let mut work: Vec<u32> = (0..ne as u32)
        .filter(|&e| regular[e as usize] && cuts[e as usize] == 1)
        .collect();
    while let Some(e) = work.pop() {
        let e = e as usize;
        if cuts[e] != 1 {
            continue;
        }
        let star = topo.star(e);
        let Some((t, i, s)) = (0..star.len()).find_map(|k| {
            let (t, s) = (star[k] as usize, star[(k + 1) % star.len()]);
            let i = face_index(nb, t, s);
            (!glued[t][i]).then_some((t, i, s as usize))
        }) else {
            continue;
        };
        debug_assert_eq!(
            aligned[t][i],
            Rot::ID,
            "a regular edge's last cut is the identity"
        );
        glued[t][i] = true;
        glued[s][face_index(nb, s, t as u32)] = true;
        for f in face_edges(t, i) {
            let f = f as usize;
            if regular[f] {
                cuts[f] -= 1;
                if cuts[f] == 1 {
                    work.push(f as u32);
                }
            }
        }
    }
    Cut {
        chart,
        aligned,
        glued,
    }
}

/// The local index of vertex `v` in tetrahedron `t`.
pub(super) fn local(mesh: &TetMesh, t: usize, v: u32) -> usize {
    mesh.tets[t].iter().position(|&x| x == v).expect("vertex")
}

/// The copies of the mesh's vertices the cut leaves: corners joined across glued faces share
/// one, and each has three unknowns (module docs, "Transitions and the cut").
pub(super) struct CutVertices {
    /// Per corner `4 t + j`, its cut vertex.
    pub(super) corner_cv: Vec<u32>,
    /// How many there are.
    pub(super) count: u32,
    /// Each one's position (its mesh vertex's).
    pub(super) pos: Vec<[f64; 3]>,
}

impl CutVertices {
    /// The unknown of parameter `r` at corner `j` of tetrahedron `t`.
    pub(super) fn xvar(&self, t: usize, j: usize, r: usize) -> u32 {
        3 * self.corner_cv[4 * t + j] + r as u32
    }
}

/// Corners → cut vertices: union across glued faces, numbered in the order of their first
/// corner.
pub(super) fn cut_vertices(mesh: &TetMesh, topo: &Topology, cut: &Cut) -> CutVertices {
    let nt = mesh.tets.len();
    let nb = &topo.neighbours;
    let mut parent: Vec<u32> = (0..4 * nt as u32).collect();
    for t in 0..nt {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET || (s as usize) < t || !cut.glued[t][i] {
                continue;
            }
            for j in FACE_OPPOSITE[i] {
                let v = mesh.tets[t][j];
                let b = (4 * s as usize + local(mesh, s as usize, v)) as u32;
                union(&mut parent, (4 * t + j) as u32, b);
            }
        }
    }
    let mut cv_of_root = vec![u32::MAX; 4 * nt];
    let mut corner_cv = vec![0u32; 4 * nt];
    let mut ncv = 0u32;
    for c in 0..4 * nt {
        let r = find(&mut parent, c as u32) as usize;
        if cv_of_root[r] == u32::MAX {
            cv_of_root[r] = ncv;
            ncv += 1;
        }
        corner_cv[c] = cv_of_root[r];
    }
    let mut cv_pos = vec![[0.0; 3]; ncv as usize];
    for (c, &cv) in corner_cv.iter().enumerate() {
        cv_pos[cv as usize] = mesh.verts[mesh.tets[c / 4][c % 4] as usize];
    }
    CutVertices {
        corner_cv,
        count: ncv,
        pos: cv_pos,
    }
}
