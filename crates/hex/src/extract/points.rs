//! Step 2 of the module docs of [`super`]: the grid points of one parity (vertices or cube
//! centres) in every chart, closed under "partner across a face", grouped by union-find into
//! the mesh's vertices (or centres), each placed by its most interior node.

use rayon::prelude::*;

use super::chart::{Ctx, apply_doubled, half};
use super::{ExtractError, MAX_CLOSURE_ROUNDS};
use crate::mesh::NO_TET;

/// Points of one parity grouped into classes (vertices or cube centres).
pub(super) struct Classes {
    /// Per tetrahedron, the range of its nodes in `pts`.
    pub(super) off: Vec<usize>,
    /// Doubled coordinates of the nodes, ascending within each tetrahedron.
    pub(super) pts: Vec<[i64; 3]>,
    /// The tetrahedron of each node.
    pub(super) tet: Vec<u32>,
    /// The class of each node.
    pub(super) class_of: Vec<u32>,
    /// The representative (most interior) node of each class.
    pub(super) rep: Vec<u32>,
    /// Face points whose partner could not be matched.
    pub(super) unmatched: usize,
}

impl Classes {
    pub(super) fn find(&self, t: usize, d: [i64; 3]) -> Option<usize> {
        let (a, b) = (self.off[t], self.off[t + 1]);
        self.pts[a..b].binary_search(&d).ok().map(|k| a + k)
    }
}

pub(super) fn uf_find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

impl Ctx<'_> {
    /// The partners `(neighbour, doubled point)` of a node across the faces it lies on.
    pub(super) fn partners(
        &self,
        t: usize,
        d: [i64; 3],
    ) -> impl Iterator<Item = (usize, [i64; 3])> + '_ {
        let ch = &self.charts[t];
        let l = ch.bary(half(d));
        (0..4).filter_map(move |i| {
            let s = self.nb[t][i];
            if s == NO_TET || !ch.on_face(&l, i) || !self.charts[s as usize].valid {
                return None;
            }
            Some((s as usize, apply_doubled(&self.map.transitions[t][i], d)))
        })
    }

    pub(super) fn classes(&self, parity: i64) -> Result<Classes, ExtractError> {
        let nt = self.charts.len();
        let per_tet: Vec<Result<Vec<[i64; 3]>, ExtractError>> = (0..nt)
            .into_par_iter()
            .map(|t| {
                if self.charts[t].valid {
                    self.charts[t].points(parity, t)
                } else {
                    Ok(Vec::new())
                }
            })
            .collect();
        let mut lists = Vec::with_capacity(nt);
        for r in per_tet {
            lists.push(r?);
        }
        // Close the set under "partner across a face" (rounding may miss a partner).
        for _ in 0..MAX_CLOSURE_ROUNDS {
            let mut missing: Vec<(usize, [i64; 3])> = (0..nt)
                .into_par_iter()
                .flat_map_iter(|t| {
                    let lists = &lists;
                    lists[t].iter().flat_map(move |&d| {
                        self.partners(t, d)
                            .filter(|(s, e)| lists[*s].binary_search(e).is_err())
                    })
                })
                .collect();
            if missing.is_empty() {
                break;
            }
            missing.sort_unstable();
            missing.dedup();
            for (s, e) in missing {
                lists[s].push(e);
            }
            for l in lists.iter_mut() {
                l.sort_unstable();
            }
        }
        let mut off = Vec::with_capacity(nt + 1);
        off.push(0);
        let mut pts = Vec::new();
        let mut tet = Vec::new();
        for (t, l) in lists.into_iter().enumerate() {
            tet.extend(std::iter::repeat_n(t as u32, l.len()));
            pts.extend(l);
            off.push(pts.len());
        }
        let mut cl = Classes {
            off,
            pts,
            tet,
            class_of: Vec::new(),
            rep: Vec::new(),
            unmatched: 0,
        };
        let n = cl.pts.len();
        assert!(n < u32::MAX as usize, "too many grid points for u32 ids");
        // Pairs of nodes that are one point.
        let pairs: Vec<(u32, Option<u32>)> = (0..n)
            .into_par_iter()
            .flat_map_iter(|k| {
                let cl = &cl;
                let t = cl.tet[k] as usize;
                self.partners(t, cl.pts[k])
                    .map(move |(s, e)| (k as u32, cl.find(s, e).map(|j| j as u32)))
            })
            .collect();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        for (a, b) in pairs {
            let Some(b) = b else {
                cl.unmatched += 1;
                continue;
            };
            let (ra, rb) = (uf_find(&mut parent, a), uf_find(&mut parent, b));
            if ra != rb {
                let (lo, hi) = (ra.min(rb), ra.max(rb));
                parent[hi as usize] = lo;
            }
        }
        // Classes in the order of their first node; the root is the smallest node.
        let mut class_of = vec![0u32; n];
        let mut classes = 0u32;
        for k in 0..n {
            let r = uf_find(&mut parent, k as u32) as usize;
            if r == k {
                class_of[k] = classes;
                classes += 1;
            } else {
                class_of[k] = class_of[r];
            }
        }
        let score: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|k| {
                let l = self.charts[cl.tet[k] as usize].bary(half(cl.pts[k]));
                l.into_iter().fold(f64::INFINITY, f64::min)
            })
            .collect();
        let mut rep = vec![u32::MAX; classes as usize];
        for k in 0..n {
            let c = class_of[k] as usize;
            if rep[c] == u32::MAX || score[k] > score[rep[c] as usize] {
                rep[c] = k as u32;
            }
        }
        cl.class_of = class_of;
        cl.rep = rep;
        Ok(cl)
    }

    /// The position in space of node `k` of `cl`.
    pub(super) fn position(&self, cl: &Classes, k: usize) -> [f64; 3] {
        let t = cl.tet[k] as usize;
        let l = self.charts[t].bary(half(cl.pts[k])).map(|x| x.max(0.0));
        let s: f64 = l.iter().sum();
        let corners = self.mesh.corners(t);
        let mut x = [0.0; 3];
        for i in 0..4 {
            let w = if s > 0.0 { l[i] / s } else { 0.25 };
            for k in 0..3 {
                x[k] += w * corners[i][k];
            }
        }
        x
    }
}
