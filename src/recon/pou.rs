//! Partition-of-unity weights on the uniform leaf lattice (Schall et al. 2006, §3.3).
//!
//! Leaf `m` (an octree cell of `E` fine voxels) owns the tensor-product bump
//! `w_m(x) = Π_a b((x_a − c_a)/r)`, `b(u) = (1 − u²)²` for `|u| < 1`, centred at the cell
//! centre `c`, with half-width `r = E/2 + ov` (the cell plus an overlap of `ov` voxels on each
//! side). The blended detail at a node is `Σ_leaves w_m d_m / W`, where `W = Σ_all cells w_m`
//! runs over **every** cell of the lattice, leaf or not. Inside the union of leaves this is the
//! usual normalised partition of unity; towards cells that hold no points the detail fades
//! smoothly to zero, so the field falls back to the coarse global solve without a seam.
//! `W` factorises per axis, so the normalised weights do too: [`leaf_weights`] gives them per
//! axis, in the fixed point of [`crate::extract::field`], which blends them.

use crate::extract::field::pou_weights;

/// The clamped overlap: `1 <= ov < e/2`. With no overlap every bump vanishes on the cell
/// faces and the weights would not cover them.
pub fn overlap(e: i64, ov: i64) -> i64 {
    ov.clamp(1, (e / 2 - 1).max(1))
}

/// The bump `b` of a cell of `e` voxels with overlap `ov` at offset `o` from its first node.
pub fn bump(e: i64, ov: i64, o: i64) -> f64 {
    let half = 0.5 * e as f64 + ov as f64;
    let u = (o as f64 - 0.5 * e as f64) / half;
    if u.abs() >= 1.0 {
        0.0
    } else {
        let t = 1.0 - u * u;
        t * t
    }
}

/// A leaf's per-axis weights at detail offsets `s = 0 ..= E + 2·ov` (node offset `s − ov`
/// from its first node), normalised over all cells and in fixed point
/// ([`pou_weights`]).
pub fn leaf_weights(e: i64, ov: i64) -> Vec<i32> {
    let ov = overlap(e, ov);
    pou_weights(e, ov, |s| bump(e, ov, s - ov))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::field::WEIGHT_BITS;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn weights_of_all_cells_sum_to_one(e in 4i64..80, ovf in 0.0f64..0.45, g in 0i64..400) {
            let ov = overlap(e, ((e as f64) * ovf) as i64);
            let q = leaf_weights(e, ov);
            let cell = g.div_euclid(e);
            let sum: i32 = (cell - 2..=cell + 2)
                .map(|m| g - (m * e - ov))
                .filter(|s| (0..q.len() as i64).contains(s))
                .map(|s| q[s as usize])
                .sum();
            prop_assert_eq!(sum, 1 << WEIGHT_BITS);
        }
    }

    #[test]
    fn vanishes_at_the_support_edge() {
        let q = leaf_weights(32, 8);
        assert_eq!((q[0], q[48]), (0, 0));
        // The centre of the cell has no neighbour's bump: all of the weight.
        assert_eq!(q[16 + 8], 1 << WEIGHT_BITS);
        assert!((bump(32, 8, 16) - 1.0).abs() < 1e-12);
    }
}
