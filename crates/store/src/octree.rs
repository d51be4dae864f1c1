//! The cell hierarchy chosen from a counting grid.
//!
//! Points are first counted on a regular grid of `8^L` cells below a base cell (the root at
//! ingest, an oversized cell when splitting again), indexed in Morton order so that the
//! eight children of a node are consecutive. The hierarchy is then cut top-down: a node that
//! holds at most `max_points` points becomes a leaf (a cell of the store); a fuller node is
//! split into its non-empty children. A grid cell that is still too full becomes an
//! *oversized* leaf, to be split again by a finer count of its own points. Leaves come out in
//! Morton order, each covering a contiguous range of grid cells, so the leaf of a point is a
//! binary search over the range starts, narrowed by a table over the grid's first
//! [`PREFIX_LEVELS`] levels to the leaves starting inside the point's block (usually none, so
//! no search at all). [`GridMap`] gives a point's grid cell.

use crate::types::{CellKey, Cube, morton3};

/// A leaf of the hierarchy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Leaf {
    /// The cell.
    pub key: CellKey,
    /// Points counted in it.
    pub count: u64,
    /// First grid cell (Morton index at the counting level, relative to the base).
    pub start: u64,
    /// One past the last grid cell.
    pub end: u64,
    /// More points than the limit, yet at the counting level: split again later.
    pub oversized: bool,
}

/// Leaves over a counting grid.
#[derive(Debug, Clone)]
pub struct Hierarchy {
    /// The cell the grid subdivides.
    pub base: CellKey,
    /// Grid levels below the base.
    pub levels: u32,
    /// Non-empty leaves in Morton order.
    pub leaves: Vec<Leaf>,
    starts: Vec<u64>,
    /// Per block of the grid's first `prefix` levels: how many leaves start at or before the
    /// block's first grid cell, and how many start before the next block.
    blocks: Vec<(u32, u32)>,
    /// Bits of a grid cell's Morton index below its block's.
    block_shift: u32,
}

/// Levels of the table that narrows [`Hierarchy::leaf_of`]'s search: `8^4` blocks, 32 KiB.
pub const PREFIX_LEVELS: u32 = 4;

impl Hierarchy {
    /// Cut the hierarchy from `counts` (length `8^levels`, Morton order).
    pub fn build(base: CellKey, levels: u32, counts: &[u64], max_points: u64) -> Hierarchy {
        debug_assert_eq!(counts.len() as u64, 1u64 << (3 * levels));
        // sums[r] holds the counts of the 8^r nodes at relative level r.
        let mut sums: Vec<Vec<u64>> = vec![Vec::new(); levels as usize + 1];
        sums[levels as usize] = counts.to_vec();
        for r in (0..levels as usize).rev() {
            let child = &sums[r + 1];
            sums[r] = child.chunks_exact(8).map(|c| c.iter().sum()).collect();
        }
        let mut leaves = Vec::new();
        // Depth-first in Morton order with an explicit stack of (level, morton).
        let mut stack = vec![(0u32, 0u64)];
        while let Some((r, m)) = stack.pop() {
            let n = sums[r as usize][m as usize];
            if n == 0 {
                continue;
            }
            if n <= max_points || r == levels {
                let shift = 3 * (levels - r);
                leaves.push(Leaf {
                    key: CellKey((base.0 << (3 * r)) | m),
                    count: n,
                    start: m << shift,
                    end: (m + 1) << shift,
                    oversized: n > max_points,
                });
            } else {
                for c in (0..8).rev() {
                    stack.push((r + 1, m * 8 + c));
                }
            }
        }
        let starts: Vec<u64> = leaves.iter().map(|l| l.start).collect();
        let block_shift = 3 * (levels - levels.min(PREFIX_LEVELS));
        let blocks = (0..1u64 << (3 * levels.min(PREFIX_LEVELS)))
            .map(|b| {
                let first = b << block_shift;
                let next = (b + 1) << block_shift;
                (
                    starts.partition_point(|&s| s <= first) as u32,
                    starts.partition_point(|&s| s < next) as u32,
                )
            })
            .collect();
        Hierarchy {
            base,
            levels,
            leaves,
            starts,
            blocks,
            block_shift,
        }
    }

    /// The leaf holding grid cell `m`, if any.
    #[inline]
    pub fn leaf_of(&self, m: u64) -> Option<u32> {
        // The leaves starting at or before m: those up to the block's first cell, and those
        // starting inside the block up to m.
        let (lo, hi) = *self.blocks.get((m >> self.block_shift) as usize)?;
        let (lo, hi) = (lo as usize, hi as usize);
        let i = lo + self.starts[lo..hi].partition_point(|&s| s <= m);
        if i == 0 {
            return None;
        }
        let l = &self.leaves[i - 1];
        (m < l.end).then_some((i - 1) as u32)
    }
}

/// Levels of a counting grid for `n` points spread on surfaces (about `4^L` occupied cells of
/// `8^L`): enough that a typical grid cell holds a sixteenth of the limit, at most `max_levels`.
pub fn count_levels(n: u64, max_points: u64, max_levels: u32) -> u32 {
    let mut l = 1;
    while l < max_levels && (n as f64) / 4f64.powi(l as i32) > max_points as f64 / 16.0 {
        l += 1;
    }
    l
}

/// Maps points to Morton indices on the grid `levels` below a base cell.
#[derive(Debug, Clone, Copy)]
pub struct GridMap {
    origin: [f64; 3],
    inv: f64,
    base: [u64; 3],
    top: u64,
}

impl GridMap {
    /// The grid `levels` below cell `base` of `cube`.
    pub fn new(cube: &Cube, base: CellKey, levels: u32) -> GridMap {
        let (bl, bc) = base.decode();
        let level = bl + levels;
        GridMap {
            origin: cube.origin,
            inv: (1u64 << level) as f64 / cube.size,
            base: bc.map(|c| (c as u64) << levels),
            top: (1u64 << levels) - 1,
        }
    }

    /// The grid cell of `p`, clamped into the grid. Agrees with [`Cube::cell_coords`]: the
    /// scale is a power of two times the cube's, so both floor the same products.
    #[inline(always)]
    pub fn index(&self, p: [f64; 3]) -> u64 {
        let mut c = [0u32; 3];
        for k in 0..3 {
            let v = (p[k] - self.origin[k]) * self.inv;
            // Truncation is floor for v > 0; v <= 0 (and NaN) clamp to 0.
            let g = if v > 0.0 { v as u64 } else { 0 };
            c[k] = g.saturating_sub(self.base[k]).min(self.top) as u32;
        }
        morton3(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cuts_and_finds() {
        // 2 levels: 64 grid cells. Put 10 points in cell 0, 1 in cells 8..16, 3 in cell 63.
        let mut c = vec![0u64; 64];
        c[0] = 10;
        for v in &mut c[8..16] {
            *v = 1;
        }
        c[63] = 3;
        let h = Hierarchy::build(CellKey::ROOT, 2, &c, 8);
        // Root (21) splits; child 0 (10) splits to grid cell 0 (oversized); child 1 (8) leaf;
        // child 7 (3) leaf.
        let keys: Vec<_> = h
            .leaves
            .iter()
            .map(|l| (l.key.decode(), l.count, l.oversized))
            .collect();
        assert_eq!(
            keys,
            vec![
                ((2, [0, 0, 0]), 10, true),
                ((1, [1, 0, 0]), 8, false),
                ((1, [1, 1, 1]), 3, false),
            ]
        );
        assert_eq!(h.leaf_of(0), Some(0));
        assert_eq!(h.leaf_of(1), None);
        assert_eq!(h.leaf_of(12), Some(1));
        assert_eq!(h.leaf_of(63), Some(2));
        assert_eq!(h.leaf_of(60), Some(2));
        assert_eq!(h.leaf_of(20), None);
    }

    #[test]
    fn the_block_table_finds_what_a_scan_finds() {
        // Clustered counts on grids coarser than, as fine as and finer than the block table, cut at
        // several limits: every grid cell's leaf is the one a linear scan of the ranges finds.
        for levels in [1, 4, 5, 6] {
            let n = 1usize << (3 * levels);
            let mut x = 12345u64;
            let counts: Vec<u64> = (0..n)
                .map(|i| {
                    x = x
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    if (i / 64) % 3 == 0 { (x >> 60) % 5 } else { 0 }
                })
                .collect();
            for max in [1, 7, 100, 5000] {
                let h = Hierarchy::build(CellKey::ROOT, levels, &counts, max);
                let mut scan = vec![None; n + 9];
                for (i, l) in h.leaves.iter().enumerate() {
                    scan[l.start as usize..l.end as usize].fill(Some(i as u32));
                }
                for (m, want) in scan.into_iter().enumerate() {
                    let got = h.leaf_of(m as u64);
                    assert_eq!(got, want, "levels {levels}, limit {max}, cell {m}");
                }
            }
        }
    }

    #[test]
    fn relative_keys_below_a_base() {
        let base = CellKey::new(3, [1, 2, 3]);
        let mut c = vec![0u64; 8];
        c[5] = 4;
        c[6] = 4;
        let h = Hierarchy::build(base, 1, &c, 5);
        assert_eq!(h.leaves.len(), 2);
        assert_eq!(h.leaves[0].key, base.child(5));
        assert_eq!(h.leaves[0].key.decode(), (4, [3, 4, 7]));
    }

    #[test]
    fn levels_grow_with_points() {
        assert_eq!(count_levels(1000, 1_000_000, 7), 1);
        assert!(count_levels(100_000_000, 1_000_000, 7) >= 5);
        assert_eq!(count_levels(u64::MAX / 2, 1, 7), 7);
    }
}
