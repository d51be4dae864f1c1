//! The frame field's sources and what it implies for the mesh: matchings across faces and the
//! singular edges (CubeCover, Nieser, Reitebuch, Polthier 2011, §2.2 and §3.2).
//!
//! # Sources (§3.2)
//!
//! * **Constant**: every tetrahedron gets the coordinate axes. With boundary alignment this is
//!   a polycube map: every boundary face is flattened onto the integer plane of the axis
//!   nearest its normal.
//! * **Meta-mesh** ([`meta_frames`]): the paper's method. The user gives a coarse hexahedral
//!   mesh covering the solid (any hex mesh [`crate::volume`] reads: `.vtk`, `.mesh`,
//!   `.msh`); a tetrahedron takes the frame of the meta-hex that contains its centroid (the
//!   nearest meta-hex by centroid when none does): the orthonormal part (polar decomposition)
//!   of the trilinear map's Jacobian there, so `frame[k]` follows the hex's `k`-th parameter
//!   direction (VTK order: `v0→v1`, `v0→v3`, `v0→v4`).
//! * **Smooth**: boundary-aligned smooth frames, [`super::smooth_frames`].
//!
//! # Matchings and singular edges (§2.2)
//!
//! The matching across the face from `t` to its neighbour `s` is the cube rotation closest to
//! `F_sᵀ F_t` ([`super::rotation::matching`]): it maps parameter coordinates of `t`'s chart to
//! `s`'s. Both sides are made consistent (`Π_st = Π_ts⁻¹`). Around an interior edge, the
//! product of the matchings over its star (walked in its rotation order, in the chart of the
//! star's first tetrahedron) is the edge's holonomy. The identity is a regular edge; a quarter
//! turn about the parameter axis along the edge makes a singular edge of valence 3 (a turn
//! of +90° about the edge's direction: three cubes fill the full turn) or 5 (−90°), a half
//! turn one of valence 2 or 6. Any other holonomy (about another axis, or a third turn about a
//! diagonal) cannot occur in a hexahedral mesh: such an edge is reported, as is a turn axis
//! more than 45° from the edge, and a singular curve that ends inside the solid (an interior
//! vertex with exactly one singular edge). At a vertex where several singular edges meet (a
//! node) the numbers of valence-3 and valence-5 edges are reported with it.

use super::mesh::{Frame, HexMesh, NO_TET, TetMesh};
use super::rotation::{Holonomy, Rot, holonomy, matching};
use super::topology::Topology;
use crate::geom::vec::{dot, norm, sub};

/// The identity frame.
pub const IDENTITY: Frame = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Constant frames: the coordinate axes in every tetrahedron.
pub fn constant_frames(tets: usize) -> Vec<Frame> {
    vec![IDENTITY; tets]
}

/// Trilinear shape functions' derivatives at `(ξ, η, ζ) ∈ [0, 1]³` in VTK corner order: the
/// map's value and its Jacobian (columns `∂/∂ξ`, `∂/∂η`, `∂/∂ζ`).
fn trilinear(c: &[[f64; 3]; 8], p: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    // Corner k at parameter (i, j, l).
    const AT: [[f64; 3]; 8] = [
        [0., 0., 0.],
        [1., 0., 0.],
        [1., 1., 0.],
        [0., 1., 0.],
        [0., 0., 1.],
        [1., 0., 1.],
        [1., 1., 1.],
        [0., 1., 1.],
    ];
    let mut x = [0.0; 3];
    let mut jac = [[0.0; 3]; 3]; // jac[d][r]: ∂x_r/∂p_d
    for (k, a) in AT.iter().enumerate() {
        let w = |d: usize| if a[d] == 1.0 { p[d] } else { 1.0 - p[d] };
        let dw = |d: usize| if a[d] == 1.0 { 1.0 } else { -1.0 };
        let val = w(0) * w(1) * w(2);
        let grad = [
            dw(0) * w(1) * w(2),
            w(0) * dw(1) * w(2),
            w(0) * w(1) * dw(2),
        ];
        for r in 0..3 {
            x[r] += val * c[k][r];
            for d in 0..3 {
                jac[d][r] += grad[d] * c[k][r];
            }
        }
    }
    (x, jac)
}

/// The parameter of `q` in the trilinear hex `c` by Newton's method, if it converges.
fn invert_trilinear(c: &[[f64; 3]; 8], q: [f64; 3]) -> Option<[f64; 3]> {
    let mut p = [0.5; 3];
    for _ in 0..20 {
        let (x, j) = trilinear(c, p);
        let r = sub(q, x);
        let m = nalgebra::Matrix3::from_fn(|row, col| j[col][row]);
        let step = m.lu().solve(&nalgebra::Vector3::new(r[0], r[1], r[2]))?;
        for d in 0..3 {
            p[d] += step[d];
        }
        if step.norm() < 1e-12 {
            break;
        }
    }
    p.iter().all(|x| x.is_finite()).then_some(p)
}

/// The orthonormal part of a Jacobian (columns the parameter directions), as a right-handed
/// frame; `None` for a degenerate or inverted one.
fn polar_frame(j: &[[f64; 3]; 3]) -> Option<Frame> {
    let m = nalgebra::Matrix3::from_fn(|row, col| j[col][row]);
    if m.determinant().is_nan() || m.determinant() <= 0.0 {
        return None;
    }
    let svd = m.svd(true, true);
    let r = svd.u? * svd.v_t?;
    Some([0, 1, 2].map(|k| [r[(0, k)], r[(1, k)], r[(2, k)]]))
}

/// Why meta-mesh frames could not be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MetaError {
    /// The meta-mesh has no hexahedra.
    #[error("the meta-mesh holds no hexahedra")]
    Empty,
    /// A meta-hex is inverted or degenerate at its centre.
    #[error("meta-hex {0} is inverted or degenerate at its centre")]
    BadHex(usize),
}

/// Frames from a coarse hexahedral meta-mesh (module docs): per tetrahedron, the orthonormal
/// part of the Jacobian of the meta-hex containing its centroid, at the centroid.
pub fn meta_frames(mesh: &TetMesh, meta: &HexMesh) -> Result<Vec<Frame>, MetaError> {
    use kiddo::{KdTree, SquaredEuclidean};
    if meta.hexes.is_empty() {
        return Err(MetaError::Empty);
    }
    let corners: Vec<[[f64; 3]; 8]> = meta
        .hexes
        .iter()
        .map(|h| h.map(|v| meta.verts[v as usize]))
        .collect();
    let mut centre_frames = Vec::with_capacity(corners.len());
    let mut tree: KdTree<f64, 3> = KdTree::with_capacity(corners.len());
    for (h, c) in corners.iter().enumerate() {
        let (x, j) = trilinear(c, [0.5; 3]);
        centre_frames.push(polar_frame(&j).ok_or(MetaError::BadHex(h))?);
        tree.add(&x, h as u64);
    }
    let k = 8.min(corners.len());
    Ok((0..mesh.tets.len())
        .map(|t| {
            let cs = mesh.corners(t);
            let q = [0, 1, 2].map(|r| cs.iter().map(|c| c[r]).sum::<f64>() / 4.0);
            let near = tree.nearest_n::<SquaredEuclidean>(&q, k);
            for n in &near {
                let c = &corners[n.item as usize];
                if let Some(p) = invert_trilinear(c, q)
                    && p.iter().all(|&x| (-1e-9..=1.0 + 1e-9).contains(&x))
                    && let Some(f) = polar_frame(&trilinear(c, p).1)
                {
                    return f;
                }
            }
            centre_frames[near[0].item as usize]
        })
        .collect())
}

/// The matchings of a frame field: `m[t][i]` maps `t`'s parameter coordinates into those of
/// its neighbour across face `i` ([`Rot::ID`] on the boundary); `m[s][j] = m[t][i]⁻¹` for the
/// same face seen from the other side.
pub fn matchings(frames: &[Frame], topo: &Topology) -> Vec<[Rot; 4]> {
    let nb = &topo.neighbours;
    let mut m = vec![[Rot::ID; 4]; nb.len()];
    for t in 0..nb.len() {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET || (s as usize) < t {
                continue;
            }
            let r = matching(&frames[t], &frames[s as usize]);
            m[t][i] = r;
            let j = face_index(nb, s as usize, t as u32);
            m[s as usize][j] = r.inverse();
        }
    }
    m
}

/// The local face of `s` shared with `t`.
pub fn face_index(nb: &[[u32; 4]], s: usize, t: u32) -> usize {
    nb[s]
        .iter()
        .position(|&x| x == t)
        .expect("neighbours point back")
}

/// A singular edge of the frame field.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SingularEdge {
    /// Index into [`Topology::edges`].
    pub edge: u32,
    /// Its vertices.
    pub verts: [u32; 2],
    /// 3 or 5 for quarter turns, 6 for a half turn (2 or 6; 6 is reported).
    pub valence: u8,
    /// The parameter axis along the edge, in the chart of the first tetrahedron of its star.
    pub axis: u8,
}

/// A configuration of the frame field that no hexahedral mesh has.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum Invalid {
    /// The holonomy is not a quarter or half turn about a parameter axis.
    Holonomy {
        /// The edge's vertices.
        verts: [u32; 2],
        /// The holonomy's matrix.
        matrix: [[i8; 3]; 3],
    },
    /// The turn's axis is far from the edge's direction.
    Misaligned {
        /// The edge's vertices.
        verts: [u32; 2],
        /// Angle between the edge and the turn's axis, degrees.
        angle_deg: f64,
    },
    /// A singular curve ends at an interior vertex.
    Dangling {
        /// The vertex.
        vertex: u32,
        /// The singular edge that ends there.
        verts: [u32; 2],
    },
}

impl std::fmt::Display for Invalid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Invalid::Holonomy { verts, matrix } => write!(
                f,
                "edge {}–{}: the matchings around it compose to {matrix:?}, a turn no hexahedral mesh has around an edge",
                verts[0], verts[1]
            ),
            Invalid::Misaligned { verts, angle_deg } => write!(
                f,
                "edge {}–{}: singular, but its turn's axis is {angle_deg:.1}° from the edge",
                verts[0], verts[1]
            ),
            Invalid::Dangling { vertex, verts } => write!(
                f,
                "vertex {vertex}: the singular curve through edge {}–{} ends inside the solid",
                verts[0], verts[1]
            ),
        }
    }
}

/// A vertex where three or more singular edges meet.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Node {
    /// The vertex.
    pub vertex: u32,
    /// Valence-3 edges at it.
    pub valence3: u32,
    /// Valence-5 edges at it.
    pub valence5: u32,
    /// Valence-2/6 edges at it.
    pub valence6: u32,
}

/// The singularity graph: its edges, nodes and invalid configurations.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Singularities {
    /// The singular interior edges.
    pub edges: Vec<SingularEdge>,
    /// Vertices where three or more meet.
    pub nodes: Vec<Node>,
    /// What makes the field unusable, in edge then vertex order.
    pub invalid: Vec<Invalid>,
}

impl Singularities {
    /// Singular edges of each valence `[3, 5, 6]`.
    pub fn by_valence(&self) -> [usize; 3] {
        let mut c = [0; 3];
        for e in &self.edges {
            c[match e.valence {
                3 => 0,
                5 => 1,
                _ => 2,
            }] += 1;
        }
        c
    }
}

/// The product of the matchings around interior edge `e`, in the chart of its star's first
/// tetrahedron: the map a chart returns as after the full turn.
pub fn edge_holonomy(topo: &Topology, m: &[[Rot; 4]], e: usize) -> Rot {
    let star = topo.star(e);
    let mut h = Rot::ID;
    for k in 0..star.len() {
        let (t, s) = (star[k] as usize, star[(k + 1) % star.len()]);
        let i = face_index(&topo.neighbours, t, s);
        h = m[t][i].compose(h);
    }
    h
}

/// Classifies every interior edge and checks the singularity graph (module docs).
pub fn singularities(
    mesh: &TetMesh,
    topo: &Topology,
    frames: &[Frame],
    m: &[[Rot; 4]],
) -> Singularities {
    let mut out = Singularities::default();
    let nv = mesh.verts.len();
    let mut count = vec![[0u32; 3]; nv];
    let mut last = vec![u32::MAX; nv];
    for e in 0..topo.num_edges() {
        if topo.edge_on_boundary[e] {
            continue;
        }
        let h = edge_holonomy(topo, m, e);
        let verts = topo.edges[e];
        match holonomy(h) {
            Holonomy::Regular => {}
            Holonomy::Invalid => out.invalid.push(Invalid::Holonomy {
                verts,
                matrix: h.matrix(),
            }),
            Holonomy::Turn {
                axis,
                quarter_turns,
            } => {
                let t0 = topo.star(e)[0] as usize;
                let d = sub(mesh.verts[verts[1] as usize], mesh.verts[verts[0] as usize]);
                let along = dot(frames[t0][axis], d) / norm(d);
                let angle_deg = along.abs().min(1.0).acos().to_degrees();
                if angle_deg > 45.0 {
                    out.invalid.push(Invalid::Misaligned { verts, angle_deg });
                    continue;
                }
                // Quarter turns about the edge's direction a → b.
                let q = if along > 0.0 {
                    quarter_turns
                } else {
                    (4 - quarter_turns) % 4
                };
                let valence = match q {
                    1 => 3,
                    3 => 5,
                    _ => 6,
                };
                out.edges.push(SingularEdge {
                    edge: e as u32,
                    verts,
                    valence,
                    axis: axis as u8,
                });
                for v in verts {
                    count[v as usize][match valence {
                        3 => 0,
                        5 => 1,
                        _ => 2,
                    }] += 1;
                    last[v as usize] = e as u32;
                }
            }
        }
    }
    for v in 0..nv {
        let c = count[v];
        let n = c[0] + c[1] + c[2];
        if n == 1 && !topo.vertex_on_boundary[v] {
            out.invalid.push(Invalid::Dangling {
                vertex: v as u32,
                verts: topo.edges[last[v] as usize],
            });
        }
        if n >= 3 {
            out.nodes.push(Node {
                vertex: v as u32,
                valence3: c[0],
                valence5: c[1],
                valence6: c[2],
            });
        }
    }
    out
}
