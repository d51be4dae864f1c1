//! Hexahedra from an integer-grid map: the extraction step of CubeCover (Nieser, Reitebuch,
//! Polthier, "CubeCover — parameterization of 3D volumes", SGP 2011, §3.2), in the spirit of
//! HexEx (Lyon, Bommes, Kobbelt, "HexEx: robust hexahedral mesh extraction", SIGGRAPH 2016)
//! but with a simpler scheme that is exact for a valid map: one in which every tetrahedron
//! keeps its orientation in parameter space and the transitions are consistent.
//!
//! The map ([`GridMap`]) is linear in each tetrahedron; its chart gives the parameters
//! `(u, v, w)` of the tetrahedron's four corners, and the transition across each interior
//! face (`x_neighbour = R · x + shift`, `R` a cube rotation, `shift` integer) carries points
//! into the neighbour's chart. The integer grid pulled back by the map is the hexahedral mesh.
//!
//! # Method
//!
//! 1. **Charts.** Each tetrahedron's parameter-space volume decides whether it can be used:
//!    with `D` the largest edge of the tetrahedron in parameter space, a volume below
//!    `−`[`DEGENERATE_PARAM_VOLUME`]` · D³` is *flipped*, one within `±` that bound is
//!    *degenerate*. Both are reported by index ([`ExtractReport::flipped_tets`],
//!    [`ExtractReport::degenerate_tets`]); no grid point is taken from them, and a walk
//!    (step 3) that has to enter one stops the extraction with
//!    [`ExtractError::InvalidTetCrossed`], naming it. Points are tested against a
//!    tetrahedron with a tolerance `ε = `[`REL_EPS`]` · D + 1e-13 · max|uvw|` on the signed
//!    distance to each face plane in parameter space.
//! 2. **Grid points.** Every integer point `q` of a tetrahedron's chart inside or on it is a
//!    node `(t, q)`; a node on face `i` (within `ε`) is the same point as the node
//!    `(s, T q)` of the neighbour `s` across it (`T` the face's transition), so union-find
//!    over these pairs groups the nodes into the mesh's vertices (a point on an edge or a
//!    vertex of the tetrahedral mesh, singular edges included, joins the nodes of all the
//!    tetrahedra around it through their shared faces). A partner missing because of
//!    rounding is added to the neighbour. Each vertex lies where its most interior node
//!    (largest smallest barycentric coordinate, ties to the lowest tetrahedron) puts it: the
//!    barycentric interpolation of `q` in that tetrahedron in space. The same is done for
//!    the half-integer points (all coordinates in `ℤ + ½`), the centres of the grid's unit
//!    cubes, so that a centre on a shared face, edge or vertex is one centre.
//! 3. **Hexahedra.** From each cube centre `c` (its most interior node `(t, c)`), eight walks
//!    follow the straight segments from `c` to the corners `c + (±½, ±½, ±½)` in VTK order,
//!    `(−,−,−), (+,−,−), (+,+,−), (−,+,−), (−,−,+), (+,−,+), (+,+,+), (−,+,+)`, which is
//!    positively oriented in the chart. A walk stops in the first tetrahedron that contains
//!    the corner (within `ε`), whose node there names the vertex; otherwise it leaves the
//!    tetrahedron through the face the segment crosses first, applying the face's transition
//!    to the current point and to the corner. The open cube contains no singular edge of a
//!    valid CubeCover map (they lie on integer lines), so every path inside it reaches the
//!    same vertex. Passing exactly through a tetrahedron's edge or vertex is resolved by a
//!    fixed tie-break (the face crossed first; among faces crossed at the same point an
//!    interior face before a boundary face, then the face the corner lies farthest beyond,
//!    then the lowest index; never straight back through the face just entered unless it is
//!    the only one left). A walk that has not arrived after [`MAX_WALK_STEPS`] steps is
//!    retried along two legs through a fixed generic point inside the cube's octant; if that
//!    fails too the walk is counted as failed ([`ExtractReport::failed_walks`]) and its cube
//!    dropped. A walk that leaves through a boundary face means the cube is not inside the
//!    domain: it is counted as *partial* and gives no hexahedron (even when another of its
//!    walks met a flipped tetrahedron: only walks of cubes inside are needed).
//! 4. **Output.** The cubes are taken in the order of their centres (first node, by
//!    tetrahedron then doubled coordinates), the vertices renumbered in the order of their
//!    first node, keeping only those used by a hexahedron. A cube whose eight corners are not
//!    eight distinct vertices (a map that collapses it) is dropped and counted, as is a
//!    second cube with the same eight vertices.
//!
//! The stages run in parallel with rayon; results are gathered in index order and the
//! union-find runs sequentially, so the output is the same for any thread count.
//!
//! Points are handled in *doubled* integer coordinates (`2x`): integer points have all three
//! coordinates even, cube centres all three odd, and a transition acts exactly as
//! `2x ↦ R (2x) + 2 shift`.

use crate::geom::vec::{cross, dot, norm, sub};
use crate::mesh::{FACE_OPPOSITE, HexMesh, NO_TET, TetMesh, tet_neighbours};
use crate::param::{GridMap, Transition};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;

/// Relative tolerance of the point-in-tetrahedron test: a point counts as inside when its
/// signed distance to every face plane (parameter space) is at least `−REL_EPS · D`, `D` the
/// tetrahedron's largest edge in parameter space (plus a rounding allowance
/// `1e-13 · max|uvw|`).
pub const REL_EPS: f64 = 1e-9;

/// A tetrahedron whose parameter-space volume `V` satisfies `|V| ≤ DEGENERATE_PARAM_VOLUME ·
/// D³` (`D` its largest edge in parameter space) is degenerate; `V` below `−` that bound is
/// flipped.
pub const DEGENERATE_PARAM_VOLUME: f64 = 1e-12;

/// The most tetrahedra a single walk may cross before it counts as failed.
pub const MAX_WALK_STEPS: usize = 10_000;

/// The most candidate grid points a single tetrahedron's parameter bounding box may hold
/// (a guard against a broken map with enormous parameters).
pub const MAX_POINTS_PER_TET: u64 = 1 << 24;

/// Rounds of adding missing partners of face points (step 2 of the module docs).
const MAX_CLOSURE_ROUNDS: usize = 8;

/// The eight corners of a grid cube relative to its centre, doubled (`±1` is `±½`), in VTK
/// order.
pub const CUBE_CORNERS: [[i64; 3]; 8] = [
    [-1, -1, -1],
    [1, -1, -1],
    [1, 1, -1],
    [-1, 1, -1],
    [-1, -1, 1],
    [1, -1, 1],
    [1, 1, 1],
    [-1, 1, 1],
];

/// Why [`extract`] produced no mesh.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ExtractError {
    /// The map does not have one chart and one set of transitions per tetrahedron.
    #[error(
        "hex extraction: the map has {uvw} charts and {transitions} transition sets for {tets} \
         tetrahedra, expected one each"
    )]
    SizeMismatch {
        /// Tetrahedra in the mesh.
        tets: usize,
        /// Entries of [`GridMap::uvw`].
        uvw: usize,
        /// Entries of [`GridMap::transitions`].
        transitions: usize,
    },
    /// A tetrahedron names a vertex beyond the vertex list.
    #[error("hex extraction: tetrahedron {tet} names vertex {vertex}, but there are {count}")]
    VertexIndex {
        /// The tetrahedron.
        tet: usize,
        /// The vertex index it names.
        vertex: u32,
        /// Number of vertices.
        count: usize,
    },
    /// A chart holds a non-finite parameter.
    #[error("hex extraction: the chart of tetrahedron {tet} holds a non-finite parameter")]
    NonFiniteParam {
        /// The tetrahedron.
        tet: usize,
    },
    /// A face is shared by more than two tetrahedra.
    #[error("hex extraction: face {vertices:?} is shared by tetrahedra {tets:?} (non-manifold)")]
    NonManifoldFace {
        /// The face's vertices, ascending.
        vertices: [u32; 3],
        /// The tetrahedra on it.
        tets: Vec<u32>,
    },
    /// A transition names a rotation index outside `0..24`.
    #[error(
        "hex extraction: the transition of tetrahedron {tet} across face {face} has rotation index {rot}, expected 0..24"
    )]
    BadRotation {
        /// The tetrahedron.
        tet: usize,
        /// Its local face (opposite local vertex `face`).
        face: usize,
        /// The index found.
        rot: u8,
    },
    /// The transitions of the two sides of an interior face are not inverse to each other.
    #[error(
        "hex extraction: the transition of tetrahedron {tet} across face {face} into tetrahedron \
         {neighbour} is not the inverse of the one back"
    )]
    InconsistentTransition {
        /// The tetrahedron.
        tet: usize,
        /// Its local face.
        face: usize,
        /// The tetrahedron across it.
        neighbour: usize,
    },
    /// A tetrahedron's parameter bounding box holds too many grid points.
    #[error(
        "hex extraction: the parameter bounding box of tetrahedron {tet} holds about {points} grid \
         points, more than {MAX_POINTS_PER_TET}; the map's scale is broken"
    )]
    TooManyGridPoints {
        /// The tetrahedron.
        tet: usize,
        /// Candidate points in its box (saturating).
        points: u64,
    },
    /// A walk needed for a hexahedron entered a flipped or degenerate tetrahedron.
    #[error(
        "hex extraction: a walk from tetrahedron {from_tet} across its face {face} enters \
         tetrahedron {tet}, which is flipped or degenerate in parameter space (volume \
         {param_volume:e})"
    )]
    InvalidTetCrossed {
        /// The flipped or degenerate tetrahedron.
        tet: usize,
        /// The tetrahedron the walk came from.
        from_tet: usize,
        /// The local face of `from_tet` it crossed.
        face: usize,
        /// The parameter-space volume of `tet`.
        param_volume: f64,
    },
}

/// What [`extract`] found, besides the mesh.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ExtractReport {
    /// Integer grid points in the domain (vertices before unused ones are dropped).
    pub grid_vertices: usize,
    /// Vertices of the output mesh (those used by a hexahedron).
    pub vertices: usize,
    /// Cube centres (half-integer points) in the domain.
    pub cube_centres: usize,
    /// Hexahedra output.
    pub hexes: usize,
    /// Cubes whose centre is in the domain but that stick out of it (a walk left through a
    /// boundary face).
    pub partial_cubes: usize,
    /// Cubes dropped because a walk to one of their corners failed.
    pub failed_cubes: usize,
    /// Walks that failed (no arrival within [`MAX_WALK_STEPS`], on both paths tried).
    pub failed_walks: usize,
    /// Walks whose straight path failed and that were retried along two legs.
    pub retried_walks: usize,
    /// Cubes dropped because their corners are not eight distinct vertices.
    pub collapsed_cubes: usize,
    /// Cubes dropped because an earlier cube has the same eight vertices.
    pub duplicate_cubes: usize,
    /// Grid points on a face whose partner in the neighbour could not be matched (a map that
    /// is not seamless); 0 for a valid map.
    pub unmatched_face_points: usize,
    /// The most tetrahedra one walk crossed.
    pub max_walk_steps: usize,
    /// Tetrahedra with negative parameter-space volume, ascending.
    pub flipped_tets: Vec<u32>,
    /// Tetrahedra with (nearly) zero parameter-space volume, ascending.
    pub degenerate_tets: Vec<u32>,
}

fn half(d: [i64; 3]) -> [f64; 3] {
    d.map(|x| x as f64 * 0.5)
}

/// A transition acting on doubled coordinates: `2x ↦ R (2x) + 2 shift`.
fn apply_doubled(tr: &Transition, d: [i64; 3]) -> [i64; 3] {
    let r = tr.rot.apply_i(d);
    [0, 1, 2].map(|k| r[k] + 2 * i64::from(tr.shift[k]))
}

/// One tetrahedron in parameter space.
#[derive(Clone, Copy, Debug)]
struct Chart {
    /// Its corners' parameters.
    p: [[f64; 3]; 4],
    /// `λ_i(x) = g[i] · (x − p[FACE_OPPOSITE[i][0]])`, the barycentric coordinates.
    g: [[f64; 3]; 4],
    /// The tolerance on `λ_i`: `ε |g_i|` (a distance `ε` to face `i`).
    tol: [f64; 4],
    /// Absolute tolerance `ε` (parameter units).
    eps: f64,
    /// Signed volume.
    volume: f64,
    /// Largest edge.
    diam: f64,
    /// Whether the chart is usable (volume above the degenerate bound).
    valid: bool,
}

impl Chart {
    fn new(p: [[f64; 3]; 4]) -> Chart {
        let mut diam: f64 = 0.0;
        let mut maxabs: f64 = 0.0;
        for a in 0..4 {
            for k in 0..3 {
                maxabs = maxabs.max(p[a][k].abs());
            }
            for b in a + 1..4 {
                diam = diam.max(norm(sub(p[b], p[a])));
            }
        }
        let volume = crate::mesh::tet_volume(p[0], p[1], p[2], p[3]);
        let valid = volume > DEGENERATE_PARAM_VOLUME * diam * diam * diam && diam > 0.0;
        let eps = REL_EPS * diam + 1e-13 * maxabs;
        let mut g = [[0.0; 3]; 4];
        let mut tol = [0.0; 4];
        if valid {
            for (i, f) in FACE_OPPOSITE.iter().enumerate() {
                let n = cross(sub(p[f[1]], p[f[0]]), sub(p[f[2]], p[f[0]]));
                let h = dot(n, sub(p[i], p[f[0]]));
                g[i] = n.map(|x| x / h);
                tol[i] = eps * norm(g[i]);
            }
        }
        Chart {
            p,
            g,
            tol,
            eps,
            volume,
            diam,
            valid,
        }
    }

    fn bary(&self, x: [f64; 3]) -> [f64; 4] {
        [0, 1, 2, 3].map(|i| dot(self.g[i], sub(x, self.p[FACE_OPPOSITE[i][0]])))
    }

    fn contains(&self, l: &[f64; 4]) -> bool {
        (0..4).all(|i| l[i] >= -self.tol[i])
    }

    fn on_face(&self, l: &[f64; 4], i: usize) -> bool {
        l[i] <= self.tol[i]
    }

    /// The doubled integer points of the given parity (0: all even, 1: all odd) inside.
    fn points(&self, parity: i64, tet: usize) -> Result<Vec<[i64; 3]>, ExtractError> {
        let margin = 1e3 * self.eps;
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        let mut count: u64 = 1;
        for k in 0..3 {
            let mn = self.p.iter().map(|q| q[k]).fold(f64::INFINITY, f64::min) - margin;
            let mx = self
                .p
                .iter()
                .map(|q| q[k])
                .fold(f64::NEG_INFINITY, f64::max)
                + margin;
            let mut a = (2.0 * mn).ceil() as i64;
            if (a - parity).rem_euclid(2) != 0 {
                a += 1;
            }
            let b = (2.0 * mx).floor() as i64;
            lo[k] = a;
            hi[k] = b;
            let n = if b >= a { ((b - a) / 2 + 1) as u64 } else { 0 };
            count = count.saturating_mul(n);
        }
        if count > MAX_POINTS_PER_TET {
            return Err(ExtractError::TooManyGridPoints { tet, points: count });
        }
        let mut out = Vec::new();
        let mut d0 = lo[0];
        while d0 <= hi[0] {
            let mut d1 = lo[1];
            while d1 <= hi[1] {
                let mut d2 = lo[2];
                while d2 <= hi[2] {
                    let d = [d0, d1, d2];
                    if self.contains(&self.bary(half(d))) {
                        out.push(d);
                    }
                    d2 += 2;
                }
                d1 += 2;
            }
            d0 += 2;
        }
        Ok(out)
    }
}

/// The checked input: charts, neighbours and the face back from each neighbour.
struct Ctx<'a> {
    mesh: &'a TetMesh,
    map: &'a GridMap,
    charts: Vec<Chart>,
    nb: Vec<[u32; 4]>,
    /// `back[t][i]`: the local face of `nb[t][i]` that is face `i` of `t`.
    back: Vec<[u8; 4]>,
}

/// Points of one parity grouped into classes (vertices or cube centres).
struct Classes {
    /// Per tetrahedron, the range of its nodes in `pts`.
    off: Vec<usize>,
    /// Doubled coordinates of the nodes, ascending within each tetrahedron.
    pts: Vec<[i64; 3]>,
    /// The tetrahedron of each node.
    tet: Vec<u32>,
    /// The class of each node.
    class_of: Vec<u32>,
    /// The representative (most interior) node of each class.
    rep: Vec<u32>,
    /// Face points whose partner could not be matched.
    unmatched: usize,
}

impl Classes {
    fn find(&self, t: usize, d: [i64; 3]) -> Option<usize> {
        let (a, b) = (self.off[t], self.off[t + 1]);
        self.pts[a..b].binary_search(&d).ok().map(|k| a + k)
    }
}

fn uf_find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

impl Ctx<'_> {
    /// The partners `(neighbour, doubled point)` of a node across the faces it lies on.
    fn partners(&self, t: usize, d: [i64; 3]) -> impl Iterator<Item = (usize, [i64; 3])> + '_ {
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

    fn classes(&self, parity: i64) -> Result<Classes, ExtractError> {
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
    fn position(&self, cl: &Classes, k: usize) -> [f64; 3] {
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

/// Where a walk ended.
#[derive(Clone, Copy, Debug, PartialEq)]
enum WalkEnd {
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
enum CornerEnd {
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
enum CubeEnd {
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
    fn walk(
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
    fn corner(
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

/// Checks the input and builds the charts and the face adjacency.
fn context<'a>(mesh: &'a TetMesh, map: &'a GridMap) -> Result<Ctx<'a>, ExtractError> {
    let nt = mesh.tets.len();
    if map.uvw.len() != nt || map.transitions.len() != nt {
        return Err(ExtractError::SizeMismatch {
            tets: nt,
            uvw: map.uvw.len(),
            transitions: map.transitions.len(),
        });
    }
    for (t, tet) in mesh.tets.iter().enumerate() {
        if let Some(&v) = tet.iter().find(|&&v| v as usize >= mesh.verts.len()) {
            return Err(ExtractError::VertexIndex {
                tet: t,
                vertex: v,
                count: mesh.verts.len(),
            });
        }
        if map.uvw[t].iter().flatten().any(|x| !x.is_finite()) {
            return Err(ExtractError::NonFiniteParam { tet: t });
        }
        for (i, tr) in map.transitions[t].iter().enumerate() {
            if tr.rot.0 >= 24 {
                return Err(ExtractError::BadRotation {
                    tet: t,
                    face: i,
                    rot: tr.rot.0,
                });
            }
        }
    }
    let nb = tet_neighbours(mesh).map_err(|f| ExtractError::NonManifoldFace {
        vertices: f.vertices,
        tets: f.tets,
    })?;
    let mut back = vec![[0u8; 4]; nt];
    for t in 0..nt {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET {
                continue;
            }
            let s = s as usize;
            let mut key = FACE_OPPOSITE[i].map(|j| mesh.tets[t][j]);
            key.sort_unstable();
            let j = (0..4)
                .find(|&j| {
                    let mut k = FACE_OPPOSITE[j].map(|m| mesh.tets[s][m]);
                    k.sort_unstable();
                    k == key && nb[s][j] as usize == t
                })
                .expect("neighbours pair up");
            back[t][i] = j as u8;
            if map.transitions[s][j] != map.transitions[t][i].inverse() {
                return Err(ExtractError::InconsistentTransition {
                    tet: t,
                    face: i,
                    neighbour: s,
                });
            }
        }
    }
    let charts = map.uvw.par_iter().map(|&p| Chart::new(p)).collect();
    Ok(Ctx {
        mesh,
        map,
        charts,
        nb,
        back,
    })
}

/// Extracts the hexahedral mesh of an integer-grid map (see the module docs): the mesh, with
/// hexahedra in VTK order, and a report of what was found. Deterministic: the same input
/// gives the same output for any thread count.
///
/// # Errors
/// [`ExtractError`]: a map that does not fit the mesh, a non-manifold face, transitions that
/// are not inverse across a face, a chart with an enormous grid, or a walk needed for a
/// hexahedron that enters a flipped or degenerate tetrahedron (named).
pub fn extract(mesh: &TetMesh, map: &GridMap) -> Result<(HexMesh, ExtractReport), ExtractError> {
    let ctx = context(mesh, map)?;
    let mut report = ExtractReport::default();
    for (t, ch) in ctx.charts.iter().enumerate() {
        if !ch.valid {
            if ch.volume < -DEGENERATE_PARAM_VOLUME * ch.diam.powi(3) {
                report.flipped_tets.push(t as u32);
            } else {
                report.degenerate_tets.push(t as u32);
            }
        }
    }
    let verts = ctx.classes(0)?;
    let centres = ctx.classes(1)?;
    report.grid_vertices = verts.rep.len();
    report.cube_centres = centres.rep.len();
    report.unmatched_face_points = verts.unmatched + centres.unmatched;

    let ends: Vec<(CubeEnd, usize, usize, usize)> = centres
        .rep
        .par_iter()
        .map(|&k| {
            let mut max_steps = 0;
            let (mut failed, mut retried) = (0, 0);
            let mut corners = [0u32; 8];
            let (mut partial, mut bad, mut invalid) = (false, false, None);
            for (c, off) in CUBE_CORNERS.iter().enumerate() {
                let mut s = 0;
                let mut r = false;
                let end = ctx.corner(&centres, &verts, k as usize, *off, &mut s, &mut r);
                retried += usize::from(r);
                max_steps = max_steps.max(s);
                match end {
                    CornerEnd::Vertex(v) => corners[c] = v,
                    CornerEnd::Boundary => partial = true,
                    CornerEnd::Failed => {
                        bad = true;
                        failed += 1;
                    }
                    CornerEnd::Invalid {
                        tet,
                        from_tet,
                        face,
                    } => {
                        invalid.get_or_insert(CubeEnd::Invalid {
                            tet,
                            from_tet,
                            face,
                        });
                    }
                }
            }
            let end = if partial {
                CubeEnd::Partial
            } else if let Some(e) = invalid {
                e
            } else if bad {
                CubeEnd::Failed
            } else {
                CubeEnd::Hex(corners)
            };
            (end, failed, retried, max_steps)
        })
        .collect();

    let mut hexes: Vec<[u32; 8]> = Vec::new();
    let mut seen: HashSet<[u32; 8]> = HashSet::new();
    for (end, failed, retried, steps) in ends {
        report.failed_walks += failed;
        report.retried_walks += retried;
        report.max_walk_steps = report.max_walk_steps.max(steps);
        match end {
            CubeEnd::Hex(h) => {
                let mut key = h;
                key.sort_unstable();
                if key.windows(2).any(|w| w[0] == w[1]) {
                    report.collapsed_cubes += 1;
                } else if !seen.insert(key) {
                    report.duplicate_cubes += 1;
                } else {
                    hexes.push(h);
                }
            }
            CubeEnd::Partial => report.partial_cubes += 1,
            CubeEnd::Failed => report.failed_cubes += 1,
            CubeEnd::Invalid {
                tet,
                from_tet,
                face,
            } => {
                return Err(ExtractError::InvalidTetCrossed {
                    tet,
                    from_tet,
                    face,
                    param_volume: ctx.charts[tet].volume,
                });
            }
        }
    }

    // Keep the vertices used, in class order.
    let mut used = vec![false; verts.rep.len()];
    for h in &hexes {
        for &v in h {
            used[v as usize] = true;
        }
    }
    let mut new_id = vec![u32::MAX; verts.rep.len()];
    let mut positions_of = Vec::new();
    for c in (0..used.len()).filter(|&c| used[c]) {
        new_id[c] = positions_of.len() as u32;
        positions_of.push(verts.rep[c] as usize);
    }
    let positions: Vec<[f64; 3]> = positions_of
        .par_iter()
        .map(|&k| ctx.position(&verts, k))
        .collect();
    for h in hexes.iter_mut() {
        for v in h.iter_mut() {
            *v = new_id[*v as usize];
        }
    }
    report.vertices = positions.len();
    report.hexes = hexes.len();
    Ok((
        HexMesh {
            verts: positions,
            hexes,
        },
        report,
    ))
}

/// Test meshes and maps shared with the relaxation tests.
#[cfg(test)]
pub(crate) mod fixtures;

#[cfg(test)]
mod tests;
