//! Hierarchical bicubic B-splines on nested rectangular regions (Greiner & Hormann 1997, §5).
//!
//! # The space
//!
//! Level `l` has knot spacing `h_l = h_0 / 2^l` over the domain `[0, n_0 h_0] × [0, m_0 h_0]`
//! and `n_l × m_l = (n_0 2^l) × (m_0 2^l)` cells. The regions are nested,
//! `Ω_0 = domain ⊇ Ω_1 ⊇ … ⊇ Ω_L`, each `Ω_{l+1}` a union of level-`l` cells (the *refined*
//! cells of level `l`). The basis is Kraft's selection of the levels' B-splines, the one
//! Greiner & Hormann use: `B^l_ij` belongs to it iff its support (4 × 4 level-`l` cells) lies
//! in `Ω_l` and not in `Ω_{l+1}`. The functions are linearly independent, and the spaces are
//! nested as the regions grow, since a level-`l` function whose support lies in `Ω_{l+1}` is
//! a combination of level-`l+1` functions (`basis::MASK`) whose supports lie there too.
//!
//! Functions near the domain's edge reach outside it. A cell outside the domain counts as
//! belonging to a region when the nearest cell inside does (the cell index is clamped), so a
//! region that touches the edge extends across it and its functions there are selected like
//! interior ones.
//!
//! A point of the domain lies in exactly one *leaf* cell: a level-`l` cell of `Ω_l` that is not
//! refined. Every basis function is a polynomial on a leaf cell (coarser knots are a subset of
//! finer ones), so integrals over the domain are sums of Gauss quadratures over leaf cells.
//!
//! # Refinement (§5)
//!
//! [`Hierarchy::refine`] takes the leaf cells where the fit misses the tolerance, grows each
//! level's set by one ring of cells (a region of one cell would hold no finer function: a
//! level-`l+1` support spans two level-`l` cells), groups it into rectangles (the bounding
//! boxes of its 8-connected components, clipped to the level's leaf cells) and refines those;
//! where more than half of a level's leaf area would be refined, the whole level is
//! (global refinement, halving the knot spacing).
//!
//! # Export
//!
//! [`Hierarchy::to_tensor`] rewrites the surface exactly as one tensor-product B-spline: the
//! knot vector along each axis is the union of the knots of the selected functions, every
//! function is expanded in it by knot insertion (`basis::oslo`), and the ends are clamped by
//! raising the domain's end knots to multiplicity 4.

use std::collections::{BTreeSet, HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use super::basis::{cubic, oslo};
use crate::types::TensorSurface;

/// A fast, deterministic hasher for small integer keys (multiply–rotate).
#[derive(Default, Clone, Copy)]
pub struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(26) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
    fn write_i64(&mut self, x: i64) {
        self.write_u64(x as u64);
    }
}

type Build = BuildHasherDefault<CellHasher>;
/// A set of cells `[a, b]` of one level.
pub type CellSet = HashSet<[i64; 2], Build>;
type CellMap = HashMap<[i64; 2], u32, Build>;
/// Per (level, index): a 1D function's expansion in the merged knot vector.
type Expansions = HashMap<(usize, i64), (usize, Vec<f64>)>;

/// A leaf cell: its level and its cell index at that level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Leaf {
    /// Level.
    pub level: u8,
    /// Cell index `[a, b]` along u and v at that level.
    pub cell: [i64; 2],
}

/// One basis function nonzero on a leaf cell: its global index, level and index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Support {
    /// Index of the function's coefficient.
    pub index: u32,
    /// Level of the function.
    pub level: u8,
    /// Position of the function among the 4 × 4 nonzero at that level (`du + 4 dv`).
    pub slot: u8,
}

/// The values of the basis functions of a leaf cell at one parameter point: per level the
/// cubic pieces along u and v (`basis::cubic`, scaled to derivatives in parameter units).
#[derive(Clone, Debug, Default)]
pub struct LocalBasis {
    /// `[value, d/du, d²/du²]` of the four functions per level, along u.
    pub u: Vec<[[f64; 4]; 3]>,
    /// The same along v.
    pub v: Vec<[[f64; 4]; 3]>,
}

impl LocalBasis {
    /// `(B, B_u, B_v, B_uu, B_uv, B_vv)` of one function of the leaf.
    pub fn derivs(&self, s: &Support) -> [f64; 6] {
        let (l, du, dv) = (
            s.level as usize,
            (s.slot % 4) as usize,
            (s.slot / 4) as usize,
        );
        let (u, v) = (&self.u[l], &self.v[l]);
        [
            u[0][du] * v[0][dv],
            u[1][du] * v[0][dv],
            u[0][du] * v[1][dv],
            u[2][du] * v[0][dv],
            u[1][du] * v[1][dv],
            u[0][du] * v[2][dv],
        ]
    }

    /// The value of one function of the leaf.
    pub fn value(&self, s: &Support) -> f64 {
        let (l, du, dv) = (
            s.level as usize,
            (s.slot % 4) as usize,
            (s.slot / 4) as usize,
        );
        self.u[l][0][du] * self.v[l][0][dv]
    }
}

/// The hierarchical B-spline space: levels, regions and the selected functions.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Level-0 knot spacing, parameter units.
    pub h0: f64,
    /// Level-0 cells along u and v.
    pub cells0: [i64; 2],
    /// `refined[l]`: the level-`l` cells (inside the domain) refined into level `l + 1`.
    refined: Vec<CellSet>,
    /// Selected functions per level, sorted by `(j, i)`.
    active: Vec<Vec<[i64; 2]>>,
    /// Per level: function `[i, j]` → coefficient index.
    index: Vec<CellMap>,
    /// Per level: the index of its first coefficient.
    offset: Vec<usize>,
}

impl Hierarchy {
    /// One level of `cells0` cells of size `h0`.
    pub fn new(h0: f64, cells0: [i64; 2]) -> Hierarchy {
        let mut h = Hierarchy {
            h0,
            cells0,
            refined: vec![CellSet::default()],
            active: Vec::new(),
            index: Vec::new(),
            offset: Vec::new(),
        };
        h.select();
        h
    }

    /// Number of levels (the finest is `levels() - 1`).
    pub fn levels(&self) -> usize {
        self.refined.len()
    }

    /// Number of coefficients (selected functions).
    pub fn len(&self) -> usize {
        self.offset.last().copied().unwrap_or(0) + self.active.last().map_or(0, Vec::len)
    }

    /// Whether the space is empty (never, for a valid domain).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Selected functions per level.
    pub fn per_level(&self) -> Vec<usize> {
        self.active.iter().map(Vec::len).collect()
    }

    /// The coefficients in the refined space `new` (whose regions contain this one's) of the
    /// same surface: a function still selected keeps its coefficient; one that is not is
    /// split by the refinement mask into the next level's, recursively (exact, since the
    /// spaces are nested).
    pub fn prolong(&self, coef: &[[f64; 3]], new: &Hierarchy) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0f64; 3]; new.len()];
        for (idx, l, f) in self.functions() {
            new.add_function(l, f, coef[idx as usize], &mut out);
        }
        out
    }

    fn add_function(&self, l: usize, f: [i64; 2], c: [f64; 3], out: &mut [[f64; 3]]) {
        let n = self.cells(l);
        if f[0] < -3 || f[1] < -3 || f[0] >= n[0] || f[1] >= n[1] {
            return;
        }
        if let Some(&k) = self.index.get(l).and_then(|m| m.get(&f)) {
            for x in 0..3 {
                out[k as usize][x] += c[x];
            }
            return;
        }
        if l + 1 >= self.levels() {
            return;
        }
        for (b, wb) in super::basis::MASK.iter().enumerate() {
            for (a, wa) in super::basis::MASK.iter().enumerate() {
                let g = [2 * f[0] + a as i64, 2 * f[1] + b as i64];
                let w = wa * wb;
                self.add_function(l + 1, g, [c[0] * w, c[1] * w, c[2] * w], out);
            }
        }
    }

    /// Every selected function as `(index, level, [i, j])`, in index order.
    pub fn functions(&self) -> impl Iterator<Item = (u32, usize, [i64; 2])> + '_ {
        self.active.iter().enumerate().flat_map(move |(l, act)| {
            act.iter()
                .enumerate()
                .map(move |(k, &f)| ((self.offset[l] + k) as u32, l, f))
        })
    }

    /// Knot spacing of level `l`.
    pub fn spacing(&self, l: usize) -> f64 {
        self.h0 / f64::from(1u32 << l)
    }

    /// Cells of level `l` along u and v.
    pub fn cells(&self, l: usize) -> [i64; 2] {
        [self.cells0[0] << l, self.cells0[1] << l]
    }

    /// The domain's size `[n_0 h_0, m_0 h_0]`.
    pub fn size(&self) -> [f64; 2] {
        [
            self.cells0[0] as f64 * self.h0,
            self.cells0[1] as f64 * self.h0,
        ]
    }

    fn clamp_cell(&self, l: usize, c: [i64; 2]) -> [i64; 2] {
        let n = self.cells(l);
        [c[0].clamp(0, n[0] - 1), c[1].clamp(0, n[1] - 1)]
    }

    /// Whether the level-`l` cell `c` (clamped into the domain) lies in `Ω_l`.
    pub fn in_region(&self, l: usize, c: [i64; 2]) -> bool {
        if l == 0 {
            return true;
        }
        if l >= self.levels() {
            return false;
        }
        let c = self.clamp_cell(l, c);
        self.refined[l - 1].contains(&[c[0] >> 1, c[1] >> 1])
    }

    fn support_in(&self, l: usize, f: [i64; 2]) -> bool {
        (0..4).all(|b| (0..4).all(|a| self.in_region(l, [f[0] + a, f[1] + b])))
    }

    /// Whether every level-`l` cell of the support of `f` (clamped into the domain) is
    /// refined, i.e. the support lies in `Ω_{l+1}`.
    fn support_refined(&self, l: usize, f: [i64; 2]) -> bool {
        l + 1 < self.levels()
            && (0..4).all(|b| {
                (0..4).all(|a| {
                    let c = self.clamp_cell(l, [f[0] + a, f[1] + b]);
                    self.refined[l].contains(&c)
                })
            })
    }

    /// Cells of `Ω_l` inside the domain, sorted.
    fn region_cells(&self, l: usize) -> Vec<[i64; 2]> {
        if l == 0 {
            let n = self.cells(0);
            return (0..n[1])
                .flat_map(|b| (0..n[0]).map(move |a| [a, b]))
                .collect();
        }
        let mut out: Vec<[i64; 2]> = self.refined[l - 1]
            .iter()
            .flat_map(|&[a, b]| {
                [
                    [2 * a, 2 * b],
                    [2 * a + 1, 2 * b],
                    [2 * a, 2 * b + 1],
                    [2 * a + 1, 2 * b + 1],
                ]
            })
            .collect();
        out.sort_unstable_by_key(|c| (c[1], c[0]));
        out
    }

    /// Kraft's selection, level by level, and the coefficient numbering.
    fn select(&mut self) {
        self.active.clear();
        self.index.clear();
        self.offset.clear();
        let mut offset = 0;
        for l in 0..self.levels() {
            let n = self.cells(l);
            let mut cand: BTreeSet<(i64, i64)> = BTreeSet::new();
            for [a, b] in self.region_cells(l) {
                for db in 0..4 {
                    for da in 0..4 {
                        let (i, j) = (a - da, b - db);
                        if i >= -3 && i < n[0] && j >= -3 && j < n[1] {
                            cand.insert((j, i));
                        }
                    }
                }
            }
            let act: Vec<[i64; 2]> = cand
                .into_iter()
                .map(|(j, i)| [i, j])
                .filter(|&f| self.support_in(l, f) && !self.support_refined(l, f))
                .collect();
            let map: CellMap = act
                .iter()
                .enumerate()
                .map(|(k, &f)| (f, (offset + k) as u32))
                .collect();
            self.offset.push(offset);
            offset += act.len();
            self.active.push(act);
            self.index.push(map);
        }
    }

    /// The leaf cell holding the parameter point `uv` (clamped into the domain).
    pub fn leaf_of(&self, uv: [f64; 2]) -> Leaf {
        let mut l = 0;
        loop {
            let h = self.spacing(l);
            let c = self.clamp_cell(l, [(uv[0] / h).floor() as i64, (uv[1] / h).floor() as i64]);
            if l + 1 < self.levels() && self.refined[l].contains(&c) {
                l += 1;
            } else {
                return Leaf {
                    level: l as u8,
                    cell: c,
                };
            }
        }
    }

    /// The functions nonzero on a leaf cell, coarse levels first.
    pub fn supports(&self, leaf: Leaf, out: &mut Vec<Support>) {
        out.clear();
        let lf = leaf.level as usize;
        for l in 0..=lf {
            let [a, b] = [leaf.cell[0] >> (lf - l), leaf.cell[1] >> (lf - l)];
            for dv in 0..4i64 {
                for du in 0..4i64 {
                    if let Some(&index) = self.index[l].get(&[a - 3 + du, b - 3 + dv]) {
                        out.push(Support {
                            index,
                            level: l as u8,
                            slot: (du + 4 * dv) as u8,
                        });
                    }
                }
            }
        }
    }

    /// The local basis of `leaf` at `uv` (clamped into the leaf's cell).
    pub fn local_basis(&self, leaf: Leaf, uv: [f64; 2], out: &mut LocalBasis) {
        let lf = leaf.level as usize;
        out.u.clear();
        out.v.clear();
        for l in 0..=lf {
            let h = self.spacing(l);
            let c = [leaf.cell[0] >> (lf - l), leaf.cell[1] >> (lf - l)];
            let piece = |x: f64, c: i64| {
                let s = (x / h - c as f64).clamp(0.0, 1.0);
                let [v, d, dd] = cubic(s);
                [v, d.map(|x| x / h), dd.map(|x| x / (h * h))]
            };
            out.u.push(piece(uv[0], c[0]));
            out.v.push(piece(uv[1], c[1]));
        }
    }

    /// Leaf cells inside the domain, sorted by level then `(b, a)`.
    pub fn leaves(&self) -> Vec<Leaf> {
        let mut out = Vec::new();
        for l in 0..self.levels() {
            for c in self.region_cells(l) {
                if l + 1 >= self.levels() || !self.refined[l].contains(&c) {
                    out.push(Leaf {
                        level: l as u8,
                        cell: c,
                    });
                }
            }
        }
        out
    }

    /// The surface `(S, S_u, S_v, S_uu, S_uv, S_vv)` at `uv` for coefficients `coef`.
    pub fn eval(&self, coef: &[[f64; 3]], uv: [f64; 2]) -> [[f64; 3]; 6] {
        let leaf = self.leaf_of(uv);
        let mut sup = Vec::new();
        let mut lb = LocalBasis::default();
        self.supports(leaf, &mut sup);
        self.local_basis(leaf, uv, &mut lb);
        let mut out = [[0.0; 3]; 6];
        for s in &sup {
            let d = lb.derivs(s);
            let c = coef[s.index as usize];
            for k in 0..6 {
                for x in 0..3 {
                    out[k][x] += d[k] * c[x];
                }
            }
        }
        out
    }

    /// Refines the regions around the given leaf cells (see the module docs). Leaves at
    /// `max_level` cannot be refined: they are returned. Returns also whether anything was
    /// refined.
    pub fn refine(&mut self, marked: &[Leaf], max_level: usize) -> (Vec<Leaf>, bool) {
        let mut missed = Vec::new();
        let mut changed = false;
        let levels = self.levels();
        for l in 0..levels {
            let mut cells: Vec<[i64; 2]> = Vec::new();
            for m in marked.iter().filter(|m| m.level as usize == l) {
                if l >= max_level {
                    missed.push(*m);
                } else {
                    cells.push(m.cell);
                }
            }
            if cells.is_empty() {
                continue;
            }
            let grown = self.grow_to_rectangles(l, &cells);
            if grown.is_empty() {
                continue;
            }
            if l + 1 >= self.levels() {
                self.refined.push(CellSet::default());
            }
            self.refined[l].extend(grown);
            changed = true;
        }
        missed.sort_unstable();
        if changed {
            self.select();
        }
        (missed, changed)
    }

    /// Level-`l` leaf cells to refine for the marked `cells`: one ring grown, bounding boxes
    /// of 8-connected components, clipped to the leaf cells; all leaf cells where that is
    /// more than half of them.
    fn grow_to_rectangles(&self, l: usize, cells: &[[i64; 2]]) -> Vec<[i64; 2]> {
        let leaf = |c: [i64; 2]| {
            let n = self.cells(l);
            c[0] >= 0
                && c[1] >= 0
                && c[0] < n[0]
                && c[1] < n[1]
                && self.in_region(l, c)
                && (l + 1 >= self.levels() || !self.refined[l].contains(&c))
        };
        let mut grown: BTreeSet<(i64, i64)> = BTreeSet::new();
        for &[a, b] in cells {
            for db in -1..=1 {
                for da in -1..=1 {
                    if leaf([a + da, b + db]) {
                        grown.insert((b + db, a + da));
                    }
                }
            }
        }
        // 8-connected components and their bounding boxes.
        let mut seen: BTreeSet<(i64, i64)> = BTreeSet::new();
        let mut out: BTreeSet<(i64, i64)> = BTreeSet::new();
        for &start in &grown {
            if !seen.insert(start) {
                continue;
            }
            let (mut lo, mut hi) = (start, start);
            let mut stack = vec![start];
            while let Some((b, a)) = stack.pop() {
                lo = (lo.0.min(b), lo.1.min(a));
                hi = (hi.0.max(b), hi.1.max(a));
                for db in -1..=1 {
                    for da in -1..=1 {
                        let n = (b + db, a + da);
                        if grown.contains(&n) && seen.insert(n) {
                            stack.push(n);
                        }
                    }
                }
            }
            for b in lo.0..=hi.0 {
                for a in lo.1..=hi.1 {
                    if leaf([a, b]) {
                        out.insert((b, a));
                    }
                }
            }
        }
        let total = self
            .region_cells(l)
            .into_iter()
            .filter(|&c| leaf(c))
            .count();
        if 2 * out.len() > total {
            return self
                .region_cells(l)
                .into_iter()
                .filter(|&c| leaf(c))
                .collect();
        }
        out.into_iter().map(|(b, a)| [a, b]).collect()
    }

    /// The surface as one tensor-product B-spline with clamped knots (module docs), its
    /// control points `coef[k] + origin`.
    pub fn to_tensor(&self, coef: &[[f64; 3]], origin: [f64; 3]) -> TensorSurface {
        self.to_tensor_rect(coef, origin, [0, 0], self.cells0)
    }

    /// The surface restricted to the rectangle of level-0 cells `[lo, hi)` as one clamped
    /// tensor-product B-spline, parameters unchanged (its domain is `[lo h₀, hi h₀]`). The
    /// pieces of neighbouring rectangles are the same spline, so they meet with the
    /// spline's own continuity (C2 where no knot is repeated).
    pub fn to_tensor_rect(
        &self,
        coef: &[[f64; 3]],
        origin: [f64; 3],
        lo: [i64; 2],
        hi: [i64; 2],
    ) -> TensorSurface {
        let fine = self.levels() - 1;
        let h = self.spacing(fine);
        let lo = [lo[0] << fine, lo[1] << fine];
        let hi = [hi[0] << fine, hi[1] << fine];
        // The functions nonzero inside the rectangle, in finest units.
        let touches = |l: usize, f: &[i64; 2]| {
            let s = fine - l;
            (0..2).all(|d| (f[d] << s) < hi[d] && ((f[d] + 4) << s) > lo[d])
        };
        let mut taus: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
        for d in 0..2 {
            let mut set: BTreeSet<i64> = BTreeSet::new();
            for (l, act) in self.active.iter().enumerate() {
                let shift = fine - l;
                for f in act.iter().filter(|f| touches(l, f)) {
                    for k in 0..5 {
                        set.insert((f[d] + k) << shift);
                    }
                }
            }
            set.insert(lo[d]);
            set.insert(hi[d]);
            let mut tau: Vec<f64> = set.into_iter().map(|k| k as f64).collect();
            for end in [lo[d] as f64, hi[d] as f64] {
                let at = tau.partition_point(|&x| x < end);
                tau.splice(at..at, [end, end]);
            }
            taus[d] = tau;
        }
        let n = [taus[0].len() - 4, taus[1].len() - 4];
        let mut net = vec![[0.0f64; 3]; n[0] * n[1]];
        let mut cache: [Expansions; 2] = [HashMap::new(), HashMap::new()];
        for (l, act) in self.active.iter().enumerate() {
            let shift = fine - l;
            for (k, f) in act.iter().enumerate() {
                if !touches(l, f) {
                    continue;
                }
                let c = coef[self.offset[l] + k];
                let mut alpha = |d: usize| {
                    cache[d]
                        .entry((l, f[d]))
                        .or_insert_with(|| {
                            let t: [f64; 5] =
                                std::array::from_fn(|m| ((f[d] + m as i64) << shift) as f64);
                            oslo(&t, &taus[d])
                        })
                        .clone()
                };
                let (fu, au) = alpha(0);
                let (fv, av) = alpha(1);
                for (jv, bv) in av.iter().enumerate() {
                    let row = (fv + jv) * n[0];
                    for (ju, bu) in au.iter().enumerate() {
                        let w = bu * bv;
                        let p = &mut net[row + fu + ju];
                        for x in 0..3 {
                            p[x] += w * c[x];
                        }
                    }
                }
            }
        }
        // Clamp: keep the functions from the one with three knots at the low end to the one
        // with three knots at the high end.
        let mut keep = [(0, 0); 2];
        let mut knots: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
        for d in 0..2 {
            let tau = &taus[d];
            let p0 = tau.partition_point(|&x| x < lo[d] as f64);
            let q0 = tau.partition_point(|&x| x < hi[d] as f64);
            keep[d] = (p0 - 1, q0 - 1);
            let mut k = Vec::with_capacity(q0 - p0 + 5);
            k.push(lo[d] as f64 * h);
            k.extend(tau[p0..q0 + 3].iter().map(|&x| x * h));
            k.push(hi[d] as f64 * h);
            knots[d] = k;
        }
        let count = [keep[0].1 - keep[0].0 + 1, keep[1].1 - keep[1].0 + 1];
        let mut ctrl = Vec::with_capacity(count[0] * count[1]);
        for jv in keep[1].0..=keep[1].1 {
            for ju in keep[0].0..=keep[0].1 {
                let p = net[ju + jv * n[0]];
                ctrl.push([p[0] + origin[0], p[1] + origin[1], p[2] + origin[2]]);
            }
        }
        TensorSurface {
            degree: [3, 3],
            knots,
            count,
            ctrl,
        }
    }
}

#[cfg(test)]
mod tests;
