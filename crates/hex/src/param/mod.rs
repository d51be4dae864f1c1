//! The CubeCover parameterisation (Nieser, Reitebuch, Polthier 2011, §3.1): a map from the
//! tetrahedral mesh to parameter space, linear in each tetrahedron, whose transitions between
//! neighbouring tetrahedra are cube rotations with integer translations, so that the
//! integer grid pulls back to a hexahedral mesh.
//!
//! # Unknowns and energy (§3.1)
//!
//! Each tetrahedron `t` has its own chart: a linear map `x_t(p) = Σⱼ x_{t,j} φⱼ(p)` given by
//! the parameters `x_{t,j} ∈ ℝ³` of its four corners (12 unknowns per tetrahedron). The map
//! should follow the frame field: `E = Σ_t vol_t Σ_r |∇x_t^r − F_t^r / s|²`, `F_t^r` the
//! frame's `r`-th axis and `s` the target hex edge ([`ParamParams::scale`]).
//!
//! # Transitions and the cut
//!
//! Across an interior face from `t` to `s`: `x_s = Π_ts x_t + g_ts` on the face's three
//! vertices, `Π_ts` the matching and `g_ts` the gap. As in the paper, the gaps of a spanning
//! tree of the tetrahedra (across faces, breadth first from tetrahedron 0) are zero; each
//! chart is then rotated by the product of the matchings along its tree path, so that every
//! tree face's transition is the identity. Faces off the tree are glued too where the gap is
//! forced to zero: around a regular interior edge (holonomy the identity) whose only cut face
//! is this one, the transitions around the edge compose to the identity, so the last one is
//! the identity (repeated until no such edge is left; what stays cut hangs on singular
//! edges, boundary edges or the solid's handles). Corners joined across glued faces share
//! their unknowns: a vertex has as many copies as the cut splits its star into.
//!
//! # Constraints
//!
//! * each cut face: `x_s(v) − Π x_t(v) − g = 0` for its three vertices, `g ∈ ℤ³`;
//! * boundary alignment: on a boundary face the coordinate of the axis nearest its normal
//!   (or the axis the caller gives, [`Field::axes`]) is one integer `b` at its three vertices
//!   (the face lies in an integer plane);
//! * singular edges: the two coordinates across the edge's axis are integers `c₁, c₂` at
//!   both its vertices (the edge lies on an integer line);
//! * translation: per axis, one vertex of the first boundary face aligned with that axis has
//!   that coordinate 0 (the first corner of tetrahedron 0 for an axis no face has). Anchoring
//!   on a boundary plane matters: an anchor inside the solid a fraction of a cell from a
//!   boundary plane is pinched flat against it when that plane is rounded.
//!
//! The energy is `Σ_t vol_t |∇x_t − T_t/s|²`, `T_t` the frame (or the target gradients the
//! caller gives, [`Field::targets`]) and `s` the hex edge.
//!
//! They are eliminated exactly (Gaussian elimination that keeps every eliminated unknown as
//! an expression in free ones, pivoting on continuous unknowns with unit coefficients first;
//! Bommes, Zimmer, Kobbelt, "Mixed-integer quadrangulation", 2009, §4). Redundant rows (most
//! of them: neighbouring cut faces share vertices) reduce to `0 = 0`; a contradiction is an
//! error naming the constraint. The energy in the free unknowns is a sparse symmetric
//! positive definite system, solved by faer's sparse Cholesky. It is split first into its
//! independent blocks (the connected components of the matrix's graph), each factored on
//! its own: where no transition rotates the axes (a polycube map has none) the three
//! parameter coordinates never meet, and three factorisations of a third of the unknowns
//! cost a fraction of one of all of them.
//!
//! # Greedy rounding (§3.1)
//!
//! The free integer unknowns are rounded in the paper's greedy order, closest to an integer
//! first. While more than [`ParamParams::one_at_a_time`] are open, each round fixes a share
//! ([`ParamParams::batch`]) and refactors. The last ones are fixed one at a time on a single
//! factorisation: with `K z = b` the system where they are free, holding a set `S` of them
//! at integers `k` gives `z = z₀ + K⁻¹E_S μ`, `(E_Sᵀ K⁻¹ E_S) μ = k − z₀_S` (the Schur
//! complement of the fixed unknowns, a small dense system), so each fix costs one solved
//! column `K⁻¹eⱼ` and a dense solve, not a factorisation, and the result is the same as
//! refactoring after each (a test compares them). One at a time, the rounding also looks
//! ahead: when the nearest integer would flip more tetrahedra (non-positive parameter volume)
//! than are flipped already, the integer on the other side is taken if it flips fewer
//! ([`ParamReport::redirected`]). The report names the first round after which more
//! tetrahedra were flipped, and what it fixed.
//!
//! # Untangling
//!
//! The least-squares energy does not forbid inversion: where the rounded planes squeeze a
//! region, a few tetrahedra come out flipped although an injective map with the same
//! integers exists. With every integer fixed, the map is an affine function of the
//! remaining continuous unknowns (the elimination's expressions), and
//! [`super::untangle`] moves those near the flipped tetrahedra to minimise the
//! foldover-free energy of Garanzha et al. (2021) against each tetrahedron's target
//! gradients, so the constraints hold exactly and the rest of the map stays
//! ([`ParamParams::untangle`], [`ParamReport::untangle`]).
//!
//! # Where the steps live
//!
//! [`parameterise_with`] runs them in this order: `cut.rs` (the spanning tree, the glued
//! faces and the cut vertices), `constraints.rs` (the constraint rows and their elimination,
//! by `elim.rs`), `system.rs` (the local energies, the normal equations factored block by
//! block, the untangling's problem) and `rounding.rs` (the greedy rounding); this file holds
//! the types of the interface and turns the final unknowns into the [`GridMap`].

mod constraints;
mod cut;
mod elim;
mod rounding;
mod system;

use super::mesh::{FACE_OPPOSITE, Frame, NO_TET, TetMesh};
use super::rotation::Rot;
use super::topology::Topology;
use crate::geom::vec::{cross, dot, sub};
use constraints::{constraint_rows, eliminate};
use cut::{Cut, build_cut, cut_vertices, local};
use rounding::Rounder;
use system::{corner_params, local_energies};

/// The transition from a tetrahedron's chart into its neighbour's across a shared face:
/// `x_neighbour = rot · x + shift`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Transition {
    /// The matching, a cube rotation.
    pub rot: Rot,
    /// The integer translation (the gap, zero on faces of the spanning tree).
    pub shift: [i32; 3],
}

impl Transition {
    /// The identity (and the value stored for boundary faces).
    pub const ID: Transition = Transition {
        rot: Rot::ID,
        shift: [0; 3],
    };

    /// Maps a parameter point of this chart into the neighbour's.
    pub fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        let r = self.rot.apply(x);
        [0, 1, 2].map(|k| r[k] + f64::from(self.shift[k]))
    }

    /// Maps an integer point of this chart into the neighbour's.
    pub fn apply_i(&self, x: [i64; 3]) -> [i64; 3] {
        let r = self.rot.apply_i(x);
        [0, 1, 2].map(|k| r[k] + i64::from(self.shift[k]))
    }

    /// The transition back: `x = rot⁻¹ (x_neighbour − shift)`.
    pub fn inverse(&self) -> Transition {
        let inv = self.rot.inverse();
        let s = inv.apply_i(self.shift.map(i64::from));
        Transition {
            rot: inv,
            shift: s.map(|x| -x as i32),
        }
    }
}

/// An integer-grid map: per tetrahedron the parameters of its four corners in its own chart,
/// per tetrahedron and local face `i` (opposite local vertex `i`, as in
/// [`super::mesh::FACE_OPPOSITE`]) the transition into the neighbour's chart. Seamless: a
/// vertex shared by two face neighbours has parameters related by their transition.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GridMap {
    /// `uvw[t][j]`: the parameters of local vertex `j` of tetrahedron `t`, in `t`'s chart.
    pub uvw: Vec<[[f64; 3]; 4]>,
    /// `transitions[t][i]`: into the chart of the neighbour across face `i`;
    /// [`Transition::ID`] on the boundary.
    pub transitions: Vec<[Transition; 4]>,
}

/// Parameters of [`parameterise`].
#[derive(Clone, Debug, PartialEq)]
pub struct ParamParams {
    /// Target hexahedron edge length in input units: the frames' axes are scaled by `1/scale`.
    pub scale: f64,
    /// Round the integer variables (gaps, boundary planes, singular lines); without it the map
    /// is the continuous solution and not a hex map.
    pub round: bool,
    /// Fraction of the unrounded integer variables fixed per rounding round, closest to an
    /// integer first (at least one; `0` fixes one per round, the paper's greedy order), while
    /// more than `one_at_a_time` are open.
    pub batch: f64,
    /// Most open integer unknowns rounded one at a time on one factorisation (module docs);
    /// each keeps a solved column in memory. `0`: every round refactors.
    pub one_at_a_time: usize,
    /// After rounding, turn back the tetrahedra it left inverted by moving the continuous
    /// unknowns near them ([`super::untangle`]); the integers and constraints stay.
    pub untangle: bool,
}

impl Default for ParamParams {
    fn default() -> Self {
        ParamParams {
            scale: 1.0,
            round: true,
            batch: 0.25,
            one_at_a_time: 128,
            untangle: true,
        }
    }
}

/// What one integer variable stands for, to name it in reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum IntegerVar {
    /// Component `axis` of the translation across the face between two tetrahedra.
    Gap {
        /// The tetrahedra on the face.
        tets: [u32; 2],
        /// Parameter axis.
        axis: u8,
    },
    /// The integer plane of a boundary face (tetrahedron, its local face).
    Plane {
        /// The tetrahedron.
        tet: u32,
        /// Its local face.
        face: u8,
    },
    /// A coordinate of the integer line of a singular edge.
    Line {
        /// The edge's vertices.
        verts: [u32; 2],
        /// Parameter axis.
        axis: u8,
    },
}

impl std::fmt::Display for IntegerVar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            IntegerVar::Gap { tets, axis } => write!(
                f,
                "the {}-gap across the face of tetrahedra {} and {}",
                ["u", "v", "w"][*axis as usize],
                tets[0],
                tets[1]
            ),
            IntegerVar::Plane { tet, face } => write!(
                f,
                "the integer plane of boundary face {face} of tetrahedron {tet}"
            ),
            IntegerVar::Line { verts, axis } => write!(
                f,
                "the {}-coordinate of the singular edge {}–{}",
                ["u", "v", "w"][*axis as usize],
                verts[0],
                verts[1]
            ),
        }
    }
}

/// The rounding round after which tetrahedra first flipped.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FlipCause {
    /// Rounding round (1-based).
    pub round: usize,
    /// The variables fixed in that round (at most 8 listed) and their rounded values.
    pub fixed: Vec<(String, i64)>,
    /// Tetrahedra with non-positive parameter volume after it (at most 16 listed).
    pub tets: Vec<u32>,
}

/// What [`parameterise`] measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ParamReport {
    /// Interior faces whose transition is a cut (non-identity or a possible gap).
    pub cut_faces: usize,
    /// Copies of vertices after cutting (three unknowns each before the constraints).
    pub cut_vertices: usize,
    /// Unknowns left after eliminating the constraints.
    pub unknowns: usize,
    /// Of them integer.
    pub integer_unknowns: usize,
    /// Rounding rounds: a factorisation and solve for each batch, and one per unknown fixed
    /// one at a time on the last factorisation.
    pub rounds: usize,
    /// Nonzeros of the lower triangle of the first system's matrix.
    pub matrix_nonzeros: usize,
    /// Alignment energy of the continuous solution and of the final map (∑ vol |∇x − F/s|²,
    /// divided by the total volume: a mean squared gradient error).
    pub energy_continuous: f64,
    /// As `energy_continuous`, after rounding.
    pub energy_final: f64,
    /// Tetrahedra with non-positive parameter volume in the continuous solution.
    pub flipped_continuous: usize,

    /// The same after rounding.
    pub flipped_final: usize,
    /// The first round that flipped tetrahedra, when rounding did.
    pub first_flip: Option<FlipCause>,
    /// Largest distance of a rounded variable's continuous value from the integer it got.
    pub max_rounding: f64,
    /// Integer unknowns rounded to the integer on the far side of their value, because the
    /// nearest one flipped more tetrahedra (the one-at-a-time rounding's lookahead).
    pub redirected: usize,
    /// The untangling of the rounded map, when it left tetrahedra inverted
    /// (`flipped_final` counts them after it).
    pub untangle: Option<super::untangle::UntangleReport>,
}

/// Why the parameterisation failed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ParamError {
    /// The constraints contradict each other.
    #[error("the constraints contradict each other at {0}")]
    Inconsistent(String),
    /// The sparse factorisation failed.
    #[error("the parameterisation's linear system could not be solved: {0}")]
    Solve(String),
    /// `scale` is not positive and finite.
    #[error("the hex size must be positive and finite, not {0}")]
    Scale(f64),
}

/// Gradients of the four barycentric functions of a tetrahedron.
pub(crate) fn gradients(c: &[[f64; 3]; 4]) -> [[f64; 3]; 4] {
    let e = [sub(c[1], c[0]), sub(c[2], c[0]), sub(c[3], c[0])];
    let det = dot(e[0], cross(e[1], e[2]));
    // Rows of the inverse transpose: ∇φ₁ = (e₁ × e₂)/det, …
    let g1 = cross(e[1], e[2]).map(|x| x / det);
    let g2 = cross(e[2], e[0]).map(|x| x / det);
    let g3 = cross(e[0], e[1]).map(|x| x / det);
    let g0 = [0, 1, 2].map(|k| -(g1[k] + g2[k] + g3[k]));
    [g0, g1, g2, g3]
}

/// Signed volume of a tetrahedron in parameter space.
pub fn param_volume(p: &[[f64; 3]; 4]) -> f64 {
    let e = [sub(p[1], p[0]), sub(p[2], p[0]), sub(p[3], p[0])];
    dot(e[0], cross(e[1], e[2])) / 6.0
}

/// The CubeCover parameterisation of `mesh` for the frame field `frames` with matchings `m`
/// ([`super::frames::matchings`]) and singular edges `singular` (from
/// [`super::frames::singularities`]; they must be valid). Method: module docs.
pub fn parameterise(
    mesh: &TetMesh,
    topo: &Topology,
    frames: &[Frame],
    m: &[[Rot; 4]],
    singular: &[super::frames::SingularEdge],
    params: &ParamParams,
) -> Result<(GridMap, ParamReport), ParamError> {
    let field = Field {
        frames,
        targets: frames,
        axes: None,
        matchings: m,
        singular,
    };
    parameterise_with(mesh, topo, &field, params)
}

/// What [`parameterise_with`] fits: the frames and what may replace their defaults.
#[derive(Clone, Copy, Debug)]
pub struct Field<'a> {
    /// One frame per tetrahedron.
    pub frames: &'a [Frame],
    /// Per tetrahedron, the gradients `∇u`, `∇v`, `∇w` (rows, times the scale) the map is
    /// drawn towards; [`parameterise`] uses the frames.
    pub targets: &'a [Frame],
    /// Per boundary face (in [`Topology::boundary`]'s order), the parameter axis (0, 1, 2;
    /// in the tetrahedron's frame) it is aligned with; `None`: the frame axis nearest its
    /// normal.
    pub axes: Option<&'a [u8]>,
    /// The matchings ([`super::frames::matchings`]).
    pub matchings: &'a [[Rot; 4]],
    /// The singular edges, all valid ([`super::frames::singularities`]).
    pub singular: &'a [super::frames::SingularEdge],
}

/// As [`parameterise`], with targets and boundary axes that may differ from the frames'. A
/// polycube deformation ([`super::polycube`]) gives both: its gradients are a map whose
/// boundary is nearly axis-aligned with no tetrahedron inverted, and its cleaned-up labels
/// say which plane each boundary face goes to.
pub fn parameterise_with(
    mesh: &TetMesh,
    topo: &Topology,
    field: &Field<'_>,
    params: &ParamParams,
) -> Result<(GridMap, ParamReport), ParamError> {
    if !(params.scale.is_finite() && params.scale > 0.0) {
        return Err(ParamError::Scale(params.scale));
    }
    let cut = build_cut(mesh, topo, field.matchings);
    let mut report = ParamReport::default();
    let cv = cut_vertices(mesh, topo, &cut);
    report.cut_vertices = cv.count as usize;
    let (names, rows) = constraint_rows(mesh, topo, field, &cut, &cv, &mut report);
    let base = 3 * cv.count;
    let mut elim = eliminate(&rows, base, &names)?;
    let local = local_energies(mesh, field, &cut, params);
    let rounder = Rounder {
        params,
        names: &names,
        base,
        nvar: (base as usize) + names.len(),
        cv: &cv,
        local: &local,
    };
    let values = rounder.run(&mut elim, &mut report)?;
    Ok((grid_map(mesh, topo, &cut, &cv.corner_cv, &values), report))
}

/// The map: corner parameters and transitions between aligned charts, each cut face's shift
/// read off the parameters of one of its vertices on both sides.
fn grid_map(
    mesh: &TetMesh,
    topo: &Topology,
    cut: &Cut,
    corner_cv: &[u32],
    values: &[f64],
) -> GridMap {
    let nt = mesh.tets.len();
    let nb = &topo.neighbours;
    let uvw = corner_params(corner_cv, values);
    let transitions: Vec<[Transition; 4]> = (0..nt)
        .map(|t| {
            std::array::from_fn(|i| {
                let s = nb[t][i];
                if s == NO_TET || cut.glued[t][i] {
                    return Transition::ID;
                }
                let s = s as usize;
                let rot = cut.aligned[t][i];
                let j = FACE_OPPOSITE[i][0];
                let js = local(mesh, s, mesh.tets[t][j]);
                let there = uvw[s][js];
                let here = rot.apply(uvw[t][j]);
                Transition {
                    rot,
                    shift: [0, 1, 2].map(|r| (there[r] - here[r]).round() as i32),
                }
            })
        })
        .collect();
    GridMap { uvw, transitions }
}

#[cfg(test)]
mod tests;
