//! The bookkeeping and the last two steps of the module docs of [`super`]: the vertex →
//! hexahedron incidences, the vertices' kinds (interior, surface, fixed features), the mean
//! edge length; step 4 (apply the moves, put back those that make a hexahedron worse than
//! allowed) and step 5 (untangle what stays inverted, the surface vertices sliding in their
//! tangent planes).

use rayon::prelude::*;

use super::bvh::Bvh;
use super::cube::corners;
use super::{Kind, RelaxParams, RelaxReport, UNTANGLE_ROUNDS, dist2, summary};
use crate::geom::vec::{add, dot, scale};
use crate::mesh::HexMesh;
use crate::quality::{HEX_EDGES, hex_scaled_jacobian};
use crate::untangle::{Freedom, UntangleParams, untangle_hexes};

/// Vertex → (hexahedron, corner) incidences, CSR: vertex `v`'s are
/// `inc[off[v]..off[v + 1]]`, in hexahedron order.
pub(super) fn incidences(hex: &HexMesh) -> (Vec<usize>, Vec<(u32, u8)>) {
    let nv = hex.verts.len();
    let mut off = vec![0usize; nv + 1];
    for h in &hex.hexes {
        for &v in h {
            off[v as usize + 1] += 1;
        }
    }
    for v in 0..nv {
        off[v + 1] += off[v];
    }
    let mut inc = vec![(0u32, 0u8); off[nv]];
    let mut fill = off.clone();
    for (k, h) in hex.hexes.iter().enumerate() {
        for (c, &v) in h.iter().enumerate() {
            inc[fill[v as usize]] = (k as u32, c as u8);
            fill[v as usize] += 1;
        }
    }
    (off, inc)
}

/// Each vertex's kind: unused and feature vertices (and all boundary vertices when there
/// is no surface to project onto) are fixed.
pub(super) fn vertex_kinds(
    off: &[usize],
    normals: &[Vec<[f64; 3]>],
    bvh: &Bvh,
    params: &RelaxParams,
) -> Vec<Kind> {
    let nv = off.len() - 1;
    let cos_feature = params.feature_angle_deg.to_radians().cos();
    (0..nv)
        .map(|v| {
            if off[v + 1] == off[v] {
                Kind::Fixed
            } else if normals[v].is_empty() {
                Kind::Interior
            } else if bvh.is_empty() {
                Kind::Fixed
            } else {
                let ns = &normals[v];
                let bent = (0..ns.len())
                    .any(|a| (a + 1..ns.len()).any(|b| dot(ns[a], ns[b]) < cos_feature));
                if bent { Kind::Fixed } else { Kind::Surface }
            }
        })
        .collect()
}

/// The scaled Jacobian of hexahedron `k` at the positions `verts`.
pub(super) fn sj_of(hexes: &[[u32; 8]], verts: &[[f64; 3]], k: usize) -> f64 {
    hex_scaled_jacobian(&corners(verts, &hexes[k]))
}

/// The mean edge length, summed hexahedron by hexahedron (shared edges counted once per
/// hexahedron); 0 without hexahedra.
pub(super) fn mean_edge_length(hex: &HexMesh) -> f64 {
    let nh = hex.hexes.len();
    let mut edge_sum = 0.0;
    for h in &hex.hexes {
        for [a, b] in HEX_EDGES {
            edge_sum += dist2(hex.verts[h[a] as usize], hex.verts[h[b] as usize]).sqrt();
        }
    }
    if nh > 0 {
        edge_sum / (12 * nh) as f64
    } else {
        0.0
    }
}

/// Step 4 of the module docs: applies the proposals, then puts back the moves that make a
/// hexahedron worse than its own scaled Jacobian or `tau` (whichever is lower), until none
/// does. `(off, inc)` are the incidences; `(mark, epoch)` the per-hexahedron visit marks.
/// Returns the new positions, their scaled Jacobians, the moved vertices in order and which
/// of them were put back.
pub(super) fn apply_moves(
    hex: &HexMesh,
    proposal: &[Option<[f64; 3]>],
    (off, inc): (&[usize], &[(u32, u8)]),
    sj: &[f64],
    tau: f64,
    (mark, epoch): (&mut [u32], &mut u32),
) -> (Vec<[f64; 3]>, Vec<f64>, Vec<u32>, Vec<bool>) {
    let nv = hex.verts.len();
    let mut next = hex.verts.clone();
    let moved: Vec<u32> = (0..nv as u32)
        .filter(|&v| proposal[v as usize].is_some())
        .collect();
    let mut dirty = Vec::new();
    *epoch += 1;
    for &v in &moved {
        next[v as usize] = proposal[v as usize].expect("moved");
        for &(k, _) in &inc[off[v as usize]..off[v as usize + 1]] {
            if mark[k as usize] != *epoch {
                mark[k as usize] = *epoch;
                dirty.push(k);
            }
        }
    }
    let mut is_moved = vec![false; nv];
    for &v in &moved {
        is_moved[v as usize] = true;
    }
    let mut put_back = vec![false; nv];
    let mut sj_next = sj.to_vec();
    while !dirty.is_empty() {
        dirty.sort_unstable();
        let vals: Vec<f64> = dirty
            .par_iter()
            .map(|&k| sj_of(&hex.hexes, &next, k as usize))
            .collect();
        let mut worse = Vec::new();
        for (&k, &val) in dirty.iter().zip(vals.iter()) {
            sj_next[k as usize] = val;
            if val.is_nan() || val < sj[k as usize].min(tau) {
                worse.push(k);
            }
        }
        *epoch += 1;
        dirty.clear();
        for k in worse {
            for &v in &hex.hexes[k as usize] {
                let vi = v as usize;
                if is_moved[vi] && !put_back[vi] {
                    put_back[vi] = true;
                    next[vi] = hex.verts[vi];
                    for &(h, _) in &inc[off[vi]..off[vi + 1]] {
                        if mark[h as usize] != *epoch {
                            mark[h as usize] = *epoch;
                            dirty.push(h);
                        }
                    }
                }
            }
        }
    }
    (next, sj_next, moved, put_back)
}

/// Step 5 of the module docs: hexahedra still inverted are untangled: first with the
/// boundary held, then with the surface vertices sliding in their tangent planes and
/// projected back onto the surface; a round is kept only when it leaves fewer hexahedra
/// inverted. `sj` holds the scaled Jacobians at the current positions and is kept up to date.
pub(super) fn untangle_rounds(
    hex: &mut HexMesh,
    kind: &[Kind],
    normals: &[Vec<[f64; 3]>],
    project: &impl Fn(usize, [f64; 3]) -> Option<[f64; 3]>,
    sj: &mut Vec<f64>,
    report: &mut RelaxReport,
) {
    let (nv, nh) = (hex.verts.len(), hex.hexes.len());
    for round in 0..UNTANGLE_ROUNDS {
        let inverted = summary(sj).2;
        if inverted == 0 {
            break;
        }
        let freedom: Vec<Freedom> = (0..nv)
            .map(|v| match kind[v] {
                Kind::Interior => Freedom::Free,
                Kind::Fixed => Freedom::Fixed,
                Kind::Surface if round == 0 => Freedom::Fixed,
                Kind::Surface => {
                    let n = normals[v].iter().fold([0.0; 3], |a, &b| add(a, b));
                    let l = dot(n, n).sqrt();
                    if l > 0.0 {
                        Freedom::Plane(scale(n, 1.0 / l))
                    } else {
                        Freedom::Fixed
                    }
                }
            })
            .collect();
        let before = hex.verts.clone();
        let r = untangle_hexes(
            &mut hex.verts,
            &hex.hexes,
            &freedom,
            &UntangleParams::default(),
        );
        for v in 0..nv {
            if kind[v] == Kind::Surface
                && hex.verts[v] != before[v]
                && let Some(q) = project(v, hex.verts[v])
            {
                hex.verts[v] = q;
            }
        }
        let untangled: Vec<f64> = (0..nh)
            .into_par_iter()
            .map(|k| sj_of(&hex.hexes, &hex.verts, k))
            .collect();
        let worse = summary(&untangled).2 >= inverted;
        report.untangle = Some(r);
        if worse {
            hex.verts = before;
            break;
        }
        *sj = untangled;
    }
}
