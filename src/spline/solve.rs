//! Sparse assembly and the two linear systems of the fit (Greiner & Hormann 1997, §7),
//! solved by faer's sparse factorisations (sequential, so the bits do not depend on threads).
//!
//! * Approximation, the penalty method: minimising `|B c - P|² + ω E(c)` over the
//!   coefficients gives the symmetric positive definite system `(BᵀB + ω A₀) c = BᵀP`
//!   (`B` the basis functions at the points' parameters, `A₀` the fairness energy's matrix),
//!   factored by sparse Cholesky `LLᵀ` after a fill-reducing ordering.
//! * Interpolation by Lagrange multipliers: minimising `E(c)` subject to `B c = P` gives the
//!   saddle-point system `[A₀ Bᵀ; B 0] [c; λ] = [0; P]`, factored by sparse LU with partial
//!   pivoting. (The paper relaxes it by block Gauss–Seidel over 4 × 4 sub-grids; a direct
//!   factorisation reaches the `1e-9` interpolation bound without an iteration count to tune.)
//!
//! [`Triplets`] accumulates entries `(row, column, value)` and merges duplicates in a fixed
//! order (stable sort by position, sums in insertion order), so the matrix's bits depend only
//! on the order the entries were pushed in.

use faer::Side;
use faer::prelude::*;
use faer::sparse::{SparseColMat, Triplet};

/// Entries of a sparse matrix, duplicates summed on [`Triplets::compact`].
#[derive(Debug, Default)]
pub struct Triplets {
    n: usize,
    entries: Vec<(u64, f64)>,
    compacted: usize,
}

/// Entries kept unmerged before a compaction.
const COMPACT_EVERY: usize = 1 << 22;

impl Triplets {
    /// An `n × n` matrix with no entries.
    pub fn new(n: usize) -> Triplets {
        Triplets {
            n,
            entries: Vec::new(),
            compacted: 0,
        }
    }

    /// Adds `value` at `(row, col)`.
    pub fn push(&mut self, row: usize, col: usize, value: f64) {
        self.entries
            .push((((col as u64) << 32) | row as u64, value));
        if self.entries.len() - self.compacted > COMPACT_EVERY {
            self.compact();
        }
    }

    /// Sorts by column then row and sums duplicates.
    pub fn compact(&mut self) {
        self.entries.sort_by_key(|e| e.0);
        let mut out: Vec<(u64, f64)> = Vec::with_capacity(self.entries.len());
        for &(k, v) in &self.entries {
            match out.last_mut() {
                Some(last) if last.0 == k => last.1 += v,
                _ => out.push((k, v)),
            }
        }
        self.entries = out;
        self.compacted = self.entries.len();
    }

    /// Unknowns (rows and columns).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of stored entries (after [`Triplets::compact`], the nonzeros).
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no entry is stored.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The sum of the diagonal entries.
    pub fn trace(&mut self) -> f64 {
        self.compact();
        self.entries
            .iter()
            .filter(|(k, _)| (k >> 32) == (k & 0xFFFF_FFFF))
            .map(|e| e.1)
            .sum()
    }

    /// Every entry scaled by `s` and added to `self`.
    pub fn add_scaled(&mut self, other: &Triplets, s: f64) {
        for &(k, v) in &other.entries {
            self.entries.push((k, v * s));
        }
        self.compact();
    }

    fn matrix(&mut self) -> Result<SparseColMat<usize, f64>, String> {
        self.compact();
        let t: Vec<Triplet<usize, usize, f64>> = self
            .entries
            .iter()
            .map(|&(k, v)| Triplet::new((k & 0xFFFF_FFFF) as usize, (k >> 32) as usize, v))
            .collect();
        SparseColMat::try_new_from_triplets(self.n, self.n, &t).map_err(|e| format!("{e:?}"))
    }

    /// `A x` for a symmetric matrix stored as its lower triangle.
    pub fn sym_mul(&self, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let mut y = vec![[0.0; 3]; self.n];
        for &(k, v) in &self.entries {
            let (r, c) = ((k & 0xFFFF_FFFF) as usize, (k >> 32) as usize);
            for d in 0..3 {
                y[r][d] += v * x[c][d];
                if r != c {
                    y[c][d] += v * x[r][d];
                }
            }
        }
        y
    }

    /// The compacted entries as `(row, col, value)`.
    pub fn entries_rc(&self) -> Vec<(usize, usize, f64)> {
        self.entries
            .iter()
            .map(|&(k, v)| ((k & 0xFFFF_FFFF) as usize, (k >> 32) as usize, v))
            .collect()
    }

    /// The trace and the compacted entries as `(row, col, value)`.
    pub fn trace_and_entries(&self) -> (f64, Vec<(usize, usize, f64)>) {
        let e = self.entries_rc();
        let tr = e.iter().filter(|x| x.0 == x.1).map(|x| x.2).sum();
        (tr, e)
    }
}

fn rhs_mat(rhs: &[[f64; 3]], n: usize) -> Mat<f64> {
    Mat::from_fn(n, 3, |i, j| rhs.get(i).map_or(0.0, |r| r[j]))
}

fn columns(x: &Mat<f64>, n: usize) -> Vec<[f64; 3]> {
    (0..n).map(|i| [x[(i, 0)], x[(i, 1)], x[(i, 2)]]).collect()
}

/// Bytes a factor of `A` occupies, from the symbolic Cholesky factorisation of its lower
/// triangle after the fill-reducing ordering (no numbers computed): 16 bytes per stored value
/// of `L` (the value and its row index) and 64 per unknown for the ordering and workspace.
/// `lu`: the LU factors of a matrix with `A`'s symmetric pattern take twice that (`L` and
/// `U`, pivoting aside). The fit checks it against its budget before factoring.
pub fn factor_bytes(a: &mut Triplets, lu: bool) -> Result<u64, String> {
    use faer::sparse::linalg::cholesky::{SymmetricOrdering, factorize_symbolic_cholesky};
    let n = a.n as u64;
    let m = a.matrix()?;
    let sym = factorize_symbolic_cholesky(
        m.symbolic(),
        Side::Lower,
        SymmetricOrdering::Amd,
        Default::default(),
    )
    .map_err(|e| format!("symbolic Cholesky failed: {e:?}"))?;
    let l = sym.len_val() as u64 * 16;
    Ok(if lu { 2 * l } else { l } + 64 * n)
}

/// Solves `A x = rhs` for a symmetric positive definite `A` given by its lower triangle.
pub fn cholesky(a: &mut Triplets, rhs: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, String> {
    let n = a.n;
    let m = a.matrix()?;
    let llt = m
        .sp_cholesky(Side::Lower)
        .map_err(|e| format!("sparse Cholesky failed: {e:?}"))?;
    let x = llt.solve(rhs_mat(rhs, n));
    Ok(columns(&x, n))
}

/// A sparse Cholesky factor of a symmetric positive definite matrix, kept to solve for
/// several right-hand sides over time (one factorisation, many solves).
pub struct CholeskyFactor {
    n: usize,
    llt: faer::sparse::linalg::solvers::Llt<usize, f64>,
}

impl CholeskyFactor {
    /// Factors `A` given by its lower triangle.
    pub fn new(a: &mut Triplets) -> Result<CholeskyFactor, String> {
        let m = a.matrix()?;
        let llt = m
            .sp_cholesky(Side::Lower)
            .map_err(|e| format!("sparse Cholesky failed: {e:?}"))?;
        Ok(CholeskyFactor { n: a.n, llt })
    }

    /// `A⁻¹ rhs`.
    pub fn solve(&self, rhs: &[[f64; 3]]) -> Vec<[f64; 3]> {
        columns(&self.llt.solve(rhs_mat(rhs, self.n)), self.n)
    }
}

/// Solves `A x = rhs` for a general square `A` given by all its entries (sparse LU).
pub fn lu(a: &mut Triplets, rhs: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, String> {
    let n = a.n;
    let m = a.matrix()?;
    let lu = m.sp_lu().map_err(|e| format!("sparse LU failed: {e:?}"))?;
    let x = lu.solve(rhs_mat(rhs, n));
    Ok(columns(&x, n))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_and_lu_solve_a_small_laplacian() {
        // 1D Laplacian plus identity, n = 50, against a dense Thomas solve.
        let n = 50;
        let mut lower = Triplets::new(n);
        let mut full = Triplets::new(n);
        for i in 0..n {
            lower.push(i, i, 3.0);
            full.push(i, i, 3.0);
            if i + 1 < n {
                lower.push(i + 1, i, -1.0);
                full.push(i + 1, i, -1.0);
                full.push(i, i + 1, -1.0);
            }
        }
        let rhs: Vec<[f64; 3]> = (0..n).map(|i| [i as f64, 1.0, (i as f64).sin()]).collect();
        let x = cholesky(&mut lower, &rhs).unwrap();
        let y = lu(&mut full, &rhs).unwrap();
        let back = lower.sym_mul(&x);
        for i in 0..n {
            for d in 0..3 {
                assert!((back[i][d] - rhs[i][d]).abs() < 1e-12);
                assert!((x[i][d] - y[i][d]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn factor_bytes_follow_the_fill() {
        // A tridiagonal matrix factors without fill: n values of the diagonal, n - 1 below.
        let n = 100;
        let mut a = Triplets::new(n);
        for i in 0..n {
            a.push(i, i, 2.0);
            if i > 0 {
                a.push(i, i - 1, -1.0);
            }
        }
        let b = factor_bytes(&mut a, false).unwrap();
        assert!(
            b >= (2 * n as u64 - 1) * 16 && b <= 64 * n as u64 + 3 * n as u64 * 16,
            "{b}"
        );
        assert!(factor_bytes(&mut a, true).unwrap() > b);
    }

    #[test]
    fn duplicates_sum_in_push_order() {
        let mut t = Triplets::new(2);
        t.push(1, 0, 0.1);
        t.push(0, 0, 1.0);
        t.push(1, 0, 0.2);
        t.compact();
        assert_eq!(t.len(), 2);
        assert_eq!(t.entries[1].1, 0.1 + 0.2);
    }
}
