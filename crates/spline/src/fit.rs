//! The fitting loop (Greiner & Hormann 1997, §5–§7): solve, correct the parameters, measure,
//! refine where the tolerance is missed, repeat.
//!
//! # One iteration
//!
//! 1. **Solve** for the coefficients of the current hierarchical space ([`super::hier`]):
//!    approximation by the penalty method `(BᵀB + ω s A₀) c = BᵀP` ([`crate::sparse`]), where
//!    `s = tr(BᵀB) / tr(A₀)` makes `ω` dimensionless (the same `ω` weighs fairness alike at
//!    every level and scale); `ω` starts at `--omega` (0.1) and is multiplied by 0.1 each
//!    iteration, down to [`OMEGA_FLOOR`] (a floor, so that a region with few points keeps
//!    a smooth surface instead of folding between them). Interpolation solves the Lagrange system instead, once the
//!    space holds at most one point per leaf cell.
//! 2. **Fairness** `A₀` (§6) is the thin-plate energy `∫ |S_uu|² + 2|S_uv|² + |S_vv|²` over
//!    the domain (*simple*), or its data-dependent form `∫ tr(G⁻¹ H G⁻¹ H) √det G`, where `H`
//!    holds the second derivatives and `G` is the first fundamental form of the previous
//!    iteration's surface (*data*: the energy of a surface measured in the metric of the
//!    surface it approximates, nearly independent of the parameterisation; the first
//!    iteration uses the simple form). Both are assembled exactly (simple) or to Gauss
//!    accuracy (data) by 4 × 4-point Gauss quadrature over the leaf cells. With
//!    `K = G⁻¹ = [p q; q r]` the integrand is `xᵀ M x` for `x = (S_uu, S_uv, S_vv)` and
//!    `M = [p², 2pq, q²; 2pq, 2q² + 2pr, 2qr; q², 2qr, r²]` (the identity metric gives
//!    `diag(1, 2, 1)`).
//! 3. **Parameter correction** (Hoschek 1988): every point's parameter moves to its foot
//!    point on the new surface (Newton projection, [`super::tensor::project`]), and the
//!    distance there is its deviation. The deviations reported are these orthogonal distances
//!    to the exported surface itself.
//! 4. **Refinement** (§5): the leaf cells holding a point whose deviation exceeds the
//!    tolerance are refined ([`super::hier::Hierarchy::refine`]); cells at `--max-level`
//!    cannot be, and are reported as missed. The loop ends when the tolerance holds, when
//!    nothing more can be refined, or after a bounded number of iterations.

use rayon::prelude::*;

use super::basis::GAUSS4;
use super::hier::{Hierarchy, Leaf, LocalBasis, Support};
use super::tensor;
use crate::error::Setting;
use crate::sparse::{Triplets, cholesky, factor_bytes, lu};
use crate::types::TensorSurface;

/// Which fairness energy regularises the fit (§6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fairness {
    /// The thin-plate energy in parameter space.
    Simple,
    /// The thin-plate energy in the metric of the previous iteration's surface.
    Data,
}

/// Options of one fit.
#[derive(Clone, Debug)]
pub struct FitParams {
    /// Largest allowed deviation, input units.
    pub tolerance: f64,
    /// Interpolate every point (Lagrange multipliers) instead of approximating.
    pub interpolate: bool,
    /// Fairness energy.
    pub fairness: Fairness,
    /// Starting fairness weight ω (dimensionless, see the module docs).
    pub omega: f64,
    /// Finest level that refinement may create.
    pub max_level: usize,
    /// Level-0 cells along the domain's longer side.
    pub base_cells: usize,
    /// Local (hierarchical) or global refinement.
    pub refine: Refine,
    /// Bytes the sparse factorisation may take ([`factor_bytes`], checked before each
    /// factorisation); `u64::MAX`: unchecked. The driver derives it from `--mem`.
    pub max_factor_bytes: u64,
}

impl Default for FitParams {
    fn default() -> FitParams {
        FitParams {
            tolerance: 0.0,
            interpolate: false,
            fairness: Fairness::Simple,
            omega: 0.1,
            max_level: 10,
            base_cells: 4,
            refine: Refine::Local,
            max_factor_bytes: u64::MAX,
        }
    }
}

/// Smallest ω the schedule reaches.
pub const OMEGA_FLOOR: f64 = 1e-4;

/// A leaf cell where the tolerance could not be met within `max_level`.
#[derive(Clone, Debug, PartialEq)]
pub struct Missed {
    /// Its parameter rectangle `[[u0, v0], [u1, v1]]`, in the surface's parameters.
    pub rect: [[f64; 2]; 2],
    /// The bounding box `[lo, hi]` of its points beyond the tolerance, input coordinates.
    pub bounds: [[f64; 3]; 2],
    /// Points in it beyond the tolerance.
    pub points: usize,
    /// The largest deviation among them.
    pub max_deviation: f64,
}

/// How the space grows where the tolerance is missed (§5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refine {
    /// Hierarchically: only the regions around the points that miss it.
    Local,
    /// Globally: every leaf, halving the knot spacing everywhere (for comparison).
    Global,
}

/// What a fit reports (§7's quantities; units are the input's).
#[derive(Clone, Debug, Default)]
pub struct FitReport {
    /// Coefficients of the hierarchical surface.
    pub control_points: usize,
    /// Coefficients per level.
    pub per_level: Vec<usize>,
    /// Control points of the exported tensor-product surface.
    pub tensor_control_points: usize,
    /// Largest orthogonal distance from a point to the surface.
    pub max_deviation: f64,
    /// Root mean square of the distances.
    pub rms_deviation: f64,
    /// Largest distance `|S(u_i) - p_i|` at the points' own parameters (interpolation's
    /// residual).
    pub max_residual: f64,
    /// The fairness energy of the result (the functional used).
    pub fairness_energy: f64,
    /// Iterations run.
    pub iterations: usize,
    /// The last ω used.
    pub omega: f64,
    /// Whether every point lies within the tolerance.
    pub met: bool,
    /// Where it does not.
    pub missed: Vec<Missed>,
}

/// A fitted surface.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The surface, in the coordinates of the points given.
    pub surface: TensorSurface,
    /// The report.
    pub report: FitReport,
    /// Every point's foot-point parameter, in the surface's parameters.
    pub foot: Vec<[f64; 2]>,
    /// Every point's distance to the surface.
    pub distance: Vec<f64>,
}

/// Why a fit cannot run.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum FitError {
    /// Fewer points than a surface needs.
    #[error("{0} points: a surface needs at least 3 points not on one line")]
    TooFewPoints(usize),
    /// A parameter rectangle of zero width.
    #[error("the points' parameters span a degenerate rectangle {0:?}: they lie on a line")]
    Degenerate([f64; 2]),
    /// The linear system could not be factored.
    #[error("the fit's linear system could not be solved: {0}")]
    Solve(String),
    /// The factorisation would take more memory than the fit may use.
    #[error(
        "the sparse factorisation of {unknowns} unknowns needs {}, more than the {} this surface may use under {mem}: raise {mem}, or loosen {}, or lower {}, or split the points ({}, {})",
        crate::exec::human_bytes(*need),
        crate::exec::human_bytes(*limit),
        Setting::Tolerance,
        Setting::MaxLevel,
        Setting::Patches,
        Setting::Tiles,
        mem = Setting::Mem
    )]
    Memory {
        /// Unknowns of the system.
        unknowns: usize,
        /// Bytes the factorisation needs.
        need: u64,
        /// Bytes it may use.
        limit: u64,
    },
}

/// Checks that factoring `a` fits in `limit` bytes (`u64::MAX`: no check).
fn admit_factor(a: &mut Triplets, lu: bool, limit: u64) -> Result<(), FitError> {
    if limit == u64::MAX {
        return Ok(());
    }
    let need = factor_bytes(a, lu).map_err(FitError::Solve)?;
    if need > limit {
        return Err(FitError::Memory {
            unknowns: a.n(),
            need,
            limit,
        });
    }
    Ok(())
}

/// The points' parameters in the hierarchy's domain: the domain is the parameter rectangle
/// grown by 0.5% of its longer side on each side (so foot points stay inside) and rounded up to
/// whole level-0 cells, centred on it.
fn domain(size: [f64; 2], base: usize) -> (f64, [i64; 2], [f64; 2]) {
    let margin = 0.005 * size[0].max(size[1]);
    let grown = [size[0] + 2.0 * margin, size[1] + 2.0 * margin];
    let h0 = grown[0].max(grown[1]) / base as f64;
    let cells = grown.map(|g| ((g / h0) - 1e-9).ceil().max(1.0) as i64);
    let shift = [0, 1].map(|d| (cells[d] as f64 * h0 - size[d]) / 2.0);
    (h0, cells, shift)
}

/// Points grouped by leaf cell: point indices sorted by (leaf, index).
struct Groups {
    order: Vec<u32>,
    runs: Vec<(Leaf, usize, usize)>,
}

fn group(h: &Hierarchy, uv: &[[f64; 2]]) -> Groups {
    let leaves: Vec<Leaf> = uv.par_iter().map(|&p| h.leaf_of(p)).collect();
    let mut order: Vec<u32> = (0..uv.len() as u32).collect();
    order.par_sort_by_key(|&i| (leaves[i as usize], i));
    let mut runs = Vec::new();
    let mut start = 0;
    for k in 1..=order.len() {
        if k == order.len() || leaves[order[k] as usize] != leaves[order[start] as usize] {
            runs.push((leaves[order[start] as usize], start, k));
            start = k;
        }
    }
    Groups { order, runs }
}

/// A block of a matrix: the functions it touches and its dense entries (lower triangle used).
struct Block {
    sup: Vec<Support>,
    mat: Vec<f64>,
    rhs: Vec<[f64; 3]>,
}

fn push_block(t: &mut Triplets, b: &Block) {
    let k = b.sup.len();
    for r in 0..k {
        for c in 0..=r {
            let v = b.mat[r * k + c];
            if v != 0.0 {
                let (i, j) = (b.sup[r].index as usize, b.sup[c].index as usize);
                t.push(i.max(j), i.min(j), v);
            }
        }
    }
}

const CHUNK: usize = 2048;

/// `BᵀB` (lower triangle) and `BᵀP`.
fn assemble_data(
    h: &Hierarchy,
    g: &Groups,
    pts: &[[f64; 3]],
    uv: &[[f64; 2]],
) -> (Triplets, Vec<[f64; 3]>) {
    let mut t = Triplets::new(h.len());
    let mut rhs = vec![[0.0; 3]; h.len()];
    for runs in g.runs.chunks(CHUNK) {
        let blocks: Vec<Block> = runs
            .par_iter()
            .map(|&(leaf, s, e)| {
                let mut sup = Vec::new();
                h.supports(leaf, &mut sup);
                let k = sup.len();
                let mut mat = vec![0.0; k * k];
                let mut r = vec![[0.0; 3]; k];
                let mut lb = LocalBasis::default();
                let mut b = vec![0.0; k];
                for &i in &g.order[s..e] {
                    let i = i as usize;
                    h.local_basis(leaf, uv[i], &mut lb);
                    for (m, sm) in sup.iter().enumerate() {
                        b[m] = lb.value(sm);
                    }
                    for m in 0..k {
                        for n in 0..=m {
                            mat[m * k + n] += b[m] * b[n];
                        }
                        for x in 0..3 {
                            r[m][x] += b[m] * pts[i][x];
                        }
                    }
                }
                Block { sup, mat, rhs: r }
            })
            .collect();
        for b in &blocks {
            push_block(&mut t, b);
            for (s, r) in b.sup.iter().zip(&b.rhs) {
                for x in 0..3 {
                    rhs[s.index as usize][x] += r[x];
                }
            }
        }
    }
    (t, rhs)
}

/// The 3 × 3 matrix `M` of the integrand `xᵀ M x` and the area element, for a reference
/// tangent pair (module docs); the identity metric without a reference.
pub(crate) fn metric(reference: Option<(&[f64; 3], &[f64; 3])>) -> ([[f64; 3]; 3], f64) {
    let Some((su, sv)) = reference else {
        return ([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]], 1.0);
    };
    let e = su[0] * su[0] + su[1] * su[1] + su[2] * su[2];
    let f = su[0] * sv[0] + su[1] * sv[1] + su[2] * sv[2];
    let gg = sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2];
    let det = e * gg - f * f;
    if det.is_nan() || det <= 1e-300 {
        return ([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]], 1.0);
    }
    let (p, q, r) = (gg / det, -f / det, e / det);
    (
        [
            [p * p, 2.0 * p * q, q * q],
            [2.0 * p * q, 2.0 * q * q + 2.0 * p * r, 2.0 * q * r],
            [q * q, 2.0 * q * r, r * r],
        ],
        det.sqrt(),
    )
}

/// The fairness matrix `A₀` (lower triangle) by Gauss quadrature over the leaf cells.
fn assemble_fairness(h: &Hierarchy, reference: Option<&TensorSurface>) -> Triplets {
    let mut t = Triplets::new(h.len());
    let leaves = h.leaves();
    for chunk in leaves.chunks(CHUNK) {
        let blocks: Vec<Block> = chunk
            .par_iter()
            .map(|&leaf| {
                let mut sup = Vec::new();
                h.supports(leaf, &mut sup);
                let k = sup.len();
                let mut mat = vec![0.0; k * k];
                let mut lb = LocalBasis::default();
                let mut d2 = vec![[0.0; 3]; k];
                let hl = h.spacing(leaf.level as usize);
                let corner = [leaf.cell[0] as f64 * hl, leaf.cell[1] as f64 * hl];
                for &(gu, wu) in &GAUSS4 {
                    for &(gv, wv) in &GAUSS4 {
                        let uv = [corner[0] + gu * hl, corner[1] + gv * hl];
                        h.local_basis(leaf, uv, &mut lb);
                        let refd = reference.map(|s| tensor::eval(s, uv));
                        let (m, area) = metric(refd.as_ref().map(|d| (&d[1], &d[2])));
                        let w = wu * wv * hl * hl * area;
                        for (n, sn) in sup.iter().enumerate() {
                            let d = lb.derivs(sn);
                            d2[n] = [d[3], d[4], d[5]];
                        }
                        for a in 0..k {
                            let ma = [
                                m[0][0] * d2[a][0] + m[0][1] * d2[a][1] + m[0][2] * d2[a][2],
                                m[1][0] * d2[a][0] + m[1][1] * d2[a][1] + m[1][2] * d2[a][2],
                                m[2][0] * d2[a][0] + m[2][1] * d2[a][1] + m[2][2] * d2[a][2],
                            ];
                            for b in 0..=a {
                                mat[a * k + b] +=
                                    w * (ma[0] * d2[b][0] + ma[1] * d2[b][1] + ma[2] * d2[b][2]);
                            }
                        }
                    }
                }
                Block {
                    sup,
                    mat,
                    rhs: Vec::new(),
                }
            })
            .collect();
        for b in &blocks {
            push_block(&mut t, b);
        }
    }
    t.compact();
    t
}

/// Energy `Σ_x c_xᵀ A c_x` of coefficients under a symmetric matrix.
fn energy(a: &Triplets, coef: &[[f64; 3]]) -> f64 {
    let ac = a.sym_mul(coef);
    coef.iter()
        .zip(&ac)
        .map(|(c, y)| c[0] * y[0] + c[1] * y[1] + c[2] * y[2])
        .sum()
}

/// Solves the penalty system for the current space.
fn solve_penalty(
    h: &Hierarchy,
    g: &Groups,
    pts: &[[f64; 3]],
    uv: &[[f64; 2]],
    fair: &mut Triplets,
    omega: f64,
    max_factor_bytes: u64,
) -> Result<Vec<[f64; 3]>, FitError> {
    let (mut a, rhs) = assemble_data(h, g, pts, uv);
    let ta = a.trace();
    let tf = fair.trace();
    let s = if tf > 0.0 { ta / tf } else { 1.0 };
    a.add_scaled(fair, omega * s);
    admit_factor(&mut a, false, max_factor_bytes)?;
    match cholesky(&mut a, &rhs) {
        Ok(c) if c.iter().all(|c| c.iter().all(|x| x.is_finite())) => Ok(c),
        _ => {
            // Not positive definite in floating point (a function carrying next to no data
            // and no curvature): a ridge of 1e-12 of the mean diagonal makes it so.
            let n = h.len();
            let ridge = 1e-12 * ta.max(1e-300) / n as f64;
            for i in 0..n {
                a.push(i, i, ridge);
            }
            cholesky(&mut a, &rhs).map_err(FitError::Solve)
        }
    }
}

/// Solves the Lagrange system: minimal fairness subject to `S(u_i) = p_i`.
fn solve_lagrange(
    h: &Hierarchy,
    g: &Groups,
    pts: &[[f64; 3]],
    uv: &[[f64; 2]],
    fair: &Triplets,
    max_factor_bytes: u64,
) -> Result<Vec<[f64; 3]>, FitError> {
    let n = h.len();
    let m = pts.len();
    let mut k = Triplets::new(n + m);
    let tf = fair.trace_and_entries();
    let scale = if tf.0 > 0.0 { n as f64 / tf.0 } else { 1.0 };
    for &(r, c, v) in &tf.1 {
        k.push(r, c, v * scale);
        if r != c {
            k.push(c, r, v * scale);
        }
    }
    let mut rhs = vec![[0.0; 3]; n + m];
    let mut sup = Vec::new();
    let mut lb = LocalBasis::default();
    for &(leaf, s, e) in &g.runs {
        h.supports(leaf, &mut sup);
        for &i in &g.order[s..e] {
            let i = i as usize;
            h.local_basis(leaf, uv[i], &mut lb);
            for sm in &sup {
                let b = lb.value(sm);
                if b != 0.0 {
                    k.push(n + i, sm.index as usize, b);
                    k.push(sm.index as usize, n + i, b);
                }
            }
            rhs[n + i] = pts[i];
        }
    }
    admit_factor(&mut k, true, max_factor_bytes)?;
    let x = lu(&mut k, &rhs).map_err(FitError::Solve)?;
    Ok(x[..n].to_vec())
}

/// Fits a surface to `pts` at parameters `uv` inside the rectangle `[0, size]`.
pub fn fit(
    pts: &[[f64; 3]],
    uv: &[[f64; 2]],
    size: [f64; 2],
    params: &FitParams,
) -> Result<Fit, FitError> {
    if pts.len() < 3 {
        return Err(FitError::TooFewPoints(pts.len()));
    }
    if !(size[0] > 0.0 && size[1] > 0.0) {
        return Err(FitError::Degenerate(size));
    }
    let (h0, cells, shift) = domain(size, params.base_cells.max(1));
    let mut h = Hierarchy::new(h0, cells);
    // Local coordinates about the centroid, for the conditioning of the solve.
    let n = pts.len() as f64;
    let origin = [0, 1, 2].map(|x| pts.iter().map(|p| p[x]).sum::<f64>() / n);
    let local: Vec<[f64; 3]> = pts
        .iter()
        .map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]])
        .collect();
    let mut par: Vec<[f64; 2]> = uv
        .iter()
        .map(|p| [p[0] + shift[0], p[1] + shift[1]])
        .collect();
    let mut omega = params.omega;
    let mut reference: Option<TensorSurface> = None;
    let max_iter = 3 * (params.max_level + 1) + 6;
    let mut report = FitReport::default();
    let mut coef;
    let mut surface;
    let mut distance;
    let mut iterations = 0;
    loop {
        iterations += 1;
        let g = group(&h, &par);
        let fref = match params.fairness {
            Fairness::Data => reference.as_ref(),
            Fairness::Simple => None,
        };
        let mut fair = assemble_fairness(&h, fref);
        if params.interpolate {
            // Refine until every leaf holds at most one point, then solve exactly.
            let crowded: Vec<Leaf> = g
                .runs
                .iter()
                .filter(|r| r.2 - r.1 > 1)
                .map(|r| r.0)
                .collect();
            if !crowded.is_empty() && iterations < max_iter {
                let (_, changed) = h.refine(&crowded, params.max_level);
                if changed {
                    continue;
                }
            }
            coef = solve_lagrange(&h, &g, &local, &par, &fair, params.max_factor_bytes)?;
        } else {
            coef = solve_penalty(
                &h,
                &g,
                &local,
                &par,
                &mut fair,
                omega,
                params.max_factor_bytes,
            )?;
        }
        surface = h.to_tensor(&coef, [0.0; 3]);
        report.fairness_energy = energy(&fair, &coef);
        report.omega = omega;
        // Residuals at the current parameters, then the parameter correction.
        let resid: Vec<f64> = par
            .par_iter()
            .zip(&local)
            .map(|(&q, p)| {
                let s = tensor::eval(&surface, q)[0];
                ((s[0] - p[0]).powi(2) + (s[1] - p[1]).powi(2) + (s[2] - p[2]).powi(2)).sqrt()
            })
            .collect();
        report.max_residual = resid.iter().fold(0.0, |a: f64, &b| a.max(b));
        let proj: Vec<([f64; 2], f64)> = par
            .par_iter()
            .zip(&local)
            .map(|(&q, &p)| tensor::project(&surface, p, q))
            .collect();
        distance = proj.iter().map(|x| x.1).collect::<Vec<f64>>();
        if params.interpolate {
            break;
        }
        for (p, x) in par.iter_mut().zip(&proj) {
            *p = x.0;
        }
        let bad: Vec<Leaf> = {
            let mut v: Vec<Leaf> = par
                .iter()
                .zip(&distance)
                .filter(|(_, d)| **d > params.tolerance)
                .map(|(&q, _)| h.leaf_of(q))
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        if bad.is_empty() || iterations >= max_iter {
            break;
        }
        reference = Some(surface.clone());
        let bad = match params.refine {
            Refine::Local => bad,
            Refine::Global => h.leaves(),
        };
        let (_, changed) = h.refine(&bad, params.max_level);
        omega = (omega * 0.1).max(OMEGA_FLOOR);
        if !changed && omega <= OMEGA_FLOOR {
            break;
        }
    }
    report.iterations = iterations;
    report.control_points = h.len();
    report.per_level = h.per_level();
    report.tensor_control_points = surface.ctrl.len();
    report.max_deviation = distance.iter().fold(0.0, |a: f64, &b| a.max(b));
    report.rms_deviation = (distance.iter().map(|d| d * d).sum::<f64>() / n).sqrt();
    report.met = if params.interpolate {
        report.max_residual <= params.tolerance
    } else {
        report.max_deviation <= params.tolerance
    };
    report.missed = missed(&h, &par, pts, &distance, params.tolerance);
    for c in &mut surface.ctrl {
        for x in 0..3 {
            c[x] += origin[x];
        }
    }
    let foot = par;
    Ok(Fit {
        surface,
        report,
        foot,
        distance,
    })
}

/// The leaf cells holding points beyond the tolerance, with their counts, worst deviation
/// and the bounding box of those points.
fn missed(
    h: &Hierarchy,
    par: &[[f64; 2]],
    pts: &[[f64; 3]],
    dist: &[f64],
    tol: f64,
) -> Vec<Missed> {
    let mut cells: Vec<(Leaf, usize)> = (0..par.len())
        .filter(|&i| dist[i] > tol)
        .map(|i| (h.leaf_of(par[i]), i))
        .collect();
    cells.sort_unstable();
    let mut out: Vec<(Leaf, Missed)> = Vec::new();
    for (leaf, i) in cells {
        let (p, d) = (pts[i], dist[i]);
        match out.last_mut() {
            Some((l, m)) if *l == leaf => {
                m.points += 1;
                m.max_deviation = m.max_deviation.max(d);
                for x in 0..3 {
                    m.bounds[0][x] = m.bounds[0][x].min(p[x]);
                    m.bounds[1][x] = m.bounds[1][x].max(p[x]);
                }
            }
            _ => {
                let s = h.spacing(leaf.level as usize);
                let lo = [leaf.cell[0] as f64 * s, leaf.cell[1] as f64 * s];
                out.push((
                    leaf,
                    Missed {
                        rect: [lo, [lo[0] + s, lo[1] + s]],
                        bounds: [p, p],
                        points: 1,
                        max_deviation: d,
                    },
                ));
            }
        }
    }
    out.into_iter().map(|x| x.1).collect()
}

#[cfg(test)]
mod tests;
