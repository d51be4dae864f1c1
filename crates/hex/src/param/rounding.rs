//! The greedy rounding of §3.1 (module docs of [`super`], "Greedy rounding"): solve, fix the
//! open integer unknowns closest to an integer in batches, one factorisation per round, then
//! the last ones one at a time on a single factorisation through the Schur complement of the
//! fixed unknowns, looking ahead at the flips; the untangling of what stays flipped.

use faer::Mat;

use super::cut::CutVertices;
use super::elim::{Elim, Expr};
use super::system::{Factored, LocalEnergies, System, corner_params};
use super::{FlipCause, IntegerVar, ParamError, ParamParams, ParamReport, param_volume};

/// The unknowns the elimination leaves free, their normal equations factored, and every
/// unknown's expression in them: one solve of the rounding.
pub(super) struct FreeSolve {
    /// The free unknowns, ascending.
    pub(super) free: Vec<u32>,
    /// Per unknown, its index in `free` (`u32::MAX` when eliminated).
    pub(super) index: Vec<u32>,
    /// Per free unknown, its vertex's position (NaN for an integer unknown).
    pub(super) points: Vec<[f64; 3]>,
    pub(super) fac: Factored,
    pub(super) exprs: Vec<Expr>,
}

impl FreeSolve {
    /// Every unknown's value when the free ones are `z`.
    pub(super) fn eval(&self, z: &[f64]) -> Vec<f64> {
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
pub(super) struct Rounder<'a> {
    pub(super) params: &'a ParamParams,
    pub(super) names: &'a [IntegerVar],
    /// The first integer unknown (the continuous ones come first).
    pub(super) base: u32,
    /// All unknowns.
    pub(super) nvar: usize,
    pub(super) cv: &'a CutVertices,
    pub(super) local: &'a LocalEnergies,
}

impl Rounder<'_> {
    /// The tetrahedra with non-positive parameter volume in the map of `values`.
    pub(super) fn flipped_of(&self, values: &[f64]) -> Vec<u32> {
        let uvw = corner_params(&self.cv.corner_cv, values);
        (0..uvw.len() as u32)
            .filter(|&t| param_volume(&uvw[t as usize]) <= 0.0)
            .collect()
    }

    /// The normal equations over the unknowns `st` leaves free.
    pub(super) fn system<'s>(&'s self, elim: &'s Elim, st: &'s FreeSolve) -> System<'s> {
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
    pub(super) fn solve(&self, elim: &Elim) -> Result<FreeSolve, ParamError> {
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
    pub(super) fn finish(&self, st: &FreeSolve, z: &[f64], report: &mut ParamReport) -> Vec<f64> {
        let values = st.eval(z);
        report.flipped_final = self.flipped_of(&values).len();
        report.energy_final = self.local.mean(&self.cv.corner_cv, &values);
        values
    }

    /// Rounds the integer unknowns and untangles the map (module docs): solve, record the
    /// flips, fix a batch, until few enough are open to fix one at a time on the last
    /// factorisation. Returns every unknown's value.
    pub(super) fn run(
        &self,
        elim: &mut Elim,
        report: &mut ParamReport,
    ) -> Result<Vec<f64>, ParamError> {
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
    pub(super) fn one_at_a_time(
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
    pub(super) fn fix_batch(
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

/// Open integer unknowns held at values: (index into the open list, value).
pub(super) type Fixed = Vec<(usize, f64)>;

/// The free variables' values with the integer unknowns `fixed` held at given values, on the
/// factorisation of the system where they were free: minimising `½ zᵀKz − bᵀz` subject to
/// `z_S = k` gives `z = z₀ + Z_S μ`, `Z_S = K⁻¹ E_S`, with `(E_Sᵀ K⁻¹ E_S) μ = k − z₀_S`
/// (the Schur complement of the fixed unknowns, a small dense system).
pub(super) struct Rounding<'a> {
    pub(super) f: &'a Factored,
    /// The open integer unknowns (free indices) and their solved columns `K⁻¹ eⱼ`, over the
    /// variables of their block.
    pub(super) open: Vec<u32>,
    pub(super) columns: Vec<Vec<f64>>,
}

impl<'a> Rounding<'a> {
    pub(super) fn new(f: &'a Factored, open: Vec<u32>) -> Rounding<'a> {
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
    pub(super) fn entry(&self, k: usize, v: u32) -> f64 {
        let (bk, _) = self.f.at[self.open[k] as usize];
        let (bv, lv) = self.f.at[v as usize];
        if bk == bv {
            self.columns[k][lv as usize]
        } else {
            0.0
        }
    }

    /// The multipliers `μ` for the open unknowns `fixed` (indices into `open`) at `values`.
    pub(super) fn multipliers(&self, fixed: &[(usize, f64)]) -> Option<Vec<f64>> {
        let m = fixed.len();
        let a =
            nalgebra::DMatrix::from_fn(m, m, |r, c| self.entry(fixed[c].0, self.open[fixed[r].0]));
        let b = nalgebra::DVector::from_fn(m, |r, _| {
            fixed[r].1 - self.f.x0[self.open[fixed[r].0] as usize]
        });
        a.cholesky().map(|c| c.solve(&b).iter().copied().collect())
    }

    /// Value of free variable `v` under multipliers `mu` for `fixed`.
    pub(super) fn value(&self, fixed: &[(usize, f64)], mu: &[f64], v: u32) -> f64 {
        self.f.x0[v as usize]
            + fixed
                .iter()
                .zip(mu)
                .map(|(&(k, _), m)| m * self.entry(k, v))
                .sum::<f64>()
    }

    /// All free variables under `fixed`.
    pub(super) fn solution(&self, fixed: &[(usize, f64)]) -> Option<Vec<f64>> {
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
