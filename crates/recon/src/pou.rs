//! Partition-of-unity weights on the uniform leaf lattice, and the fixed point the tile field
//! is blended in (Schall, Belyaev & Seidel 2006, §3.3).
//!
//! Leaf `m` (an octree cell of `E` fine voxels) owns the tensor-product bump
//! `w_m(x) = Π_a b((x_a − c_a)/r)`, `b(u) = (1 − u²)²` for `|u| < 1`, centred at the cell
//! centre `c`, with half-width `r = E/2 + ov` (the cell plus an overlap of `ov` voxels on each
//! side). The blended detail at a node is `Σ_leaves w_m d_m / W`, where `W = Σ_all cells w_m`
//! runs over **every** cell of the lattice, leaf or not. Inside the union of leaves this is the
//! usual normalised partition of unity; towards cells that hold no points the detail fades
//! smoothly to zero, so the field falls back to the coarse global solve without a seam.
//!
//! `W` factorises per axis, so the normalised weights do too: [`leaf_weights`] gives them per
//! axis in [`WEIGHT_BITS`] = `B` bits, rounded so that the weights of the cells meeting at a
//! node sum to exactly `2^B` per axis ([`pou_weights`]): the integer blend then is an exact
//! partition of unity. Values enter the blend in fixed point: a power-of-two unit
//! ([`unit_for`], [`quantise`]) and 16-bit leaf details with a per-leaf exponent
//! ([`quantise_detail`]). The blend itself, its data ([`crate::types::Blend`]) and why the
//! CPU and GPU agree to the bit are in `types::field` and `extract::field`.

use crate::types::{Detail, MAX_SHIFT, VALUE_LIMIT, WEIGHT_BITS};

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

/// Per-axis weights of a leaf at detail offsets `s = 0..dm`, for cells of `e` voxels with
/// overlap `ov`: `bump(s)` (the cell's bump at offset `s − ov` from its first node) divided by
/// the sum of the bumps of all cells at that node, in [`WEIGHT_BITS`] bits, rounded so that
/// the cells' weights at every node sum to exactly `2^WEIGHT_BITS` (the largest absorbs the
/// rounding).
pub fn pou_weights(e: i64, ov: i64, bump: impl Fn(i64) -> f64) -> Vec<i32> {
    let dm = e + 2 * ov + 1;
    let one = 1i64 << WEIGHT_BITS;
    let mut q = vec![0i32; dm as usize];
    // The offsets that meet at one node: s ≡ o + ov (mod e).
    for o in 0..e {
        let group: Vec<i64> = (-1..=1)
            .map(|j| o + ov + j * e)
            .filter(|s| (0..dm).contains(s))
            .collect();
        let total: f64 = group.iter().map(|&s| bump(s)).sum();
        let Some(&first) = group.first() else {
            continue;
        };
        let mut sum = 0;
        let mut largest = first;
        for &s in &group {
            let v = (bump(s) / total * one as f64).round() as i64;
            q[s as usize] = v as i32;
            sum += v;
            if bump(s) > bump(largest) {
                largest = s;
            }
        }
        q[largest as usize] += (one - sum) as i32;
    }
    q
}

/// The power-of-two unit that puts `max_abs` at `2^21` units or below: 32 times that still
/// fits [`VALUE_LIMIT`].
pub fn unit_for(max_abs: f64) -> f32 {
    let m = if max_abs.is_finite() && max_abs > 0.0 {
        max_abs
    } else {
        1.0
    };
    let k = (m.log2().ceil() as i32 - 21).clamp(-100, 100);
    2f32.powi(k)
}

/// `v` in fixed point: `v / unit` rounded to the nearest integer (ties to even), clamped to
/// [`VALUE_LIMIT`] (NaN to 0).
pub fn quantise(v: &[f32], unit: f32) -> Vec<i32> {
    // Adding and taking away 1.5·2^52 rounds an f64 below 2^51 to an integer, ties to even,
    // in two instructions where `f64::round` is a library call on baseline x86-64.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let inv = 1.0 / unit as f64;
    let lim = VALUE_LIMIT as f64;
    v.iter()
        .map(|&x| (((x as f64 * inv).clamp(-lim, lim) + MAGIC) - MAGIC) as i32)
        .collect()
}

/// A leaf's detail grid in 16 bits: `round(v / (unit·2^shift))` with the smallest `shift`
/// (at most [`MAX_SHIFT`]) that fits the largest value in an `i16`, padded with one 0 to an
/// even length (the GPU reads two values a word). Details are corrections to the coarse
/// solution, small next to the coarse values that set `unit`, so most leaves keep `shift`
/// 0 and the same resolution as the coarse values; 16 bits halve what crosses the bus and
/// what the caches hold.
pub fn quantise_detail(v: &[f32], unit: f32) -> Detail {
    let fixed = quantise(v, unit);
    let max = fixed.iter().map(|x| x.unsigned_abs()).max().unwrap_or(0);
    let mut shift = 0;
    while shift < MAX_SHIFT && (max >> shift) > i16::MAX as u32 {
        shift += 1;
    }
    let half = if shift == 0 { 0 } else { 1i64 << (shift - 1) };
    let mut q: Vec<i16> = fixed
        .iter()
        .map(|&x| ((x as i64 + half) >> shift).clamp(-(i16::MAX as i64), i16::MAX as i64) as i16)
        .collect();
    if q.len() % 2 == 1 {
        q.push(0);
    }
    Detail { values: q, shift }
}

#[cfg(test)]
mod tests {
    use super::*;
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

    #[test]
    fn weights_are_a_partition_of_unity() {
        for (e, ov) in [(8, 2), (32, 8), (64, 16), (1024, 256)] {
            let q = leaf_weights(e, ov);
            assert_eq!(q.len() as i64, e + 2 * ov + 1);
            assert_eq!((q[0], q[q.len() - 1]), (0, 0));
            for g in 0..3 * e {
                // Every cell whose grid holds g.
                let sum: i32 = (-3..=3)
                    .map(|c| g - (e * c - ov))
                    .filter(|s| (0..q.len() as i64).contains(s))
                    .map(|s| q[s as usize])
                    .sum();
                assert_eq!(sum, 1 << WEIGHT_BITS, "e {e} node {g}");
            }
        }
    }

    #[test]
    fn details_keep_16_bits_at_the_smallest_exponent() {
        let u = unit_for(1.0);
        let Detail {
            values: q,
            shift: s,
        } = quantise_detail(&[0.001, -0.002, 0.0], u);
        assert_eq!(s, 0);
        assert_eq!(q, vec![2097, -4194, 0, 0]);
        let Detail {
            values: q,
            shift: s,
        } = quantise_detail(&[0.1, -0.05, 0.0001], u);
        assert_eq!(s, 3);
        assert_eq!(q[0] as i64 * 8, (0.1 / u as f64).round() as i64 / 8 * 8);
        assert!(q.iter().all(|v| v.unsigned_abs() <= i16::MAX as u16));
        // Beyond VALUE_LIMIT: clamped at the largest exponent.
        let d = quantise_detail(&[1e9, -1e9], u);
        assert_eq!((d.shift, d.values), (MAX_SHIFT, vec![i16::MAX, -i16::MAX]));
    }

    #[test]
    fn quantise_rounds_and_clamps() {
        let u = unit_for(1.0);
        assert_eq!(u, 2f32.powi(-21));
        assert_eq!(unit_for(3.0), 2f32.powi(-19));
        let q = quantise(&[0.5, -1.0, 1e9, f32::NAN, 1.4 * u, 2.5 * u, -2.5 * u], u);
        assert_eq!(q, vec![1 << 20, -(1 << 21), VALUE_LIMIT, 0, 1, 2, -2]);
    }
}
