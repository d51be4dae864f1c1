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
//!
//! # Where the steps live
//!
//! `chart.rs` (step 1: the checked input and the charts), `points.rs` (step 2: grid points
//! and their classes), `walk.rs` (step 3: the walks to the corners); [`extract`], here, runs
//! them and gathers the output (step 4).

mod chart;
mod points;
mod walk;

use crate::mesh::{HexMesh, TetMesh};
use crate::param::GridMap;
use chart::context;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;
use walk::{CornerEnd, CubeEnd};

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
