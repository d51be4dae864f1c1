//! Evaluating a tile's field ([`crate::types::Blend`], whose docs define it) on the CPU, bit
//! for bit the same as the GPU (`gpu/shaders/field.wgsl`), so that leaf grids rather than dense
//! tiles cross the bus.
//!
//! # Why both sides agree to the bit
//!
//! The blend is done in integers: values are fixed point in a power-of-two `unit`, details in
//! 16 bits of `unit·2^shift` per leaf, the partition-of-unity weights in
//! [`WEIGHT_BITS`] = `B` bits per axis (recon makes them; Schall, Belyaev & Seidel 2006, §3.3).
//! A node's field is the exact 64-bit integer
//!
//! ```text
//! N = ((Σ_corners w·c) << (3B − 3k)  +  Σ_leaves q_z·q_y·q_x·d) >> 3B
//! ```
//!
//! clamped to `|N| <` [`FIELD_LIMIT`] `+ 1 = 2^24`, and `F = N · unit` in `f32`, both exact.
//! Integer sums do not depend on order, and there is no float rounding for a compiler or a GPU
//! to do differently: WGSL lets `fma` round twice and lets a compiler contract `a·b + c`
//! (Mesa's lavapipe was seen to do both, for some nodes and not others), and its division is
//! not correctly rounded. Values are bounded by [`crate::types::VALUE_LIMIT`], so the sums
//! stay below `2^58`. The GPU side needs 64-bit integers in shaders
//! (`wgpu::Features::SHADER_INT64`); where an adapter lacks them, tiles are blended on the
//! host, here.

use crate::error::{Error, Result};
use crate::types::{Blend, FIELD_LIMIT, Leaf, WEIGHT_BITS};

/// The CPU evaluation of a [`Blend`] (an extension trait: the data lives in `types`, which
/// crosses stages, and its evaluation here, in the stage that uses it).
pub trait BlendEval {
    /// The field on the block's nodes, x fastest.
    ///
    /// All sums are integer sums modulo 2^64, so their order does not matter: the coarse part
    /// is interpolated one axis at a time (x, then y, then z: 2 products a node instead of 8
    /// of 3), and then each leaf adds its detail row by row. Peak scratch: the node
    /// accumulator (8 bytes a node) plus the two partial interpolations, which are smaller
    /// than a third of it for `r ≥ 4`; then the accumulator and the output (12 bytes a node).
    ///
    /// # Panics
    ///
    /// When the blend does not pass [`Blend::validate`] (an index leaves its table): a caller
    /// bug. [`BlendEval::try_eval`] checks first.
    fn eval(&self) -> Vec<f32>;

    /// [`BlendEval::eval`] after [`Blend::validate`]: [`Error::Internal`] naming what is wrong
    /// instead of a panic.
    fn try_eval(&self) -> Result<Vec<f32>>;
}

impl BlendEval for Blend<'_> {
    fn eval(&self) -> Vec<f32> {
        let mut acc = coarse_part(self);
        for leaf in &self.leaves {
            add_leaf(self, leaf, &mut acc);
        }
        let unit = self.unit;
        acc.iter()
            .map(|&a| (a >> (3 * WEIGHT_BITS)).clamp(-FIELD_LIMIT, FIELD_LIMIT) as f32 * unit)
            .collect()
    }

    fn try_eval(&self) -> Result<Vec<f32>> {
        self.validate()
            .map_err(|e| Error::Internal(format!("tile field: {e}")))?;
        Ok(self.eval())
    }
}

/// Add `leaf`'s weighted detail to the accumulator `acc` of [`BlendEval::eval`], over the
/// block nodes its grid covers.
fn add_leaf(b: &Blend, leaf: &Leaf, acc: &mut [i64]) {
    let [nx, ny, _] = b.dims;
    let dm = b.dm() as i64;
    let dmu = dm as usize;
    // Detail offset of block node p: lo + p − (E·cell − ov).
    let base = [0, 1, 2].map(|a| b.lo[a] - (b.e * leaf.cell[a] - b.ov));
    let p0 = [0, 1, 2].map(|a| (-base[a]).max(0));
    let p1 = [0, 1, 2].map(|a| (dm - 1 - base[a]).min(b.dims[a] as i64 - 1));
    if (0..3).any(|a| p0[a] > p1[a]) {
        return;
    }
    let sx0 = (base[0] + p0[0]) as usize;
    let len = (p1[0] - p0[0] + 1) as usize;
    let wx = &b.own[sx0..sx0 + len];
    for pz in p0[2]..=p1[2] {
        let sz = (base[2] + pz) as usize;
        let wz = b.own[sz] as i64;
        for py in p0[1]..=p1[1] {
            let sy = (base[1] + py) as usize;
            let wzy = wz * b.own[sy] as i64;
            if wzy == 0 {
                continue;
            }
            let d0 = (sz * dmu + sy) * dmu + sx0;
            let d = &leaf.detail[d0..d0 + len];
            let a0 = (pz as usize * ny + py as usize) * nx + p0[0] as usize;
            // wx · v fits 27 bits; times wzy · 2^shift, 58 bits.
            let row_w = wzy << leaf.shift;
            for ((r, &w), &v) in acc[a0..a0 + len].iter_mut().zip(wx).zip(d) {
                let wv = w * v as i32;
                *r = r.wrapping_add(row_w.wrapping_mul(wv as i64));
            }
        }
    }
}

/// The coarse part of [`BlendEval::eval`]'s accumulator: the trilinear interpolation of the
/// coarse values at every node, scaled by `2^coarse_shift` to the weights' fixed point.
fn coarse_part(b: &Blend) -> Vec<i64> {
    let [nx, ny, nz] = b.dims;
    let [ax, ay, az] = &b.axes;
    let [cx, cy, cz] = b.coarse_dims;
    // Along x, for every coarse (z, y) row.
    let mut along_x = vec![0i64; cz * cy * nx];
    for (row, out) in along_x.chunks_exact_mut(nx).enumerate() {
        let c = &b.coarse[row * cx..(row + 1) * cx];
        for (x, o) in out.iter_mut().enumerate() {
            let i = ax.c0[x] as usize;
            *o = (ax.w0[x] as i64 * c[i] as i64).wrapping_add(ax.w1[x] as i64 * c[i + 1] as i64);
        }
    }
    // Along y, for every coarse z.
    let mut along_y = vec![0i64; cz * ny * nx];
    for (zy, out) in along_y.chunks_exact_mut(nx).enumerate() {
        let (zc, y) = (zy / ny, zy % ny);
        let r0 = (zc * cy + ay.c0[y] as usize) * nx;
        let (w0, w1) = (ay.w0[y] as i64, ay.w1[y] as i64);
        let (a, b) = (&along_x[r0..r0 + nx], &along_x[r0 + nx..r0 + 2 * nx]);
        for ((o, &a), &b) in out.iter_mut().zip(a).zip(b) {
            *o = w0.wrapping_mul(a).wrapping_add(w1.wrapping_mul(b));
        }
    }
    drop(along_x);
    // Along z, at every node.
    let shift = b.coarse_shift();
    let mut acc = vec![0i64; nx * ny * nz];
    for (zy, out) in acc.chunks_exact_mut(nx).enumerate() {
        let (z, y) = (zy / ny, zy % ny);
        let r0 = (az.c0[z] as usize * ny + y) * nx;
        let r1 = r0 + ny * nx;
        let (w0, w1) = (az.w0[z] as i64, az.w1[z] as i64);
        let (a, b) = (&along_y[r0..r0 + nx], &along_y[r1..r1 + nx]);
        for ((o, &a), &b) in out.iter_mut().zip(a).zip(b) {
            *o = w0
                .wrapping_mul(a)
                .wrapping_add(w1.wrapping_mul(b))
                .wrapping_shl(shift);
        }
    }
    acc
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::types::{Axis, Detail, MAX_SHIFT};
    use rand::{Rng, SeedableRng};

    /// The fixed-point unit of the random blends: coarse values in ±1 are within `2^21` units.
    const UNIT_BITS: i32 = 21;

    /// Owned storage behind a random [`Blend`]: fixed-point leaf details and coarse values.
    /// Built here from integers, without recon's quantisation; its weights are a partition of
    /// unity with linear ramps over the overlap ([`RandomBlend::ramp_weights`]), recon's are bumps.
    pub(crate) struct RandomBlend {
        pub lo: [i64; 3],
        pub dims: [usize; 3],
        pub e: i64,
        pub ov: i64,
        pub r: i64,
        pub unit: f32,
        pub coarse_full: Vec<i32>,
        pub coarse_n: usize,
        pub details: Vec<([i64; 3], Detail)>,
        /// Per-axis leaf weights at detail offsets ([`RandomBlend::ramp_weights`] unless a
        /// test puts others here).
        pub own: Vec<i32>,
    }

    impl RandomBlend {
        /// A block at `lo` of `dims` nodes on a lattice of leaves of `e` voxels (overlap
        /// `e/4`, coarse ratio `e/8`), with leaves at about `fill` of the cells near the
        /// block and random values (coarse in ±1, details in ±0.1, at exponents 3 to 5).
        pub(crate) fn new(seed: u64, lo: [i64; 3], dims: [usize; 3], e: i64, fill: f64) -> Self {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let ov = e / 4;
            let r = e / 8;
            let dm = (e + 2 * ov + 1) as usize;
            let n = dm * dm * dm;
            let one = 1i32 << UNIT_BITS;
            let hi = [0, 1, 2].map(|a| lo[a] + dims[a] as i64 - 1);
            let coarse_n = ((hi.iter().max().copied().unwrap_or(0) + 2 * e) / r + 2) as usize;
            let coarse_full: Vec<i32> = (0..coarse_n.pow(3))
                .map(|_| rng.random_range(-one..=one))
                .collect();
            let mut details = Vec::new();
            let c0 = lo.map(|v| ((v - ov) / e - 1).max(0));
            let c1 = hi.map(|v| (v + ov) / e + 1);
            for z in c0[2]..=c1[2] {
                for y in c0[1]..=c1[1] {
                    for x in c0[0]..=c1[0] {
                        if rng.random_bool(fill) {
                            let shift = rng.random_range(3..=5u32);
                            let m = (one / 10) >> shift;
                            let mut values: Vec<i16> =
                                (0..n).map(|_| rng.random_range(-m..=m) as i16).collect();
                            if n % 2 == 1 {
                                values.push(0);
                            }
                            details.push(([x, y, z], Detail { values, shift }));
                        }
                    }
                }
            }
            RandomBlend {
                lo,
                dims,
                e,
                ov,
                r,
                unit: 2f32.powi(-UNIT_BITS),
                coarse_full,
                coarse_n,
                details,
                own: Self::ramp_weights(e, ov),
            }
        }

        /// Per-axis weights at detail offsets `0..dm`: 0 to `2^B` linearly over the first
        /// `2·ov` offsets, `2^B` over the cell, and the complement of the neighbour's ramp over
        /// the last `2·ov`, so the cells' weights at a node sum to exactly `2^B`. A test may
        /// put other weights in [`RandomBlend::own`] (recon's bumps, in the pipeline's tests).
        pub(crate) fn ramp_weights(e: i64, ov: i64) -> Vec<i32> {
            let one = 1i64 << WEIGHT_BITS;
            let w = 2 * ov;
            let up = |s: i64| (one * s / w).min(one);
            (0..e + w + 1)
                .map(|s| if s < e { up(s) } else { one - up(s - e) } as i32)
                .collect()
        }

        pub(crate) fn blend(&self) -> Blend<'_> {
            let mut axes: [Axis; 3] = Default::default();
            let mut cmin = [0usize; 3];
            let mut cdims = [0usize; 3];
            for a in 0..3 {
                let first = (self.lo[a] / self.r) as usize;
                let last = ((self.lo[a] + self.dims[a] as i64 - 1) / self.r) as usize + 1;
                cmin[a] = first;
                cdims[a] = last - first + 1;
                for p in 0..self.dims[a] as i64 {
                    let g = self.lo[a] + p;
                    let ax = &mut axes[a];
                    ax.c0.push((g / self.r) as u32 - first as u32);
                    ax.w0.push((self.r - g % self.r) as i32);
                    ax.w1.push((g % self.r) as i32);
                }
            }
            let n = self.coarse_n;
            let mut coarse = Vec::new();
            for z in 0..cdims[2] {
                for y in 0..cdims[1] {
                    for x in 0..cdims[0] {
                        let (gx, gy, gz) = (x + cmin[0], y + cmin[1], z + cmin[2]);
                        coarse.push(self.coarse_full[(gz * n + gy) * n + gx]);
                    }
                }
            }
            Blend {
                lo: self.lo,
                dims: self.dims,
                axes,
                coarse,
                coarse_dims: cdims,
                coarse_bits: self.r.trailing_zeros(),
                e: self.e,
                ov: self.ov,
                own: self.own.clone(),
                unit: self.unit,
                leaves: self
                    .details
                    .iter()
                    .enumerate()
                    .map(|(i, (c, d))| Leaf {
                        cell: *c,
                        id: i as u64,
                        detail: &d.values,
                        shift: d.shift,
                    })
                    .collect(),
            }
        }

        /// The field at block node `p` in f64, from the definition: trilinear coarse values
        /// plus every leaf's detail times its weight `q_z·q_y·q_x / 2^(3B)`.
        pub(crate) fn reference(&self, p: [usize; 3]) -> f64 {
            let g = [0, 1, 2].map(|a| self.lo[a] + p[a] as i64);
            let n = self.coarse_n;
            let u = self.unit as f64;
            let mut c = 0.0;
            for k in 0..8 {
                let d = [k & 1, (k >> 1) & 1, k >> 2];
                let mut w = 1.0;
                let mut i = [0usize; 3];
                for a in 0..3 {
                    let f = (g[a] % self.r) as f64 / self.r as f64;
                    w *= if d[a] == 1 { f } else { 1.0 - f };
                    i[a] = (g[a] / self.r) as usize + d[a];
                }
                c += w * self.coarse_full[(i[2] * n + i[1]) * n + i[0]] as f64 * u;
            }
            let dm = self.e + 2 * self.ov + 1;
            let q = &self.own;
            let one = (1u64 << WEIGHT_BITS) as f64;
            let mut acc = 0.0;
            for (cell, Detail { values: d, shift }) in &self.details {
                let u = u * 2f64.powi(*shift as i32);
                let s = [0, 1, 2].map(|a| g[a] - (self.e * cell[a] - self.ov));
                if s.iter().all(|&v| (0..dm).contains(&v)) {
                    let w: f64 = (0..3).map(|a| q[s[a] as usize] as f64 / one).product();
                    acc += w * d[((s[2] * dm + s[1]) * dm + s[0]) as usize] as f64 * u;
                }
            }
            c + acc
        }
    }

    #[test]
    fn blend_matches_the_definition() {
        for (seed, lo, dims, e) in [
            (1, [0, 0, 0], [33, 33, 33], 32),
            (2, [64, 32, 96], [65, 17, 40], 32),
            (3, [40, 8, 0], [20, 30, 50], 16),
        ] {
            let rb = RandomBlend::new(seed, lo, dims, e, 0.6);
            let b = rb.blend();
            b.validate().unwrap();
            let f = b.eval();
            assert_eq!(b.try_eval().unwrap(), f);
            let mut worst = 0f64;
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let v = f[(z * dims[1] + y) * dims[0] + x] as f64;
                        worst = worst.max((v - rb.reference([x, y, z])).abs());
                    }
                }
            }
            // Exact but for the final shift, which rounds down to a whole unit.
            assert!(worst <= rb.unit as f64, "seed {seed}: off by {worst}");
        }
    }

    #[test]
    fn the_test_weights_are_a_partition_of_unity() {
        let rb = RandomBlend::new(0, [0; 3], [2; 3], 32, 0.0);
        let q = &rb.own;
        let e = rb.e;
        assert_eq!((q[0], q[q.len() - 1]), (0, 0));
        for g in 0..3 * e {
            let sum: i32 = (-3..=3)
                .map(|c| g - (e * c - rb.ov))
                .filter(|s| (0..q.len() as i64).contains(s))
                .map(|s| q[s as usize])
                .sum();
            assert_eq!(sum, 1 << WEIGHT_BITS, "node {g}");
        }
    }

    #[test]
    fn leaf_order_does_not_matter() {
        let rb = RandomBlend::new(4, [32, 0, 16], [40, 41, 42], 32, 0.7);
        let b = rb.blend();
        let mut r = b.clone();
        r.leaves.reverse();
        let (x, y) = (b.eval(), r.eval());
        assert!(x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()));
    }

    /// [`Blend::validate`] lives with the data in `types`; its test needs this module's
    /// random blends.
    #[test]
    fn validate_names_what_is_wrong() {
        let rb = RandomBlend::new(5, [0, 0, 0], [9, 9, 9], 16, 0.5);
        let mut b = rb.blend();
        b.own.pop();
        assert!(b.validate().unwrap_err().contains("weights"));
        assert!(matches!(b.try_eval(), Err(Error::Internal(_))));
        let mut b = rb.blend();
        b.own[0] = 1;
        assert!(b.validate().unwrap_err().contains("both ends"));
        let mut b = rb.blend();
        b.axes[1].c0[3] = 1000;
        assert!(b.validate().unwrap_err().contains("axis 1"));
        assert!(matches!(b.try_eval(), Err(Error::Internal(_))));
        let mut b = rb.blend();
        b.axes[2].w1[1] += 1;
        assert!(b.validate().unwrap_err().contains("sum"));
        let mut b = rb.blend();
        assert!(b.leaves.len() > 1, "the test blend has several leaves");
        b.leaves[1].cell = b.leaves[0].cell;
        assert!(b.validate().unwrap_err().contains("one cell"));
        let mut b = rb.blend();
        b.leaves[0].shift = MAX_SHIFT + 1;
        assert!(b.validate().unwrap_err().contains("exponent"));
        let mut b = rb.blend();
        b.unit = 0.3;
        assert!(b.validate().unwrap_err().contains("power of two"));
    }

    /// The tile field across stages: recon's partition-of-unity weights (bumps normalised
    /// over the cells meeting at a node, Schall, Belyaev & Seidel 2006 §3.3) blended by
    /// extract's integer evaluation give the field of the definition.
    #[test]
    fn blend_with_recon_weights_matches_the_definition() {
        use crate::pou;
        use crate::types::WEIGHT_BITS;
        let one = (1u64 << WEIGHT_BITS) as f64;
        for (seed, lo, dims, e) in [
            (1, [0, 0, 0], [33, 33, 33], 32),
            (2, [64, 32, 96], [65, 17, 40], 32),
            (3, [40, 8, 0], [20, 30, 50], 16),
        ] {
            let mut rb = RandomBlend::new(seed, lo, dims, e, 0.6);
            rb.own = pou::leaf_weights(rb.e, rb.ov);
            // The integer weights are the normalised bumps to within their rounding.
            let (e, ov) = (rb.e, rb.ov);
            let total = |o: i64| -> f64 { (-2..=2).map(|m| pou::bump(e, ov, o - m * e)).sum() };
            for (s, &q) in rb.own.iter().enumerate() {
                let o = s as i64 - ov;
                let want = pou::bump(e, ov, o) / total(o.rem_euclid(e));
                assert!((q as f64 / one - want).abs() <= 1.0 / one, "offset {s}");
            }
            let f = rb.blend().try_eval().unwrap();
            let mut worst = 0f64;
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let v = f[(z * dims[1] + y) * dims[0] + x] as f64;
                        worst = worst.max((v - rb.reference([x, y, z])).abs());
                    }
                }
            }
            // Exact but for the final shift, which rounds down to a whole unit.
            assert!(worst <= rb.unit as f64, "seed {seed}: off by {worst}");
        }
    }
}
