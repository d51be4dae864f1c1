//! A tile's field as a partition-of-unity blend, evaluated bit for bit the same on the CPU
//! ([`Blend::eval`]) and on the GPU (`shaders/field.wgsl`,
//! [`super::GpuExtractor::extract_blend`]), so that leaf grids rather than dense tiles cross
//! the bus.
//!
//! # The field
//!
//! The two-level scheme of `notes/adfft.md` (Schall, Belyaev & Seidel 2006, §3.3, on a coarse
//! global solve): at fine node `g` the field is
//!
//! ```text
//! F(g) = C(g) + Σ_m w_m(g) d_m(g)
//! ```
//!
//! - `C` is the coarse solution, trilinear between coarse nodes `r = 2^k` fine voxels apart:
//!   per axis a lower coarse node `c0` and integer weights `w0 = r − f`, `w1 = f` ([`Axis`]).
//! - `d_m` is the detail grid of leaf `m`: `dm = E + 2·ov + 1` nodes per axis starting at
//!   global node `E·cell − ov`, weighted by `w_m = q[s_z]·q[s_y]·q[s_x] / 2^(3B)` with `s` the
//!   node's offset in that grid. `q` is the leaf's bump (`(1 − u²)²` over the cell and its
//!   overlap) divided by the sum of the bumps of all cells of the lattice at that node, per
//!   axis, and rounded to [`WEIGHT_BITS`] = `B` bits so that the cells' weights at a node sum
//!   to exactly `2^B` per axis ([`pou_weights`]): the weights of all cells, leaf or not, are a
//!   partition of unity, so the detail fades to zero towards cells without points and the
//!   field falls back to the coarse solve without a seam.
//!
//! # Why both sides agree to the bit
//!
//! The blend is done in integers: values are fixed point in a power-of-two `unit`
//! ([`unit_for`], [`quantise`]; details in 16 bits of `unit·2^shift` per leaf,
//! [`quantise_detail`]), a node's field is the exact 64-bit integer
//!
//! ```text
//! N = ((Σ_corners w·c) << (3B − 3k)  +  Σ_leaves q_z·q_y·q_x·d) >> 3B
//! ```
//!
//! clamped to `|N| < 2^24`, and `F = N · unit` in `f32`, both exact. Integer sums do not
//! depend on order, and there is no float rounding for a compiler or a GPU to do differently:
//! WGSL lets `fma` round twice and lets a compiler contract `a·b + c` (Mesa's lavapipe was
//! seen to do both, for some nodes and not others), and its division is not correctly
//! rounded. Values are bounded by [`VALUE_LIMIT`], so the sums stay below `2^58`. The GPU side
//! needs 64-bit integers in shaders (`wgpu::Features::SHADER_INT64`); where an adapter lacks
//! them, tiles are blended on the host.

/// Bits of the per-axis partition-of-unity weights: each axis's weights at a node sum to
/// `2^WEIGHT_BITS`.
pub const WEIGHT_BITS: u32 = 10;

/// Largest magnitude of a fixed-point value (coarse or detail); larger ones are clamped.
pub const VALUE_LIMIT: i32 = 1 << 26;

/// Largest exponent of a leaf's 16-bit details: `2^15 · 2^11` is [`VALUE_LIMIT`].
pub const MAX_SHIFT: u32 = 11;

/// Largest magnitude of a node's fixed-point field: below `2^24`, so `f32` holds it exactly.
pub const FIELD_LIMIT: i64 = (1 << 24) - 1;

/// Per-axis tables of a block, one entry per block node along the axis.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Axis {
    /// Index, in the block's coarse sub-grid, of the lower coarse node.
    pub c0: Vec<u32>,
    /// Weight of the lower coarse node (`r − f`).
    pub w0: Vec<i32>,
    /// Weight of the upper coarse node (`f`).
    pub w1: Vec<i32>,
}

/// A leaf's detail grid.
#[derive(Debug, Clone, Copy)]
pub struct Leaf<'a> {
    /// The leaf's cell on the leaf lattice (its grid starts at global node `E·cell − ov`).
    pub cell: [i64; 3],
    /// A name for the GPU's cache of leaf grids: the same id must mean the same detail for the
    /// life of a [`super::GpuExtractor`] (or until [`super::GpuExtractor::forget_leaves`]).
    pub id: u64,
    /// `dm³` values, x fastest, then one 0 if `dm³` is odd ([`quantise_detail`]): in units of
    /// `unit·2^shift`.
    pub detail: &'a [i16],
    /// The leaf's exponent (at most [`MAX_SHIFT`]).
    pub shift: u32,
}

/// One block's blended field; see the [module docs](self).
#[derive(Debug, Clone)]
pub struct Blend<'a> {
    /// Global node of the block's node 0 (nodes are non-negative).
    pub lo: [i64; 3],
    /// Nodes per axis.
    pub dims: [usize; 3],
    /// Per-axis tables, `dims[a]` entries each.
    pub axes: [Axis; 3],
    /// The fixed-point coarse values the block reads, x fastest, `coarse_dims` per axis.
    pub coarse: Vec<i32>,
    /// Nodes per axis of `coarse`.
    pub coarse_dims: [usize; 3],
    /// `k` of the coarse spacing `r = 2^k` fine voxels (at most [`WEIGHT_BITS`]).
    pub coarse_bits: u32,
    /// Leaf cell edge in fine voxels.
    pub e: i64,
    /// Detail overlap in fine voxels (`1 <= ov < e/2`).
    pub ov: i64,
    /// Weight at detail offset `s`, `dm` entries, 0 at both ends ([`pou_weights`]; the GPU
    /// skips the ends).
    pub own: Vec<i32>,
    /// The fixed-point unit, a power of two ([`unit_for`]).
    pub unit: f32,
    /// The leaves whose grids meet the block (any order).
    pub leaves: Vec<Leaf<'a>>,
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

/// A leaf's detail grid in 16 bits ([`quantise_detail`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Detail {
    /// The values in units of `unit·2^shift`, padded to an even length.
    pub values: Vec<i16>,
    /// The exponent.
    pub shift: u32,
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
        let mut sum = 0;
        let mut largest = group[0];
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

impl Blend<'_> {
    /// Detail nodes per axis.
    pub fn dm(&self) -> usize {
        (self.e + 2 * self.ov + 1) as usize
    }

    /// Nodes of the block.
    pub fn nodes(&self) -> usize {
        self.dims.iter().product()
    }

    /// Shift of the coarse sum before the leaves are added: `3B − 3k`.
    pub fn coarse_shift(&self) -> u32 {
        3 * (WEIGHT_BITS - self.coarse_bits)
    }

    /// Check the tables against each other: sizes, indices and weights in range. The GPU
    /// path relies on it.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let dm = self.dm();
        if self.e < 4 || self.ov < 1 || 2 * self.ov >= self.e {
            return Err(format!("leaf edge {} with overlap {}", self.e, self.ov));
        }
        if self.own.len() != dm
            || self
                .own
                .iter()
                .any(|&q| !(0..=1 << WEIGHT_BITS).contains(&q))
            || self.own[0] != 0
            || self.own[dm - 1] != 0
        {
            return Err(format!(
                "{} weights for {dm} detail nodes, out of 0..=2^{WEIGHT_BITS}, or not 0 at \
                 both ends",
                self.own.len()
            ));
        }
        if self
            .lo
            .iter()
            .any(|&v| !(0..i32::MAX as i64 / 2).contains(&v))
            || self.dims.contains(&0)
        {
            return Err(format!("block at {:?} of {:?} nodes", self.lo, self.dims));
        }
        if self.coarse.len() != self.coarse_dims.iter().product::<usize>() {
            return Err("coarse values do not match their dimensions".into());
        }
        if self.coarse_bits > WEIGHT_BITS {
            return Err(format!("coarse spacing 2^{}", self.coarse_bits));
        }
        if !(self.unit.is_normal() && self.unit.to_bits() & 0x007f_ffff == 0) {
            return Err(format!("unit {} is not a power of two", self.unit));
        }
        let r = 1i32 << self.coarse_bits;
        for a in 0..3 {
            let ax = &self.axes[a];
            let n = self.dims[a];
            if [ax.c0.len(), ax.w0.len(), ax.w1.len()] != [n; 3] {
                return Err(format!("axis {a}: tables of the wrong length"));
            }
            if ax.c0.iter().any(|&c| c as usize + 1 >= self.coarse_dims[a]) {
                return Err(format!("axis {a}: coarse index out of the sub-grid"));
            }
            if ax
                .w0
                .iter()
                .zip(&ax.w1)
                .any(|(&u, &v)| u < 0 || v < 0 || u + v != r)
            {
                return Err(format!("axis {a}: coarse weights do not sum to {r}"));
            }
        }
        let n = dm * dm * dm;
        if self.leaves.iter().any(|l| l.detail.len() != n + n % 2) {
            return Err(format!(
                "a leaf's detail is not {dm}³ values (padded to even)"
            ));
        }
        if self.leaves.iter().any(|l| l.shift > MAX_SHIFT) {
            return Err(format!("a leaf's exponent exceeds {MAX_SHIFT}"));
        }
        let mut ids: Vec<u64> = self.leaves.iter().map(|l| l.id).collect();
        ids.sort_unstable();
        if ids.windows(2).any(|w| w[0] == w[1]) {
            return Err("two leaves with one id".into());
        }
        // The GPU looks leaves up by cell: one leaf a cell.
        let mut cells: Vec<[i64; 3]> = self.leaves.iter().map(|l| l.cell).collect();
        cells.sort_unstable();
        if cells.windows(2).any(|w| w[0] == w[1]) {
            return Err("two leaves in one cell".into());
        }
        Ok(())
    }

    /// The field on the block's nodes, x fastest.
    ///
    /// All sums are integer sums modulo 2^64, so their order does not matter: the coarse part
    /// is interpolated one axis at a time (x, then y, then z: 2 products a node instead of 8
    /// of 3), and then each leaf adds its detail row by row. Peak scratch: the node
    /// accumulator (8 bytes a node) plus the two partial interpolations, which are smaller
    /// than a third of it for `r ≥ 4`; then the accumulator and the output (12 bytes a node).
    pub fn eval(&self) -> Vec<f32> {
        let [nx, ny, _] = self.dims;
        let mut acc = self.coarse_part();
        let dm = self.dm() as i64;
        let dmu = dm as usize;
        for leaf in &self.leaves {
            // Detail offset of block node p: lo + p − (E·cell − ov).
            let base = [0, 1, 2].map(|a| self.lo[a] - (self.e * leaf.cell[a] - self.ov));
            let p0 = [0, 1, 2].map(|a| (-base[a]).max(0));
            let p1 = [0, 1, 2].map(|a| (dm - 1 - base[a]).min(self.dims[a] as i64 - 1));
            if (0..3).any(|a| p0[a] > p1[a]) {
                continue;
            }
            let sx0 = (base[0] + p0[0]) as usize;
            let len = (p1[0] - p0[0] + 1) as usize;
            let wx = &self.own[sx0..sx0 + len];
            for pz in p0[2]..=p1[2] {
                let sz = (base[2] + pz) as usize;
                let wz = self.own[sz] as i64;
                for py in p0[1]..=p1[1] {
                    let sy = (base[1] + py) as usize;
                    let wzy = wz * self.own[sy] as i64;
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
        let unit = self.unit;
        acc.iter()
            .map(|&a| (a >> (3 * WEIGHT_BITS)).clamp(-FIELD_LIMIT, FIELD_LIMIT) as f32 * unit)
            .collect()
    }

    /// The coarse part of [`Blend::eval`]'s accumulator: the trilinear interpolation of the
    /// coarse values at every node, scaled by `2^coarse_shift` to the weights' fixed point.
    fn coarse_part(&self) -> Vec<i64> {
        let [nx, ny, nz] = self.dims;
        let [ax, ay, az] = &self.axes;
        let [cx, cy, cz] = self.coarse_dims;
        // Along x, for every coarse (z, y) row.
        let mut along_x = vec![0i64; cz * cy * nx];
        for (row, out) in along_x.chunks_exact_mut(nx).enumerate() {
            let c = &self.coarse[row * cx..(row + 1) * cx];
            for (x, o) in out.iter_mut().enumerate() {
                let i = ax.c0[x] as usize;
                *o =
                    (ax.w0[x] as i64 * c[i] as i64).wrapping_add(ax.w1[x] as i64 * c[i + 1] as i64);
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
        let shift = self.coarse_shift();
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
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Owned storage behind a random [`Blend`]: fixed-point leaf details and coarse values.
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
    }

    impl RandomBlend {
        /// A block at `lo` of `dims` nodes on a lattice of leaves of `e` voxels (overlap
        /// `e/4`, coarse ratio `e/8`), with leaves at about `fill` of the cells near the
        /// block and random values (coarse in ±1, details in ±0.1).
        pub(crate) fn new(seed: u64, lo: [i64; 3], dims: [usize; 3], e: i64, fill: f64) -> Self {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let ov = e / 4;
            let r = e / 8;
            let dm = (e + 2 * ov + 1) as usize;
            let unit = unit_for(1.0);
            let hi = [0, 1, 2].map(|a| lo[a] + dims[a] as i64 - 1);
            let coarse_n = ((hi.iter().max().unwrap() + 2 * e) / r + 2) as usize;
            let raw: Vec<f32> = (0..coarse_n.pow(3))
                .map(|_| rng.random_range(-1.0f32..1.0))
                .collect();
            let mut details = Vec::new();
            let c0 = lo.map(|v| ((v - ov) / e - 1).max(0));
            let c1 = hi.map(|v| (v + ov) / e + 1);
            for z in c0[2]..=c1[2] {
                for y in c0[1]..=c1[1] {
                    for x in c0[0]..=c1[0] {
                        if rng.random_bool(fill) {
                            let d: Vec<f32> = (0..dm * dm * dm)
                                .map(|_| rng.random_range(-0.1f32..0.1))
                                .collect();
                            details.push(([x, y, z], quantise_detail(&d, unit)));
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
                unit,
                coarse_full: quantise(&raw, unit),
                coarse_n,
                details,
            }
        }

        fn bump(&self, s: i64) -> f64 {
            let half = 0.5 * self.e as f64 + self.ov as f64;
            let u = ((s - self.ov) as f64 - 0.5 * self.e as f64) / half;
            if u.abs() >= 1.0 {
                0.0
            } else {
                (1.0 - u * u) * (1.0 - u * u)
            }
        }

        fn own(&self) -> Vec<i32> {
            pou_weights(self.e, self.ov, |s| self.bump(s))
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
                own: self.own(),
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

        /// The field at block node `p` in f64, from the definition with real weights.
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
            // The sum of all lattice cells' bumps at g, per axis.
            let total = |v: i64| -> f64 {
                let o = v.rem_euclid(self.e);
                (-2..=2).map(|m| self.bump(o - m * self.e + self.ov)).sum()
            };
            let mut acc = 0.0;
            for (cell, Detail { values: d, shift }) in &self.details {
                let u = u * 2f64.powi(*shift as i32);
                let s = [0, 1, 2].map(|a| g[a] - (self.e * cell[a] - self.ov));
                if s.iter().all(|&v| (0..dm).contains(&v)) {
                    let w: f64 = (0..3).map(|a| self.bump(s[a]) / total(g[a])).product();
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
            let mut worst = 0f64;
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let v = f[(z * dims[1] + y) * dims[0] + x] as f64;
                        worst = worst.max((v - rb.reference([x, y, z])).abs());
                    }
                }
            }
            // Weights in 10 bits against details up to 0.1: a few 1e-4 at most.
            assert!(worst < 2e-4, "seed {seed}: off by {worst}");
        }
    }

    #[test]
    fn weights_are_a_partition_of_unity() {
        for (e, ov) in [(8, 2), (32, 8), (64, 16), (1024, 256)] {
            let rb = RandomBlend {
                e,
                ov,
                ..RandomBlend::new(0, [0; 3], [2; 3], 8, 0.0)
            };
            let q = rb.own();
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
    fn leaf_order_does_not_matter() {
        let rb = RandomBlend::new(4, [32, 0, 16], [40, 41, 42], 32, 0.7);
        let b = rb.blend();
        let mut r = b.clone();
        r.leaves.reverse();
        let (x, y) = (b.eval(), r.eval());
        assert!(x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()));
    }

    #[test]
    fn validate_names_what_is_wrong() {
        let rb = RandomBlend::new(5, [0, 0, 0], [9, 9, 9], 16, 0.5);
        let mut b = rb.blend();
        b.own.pop();
        assert!(b.validate().unwrap_err().contains("weights"));
        let mut b = rb.blend();
        b.own[0] = 1;
        assert!(b.validate().unwrap_err().contains("both ends"));
        let mut b = rb.blend();
        b.axes[1].c0[3] = 1000;
        assert!(b.validate().unwrap_err().contains("axis 1"));
        let mut b = rb.blend();
        b.axes[2].w1[1] += 1;
        assert!(b.validate().unwrap_err().contains("sum"));
        let mut b = rb.blend();
        assert!(b.leaves.len() > 1, "the test blend has several leaves");
        b.leaves[1].cell = b.leaves[0].cell;
        assert!(b.validate().unwrap_err().contains("one cell"));
        let mut b = rb.blend();
        b.unit = 0.3;
        assert!(b.validate().unwrap_err().contains("power of two"));
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
