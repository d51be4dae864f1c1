//! Partition-of-unity weights on the uniform leaf lattice (Schall et al. 2006, §3.3).
//!
//! Leaf `m` (an octree cell of `E` fine voxels) owns the tensor-product bump
//! `w_m(x) = Π_a b((x_a − c_a)/r)`, `b(u) = (1 − u²)²` for `|u| < 1`, centred at the cell
//! centre `c`, with half-width `r = E/2 + ov` (the cell plus an overlap of `ov` voxels on each
//! side). The blended detail at a node is `Σ_leaves w_m d_m / W`, where `W = Σ_all cells w_m`
//! runs over **every** cell of the lattice, leaf or not. Inside the union of leaves this is the
//! usual normalised partition of unity; towards cells that hold no points the detail fades
//! smoothly to zero, so the field falls back to the coarse global solve without a seam.
//! `W` factorises per axis into a function of the node's offset within its cell.

/// Weights of one lattice axis, for `E` voxels per cell and an overlap of `ov` voxels.
#[derive(Debug, Clone)]
pub struct Bump {
    /// Cell edge in voxels.
    pub e: i64,
    /// Overlap in voxels.
    pub ov: i64,
    /// `b((o − E/2)/r)` for offsets `o = −ov ..= E + ov` from the cell's first node.
    own: Vec<f32>,
    /// `Σ_m b(...)` over all cells, for offsets `0 ..= E - 1` within a cell.
    total: Vec<f32>,
}

impl Bump {
    /// Weights for cells of `e` voxels with overlap `ov`, clamped to `1 <= ov < e/2`: with no
    /// overlap every bump vanishes on the cell faces and the weights would not cover them.
    pub fn new(e: i64, ov: i64) -> Bump {
        let ov = ov.clamp(1, (e / 2 - 1).max(1));
        let half = 0.5 * e as f64 + ov as f64;
        let b = |x: f64| {
            let u = x / half;
            if u.abs() >= 1.0 {
                0.0
            } else {
                let t = 1.0 - u * u;
                t * t
            }
        };
        let own = (-ov..=e + ov)
            .map(|o| b(o as f64 - 0.5 * e as f64) as f32)
            .collect();
        let total = (0..e)
            .map(|o| {
                (-1..=1)
                    .map(|m| b(o as f64 - (m * e) as f64 - 0.5 * e as f64))
                    .sum::<f64>() as f32
            })
            .collect();
        Bump { e, ov, own, total }
    }

    /// Weight of a cell at node offset `o` from its first node (`−ov ..= E + ov`, else 0).
    #[inline]
    pub fn own(&self, o: i64) -> f32 {
        if o < -self.ov || o > self.e + self.ov {
            0.0
        } else {
            self.own[(o + self.ov) as usize]
        }
    }

    /// The sum of all cells' weights at global node coordinate `g` (one axis).
    #[inline]
    pub fn total(&self, g: i64) -> f32 {
        self.total[g.rem_euclid(self.e) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn total_is_the_sum_of_every_cells_weight(e in 4i64..80, ovf in 0.0f64..0.45, g in -200i64..200) {
            let b = Bump::new(e, ((e as f64) * ovf) as i64);
            let cell = g.div_euclid(e);
            let sum: f32 = (cell - 2..=cell + 2).map(|m| b.own(g - m * e)).sum();
            prop_assert!((sum - b.total(g)).abs() < 1e-5);
            prop_assert!(b.total(g) > 0.0);
        }
    }

    #[test]
    fn vanishes_at_the_support_edge() {
        let b = Bump::new(32, 8);
        assert_eq!(b.own(-8), 0.0);
        assert_eq!(b.own(40), 0.0);
        assert!((b.own(16) - 1.0).abs() < 1e-6);
    }
}
