//! The energy of §3.1 in the free unknowns (module docs of [`super`], "Unknowns and energy"):
//! the tetrahedra's local energies `vol_t |∇x_t − T_t/s|²`, the reduced normal equations
//! (every unknown an expression of the elimination), split into their independent blocks and
//! each factored by sparse Cholesky, and the untangling of a rounded map (module docs,
//! "Untangling").

use faer::Mat;

use super::cut::Cut;
use super::elim::{Elim, Expr};
use super::{Field, ParamParams, gradients};
use crate::geom::vec::dot;
use crate::mesh::{Frame, TetMesh};
use crate::rotation::Rot;
use crate::sparse::{CholeskyFactor, Triplets};
use crate::topology::{find, union};

/// What the energy `Σ_t vol_t |∇x_t − T_t/s|²` of each tetrahedron reads: its barycentric
/// gradients, its target gradients in its aligned chart over the scale, its volume.
pub(super) struct LocalEnergies {
    pub(super) grads: Vec<[[f64; 3]; 4]>,
    pub(super) targets: Vec<Frame>,
    pub(super) volumes: Vec<f64>,
    pub(super) total_volume: f64,
}

impl LocalEnergies {
    /// The energy of the map of `values` (corners by `corner_cv`) over the total volume.
    pub(super) fn mean(&self, corner_cv: &[u32], values: &[f64]) -> f64 {
        energy(
            &corner_params(corner_cv, values),
            &self.grads,
            &self.targets,
            &self.volumes,
        ) / self.total_volume
    }
}

/// The local energies of the tetrahedra (module docs, "Unknowns and energy").
pub(super) fn local_energies(
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

/// A frame's axes in an aligned chart: row `r` of `R F`.
pub(super) fn aligned_frame(f: &Frame, chart: Rot) -> Frame {
    let m = chart.matrix();
    [0, 1, 2].map(|r| [0, 1, 2].map(|x| (0..3).map(|k| f64::from(m[r][k]) * f[k][x]).sum()))
}

pub(super) fn corner_params(corner_cv: &[u32], values: &[f64]) -> Vec<[[f64; 3]; 4]> {
    corner_cv
        .chunks_exact(4)
        .map(|c| std::array::from_fn(|j| std::array::from_fn(|r| values[3 * c[j] as usize + r])))
        .collect()
}

/// `Σ vol |∇x − F/s|²` over the tetrahedra.
pub(super) fn energy(
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

/// The reduced normal equations over the free variables.
pub(super) struct System<'a> {
    /// Per free variable, the position of its vertex (NaN for an integer unknown): the
    /// factorisation's nested-dissection ordering.
    pub(super) points: &'a [[f64; 3]],
    pub(super) elim: &'a Elim,
    pub(super) index: &'a [u32],
    pub(super) corner_cv: &'a [u32],
    pub(super) grads: &'a [[[f64; 3]; 4]],
    pub(super) targets: &'a [Frame],
    pub(super) volumes: &'a [f64],
}

impl System<'_> {
    /// Untangles the map of the free unknowns `z` ([`crate::untangle`]), moving those marked
    /// `movable`; `ncv` cut vertices, each tetrahedron measured against its target gradients.
    pub(super) fn untangle(
        &self,
        exprs: &[Expr],
        ncv: usize,
        z: &mut [f64],
        movable: &[bool],
    ) -> crate::untangle::UntangleReport {
        use crate::untangle::{Affine, Problem, UntangleParams, untangle};
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
    pub(super) fn factor(&self, n: usize) -> Result<Factored, String> {
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
pub(super) struct Block {
    /// Its free variables (indices into the free list), ascending.
    pub(super) vars: Vec<u32>,
    pub(super) factor: CholeskyFactor,
}

/// The normal equations over the free variables, factored block by block.
pub(super) struct Factored {
    /// Per free variable, its block and its index in the block.
    pub(super) at: Vec<(u32, u32)>,
    pub(super) blocks: Vec<Block>,
    /// The solution with every free variable free.
    pub(super) x0: Vec<f64>,
    /// Nonzeros of the matrix's lower triangle.
    pub(super) nnz: usize,
}
