//! Step 3 of the module docs of [`super`]: the walks from a cube centre to its eight corners
//! through the tetrahedra, crossing faces by their transitions, with the fixed tie-break at
//! edges and vertices and the two-leg retry; how a walk, a corner and a cube ended.

use super::MAX_WALK_STEPS;
use super::chart::{Ctx, apply_doubled, half};
use super::points::Classes;
use crate::geom::vec::norm;
use crate::mesh::NO_TET;

/// Where a walk ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum WalkEnd {
    /// In tetrahedron `t` at the target `p` (its chart); `target` the target's doubled
    /// coordinates there when it is a grid point, `carry` the carried point's.
    Arrived {
        t: usize,
        p: [f64; 3],
        target: Option<[i64; 3]>,
        carry: Option<[i64; 3]>,
    },
    /// Left the domain through a boundary face.
    Boundary,
    /// No arrival within [`MAX_WALK_STEPS`].
    Failed,
    /// Entered a flipped or degenerate tetrahedron.
    Invalid {
        tet: usize,
        from_tet: usize,
        face: usize,
    },
}

/// How a corner walk ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum CornerEnd {
    Vertex(u32),
    Boundary,
    Failed,
    Invalid {
        tet: usize,
        from_tet: usize,
        face: usize,
    },
}

/// What became of one cube.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum CubeEnd {
    Hex([u32; 8]),
    Partial,
    Failed,
    Invalid {
        tet: usize,
        from_tet: usize,
        face: usize,
    },
}

impl Ctx<'_> {
    /// Walks from `p` in tetrahedron `t` along the straight segment to `q`. `qd`: the
    /// target's doubled coordinates when it is a grid point, carried exactly across
    /// transitions; `carry`: another grid point carried along (for a two-leg walk).
    pub(super) fn walk(
        &self,
        mut t: usize,
        mut p: [f64; 3],
        mut q: [f64; 3],
        mut qd: Option<[i64; 3]>,
        mut carry: Option<[i64; 3]>,
        steps: &mut usize,
    ) -> WalkEnd {
        let mut entry: Option<usize> = None;
        for _ in 0..MAX_WALK_STEPS {
            let ch = &self.charts[t];
            let lq = ch.bary(q);
            if ch.contains(&lq) {
                return WalkEnd::Arrived {
                    t,
                    p: q,
                    target: qd,
                    carry,
                };
            }
            let lp = ch.bary(p);
            // Candidate exits: the faces the target lies beyond, not the one just entered
            // unless it is the only one.
            let mut cand = [false; 4];
            for i in 0..4 {
                cand[i] = lq[i] < -ch.tol[i];
            }
            if let Some(e) = entry
                && (0..4).any(|i| cand[i] && i != e)
            {
                cand[e] = false;
            }
            let s_of = |i: usize| {
                let a = lp[i].max(0.0);
                a / (a - lq[i])
            };
            let smin = (0..4)
                .filter(|&i| cand[i])
                .map(s_of)
                .fold(f64::INFINITY, f64::min);
            let boundary = |i: usize| self.nb[t][i] == NO_TET;
            let beyond = |i: usize| lq[i] / norm(ch.g[i]);
            let Some(i) = (0..4)
                .filter(|&i| cand[i] && s_of(i) <= smin + 1e-12)
                .min_by(|&a, &b| {
                    boundary(a)
                        .cmp(&boundary(b))
                        .then(beyond(a).total_cmp(&beyond(b)))
                        .then(a.cmp(&b))
                })
            else {
                return WalkEnd::Failed;
            };
            let s = s_of(i);
            let n = self.nb[t][i];
            if n == NO_TET {
                return WalkEnd::Boundary;
            }
            let n = n as usize;
            if !self.charts[n].valid {
                return WalkEnd::Invalid {
                    tet: n,
                    from_tet: t,
                    face: i,
                };
            }
            let x = [0, 1, 2].map(|k| p[k] + s * (q[k] - p[k]));
            let tr = &self.map.transitions[t][i];
            p = tr.apply(x);
            q = match qd {
                Some(d) => {
                    let e = apply_doubled(tr, d);
                    qd = Some(e);
                    half(e)
                }
                None => tr.apply(q),
            };
            carry = carry.map(|d| apply_doubled(tr, d));
            entry = Some(self.back[t][i] as usize);
            t = n;
            *steps += 1;
        }
        WalkEnd::Failed
    }

    /// Where the walk from the centre node `k` of `centres` to its corner `corner` (doubled
    /// offset) ends.
    pub(super) fn corner(
        &self,
        centres: &Classes,
        verts: &Classes,
        k: usize,
        corner: [i64; 3],
        steps: &mut usize,
        retried: &mut bool,
    ) -> CornerEnd {
        let t = centres.tet[k] as usize;
        let c = centres.pts[k];
        let target = [0, 1, 2].map(|j| c[j] + corner[j]);
        let mut end = self.walk(t, half(c), half(target), Some(target), None, steps);
        if end == WalkEnd::Failed {
            *retried = true;
            // Two legs through a generic point inside the cube's octant, carrying the corner
            // along the first.
            const GENERIC: [f64; 3] = [0.543_656, 0.628_318, 0.323_606];
            let m = [0, 1, 2].map(|j| half(c)[j] + 0.5 * corner[j] as f64 * GENERIC[j]);
            end = match self.walk(t, half(c), m, None, Some(target), steps) {
                WalkEnd::Arrived {
                    t: t1,
                    p: m1,
                    carry: Some(tg),
                    ..
                } => self.walk(t1, m1, half(tg), Some(tg), None, steps),
                other => other,
            };
        }
        match end {
            WalkEnd::Arrived {
                t, target: Some(d), ..
            } => match verts.find(t, d) {
                Some(j) => CornerEnd::Vertex(verts.class_of[j]),
                None => CornerEnd::Failed,
            },
            WalkEnd::Arrived { target: None, .. } | WalkEnd::Failed => CornerEnd::Failed,
            WalkEnd::Boundary => CornerEnd::Boundary,
            WalkEnd::Invalid {
                tet,
                from_tet,
                face,
            } => CornerEnd::Invalid {
                tet,
                from_tet,
                face,
            },
        }
    }
}
