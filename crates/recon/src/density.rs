//! Sampling-density weights: each sample's normal stands for the surface area around it, so
//! that the indicator function jumps by the same amount wherever the scan is dense or sparse.
//!
//! **Why.** The normal field `V = Σ_s n_s K(· − s)` approximates `∫_∂M n dA` only when the
//! samples are uniform; otherwise `V` is that integral weighted by the sampling density, and
//! the indicator `χ` solved from it jumps across the surface by an amount proportional to the
//! local density. One iso-value (the mean of `χ` at the samples) then sits near the dense
//! parts' half-jump, which is above a part sampled 16 times more sparsely: such a part sinks
//! inward and breaks up, or vanishes (measured: a sphere whose half is 16× sparser than the
//! other, depth 8, sank by 7 voxels into 76 pieces; a small sphere sampled 40× more densely
//! beside a large one took the large one's whole surface away). Kazhdan, Bolitho and Hoppe,
//! "Poisson surface reconstruction" (SGP 2006), §4.3 "Non-uniform samples": estimate the
//! density `W(q) = Σ_s K̃(q − s)` with a kernel wider than the solve's and weigh each sample's
//! contribution by `1/W(s)`, so that `V` integrates area again.
//!
//! **Here.** `W` is splatted onto the nodes of a grid over the cube with the coarse solve's
//! spacing (`r` fine voxels, `r >= 4`: PoissonRecon splats its density two levels above the
//! finest, four voxels, likewise) with the quadratic B-spline, and read back at each sample
//! with the same kernel. A trilinear kernel would be cheaper, but on a surface between two
//! node layers at fraction `f` it reads `(1 − f)² + f²` of the density, so uniform samples
//! would weigh up to twice as much where the surface runs midway between layers; with the
//! quadratic B-spline the sum of squared weights varies by 16% at most, and the weights of a
//! uniformly sampled sphere stay within 0.94 and 1.08 (a unit test).
//! A sample's weight is `A_s = W̄ / W(s)`, where `W̄ = Σ_j W_j² / Σ_j W_j` over the nodes is
//! the sample-weighted mean density, so uniform samples keep weights near 1 and the screening
//! weight and every field scale keep their meaning; `A_s` is clamped to
//! [`1/MAX_WEIGHT`, `MAX_WEIGHT`]. **Outliers**: an isolated sample's density is all its own
//! kernel, so `W̄/W(s)` would make it stand for a whole patch of surface (measured: 5%
//! uniform outliers around a 100k-point sphere at depth 8 grew 348 blobs). So a sample is
//! scaled up only as far as it has company: with `ν = W(s) / (its own kernel's share)`
//! samples around it (itself included), the cap rises linearly from 1 at `ν = 1.25` to
//! `MAX_WEIGHT` at `ν = 2.5` ([`LONE`]); the same outliers then leave 4 specks of 0.007
//! square units in all (PoissonRecon: 18 pieces, 2.9 square units). The normal field, in the coarse solve
//! and in every leaf solve, is built from `A_s n_s`; the screening term and the iso-value
//! keep one weight per sample (as with `--confidence`).
//!
//! **Exact.** The splat adds each sample's B-spline weights as integers (1/256 steps,
//! saturating), so the grid, and every weight read from it, is the same whatever the order of
//! the cells, the thread count or the shard count.
//!
//! **Memory**: 4 bytes a node, `(N/r + 1)³` nodes: as many as the coarse solution, beside
//! which it is held through the leaf and tile passes (the plan charges it).

use rayon::prelude::*;

use crate::types::{Cube, round_index};

/// The largest factor by which a sample's normal is scaled up (or down): density contrasts
/// up to this ratio are fully compensated (module docs).
pub const MAX_WEIGHT: f64 = 16.0;

/// Below this many samples around it (itself included, in the kernel's measure) a sample is
/// not scaled up; at twice as many the cap is [`MAX_WEIGHT`] (module docs).
pub const LONE: f64 = 1.25;

/// Fixed-point steps of one sample's splat.
const ONE: f64 = 256.0;

/// `∫ B²` of the quadratic B-spline: the mean of `Σ_k b_k²` over a surface's offsets from the
/// nodes ([`DensityGrid::sample_spacing`]).
const B_SQUARED_MEAN: f64 = 11.0 / 20.0;

/// One batch's splat kept apart from the grid ([`DensityGrid::part`]): the nodes
/// `lo ..= lo + dims − 1` its kernels reach, x fastest. A split run's shards splat their
/// store cells into parts and every shard adds them all up ([`DensityGrid::add_parts`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DensityBox {
    /// The box's lowest node.
    pub lo: [usize; 3],
    /// Nodes per axis.
    pub dims: [usize; 3],
    /// Per node, x fastest, in 1/256 steps.
    pub counts: Vec<u32>,
}

impl DensityBox {
    /// Bytes of the counts.
    pub fn bytes(&self) -> u64 {
        4 * self.counts.len() as u64
    }
}

/// Sampling density on the nodes of a grid over the cube (module docs).
#[derive(Debug, Clone)]
pub struct DensityGrid {
    origin: [f64; 3],
    inv_h: f64,
    /// Nodes per axis.
    n: usize,
    /// Splatted samples, in 1/256 steps.
    counts: Vec<u32>,
    /// `W̄` in the same units, once [`DensityGrid::finish`] has run.
    mean: f64,
}

impl DensityGrid {
    /// Bytes of the grid over a cube of `cells` voxels per edge.
    pub fn bytes(cells: u64) -> u64 {
        (cells + 1).pow(3) * 4
    }

    /// An empty grid over `cube`, of `cells` voxels per edge.
    pub fn new(cube: &Cube, cells: u64) -> DensityGrid {
        let n = cells as usize + 1;
        DensityGrid::of_counts(cube, cells, vec![0; n * n * n])
    }

    /// The grid over `cube` of `cells` voxels per edge holding `counts` (of its length),
    /// not finished.
    fn of_counts(cube: &Cube, cells: u64, counts: Vec<u32>) -> DensityGrid {
        DensityGrid {
            origin: cube.origin,
            inv_h: cells as f64 / cube.size,
            n: cells as usize + 1,
            counts,
            mean: 0.0,
        }
    }

    /// Along axis `a`: the three nodes around coordinate `x` (clamped into the grid) and
    /// their quadratic B-spline weights (they sum to 1).
    #[inline(always)]
    fn axis(&self, x: f64, a: usize) -> ([usize; 3], [f64; 3]) {
        let top = self.n - 1;
        let u = ((x - self.origin[a]) * self.inv_h).clamp(0.0, top as f64);
        let c = round_index(u);
        let t = u - c as f64;
        let w = [
            0.5 * (0.5 - t) * (0.5 - t),
            0.75 - t * t,
            0.5 * (0.5 + t) * (0.5 + t),
        ];
        ([c.saturating_sub(1), c, (c + 1).min(top)], w)
    }

    /// The 27 nodes around `p` with their quadratic B-spline weights (clamped into the
    /// grid; they sum to 1).
    #[cfg(test)]
    #[inline]
    fn support(&self, p: [f64; 3]) -> [(usize, f64); 27] {
        let [(a0, w0), (a1, w1), (a2, w2)] = [0, 1, 2].map(|a| self.axis(p[a], a));
        let n = self.n;
        std::array::from_fn(|c| {
            let (i, j, k) = (c % 3, c / 3 % 3, c / 9);
            let idx = (a2[k] * n + a1[j]) * n + a0[i];
            (idx, w0[i] * w1[j] * w2[k])
        })
    }

    /// Splat the samples `pos`.
    pub fn add(&mut self, pos: &[[f64; 3]]) {
        let part = self.part(pos);
        self.add_parts(&[&part]);
    }

    /// The grid's geometry without its counts: [`DensityGrid::part`]s computed beside the
    /// grid they are added to.
    pub fn layout(&self) -> DensityGrid {
        DensityGrid {
            counts: Vec::new(),
            ..*self
        }
    }

    /// The splat of the samples `pos` apart from the grid ([`DensityBox`]).
    pub fn part(&self, pos: &[[f64; 3]]) -> DensityBox {
        if pos.is_empty() {
            return DensityBox::default();
        }
        let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
        for p in pos {
            for a in 0..3 {
                let (at, _) = self.axis(p[a], a);
                lo[a] = lo[a].min(at[0]);
                hi[a] = hi[a].max(at[2]);
            }
        }
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut counts = vec![0u32; dims[0] * dims[1] * dims[2]];
        for p in pos {
            let [(a0, w0), (a1, w1), (a2, w2)] = [0, 1, 2].map(|a| self.axis(p[a], a));
            // As [`DensityGrid::support`] weighs them (the clamped nodes repeat).
            for c in 0..27 {
                let (i, j, k) = (c % 3, c / 3 % 3, c / 9);
                let q = round_index(w0[i] * w1[j] * w2[k] * ONE) as u32;
                let at = ((a2[k] - lo[2]) * dims[1] + a1[j] - lo[1]) * dims[0] + a0[i] - lo[0];
                counts[at] = counts[at].saturating_add(q);
            }
        }
        DensityBox { lo, dims, counts }
    }

    /// Add the parts `parts` ([`DensityGrid::part`] of this grid), in parallel over z-slabs
    /// of the grid (one a thread of the pool it runs in). The counts are integers added with
    /// saturation, never negative: the same grid in any order, for any number of slabs and
    /// however the samples were split into parts.
    pub fn add_parts(&mut self, parts: &[&DensityBox]) {
        let n = self.n;
        let slab = n * n;
        let per = n.div_ceil(rayon::current_num_threads().max(1)).max(1);
        self.counts
            .par_chunks_mut(per * slab)
            .enumerate()
            .for_each(|(s, chunk)| {
                let (z0, z1) = (s * per, s * per + chunk.len() / slab);
                for b in parts {
                    let [dx, dy, dz] = b.dims;
                    for bz in (0..dz).filter(|&k| (z0..z1).contains(&(b.lo[2] + k))) {
                        for by in 0..dy {
                            let row = ((b.lo[2] + bz - z0) * n + b.lo[1] + by) * n + b.lo[0];
                            let from = &b.counts[(bz * dy + by) * dx..][..dx];
                            for (c, &q) in chunk[row..row + dx].iter_mut().zip(from) {
                                *c = c.saturating_add(q);
                            }
                        }
                    }
                }
            });
    }

    /// The counts (for a checkpoint).
    pub fn counts(&self) -> &[u32] {
        &self.counts
    }

    /// The grid over `cube` of `cells` voxels per edge holding `counts` (a checkpoint's),
    /// finished; `None` when they are not that grid's.
    pub fn with_counts(cube: &Cube, cells: u64, counts: Vec<u32>) -> Option<DensityGrid> {
        let n = cells as usize + 1;
        if counts.len() != n * n * n {
            return None;
        }
        let mut g = DensityGrid::of_counts(cube, cells, counts);
        g.finish();
        Some(g)
    }

    /// Compute `W̄` once every sample is splatted.
    pub fn finish(&mut self) {
        let (mut s1, mut s2) = (0u128, 0u128);
        for &c in &self.counts {
            s1 += u128::from(c);
            s2 += u128::from(c) * u128::from(c);
        }
        self.mean = if s1 > 0 { s2 as f64 / s1 as f64 } else { 0.0 };
    }

    /// The typical distance between neighbouring samples along the surface, in input units,
    /// from `W̄` (`None` before [`DensityGrid::finish`] or without samples).
    ///
    /// Samples spread over a surface at `ρ` a voxel of this grid's area splat, on the nodes
    /// across it, `256 ρ` times the quadratic B-spline's weights `b_k` (summing to 1), so
    /// `W̄ = 256 ρ Σ b_k²`; over the surface's offsets from the nodes `Σ b_k²` averages
    /// `∫ B² = 11/20` (0.5 to 0.59). The spacing is then `h/√ρ`, `h` the grid's spacing
    /// (a unit test checks it within 10% on a sphere).
    pub fn sample_spacing(&self) -> Option<f64> {
        let rho = self.mean / (ONE * B_SQUARED_MEAN);
        (rho > 0.0).then(|| 1.0 / (self.inv_h * rho.sqrt()))
    }

    /// The weight `A_s` of a sample at `p` (module docs).
    pub fn weight(&self, p: [f64; 3]) -> f64 {
        // The kernel is a product over the axes, so both sums are too.
        let [(a0, w0), (a1, w1), (a2, w2)] = [0, 1, 2].map(|a| self.axis(p[a], a));
        let n = self.n;
        let mut d = 0.0;
        for k in 0..3 {
            let mut dk = 0.0;
            for j in 0..3 {
                let row = &self.counts[(a2[k] * n + a1[j]) * n..];
                let dj = w0[0] * f64::from(row[a0[0]])
                    + w0[1] * f64::from(row[a0[1]])
                    + w0[2] * f64::from(row[a0[2]]);
                dk += w1[j] * dj;
            }
            d += w2[k] * dk;
        }
        let sq = |w: [f64; 3]| w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
        let own = sq(w0) * sq(w1) * sq(w2) * ONE;
        if d <= 0.0 || self.mean <= 0.0 {
            return 1.0;
        }
        // Samples around, counting this one: an isolated sample (an outlier) has about 1 and
        // is not scaled up; from `LONE` to twice that the cap rises to `MAX_WEIGHT`.
        let around = d / own;
        let cap = 1.0 + (MAX_WEIGHT - 1.0) * ((around - LONE) / LONE).clamp(0.0, 1.0);
        (self.mean / d).clamp(1.0 / MAX_WEIGHT, cap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> Cube {
        Cube {
            origin: [0.0; 3],
            size: 1.0,
        }
    }

    /// Samples on the plane z = 0.5, `per_axis²` of them over x in `[x0, x1)`.
    fn plane(x0: f64, x1: f64, per_axis: usize) -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        for i in 0..per_axis {
            for j in 0..per_axis {
                let x = x0 + (x1 - x0) * (i as f64 + 0.5) / per_axis as f64;
                v.push([x, (j as f64 + 0.5) / per_axis as f64, 0.5]);
            }
        }
        v
    }

    #[test]
    fn parts_add_the_counts_of_one_pass_for_any_thread_count() {
        // Tilted planes in three batches, one spanning the cube's whole height.
        let mut pts = plane(0.1, 0.9, 120);
        for (i, p) in pts.iter_mut().enumerate() {
            p[2] = 0.05 + 0.9 * p[0] * (1.0 + (i % 7) as f64 * 0.01);
        }
        let batches: Vec<&[[f64; 3]]> = vec![&pts[..5000], &pts[5000..5001], &pts[5001..]];
        let mut want = DensityGrid::new(&unit(), 32);
        for b in &batches {
            for p in *b {
                for (i, w) in want.support(*p) {
                    want.counts[i] += round_index(w * ONE) as u32;
                }
            }
        }
        for threads in [1, 2, 5, 16] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut got = DensityGrid::new(&unit(), 32);
            let parts: Vec<DensityBox> = batches.iter().map(|b| got.part(b)).collect();
            let parts: Vec<&DensityBox> = parts.iter().collect();
            pool.install(|| got.add_parts(&parts));
            assert!(got.counts == want.counts, "{threads} threads");
        }
    }

    /// `n` samples spread uniformly (a Fibonacci lattice) over the sphere of radius 0.3
    /// about the unit cube's centre.
    fn fibonacci_sphere(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let z = 1.0 - (2 * i + 1) as f64 / n as f64;
                let r = (1.0 - z * z).sqrt();
                let a = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                [
                    0.5 + 0.3 * r * a.cos(),
                    0.5 + 0.3 * r * a.sin(),
                    0.5 + 0.3 * z,
                ]
            })
            .collect()
    }

    #[test]
    fn uniform_samples_weigh_one_and_a_sparser_half_weighs_its_ratio() {
        // A uniformly sampled sphere (a Fibonacci lattice): every weight near 1, whatever
        // the surface's slant through the grid.
        let n = 40_000;
        let sphere = fibonacci_sphere(n);
        let mut g = DensityGrid::new(&unit(), 16);
        g.add(&sphere);
        g.finish();
        let w: Vec<f64> = sphere.iter().map(|p| g.weight(*p)).collect();
        let (lo, hi) = w
            .iter()
            .fold((f64::MAX, 0f64), |(a, b), &x| (a.min(x), b.max(x)));
        let mean = w.iter().sum::<f64>() / n as f64;
        assert!(
            (mean - 1.0).abs() < 0.01 && lo > 0.9 && hi < 1.1,
            "{lo} {mean} {hi}"
        );
        // The left half 9 times sparser (in area) than the right.
        let mut g = DensityGrid::new(&unit(), 16);
        g.add(&plane(0.0, 0.5, 100 / 3));
        g.add(&plane(0.5, 1.0, 100));
        g.finish();
        let (l, r) = (g.weight([0.2, 0.5, 0.5]), g.weight([0.8, 0.5, 0.5]));
        assert!((l / r - 9.0).abs() < 0.5, "{l} {r}");
        // Most samples are the dense half's: weights near 1 there (less at the plane's
        // edges, where the density falls off).
        assert!((r - 1.0).abs() < 0.25, "{r}");
        // An outlier far from everything is not scaled up: its density is its own.
        let mut g2 = g.clone();
        g2.add(&[[0.5, 0.5, 0.95]]);
        g2.finish();
        assert_eq!(g2.weight([0.5, 0.5, 0.95]), 1.0);
    }

    #[test]
    fn the_sample_spacing_is_read_from_the_density() {
        // Fibonacci spheres of radius 0.3: `n` samples over `4π 0.09` square units, so
        // neighbouring samples lie `√(area / n)` apart. Dense and sparse against the grid,
        // on coarse and fine grids: within 10%.
        assert_eq!(DensityGrid::new(&unit(), 16).sample_spacing(), None);
        for (n, cells) in [(40_000, 16), (40_000, 64), (2_000, 64), (200_000, 32)] {
            let sphere = fibonacci_sphere(n);
            let mut g = DensityGrid::new(&unit(), cells);
            g.add(&sphere);
            g.finish();
            let want = (4.0 * std::f64::consts::PI * 0.09 / n as f64).sqrt();
            let got = g.sample_spacing().unwrap();
            assert!(
                (got / want - 1.0).abs() < 0.1,
                "{n} on {cells}: {got} {want}"
            );
        }
    }

    #[test]
    fn the_grid_is_the_same_in_any_order_and_split() {
        let pts = plane(0.1, 0.9, 50);
        let mut a = DensityGrid::new(&unit(), 8);
        a.add(&pts);
        let mut b = DensityGrid::new(&unit(), 8);
        let mut rev = pts.clone();
        rev.reverse();
        let (x, y) = rev.split_at(777);
        b.add(y);
        b.add(x);
        assert_eq!(a.counts, b.counts);
        // Points on the cube's far faces stay inside the grid.
        a.add(&[[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]);
        assert_eq!(DensityGrid::bytes(8), a.counts.len() as u64 * 4);
    }
}
