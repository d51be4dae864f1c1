//! A tile's field as data: a coarse trilinear solution plus partition-of-unity weighted leaf
//! details, all in fixed point. Recon builds it (`recon::pou` has the weights and the
//! fixed-point conversions); extract evaluates it bit for bit the same on the CPU
//! (`extract::field`) and on the GPU, so that leaf grids rather than dense tiles cross the bus.
//!
//! # The representation
//!
//! At fine node `g` the field is (Schall, Belyaev & Seidel 2006, §3.3, on a coarse global
//! solve)
//!
//! ```text
//! F(g) = C(g) + Σ_m w_m(g) d_m(g)
//! ```
//!
//! - `C` is the coarse solution, trilinear between coarse nodes `r = 2^k` fine voxels apart:
//!   per axis a lower coarse node `c0` and integer weights `w0 = r − f`, `w1 = f` ([`Axis`]).
//! - `d_m` is the detail grid of leaf `m` ([`Leaf`]): `dm = E + 2·ov + 1` nodes per axis
//!   starting at global node `E·cell − ov`, weighted by `w_m = q[s_z]·q[s_y]·q[s_x] / 2^(3B)`
//!   with `s` the node's offset in that grid and `q` ([`Blend::own`]) the per-axis
//!   partition-of-unity weights in [`WEIGHT_BITS`] = `B` bits, which sum to exactly `2^B` per
//!   axis over the cells at a node.
//! - Values are fixed point in a power-of-two `unit` ([`Blend::unit`]): coarse values as `i32`
//!   bounded by [`VALUE_LIMIT`], details as `i16` in units of `unit·2^shift` per leaf
//!   ([`Detail`], `shift ≤` [`MAX_SHIFT`]).
//! - A node's field is the integer `N = ((Σ_corners w·c) << (3B − 3k) + Σ_leaves
//!   q_z·q_y·q_x·d) >> 3B`, clamped to [`FIELD_LIMIT`], times `unit`: exact in `f32`.
//!
//! [`Blend::validate`] checks a blend's tables against each other; the evaluators rely on it.

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
    /// life of a `GpuExtractor` (or until its `forget_leaves`).
    pub id: u64,
    /// `dm³` values, x fastest, then one 0 if `dm³` is odd (`recon::pou::quantise_detail`):
    /// in units of `unit·2^shift`.
    pub detail: &'a [i16],
    /// The leaf's exponent (at most [`MAX_SHIFT`]).
    pub shift: u32,
}

/// One block's blended field; see the [module docs](self).
#[derive(Debug, Clone)]
pub struct Blend<'a> {
    /// Global node of the block's node 0 (a tile's are non-negative; a window of a level of
    /// the recursive scheme can start a node or two below the cube).
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
    /// Weight at detail offset `s`, `dm` entries, 0 at both ends (`recon::pou::pou_weights`;
    /// the GPU skips the ends).
    pub own: Vec<i32>,
    /// The fixed-point unit, a power of two (`recon::pou::unit_for`).
    pub unit: f32,
    /// The leaves whose grids meet the block (any order).
    pub leaves: Vec<Leaf<'a>>,
}

/// A leaf's detail grid in 16 bits (`recon::pou::quantise_detail` makes it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Detail {
    /// The values in units of `unit·2^shift`, padded to an even length.
    pub values: Vec<i16>,
    /// The exponent.
    pub shift: u32,
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

    /// Check the tables against each other: sizes, indices and weights in range; the error
    /// names what is wrong. The GPU path relies on it, and the CPU blend's indexing stays in
    /// bounds for a blend that passes it.
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
            .any(|&v| !(-(i32::MAX as i64 / 2)..i32::MAX as i64 / 2).contains(&v))
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
}
