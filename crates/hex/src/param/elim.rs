//! The exact elimination of the constraints (module docs of [`super`], "Constraints"):
//! linear expressions in the free unknowns, and Gaussian elimination that keeps every
//! eliminated unknown as such an expression, pivoting on continuous unknowns with unit
//! coefficients first (Bommes, Zimmer, Kobbelt, "Mixed-integer quadrangulation", 2009, §4).

/// A linear expression `Σ cᵢ yᵢ + k` in free variables.
#[derive(Clone, Debug, Default)]
pub(super) struct Expr {
    pub(super) terms: Vec<(u32, f64)>,
    pub(super) constant: f64,
}

impl Expr {
    pub(super) fn add_scaled(&mut self, other: &Expr, s: f64) {
        let mut out = Vec::with_capacity(self.terms.len() + other.terms.len());
        let (mut i, mut j) = (0, 0);
        while i < self.terms.len() || j < other.terms.len() {
            let a = self.terms.get(i);
            let b = other.terms.get(j);
            match (a, b) {
                (Some(&(va, ca)), Some(&(vb, cb))) if va == vb => {
                    let c = ca + s * cb;
                    if c != 0.0 {
                        out.push((va, c));
                    }
                    i += 1;
                    j += 1;
                }
                (Some(&(va, ca)), Some(&(vb, _))) if va < vb => {
                    out.push((va, ca));
                    i += 1;
                }
                (Some(&(va, ca)), None) => {
                    out.push((va, ca));
                    i += 1;
                }
                (_, Some(&(vb, cb))) => {
                    out.push((vb, s * cb));
                    j += 1;
                }
                (None, None) => unreachable!(),
            }
        }
        self.terms = out;
        self.constant += s * other.constant;
    }

    pub(super) fn coef(&self, v: u32) -> f64 {
        self.terms
            .binary_search_by_key(&v, |t| t.0)
            .map_or(0.0, |k| self.terms[k].1)
    }
}

/// Gaussian elimination of linear constraints, keeping every eliminated variable as an
/// expression in free ones. A row pivots on a continuous variable with a unit coefficient
/// when it has one, else on an integer variable with a unit coefficient, so free integer
/// variables stay independent and eliminated integer variables are integer combinations of
/// free integer ones (as in Bommes, Zimmer, Kobbelt 2009, §4).
pub(super) struct Elim {
    pub(super) expr: Vec<Option<Expr>>,
    pub(super) users: Vec<Vec<u32>>,
    pub(super) integer: Vec<bool>,
}

impl Elim {
    pub(super) fn new(integer: Vec<bool>) -> Elim {
        let n = integer.len();
        Elim {
            expr: vec![None; n],
            users: vec![Vec::new(); n],
            integer,
        }
    }

    /// The expression of variable `v` in free variables.
    pub(super) fn of(&self, v: u32) -> Expr {
        match &self.expr[v as usize] {
            Some(e) => e.clone(),
            None => Expr {
                terms: vec![(v, 1.0)],
                constant: 0.0,
            },
        }
    }

    /// Adds the constraint `Σ cᵢ yᵢ = rhs`. Returns whether it was independent; `Err` when it
    /// reduces to `0 = nonzero`.
    pub(super) fn add(&mut self, row: &[(u32, f64)], rhs: f64) -> Result<bool, f64> {
        let mut e = Expr {
            terms: Vec::new(),
            constant: -rhs,
        };
        for &(v, c) in row {
            e.add_scaled(&self.of(v), c);
        }
        e.terms.retain(|t| t.1.abs() > 1e-12);
        let unit = |t: &&(u32, f64)| (t.1.abs() - 1.0).abs() < 1e-12;
        let pivot = e
            .terms
            .iter()
            .filter(unit)
            .filter(|t| !self.integer[t.0 as usize])
            .max_by_key(|t| t.0)
            .or_else(|| e.terms.iter().filter(unit).max_by_key(|t| t.0))
            .or_else(|| {
                e.terms
                    .iter()
                    .filter(|t| !self.integer[t.0 as usize])
                    .max_by_key(|t| t.0)
            })
            .or_else(|| e.terms.iter().max_by_key(|t| t.0))
            .copied();
        let Some((p, cp)) = pivot else {
            return if e.constant.abs() < 1e-9 {
                Ok(false)
            } else {
                Err(e.constant)
            };
        };
        // p = −(e − cp p) / cp
        let mut ep = Expr {
            terms: e
                .terms
                .iter()
                .filter(|t| t.0 != p)
                .map(|&(v, c)| (v, -c / cp))
                .collect(),
            constant: -e.constant / cp,
        };
        ep.terms.retain(|t| t.1 != 0.0);
        for q in std::mem::take(&mut self.users[p as usize]) {
            let Some(eq) = self.expr[q as usize].as_mut() else {
                continue;
            };
            let c = eq.coef(p);
            if c == 0.0 {
                continue;
            }
            let mut removed = Expr {
                terms: vec![(p, 1.0)],
                constant: 0.0,
            };
            removed.add_scaled(&ep, -1.0);
            eq.add_scaled(&removed, -c);
            for &(v, _) in &ep.terms {
                self.users[v as usize].push(q);
            }
        }
        for &(v, _) in &ep.terms {
            self.users[v as usize].push(p);
        }
        self.expr[p as usize] = Some(ep);
        Ok(true)
    }
}
