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

use super::rotation::Rot;

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

// ---------------------------------------------------------------------------------------------
// The solve.

use std::collections::VecDeque;

use crate::geom::vec::{cross, dot, sub};
use crate::sparse::{CholeskyFactor, Triplets};
use faer::prelude::*;

use super::frames::{edge_holonomy, face_index};
use super::mesh::{FACE_OPPOSITE, Frame, NO_TET, TetMesh};
use super::topology::{Topology, find, union};

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

/// A linear expression `Σ cᵢ yᵢ + k` in free variables.
#[derive(Clone, Debug, Default)]
struct Expr {
    terms: Vec<(u32, f64)>,
    constant: f64,
}

impl Expr {
    fn add_scaled(&mut self, other: &Expr, s: f64) {
        let mut out = Vec::with_capacity(self.terms.len() + other.terms.len());
        let (mut i, mut j) = (0, 0);
        while i < self.terms.len() || j < other.terms.len() {
            let a = self.terms.get(i);
            let b = other.terms.get(j);
            match (a, b) {
                (Some(&(va, ca)), Some(&(vb, cb))) if va == vb => {
                    let c = ca + s * cb;
                    if c != 0.0 {
                        out.push((va, c));
                    }
                    i += 1;
                    j += 1;
                }
                (Some(&(va, ca)), Some(&(vb, _))) if va < vb => {
                    out.push((va, ca));
                    i += 1;
                }
                (Some(&(va, ca)), None) => {
                    out.push((va, ca));
                    i += 1;
                }
                (_, Some(&(vb, cb))) => {
                    out.push((vb, s * cb));
                    j += 1;
                }
                (None, None) => unreachable!(),
            }
        }
        self.terms = out;
        self.constant += s * other.constant;
    }

    fn coef(&self, v: u32) -> f64 {
        self.terms
            .binary_search_by_key(&v, |t| t.0)
            .map_or(0.0, |k| self.terms[k].1)
    }
}

/// Gaussian elimination of linear constraints, keeping every eliminated variable as an
/// expression in free ones. A row pivots on a continuous variable with a unit coefficient
/// when it has one, else on an integer variable with a unit coefficient, so free integer
/// variables stay independent and eliminated integer variables are integer combinations of
/// free integer ones (as in Bommes, Zimmer, Kobbelt 2009, §4).
struct Elim {
    expr: Vec<Option<Expr>>,
    users: Vec<Vec<u32>>,
    integer: Vec<bool>,
}

impl Elim {
    fn new(integer: Vec<bool>) -> Elim {
        let n = integer.len();
        Elim {
            expr: vec![None; n],
            users: vec![Vec::new(); n],
            integer,
        }
    }

    /// The expression of variable `v` in free variables.
    fn of(&self, v: u32) -> Expr {
        match &self.expr[v as usize] {
            Some(e) => e.clone(),
            None => Expr {
                terms: vec![(v, 1.0)],
                constant: 0.0,
            },
        }
    }

    /// Adds the constraint `Σ cᵢ yᵢ = rhs`. Returns whether it was independent; `Err` when it
    /// reduces to `0 = nonzero`.
    fn add(&mut self, row: &[(u32, f64)], rhs: f64) -> Result<bool, f64> {
        let mut e = Expr {
            terms: Vec::new(),
            constant: -rhs,
        };
        for &(v, c) in row {
            e.add_scaled(&self.of(v), c);
        }
        e.terms.retain(|t| t.1.abs() > 1e-12);
        let unit = |t: &&(u32, f64)| (t.1.abs() - 1.0).abs() < 1e-12;
        let pivot = e
            .terms
            .iter()
            .filter(unit)
            .filter(|t| !self.integer[t.0 as usize])
            .max_by_key(|t| t.0)
            .or_else(|| e.terms.iter().filter(unit).max_by_key(|t| t.0))
            .or_else(|| {
                e.terms
                    .iter()
                    .filter(|t| !self.integer[t.0 as usize])
                    .max_by_key(|t| t.0)
            })
            .or_else(|| e.terms.iter().max_by_key(|t| t.0))
            .copied();
        let Some((p, cp)) = pivot else {
            return if e.constant.abs() < 1e-9 {
                Ok(false)
            } else {
                Err(e.constant)
            };
        };
        // p = −(e − cp p) / cp
        let mut ep = Expr {
            terms: e
                .terms
                .iter()
                .filter(|t| t.0 != p)
                .map(|&(v, c)| (v, -c / cp))
                .collect(),
            constant: -e.constant / cp,
        };
        ep.terms.retain(|t| t.1 != 0.0);
        for q in std::mem::take(&mut self.users[p as usize]) {
            let Some(eq) = self.expr[q as usize].as_mut() else {
                continue;
            };
            let c = eq.coef(p);
            if c == 0.0 {
                continue;
            }
            let mut removed = Expr {
                terms: vec![(p, 1.0)],
                constant: 0.0,
            };
            removed.add_scaled(&ep, -1.0);
            eq.add_scaled(&removed, -c);
            for &(v, _) in &ep.terms {
                self.users[v as usize].push(q);
            }
        }
        for &(v, _) in &ep.terms {
            self.users[v as usize].push(p);
        }
        self.expr[p as usize] = Some(ep);
        Ok(true)
    }
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

/// The cut: a spanning tree of tetrahedra across faces, the chart rotations that make its
/// faces' matchings the identity, and the faces glued on top of it.
struct Cut {
    /// Chart rotation of each tetrahedron: aligned chart `x' = R x`.
    chart: Vec<Rot>,
    /// Matchings between aligned charts.
    aligned: Vec<[Rot; 4]>,
    /// Whether each (tet, face) is glued (identity transition, zero gap).
    glued: Vec<[bool; 4]>,
}

fn build_cut(mesh: &TetMesh, topo: &Topology, m: &[[Rot; 4]]) -> Cut {
    let nt = mesh.tets.len();
    let nb = &topo.neighbours;
    let mut chart = vec![Rot::ID; nt];
    let mut glued = vec![[false; 4]; nt];
    let mut seen = vec![false; nt];
    let mut queue = VecDeque::from([0usize]);
    seen[0] = true;
    while let Some(t) = queue.pop_front() {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET || seen[s as usize] {
                continue;
            }
            let s = s as usize;
            seen[s] = true;
            // R_s = R_t m_ts⁻¹ makes the aligned matching R_s m_ts R_t⁻¹ the identity.
            chart[s] = chart[t].compose(m[t][i].inverse());
            glued[t][i] = true;
            glued[s][face_index(nb, s, t as u32)] = true;
            queue.push_back(s);
        }
    }
    let aligned: Vec<[Rot; 4]> = (0..nt)
        .map(|t| {
            std::array::from_fn(|i| {
                let s = nb[t][i];
                if s == NO_TET {
                    Rot::ID
                } else {
                    chart[s as usize]
                        .compose(m[t][i])
                        .compose(chart[t].inverse())
                }
            })
        })
        .collect();
    // Glue faces hanging off regular interior edges: around such an edge the matchings
    // compose to the identity, so when all other faces are glued the last one is forced to
    // the identity with zero gap.
    let ne = topo.num_edges();
    let regular: Vec<bool> = (0..ne)
        .map(|e| !topo.edge_on_boundary[e] && edge_holonomy(topo, m, e) == Rot::ID)
        .collect();
    let face_edges = |t: usize, i: usize| -> [u32; 3] {
        let f = FACE_OPPOSITE[i].map(|j| mesh.tets[t][j]);
        [(0, 1), (1, 2), (2, 0)].map(|(a, b)| topo.edge_id(f[a], f[b]).expect("face edge"))
    };
    let mut cuts = vec![0u32; ne];
    for e in 0..ne {
        if !regular[e] {
            continue;
        }
        let star = topo.star(e);
        for k in 0..star.len() {
            let (t, s) = (star[k] as usize, star[(k + 1) % star.len()]);
            if !glued[t][face_index(nb, t, s)] {
                cuts[e] += 1;
            }
        }
    }
    let mut work: Vec<u32> = (0..ne as u32)
        .filter(|&e| regular[e as usize] && cuts[e as usize] == 1)
        .collect();
    while let Some(e) = work.pop() {
        let e = e as usize;
        if cuts[e] != 1 {
            continue;
        }
        let star = topo.star(e);
        let Some((t, i, s)) = (0..star.len()).find_map(|k| {
            let (t, s) = (star[k] as usize, star[(k + 1) % star.len()]);
            let i = face_index(nb, t, s);
            (!glued[t][i]).then_some((t, i, s as usize))
        }) else {
            continue;
        };
        debug_assert_eq!(
            aligned[t][i],
            Rot::ID,
            "a regular edge's last cut is the identity"
        );
        glued[t][i] = true;
        glued[s][face_index(nb, s, t as u32)] = true;
        for f in face_edges(t, i) {
            let f = f as usize;
            if regular[f] {
                cuts[f] -= 1;
                if cuts[f] == 1 {
                    work.push(f as u32);
                }
            }
        }
    }
    Cut {
        chart,
        aligned,
        glued,
    }
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

/// The local index of vertex `v` in tetrahedron `t`.
fn local(mesh: &TetMesh, t: usize, v: u32) -> usize {
    mesh.tets[t].iter().position(|&x| x == v).expect("vertex")
}

/// The copies of the mesh's vertices the cut leaves: corners joined across glued faces share
/// one, and each has three unknowns (module docs, "Transitions and the cut").
struct CutVertices {
    /// Per corner `4 t + j`, its cut vertex.
    corner_cv: Vec<u32>,
    /// How many there are.
    count: u32,
    /// Each one's position (its mesh vertex's).
    pos: Vec<[f64; 3]>,
}

impl CutVertices {
    /// The unknown of parameter `r` at corner `j` of tetrahedron `t`.
    fn xvar(&self, t: usize, j: usize, r: usize) -> u32 {
        3 * self.corner_cv[4 * t + j] + r as u32
    }
}

/// Corners → cut vertices: union across glued faces, numbered in the order of their first
/// corner.
fn cut_vertices(mesh: &TetMesh, topo: &Topology, cut: &Cut) -> CutVertices {
    let nt = mesh.tets.len();
    let nb = &topo.neighbours;
    let mut parent: Vec<u32> = (0..4 * nt as u32).collect();
    for t in 0..nt {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET || (s as usize) < t || !cut.glued[t][i] {
                continue;
            }
            for j in FACE_OPPOSITE[i] {
                let v = mesh.tets[t][j];
                let b = (4 * s as usize + local(mesh, s as usize, v)) as u32;
                union(&mut parent, (4 * t + j) as u32, b);
            }
        }
    }
    let mut cv_of_root = vec![u32::MAX; 4 * nt];
    let mut corner_cv = vec![0u32; 4 * nt];
    let mut ncv = 0u32;
    for c in 0..4 * nt {
        let r = find(&mut parent, c as u32) as usize;
        if cv_of_root[r] == u32::MAX {
            cv_of_root[r] = ncv;
            ncv += 1;
        }
        corner_cv[c] = cv_of_root[r];
    }
    let mut cv_pos = vec![[0.0; 3]; ncv as usize];
    for (c, &cv) in corner_cv.iter().enumerate() {
        cv_pos[cv as usize] = mesh.verts[mesh.tets[c / 4][c % 4] as usize];
    }
    CutVertices {
        corner_cv,
        count: ncv,
        pos: cv_pos,
    }
}

/// A linear constraint `Σ cᵢ yᵢ = rhs`: the terms and the right-hand side.
type Row = (Vec<(u32, f64)>, f64);

/// The aligned axis of each boundary face's plane: the given one ([`Field::axes`]), or the
/// frame axis nearest its normal.
fn face_axes(mesh: &TetMesh, topo: &Topology, field: &Field<'_>, cut: &Cut) -> Vec<usize> {
    topo.boundary
        .iter()
        .enumerate()
        .map(|(face, &(t, i))| {
            let (t, i) = (t as usize, i as usize);
            match field.axes {
                Some(axes) => {
                    let rm = cut.chart[t].matrix();
                    (0..3)
                        .find(|&a| rm[a][axes[face] as usize] != 0)
                        .expect("a rotation maps an axis to an axis")
                }
                None => {
                    let f = FACE_OPPOSITE[i].map(|j| mesh.verts[mesh.tets[t][j] as usize]);
                    let n = cross(sub(f[1], f[0]), sub(f[2], f[0]));
                    let fr = aligned_frame(&field.frames[t], cut.chart[t]);
                    (0..3)
                        .max_by(|&a, &b| dot(fr[a], n).abs().total_cmp(&dot(fr[b], n).abs()))
                        .expect("three axes")
                }
            }
        })
        .collect()
}

/// The integer unknowns (numbered after the `3 · cv.count` continuous ones, named) and the
/// constraints of the module docs: the translation anchors, the cut faces' transitions with
/// their gaps (counted in [`ParamReport::cut_faces`]), the boundary faces' integer planes
/// and the singular edges' integer lines.
fn constraint_rows(
    mesh: &TetMesh,
    topo: &Topology,
    field: &Field<'_>,
    cut: &Cut,
    cv: &CutVertices,
    report: &mut ParamReport,
) -> (Vec<IntegerVar>, Vec<Row>) {
    let nt = mesh.tets.len();
    let nb = &topo.neighbours;
    let xvar = |t: usize, j: usize, r: usize| cv.xvar(t, j, r);
    let mut names: Vec<IntegerVar> = Vec::new();
    let base = 3 * cv.count;
    let mut rows: Vec<Row> = Vec::new();
    let face_axis = face_axes(mesh, topo, field, cut);
    // Translation: per axis, a vertex of the first boundary face on a plane of that axis at
    // 0 (so the grid is anchored on a boundary plane, and rounding the other planes cannot
    // pinch the solid against an anchor inside it); the first corner when no face has it.
    for r in 0..3 {
        let anchor = topo
            .boundary
            .iter()
            .zip(&face_axis)
            .find(|&(_, &k)| k == r)
            .map_or((0, 0), |(&(t, i), _)| {
                (t as usize, FACE_OPPOSITE[i as usize][0])
            });
        rows.push((vec![(xvar(anchor.0, anchor.1, r), 1.0)], 0.0));
    }
    for t in 0..nt {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET || (s as usize) < t || cut.glued[t][i] {
                continue;
            }
            report.cut_faces += 1;
            let s = s as usize;
            let g0 = base + names.len() as u32;
            for axis in 0..3u8 {
                names.push(IntegerVar::Gap {
                    tets: [t as u32, s as u32],
                    axis,
                });
            }
            let rot = cut.aligned[t][i].matrix();
            for j in FACE_OPPOSITE[i] {
                let v = mesh.tets[t][j];
                let js = local(mesh, s, v);
                for (r, rot_r) in rot.iter().enumerate() {
                    let mut row = vec![(xvar(s, js, r), 1.0), (g0 + r as u32, -1.0)];
                    for (k, &c) in rot_r.iter().enumerate() {
                        if c != 0 {
                            row.push((xvar(t, j, k), -f64::from(c)));
                        }
                    }
                    rows.push((row, 0.0));
                }
            }
        }
    }
    // Boundary faces on integer planes of their axis.
    for (face, &(t, i)) in topo.boundary.iter().enumerate() {
        let (t, i, k) = (t as usize, i as usize, face_axis[face]);
        let b = base + names.len() as u32;
        names.push(IntegerVar::Plane {
            tet: t as u32,
            face: i as u8,
        });
        for j in FACE_OPPOSITE[i] {
            rows.push((vec![(xvar(t, j, k), 1.0), (b, -1.0)], 0.0));
        }
    }
    // Singular edges on integer lines of their axis.
    for e in field.singular {
        let t0 = topo.star(e.edge as usize)[0] as usize;
        let rm = cut.chart[t0].matrix();
        let axis = (0..3)
            .find(|&a| rm[a][e.axis as usize] != 0)
            .expect("a rotation maps an axis to an axis");
        for other in (0..3).filter(|&a| a != axis) {
            let c = base + names.len() as u32;
            names.push(IntegerVar::Line {
                verts: e.verts,
                axis: other as u8,
            });
            for v in e.verts {
                rows.push((
                    vec![(xvar(t0, local(mesh, t0, v), other), 1.0), (c, -1.0)],
                    0.0,
                ));
            }
        }
    }
    (names, rows)
}

/// Eliminates the constraints `rows` over the `base` continuous and `names.len()` integer
/// unknowns; a contradiction names the constraint.
fn eliminate(rows: &[Row], base: u32, names: &[IntegerVar]) -> Result<Elim, ParamError> {
    let nvar = (base as usize) + names.len();
    let mut integer = vec![false; nvar];
    integer[base as usize..].fill(true);
    let mut elim = Elim::new(integer);
    for (row, rhs) in rows {
        elim.add(row, *rhs).map_err(|c| {
            ParamError::Inconsistent(format!(
                "a constraint on {} (residual {c})",
                describe_row(row, base, names)
            ))
        })?;
    }
    Ok(elim)
}

/// What the energy `Σ_t vol_t |∇x_t − T_t/s|²` of each tetrahedron reads: its barycentric
/// gradients, its target gradients in its aligned chart over the scale, its volume.
struct LocalEnergies {
    grads: Vec<[[f64; 3]; 4]>,
    targets: Vec<Frame>,
    volumes: Vec<f64>,
    total_volume: f64,
}

impl LocalEnergies {
    /// The energy of the map of `values` (corners by `corner_cv`) over the total volume.
    fn mean(&self, corner_cv: &[u32], values: &[f64]) -> f64 {
        energy(
            &corner_params(corner_cv, values),
            &self.grads,
            &self.targets,
            &self.volumes,
        ) / self.total_volume
    }
}

/// The local energies of the tetrahedra (module docs, "Unknowns and energy").
fn local_energies(
    mesh: &TetMesh,
    field: &Field<'_>,
    cut: &Cut,
    params: &ParamParams,
) -> LocalEnergies {
    let nt = mesh.tets.len();
    let grads: Vec<[[f64; 3]; 4]> = (0..nt).map(|t| gradients(&mesh.corners(t))).collect();
    let targets: Vec<Frame> = (0..nt)
        .map(|t| {
            aligned_frame(&field.targets[t], cut.chart[t]).map(|a| a.map(|x| x / params.scale))
        })
        .collect();
    let volumes: Vec<f64> = (0..nt).map(|t| mesh.volume(t)).collect();
    let total_volume: f64 = volumes.iter().sum();
    LocalEnergies {
        grads,
        targets,
        volumes,
        total_volume,
    }
}

/// The unknowns the elimination leaves free, their normal equations factored, and every
/// unknown's expression in them: one solve of the rounding.
struct FreeSolve {
    /// The free unknowns, ascending.
    free: Vec<u32>,
    /// Per unknown, its index in `free` (`u32::MAX` when eliminated).
    index: Vec<u32>,
    /// Per free unknown, its vertex's position (NaN for an integer unknown).
    points: Vec<[f64; 3]>,
    fac: Factored,
    exprs: Vec<Expr>,
}

impl FreeSolve {
    /// Every unknown's value when the free ones are `z`.
    fn eval(&self, z: &[f64]) -> Vec<f64> {
        self.exprs
            .iter()
            .map(|e| {
                e.constant
                    + e.terms
                        .iter()
                        .map(|&(f, c)| c * z[self.index[f as usize] as usize])
                        .sum::<f64>()
            })
            .collect()
    }
}

/// The greedy rounding of the integer unknowns (§3.1) and the untangling after it, over the
/// constraints eliminated so far.
struct Rounder<'a> {
    params: &'a ParamParams,
    names: &'a [IntegerVar],
    /// The first integer unknown (the continuous ones come first).
    base: u32,
    /// All unknowns.
    nvar: usize,
    cv: &'a CutVertices,
    local: &'a LocalEnergies,
}

impl Rounder<'_> {
    /// The tetrahedra with non-positive parameter volume in the map of `values`.
    fn flipped_of(&self, values: &[f64]) -> Vec<u32> {
        let uvw = corner_params(&self.cv.corner_cv, values);
        (0..uvw.len() as u32)
            .filter(|&t| param_volume(&uvw[t as usize]) <= 0.0)
            .collect()
    }

    /// The normal equations over the unknowns `st` leaves free.
    fn system<'s>(&'s self, elim: &'s Elim, st: &'s FreeSolve) -> System<'s> {
        System {
            points: &st.points,
            elim,
            index: &st.index,
            corner_cv: &self.cv.corner_cv,
            grads: &self.local.grads,
            targets: &self.local.targets,
            volumes: &self.local.volumes,
        }
    }

    /// Factors and solves the normal equations over the unknowns `elim` leaves free.
    fn solve(&self, elim: &Elim) -> Result<FreeSolve, ParamError> {
        let nvar = self.nvar;
        let free: Vec<u32> = (0..nvar as u32)
            .filter(|&v| elim.expr[v as usize].is_none())
            .collect();
        let mut index = vec![u32::MAX; nvar];
        for (k, &v) in free.iter().enumerate() {
            index[v as usize] = k as u32;
        }
        let points: Vec<[f64; 3]> = free
            .iter()
            .map(|&v| {
                if v < self.base {
                    self.cv.pos[(v / 3) as usize]
                } else {
                    [f64::NAN; 3]
                }
            })
            .collect();
        let sys = System {
            points: &points,
            elim,
            index: &index,
            corner_cv: &self.cv.corner_cv,
            grads: &self.local.grads,
            targets: &self.local.targets,
            volumes: &self.local.volumes,
        };
        let fac = sys.factor(free.len()).map_err(ParamError::Solve)?;
        let exprs: Vec<Expr> = (0..nvar as u32).map(|v| elim.of(v)).collect();
        Ok(FreeSolve {
            free,
            index,
            points,
            fac,
            exprs,
        })
    }

    /// The map of the final free unknowns `z`, its flips and energy recorded.
    fn finish(&self, st: &FreeSolve, z: &[f64], report: &mut ParamReport) -> Vec<f64> {
        let values = st.eval(z);
        report.flipped_final = self.flipped_of(&values).len();
        report.energy_final = self.local.mean(&self.cv.corner_cv, &values);
        values
    }

    /// Rounds the integer unknowns and untangles the map (module docs): solve, record the
    /// flips, fix a batch, until few enough are open to fix one at a time on the last
    /// factorisation. Returns every unknown's value.
    fn run(&self, elim: &mut Elim, report: &mut ParamReport) -> Result<Vec<f64>, ParamError> {
        let params = self.params;
        let mut last_fixed: Vec<(String, i64)> = Vec::new();
        let mut prev_flipped = usize::MAX;
        loop {
            let st = self.solve(elim)?;
            if report.rounds == 0 {
                report.unknowns = st.free.len();
                report.integer_unknowns = st
                    .free
                    .iter()
                    .filter(|&&v| elim.integer[v as usize])
                    .count();
                report.matrix_nonzeros = st.fac.nnz;
            }
            let values = st.eval(&st.fac.x0);
            let flipped = self.flipped_of(&values);
            let e = self.local.mean(&self.cv.corner_cv, &values);
            if report.rounds == 0 {
                report.flipped_continuous = flipped.len();
                report.energy_continuous = e;
            } else if flipped.len() > prev_flipped && report.first_flip.is_none() {
                report.first_flip = Some(FlipCause {
                    round: report.rounds,
                    fixed: std::mem::take(&mut last_fixed),
                    tets: flipped.iter().copied().take(16).collect(),
                });
            }
            prev_flipped = flipped.len();
            report.flipped_final = flipped.len();
            report.energy_final = e;
            // The open integer unknowns, as indices into the free list.
            let open: Vec<u32> = st
                .free
                .iter()
                .enumerate()
                .filter(|&(_, &v)| elim.integer[v as usize])
                .map(|(k, _)| k as u32)
                .collect();
            if !params.round {
                return Ok(values);
            }
            if open.is_empty() {
                if flipped.is_empty() || !params.untangle {
                    return Ok(values);
                }
                let mut z = st.fac.x0.clone();
                let movable = vec![true; z.len()];
                let ncv = self.cv.count as usize;
                report.untangle = Some(
                    self.system(elim, &st)
                        .untangle(&st.exprs, ncv, &mut z, &movable),
                );
                return Ok(self.finish(&st, &z, report));
            }
            if open.len() <= params.one_at_a_time {
                return self.one_at_a_time(elim, &st, open, flipped.len(), report);
            }
            self.fix_batch(elim, &st, &open, &values, &mut last_fixed, report)?;
        }
    }

    /// Greedy rounding (§3.1) one unknown at a time, closest to an integer first, on the one
    /// factorisation of `st`; an unknown whose nearest integer would flip more tetrahedra
    /// takes the integer on its other side when that flips fewer. `flipped`: the tetrahedra
    /// flipped before. Untangles what stays flipped; returns every unknown's value.
    fn one_at_a_time(
        &self,
        elim: &Elim,
        st: &FreeSolve,
        open: Vec<u32>,
        flipped: usize,
        report: &mut ParamReport,
    ) -> Result<Vec<f64>, ParamError> {
        let (params, names, base) = (self.params, self.names, self.base);
        let free = &st.free;
        let r = Rounding::new(&st.fac, open.clone());
        let singular = || ParamError::Solve("the rounding's Schur complement is singular".into());
        let mut fixed: Vec<(usize, f64)> = Vec::new();
        let mut mu: Vec<f64> = Vec::new();
        let mut done = vec![false; open.len()];
        let mut flips_now = flipped;
        for _ in 0..open.len() {
            let off = |x: f64| (x - x.round()).abs();
            let (k, x) = (0..open.len())
                .filter(|&k| !done[k])
                .map(|k| (k, r.value(&fixed, &mu, open[k])))
                .min_by(|a, b| off(a.1).total_cmp(&off(b.1)).then(a.0.cmp(&b.0)))
                .expect("an open unknown is left");
            let near = x.round();
            let far = if x >= near { near + 1.0 } else { near - 1.0 };
            let attempt = |value: f64| -> Result<(Vec<u32>, Fixed), ParamError> {
                let mut with = fixed.clone();
                with.push((k, value));
                let z = r.solution(&with).ok_or_else(singular)?;
                Ok((self.flipped_of(&st.eval(&z)), with))
            };
            let mut pick = attempt(near)?;
            let mut chosen = near;
            if pick.0.len() > flips_now {
                let other = attempt(far)?;
                if other.0.len() < pick.0.len() {
                    (pick, chosen) = (other, far);
                    report.redirected += 1;
                }
            }
            report.rounds += 1;
            report.max_rounding = report.max_rounding.max((x - chosen).abs());
            if pick.0.len() > flips_now && report.first_flip.is_none() {
                let name = names[(free[open[k] as usize] - base) as usize];
                report.first_flip = Some(FlipCause {
                    round: report.rounds,
                    fixed: vec![(name.to_string(), chosen as i64)],
                    tets: pick.0.iter().copied().take(16).collect(),
                });
            }
            flips_now = pick.0.len();
            fixed = pick.1;
            mu = r.multipliers(&fixed).ok_or_else(singular)?;
            done[k] = true;
        }
        let mut z = r.solution(&fixed).ok_or_else(singular)?;
        if flips_now > 0 && params.untangle {
            let movable: Vec<bool> = free.iter().map(|&v| !elim.integer[v as usize]).collect();
            let ncv = self.cv.count as usize;
            report.untangle = Some(
                self.system(elim, st)
                    .untangle(&st.exprs, ncv, &mut z, &movable),
            );
        }
        Ok(self.finish(st, &z, report))
    }

    /// One round of the batched greedy rounding (§3.1): of the `open` unknowns (indices into
    /// `st`'s free list, at `values`), the share [`ParamParams::batch`] closest to an integer
    /// is fixed, leaving at least [`ParamParams::one_at_a_time`] (and one) open; what it
    /// fixed is kept in `last_fixed` for the report.
    fn fix_batch(
        &self,
        elim: &mut Elim,
        st: &FreeSolve,
        open: &[u32],
        values: &[f64],
        last_fixed: &mut Vec<(String, i64)>,
        report: &mut ParamReport,
    ) -> Result<(), ParamError> {
        let params = self.params;
        let mut order: Vec<(f64, u32)> = open
            .iter()
            .map(|&k| {
                let v = st.free[k as usize];
                let x = values[v as usize];
                ((x - x.round()).abs(), v)
            })
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let take = ((open.len() as f64 * params.batch).ceil() as usize)
            .clamp(1, open.len())
            .min(open.len() - params.one_at_a_time.min(open.len() - 1));
        last_fixed.clear();
        for &(d, v) in &order[..take] {
            let k = values[v as usize].round();
            report.max_rounding = report.max_rounding.max(d);
            let name = self.names[(v - self.base) as usize];
            elim.add(&[(v, 1.0)], k).map_err(|c| {
                ParamError::Inconsistent(format!("rounding {name} to {k} (residual {c})"))
            })?;
            if last_fixed.len() < 8 {
                last_fixed.push((name.to_string(), k as i64));
            }
        }
        report.rounds += 1;
        Ok(())
    }
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

/// A frame's axes in an aligned chart: row `r` of `R F`.
fn aligned_frame(f: &Frame, chart: Rot) -> Frame {
    let m = chart.matrix();
    [0, 1, 2].map(|r| [0, 1, 2].map(|x| (0..3).map(|k| f64::from(m[r][k]) * f[k][x]).sum()))
}

fn corner_params(corner_cv: &[u32], values: &[f64]) -> Vec<[[f64; 3]; 4]> {
    corner_cv
        .chunks_exact(4)
        .map(|c| std::array::from_fn(|j| std::array::from_fn(|r| values[3 * c[j] as usize + r])))
        .collect()
}

/// `Σ vol |∇x − F/s|²` over the tetrahedra.
fn energy(
    uvw: &[[[f64; 3]; 4]],
    grads: &[[[f64; 3]; 4]],
    targets: &[Frame],
    volumes: &[f64],
) -> f64 {
    (0..uvw.len())
        .map(|t| {
            let mut e = 0.0;
            for r in 0..3 {
                for x in 0..3 {
                    let g: f64 = (0..4).map(|j| uvw[t][j][r] * grads[t][j][x]).sum();
                    e += (g - targets[t][r][x]).powi(2);
                }
            }
            volumes[t] * e
        })
        .sum()
}

fn describe_row(row: &[(u32, f64)], base: u32, names: &[IntegerVar]) -> String {
    row.iter().find(|t| t.0 >= base).map_or_else(
        || "the fixed corner".to_string(),
        |t| names[(t.0 - base) as usize].to_string(),
    )
}

/// The reduced normal equations over the free variables.
struct System<'a> {
    /// Per free variable, the position of its vertex (NaN for an integer unknown): the
    /// factorisation's nested-dissection ordering.
    points: &'a [[f64; 3]],
    elim: &'a Elim,
    index: &'a [u32],
    corner_cv: &'a [u32],
    grads: &'a [[[f64; 3]; 4]],
    targets: &'a [Frame],
    volumes: &'a [f64],
}

impl System<'_> {
    /// Untangles the map of the free unknowns `z` ([`super::untangle`]), moving those marked
    /// `movable`; `ncv` cut vertices, each tetrahedron measured against its target gradients.
    fn untangle(
        &self,
        exprs: &[Expr],
        ncv: usize,
        z: &mut [f64],
        movable: &[bool],
    ) -> super::untangle::UntangleReport {
        use super::untangle::{Affine, Problem, UntangleParams, untangle};
        let nt = self.volumes.len();
        let corners: Vec<[u32; 4]> = self
            .corner_cv
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        let points: Vec<[Affine; 3]> = (0..ncv)
            .map(|cv| {
                std::array::from_fn(|r| {
                    let e = &exprs[3 * cv + r];
                    Affine {
                        terms: e
                            .terms
                            .iter()
                            .map(|&(f, c)| (self.index[f as usize], c))
                            .collect(),
                        constant: e.constant,
                    }
                })
            })
            .collect();
        let reference: Vec<[[f64; 3]; 4]> = (0..nt)
            .map(|t| {
                let tm = nalgebra::Matrix3::from_fn(|r, c| self.targets[t][r][c]);
                let g = &self.grads[t];
                match tm.try_inverse().filter(|_| tm.determinant() > 0.0) {
                    // h = T⁻ᵀ g
                    Some(inv) => std::array::from_fn(|j| {
                        std::array::from_fn(|c| (0..3).map(|k| inv[(k, c)] * g[j][k]).sum())
                    }),
                    None => {
                        let s = 1.0 / tm.norm().max(f64::MIN_POSITIVE) * 3f64.sqrt();
                        g.map(|v| v.map(|x| x * s))
                    }
                }
            })
            .collect();
        let mean = self.volumes.iter().sum::<f64>() / nt.max(1) as f64;
        let weights: Vec<f64> = self.volumes.iter().map(|v| v / mean).collect();
        let problem = Problem {
            corners: &corners,
            points: &points,
            reference: &reference,
            weights: &weights,
        };
        untangle(&problem, z, movable, &UntangleParams::default())
    }

    /// Assembles the normal equations, splits them into independent blocks (the connected
    /// components of the matrix: with identity transitions the three parameter axes never
    /// meet) and factors each; returns the factors with the solution.
    fn factor(&self, n: usize) -> Result<Factored, String> {
        let mut trip: Vec<(u32, u32, f64)> = Vec::new();
        let mut rhs = vec![0.0; n];
        let mut diag = vec![0.0f64; n];
        let nt = self.volumes.len();
        for t in 0..nt {
            let g = &self.grads[t];
            let vol = self.volumes[t];
            for r in 0..3 {
                let ex: [Expr; 4] =
                    std::array::from_fn(|j| self.elim.of(3 * self.corner_cv[4 * t + j] + r as u32));
                for j in 0..4 {
                    let bj = vol * dot(g[j], self.targets[t][r]);
                    for &(f, c) in &ex[j].terms {
                        rhs[self.index[f as usize] as usize] += c * bj;
                    }
                    for l in 0..4 {
                        let h = vol * dot(g[j], g[l]);
                        for &(f, c) in &ex[j].terms {
                            let fi = self.index[f as usize];
                            rhs[fi as usize] -= c * h * ex[l].constant;
                            for &(f2, c2) in &ex[l].terms {
                                let fk = self.index[f2 as usize];
                                if fk <= fi {
                                    trip.push((fi, fk, c * c2 * h));
                                }
                                if fk == fi {
                                    diag[fi as usize] += c * c2 * h;
                                }
                            }
                        }
                    }
                }
            }
        }
        // A tiny diagonal shift keeps a variable no energy term reaches at zero.
        let mean = diag.iter().sum::<f64>() / n.max(1) as f64;
        for i in 0..n {
            trip.push((i as u32, i as u32, 1e-10 * mean.max(f64::MIN_POSITIVE)));
        }
        trip.sort_by_key(|a| (a.1, a.0));
        let mut merged: Vec<(u32, u32, f64)> = Vec::with_capacity(trip.len() / 4);
        for (r, c, v) in trip {
            match merged.last_mut() {
                Some(last) if last.0 == r && last.1 == c => last.2 += v,
                _ => merged.push((r, c, v)),
            }
        }
        // Blocks: components of the matrix's graph, numbered by their first variable.
        let mut parent: Vec<u32> = (0..n as u32).collect();
        for &(r, c, _) in &merged {
            if r != c {
                union(&mut parent, r, c);
            }
        }
        let mut block_of_root = vec![u32::MAX; n];
        let mut at = Vec::with_capacity(n);
        let mut vars: Vec<Vec<u32>> = Vec::new();
        for i in 0..n as u32 {
            let root = find(&mut parent, i) as usize;
            if block_of_root[root] == u32::MAX {
                block_of_root[root] = vars.len() as u32;
                vars.push(Vec::new());
            }
            let b = block_of_root[root];
            at.push((b, vars[b as usize].len() as u32));
            vars[b as usize].push(i);
        }
        let mut entries: Vec<Triplets> = vars.iter().map(|v| Triplets::new(v.len())).collect();
        for &(r, c, v) in &merged {
            let (b, lr) = at[r as usize];
            entries[b as usize].push(lr as usize, at[c as usize].1 as usize, v);
        }
        let nnz = merged.len();
        drop(merged);
        use rayon::prelude::*;
        let blocks: Vec<Block> = vars
            .into_par_iter()
            .zip(entries)
            .map(|(vars, mut entries)| {
                let points: Vec<[f64; 3]> = vars.iter().map(|&i| self.points[i as usize]).collect();
                let factor = CholeskyFactor::with_points(&mut entries, &points)?;
                Ok(Block { vars, factor })
            })
            .collect::<Result<_, String>>()?;
        let mut x0 = vec![0.0; n];
        for b in &blocks {
            let mut x = Mat::from_fn(b.vars.len(), 1, |i, _| rhs[b.vars[i] as usize]);
            b.factor.solve_in_place(&mut x);
            for (i, &v) in b.vars.iter().enumerate() {
                x0[v as usize] = x[(i, 0)];
            }
        }
        Ok(Factored {
            at,
            blocks,
            x0,
            nnz,
        })
    }
}

/// One independent block of the normal equations, factored.
struct Block {
    /// Its free variables (indices into the free list), ascending.
    vars: Vec<u32>,
    factor: CholeskyFactor,
}

/// The normal equations over the free variables, factored block by block.
struct Factored {
    /// Per free variable, its block and its index in the block.
    at: Vec<(u32, u32)>,
    blocks: Vec<Block>,
    /// The solution with every free variable free.
    x0: Vec<f64>,
    /// Nonzeros of the matrix's lower triangle.
    nnz: usize,
}

/// Open integer unknowns held at values: (index into the open list, value).
type Fixed = Vec<(usize, f64)>;

/// The free variables' values with the integer unknowns `fixed` held at given values, on the
/// factorisation of the system where they were free: minimising `½ zᵀKz − bᵀz` subject to
/// `z_S = k` gives `z = z₀ + Z_S μ`, `Z_S = K⁻¹ E_S`, with `(E_Sᵀ K⁻¹ E_S) μ = k − z₀_S`
/// (the Schur complement of the fixed unknowns, a small dense system).
struct Rounding<'a> {
    f: &'a Factored,
    /// The open integer unknowns (free indices) and their solved columns `K⁻¹ eⱼ`, over the
    /// variables of their block.
    open: Vec<u32>,
    columns: Vec<Vec<f64>>,
}

impl<'a> Rounding<'a> {
    fn new(f: &'a Factored, open: Vec<u32>) -> Rounding<'a> {
        use rayon::prelude::*;
        let columns = open
            .par_iter()
            .map(|&j| {
                let (b, l) = f.at[j as usize];
                let block = &f.blocks[b as usize];
                let m = block.vars.len();
                let mut x = Mat::from_fn(m, 1, |i, _| f64::from(u8::from(i == l as usize)));
                block.factor.solve_in_place(&mut x);
                (0..m).map(|i| x[(i, 0)]).collect()
            })
            .collect();
        Rounding { f, open, columns }
    }

    /// Entry of column `k` (an index into `open`) at free variable `v`.
    fn entry(&self, k: usize, v: u32) -> f64 {
        let (bk, _) = self.f.at[self.open[k] as usize];
        let (bv, lv) = self.f.at[v as usize];
        if bk == bv {
            self.columns[k][lv as usize]
        } else {
            0.0
        }
    }

    /// The multipliers `μ` for the open unknowns `fixed` (indices into `open`) at `values`.
    fn multipliers(&self, fixed: &[(usize, f64)]) -> Option<Vec<f64>> {
        let m = fixed.len();
        let a =
            nalgebra::DMatrix::from_fn(m, m, |r, c| self.entry(fixed[c].0, self.open[fixed[r].0]));
        let b = nalgebra::DVector::from_fn(m, |r, _| {
            fixed[r].1 - self.f.x0[self.open[fixed[r].0] as usize]
        });
        a.cholesky().map(|c| c.solve(&b).iter().copied().collect())
    }

    /// Value of free variable `v` under multipliers `mu` for `fixed`.
    fn value(&self, fixed: &[(usize, f64)], mu: &[f64], v: u32) -> f64 {
        self.f.x0[v as usize]
            + fixed
                .iter()
                .zip(mu)
                .map(|(&(k, _), m)| m * self.entry(k, v))
                .sum::<f64>()
    }

    /// All free variables under `fixed`.
    fn solution(&self, fixed: &[(usize, f64)]) -> Option<Vec<f64>> {
        let mu = self.multipliers(fixed)?;
        let mut z = self.f.x0.clone();
        for (&(k, _), m) in fixed.iter().zip(&mu) {
            let (b, _) = self.f.at[self.open[k] as usize];
            for (i, &v) in self.f.blocks[b as usize].vars.iter().enumerate() {
                z[v as usize] += m * self.columns[k][i];
            }
        }
        for &(k, x) in fixed {
            z[self.open[k] as usize] = x;
        }
        Some(z)
    }
}

#[cfg(test)]
mod tests;
