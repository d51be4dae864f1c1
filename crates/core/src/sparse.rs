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
//!
//! Where one sparsity pattern is factored for several matrices (the hex stage's smooth frame
//! field factors `L + diag(d)` for two diagonals `d`), a [`LowerMatrix`] built column by
//! column is analysed once ([`SymbolicFactor`], approximate minimum degree ordering) and each
//! matrix gets its [`NumericFactor`] on that analysis.

use faer::Side;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::prelude::*;
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat, Triplet};

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

/// The `n × K` right-hand side of `K`-vectors (rows past `rhs` zero).
fn rhs_mat<const K: usize>(rhs: &[[f64; K]], n: usize) -> Mat<f64> {
    Mat::from_fn(n, K, |i, j| rhs.get(i).map_or(0.0, |r| r[j]))
}

/// The first `n` rows of `x` as `K`-vectors.
fn columns<const K: usize>(x: &Mat<f64>, n: usize) -> Vec<[f64; K]> {
    (0..n).map(|i| std::array::from_fn(|j| x[(i, j)])).collect()
}

/// The symbolic Cholesky factorisation of the lower triangle of `m` under `ordering`; the
/// error is faer's, formatted with `{:?}` (callers say what failed).
fn symbolic(
    m: &SparseColMat<usize, f64>,
    ordering: SymmetricOrdering<'_, usize>,
) -> Result<SymbolicCholesky<usize>, String> {
    factorize_symbolic_cholesky(m.symbolic(), Side::Lower, ordering, Default::default())
        .map_err(|e| format!("{e:?}"))
}

/// Why [`numeric_llt`] failed: no memory for its workspace, or the factorisation itself
/// (faer's errors, formatted with `{:?}`).
enum NumericError {
    Memory(String),
    Llt(String),
}

/// The values of the numeric Cholesky factor `LLᵀ` of the lower triangle of `m` on the
/// symbolic factorisation `sym` (sequential).
fn numeric_llt(
    sym: &SymbolicCholesky<usize>,
    m: &SparseColMat<usize, f64>,
) -> Result<Vec<f64>, NumericError> {
    let mut values = vec![0.0; sym.len_val()];
    let req = sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
    let mut mem = MemBuffer::try_new(req).map_err(|e| NumericError::Memory(format!("{e:?}")))?;
    sym.factorize_numeric_llt::<f64>(
        &mut values,
        m.as_ref(),
        Side::Lower,
        LltRegularization::default(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|e| NumericError::Llt(format!("{e:?}")))?;
    Ok(values)
}

/// `x ← A⁻¹ x` by the factor `values` on `sym`, for any number of columns (sequential).
fn solve_llt_in_place(sym: &SymbolicCholesky<usize>, values: &[f64], x: &mut Mat<f64>) {
    let req = sym.solve_in_place_scratch::<f64>(x.ncols(), Par::Seq);
    let mut mem = MemBuffer::new(req);
    LltRef::new(sym, values).solve_in_place_with_conj(
        faer::Conj::No,
        x.as_mut(),
        Par::Seq,
        MemStack::new(&mut mem),
    );
}

/// Bytes a factor of `A` occupies, from the symbolic Cholesky factorisation of its lower
/// triangle after the fill-reducing ordering (no numbers computed): 16 bytes per stored value
/// of `L` (the value and its row index) and 64 per unknown for the ordering and workspace.
/// `lu`: the LU factors of a matrix with `A`'s symmetric pattern take twice that (`L` and
/// `U`, pivoting aside). The fit checks it against its budget before factoring.
pub fn factor_bytes(a: &mut Triplets, lu: bool) -> Result<u64, String> {
    let n = a.n as u64;
    let m = a.matrix()?;
    let sym = symbolic(&m, SymmetricOrdering::Amd)
        .map_err(|e| format!("symbolic Cholesky failed: {e}"))?;
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
pub enum CholeskyFactor {
    /// Ordered by faer's approximate minimum degree.
    Amd {
        /// Unknowns.
        n: usize,
        /// The factor.
        llt: faer::sparse::linalg::solvers::Llt<usize, f64>,
    },
    /// Ordered by nested dissection.
    Custom {
        /// Unknowns.
        n: usize,
        /// The symbolic factor (with the ordering).
        sym: Box<faer::sparse::linalg::cholesky::SymbolicCholesky<usize>>,
        /// The numeric factor's values.
        values: Vec<f64>,
    },
}

impl CholeskyFactor {
    /// Factors `A` given by its lower triangle.
    pub fn new(a: &mut Triplets) -> Result<CholeskyFactor, String> {
        let m = a.matrix()?;
        let llt = m
            .sp_cholesky(Side::Lower)
            .map_err(|e| format!("sparse Cholesky failed: {e:?}"))?;
        Ok(CholeskyFactor::Amd { n: a.n, llt })
    }

    /// Factors `A` given by its lower triangle, its unknowns ordered by nested dissection
    /// of their `points` ([`nested_dissection`]).
    pub fn with_points(a: &mut Triplets, points: &[[f64; 3]]) -> Result<CholeskyFactor, String> {
        use faer::perm::Perm;
        let order = nested_dissection(a, points);
        let mut inverse = vec![0usize; order.len()];
        for (i, &v) in order.iter().enumerate() {
            inverse[v] = i;
        }
        let perm = Perm::new_checked(order.into_boxed_slice(), inverse.into_boxed_slice(), a.n);
        let m = a.matrix()?;
        let sym = symbolic(&m, SymmetricOrdering::Custom(perm.as_ref()))
            .map_err(|e| format!("symbolic Cholesky failed: {e}"))?;
        let values = numeric_llt(&sym, &m).map_err(|e| match e {
            NumericError::Memory(e) => e,
            NumericError::Llt(e) => format!("sparse Cholesky failed: {e}"),
        })?;
        Ok(CholeskyFactor::Custom {
            n: a.n,
            sym: Box::new(sym),
            values,
        })
    }

    /// `A⁻¹ rhs`.
    pub fn solve(&self, rhs: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let n = match self {
            CholeskyFactor::Amd { n, .. } | CholeskyFactor::Custom { n, .. } => *n,
        };
        let mut x = rhs_mat(rhs, n);
        self.solve_in_place(&mut x);
        columns(&x, n)
    }

    /// `x ← A⁻¹ x`, for any number of columns.
    pub fn solve_in_place(&self, x: &mut Mat<f64>) {
        match self {
            CholeskyFactor::Amd { llt, .. } => {
                *x = llt.solve(x.as_ref());
            }
            CholeskyFactor::Custom { sym, values, .. } => solve_llt_in_place(sym, values, x),
        }
    }
}

/// The lower triangle of a symmetric `n × n` sparse matrix in compressed columns, built
/// directly where the caller produces its columns in order (say, a graph Laplacian assembled
/// node by node), without the sort and merge of [`Triplets`].
pub struct LowerMatrix(SparseColMat<usize, f64>);

impl LowerMatrix {
    /// Column `j` holds the rows `rows[col_ptr[j]..col_ptr[j + 1]]` (ascending, none above
    /// the diagonal) with the values `values[col_ptr[j]..col_ptr[j + 1]]`.
    ///
    /// # Panics
    /// If `col_ptr` and `rows` do not describe an `n × n` pattern (faer's checks: `n + 1`
    /// non-decreasing offsets, rows below `n`, sorted and distinct within each column), or
    /// `values` does not have one value per row index.
    pub fn from_columns(
        n: usize,
        col_ptr: Vec<usize>,
        rows: Vec<usize>,
        values: Vec<f64>,
    ) -> LowerMatrix {
        LowerMatrix(SparseColMat::new(
            SymbolicSparseColMat::new_checked(n, n, col_ptr, None, rows),
            values,
        ))
    }

    /// Rows (and columns).
    pub fn n(&self) -> usize {
        self.0.nrows()
    }
}

/// The symbolic sparse Cholesky factorisation of a [`LowerMatrix`]'s pattern (approximate
/// minimum degree ordering, faer's default), shared by the [`NumericFactor`]s of every
/// symmetric positive definite matrix with that pattern: one analysis, several
/// factorisations.
pub struct SymbolicFactor(SymbolicCholesky<usize>);

impl SymbolicFactor {
    /// Orders and analyses the pattern of `a`. The error is faer's, formatted with `{:?}`:
    /// the caller says what failed.
    pub fn new(a: &LowerMatrix) -> Result<SymbolicFactor, String> {
        symbolic(&a.0, Default::default()).map(SymbolicFactor)
    }

    /// Stored values of the factor `L` (each 16 bytes in memory: the value and its row).
    pub fn nonzeros(&self) -> usize {
        self.0.len_val()
    }

    /// The numeric factor `LLᵀ` of `a`, whose pattern must be the analysed one. The error is
    /// faer's (no memory for the workspace, or `a` not positive definite), formatted with
    /// `{:?}`.
    pub fn factor(&self, a: &LowerMatrix) -> Result<NumericFactor<'_>, String> {
        let values = numeric_llt(&self.0, &a.0).map_err(|e| match e {
            NumericError::Memory(e) | NumericError::Llt(e) => e,
        })?;
        Ok(NumericFactor {
            sym: &self.0,
            n: a.n(),
            values,
        })
    }
}

/// A numeric sparse Cholesky factor on a shared [`SymbolicFactor`].
pub struct NumericFactor<'a> {
    sym: &'a SymbolicCholesky<usize>,
    n: usize,
    values: Vec<f64>,
}

impl NumericFactor<'_> {
    /// `A⁻¹ rhs` for `K` right-hand sides at once, `rhs` one `K`-vector per unknown.
    pub fn solve<const K: usize>(&self, rhs: &[[f64; K]]) -> Vec<[f64; K]> {
        let mut x = rhs_mat(rhs, self.n);
        self.solve_in_place(&mut x);
        columns(&x, self.n)
    }

    /// `x ← A⁻¹ x`, for any number of columns.
    pub fn solve_in_place(&self, x: &mut Mat<f64>) {
        solve_llt_in_place(self.sym, &self.values, x);
    }
}

/// A fill-reducing ordering of a sparse symmetric matrix whose unknowns sit at `points`:
/// geometric nested dissection (George 1973; Gilbert, Miller, Teng 1998). The unknowns are
/// split at the median of the widest coordinate, the unknowns of the lower half with a
/// neighbour in the upper half form the separator, and the order is the lower half, the
/// upper half (each ordered the same way, recursively) and the separator last, so that
/// eliminating one half never fills the other. On meshes of solids it leaves a fraction of
/// the fill that approximate minimum degree leaves. Unknowns whose point is not finite (no
/// position: say, an unknown shared by a whole plane) are ordered last. Returns the
/// permutation: position → unknown.
pub fn nested_dissection(a: &mut Triplets, points: &[[f64; 3]]) -> Vec<usize> {
    a.compact();
    let n = a.n;
    let mut degree = vec![0usize; n + 1];
    let pairs: Vec<(usize, usize)> = a
        .entries
        .iter()
        .map(|&(k, _)| ((k & 0xFFFF_FFFF) as usize, (k >> 32) as usize))
        .filter(|(r, c)| r != c)
        .collect();
    for &(r, c) in &pairs {
        degree[r] += 1;
        degree[c] += 1;
    }
    let mut offsets = vec![0usize; n + 1];
    for i in 0..n {
        offsets[i + 1] = offsets[i] + degree[i];
    }
    let mut fill = offsets.clone();
    let mut adj = vec![0u32; offsets[n]];
    for &(r, c) in &pairs {
        adj[fill[r]] = c as u32;
        fill[r] += 1;
        adj[fill[c]] = r as u32;
        fill[c] += 1;
    }
    // part[v]: the piece of the current split v belongs to.
    let mut part = vec![0u32; n];
    let mut order = Vec::with_capacity(n);
    let mut next_part = 1u32;
    // Stack of pieces to split; a separator is pushed to be emitted after both halves.
    enum Task {
        Split(Vec<u32>),
        Emit(Vec<u32>),
    }
    // Unknowns with no position (not finite) come last, after every piece.
    let (placed, unplaced): (Vec<u32>, Vec<u32>) =
        (0..n as u32).partition(|&v| points[v as usize].iter().all(|x| x.is_finite()));
    let mut stack = vec![Task::Emit(unplaced), Task::Split(placed)];
    while let Some(task) = stack.pop() {
        let mut verts = match task {
            Task::Emit(v) => {
                order.extend(v.iter().map(|&x| x as usize));
                continue;
            }
            Task::Split(v) => v,
        };
        if verts.len() <= ND_LEAF {
            order.extend(verts.iter().map(|&x| x as usize));
            continue;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &v in &verts {
            for k in 0..3 {
                lo[k] = lo[k].min(points[v as usize][k]);
                hi[k] = hi[k].max(points[v as usize][k]);
            }
        }
        let axis = (0..3)
            .max_by(|&x, &y| (hi[x] - lo[x]).total_cmp(&(hi[y] - lo[y])))
            .expect("three axes");
        let mid = verts.len() / 2;
        verts.select_nth_unstable_by(mid, |&x, &y| {
            points[x as usize][axis]
                .total_cmp(&points[y as usize][axis])
                .then(x.cmp(&y))
        });
        let (lower_id, upper_id) = (next_part, next_part + 1);
        next_part += 2;
        for (i, &v) in verts.iter().enumerate() {
            part[v as usize] = if i < mid { lower_id } else { upper_id };
        }
        let (mut lower, mut upper, mut sep) = (Vec::new(), Vec::new(), Vec::new());
        for (i, &v) in verts.iter().enumerate() {
            if i >= mid {
                upper.push(v);
            } else if adj[offsets[v as usize]..offsets[v as usize + 1]]
                .iter()
                .any(|&u| part[u as usize] == upper_id)
            {
                sep.push(v);
            } else {
                lower.push(v);
            }
        }
        for piece in [&mut lower, &mut upper, &mut sep] {
            piece.sort_unstable();
        }
        stack.push(Task::Emit(sep));
        stack.push(Task::Split(upper));
        stack.push(Task::Split(lower));
    }
    order
}

/// Pieces of at most this many unknowns are not split further by [`nested_dissection`].
const ND_LEAF: usize = 64;

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
    fn nested_dissection_orders_every_unknown_once_and_solves_as_minimum_degree_does() {
        // A 12 × 9 × 7 grid Laplacian (plus a shift), one unknown left without a position.
        let (nx, ny, nz) = (12, 9, 7);
        let id = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
        let n = nx * ny * nz;
        let build = || {
            let mut a = Triplets::new(n);
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let i = id(x, y, z);
                        a.push(i, i, 0.1);
                        for (dx, dy, dz) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                            let (u, v, w) = (x + dx, y + dy, z + dz);
                            if u < nx && v < ny && w < nz {
                                let j = id(u, v, w);
                                a.push(i, i, 1.0);
                                a.push(j, j, 1.0);
                                a.push(j, i, -1.0);
                            }
                        }
                    }
                }
            }
            a
        };
        let mut points: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                [
                    (i % nx) as f64,
                    ((i / nx) % ny) as f64,
                    (i / (nx * ny)) as f64,
                ]
            })
            .collect();
        points[17] = [f64::NAN; 3];
        let order = nested_dissection(&mut build(), &points);
        assert_eq!(*order.last().unwrap(), 17);
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..n).collect::<Vec<_>>());
        let rhs: Vec<[f64; 3]> = (0..n).map(|i| [i as f64, 1.0, (i % 7) as f64]).collect();
        let amd = CholeskyFactor::new(&mut build()).unwrap().solve(&rhs);
        let nd = CholeskyFactor::with_points(&mut build(), &points)
            .unwrap()
            .solve(&rhs);
        for (a, b) in amd.iter().zip(&nd) {
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() < 1e-9 * (1.0 + a[k].abs()),
                    "{a:?} {b:?}"
                );
            }
        }
    }

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
    fn one_symbolic_factor_serves_two_diagonals() {
        // L + diag(d) of a path graph, for two diagonals d, built column by column; each
        // solve of 9 right-hand sides matches the one through Triplets.
        let n = 40;
        let lower = |d: f64| {
            let (mut col_ptr, mut rows, mut vals) = (vec![0], Vec::new(), Vec::new());
            for i in 0..n {
                rows.push(i);
                vals.push(2.0 + d);
                if i + 1 < n {
                    rows.push(i + 1);
                    vals.push(-1.0);
                }
                col_ptr.push(rows.len());
            }
            LowerMatrix::from_columns(n, col_ptr, rows, vals)
        };
        let sym = SymbolicFactor::new(&lower(0.5)).unwrap();
        assert!(sym.nonzeros() >= 2 * n - 1);
        let rhs: Vec<[f64; 9]> = (0..n)
            .map(|i| std::array::from_fn(|j| (i * 9 + j) as f64))
            .collect();
        for d in [0.5, 3.0] {
            let x = sym.factor(&lower(d)).unwrap().solve(&rhs);
            let mut t = Triplets::new(n);
            for i in 0..n {
                t.push(i, i, 2.0 + d);
                if i + 1 < n {
                    t.push(i + 1, i, -1.0);
                }
            }
            for c in 0..3 {
                let three: Vec<[f64; 3]> = rhs
                    .iter()
                    .map(|r| [r[3 * c], r[3 * c + 1], r[3 * c + 2]])
                    .collect();
                let y = cholesky(&mut t, &three).unwrap();
                for i in 0..n {
                    for k in 0..3 {
                        let (a, b) = (x[i][3 * c + k], y[i][k]);
                        assert!((a - b).abs() < 1e-12 * (1.0 + b.abs()), "{a} {b}");
                    }
                }
            }
        }
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
