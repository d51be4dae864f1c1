//! Check 8 of the module docs of [`super`]: the unique edges and, for each, its star of
//! tetrahedra walked around it through shared faces in rotation order (a cycle for an
//! interior edge, a chain for a boundary edge); an edge whose walk misses some is
//! non-manifold.

use super::{TET_EDGES, TetError, star_wedge};
use crate::mesh::{NO_TET, TetMesh};

pub(super) fn local(tet: &[u32; 4], v: u32) -> usize {
    tet.iter().position(|&x| x == v).expect("vertex in tet")
}

/// The unique edges with their stars, as [`Topology`] holds them.
pub(super) struct EdgeStars {
    pub(super) edges: Vec<[u32; 2]>,
    pub(super) tet_edges: Vec<[u32; 6]>,
    pub(super) star_offsets: Vec<usize>,
    pub(super) star_tets: Vec<u32>,
    pub(super) edge_on_boundary: Vec<bool>,
}

/// Edges and their stars: each edge's tetrahedra, walked around it in order; an edge whose
/// walk does not reach all its tetrahedra is non-manifold.
pub(super) fn edge_stars(mesh: &TetMesh, neighbours: &[[u32; 4]]) -> Result<EdgeStars, TetError> {
    let nt = mesh.tets.len();
    let mut inc: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(6 * nt);
    for (t, tet) in mesh.tets.iter().enumerate() {
        for (k, &[i, j]) in TET_EDGES.iter().enumerate() {
            let (a, b) = (tet[i], tet[j]);
            inc.push((a.min(b), a.max(b), t as u32, k as u8));
        }
    }
    inc.sort_unstable();
    let mut edges: Vec<[u32; 2]> = Vec::new();
    let mut tet_edges = vec![[0u32; 6]; nt];
    let mut star_offsets = vec![0usize];
    let mut star_tets: Vec<u32> = Vec::with_capacity(6 * nt);
    let mut edge_on_boundary = Vec::new();
    let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
    let mut s = 0;
    while s < inc.len() {
        let mut e = s + 1;
        while e < inc.len() && inc[e].0 == inc[s].0 && inc[e].1 == inc[s].1 {
            e += 1;
        }
        let id = edges.len() as u32;
        let (a, b) = (inc[s].0, inc[s].1);
        edges.push([a, b]);
        for x in &inc[s..e] {
            tet_edges[x.2 as usize][x.3 as usize] = id;
        }
        let m = e - s;
        let start = inc[s].2;
        fwd.clear();
        bwd.clear();
        fwd.push(start);
        let mut t = start;
        let mut closed = false;
        loop {
            let tet = &mesh.tets[t as usize];
            let [c, _] = star_wedge(*tet, a, b);
            let n = neighbours[t as usize][local(tet, c)];
            if n == NO_TET {
                break;
            }
            if n == start {
                closed = true;
                break;
            }
            fwd.push(n);
            t = n;
            if fwd.len() > m {
                break;
            }
        }
        if !closed {
            let mut t = start;
            loop {
                let tet = &mesh.tets[t as usize];
                let [_, d] = star_wedge(*tet, a, b);
                let p = neighbours[t as usize][local(tet, d)];
                if p == NO_TET || p == start || fwd.len() + bwd.len() > m {
                    break;
                }
                bwd.push(p);
                t = p;
            }
        }
        let walked = fwd.len() + bwd.len();
        if walked != m {
            return Err(TetError::NonManifoldEdge {
                edge: [a, b],
                tets: m,
                start,
                walked,
            });
        }
        star_tets.extend(bwd.iter().rev());
        star_tets.extend(&fwd);
        star_offsets.push(star_tets.len());
        edge_on_boundary.push(!closed);
        s = e;
    }
    Ok(EdgeStars {
        edges,
        tet_edges,
        star_offsets,
        star_tets,
        edge_on_boundary,
    })
}
