//! Untangling a linearly constrained tetrahedral map: the inverted tetrahedra a rounded
//! parameterisation leaves are turned back by minimising the regularised distortion energy of
//! Garanzha, Kaporin, Kudryavtseva, Protais, Ray, Sokolov, "Foldover-free maps in 50 lines of
//! code" (SIGGRAPH 2021), over the map's continuous unknowns only, so that every constraint
//! (integer planes, transitions, singular lines) still holds exactly.
//!
//! # Method
//!
//! Per tetrahedron `t` the map is linear with Jacobian `J = Σⱼ uⱼ ⊗ ∇φⱼ` (`uⱼ` the parameters
//! of corner `j`, `φⱼ` its barycentric function in space). Measured against a reference `T`
//! (the gradients the parameterisation aimed at), `K = J T⁻¹ = Σⱼ uⱼ ⊗ hⱼ` with
//! `hⱼ = T⁻ᵀ∇φⱼ`; `det K > 0` exactly where the tetrahedron keeps its orientation. With
//! `χ(D, ε) = (D + √(ε² + D²)) / 2`, a smooth positive stand-in for `max(D, 0)` (§3), each
//! tetrahedron contributes its weight times
//!
//! ```text
//!   f_ε(K) = tr(KᵀK) / (3 χ(det K, ε)^{2/3})  +  λ (det²K + 1) / (2 χ(det K, ε))
//! ```
//!
//! the shape term (scale invariant, 1 for a rotation) and the volume term (1 at `det K = 1`).
//! For `ε > 0` the energy is finite and smooth everywhere, inverted tetrahedra included; as
//! `ε → 0` it becomes a barrier that no minimiser crosses. The unknowns the map depends on are
//! reached through fixed affine forms ([`Affine`]: what elimination of the constraints left),
//! so the gradient is the chain rule through them. Each value of `ε` is minimised by L-BFGS
//! (two-loop recursion, backtracking line search), then `ε` is lowered by the paper's rule
//! (§4): with `E` the energy before and after the stage, `σ = max(1 − E_after/E_before, 0.1)`,
//! `μ = (1 − σ) χ(D_min, ε)`, and `ε ← 2 √(μ (μ − D_min))` while `D_min < μ`, else a tiny
//! `ε`; it stops when no tetrahedron is inverted and the energy has settled.
//!
//! The map is changed only near the inverted tetrahedra: the unknowns of the tetrahedra within
//! `r` rings (tetrahedra sharing a point) of an inverted one move, every tetrahedron they touch
//! is in the energy, and the rest of the map is kept. When that does not untangle everything
//! the region grows ([`UntangleParams::rings`]), the last try over the whole map.
//!
//! Per-tetrahedron terms are evaluated in parallel and summed in index order, so the result
//! is the same for any thread count.

use rayon::prelude::*;

use crate::geom::vec::{cross, dot};

/// A parameter as an affine function of the unknowns: `constant + Σ c · z[i]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Affine {
    /// `(unknown, coefficient)` pairs.
    pub terms: Vec<(u32, f64)>,
    /// The constant part.
    pub constant: f64,
}

impl Affine {
    fn eval(&self, z: &[f64]) -> f64 {
        self.constant
            + self
                .terms
                .iter()
                .map(|&(i, c)| c * z[i as usize])
                .sum::<f64>()
    }
}

/// A tetrahedral map whose corner parameters are affine in the unknowns.
pub struct Problem<'a> {
    /// Per tetrahedron, its four corners' points (indices into `points`).
    pub corners: &'a [[u32; 4]],
    /// Per point, its three parameters.
    pub points: &'a [[Affine; 3]],
    /// Per tetrahedron, the reference gradients `hⱼ = T⁻ᵀ∇φⱼ` (module docs).
    pub reference: &'a [[[f64; 3]; 4]],
    /// Per tetrahedron, its weight (its volume over the mean volume).
    pub weights: &'a [f64],
}

/// Stages without fewer inverted tetrahedra after which a region is given up.
const STALL_STAGES: usize = 4;

/// Parameters of [`untangle`].
#[derive(Clone, Debug, PartialEq)]
pub struct UntangleParams {
    /// The region's radius in rings of tetrahedra around the inverted ones, tried in turn
    /// until none is inverted; `usize::MAX`: the whole map.
    pub rings: Vec<usize>,
    /// Weight `λ` of the volume term.
    pub lambda: f64,
    /// Most values of `ε` per region.
    pub max_stages: usize,
    /// Most L-BFGS iterations per value of `ε`.
    pub max_iterations: usize,
    /// With more inverted tetrahedra than this fraction of them (and more than
    /// [`UntangleParams::min_inverted_cap`]) the map is not a small perturbation of an
    /// injective one (its layout is wrong, not its placement) and is left as it is.
    pub max_inverted_fraction: f64,
    /// The fraction's floor: this many inverted tetrahedra are always tried.
    pub min_inverted_cap: usize,
}

impl Default for UntangleParams {
    fn default() -> Self {
        UntangleParams {
            rings: vec![3, 6, 12, usize::MAX],
            lambda: 1.0,
            max_stages: 40,
            max_iterations: 300,
            max_inverted_fraction: 0.01,
            min_inverted_cap: 100,
        }
    }
}

/// What [`untangle`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct UntangleReport {
    /// Inverted tetrahedra (`det K ≤ 0`) before.
    pub inverted_before: usize,
    /// And after.
    pub inverted_after: usize,
    /// The last region tried, in rings (`None`: the whole map).
    pub rings: Option<usize>,
    /// Unknowns moved in the last region.
    pub unknowns: usize,
    /// Tetrahedra in its energy.
    pub tets: usize,
    /// Values of `ε` minimised, over all regions.
    pub stages: usize,
    /// L-BFGS iterations over all regions.
    pub iterations: usize,
    /// Smallest `det K` after.
    pub min_det: f64,
    /// Whether the map had too many inverted tetrahedra to be untangled and was left as it
    /// was ([`UntangleParams::max_inverted_fraction`]).
    pub too_many: bool,
    /// Pairs of tetrahedra on the same four points with opposite orientations (at most 16
    /// listed): no map turns both positive, so they are left out of the untangling.
    pub conflicts: Vec<[u32; 2]>,
}

/// `χ(D, ε)` and its derivative in `D`.
fn chi(d: f64, eps: f64) -> (f64, f64) {
    let s = (eps * eps + d * d).sqrt();
    if d >= 0.0 {
        ((d + s) / 2.0, (1.0 + d / s) / 2.0)
    } else {
        // The same value without cancellation: (D + s)/2 = ε² / (2 (s − D)).
        (eps * eps / (2.0 * (s - d)), (1.0 + d / s) / 2.0)
    }
}

impl Problem<'_> {
    /// Corner parameters of tetrahedron `t` for unknowns `z`.
    fn corner_params(&self, t: usize, z: &[f64]) -> [[f64; 3]; 4] {
        self.corners[t].map(|p| self.points[p as usize].each_ref().map(|a| a.eval(z)))
    }

    /// `K` of tetrahedron `t` (rows).
    fn k(&self, t: usize, z: &[f64]) -> [[f64; 3]; 3] {
        let u = self.corner_params(t, z);
        let h = &self.reference[t];
        std::array::from_fn(|r| std::array::from_fn(|c| (0..4).map(|j| u[j][r] * h[j][c]).sum()))
    }

    fn det(&self, t: usize, z: &[f64]) -> f64 {
        let k = self.k(t, z);
        dot(k[0], cross(k[1], k[2]))
    }

    /// Smallest `det K` over all tetrahedra.
    fn min_det(&self, z: &[f64]) -> f64 {
        (0..self.corners.len())
            .into_par_iter()
            .map(|t| self.det(t, z))
            .reduce(|| f64::INFINITY, f64::min)
    }

    /// Tetrahedra with `det K ≤ 0`.
    pub fn inverted(&self, z: &[f64]) -> Vec<u32> {
        (0..self.corners.len() as u32)
            .into_par_iter()
            .filter(|&t| self.det(t as usize, z) <= 0.0)
            .collect()
    }

    /// Energy of tetrahedron `t` and its gradient in the corner parameters.
    fn term(&self, t: usize, z: &[f64], eps: f64, lambda: f64) -> (f64, [[f64; 3]; 4]) {
        let k = self.k(t, z);
        let cof = [cross(k[1], k[2]), cross(k[2], k[0]), cross(k[0], k[1])];
        let d = dot(k[0], cof[0]);
        let tr: f64 = k.iter().map(|r| dot(*r, *r)).sum();
        let (x, dx) = chi(d, eps);
        let x23 = x.powf(2.0 / 3.0);
        let shape = tr / (3.0 * x23);
        let volume = (d * d + 1.0) / (2.0 * x);
        let w = self.weights[t];
        // ∂f/∂K = a K + b cof(K).
        let a = 2.0 / (3.0 * x23);
        let b = -(2.0 / 9.0) * tr / (x23 * x) * dx
            + lambda * (d / x - (d * d + 1.0) * dx / (2.0 * x * x));
        let g: [[f64; 3]; 3] =
            std::array::from_fn(|r| std::array::from_fn(|c| w * (a * k[r][c] + b * cof[r][c])));
        let h = &self.reference[t];
        let du = std::array::from_fn(|j| std::array::from_fn(|r| dot(g[r], h[j])));
        (w * (shape + lambda * volume), du)
    }
}

/// One region's unknowns and the tetrahedra of its energy.
struct Region {
    /// Unknowns that move, ascending.
    moving: Vec<u32>,
    /// Position of each unknown in `moving` (`u32::MAX`: fixed).
    slot: Vec<u32>,
    /// Tetrahedra whose corners depend on a moving unknown, ascending.
    tets: Vec<u32>,
}

/// Point → tetrahedra and unknown → points incidence, in CSR form.
struct Incidence {
    point_tets: (Vec<usize>, Vec<u32>),
    unknown_points: (Vec<usize>, Vec<u32>),
}

fn csr(n: usize, pairs: &mut Vec<(u32, u32)>) -> (Vec<usize>, Vec<u32>) {
    pairs.sort_unstable();
    pairs.dedup();
    let mut start = vec![0usize; n + 1];
    for &(a, _) in pairs.iter() {
        start[a as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    (start, pairs.iter().map(|p| p.1).collect())
}

fn row(c: &(Vec<usize>, Vec<u32>), i: usize) -> &[u32] {
    &c.1[c.0[i]..c.0[i + 1]]
}

impl Incidence {
    fn new(p: &Problem<'_>, nz: usize) -> Incidence {
        let mut pt: Vec<(u32, u32)> = Vec::with_capacity(4 * p.corners.len());
        for (t, c) in p.corners.iter().enumerate() {
            for &q in c {
                pt.push((q, t as u32));
            }
        }
        let mut up: Vec<(u32, u32)> = Vec::new();
        for (q, axes) in p.points.iter().enumerate() {
            for a in axes {
                for &(i, _) in &a.terms {
                    up.push((i, q as u32));
                }
            }
        }
        Incidence {
            point_tets: csr(p.points.len(), &mut pt),
            unknown_points: csr(nz, &mut up),
        }
    }

    /// The region of `rings` rings around `seeds`, moving only `movable` unknowns.
    fn region(&self, p: &Problem<'_>, seeds: &[u32], rings: usize, movable: &[bool]) -> Region {
        let nt = p.corners.len();
        let mut in_region = vec![false; nt];
        let mut front: Vec<u32> = seeds.to_vec();
        for &t in seeds {
            in_region[t as usize] = true;
        }
        let mut ring = 0;
        while ring < rings && !front.is_empty() {
            let mut next = Vec::new();
            for &t in &front {
                for &q in &p.corners[t as usize] {
                    for &s in row(&self.point_tets, q as usize) {
                        if !in_region[s as usize] {
                            in_region[s as usize] = true;
                            next.push(s);
                        }
                    }
                }
            }
            front = next;
            ring += 1;
        }
        let nz = movable.len();
        let mut moves = vec![false; nz];
        for t in (0..nt).filter(|&t| in_region[t]) {
            for &q in &p.corners[t] {
                for a in &p.points[q as usize] {
                    for &(i, _) in &a.terms {
                        moves[i as usize] = movable[i as usize];
                    }
                }
            }
        }
        let moving: Vec<u32> = (0..nz as u32).filter(|&i| moves[i as usize]).collect();
        let mut slot = vec![u32::MAX; nz];
        for (k, &i) in moving.iter().enumerate() {
            slot[i as usize] = k as u32;
        }
        let mut touched = vec![false; nt];
        for &i in &moving {
            for &q in row(&self.unknown_points, i as usize) {
                for &t in row(&self.point_tets, q as usize) {
                    touched[t as usize] = true;
                }
            }
        }
        let tets = (0..nt as u32).filter(|&t| touched[t as usize]).collect();
        Region { moving, slot, tets }
    }
}

/// Energy of the region's tetrahedra at `z` and its gradient in the moving unknowns.
fn energy(p: &Problem<'_>, r: &Region, z: &[f64], eps: f64, lambda: f64, grad: &mut [f64]) -> f64 {
    let terms: Vec<(f64, [[f64; 3]; 4])> = r
        .tets
        .par_iter()
        .map(|&t| p.term(t as usize, z, eps, lambda))
        .collect();
    grad.fill(0.0);
    let mut e = 0.0;
    for (&t, (et, du)) in r.tets.iter().zip(&terms) {
        e += et;
        for (j, &q) in p.corners[t as usize].iter().enumerate() {
            for (a, axis) in p.points[q as usize].iter().enumerate() {
                for &(i, c) in &axis.terms {
                    let s = r.slot[i as usize];
                    if s != u32::MAX {
                        grad[s as usize] += c * du[j][a];
                    }
                }
            }
        }
    }
    e
}

/// L-BFGS on `f` (energy, gradient) from `x`: at most `max_iter` iterations, stopping when a
/// step no longer lowers the energy by a relative `1e-9` or the gradient vanishes. Returns
/// the iterations taken.
fn lbfgs(f: &mut dyn FnMut(&[f64], &mut [f64]) -> f64, x: &mut [f64], max_iter: usize) -> usize {
    const HISTORY: usize = 8;
    let n = x.len();
    let mut g = vec![0.0; n];
    let mut e = f(x, &mut g);
    let mut s_hist: Vec<Vec<f64>> = Vec::new();
    let mut y_hist: Vec<Vec<f64>> = Vec::new();
    let mut xn = vec![0.0; n];
    let mut gn = vec![0.0; n];
    for iter in 0..max_iter {
        let gnorm = g.iter().map(|v| v * v).sum::<f64>().sqrt();
        if gnorm <= 1e-12 * (1.0 + e.abs()) {
            return iter;
        }
        // Two-loop recursion: d = −H g.
        let mut q = g.clone();
        let mut alpha = vec![0.0; s_hist.len()];
        for k in (0..s_hist.len()).rev() {
            let rho = 1.0 / dotn(&y_hist[k], &s_hist[k]);
            alpha[k] = rho * dotn(&s_hist[k], &q);
            for (qi, yi) in q.iter_mut().zip(&y_hist[k]) {
                *qi -= alpha[k] * yi;
            }
        }
        let gamma = match (s_hist.last(), y_hist.last()) {
            (Some(s), Some(y)) => dotn(s, y) / dotn(y, y),
            _ => 1.0 / gnorm.max(1e-300),
        };
        for qi in q.iter_mut() {
            *qi *= gamma;
        }
        for k in 0..s_hist.len() {
            let rho = 1.0 / dotn(&y_hist[k], &s_hist[k]);
            let beta = rho * dotn(&y_hist[k], &q);
            for (qi, si) in q.iter_mut().zip(&s_hist[k]) {
                *qi += (alpha[k] - beta) * si;
            }
        }
        let mut slope = -dotn(&g, &q);
        if slope >= 0.0 {
            // Not a descent direction: restart from the steepest descent.
            s_hist.clear();
            y_hist.clear();
            q.clone_from(&g);
            let scale = 1.0 / gnorm;
            for qi in q.iter_mut() {
                *qi *= scale;
            }
            slope = -dotn(&g, &q);
        }
        // Backtracking line search on the Armijo condition.
        let mut step = 1.0;
        let mut accepted = None;
        for _ in 0..40 {
            for i in 0..n {
                xn[i] = x[i] - step * q[i];
            }
            let en = f(&xn, &mut gn);
            if en.is_finite() && en <= e + 1e-4 * step * slope {
                accepted = Some(en);
                break;
            }
            step *= 0.5;
        }
        let Some(en) = accepted else {
            return iter;
        };
        let s: Vec<f64> = (0..n).map(|i| xn[i] - x[i]).collect();
        let y: Vec<f64> = (0..n).map(|i| gn[i] - g[i]).collect();
        if dotn(&s, &y) > 1e-16 * dotn(&y, &y).max(1e-300) {
            if s_hist.len() == HISTORY {
                s_hist.remove(0);
                y_hist.remove(0);
            }
            s_hist.push(s);
            y_hist.push(y);
        }
        x.copy_from_slice(&xn);
        g.copy_from_slice(&gn);
        let decrease = e - en;
        e = en;
        if decrease <= 1e-9 * e.abs() {
            return iter + 1;
        }
    }
    max_iter
}

fn dotn(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Untangles the map `z` of `p` (module docs), moving only the unknowns marked `movable`.
pub fn untangle(
    p: &Problem<'_>,
    z: &mut [f64],
    movable: &[bool],
    params: &UntangleParams,
) -> UntangleReport {
    let mut report = UntangleReport::default();
    let seeds = p.inverted(z);
    report.inverted_before = seeds.len();
    report.inverted_after = seeds.len();
    let too_many = seeds.len() > params.min_inverted_cap
        && seeds.len() as f64 > params.max_inverted_fraction * p.corners.len() as f64;
    report.too_many = too_many;
    if seeds.is_empty() || too_many {
        report.min_det = p.min_det(z);
        return report;
    }
    let incidence = Incidence::new(p, z.len());
    let conflicts = conflicts(p.corners);
    let mut hopeless = vec![false; p.corners.len()];
    for &[a, b] in &conflicts {
        hopeless[a as usize] = true;
        hopeless[b as usize] = true;
    }
    report.conflicts = conflicts.into_iter().take(16).collect();
    // A tetrahedron none of whose points moves cannot be turned back.
    let can_move = |t: u32| {
        !hopeless[t as usize]
            && p.corners[t as usize].iter().any(|&q| {
                p.points[q as usize]
                    .iter()
                    .any(|a| a.terms.iter().any(|&(i, _)| movable[i as usize]))
            })
    };
    for &rings in &params.rings {
        let seeds: Vec<u32> = p.inverted(z).into_iter().filter(|&t| can_move(t)).collect();
        if seeds.is_empty() {
            break;
        }
        let region = incidence.region(p, &seeds, rings, movable);
        report.rings = (rings != usize::MAX).then_some(rings);
        report.unknowns = region.moving.len();
        report.tets = region.tets.len();
        let mut x: Vec<f64> = region.moving.iter().map(|&i| z[i as usize]).collect();
        let mut work = z.to_vec();
        let mut dmin = region
            .tets
            .par_iter()
            .map(|&t| p.det(t as usize, z))
            .reduce(|| f64::INFINITY, f64::min);
        let mut eps = (1e-10 + 0.04 * dmin * dmin).sqrt();
        let mut grad = vec![0.0; x.len()];
        let mut e_prev = energy(p, &region, z, eps, params.lambda, &mut grad);
        let mut best = (usize::MAX, 0);
        for stage in 0..params.max_stages {
            report.stages += 1;
            let mut f = |xs: &[f64], g: &mut [f64]| {
                for (k, &i) in region.moving.iter().enumerate() {
                    work[i as usize] = xs[k];
                }
                energy(p, &region, &work, eps, params.lambda, g)
            };
            report.iterations += lbfgs(&mut f, &mut x, params.max_iterations);
            let e = f(&x, &mut grad);
            let dets: Vec<f64> = region
                .tets
                .par_iter()
                .map(|&t| p.det(t as usize, &work))
                .collect();
            dmin = dets.iter().copied().fold(f64::INFINITY, f64::min);
            let sigma = (1.0 - e / e_prev).max(0.1);
            let mu = (1.0 - sigma) * chi(dmin, eps).0;
            eps = if dmin < mu {
                2.0 * (mu * (mu - dmin)).sqrt()
            } else {
                1e-10
            };
            let settled = (e_prev - e).abs() <= 1e-5 * e.abs();
            e_prev = e;
            if dmin > 0.0 && settled {
                break;
            }
            // Stalled: the inverted tetrahedra have not become fewer for a few stages.
            let inverted = dets.iter().filter(|&&d| d <= 0.0).count();
            if inverted < best.0 {
                best = (inverted, stage);
            } else if stage >= best.1 + STALL_STAGES {
                break;
            }
        }
        for (k, &i) in region.moving.iter().enumerate() {
            z[i as usize] = x[k];
        }
        report.inverted_after = p.inverted(z).len();
        if report.inverted_after == 0 {
            break;
        }
    }
    report.min_det = p.min_det(z);
    report
}

/// How a vertex may move in [`untangle_hexes`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Freedom {
    /// It stays.
    Fixed,
    /// Anywhere.
    Free,
    /// In the plane through it with this unit normal.
    Plane([f64; 3]),
}

/// Untangles hexahedra (vertices `verts`, corners in VTK order) by their corner tetrahedra:
/// each corner with the ends of its three edges ([`super::quality::HEX_CORNER_EDGES`], whose
/// determinants are Verdict's corner Jacobians), measured against the right-angled corner of
/// a cube with the hexahedron's mean edge length. Each vertex moves as its [`Freedom`] allows
/// ([`untangle`]).
pub fn untangle_hexes(
    verts: &mut [[f64; 3]],
    hexes: &[[u32; 8]],
    freedom: &[Freedom],
    params: &UntangleParams,
) -> UntangleReport {
    use super::quality::{HEX_CORNER_EDGES, HEX_EDGES};
    let mut z = Vec::new();
    let points: Vec<[Affine; 3]> = verts
        .iter()
        .zip(freedom)
        .map(|(p, f)| {
            let dirs: Vec<[f64; 3]> = match *f {
                Freedom::Fixed => Vec::new(),
                Freedom::Free => vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                Freedom::Plane(n) => {
                    let (t1, t2) = super::smooth_frames::tangents(n);
                    vec![t1, t2]
                }
            };
            let first = z.len() as u32;
            z.extend(dirs.iter().map(|_| 0.0));
            std::array::from_fn(|a| Affine {
                terms: dirs
                    .iter()
                    .enumerate()
                    .filter(|(_, d)| d[a] != 0.0)
                    .map(|(k, d)| (first + k as u32, d[a]))
                    .collect(),
                constant: p[a],
            })
        })
        .collect();
    let movable = vec![true; z.len()];
    let mut corners = Vec::with_capacity(8 * hexes.len());
    let mut reference = Vec::with_capacity(8 * hexes.len());
    for h in hexes {
        let edge = HEX_EDGES
            .iter()
            .map(|&[a, b]| {
                let (p, q) = (verts[h[a] as usize], verts[h[b] as usize]);
                let d = [0, 1, 2].map(|x| p[x] - q[x]);
                dot(d, d).sqrt()
            })
            .sum::<f64>()
            / 12.0;
        let l = if edge > 0.0 { edge } else { 1.0 };
        // The barycentric gradients of the corner tetrahedron (0, l e₁, l e₂, l e₃).
        let h_ref = [
            [-1.0 / l, -1.0 / l, -1.0 / l],
            [1.0 / l, 0.0, 0.0],
            [0.0, 1.0 / l, 0.0],
            [0.0, 0.0, 1.0 / l],
        ];
        for c in HEX_CORNER_EDGES {
            corners.push(c.map(|i| h[i]));
            reference.push(h_ref);
        }
    }
    let weights = vec![1.0; corners.len()];
    let problem = Problem {
        corners: &corners,
        points: &points,
        reference: &reference,
        weights: &weights,
    };
    let report = untangle(&problem, &mut z, &movable, params);
    for (p, a) in verts.iter_mut().zip(&points) {
        *p = std::array::from_fn(|x| a[x].eval(&z));
    }
    report
}

/// Pairs of tetrahedra with the same four points in orders of opposite parity.
fn conflicts(corners: &[[u32; 4]]) -> Vec<[u32; 2]> {
    let mut keyed: Vec<([u32; 4], bool, u32)> = corners
        .iter()
        .enumerate()
        .map(|(t, c)| {
            // Sort by swaps, counting their parity.
            let mut k = *c;
            let mut odd = false;
            for i in 0..4 {
                for j in 0..3 - i {
                    if k[j] > k[j + 1] {
                        k.swap(j, j + 1);
                        odd = !odd;
                    }
                }
            }
            (k, odd, t as u32)
        })
        .collect();
    keyed.sort_unstable();
    let mut out = Vec::new();
    for run in keyed.chunk_by(|a, b| a.0 == b.0) {
        if let (Some(even), Some(odd)) = (run.iter().find(|x| !x.1), run.iter().find(|x| x.1)) {
            out.push([even.2.min(odd.2), even.2.max(odd.2)]);
        }
    }
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::HexMesh;

    /// The `n³` grid of unit cubes, vertex `(i, j, k)` at `i + (n+1)(j + (n+1)k)`.
    fn unit_grid(n: usize) -> HexMesh {
        let mut m = crate::relax::tests::grid(n);
        for p in &mut m.verts {
            *p = p.map(|x| x * n as f64);
        }
        m
    }

    fn gradients(p: [[f64; 3]; 4]) -> [[f64; 3]; 4] {
        crate::param::gradients(&p)
    }

    #[test]
    fn a_pushed_through_vertex_is_pulled_back_and_the_fixed_ones_stay() {
        let n = 4;
        let crate::mesh::TetMesh { verts, tets } = crate::mesh::TetMesh::grid_box([n; 3], 1.0);
        // Unknowns: three per vertex; boundary vertices fixed (constants), interior ones free.
        let interior = |p: [f64; 3]| p.iter().all(|&x| x > 0.0 && x < n as f64);
        let mut z = Vec::new();
        let mut movable = Vec::new();
        let points: Vec<[Affine; 3]> = verts
            .iter()
            .map(|&p| {
                std::array::from_fn(|a| {
                    if interior(p) {
                        z.push(p[a]);
                        movable.push(true);
                        Affine {
                            terms: vec![((z.len() - 1) as u32, 1.0)],
                            constant: 0.0,
                        }
                    } else {
                        Affine {
                            terms: Vec::new(),
                            constant: p[a],
                        }
                    }
                })
            })
            .collect();
        let reference: Vec<[[f64; 3]; 4]> = tets
            .iter()
            .map(|t| gradients(t.map(|v| verts[v as usize])))
            .collect();
        let weights = vec![1.0; tets.len()];
        let p = Problem {
            corners: &tets,
            points: &points,
            reference: &reference,
            weights: &weights,
        };
        assert!(p.inverted(&z).is_empty());
        // Push the vertex (1, 1, 1) through its neighbours to (2.7, 2.6, 2.8).
        let v = verts.iter().position(|&q| q == [1.0, 1.0, 1.0]).unwrap();
        let zi = points[v][0].terms[0].0 as usize;
        z[zi..zi + 3].copy_from_slice(&[2.7, 2.6, 2.8]);
        let before = p.inverted(&z).len();
        assert!(before > 0);
        let start = z.clone();
        let r = untangle(&p, &mut z, &movable, &UntangleParams::default());
        assert_eq!(r.inverted_before, before);
        assert_eq!(r.inverted_after, 0, "{r:?}");
        assert!(r.min_det > 0.0);
        assert!(p.inverted(&z).is_empty());
        // Only the interior moved (the boundary points are constants), and the same way for
        // one thread.
        let mut z1 = start;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let r1 = pool.install(|| untangle(&p, &mut z1, &movable, &UntangleParams::default()));
        assert_eq!(r1, r);
        assert_eq!(z1, z);
    }

    #[test]
    fn folded_hexahedra_are_untangled_with_the_boundary_held() {
        // A 4³ grid of unit cubes; an interior vertex pushed through the far side of its
        // neighbours folds the hexahedra around it.
        let n = 4;
        let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
        let HexMesh { mut verts, hexes } = unit_grid(n);
        let boundary = |p: [f64; 3]| p.iter().any(|&x| x == 0.0 || x == n as f64);
        let freedom: Vec<Freedom> = verts
            .iter()
            .map(|&p| {
                if boundary(p) {
                    Freedom::Fixed
                } else {
                    Freedom::Free
                }
            })
            .collect();
        let sj = |v: &[[f64; 3]]| -> Vec<f64> {
            hexes
                .iter()
                .map(|h| crate::quality::hex_scaled_jacobian(&h.map(|i| v[i as usize])))
                .collect()
        };
        verts[id(1, 1, 1) as usize] = [2.6, 2.5, 2.7];
        let start = verts.clone();
        assert!(sj(&verts).iter().any(|&x| x <= 0.0));
        let r = untangle_hexes(&mut verts, &hexes, &freedom, &UntangleParams::default());
        assert!(r.inverted_before > 0 && r.inverted_after == 0, "{r:?}");
        assert!(r.conflicts.is_empty());
        assert!(sj(&verts).iter().all(|&x| x > 0.0), "{:?}", sj(&verts));
        for (v, p) in verts.iter().enumerate() {
            if boundary(start[v]) {
                assert_eq!(*p, start[v]);
            }
        }
        // A vertex held in a plane stays in it.
        let mut verts2 = start.clone();
        let mut freedom2 = freedom.clone();
        freedom2[id(1, 1, 1) as usize] = Freedom::Plane([0.0, 0.0, 1.0]);
        untangle_hexes(&mut verts2, &hexes, &freedom2, &UntangleParams::default());
        assert!((verts2[id(1, 1, 1) as usize][2] - 2.7).abs() < 1e-12);
    }

    #[test]
    fn two_tetrahedra_on_the_same_points_with_opposite_orientations_conflict() {
        let c = [
            [0, 1, 2, 3],
            [4, 5, 6, 7],
            [1, 0, 2, 3],
            [2, 3, 0, 1],
            [7, 5, 4, 6],
        ];
        // 1: an odd permutation of 0; 3: an even one (not a conflict with 0); 4: even of 1.
        assert_eq!(conflicts(&c), vec![[0, 2]]);
    }
}
