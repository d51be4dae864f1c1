//! The screening term of the screened Poisson equation (Kazhdan & Hoppe, "Screened Poisson
//! surface reconstruction", 2013, §4): the samples, aggregated per voxel of the grid being
//! solved, as the point-evaluation operator `S` and its weights `γ`.
//!
//! The unscreened solve minimises `∫|∇χ − V|²`, which fixes χ only up to its gradient: the
//! Gaussian that smooths `V` and the trilinear splat both attenuate short wavelengths of the
//! surface, and nothing pulls the level set back to the samples. The screened energy adds
//! the values at the samples,
//!
//! ```text
//!     E(χ) = ∫|∇χ − V|² + Σ_a γ_a (χ(p_a) − c)²,
//! ```
//!
//! whose normal equations on the grid are `(L + Sᵀ Γ S) χ = b + Sᵀ Γ c`, with `L = −Δ` (the
//! spectral Laplacian of [`super::fft_solve`]), `b = −∇·V` and `S` trilinear interpolation
//! at the samples. `c` is the value the samples are pulled to; any constant gives the same
//! level set, and the solver takes the mean of the unscreened field at the samples so that
//! screening moves the surface, not the gauge.
//!
//! **Aggregates.** As PoissonRecon does at its coarser depths, the samples in one voxel are
//! replaced by one at their mean position, weighted by their count `w_a`: the operator then
//! has at most one row per occupied voxel whatever the number of points, which bounds the
//! memory of the coarse global solve by its grid, not by the scan.
//!
//! **Weights.** `γ_a = α · w_a / w̄ / h²`, with `w̄` the mean count per occupied voxel and
//! `h` the grid's spacing in cube units: the paper normalises its sum by the samples'
//! density (`Area(P)/Σ w`), and here every occupied voxel holds on average `α/h²`, the
//! same share of the Laplacian's diagonal (`6/h²`) at every depth and for any sampling
//! density. A surface undulation of `λ` voxels along the surface is then held to the samples
//! where `α λ / 2π` is large against 1: with α = 4 every wavelength the grid resolves
//! (PoissonRecon's default `--pointWeight 4` scales with the depth in the same way).
//!
//! The weight α and the noise it follows live in [`crate::weight`] and [`crate::noise`],
//! re-exported here.

use rayon::prelude::*;

use super::grid::LocalGrid;
use super::voxel_sum::{OnLattice, VoxelSum, screen_voxel};
use crate::types::{KeyMap, floor, wrap};

pub use crate::noise::*;
pub use crate::weight::*;

/// A voxel's aggregate: the sum of its samples' offsets in it (in voxels) and their count.
pub type Aggregate = ([f64; 3], u64);

/// One batch's aggregates kept apart from any builder ([`ScreenBuilder::part`]): per voxel
/// (`(z·n + y)·n + x`, ascending) the sum over the batch's samples in their order. The coarse
/// pass aggregates each store cell into its own part and adds the parts in cell order
/// ([`ScreenBuilder::add_parts`]), so that cells aggregated by other threads or shards give
/// the same operator (as [`super::fft_solve::SplatBox`] does for the splat).
pub type ScreenPart = Vec<(u64, Aggregate)>;

/// Bytes of one entry of a [`ScreenPart`].
pub const SCREEN_PART_ENTRY_BYTES: u64 = 40;

/// Samples gathered per voxel of a grid, before [`ScreenBuilder::finish`] weighs them.
pub struct ScreenBuilder {
    grid: LocalGrid,
    /// Per z-slab of the grid's voxels (`per` planes each, the last maybe fewer), per wrapped
    /// voxel (`(z·n + y)·n + x`): its [`Aggregate`]. Slabs take their samples in parallel
    /// ([`ScreenBuilder::add_parts`]).
    slabs: Vec<KeyMap<u64, Aggregate>>,
    per: usize,
    /// Instead of the maps, for a leaf's grid ([`ScreenBuilder::dense`]): the aggregates in
    /// the order their voxels were first met, and per voxel its aggregate's place plus one
    /// (0: none yet).
    dense: Option<DenseIndex>,
}

/// A dense builder's aggregates, in the order their voxels were first met, and per voxel of
/// the grid its aggregate's place plus one (0: none yet).
type DenseIndex = (Vec<(u64, Aggregate)>, Vec<u32>);

/// The wrapped voxel of `grid` holding `p` (world frame), as `(z·n + y)·n + x`, and `p`'s
/// offset in it (in voxels); `None` when the voxel lies outside planes `z0 .. z1` (known
/// from `z` alone, before the other axes are computed).
#[inline]
fn voxel_in(g: &LocalGrid, p: &[f64; 3], (z0, z1): (u64, u64)) -> Option<(u64, [f64; 3])> {
    let n = g.n as i64;
    let mut key = 0u64;
    let mut off = [0f64; 3];
    for a in (0..3).rev() {
        let u = (p[a] - g.origin[a]) / g.h;
        let fl = floor(u);
        off[a] = u - fl;
        let i = wrap(fl as i64, n) as u64;
        if a == 2 && (i < z0 || i >= z1) {
            return None;
        }
        key = key * g.n as u64 + i;
    }
    Some((key, off))
}

/// Every plane of a grid.
const ALL_PLANES: (u64, u64) = (0, u64::MAX);

/// Add a sample at offset `off` (`count` of them, their offsets summed) to `e`.
#[inline]
fn aggregate(e: &mut Aggregate, off: [f64; 3], count: u64) {
    for a in 0..3 {
        e.0[a] += off[a];
    }
    e.1 += count;
}

/// One map of a [`ScreenBuilder`]: the samples of `pos` whose voxel lies in planes
/// `z0 .. z1` added to `map`.
fn add_samples(
    g: &LocalGrid,
    map: &mut KeyMap<u64, Aggregate>,
    pos: &[[f64; 3]],
    (z0, z1): (u64, u64),
) {
    for p in pos {
        if let Some((key, off)) = voxel_in(g, p, (z0, z1)) {
            aggregate(map.entry(key).or_insert(([0.0; 3], 0)), off, 1);
        }
    }
}

/// The aggregate of voxel `key` in a dense builder's `list` (`slot`: its place plus one).
#[inline]
fn dense_entry<'a>(
    list: &'a mut Vec<(u64, Aggregate)>,
    slot: &mut [u32],
    key: u64,
) -> &'a mut Aggregate {
    let s = &mut slot[key as usize];
    if *s == 0 {
        list.push((key, ([0.0; 3], 0)));
        *s = list.len() as u32;
    }
    &mut list[*s as usize - 1].1
}

impl ScreenBuilder {
    /// No samples yet, on `grid`.
    pub fn new(grid: &LocalGrid) -> ScreenBuilder {
        ScreenBuilder::with_slabs(grid, 1)
    }

    /// No samples yet, on `grid`, its voxels split into `slabs` z-slabs that
    /// [`ScreenBuilder::add_parts`] fills in parallel (the same operator for any count).
    pub fn with_slabs(grid: &LocalGrid, slabs: usize) -> ScreenBuilder {
        let per = grid.n.div_ceil(slabs.clamp(1, grid.n.max(1)));
        ScreenBuilder {
            grid: *grid,
            slabs: (0..grid.n.div_ceil(per).max(1))
                .map(|_| KeyMap::default())
                .collect(),
            per,
            dense: None,
        }
    }

    /// No samples yet, on `grid`, gathered through an index of every voxel (4 bytes a node)
    /// instead of a hash map: for a leaf's grids, where the index is smaller than the splat
    /// beside it (12 bytes a node) and is dropped before the solve, which peaks higher. The
    /// hash map's lookups were a thirteenth of the leaf stage (100M points, depth 11). The
    /// same aggregates, summed in the same order, as [`ScreenBuilder::new`].
    pub fn dense(grid: &LocalGrid) -> ScreenBuilder {
        ScreenBuilder {
            dense: Some((Vec::new(), vec![0; grid.len()])),
            ..ScreenBuilder::with_slabs(grid, 1)
        }
    }

    /// The planes `z0 .. z1` of slab `s`, `per` planes a slab.
    fn planes(per: usize, s: usize) -> (u64, u64) {
        ((s * per) as u64, ((s + 1) * per) as u64)
    }

    /// Add the samples at `pos` (world frame).
    pub fn add(&mut self, pos: &[[f64; 3]]) {
        if let Some((list, slot)) = &mut self.dense {
            for p in pos {
                if let Some((key, off)) = voxel_in(&self.grid, p, ALL_PLANES) {
                    aggregate(dense_entry(list, slot, key), off, 1);
                }
            }
            return;
        }
        for (s, map) in self.slabs.iter_mut().enumerate() {
            add_samples(&self.grid, map, pos, Self::planes(self.per, s));
        }
    }

    /// The aggregates of the samples at `pos` (world frame) on `grid`, apart from any
    /// builder ([`ScreenPart`]).
    pub fn part(grid: &LocalGrid, pos: &[[f64; 3]]) -> ScreenPart {
        let mut map = KeyMap::default();
        add_samples(grid, &mut map, pos, ALL_PLANES);
        let mut part: ScreenPart = map.into_iter().collect();
        part.sort_unstable_by_key(|e| e.0);
        part
    }

    /// Add the parts `parts` ([`ScreenBuilder::part`], on this builder's grid) in order, the
    /// slabs in parallel (on the pool it runs in): each voxel takes the parts' aggregates in
    /// the parts' order, whatever the slabs.
    pub fn add_parts(&mut self, parts: &[&[(u64, Aggregate)]]) {
        if let Some((list, slot)) = &mut self.dense {
            for &(key, (sum, count)) in parts.iter().copied().flatten() {
                aggregate(dense_entry(list, slot, key), sum, count);
            }
            return;
        }
        let (plane, per) = ((self.grid.n * self.grid.n) as u64, self.per);
        self.slabs.par_iter_mut().enumerate().for_each(|(s, map)| {
            let (z0, z1) = Self::planes(per, s);
            for part in parts {
                // Keys ascend, and a slab's keys are a range of them.
                let from = part.partition_point(|e| e.0 < z0 * plane);
                let to = part.partition_point(|e| e.0 < z1.saturating_mul(plane));
                for &(key, (sum, count)) in &part[from..to] {
                    aggregate(map.entry(key).or_insert(([0.0; 3], 0)), sum, count);
                }
            }
        });
    }

    /// Add the samples summed per voxel of a level's lattice ([`VoxelSum`]), this builder's
    /// grid placed on it by `on`: the same aggregates as their points give, up to rounding.
    pub fn add_voxels(&mut self, on: OnLattice, voxels: &[VoxelSum]) {
        let n = self.grid.n as u64;
        for s in voxels {
            let (v, off) = screen_voxel(self.grid.n, on, s);
            let key = (v[2] as u64 * n + v[1] as u64) * n + v[0] as u64;
            let e = match &mut self.dense {
                Some((list, slot)) => dense_entry(list, slot, key),
                None => self.slabs[v[2] / self.per]
                    .entry(key)
                    .or_insert(([0.0; 3], 0)),
            };
            aggregate(e, off, s.count as u64);
        }
    }

    /// Bytes the builder holds: one map entry per occupied voxel.
    pub fn bytes(&self) -> u64 {
        match &self.dense {
            Some((list, slot)) => {
                list.capacity() as u64 * VOXEL_ENTRY_BYTES + 4 * slot.len() as u64
            }
            None => self.slabs.iter().map(|m| m.capacity() as u64).sum::<u64>() * VOXEL_ENTRY_BYTES,
        }
    }

    /// The screening operator with weight `alpha` (see the module docs).
    pub fn finish(self, alpha: f64) -> Screen {
        let g = self.grid;
        let mut voxels: Vec<(u64, Aggregate)> = match self.dense {
            Some((list, _)) => list,
            None => self.slabs.into_iter().flatten().collect(),
        };
        voxels.sort_unstable_by_key(|v| v.0);
        let total: u64 = voxels.iter().map(|v| v.1.1).sum();
        let mut s = Screen {
            nodes: Vec::with_capacity(voxels.len()),
            weights: Vec::with_capacity(voxels.len()),
            gamma: Vec::with_capacity(voxels.len()),
        };
        if total == 0 || alpha <= 0.0 {
            return s;
        }
        let h_u = g.h / g.unit;
        // γ_a = α · w_a / w̄ / h², w̄ = total / occupied.
        let per_sample = alpha * voxels.len() as f64 / total as f64 / (h_u * h_u);
        let n = g.n as u64;
        for (key, (sum, count)) in voxels {
            let v = [key % n, (key / n) % n, key / (n * n)];
            let mut at = [[0usize; 2]; 3];
            let mut w = [[0f32; 2]; 3];
            for a in 0..3 {
                let f = (sum[a] / count as f64) as f32;
                at[a] = [v[a] as usize, ((v[a] + 1) % n) as usize];
                w[a] = [1.0 - f, f];
            }
            let mut nodes = [0u32; 8];
            let mut weights = [0f32; 8];
            for c in 0..8usize {
                let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
                nodes[c] = ((at[2][dz] * g.n + at[1][dy]) * g.n + at[0][dx]) as u32;
                weights[c] = w[0][dx] * w[1][dy] * w[2][dz];
            }
            s.nodes.push(nodes);
            s.weights.push(weights);
            s.gamma.push(per_sample * count as f64);
        }
        s
    }
}

/// Bytes of one occupied voxel in a [`ScreenBuilder`]'s map (key, sums, count, and the map's
/// own overhead), and then in a [`Screen`].
pub const VOXEL_ENTRY_BYTES: u64 = 64;

/// The screening operator: per aggregate, its 8 grid nodes, their trilinear weights and its
/// weight `γ_a`.
#[derive(Debug, Default)]
pub struct Screen {
    nodes: Vec<[u32; 8]>,
    weights: Vec<[f32; 8]>,
    gamma: Vec<f64>,
}

impl Screen {
    /// The operator of the samples `pos` on `grid` with weight `alpha`.
    pub fn from_points(grid: &LocalGrid, pos: &[[f64; 3]], alpha: f64) -> Screen {
        let mut b = ScreenBuilder::new(grid);
        if alpha > 0.0 {
            b.add(pos);
        }
        b.finish(alpha)
    }

    /// True when nothing is screened (no samples, or a zero weight).
    pub fn is_empty(&self) -> bool {
        self.gamma.is_empty()
    }

    /// Number of aggregates.
    pub fn len(&self) -> usize {
        self.gamma.len()
    }

    /// `Σ γ_a`.
    pub fn gamma_sum(&self) -> f64 {
        self.gamma.iter().sum()
    }

    /// The weights `γ_a`.
    pub fn gamma(&self) -> &[f64] {
        &self.gamma
    }

    /// Each aggregate's 8 grid nodes.
    pub fn nodes(&self) -> &[[u32; 8]] {
        &self.nodes
    }

    /// Each aggregate's trilinear weights, by node.
    pub fn weights(&self) -> &[[f32; 8]] {
        &self.weights
    }

    /// `S v`: the grid values `v` interpolated at each aggregate.
    pub fn gather(&self, v: &[f32]) -> Vec<f64> {
        self.nodes
            .iter()
            .zip(&self.weights)
            .map(|(nodes, w)| {
                nodes
                    .iter()
                    .zip(w)
                    .map(|(&j, &wj)| wj as f64 * v[j as usize] as f64)
                    .sum()
            })
            .collect()
    }

    /// `out += Sᵀ coef`: each aggregate's `coef` spread over its nodes by its weights, in
    /// aggregate order (the same sums for any thread count).
    pub fn scatter_add(&self, coef: &[f64], out: &mut [f32]) {
        for ((nodes, w), &c) in self.nodes.iter().zip(&self.weights).zip(coef) {
            for (&j, &wj) in nodes.iter().zip(w) {
                out[j as usize] += (c * wj as f64) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests;
