//! The solve of the module docs of [`super`] ("Energy", "Solve"), step by step: the scalar
//! matrix `L + diag(·)` factored as the preconditioner, conjugate gradients on the relaxed
//! system (Ray §4.1), the energy `E`, the projection of every tetrahedron's coefficients
//! (Huang §5.1, Ray §4.2), and the local Gauss–Seidel sweeps over a colouring of the dual
//! graph (Huang §5.2).

use rayon::prelude::*;

use super::boundary::{Kind, Setup};
use super::sh::{dist2_9, dot9, frame_to_sh, project, refine};
use crate::geom::vec::dot;
use crate::mesh::{Frame, NO_TET};
use crate::sparse::{LowerMatrix, NumericFactor};

/// The scalar matrix `L + diag(extra)`, lower triangle, in compressed columns.
pub(super) fn scalar_matrix(nb: &[[u32; 4]], s: &Setup, extra: &[f64]) -> LowerMatrix {
    let n = nb.len();
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut rows = Vec::with_capacity(3 * n);
    let mut vals = Vec::with_capacity(3 * n);
    col_ptr.push(0usize);
    for t in 0..n {
        rows.push(t);
        vals.push(s.deg[t] + extra[t] + s.eps);
        let mut below: Vec<(usize, f64)> = (0..4)
            .filter(|&i| nb[t][i] != NO_TET && nb[t][i] as usize > t)
            .map(|i| (nb[t][i] as usize, -s.w[t][i]))
            .collect();
        below.sort_by_key(|e| e.0);
        for (r, v) in below {
            rows.push(r);
            vals.push(v);
        }
        col_ptr.push(rows.len());
    }
    LowerMatrix::from_columns(n, col_ptr, rows, vals)
}

/// Chunked sum, fixed order whatever the thread count.
pub(super) fn par_dot(a: &[[f64; 9]], b: &[[f64; 9]]) -> f64 {
    const CHUNK: usize = 4096;
    let parts: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| dot9(p, q)).sum())
        .collect();
    parts.iter().sum()
}

/// `A x` of the relaxed system.
pub(super) fn relaxed_apply(nb: &[[u32; 4]], s: &Setup, x: &[[f64; 9]]) -> Vec<[f64; 9]> {
    (0..x.len())
        .into_par_iter()
        .map(|t| {
            let mut y = x[t].map(|v| v * (s.deg[t] + s.eps));
            for i in 0..4 {
                if nb[t][i] != NO_TET {
                    let u = &x[nb[t][i] as usize];
                    for m in 0..9 {
                        y[m] -= s.w[t][i] * u[m];
                    }
                }
            }
            let b = match &s.kind[t] {
                Kind::Free => None,
                Kind::Axis(ax) => Some(ax.perp(&x[t])),
                Kind::Fixed(_) => Some(x[t]),
            };
            if let Some(b) = b {
                for m in 0..9 {
                    y[m] += s.lambda[t] * b[m];
                }
            }
            y
        })
        .collect()
}

/// Preconditioned conjugate gradients; returns (x, iterations, relative residual).
pub(super) fn pcg(
    nb: &[[u32; 4]],
    s: &Setup,
    pre: &NumericFactor,
    b: &[[f64; 9]],
    tol: f64,
    max_iter: usize,
) -> (Vec<[f64; 9]>, usize, f64) {
    let n = b.len();
    let bnorm = par_dot(b, b).sqrt();
    let mut x = vec![[0.0; 9]; n];
    if bnorm == 0.0 {
        return (x, 0, 0.0);
    }
    let mut r = b.to_vec();
    let mut z = pre.solve(&r);
    let mut p = z.clone();
    let mut rz = par_dot(&r, &z);
    let mut it = 0;
    let mut rel = 1.0;
    while it < max_iter {
        let ap = relaxed_apply(nb, s, &p);
        let pap = par_dot(&p, &ap);
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        x.par_iter_mut()
            .zip(r.par_iter_mut())
            .zip(p.par_iter().zip(ap.par_iter()))
            .for_each(|((xi, ri), (pi, api))| {
                for m in 0..9 {
                    xi[m] += alpha * pi[m];
                    ri[m] -= alpha * api[m];
                }
            });
        it += 1;
        rel = par_dot(&r, &r).sqrt() / bnorm;
        if rel <= tol {
            break;
        }
        z = pre.solve(&r);
        let rz_new = par_dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut().zip(z.par_iter()).for_each(|(pi, zi)| {
            for m in 0..9 {
                pi[m] = zi[m] + beta * pi[m];
            }
        });
    }
    (x, it, rel)
}

/// `E` of a field given by its coefficients.
pub(super) fn energy(nb: &[[u32; 4]], s: &Setup, q: &[[f64; 9]]) -> f64 {
    let mut e = 0.0;
    for t in 0..q.len() {
        for i in 0..4 {
            let u = nb[t][i];
            if u != NO_TET && (u as usize) > t {
                e += s.w[t][i] * dist2_9(&q[t], &q[u as usize]);
            }
        }
    }
    e
}

/// Projects every tet's coefficients onto its admissible frames; returns the frames and the
/// largest residual `|q̂ − q(frame)|` of the free tets.
pub(super) fn project_all(s: &Setup, q: &[[f64; 9]]) -> (Vec<Frame>, f64) {
    let out: Vec<(Frame, f64)> = q
        .par_iter()
        .zip(s.kind.par_iter())
        .map(|(q, k)| match k {
            Kind::Free => project(q),
            Kind::Axis(ax) => (ax.project(q), 0.0),
            Kind::Fixed(f) => (*f, 0.0),
        })
        .collect();
    let res = out.iter().map(|o| o.1).fold(0.0, f64::max);
    (out.into_iter().map(|o| o.0).collect(), res)
}

/// Greedy colouring of the dual graph: no two neighbours share a colour.
pub(super) fn colour_classes(nb: &[[u32; 4]]) -> Vec<Vec<usize>> {
    let n = nb.len();
    let mut colour = vec![u8::MAX; n];
    let mut classes: Vec<Vec<usize>> = Vec::new();
    for t in 0..n {
        let mut used = 0u32;
        for &u in &nb[t] {
            if u != NO_TET && colour[u as usize] != u8::MAX {
                used |= 1 << colour[u as usize];
            }
        }
        let c = used.trailing_ones() as usize;
        colour[t] = c as u8;
        if classes.len() <= c {
            classes.resize(c + 1, Vec::new());
        }
        classes[c].push(t);
    }
    classes
}

/// One block Gauss–Seidel sweep over the colour classes.
pub(super) fn local_sweep(
    nb: &[[u32; 4]],
    s: &Setup,
    classes: &[Vec<usize>],
    frames: &mut [Frame],
    q: &mut [[f64; 9]],
) {
    for class in classes {
        let updates: Vec<Option<Frame>> = class
            .par_iter()
            .map(|&t| {
                let mut target = [0.0; 9];
                for i in 0..4 {
                    if nb[t][i] != NO_TET {
                        let u = &q[nb[t][i] as usize];
                        for m in 0..9 {
                            target[m] += s.w[t][i] * u[m];
                        }
                    }
                }
                match &s.kind[t] {
                    Kind::Fixed(_) => None,
                    Kind::Axis(ax) => Some(ax.project(&target)),
                    Kind::Free => {
                        let nt = dot9(&target, &target).sqrt();
                        if nt.is_nan() || nt <= 1e-300 {
                            return None;
                        }
                        let tn = target.map(|v| v / nt);
                        let cur = dist2_9(&q[t], &tn);
                        let (f, d2) = refine(&tn, frames[t], 10);
                        (d2 < cur).then_some(f)
                    }
                }
            })
            .collect();
        for (&t, up) in class.iter().zip(updates) {
            if let Some(f) = up {
                frames[t] = f;
                q[t] = frame_to_sh(&f);
            }
        }
    }
}

/// Largest angle (degrees) between a boundary face's normal and its tet's nearest axis.
pub(super) fn misalignment_deg(s: &Setup, frames: &[Frame]) -> f64 {
    s.bfaces
        .iter()
        .map(|&(t, n)| {
            let c = frames[t]
                .iter()
                .map(|a| dot(*a, n).abs())
                .fold(0.0, f64::max)
                .min(1.0);
            c.acos().to_degrees()
        })
        .fold(0.0, f64::max)
}
