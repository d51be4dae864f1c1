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
//!
//! # Where the steps live
//!
//! [`stuff`] runs them in order: `lattice.rs` (step 1, the lattice and its keys),
//! `cut_points.rs` (steps 2 and 3: signs, cut points, warping) and `stencils.rs` (step 4 and
//! the output mesh); this file checks the output's quality and volume.

mod cut_points;
mod lattice;
mod stencils;

use rayon::prelude::*;

use crate::mesh::{TetMesh, tet_volume};
use cut_points::{cut_points, signs, warp};
use lattice::lattice;
use stencils::{Stencils, output_mesh, stencil_tets};

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

#[cfg(test)]
mod tests;
