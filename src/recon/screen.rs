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

use std::collections::HashMap;

use super::fft_solve::LocalGrid;

/// Samples gathered per voxel of a grid, before [`ScreenBuilder::finish`] weighs them.
pub struct ScreenBuilder {
    grid: LocalGrid,
    /// Per wrapped voxel (`(z·n + y)·n + x`): the sum of the samples' offsets in the voxel
    /// (in voxels) and their count.
    voxels: HashMap<u64, ([f64; 3], u64)>,
}

impl ScreenBuilder {
    /// No samples yet, on `grid`.
    pub fn new(grid: &LocalGrid) -> ScreenBuilder {
        ScreenBuilder {
            grid: *grid,
            voxels: HashMap::new(),
        }
    }

    /// Add the samples at `pos` (world frame).
    pub fn add(&mut self, pos: &[[f64; 3]]) {
        let g = &self.grid;
        let n = g.n as i64;
        for p in pos {
            let mut key = 0u64;
            let mut off = [0f64; 3];
            for a in (0..3).rev() {
                let u = (p[a] - g.origin[a]) / g.h;
                let fl = u.floor();
                off[a] = u - fl;
                key = key * g.n as u64 + (fl as i64).rem_euclid(n) as u64;
            }
            let e = self.voxels.entry(key).or_insert(([0.0; 3], 0));
            for a in 0..3 {
                e.0[a] += off[a];
            }
            e.1 += 1;
        }
    }

    /// Bytes the builder holds: one map entry per occupied voxel.
    pub fn bytes(&self) -> u64 {
        self.voxels.capacity() as u64 * VOXEL_ENTRY_BYTES
    }

    /// The screening operator with weight `alpha` (see the module docs).
    pub fn finish(self, alpha: f64) -> Screen {
        let g = self.grid;
        let mut voxels: Vec<(u64, ([f64; 3], u64))> = self.voxels.into_iter().collect();
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
mod tests {
    use super::*;

    fn grid() -> LocalGrid {
        LocalGrid {
            n: 8,
            h: 0.5,
            origin: [-2.0; 3],
            unit: 4.0,
        }
    }

    #[test]
    fn samples_of_one_voxel_become_one_aggregate_at_their_mean() {
        let g = grid();
        // Two samples in voxel (4, 4, 4) and one in voxel (1, 4, 4).
        let pos = [[0.1, 0.1, 0.1], [0.3, 0.2, 0.4], [-1.4, 0.2, 0.2]];
        let s = Screen::from_points(&g, &pos, 2.0);
        assert_eq!(s.len(), 2);
        // A linear function is interpolated exactly at the aggregates' mean positions.
        let f = |i: usize| {
            let (x, y, z) = (i % 8, (i / 8) % 8, i / 64);
            (x + 2 * y + 3 * z) as f32
        };
        let v: Vec<f32> = (0..512).map(f).collect();
        let at = s.gather(&v);
        let u =
            |p: [f64; 3]| (p[0] + 2.0) / 0.5 + 2.0 * (p[1] + 2.0) / 0.5 + 3.0 * (p[2] + 2.0) / 0.5;
        let mean = [0.2, 0.15, 0.25];
        assert!((at[0] - u([-1.4, 0.2, 0.2])).abs() < 1e-5, "{at:?}");
        assert!((at[1] - u(mean)).abs() < 1e-5, "{at:?}");
        // Weights: α/h² (cube units) per sample over the mean count, so the sum is
        // α/h² per occupied voxel.
        let h_u = 0.5 / 4.0;
        assert!((s.gamma_sum() - 2.0 * 2.0 / (h_u * h_u)).abs() < 1e-9);
        assert!((s.gamma()[1] / s.gamma()[0] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn scatter_is_the_transpose_of_gather() {
        let g = grid();
        let pos: Vec<[f64; 3]> = (0..40)
            .map(|i| {
                let t = i as f64 * 0.37;
                [t.sin() * 1.7, (1.3 * t).cos() * 1.7, (0.7 * t).sin() * 1.9]
            })
            .collect();
        let s = Screen::from_points(&g, &pos, 1.0);
        let u: Vec<f32> = (0..512).map(|i| ((i * 37) % 19) as f32 - 9.0).collect();
        let c: Vec<f64> = (0..s.len()).map(|a| (a as f64 * 0.61).sin()).collect();
        // ⟨S u, c⟩ = ⟨u, Sᵀ c⟩.
        let lhs: f64 = s.gather(&u).iter().zip(&c).map(|(a, b)| a * b).sum();
        let mut st = vec![0f32; 512];
        s.scatter_add(&c, &mut st);
        let rhs: f64 = u.iter().zip(&st).map(|(a, b)| *a as f64 * *b as f64).sum();
        assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} {rhs}");
    }

    #[test]
    fn a_zero_weight_screens_nothing() {
        assert!(Screen::from_points(&grid(), &[[0.0; 3]], 0.0).is_empty());
    }
}
