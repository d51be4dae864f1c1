//! Step 4 of the module docs of [`super`] (paper §3, Fig. 3): the stencils that fill each BCC
//! tetrahedron with its part inside, by the signs of its vertices after warping, with the
//! quadrilaterals split by the colour and parity rules and every tetrahedron oriented
//! positively in the reference configuration; then the output mesh on the referenced keys.

use rayon::prelude::*;

use super::lattice::{Lattice, NEG, POS, ZERO, ckey, det_i, lkey};
use crate::mesh::TetMesh;

/// The state the stencils read: signs after warping, surviving cut points and warps.
pub(super) struct Stencils<'a> {
    pub(super) lat: &'a Lattice,
    pub(super) sign: &'a [i8],
    /// Surviving cut points by edge key, sorted.
    pub(super) cuts: &'a [(u64, [f64; 3])],
    /// Warped vertices and where they went, sorted.
    pub(super) warps: &'a [(u32, [f64; 3])],
}

impl Stencils<'_> {
    pub(super) fn vertex_pos(&self, v: u32) -> [f64; 3] {
        match self.warps.binary_search_by_key(&v, |w| w.0) {
            Ok(i) => self.warps[i].1,
            Err(_) => self.lat.pos(v),
        }
    }
    pub(super) fn key_pos(&self, key: u64) -> [f64; 3] {
        if key as u32 == u32::MAX {
            self.vertex_pos((key >> 32) as u32)
        } else {
            match self.cuts.binary_search_by_key(&key, |c| c.0) {
                Ok(i) => self.cuts[i].1,
                Err(_) => {
                    debug_assert!(false, "cut point {key:#x} missing");
                    let a = self.lat.pos((key >> 32) as u32);
                    let b = self.lat.pos(key as u32);
                    [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]))
                }
            }
        }
    }

    /// Of the − vertices `u`, `v` of a lattice face whose third vertex `w` is +, the one the
    /// quadrilateral's diagonal leaves (it ends at the cut point on the other's edge to `w`).
    pub(super) fn quad_pick(&self, w: u32, u: u32, v: u32) -> u32 {
        let lat = self.lat;
        if lat.is_long(u, v) {
            // Parity rule: the endpoint with an even lattice index along the edge's axis.
            let (du, dv) = (lat.doubled(u), lat.doubled(v));
            let axis = (0..3).find(|&a| du[a] != dv[a]).unwrap_or(0);
            let idx = |d: i64| d.div_euclid(2);
            if idx(du[axis]) % 2 == 0 { u } else { v }
        } else {
            // One of u, v spans the face's long edge with w; the diagonal leaves the other.
            if lat.is_long(u, w) { v } else { u }
        }
    }

    /// Push tetrahedron `t` (output keys), oriented positively in the reference
    /// configuration.
    pub(super) fn emit(&self, t: [u64; 4], out: &mut Vec<[u64; 4]>) {
        let r = t.map(|k| self.lat.reference(k));
        let d = det_i(r[0], r[1], r[2], r[3]);
        debug_assert!(d != 0, "degenerate stencil tetrahedron {t:x?}");
        if d > 0 {
            out.push(t);
        } else {
            out.push([t[0], t[2], t[1], t[3]]);
        }
    }

    /// Triangulate the prism with triangles `a` and `b`, rungs `a[i] b[i]`; `choice[q]` is
    /// the rung whose `a` end the diagonal of lateral quadrilateral `q` leaves, quadrilaterals
    /// being (0, 1), (1, 2), (0, 2).
    pub(super) fn prism(
        &self,
        a: [u64; 3],
        b: [u64; 3],
        choice: [usize; 3],
        out: &mut Vec<[u64; 4]>,
    ) {
        let quad = |i: usize, j: usize| -> usize {
            match (i.min(j), i.max(j)) {
                (0, 1) => choice[0],
                (1, 2) => choice[1],
                _ => choice[2],
            }
        };
        // A rung chosen by both of its quadrilaterals (exists unless the choices cycle).
        let k = (0..3).find(|&k| {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            quad(k, i) == k && quad(k, j) == k
        });
        let Some(k) = k else {
            debug_assert!(false, "cyclic prism diagonals {choice:?}");
            return;
        };
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        self.emit([a[k], b[k], b[i], b[j]], out);
        if quad(i, j) == i {
            self.emit([a[k], a[i], a[j], b[j]], out);
            self.emit([a[k], a[i], b[j], b[i]], out);
        } else {
            self.emit([a[k], a[i], a[j], b[i]], out);
            self.emit([a[k], a[j], b[j], b[i]], out);
        }
    }

    /// Fill lattice tetrahedron `t` with its stencil; returns whether it was dropped for
    /// having all four corners warped onto the surface.
    pub(super) fn fill(&self, t: [u32; 4], out: &mut Vec<[u64; 4]>) -> bool {
        let mut neg = [0u32; 4];
        let mut zero = [0u32; 4];
        let mut pos = [0u32; 4];
        let (mut nn, mut nz, mut np) = (0, 0, 0);
        for &v in &t {
            match self.sign[v as usize] {
                NEG => {
                    neg[nn] = v;
                    nn += 1;
                }
                ZERO => {
                    zero[nz] = v;
                    nz += 1;
                }
                _ => {
                    pos[np] = v;
                    np += 1;
                }
            }
        }
        if nn == 0 {
            // Outside, or all four corners on the surface (see the module docs).
            return nz == 4;
        }
        let l = lkey;
        match (np, nz) {
            (0, _) => self.emit(t.map(lkey), out),
            (1, 0) => {
                let w = pos[0];
                let u = [neg[0], neg[1], neg[2]];
                let a = u.map(l);
                let b = u.map(|x| ckey(x, w));
                let pick = |i: usize, j: usize| {
                    if self.quad_pick(w, u[i], u[j]) == u[i] {
                        i
                    } else {
                        j
                    }
                };
                self.prism(a, b, [pick(0, 1), pick(1, 2), pick(0, 2)], out);
            }
            (1, 1) => {
                let (w, z) = (pos[0], zero[0]);
                let (u1, u2) = (neg[0], neg[1]);
                let (p1, p2) = (ckey(u1, w), ckey(u2, w));
                if self.quad_pick(w, u1, u2) == u1 {
                    self.emit([l(z), l(u1), l(u2), p2], out);
                    self.emit([l(z), l(u1), p2, p1], out);
                } else {
                    self.emit([l(z), l(u1), l(u2), p1], out);
                    self.emit([l(z), l(u2), p2, p1], out);
                }
            }
            (1, 2) => {
                let (w, u) = (pos[0], neg[0]);
                self.emit([ckey(u, w), l(u), l(zero[0]), l(zero[1])], out);
            }
            (2, 0) => {
                let (w1, w2) = (pos[0], pos[1]);
                let (u1, u2) = (neg[0], neg[1]);
                let a = [l(u1), ckey(u1, w1), ckey(u1, w2)];
                let b = [l(u2), ckey(u2, w1), ckey(u2, w2)];
                let c01 = if self.quad_pick(w1, u1, u2) == u1 {
                    0
                } else {
                    1
                };
                let c02 = if self.quad_pick(w2, u1, u2) == u1 {
                    0
                } else {
                    2
                };
                let c12 = match (c01, c02) {
                    (0, 2) => 2,
                    (1, 0) => 1,
                    _ => {
                        // Free: the shorter diagonal of the quadrilateral on the surface.
                        let d = |p: u64, q: u64| {
                            let (x, y) = (self.key_pos(p), self.key_pos(q));
                            (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>()
                        };
                        if d(a[1], b[2]) <= d(a[2], b[1]) { 1 } else { 2 }
                    }
                };
                self.prism(a, b, [c01, c12, c02], out);
            }
            (2, 1) => {
                let (u, z) = (neg[0], zero[0]);
                self.emit([l(u), l(z), ckey(u, pos[0]), ckey(u, pos[1])], out);
            }
            (3, 0) => {
                let u = neg[0];
                self.emit(
                    [l(u), ckey(u, pos[0]), ckey(u, pos[1]), ckey(u, pos[2])],
                    out,
                );
            }
            _ => debug_assert!(false, "impossible sign count"),
        }
        false
    }
}

/// Stencils, slab by slab of cubes along z: the output tetrahedra as vertex keys, and how
/// many surface tetrahedra were dropped.
pub(super) fn stencil_tets(st: &Stencils) -> (Vec<[u64; 4]>, usize) {
    let (lat, sign) = (st.lat, st.sign);
    let n = lat.n;
    let slabs: Vec<(Vec<[u64; 4]>, usize)> = (0..n[2])
        .into_par_iter()
        .map(|k| {
            let mut out = Vec::new();
            let mut dropped = 0;
            for axis in 0..3 {
                let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let c = [i, j, k];
                        if c[axis] + 1 >= n[axis] {
                            continue;
                        }
                        let mut c2 = c;
                        c2[axis] += 1;
                        let r1 = lat.red(c[0], c[1], c[2]);
                        let r2 = lat.red(c2[0], c2[1], c2[2]);
                        // The shared face's corners, in cyclic order.
                        let corner = |sb: usize, sd: usize| {
                            let mut q = c;
                            q[axis] += 1;
                            q[b] += sb;
                            q[d] += sd;
                            lat.black(q[0], q[1], q[2])
                        };
                        let ring = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                        let s_any = |v: u32| sign[v as usize] != POS;
                        if !(s_any(r1) || s_any(r2) || ring.iter().any(|&v| s_any(v))) {
                            continue;
                        }
                        for e in 0..4 {
                            let (p, q) = (ring[e], ring[(e + 1) % 4]);
                            let t = [r1, r2, p, q];
                            let r = t.map(|v| lat.doubled(v));
                            let t = if det_i(r[0], r[1], r[2], r[3]) > 0 {
                                t
                            } else {
                                [r1, r2, q, p]
                            };
                            if st.fill(t, &mut out) {
                                dropped += 1;
                            }
                        }
                    }
                }
            }
            (out, dropped)
        })
        .collect();
    let surface_tets_dropped = slabs.iter().map(|s| s.1).sum();
    let keyed: Vec<[u64; 4]> = slabs.into_iter().flat_map(|s| s.0).collect();
    (keyed, surface_tets_dropped)
}

/// Output vertices: referenced keys in order; the tetrahedra renumbered onto them.
pub(super) fn output_mesh(st: &Stencils, keyed: &[[u64; 4]]) -> TetMesh {
    let mut keys: Vec<u64> = keyed.iter().flatten().copied().collect();
    keys.par_sort_unstable();
    keys.dedup();
    let verts: Vec<[f64; 3]> = keys.par_iter().map(|&k| st.key_pos(k)).collect();
    let tets: Vec<[u32; 4]> = keyed
        .par_iter()
        .map(|t| t.map(|k| keys.binary_search(&k).unwrap_or(0) as u32))
        .collect();
    TetMesh { verts, tets }
}
