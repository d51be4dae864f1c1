//! The constraints of §3.1 (module docs of [`super`], "Constraints") as rows over the
//! unknowns: the translation anchors, the cut faces' transitions with their integer gaps,
//! the boundary faces' integer planes and the singular edges' integer lines, each integer
//! unknown named ([`super::IntegerVar`]); and their elimination, a contradiction naming the
//! constraint.

use super::cut::{Cut, CutVertices, local};
use super::elim::Elim;
use super::system::aligned_frame;
use super::{Field, IntegerVar, ParamError, ParamReport};
use crate::geom::vec::{cross, dot, sub};
use crate::mesh::{FACE_OPPOSITE, NO_TET, TetMesh};
use crate::topology::Topology;

/// A linear constraint `Σ cᵢ yᵢ = rhs`: the terms and the right-hand side.
pub(super) type Row = (Vec<(u32, f64)>, f64);

/// The aligned axis of each boundary face's plane: the given one ([`Field::axes`]), or the
/// frame axis nearest its normal.
pub(super) fn face_axes(
    mesh: &TetMesh,
    topo: &Topology,
    field: &Field<'_>,
    cut: &Cut,
) -> Vec<usize> {
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
pub(super) fn constraint_rows(
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
pub(super) fn eliminate(rows: &[Row], base: u32, names: &[IntegerVar]) -> Result<Elim, ParamError> {
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

pub(super) fn describe_row(row: &[(u32, f64)], base: u32, names: &[IntegerVar]) -> String {
    row.iter().find(|t| t.0 >= base).map_or_else(
        || "the fixed corner".to_string(),
        |t| names[(t.0 - base) as usize].to_string(),
    )
}
