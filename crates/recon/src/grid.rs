//! The local grid of a solve and the splat of samples onto it (Kazhdan 2005, §4).
//!
//! A [`LocalGrid`] is a periodic grid of `n³` nodes with spacing `h`: node `i` sits at
//! `origin + h·i`, lengths are measured in the run's `unit` (the octree cube's edge), so that
//! every grid of a run approximates one continuous field ([`crate::fft_solve`]'s module docs,
//! "Scale"). The splat adds each oriented sample's normal to the eight nodes around it by
//! trilinear weights, as a density (`V_j = Σ_i n_i w_ij / h³`): in one pass ([`splat`]), per
//! sample (`splat_node`, the voxel sums' path), or as per-worker boxes summed in a fixed
//! order ([`splat_box`], [`add_boxes`]), all with the same weights. The FFT solve, the
//! screening operator, the voxel sums and the plan's memory figures all read this one grid.

use rayon::prelude::*;

use crate::types::{floor, wrap};

/// Peak bytes per node of a screened solve: the conjugate gradients' five vectors (20) and
/// the preconditioner's transform (8) ([`crate::fft_solve::Solver::solve_screened`]).
pub const SCREENED_BYTES_PER_NODE: u64 = 28;

/// A periodic grid of `n` nodes per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalGrid {
    /// Nodes per axis.
    pub n: usize,
    /// Node spacing (world units).
    pub h: f64,
    /// Position of node (0, 0, 0).
    pub origin: [f64; 3],
    /// The length unit of the solve, in world units (the cube's edge; see the module docs).
    pub unit: f64,
}

impl LocalGrid {
    /// The factor of a splatted normal, `1/h³` in the solve's unit (the module docs).
    pub(crate) fn splat_scale(&self) -> f32 {
        let h_u = self.h / self.unit;
        (1.0 / (h_u * h_u * h_u)) as f32
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.n * self.n * self.n
    }

    /// True for a grid without nodes.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Bytes of scratch [`crate::fft_solve::solve`] needs at its peak: the splatted normals (12 bytes a node)
    /// and their divergence (4). After the splat is dropped, the transform holds at most two
    /// half spectra (`n²·(n/2 + 1)` complex values each, about 4 bytes a node), or one and
    /// the divergence or the result. Plus the [`crate::fft_solve::Solver`]'s filter table.
    pub fn scratch_bytes(&self) -> u64 {
        let h1 = (self.n / 2 + 1) as u64;
        self.len() as u64 * 16 + h1 * h1 * h1 * 4
    }

    /// Bytes of scratch a solve needs at its peak: [`LocalGrid::scratch_bytes`], or with
    /// screening ([`crate::fft_solve::Solver::solve_screened`]) the conjugate gradients' five vectors and the
    /// preconditioner's transform, 28 bytes a node, with its multipliers beside the filter,
    /// when that is more.
    pub fn solve_bytes(&self, screened: bool) -> u64 {
        let plain = self.scratch_bytes();
        if screened {
            let h1 = (self.n / 2 + 1) as u64;
            plain.max(self.len() as u64 * SCREENED_BYTES_PER_NODE + 2 * h1 * h1 * h1 * 4)
        } else {
            plain
        }
    }

    /// Trilinear interpolation of node values `v` at world point `p` (periodic).
    #[inline]
    pub fn eval(&self, v: &[f32], p: [f64; 3]) -> f64 {
        let n = self.n as i64;
        // Per axis the two wrapped node indices (once, not per corner) and the offset.
        let mut at = [[0usize; 2]; 3];
        let mut f = [0f64; 3];
        for a in 0..3 {
            let u = (p[a] - self.origin[a]) / self.h;
            let fl = floor(u);
            let i0 = fl as i64;
            at[a] = [wrap(i0, n) as usize, wrap(i0 + 1, n) as usize];
            f[a] = u - fl;
        }
        let mut acc = 0.0;
        for c in 0..8 {
            let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let w = (if dx == 1 { f[0] } else { 1.0 - f[0] })
                * (if dy == 1 { f[1] } else { 1.0 - f[1] })
                * (if dz == 1 { f[2] } else { 1.0 - f[2] });
            acc += w * v[(at[2][dz] * self.n + at[1][dy]) * self.n + at[0][dx]] as f64;
        }
        acc
    }
}

/// Add the normals of `pos`/`nrm` to `v` (one `[f32; 3]` per node) as a density.
pub fn splat(grid: &LocalGrid, pos: &[[f64; 3]], nrm: &[[f32; 3]], v: &mut [[f32; 3]]) {
    let inv_h = 1.0 / grid.h;
    let scale = grid.splat_scale();
    for (p, nn) in pos.iter().zip(nrm) {
        let u = [0, 1, 2].map(|a| (p[a] - grid.origin[a]) * inv_h);
        splat_node(grid.n, u, *nn, scale, v);
    }
}

/// The lowest of the 8 nodes around `u` (in nodes, unwrapped) and the trilinear weights of
/// the 8, times `scale`, corner `c` at `(c & 1, c >> 1 & 1, c >> 2 & 1)` from it: what
/// [`splat_node`] and [`splat_box`] add, the same bits.
#[inline]
fn corners(u: [f64; 3], scale: f32) -> ([i64; 3], [f32; 8]) {
    let (mut at, mut w) = ([0i64; 3], [[0f32; 2]; 3]);
    for a in 0..3 {
        let fl = floor(u[a]);
        at[a] = fl as i64;
        let f = (u[a] - fl) as f32;
        w[a] = [1.0 - f, f];
    }
    let wc = std::array::from_fn(|c| w[0][c & 1] * w[1][(c >> 1) & 1] * w[2][(c >> 2) & 1] * scale);
    (at, wc)
}

/// One batch's [`splat`] kept apart from any grid's values: the nodes `lo ..= lo + dims − 1`
/// its samples reach (unwrapped indices, wrapped into the grid when added), x fastest, each
/// holding the sum of its additions in the samples' order.
///
/// The coarse pass splats each store cell into its own box and adds the boxes to the grid in
/// the cells' order ([`add_boxes`]): a node's value is then a sum over cells, in cell order,
/// of each cell's sum, whichever thread or shard splatted the cell. So a split run's shards
/// splat their share of the cells, keep the boxes, and every shard adds them all up into the
/// bits one process gets.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SplatBox {
    /// The box's lowest node (unwrapped).
    pub lo: [i64; 3],
    /// Nodes per axis.
    pub dims: [usize; 3],
    /// Per node, x fastest.
    pub values: Vec<[f32; 3]>,
}

impl SplatBox {
    /// Bytes of the values.
    pub fn bytes(&self) -> u64 {
        12 * self.values.len() as u64
    }

    /// Bytes of a box whose samples span `nodes` nodes per axis at most: their nodes and
    /// one more above, for the trilinear weights.
    pub fn bytes_within(nodes: u64) -> u64 {
        12 * (nodes + 1).pow(3)
    }
}

/// The splat of `pos`/`nrm` on `grid` into a box of its own ([`SplatBox`]): what [`splat`]
/// adds to each node, in the same order, summed from zero.
pub fn splat_box(grid: &LocalGrid, pos: &[[f64; 3]], nrm: &[[f32; 3]]) -> SplatBox {
    let inv_h = 1.0 / grid.h;
    let scale = grid.splat_scale();
    let node = |p: &[f64; 3]| [0, 1, 2].map(|a| (p[a] - grid.origin[a]) * inv_h);
    let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
    for p in pos {
        let u = node(p);
        for a in 0..3 {
            let f = floor(u[a]) as i64;
            lo[a] = lo[a].min(f);
            hi[a] = hi[a].max(f + 1);
        }
    }
    if pos.is_empty() {
        return SplatBox::default();
    }
    let dims = [0, 1, 2].map(|a| (hi[a] - lo[a] + 1) as usize);
    let mut values = vec![[0f32; 3]; dims[0] * dims[1] * dims[2]];
    for (p, nn) in pos.iter().zip(nrm) {
        let (at, wc) = corners(node(p), scale);
        let at = [0, 1, 2].map(|a| (at[a] - lo[a]) as usize);
        for (c, wc) in wc.into_iter().enumerate() {
            let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let cell = &mut values[((at[2] + dz) * dims[1] + at[1] + dy) * dims[0] + at[0] + dx];
            cell[0] += wc * nn[0];
            cell[1] += wc * nn[1];
            cell[2] += wc * nn[2];
        }
    }
    SplatBox { lo, dims, values }
}

/// Add the boxes `boxes` ([`splat_box`]) in order onto `v` (the grid's nodes, x fastest), in
/// parallel over z-slabs of the grid (one a thread of the pool it runs in): every node takes
/// the boxes' values in the boxes' order, so the bits do not depend on the slabs.
pub fn add_boxes(grid: &LocalGrid, boxes: &[&SplatBox], v: &mut [[f32; 3]]) {
    let n = grid.n;
    let slab = n * n;
    let per = n.div_ceil(rayon::current_num_threads().max(1)).max(1);
    let w = |i: i64, k: usize| wrap(i + k as i64, n as i64) as usize;
    v.par_chunks_mut(per * slab)
        .enumerate()
        .for_each(|(s, chunk)| {
            let (z0, z1) = (s * per, s * per + chunk.len() / slab);
            for b in boxes {
                let [dx, dy, dz] = b.dims;
                for bz in 0..dz {
                    let z = w(b.lo[2], bz);
                    if z < z0 || z >= z1 {
                        continue;
                    }
                    for by in 0..dy {
                        let row = ((z - z0) * n + w(b.lo[1], by)) * n;
                        let from = &b.values[(bz * dy + by) * dx..][..dx];
                        for (bx, val) in from.iter().enumerate() {
                            let c = &mut chunk[row + w(b.lo[0], bx)];
                            c[0] += val[0];
                            c[1] += val[1];
                            c[2] += val[2];
                        }
                    }
                }
            }
        });
}

/// Add `nn · scale` to the nodes around `u` (in nodes from node 0, wrapped into `n³`) by
/// trilinear weights: one sample of [`splat`].
pub(crate) fn splat_node(n: usize, u: [f64; 3], nn: [f32; 3], scale: f32, v: &mut [[f32; 3]]) {
    let ni = n as i64;
    let (at, wc) = corners(u, scale);
    let at = [0, 1, 2].map(|a| [wrap(at[a], ni) as usize, wrap(at[a] + 1, ni) as usize]);
    for (c, wc) in wc.into_iter().enumerate() {
        let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
        let cell = &mut v[(at[2][dz] * n + at[1][dy]) * n + at[0][dx]];
        cell[0] += wc * nn[0];
        cell[1] += wc * nn[1];
        cell[2] += wc * nn[2];
    }
}
