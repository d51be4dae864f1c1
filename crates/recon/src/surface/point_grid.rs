//! Exact k-nearest input points of a vertex, by a uniform grid of growing shells, and by a
//! k-d tree for the queries far from every point.
//!
//! The grid is the faster of the two where the query sits on the sampled surface (its k
//! nearest lie in the first shell or two), but a query far from the points (the closed
//! surface's side away from a terrain scan, say) must sweep every cell of a cube whose
//! radius is its distance to the points, and sort every point in it. After
//! `GRID_SHELLS` shells without an answer the query goes to a k-d tree instead, built once
//! per grid on first need, whose search visits only the boxes the ball of the k-th nearest
//! point meets. Both give the exact k nearest with the same order (squared distance, then
//! index) and the same distance arithmetic, so which one answered never shows in the result.

use std::cell::OnceCell;
use std::cmp::Ordering;

use crate::types::{Aabb, floor};

/// Shells of grid cells swept before a query goes to the k-d tree. Measured on the Autzen
/// LiDAR tile (110K points, depth 10), whose closed surface's underside lies 30–70 voxels
/// below the ground: the tile stage ran at 2 tiles a second with the grid alone (of 886),
/// and took 11.8 s with the tree after 3 shells (12.3 s after 2); on a 1M-point sphere at
/// depth 9, where every query is near, 3 shells left the tile stage as it was (2.5–3.9 s,
/// run to run).
const GRID_SHELLS: i64 = 3;

/// Points in a k-d tree's leaf.
const KD_LEAF: usize = 8;

/// A tile's points bucketed in a uniform grid, for exact k-nearest queries by growing shells
/// of cells: after the shell at Chebyshev distance `r` from the query's cell, every point not
/// yet seen lies at least `r·s` plus the query's distance to its own cell's faces away.
pub struct PointGrid<'a> {
    pos: &'a [[f64; 3]],
    lo: [f64; 3],
    s: f64,
    dims: [usize; 3],
    /// Start of each cell's points in `idx` (cells + 1 entries).
    start: Vec<u32>,
    /// Point indices, by cell.
    idx: Vec<u32>,
    /// The k-d tree for far queries, built on first need.
    tree: OnceCell<KdTree>,
}

impl<'a> PointGrid<'a> {
    /// Points `pos` within `lo..hi`, in cells sized so that an occupied cell holds about 4
    /// points (starting from `s`; on a surface a cell's share grows with its area). Measured
    /// on a 1M-point bumpy sphere at depth 9, 2 to 16 points a cell were within 10% of each
    /// other, 4 the fastest; the tile stage took 5.9 s against 7.3 s with a kd-tree
    /// (kiddo).
    pub fn new(pos: &'a [[f64; 3]], lo: [f64; 3], hi: [f64; 3], s: f64) -> PointGrid<'a> {
        const OCCUPANCY: f64 = 4.0;
        let n = pos.len();
        let extent = (0..3)
            .map(|a| hi[a] - lo[a])
            .fold(0f64, f64::max)
            .max(1e-300);
        let mut s = s.clamp(extent * 1e-6, extent);
        let dims_for = |s: f64| [0, 1, 2].map(|a| (((hi[a] - lo[a]) / s).ceil() as usize).max(1));
        let cell_of = |p: &[f64; 3], s: f64, d: [usize; 3]| {
            let c = [0, 1, 2].map(|a| (((p[a] - lo[a]) / s) as usize).min(d[a] - 1));
            (c[2] * d[1] + c[1]) * d[0] + c[0]
        };
        for _ in 0..3 {
            while dims_for(s).iter().product::<usize>() > 8 * n + 4096 {
                s *= 2.0;
            }
            let d = dims_for(s);
            // Occupied cells counted on a bit a cell (at most `n/8 + 512` bytes), not by
            // sorting every point's cell: that sort was a tenth of the tile stage.
            let mut seen = vec![0u64; d.iter().product::<usize>().div_ceil(64)];
            let mut occupied = 0usize;
            for p in pos {
                let c = cell_of(p, s, d);
                let bit = 1u64 << (c % 64);
                occupied += usize::from(seen[c / 64] & bit == 0);
                seen[c / 64] |= bit;
            }
            let occupancy = n as f64 / occupied.max(1) as f64;
            // Points on a surface: a cell's share grows with its area.
            let f = (OCCUPANCY / occupancy).sqrt().clamp(0.25, 4.0);
            if (0.7..1.4).contains(&f) {
                break;
            }
            s = (s * f).min(extent);
        }
        while dims_for(s).iter().product::<usize>() > 8 * n + 4096 {
            s *= 2.0;
        }
        let dims = dims_for(s);
        let mut start = vec![0u32; dims.iter().product::<usize>() + 1];
        let cell: Vec<usize> = pos.iter().map(|p| cell_of(p, s, dims)).collect();
        for &c in &cell {
            start[c + 1] += 1;
        }
        for i in 1..start.len() {
            start[i] += start[i - 1];
        }
        let mut fill = start.clone();
        let mut idx = vec![0u32; n];
        for (i, &c) in cell.iter().enumerate() {
            idx[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        PointGrid {
            pos,
            lo,
            s,
            dims,
            start,
            idx,
            tree: OnceCell::new(),
        }
    }

    /// The `k` points nearest `q` (fewer if there are fewer) into `out`, as (squared
    /// distance, index) in increasing order (ties by index).
    pub fn nearest(&self, q: [f64; 3], k: usize, out: &mut Vec<(f64, u32)>) {
        out.clear();
        if k == 0 || self.pos.is_empty() {
            return;
        }
        let d = self.dims.map(|v| v as i64);
        let qc = [0, 1, 2].map(|a| (floor((q[a] - self.lo[a]) / self.s) as i64).clamp(0, d[a] - 1));
        // The query's distance to its cell's faces (0 when outside the grid).
        let face = (0..3)
            .map(|a| {
                let c0 = self.lo[a] + qc[a] as f64 * self.s;
                (q[a] - c0).min(c0 + self.s - q[a]).max(0.0)
            })
            .fold(f64::INFINITY, f64::min);
        let mut r = 0i64;
        loop {
            let lo = qc.map(|c| c - r);
            let hi = qc.map(|c| c + r);
            for z in lo[2].max(0)..=hi[2].min(d[2] - 1) {
                for y in lo[1].max(0)..=hi[1].min(d[1] - 1) {
                    // Inside the shell only its two ends along x are new.
                    let inner = z != lo[2] && z != hi[2] && y != lo[1] && y != hi[1];
                    let step = if inner { hi[0] - lo[0] } else { 1 };
                    let mut x = if inner { lo[0] } else { lo[0].max(0) };
                    while x <= hi[0].min(d[0] - 1) {
                        if x < 0 {
                            x += step;
                            continue;
                        }
                        let c = ((z * d[1] + y) * d[0] + x) as usize;
                        for &i in &self.idx[self.start[c] as usize..self.start[c + 1] as usize] {
                            out.push((dist2(self.pos[i as usize], q), i));
                        }
                        x += step;
                    }
                }
            }
            // Keep the k best seen: a point not among them cannot be among the k nearest.
            let by = |a: &(f64, u32), b: &(f64, u32)| order(*a, *b);
            if out.len() > k {
                out.select_nth_unstable_by(k - 1, by);
                out.truncate(k);
            }
            let kth = out.iter().map(|e| e.0).fold(0f64, f64::max);
            let reach = r as f64 * self.s + face;
            let whole = (0..3).all(|a| lo[a] <= 0 && hi[a] >= d[a] - 1);
            if whole || (out.len() == k && kth <= reach * reach) {
                out.sort_unstable_by(by);
                return;
            }
            r += 1;
            if r == GRID_SHELLS {
                let tree = self.tree.get_or_init(|| KdTree::new(self.pos));
                tree.nearest(self.pos, q, k, out);
                return;
            }
        }
    }
}

/// The squared distance from `q` to `p`, in the one order both searches use.
fn dist2(p: [f64; 3], q: [f64; 3]) -> f64 {
    (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)
}

/// A k-d tree over point indices: each inner node splits its points at the median along the
/// axis of their widest extent, down to leaves of at most [`KD_LEAF`] points; every node
/// keeps its points' tight bounding box. The boxes, not the split planes, bound a node's
/// distance: a flat scan's nodes are all split across the ground, and only their boxes
/// know how far below it a query is.
struct KdTree {
    /// Point indices; every node's points are a contiguous range.
    perm: Vec<u32>,
    nodes: Vec<KdNode>,
}

struct KdNode {
    /// The node's points' bounding box.
    bx: Aabb,
    /// Its points, `perm[start..end]`.
    start: u32,
    end: u32,
    /// Its two halves, or none for a leaf.
    halves: Option<[u32; 2]>,
}

impl KdNode {
    /// A lower bound on `dist2(p, q)` for every point `p` of the node, in floats too
    /// ([`Aabb::dist2`] sums in `dist2`'s order).
    fn bound(&self, q: [f64; 3]) -> f64 {
        self.bx.dist2(q)
    }
}

impl KdTree {
    fn new(pos: &[[f64; 3]]) -> KdTree {
        let mut tree = KdTree {
            perm: (0..pos.len() as u32).collect(),
            nodes: Vec::with_capacity(2 * pos.len() / KD_LEAF + 1),
        };
        tree.build(pos, 0, pos.len());
        tree
    }

    /// Builds the node over `perm[start..end]` and returns its index.
    fn build(&mut self, pos: &[[f64; 3]], start: usize, end: usize) -> u32 {
        let range = &mut self.perm[start..end];
        let mut bx = Aabb::EMPTY;
        for &i in range.iter() {
            bx.add(pos[i as usize]);
        }
        let me = self.nodes.len() as u32;
        self.nodes.push(KdNode {
            bx,
            start: start as u32,
            end: end as u32,
            halves: None,
        });
        if end - start > KD_LEAF {
            let e = bx.extent();
            let axis = (0..3).max_by(|&a, &b| e[a].total_cmp(&e[b])).unwrap_or(0);
            let mid = range.len() / 2;
            range.select_nth_unstable_by(mid, |&a, &b| {
                pos[a as usize][axis]
                    .total_cmp(&pos[b as usize][axis])
                    .then(a.cmp(&b))
            });
            let lower = self.build(pos, start, start + mid);
            let upper = self.build(pos, start + mid, end);
            self.nodes[me as usize].halves = Some([lower, upper]);
        }
        me
    }

    /// As [`PointGrid::nearest`]: the `k` nearest of `pos` to `q`, by (squared distance,
    /// index), into `out` in that order.
    fn nearest(&self, pos: &[[f64; 3]], q: [f64; 3], k: usize, out: &mut Vec<(f64, u32)>) {
        out.clear();
        // Nodes to visit, with their bounds.
        let mut stack = vec![(0u32, self.nodes[0].bound(q))];
        while let Some((node, bound)) = stack.pop() {
            // A tie at the k-th distance may still win on its index, hence only a strictly
            // greater bound is skipped.
            if out.len() == k && bound > out[k - 1].0 {
                continue;
            }
            let n = &self.nodes[node as usize];
            match n.halves {
                None => {
                    for &i in &self.perm[n.start as usize..n.end as usize] {
                        let e = (dist2(pos[i as usize], q), i);
                        if out.len() == k && order(e, out[k - 1]).is_ge() {
                            continue;
                        }
                        let at = out.partition_point(|x| order(*x, e).is_lt());
                        out.insert(at, e);
                        out.truncate(k);
                    }
                }
                Some([lower, upper]) => {
                    let (bl, bu) = (
                        self.nodes[lower as usize].bound(q),
                        self.nodes[upper as usize].bound(q),
                    );
                    // The nearer half first (popped first).
                    if bl <= bu {
                        stack.push((upper, bu));
                        stack.push((lower, bl));
                    } else {
                        stack.push((lower, bl));
                        stack.push((upper, bu));
                    }
                }
            }
        }
    }
}

/// The order both searches rank points in: squared distance, then index.
fn order(a: (f64, u32), b: (f64, u32)) -> Ordering {
    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_grid_finds_the_exact_nearest_points() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for (n, spread) in [
            (0usize, 1.0),
            (1, 1.0),
            (30, 1.0),
            (3000, 1.0),
            (3000, 0.01),
        ] {
            // Clustered and spread points, some repeated.
            let mut pos: Vec<[f64; 3]> = (0..n)
                .map(|_| [0, 1, 2].map(|_| rng.random_range(0.0..spread)))
                .collect();
            if n > 10 {
                pos[3] = pos[2];
                // Ties: points on a lattice.
                for p in pos.iter_mut().skip(n / 2) {
                    *p = p.map(|c| (c / spread * 4.0).round() * spread / 4.0);
                }
            }
            let (lo, hi) = ([0.0; 3], [spread; 3]);
            for s in [0.001, 0.05, 0.3] {
                let g = PointGrid::new(&pos, lo, hi, s);
                let mut out = Vec::new();
                for j in 0..300 {
                    // Near queries (the grid answers) and far ones (the k-d tree does).
                    let reach = if j % 3 == 0 { 4.0 } else { 0.2 };
                    let q = [0, 1, 2]
                        .map(|_| rng.random_range(-reach * spread..(1.0 + reach) * spread));
                    for k in [1, 6, 22] {
                        g.nearest(q, k, &mut out);
                        let mut all: Vec<(f64, u32)> = pos
                            .iter()
                            .enumerate()
                            .map(|(i, p)| {
                                let d2 = (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>();
                                (d2, i as u32)
                            })
                            .collect();
                        all.sort_by(|a, b| a.partial_cmp(b).unwrap());
                        all.truncate(k);
                        assert_eq!(out, all, "n {n} s {s} k {k}");
                    }
                }
            }
        }
    }
}
