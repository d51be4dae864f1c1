//! Isosurface stuffing: a tetrahedral mesh of the solid `{p : f(p) ≤ 0}` with bounded
//! dihedral angles, after F. Labelle and J. R. Shewchuk, "Isosurface Stuffing: Fast
//! Tetrahedral Meshes with Good Dihedral Angles", ACM Trans. Graph. 26(3) (SIGGRAPH 2007).
//!
//! # Sign convention
//!
//! `f` is **negative inside, positive outside**, zero on the surface (a signed distance is
//! ideal but any continuous function with that sign works; `0.5 − w` for a generalised winding
//! number `w` works too, though it jumps at the surface, see [`crate::winding`]). A lattice
//! vertex where `f` is exactly 0 is treated as inside ("−"); the root finder then puts the cut
//! point of any edge from it to an outside vertex on the vertex itself, which warping snaps to,
//! so the vertex ends on the surface ("0") where the surface leaves it, as the paper intends
//! (§3: a vertex is +, − or 0). No other perturbation is applied.
//!
//! # The algorithm (paper §3, uniform lattice)
//!
//! 1. **The BCC lattice** (§3, Fig. 2). *Black* vertices at the corners of a cubic grid of
//!    spacing `h`, *red* vertices at the cube centres. Edges join a black to its six black
//!    grid neighbours and a red to its six red ones (*long* edges, length `h`, axis-parallel),
//!    and each red to the eight black corners of its cube (*short* edges, `√3 h / 2`). Every
//!    BCC tetrahedron joins two adjacent cube centres (a red–red edge) to the two endpoints of
//!    one edge of the square face the two cubes share (a black–black edge): 4 per interior
//!    face, 3 faces per cube, **12 per cube**. Each has two long edges (opposite each other,
//!    dihedral angle 90°) and four short ones (60°). Here the lattice covers the given box
//!    plus one cube on every side; only the tetrahedra around interior cube faces exist.
//! 2. **Signs and cut points**. `f` is sampled at every lattice vertex (in parallel). Each
//!    edge with a − and a + end gets a *cut point*, the root of `f` along the edge, found by
//!    the Illinois variant of regula falsi with a bisection every third step, keeping a
//!    bracket: it stops when the bracket is at most [`StuffingParams::root_tol`] edge lengths
//!    wide (default 1e-6) or `f` is exactly 0, after at most
//!    [`StuffingParams::max_root_iter`] evaluations (default 64, never reached by the default
//!    tolerance since bisection alone gets there in 3 · 20 steps).
//! 3. **Warping** (§3). A lattice vertex `v` is *violated* by a cut point on one of its edges
//!    that lies closer to `v` than `α` times the edge's length: `α_long` = 0.24999 for long
//!    edges, `α_short` = 0.41189 for short ones, the paper's values (the pair for which it
//!    proves the 10.7°–164.8° bounds). A violated vertex moves to the *closest* violating
//!    cut point (ties broken by the edge's key), becomes a 0 vertex, and every cut point on
//!    its edges is discarded. The α values trade how far a vertex may move (along one edge,
//!    at most α of its length) against how close a surviving cut point may be to an unwarped
//!    vertex (at least α of the edge), which together bound the stencils' angles. All
//!    violations are found from the cut points as first computed and applied together, so the
//!    result does not depend on an order of visiting vertices (a cut point on an edge whose
//!    other end also warped is discarded as well; each vertex still moves at most α along one
//!    edge, the configuration the paper's bounds cover).
//! 4. **Stencils** (§3, Fig. 3). Each BCC tetrahedron, by the signs of its vertices after
//!    warping, is filled with the part of it that lies inside, as tetrahedra on its vertices
//!    and cut points:
//!    * no + vertex and at least one −: the whole tetrahedron;
//!    * one +, three −: a triangular prism (the three − vertices and the three cut points),
//!      3 tetrahedra;
//!    * one +, two −, one 0: a pyramid with apex the 0 vertex, 2 tetrahedra;
//!    * one +, one −, two 0: one tetrahedron (the cut point replaces the + vertex);
//!    * two +, two −: a prism on the four cut points and the − edge, 3 tetrahedra;
//!    * two +, one −, one 0: one tetrahedron;
//!    * three +, one −: one tetrahedron (the − vertex and three cut points);
//!    * otherwise (no − vertex): nothing. This includes a tetrahedron whose four vertices
//!      are all 0 (all warped onto the surface): no part of it is known to lie inside, and
//!      its shape is not controlled, its corners being on the surface: it is thin where the
//!      surface is flat across it and can be badly shaped where the surface curves around
//!      it. Keeping such tetrahedra (say, by the sign of `f` at the centroid) produced
//!      dihedral angles of 8.7° and 167.6° on the tests' random fields, outside the paper's
//!      bounds, which cover what the stencils output. Dropping one keeps the mesh
//!      conforming: each of its faces is a whole lattice face with three 0 corners, and the
//!      neighbour across it is either output whole (its fourth corner is −; the face becomes
//!      a boundary face on the surface) or not at all. The count is reported
//!      ([`StuffingReport::surface_tets_dropped`]).
//!
//!    A *quadrilateral* appears on a lattice face with two − vertices `u`, `v` and one +
//!    vertex `w`: `u, v` and the cut points on `uw` and `vw`. It is split by the diagonal
//!    from one of `u`, `v` to the cut point on the other's edge, and both tetrahedra sharing
//!    the face must choose alike, so the choice depends on the face alone:
//!    * when `uv` is a short edge, one of `u`, `v` has `w`'s colour (they span the face's
//!      long edge); the diagonal leaves the *other* one (the vertex not on the long edge) and
//!      ends at the cut point on the long edge. (The other colour rule, the diagonal leaving
//!      the vertex on the long edge, is not the paper's: on the tests' random fields it gave
//!      a dihedral angle of 10.34°, below the bound, so it is not offered.)
//!    * when `uv` is a long edge (`u`, `v` of one colour), colour cannot decide, and the
//!      **parity rule** does: the diagonal leaves whichever of `u`, `v` has an even lattice
//!      index along the edge's axis. The BCC tetrahedron is symmetric under the mirror that
//!      swaps `u` and `v`, so both parities give the same angles.
//!
//!    With these rules the three quadrilaterals of a one-+ prism never form a cycle, and in a
//!    two-+ prism the quadrilateral on the isosurface (shared with no other tetrahedron) takes
//!    the diagonal that avoids a cycle, or the shorter one when both do. Every output
//!    tetrahedron is oriented positively by its sign in a reference configuration (cut points
//!    at edge midpoints, vertices unwarped; exact integer arithmetic), which the warped one
//!    shares when the α values are the paper's (checked with `debug_assert!` and in tests).
//!
//! The output is conforming (a lattice face is split the same way from both sides) and its
//! boundary is a closed triangulated surface of cut points and warped vertices, all on the
//! zero set to the root tolerance, unless the solid reaches the lattice's border (then the
//! lattice's own faces close it there).
//!
//! # Dihedral angles
//!
//! The paper proves, by a computer-assisted case analysis over the stencils, that with the α
//! values above every output dihedral angle θ of the uniformly sized mesh satisfies
//! 10.7° ≤ θ ≤ 164.8° (8.9°–158.8° with another pair of α values; both stated in its
//! abstract). The tests check these bounds on every mesh they build: spheres, a torus, boxes
//! with sharp corners or faces on lattice planes, a winding-number sphere and ten
//! high-frequency random fields, which produce every stencil with cut points all over their
//! allowed ranges. Measured over the random fields: 11.47°–156.90°
//! (`dihedral_bounds_on_random_fields`) and 11.69°–155.84°
//! (`dihedral_bounds_on_more_random_fields`).
//!
//! # Not implemented: the graded (octree) lattice
//!
//! The paper also grades the lattice with a balanced octree that is fine near the surface and
//! coarse inside, with extra stencils where cells of two sizes meet; near the surface, where
//! the cutting and warping happen, that lattice is the uniform one. That variant is **not
//! built**: only the uniform lattice, complete and tested, is offered. Meshes are therefore
//! uniform with edge length about `h`; their size grows as `(extent / h)³`.
//!
//! # Output, determinism and memory
//!
//! Vertices are the lattice vertices used (warped or not) followed by the cut points, each
//! group in the order of its lattice key (vertex id; edge as the pair of vertex ids), and
//! only those some tetrahedron references. Cut points are keyed by their lattice edge, so
//! neighbouring stencils share them. Tetrahedra come in lattice order. Everything runs in
//! parallel (rayon) and is identical for any thread count: per-item work is independent and
//! collected in order, and the only float sums (volume) are taken in a fixed order.
//!
//! Memory: [`LATTICE_BYTES_PER_VERTEX`] bytes per lattice vertex (its `f` value and its
//! sign), plus per cut point and warped vertex about 60 bytes, plus the output. Callers cap
//! the lattice with [`StuffingParams::max_lattice_vertices`] from their memory budget; the
//! lattice has about `2 (extent / h)³` vertices.

use rayon::prelude::*;

use crate::mesh::{TetMesh, tet_volume};

/// The paper's α for long (black–black, red–red) edges.
pub const ALPHA_LONG: f64 = 0.24999;
/// The paper's α for short (black–red) edges.
pub const ALPHA_SHORT: f64 = 0.41189;
/// Bytes of working memory per lattice vertex: its `f` value (8) and its sign (1).
pub const LATTICE_BYTES_PER_VERTEX: u64 = 9;

/// Parameters of [`stuff`].
#[derive(Clone, Debug, PartialEq)]
pub struct StuffingParams {
    /// Lattice spacing: the edge of the lattice cubes (long edges have this length, short
    /// ones `√3/2` of it), the target edge length. Cutting and warping shorten or lengthen
    /// the edges near the surface: measured between `0.25 h` and `1.56 h` on the tests'
    /// random fields, `0.34 h` to `1.24 h` on a sphere.
    pub h: f64,
    /// α for long edges (default [`ALPHA_LONG`]); in `(0, 0.5)`.
    pub alpha_long: f64,
    /// α for short edges (default [`ALPHA_SHORT`]); in `(0, 0.5)`.
    pub alpha_short: f64,
    /// Most lattice vertices allowed (black and red); more is [`StuffingError::TooLarge`].
    /// Derive it from a memory budget with [`LATTICE_BYTES_PER_VERTEX`].
    pub max_lattice_vertices: u64,
    /// Root-finding tolerance: the bracket around a cut point is narrowed to at most this
    /// many edge lengths (default 1e-6).
    pub root_tol: f64,
    /// Most evaluations of `f` per cut point (default 64).
    pub max_root_iter: u32,
}

impl StuffingParams {
    /// Spacing `h` with the paper's α values, at most 100 million lattice vertices, root
    /// tolerance 1e-6 and at most 64 evaluations per cut point.
    pub fn new(h: f64) -> StuffingParams {
        StuffingParams {
            h,
            alpha_long: ALPHA_LONG,
            alpha_short: ALPHA_SHORT,
            max_lattice_vertices: 100_000_000,
            root_tol: 1e-6,
            max_root_iter: 64,
        }
    }
}

/// What [`stuff`] built.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StuffingReport {
    /// Output tetrahedra.
    pub tets: usize,
    /// Output vertices.
    pub vertices: usize,
    /// Lattice vertices (black and red) sampled.
    pub lattice_vertices: u64,
    /// Cut points that survived warping (each an output vertex on the surface, if used).
    pub cut_points: usize,
    /// Lattice vertices snapped to a cut point.
    pub warped_vertices: usize,
    /// BCC tetrahedra left out because all four of their corners were warped onto the
    /// surface (see the module docs).
    pub surface_tets_dropped: usize,
    /// Smallest dihedral angle of the output, degrees.
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle of the output, degrees.
    pub max_dihedral_deg: f64,
    /// Total volume of the output tetrahedra.
    pub volume: f64,
}

/// Why [`stuff`] produced no mesh.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StuffingError {
    /// A parameter or the box is out of range; the message says which and what was expected.
    #[error("isosurface stuffing: {0}")]
    BadInput(String),
    /// The lattice would have more vertices than allowed.
    #[error(
        "isosurface stuffing: the lattice would have {needed} vertices, more than the {limit} allowed \
         ({} bytes each); use a larger spacing h or a larger budget",
        LATTICE_BYTES_PER_VERTEX
    )]
    TooLarge {
        /// Lattice vertices needed (saturating).
        needed: u64,
        /// The limit ([`StuffingParams::max_lattice_vertices`]).
        limit: u64,
    },
    /// `f` returned NaN at a lattice vertex.
    #[error("isosurface stuffing: f is NaN at ({}, {}, {}), expected a number", .at[0], .at[1], .at[2])]
    NotANumber {
        /// Where.
        at: [f64; 3],
    },
    /// No lattice vertex is inside (`f ≤ 0`): the solid is empty or thinner than the lattice.
    #[error(
        "isosurface stuffing: no lattice vertex is inside (f <= 0) at spacing h = {h}: the solid is \
         empty, outside the box, or thinner than the lattice; use a smaller h"
    )]
    NothingInside {
        /// The spacing used.
        h: f64,
    },
}

/// The lattice: cubes `n[0] × n[1] × n[2]` of edge `h` from `origin`; black ids first
/// (`(n + 1)³` grid corners), then red ids (cube centres).
#[derive(Clone, Debug)]
struct Lattice {
    n: [usize; 3],
    origin: [f64; 3],
    h: f64,
    blacks: usize,
    total: usize,
}

/// Sign of a lattice vertex after warping.
const NEG: i8 = -1;
const ZERO: i8 = 0;
const POS: i8 = 1;

/// Output-vertex key of a lattice vertex (low half all ones) or of a cut point on the edge
/// `(a, b)`, `a < b` (ids fit in 32 bits and stay below `u32::MAX`).
fn lkey(v: u32) -> u64 {
    ((v as u64) << 32) | 0xFFFF_FFFF
}
fn ckey(a: u32, b: u32) -> u64 {
    let (a, b) = if a < b { (a, b) } else { (b, a) };
    ((a as u64) << 32) | b as u64
}

impl Lattice {
    fn black(&self, i: usize, j: usize, k: usize) -> u32 {
        (i + (self.n[0] + 1) * (j + (self.n[1] + 1) * k)) as u32
    }
    fn red(&self, i: usize, j: usize, k: usize) -> u32 {
        (self.blacks + i + self.n[0] * (j + self.n[1] * k)) as u32
    }
    fn is_red(&self, v: u32) -> bool {
        v as usize >= self.blacks
    }
    /// Doubled integer coordinates: black `(2i, 2j, 2k)`, red `(2i + 1, 2j + 1, 2k + 1)`.
    fn doubled(&self, v: u32) -> [i64; 3] {
        let v = v as usize;
        if v < self.blacks {
            let (nx, ny) = (self.n[0] + 1, self.n[1] + 1);
            [
                2 * (v % nx) as i64,
                2 * ((v / nx) % ny) as i64,
                2 * (v / (nx * ny)) as i64,
            ]
        } else {
            let r = v - self.blacks;
            let (nx, ny) = (self.n[0], self.n[1]);
            [
                2 * (r % nx) as i64 + 1,
                2 * ((r / nx) % ny) as i64 + 1,
                2 * (r / (nx * ny)) as i64 + 1,
            ]
        }
    }
    fn pos(&self, v: u32) -> [f64; 3] {
        let d = self.doubled(v);
        [0, 1, 2].map(|a| self.origin[a] + d[a] as f64 * 0.5 * self.h)
    }
    /// The lattice neighbours of `v` (6 long, up to 8 short), into `out`; returns the count.
    fn neighbours(&self, v: u32, out: &mut [u32; 14]) -> usize {
        let d = self.doubled(v);
        let mut c = 0;
        let n = self.n;
        if !self.is_red(v) {
            let ijk = d.map(|x| (x / 2) as usize);
            for a in 0..3 {
                for s in [-1i64, 1] {
                    let x = ijk[a] as i64 + s;
                    if x >= 0 && x <= n[a] as i64 {
                        let mut q = ijk;
                        q[a] = x as usize;
                        out[c] = self.black(q[0], q[1], q[2]);
                        c += 1;
                    }
                }
            }
            for di in 0..2 {
                for dj in 0..2 {
                    for dk in 0..2 {
                        let q = [ijk[0] as i64 - di, ijk[1] as i64 - dj, ijk[2] as i64 - dk];
                        if (0..3).all(|a| q[a] >= 0 && q[a] < n[a] as i64) {
                            out[c] = self.red(q[0] as usize, q[1] as usize, q[2] as usize);
                            c += 1;
                        }
                    }
                }
            }
        } else {
            let ijk = d.map(|x| ((x - 1) / 2) as usize);
            for a in 0..3 {
                for s in [-1i64, 1] {
                    let x = ijk[a] as i64 + s;
                    if x >= 0 && x < n[a] as i64 {
                        let mut q = ijk;
                        q[a] = x as usize;
                        out[c] = self.red(q[0], q[1], q[2]);
                        c += 1;
                    }
                }
            }
            for di in 0..2 {
                for dj in 0..2 {
                    for dk in 0..2 {
                        out[c] = self.black(ijk[0] + di, ijk[1] + dj, ijk[2] + dk);
                        c += 1;
                    }
                }
            }
        }
        c
    }
    /// Long edge (same colour) or short.
    fn is_long(&self, a: u32, b: u32) -> bool {
        self.is_red(a) == self.is_red(b)
    }
    fn edge_len(&self, a: u32, b: u32) -> f64 {
        if self.is_long(a, b) {
            self.h
        } else {
            self.h * 3f64.sqrt() * 0.5
        }
    }
    /// Reference position (4× the lattice's half-units) of an output key: a lattice vertex
    /// at its lattice place, a cut point at its edge's midpoint.
    fn reference(&self, key: u64) -> [i64; 3] {
        let a = (key >> 32) as u32;
        let b = key as u32;
        let da = self.doubled(a);
        if b == u32::MAX {
            da.map(|x| 2 * x)
        } else {
            let db = self.doubled(b);
            [da[0] + db[0], da[1] + db[1], da[2] + db[2]]
        }
    }
}

fn det_i(a: [i64; 3], b: [i64; 3], c: [i64; 3], d: [i64; 3]) -> i64 {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0])
}

/// The state the stencils read: signs after warping, surviving cut points and warps.
struct Stencils<'a> {
    lat: &'a Lattice,
    sign: &'a [i8],
    /// Surviving cut points by edge key, sorted.
    cuts: &'a [(u64, [f64; 3])],
    /// Warped vertices and where they went, sorted.
    warps: &'a [(u32, [f64; 3])],
}

impl Stencils<'_> {
    fn vertex_pos(&self, v: u32) -> [f64; 3] {
        match self.warps.binary_search_by_key(&v, |w| w.0) {
            Ok(i) => self.warps[i].1,
            Err(_) => self.lat.pos(v),
        }
    }
    fn key_pos(&self, key: u64) -> [f64; 3] {
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
    fn quad_pick(&self, w: u32, u: u32, v: u32) -> u32 {
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
    fn emit(&self, t: [u64; 4], out: &mut Vec<[u64; 4]>) {
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
    fn prism(&self, a: [u64; 3], b: [u64; 3], choice: [usize; 3], out: &mut Vec<[u64; 4]>) {
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
    fn fill(&self, t: [u32; 4], out: &mut Vec<[u64; 4]>) -> bool {
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

/// The root of `f` on the segment `a`–`b` as a parameter in `[0, 1]` from `a`, where
/// `fa = f(a) ≤ 0 < fb = f(b)`: Illinois regula falsi with a bisection every third step.
fn root(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    a: [f64; 3],
    b: [f64; 3],
    fa: f64,
    fb: f64,
    tol: f64,
    max_iter: u32,
) -> f64 {
    if fa == 0.0 {
        return 0.0;
    }
    let (mut lo, mut hi, mut flo, mut fhi) = (0.0f64, 1.0f64, fa, fb);
    let mut side = 0i8;
    for it in 0..max_iter {
        if hi - lo <= tol {
            break;
        }
        let mid = 0.5 * (lo + hi);
        let mut t = if it % 3 == 2 {
            mid
        } else {
            (lo * fhi - hi * flo) / (fhi - flo)
        };
        if t.is_nan() || t <= lo || t >= hi {
            t = mid;
        }
        let p = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
        let ft = f(p);
        if ft.is_nan() {
            return mid;
        }
        if ft == 0.0 {
            return t;
        }
        if ft < 0.0 {
            lo = t;
            flo = ft;
            if side == -1 {
                fhi *= 0.5;
            }
            side = -1;
        } else {
            hi = t;
            fhi = ft;
            if side == 1 {
                flo *= 0.5;
            }
            side = 1;
        }
    }
    let t = (lo * fhi - hi * flo) / (fhi - flo);
    if t >= lo && t <= hi {
        t
    } else {
        0.5 * (lo + hi)
    }
}

/// The smallest and largest dihedral angle of tetrahedron `c`, degrees.
fn dihedral_range(c: [[f64; 3]; 4]) -> (f64, f64) {
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
    let n = FACES.map(|[p, q, r]| {
        let u = [0, 1, 2].map(|k| c[q][k] - c[p][k]);
        let v = [0, 1, 2].map(|k| c[r][k] - c[p][k]);
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    });
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..4 {
        for j in i + 1..4 {
            // Interior angle along the edge shared by faces i and j: 180° − ∠(n_i, n_j).
            let d = n[i][0] * n[j][0] + n[i][1] * n[j][1] + n[i][2] * n[j][2];
            let x = [
                n[i][1] * n[j][2] - n[i][2] * n[j][1],
                n[i][2] * n[j][0] - n[i][0] * n[j][2],
                n[i][0] * n[j][1] - n[i][1] * n[j][0],
            ];
            let s = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            let ang = 180.0 - s.atan2(d).to_degrees();
            lo = lo.min(ang);
            hi = hi.max(ang);
        }
    }
    (lo, hi)
}

/// Stuff the solid `{p : f(p) ≤ 0}` lying in the box `bbox_min`–`bbox_max` with tetrahedra
/// (see the module docs).
///
/// * `f` is negative inside, positive outside and is called from several threads. It should
///   be positive on and outside the box's boundary: the lattice extends one cube beyond the
///   box, and where the solid reaches the lattice's border its boundary is closed by lattice
///   faces instead of the surface.
/// * `params.h` is the lattice spacing, the target edge length (see [`StuffingParams`]).
///
/// Returns the mesh, whose tetrahedra are positively oriented (see [`crate::mesh`]), and
/// a [`StuffingReport`] with its dihedral angle range and volume. Errors
/// ([`StuffingError`]) name what is wrong: a parameter or box out of range, a lattice larger
/// than [`StuffingParams::max_lattice_vertices`], `f` NaN at a lattice vertex (with the
/// place), or no lattice vertex inside.
///
/// # Example: a closed triangle mesh, by its winding number
///
/// A closed, outward-wound triangle mesh (say from [`crate::io::obj::read_obj`]) is stuffed
/// through `f(p) = 0.5 − w(p)`, `w` its generalised winding number
/// ([`crate::winding`]): about 1 inside, 0 outside, ½ on the surface.
///
/// ```
/// use scanflow_hex::stuffing::{StuffingParams, stuff};
/// use scanflow_hex::winding::WindingNumber;
///
/// // The octahedron |x| + |y| + |z| ≤ 1 (volume 4/3), wound counter-clockwise from outside.
/// let vertices = vec![
///     [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
///     [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0],
/// ];
/// let mut triangles = Vec::new();
/// for (x, sx) in [(0, 1), (1, -1)] {
///     for (y, sy) in [(2, 1), (3, -1)] {
///         for (z, sz) in [(4, 1), (5, -1)] {
///             triangles.push(if sx * sy * sz > 0 { [x, y, z] } else { [x, z, y] });
///         }
///     }
/// }
/// let w = WindingNumber::new(&vertices, &triangles)?;
/// let f = |p: [f64; 3]| 0.5 - w.eval(p);
/// let (mesh, report) = stuff(&f, [-1.0; 3], [1.0; 3], &StuffingParams::new(0.1))?;
/// assert_eq!(mesh.tets.len(), report.tets);
/// assert!((report.volume - 4.0 / 3.0).abs() < 0.02 * 4.0 / 3.0);
/// assert!(report.min_dihedral_deg >= 10.7 && report.max_dihedral_deg <= 164.8);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn stuff(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    bbox_min: [f64; 3],
    bbox_max: [f64; 3],
    params: &StuffingParams,
) -> Result<(TetMesh, StuffingReport), StuffingError> {
    let lat = lattice(bbox_min, bbox_max, params)?;
    let total = lat.total;
    let (values, mut sign) = signs(f, &lat, params)?;
    let mut cuts = cut_points(f, &lat, &values, &sign, params);
    drop(values);
    cuts.par_sort_unstable_by_key(|c| c.0);
    let (warps, cuts) = warp(&lat, cuts, &mut sign, params);
    let st = Stencils {
        lat: &lat,
        sign: &sign,
        cuts: &cuts,
        warps: &warps,
    };
    let (keyed, surface_tets_dropped) = stencil_tets(&st);
    let mesh = output_mesh(&st, &keyed);
    let (volume, lo, hi) = quality_and_volume(&mesh, params);
    let report = StuffingReport {
        tets: mesh.tets.len(),
        vertices: mesh.verts.len(),
        lattice_vertices: total as u64,
        cut_points: cuts.len(),
        warped_vertices: warps.len(),
        surface_tets_dropped,
        min_dihedral_deg: lo,
        max_dihedral_deg: hi,
        volume,
    };
    Ok((mesh, report))
}

/// Signs: `f` at every lattice vertex, and each vertex's sign (`NEG` where `f <= 0`).
fn signs(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    lat: &Lattice,
    params: &StuffingParams,
) -> Result<(Vec<f64>, Vec<i8>), StuffingError> {
    let total = lat.total;
    let values: Vec<f64> = (0..total as u32)
        .into_par_iter()
        .map(|v| f(lat.pos(v)))
        .collect();
    if let Some(v) = values.iter().position(|x| x.is_nan()) {
        return Err(StuffingError::NotANumber {
            at: lat.pos(v as u32),
        });
    }
    let sign: Vec<i8> = values
        .par_iter()
        .map(|&x| if x <= 0.0 { NEG } else { POS })
        .collect();
    if !sign.par_iter().any(|&s| s == NEG) {
        return Err(StuffingError::NothingInside { h: params.h });
    }
    Ok((values, sign))
}

/// Cut points on − to + edges, found from their − end: (key, parameter from the key's
/// smaller id, position), unsorted.
fn cut_points(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    lat: &Lattice,
    values: &[f64],
    sign: &[i8],
    params: &StuffingParams,
) -> Vec<(u64, f64, [f64; 3])> {
    let total = lat.total;
    (0..total as u32)
        .into_par_iter()
        .filter(|&v| sign[v as usize] == NEG)
        .flat_map_iter(|v| {
            let mut nb = [0u32; 14];
            let n = lat.neighbours(v, &mut nb);
            let mut found = Vec::new();
            for &u in &nb[..n] {
                if sign[u as usize] != POS {
                    continue;
                }
                let (pa, pb) = (lat.pos(v), lat.pos(u));
                let t = root(
                    f,
                    pa,
                    pb,
                    values[v as usize],
                    values[u as usize],
                    params.root_tol,
                    params.max_root_iter,
                );
                let p = [0, 1, 2].map(|k| pa[k] + t * (pb[k] - pa[k]));
                let t_min = if v < u { t } else { 1.0 - t };
                found.push((ckey(v, u), t_min, p));
            }
            found
        })
        .collect()
}

/// Warping: each violated vertex moves to its closest violating cut point and its sign
/// becomes `ZERO`. Returns the warps and the cut points left on edges between two unwarped
/// vertices (key, position); `cuts` comes sorted by key.
#[allow(clippy::type_complexity)]
fn warp(
    lat: &Lattice,
    cuts: Vec<(u64, f64, [f64; 3])>,
    sign: &mut [i8],
    params: &StuffingParams,
) -> (Vec<(u32, [f64; 3])>, Vec<(u64, [f64; 3])>) {
    let mut cand: Vec<(u32, f64, u64)> = cuts
        .par_iter()
        .flat_map_iter(|&(key, t_min, _)| {
            let (a, b) = ((key >> 32) as u32, key as u32);
            let len = lat.edge_len(a, b);
            let alpha = if lat.is_long(a, b) {
                params.alpha_long
            } else {
                params.alpha_short
            };
            let mut c = Vec::new();
            if t_min < alpha {
                c.push((a, t_min * len, key));
            } else if 1.0 - t_min < alpha {
                c.push((b, (1.0 - t_min) * len, key));
            }
            c
        })
        .collect();
    cand.par_sort_unstable_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)).then(x.2.cmp(&y.2)));
    let mut warps: Vec<(u32, [f64; 3])> = Vec::new();
    for (i, c) in cand.iter().enumerate() {
        if i > 0 && cand[i - 1].0 == c.0 {
            continue;
        }
        let at = cuts[cuts.binary_search_by_key(&c.2, |x| x.0).unwrap_or(0)].2;
        warps.push((c.0, at));
    }
    drop(cand);
    for &(v, _) in &warps {
        sign[v as usize] = ZERO;
    }
    let cuts: Vec<(u64, [f64; 3])> = cuts
        .into_iter()
        .filter(|&(key, _, _)| {
            sign[(key >> 32) as usize] != ZERO && sign[(key as u32) as usize] != ZERO
        })
        .map(|(key, _, p)| (key, p))
        .collect();
    (warps, cuts)
}

/// Stencils, slab by slab of cubes along z: the output tetrahedra as vertex keys, and how
/// many surface tetrahedra were dropped.
fn stencil_tets(st: &Stencils) -> (Vec<[u64; 4]>, usize) {
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
fn output_mesh(st: &Stencils, keyed: &[[u64; 4]]) -> TetMesh {
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

/// Quality and volume, in a fixed order: (volume, smallest dihedral, largest dihedral).
fn quality_and_volume(mesh: &TetMesh, params: &StuffingParams) -> (f64, f64, f64) {
    let paper_alphas = params.alpha_long == ALPHA_LONG && params.alpha_short == ALPHA_SHORT;
    let per: Vec<(f64, f64, f64)> = (0..mesh.tets.len())
        .into_par_iter()
        .map(|t| {
            let c = mesh.corners(t);
            let vol = tet_volume(c[0], c[1], c[2], c[3]);
            debug_assert!(
                !paper_alphas || vol > 0.0,
                "stencil tetrahedron {t} has volume {vol}"
            );
            let (lo, hi) = dihedral_range(c);
            (vol, lo, hi)
        })
        .collect();
    let mut volume = 0.0;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(v, a, b) in &per {
        volume += v;
        lo = lo.min(a);
        hi = hi.max(b);
    }
    (volume, lo, hi)
}

/// The lattice over the box, checked against the parameters.
fn lattice(
    bbox_min: [f64; 3],
    bbox_max: [f64; 3],
    params: &StuffingParams,
) -> Result<Lattice, StuffingError> {
    let bad = |m: String| Err(StuffingError::BadInput(m));
    let h = params.h;
    if !h.is_finite() || h <= 0.0 {
        return bad(format!("spacing h is {h}, expected a finite number > 0"));
    }
    for (name, a) in [
        ("alpha_long", params.alpha_long),
        ("alpha_short", params.alpha_short),
    ] {
        if a.is_nan() || a <= 0.0 || a >= 0.5 {
            return bad(format!("{name} is {a}, expected a number in (0, 0.5)"));
        }
    }
    if !params.root_tol.is_finite() || params.root_tol <= 0.0 {
        return bad(format!(
            "root_tol is {}, expected a finite number > 0",
            params.root_tol
        ));
    }
    for a in 0..3 {
        if !(bbox_min[a].is_finite() && bbox_max[a].is_finite()) || bbox_min[a] > bbox_max[a] {
            return bad(format!(
                "box {bbox_min:?} – {bbox_max:?} is not a finite box with min <= max on every axis"
            ));
        }
    }
    let cubes = [0, 1, 2].map(|a| ((bbox_max[a] - bbox_min[a]) / h).ceil() + 2.0);
    // Vertices: (n + 1)³ blacks and n³ reds, counted in f64 first against overflow.
    let count_f =
        (cubes[0] + 1.0) * (cubes[1] + 1.0) * (cubes[2] + 1.0) + cubes[0] * cubes[1] * cubes[2];
    let limit = params.max_lattice_vertices.min(u32::MAX as u64 - 1);
    if count_f.is_nan() || count_f > limit as f64 {
        return Err(StuffingError::TooLarge {
            needed: if count_f.is_finite() && count_f < u64::MAX as f64 {
                count_f as u64
            } else {
                u64::MAX
            },
            limit: params.max_lattice_vertices,
        });
    }
    let n = cubes.map(|c| c as usize);
    let blacks = (n[0] + 1) * (n[1] + 1) * (n[2] + 1);
    Ok(Lattice {
        n,
        origin: [0, 1, 2].map(|a| bbox_min[a] - h),
        h,
        blacks,
        total: blacks + n[0] * n[1] * n[2],
    })
}

#[cfg(test)]
mod tests;
