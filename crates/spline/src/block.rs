//! One block of a block Gauss–Seidel fit: the coefficients of a subset of the basis
//! functions solved with all others held fixed (Greiner & Hormann 1997, §7, solve the
//! systems block by block; here a block is the set of functions owned by one terrain tile).
//!
//! With the free set `F` and the fixed set `X`, minimising the penalty functional over
//! `c_F` gives `(B_Fᵀ B_F + ω s A_FF) c_F = B_Fᵀ (P - B_X c_X) - ω s A_FX c_X`, where the data
//! term runs over every point in the supports of `F` (the tile's points and its halo) and
//! the fairness term over every leaf cell those supports touch. `s = tr(B_FᵀB_F) / tr(A_FF)`
//! keeps `ω` dimensionless as in the single fit. Sweeping the blocks in a fixed order until
//! the coefficients settle is Gauss–Seidel on the whole system, so the result approaches the
//! single fit's; and since every block's coefficients belong to one spline, the tiles' pieces
//! meet exactly.

use super::basis::GAUSS4;
use super::fit::{FitError, metric};
use super::hier::{Hierarchy, LocalBasis, Support};
use crate::sparse::{Triplets, cholesky};
use crate::types::TensorSurface;

/// Solves the block of the functions `free` (sorted global indices) against `pts` at their
/// parameters `uv`, every other coefficient taken from `coef`; writes the block's new
/// coefficients into `coef`. `rect` is the parameter box `[lo, hi]` of the leaf cells whose
/// fairness enters (the supports of `free`).
#[allow(clippy::too_many_arguments)]
pub fn solve_block(
    h: &Hierarchy,
    coef: &mut [[f64; 3]],
    free: &[u32],
    local: &mut [u32],
    pts: &[[f64; 3]],
    uv: &[[f64; 2]],
    rect: [[f64; 2]; 2],
    omega: f64,
    reference: Option<&TensorSurface>,
) -> Result<(), FitError> {
    let n = free.len();
    if n == 0 {
        return Ok(());
    }
    for (k, &f) in free.iter().enumerate() {
        local[f as usize] = k as u32;
    }
    let mut data = Triplets::new(n);
    let mut rhs = vec![[0.0f64; 3]; n];
    let mut sup: Vec<Support> = Vec::new();
    let mut lb = LocalBasis::default();
    // Points grouped by leaf cell: one dense block per leaf over its free functions.
    let mut order: Vec<(super::hier::Leaf, u32)> = uv
        .iter()
        .enumerate()
        .map(|(i, &q)| (h.leaf_of(q), i as u32))
        .collect();
    order.sort_unstable();
    let mut start = 0;
    let mut free_sup: Vec<(usize, usize)> = Vec::new();
    let mut block: Vec<f64> = Vec::new();
    while start < order.len() {
        let leaf = order[start].0;
        let end = start + order[start..].iter().take_while(|o| o.0 == leaf).count();
        h.supports(leaf, &mut sup);
        free_sup.clear();
        for (k, s) in sup.iter().enumerate() {
            let li = local[s.index as usize];
            if li != u32::MAX {
                free_sup.push((k, li as usize));
            }
        }
        let m = free_sup.len();
        block.clear();
        block.resize(m * m, 0.0);
        let mut vals = vec![0.0f64; sup.len()];
        for &(_, i) in &order[start..end] {
            let i = i as usize;
            h.local_basis(leaf, uv[i], &mut lb);
            let mut r = pts[i];
            for (k, s) in sup.iter().enumerate() {
                vals[k] = lb.value(s);
                let li = local[s.index as usize];
                if li == u32::MAX {
                    let c = coef[s.index as usize];
                    for x in 0..3 {
                        r[x] -= vals[k] * c[x];
                    }
                }
            }
            for (a, &(ka, la)) in free_sup.iter().enumerate() {
                for (b, &(kb, _)) in free_sup[..=a].iter().enumerate() {
                    block[a * m + b] += vals[ka] * vals[kb];
                }
                for x in 0..3 {
                    rhs[la][x] += vals[ka] * r[x];
                }
            }
        }
        for (a, &(_, la)) in free_sup.iter().enumerate() {
            for (b, &(_, lb2)) in free_sup[..=a].iter().enumerate() {
                let v = block[a * m + b];
                if v != 0.0 {
                    data.push(la.max(lb2), la.min(lb2), v);
                }
            }
        }
        start = end;
    }
    // Fairness over the leaves inside rect: the free-free block and the free-fixed coupling.
    let (mut fair, coupling) = fairness(h, coef, local, rect, reference, n, &mut sup, &mut lb);
    let ta = data.trace();
    let tf = fair.trace();
    let s = if tf > 0.0 { ta / tf } else { 1.0 };
    let w = omega * s;
    for (r, c) in rhs.iter_mut().zip(&coupling) {
        for x in 0..3 {
            r[x] -= w * c[x];
        }
    }
    data.add_scaled(&fair, w);
    let solved = match cholesky(&mut data, &rhs) {
        Ok(c) if c.iter().all(|c| c.iter().all(|x| x.is_finite())) => c,
        _ => {
            let ridge = 1e-12 * ta.max(1e-300) / n as f64;
            for i in 0..n {
                data.push(i, i, ridge);
            }
            cholesky(&mut data, &rhs).map_err(FitError::Solve)?
        }
    };
    for (&f, c) in free.iter().zip(solved) {
        coef[f as usize] = c;
        local[f as usize] = u32::MAX;
    }
    Ok(())
}

/// The fairness term of a block of `n` free functions (`local`: their local indices, or
/// `u32::MAX` for fixed ones) over the leaf cells inside `rect`: the free-free block and
/// the coupling to the fixed coefficients of `coef`, both before the scale `ω s`. `sup` and
/// `lb` are scratch.
#[allow(clippy::too_many_arguments)]
fn fairness(
    h: &Hierarchy,
    coef: &[[f64; 3]],
    local: &[u32],
    rect: [[f64; 2]; 2],
    reference: Option<&TensorSurface>,
    n: usize,
    sup: &mut Vec<Support>,
    lb: &mut LocalBasis,
) -> (Triplets, Vec<[f64; 3]>) {
    let mut fair = Triplets::new(n);
    let mut coupling = vec![[0.0f64; 3]; n];
    for leaf in h.leaves() {
        let hl = h.spacing(leaf.level as usize);
        let lo = [leaf.cell[0] as f64 * hl, leaf.cell[1] as f64 * hl];
        if lo[0] >= rect[1][0]
            || lo[1] >= rect[1][1]
            || lo[0] + hl <= rect[0][0]
            || lo[1] + hl <= rect[0][1]
        {
            continue;
        }
        h.supports(leaf, sup);
        if sup.iter().all(|s| local[s.index as usize] == u32::MAX) {
            continue;
        }
        let mut d2 = vec![[0.0f64; 3]; sup.len()];
        for &(gu, wu) in &GAUSS4 {
            for &(gv, wv) in &GAUSS4 {
                let q = [lo[0] + gu * hl, lo[1] + gv * hl];
                h.local_basis(leaf, q, lb);
                let refd = reference.map(|s| super::tensor::eval(s, q));
                let (m, area) = metric(refd.as_ref().map(|d| (&d[1], &d[2])));
                let w = wu * wv * hl * hl * area;
                for (k, s) in sup.iter().enumerate() {
                    let d = lb.derivs(s);
                    d2[k] = [d[3], d[4], d[5]];
                }
                for (a, sa) in sup.iter().enumerate() {
                    let la = local[sa.index as usize];
                    if la == u32::MAX {
                        continue;
                    }
                    let ma = [0, 1, 2]
                        .map(|r| m[r][0] * d2[a][0] + m[r][1] * d2[a][1] + m[r][2] * d2[a][2]);
                    for (b, sb) in sup.iter().enumerate() {
                        let v = w * (ma[0] * d2[b][0] + ma[1] * d2[b][1] + ma[2] * d2[b][2]);
                        let lbi = local[sb.index as usize];
                        if lbi == u32::MAX {
                            let c = coef[sb.index as usize];
                            for x in 0..3 {
                                coupling[la as usize][x] += v * c[x];
                            }
                        } else if lbi <= la {
                            fair.push(la as usize, lbi as usize, v);
                        }
                    }
                }
            }
        }
    }
    (fair, coupling)
}
