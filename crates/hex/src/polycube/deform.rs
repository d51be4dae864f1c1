//! The rotation-driven deformation of the module docs of [`super`] (Gregson et al. §4.1–4.2):
//! the spread of the boundary targets' rotations by the Laplacian `L` (steps 1–2), the
//! least-squares positions from the rotated, stretch-clamped gradients with the step control
//! and the stiffening of blocking tetrahedra (step 3), one phase of iterations; with the
//! polar decomposition and stretch clamp they use.

use nalgebra::{Matrix3, Rotation3, Vector3};
use rayon::prelude::*;

use super::labels::{axis, boundary_face, deviation, label};
use super::{PolycubeError, PolycubeParams, PolycubeReport};
use crate::mesh::{NO_TET, TetMesh};
use crate::sparse::{CholeskyFactor, Triplets};
use crate::topology::Topology;

/// The rotation nearest `m` (polar decomposition, reflections removed).
pub(super) fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        // Singular values come sorted, largest first: flip the weakest direction.
        let mut u = u;
        for row in 0..3 {
            u[(row, 2)] = -u[(row, 2)];
        }
        r = u * v_t;
    }
    r
}

/// A deformation gradient's stretches kept within `[lo, 1/lo]` (its singular values clamped;
/// a reflection stays): a target never asks a tetrahedron that is already squeezed to
/// shrink further, so the deformation does not stall on one nearly flat tetrahedron.
pub(super) fn clamp_stretch(m: &Matrix3<f64>, lo: f64) -> Matrix3<f64> {
    // Most gradients are within the bounds: the eigenvalues of mᵀm (the squared stretches,
    // in closed form) say so without a singular value decomposition.
    let (min, max) = sym_eigen_range(&(m.transpose() * m));
    if min >= lo * lo && max <= 1.0 / (lo * lo) {
        return *m;
    }
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return *m;
    };
    let s = svd.singular_values.map(|x| x.clamp(lo, 1.0 / lo));
    u * Matrix3::from_diagonal(&s) * v_t
}

/// The smallest and largest eigenvalue of the symmetric `a`, in closed form (the
/// trigonometric solution of the characteristic cubic, Smith 1961).
pub(super) fn sym_eigen_range(a: &Matrix3<f64>) -> (f64, f64) {
    let off = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    if off == 0.0 {
        let d = [a[(0, 0)], a[(1, 1)], a[(2, 2)]];
        return (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]));
    }
    let q = a.trace() / 3.0;
    let p2 =
        (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * off;
    let p = (p2 / 6.0).sqrt();
    let b = (a - Matrix3::identity() * q) / p;
    let phi = (b.determinant() / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    (smallest, largest)
}

/// Smallest stretch a deformation target keeps ([`clamp_stretch`]).
pub(super) const STRETCH: f64 = 0.5;

/// Smallest step towards the solved positions the deformation takes; below it the
/// tetrahedra that would invert are stiffened.
pub(super) const MIN_STEP: f64 = 1.0 / 64.0;

/// Factor by which a blocking tetrahedron's stiffness grows (its neighbours' by the root).
pub(super) const STIFFEN: f64 = 8.0;

/// Most stiffening rounds per iteration before the deformation stops.
pub(super) const STIFFEN_ROUNDS: usize = 4;

/// Deformation state: the input mesh, its per-tetrahedron gradients and volumes.
pub(super) struct Deformation<'a> {
    pub(super) mesh: &'a TetMesh,
    pub(super) grads: Vec<[Vector3<f64>; 4]>,
    pub(super) volumes: Vec<f64>,
}

impl Deformation<'_> {
    pub(super) fn jacobian(&self, y: &[[f64; 3]], t: usize) -> Matrix3<f64> {
        let mut j = Matrix3::zeros();
        for (k, &v) in self.mesh.tets[t].iter().enumerate() {
            j += Vector3::from(y[v as usize]) * self.grads[t][k].transpose();
        }
        j
    }

    /// The vertex pinned in `K`.
    pub(super) fn pinned(&self) -> usize {
        self.mesh.tets[0][0] as usize
    }

    /// `K = Σ w V Gᵀ G` for the weights `stiffness`, one vertex pinned; a tiny shift keeps
    /// unused vertices at rest. Returns the factor and the mean diagonal (the pin's weight).
    pub(super) fn factor_k(
        &self,
        stiffness: &[f64],
    ) -> Result<(CholeskyFactor, f64), PolycubeError> {
        let mesh = self.mesh;
        let (nt, nv) = (mesh.tets.len(), mesh.verts.len());
        let pinned = self.pinned();
        let mut k = Triplets::new(nv);
        let mut trace = 0.0;
        for t in 0..nt {
            let tet = mesh.tets[t];
            for a in 0..4 {
                for b in 0..4 {
                    let (va, vb) = (tet[a] as usize, tet[b] as usize);
                    if vb <= va {
                        let h = stiffness[t]
                            * self.volumes[t]
                            * self.grads[t][a].dot(&self.grads[t][b]);
                        k.push(va, vb, h);
                        if va == vb {
                            trace += h;
                        }
                    }
                }
            }
        }
        let mean = trace / nv.max(1) as f64;
        for v in 0..nv {
            k.push(v, v, 1e-10 * mean);
        }
        k.push(pinned, pinned, mean);
        Ok((
            CholeskyFactor::new(&mut k).map_err(PolycubeError::Solve)?,
            mean,
        ))
    }
}

/// The weights `λ A_f / Ā` of the boundary targets (module docs, step 2): each boundary
/// triangle's input area over their mean.
pub(super) fn boundary_weights(
    mesh: &TetMesh,
    topo: &Topology,
    params: &PolycubeParams,
) -> Vec<f64> {
    let areas: Vec<f64> = (0..topo.boundary.len())
        .map(|f| boundary_face(mesh, topo, &mesh.verts, f).1)
        .collect();
    let mean_area = areas.iter().sum::<f64>() / areas.len().max(1) as f64;
    areas
        .iter()
        .map(|a| params.boundary_weight * a / mean_area.max(f64::MIN_POSITIVE))
        .collect()
}

/// `L`: the graph Laplacian of the tetrahedra across faces plus the boundary `weights` (and
/// a tiny shift on the diagonal), the matrix of step 2.
pub(super) fn rotation_laplacian(topo: &Topology, weights: &[f64]) -> Triplets {
    let nt = topo.neighbours.len();
    let mut l = Triplets::new(nt);
    for t in 0..nt {
        for &s in &topo.neighbours[t] {
            if s != NO_TET && (s as usize) < t {
                l.push(t, t, 1.0);
                l.push(s as usize, s as usize, 1.0);
                l.push(t, s as usize, -1.0);
            }
        }
        l.push(t, t, 1e-10);
    }
    for (f, &(t, _)) in topo.boundary.iter().enumerate() {
        l.push(t as usize, t as usize, weights[f]);
    }
    l
}

/// The stiffness of step 3: the weights `w_t` and the factor of `K` for them, with its mean
/// diagonal (the weight pinning one vertex).
pub(super) struct Stiffness {
    pub(super) w: Vec<f64>,
    pub(super) kf: CholeskyFactor,
    pub(super) mean: f64,
}

/// What the deformation iterations share: the mesh's deformation state, the boundary
/// targets' weights and the factored Laplacian `L` of step 2.
pub(super) struct Deformer<'a> {
    pub(super) def: Deformation<'a>,
    pub(super) topo: &'a Topology,
    pub(super) weights: Vec<f64>,
    pub(super) lf: CholeskyFactor,
    pub(super) params: &'a PolycubeParams,
}

impl Deformer<'_> {
    /// One phase of the deformation (module docs): iterations from `y` until `limit` are
    /// run, the mean deviation from the axes (of the labels `fixed`, else the nearest) is
    /// below the tolerance, it has not fallen for ten iterations, or no step keeps every
    /// tetrahedron positive. `best` keeps the least deviation and its positions.
    pub(super) fn phase(
        &self,
        k: &mut Stiffness,
        y: &mut Vec<[f64; 3]>,
        best: &mut (f64, Vec<[f64; 3]>),
        fixed: Option<&[u8]>,
        limit: usize,
        report: &mut PolycubeReport,
    ) -> Result<(), PolycubeError> {
        let (mesh, topo) = (self.def.mesh, self.topo);
        let mut stale = 0;
        while report.iterations < limit && report.mean_deviation > self.params.tolerance_degrees {
            let r = self.rotations(y, fixed);
            let Some(next) = self.deform(y, &r, k, report)? else {
                break;
            };
            *y = next;
            report.iterations += 1;
            let (dev, _) = deviation(mesh, topo, y, fixed);
            report.mean_deviation = dev;
            if dev < best.0 - 1e-3 {
                *best = (dev, y.clone());
                stale = 0;
            } else {
                stale += 1;
                if stale >= 10 {
                    break;
                }
            }
        }
        Ok(())
    }

    /// Steps 1–2: each boundary triangle's target rotation towards its axis (its `fixed`
    /// label's, else the nearest), spread over the tetrahedra by `L`.
    pub(super) fn rotations(&self, y: &[[f64; 3]], fixed: Option<&[u8]>) -> Vec<Vector3<f64>> {
        let (mesh, topo) = (self.def.mesh, self.topo);
        let mut rhs = vec![[0.0; 3]; mesh.tets.len()];
        for (f, &(t, _)) in topo.boundary.iter().enumerate() {
            let (n, _) = boundary_face(mesh, topo, y, f);
            let a = match fixed {
                Some(l) => axis(l[f]),
                None => label(&n).1,
            };
            let axis = n.cross(&a);
            let s = axis.norm();
            if s > 1e-12 {
                let rho = axis * (s.atan2(n.dot(&a)) / s);
                for d in 0..3 {
                    rhs[t as usize][d] += self.weights[f] * rho[d];
                }
            }
        }
        self.lf.solve(&rhs).into_iter().map(Vector3::from).collect()
    }

    /// Step 3: rigid targets (the rotations `r` of the clamped gradients at `y`), solved for
    /// positions. A tetrahedron that blocks every step (it would turn inside out) is
    /// stiffened and the positions solved again, up to [`STIFFEN_ROUNDS`] times. Returns the
    /// next positions, or `None` when no step keeps every tetrahedron positive.
    pub(super) fn deform(
        &self,
        y: &[[f64; 3]],
        r: &[Vector3<f64>],
        k: &mut Stiffness,
        report: &mut PolycubeReport,
    ) -> Result<Option<Vec<[f64; 3]>>, PolycubeError> {
        let def = &self.def;
        let mesh = def.mesh;
        let (nt, nv) = (mesh.tets.len(), mesh.verts.len());
        let pinned = def.pinned();
        let targets: Vec<Matrix3<f64>> = (0..nt)
            .into_par_iter()
            .map(|t| {
                let turn = Rotation3::new(r[t]).into_inner();
                turn * clamp_stretch(&def.jacobian(y, t), STRETCH)
            })
            .collect();
        let flipped_now: Vec<bool> = (0..nt)
            .into_par_iter()
            .map(|t| def.jacobian(y, t).determinant() <= 0.0)
            .collect();
        for _ in 0..=STIFFEN_ROUNDS {
            let pulls: Vec<[Vector3<f64>; 4]> = (0..nt)
                .into_par_iter()
                .map(|t| def.grads[t].map(|g| targets[t] * g * (k.w[t] * def.volumes[t])))
                .collect();
            let mut b = vec![[0.0; 3]; nv];
            for (tet, pull) in mesh.tets.iter().zip(&pulls) {
                for (&v, qg) in tet.iter().zip(pull) {
                    for d in 0..3 {
                        b[v as usize][d] += qg[d];
                    }
                }
            }
            for d in 0..3 {
                b[pinned][d] += k.mean * y[pinned][d];
            }
            let target = k.kf.solve(&b);
            let blocking = match self.step_towards(y, &target, &flipped_now) {
                Ok(next) => return Ok(Some(next)),
                Err(blocking) => blocking,
            };
            for t in blocking {
                k.w[t] *= STIFFEN;
                for &s in &self.topo.neighbours[t] {
                    if s != NO_TET {
                        k.w[s as usize] *= STIFFEN.sqrt();
                    }
                }
            }
            report.stiffened += 1;
            (k.kf, k.mean) = def.factor_k(&k.w)?;
        }
        Ok(None)
    }

    /// The step from `y` towards the solve's positions `target`, halved while a tetrahedron
    /// would turn inside out (one already flipped, `flipped_now`, does not count). `Err`:
    /// the tetrahedra that would still turn at a step of [`MIN_STEP`].
    pub(super) fn step_towards(
        &self,
        y: &[[f64; 3]],
        target: &[[f64; 3]],
        flipped_now: &[bool],
    ) -> Result<Vec<[f64; 3]>, Vec<usize>> {
        let def = &self.def;
        let nt = def.mesh.tets.len();
        let mut step = 1.0;
        loop {
            let cand: Vec<[f64; 3]> = y
                .par_iter()
                .zip(target)
                .map(|(a, b)| std::array::from_fn(|d| a[d] + step * (b[d] - a[d])))
                .collect();
            let bad: Vec<usize> = (0..nt)
                .into_par_iter()
                .filter(|&t| !flipped_now[t] && def.jacobian(&cand, t).determinant() <= 0.0)
                .collect();
            if bad.is_empty() {
                return Ok(cand);
            }
            if step <= MIN_STEP {
                return Err(bad);
            }
            step *= 0.5;
        }
    }
}
