//! Sub-block planning: a tile whose buffers would exceed the device's limits is cut into
//! sub-blocks that share a face of nodes, in an order whose concatenated cell orders give the
//! tile's cell order (see the [parent module's docs](super), "Sub-blocks").

/// Largest node count of a sub-block: keeps `3·nodes` edge ids below bit 30 (bit 31 flags
/// seams).
const MAX_BLOCK_NODES: u64 = 1 << 28;

/// Bytes of a sub-block's largest buffer known before it runs, per node: the counts of
/// `classify.wgsl`, four `u32` (vertices, active, triangles, padding).
const COUNT_BYTES_PER_NODE: u64 = 16;

/// A sub-block of a tile: node offset in the tile and node counts (at least 2 per axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct SubBlock {
    /// Offset of its lowest node in the tile, in nodes.
    pub(super) at: [usize; 3],
    /// Nodes per axis.
    pub(super) dims: [usize; 3],
}

impl SubBlock {
    /// Faces shared with the rest of a tile of `tile` nodes: bit `2·axis` lower, `2·axis + 1`
    /// upper.
    pub(super) fn seam_mask(&self, tile: [usize; 3]) -> u32 {
        (0..3).fold(0, |m, d| {
            m | (((self.at[d] > 0) as u32) << (2 * d))
                | (((self.at[d] + self.dims[d] < tile[d]) as u32) << (2 * d + 1))
        })
    }

    /// Halves along the outermost axis with more than one cell (z, then y, then x): a slab
    /// into slabs, a layer into bands, a band into bands, a row into runs, so that the halves
    /// keep the tile's cell order. `None` for a single cell.
    pub(super) fn halve(&self) -> Option<(SubBlock, SubBlock)> {
        let d = (0..3).rev().find(|&d| self.dims[d] > 2)?;
        let cells = self.dims[d] - 1;
        let mut lo = *self;
        let mut hi = *self;
        lo.dims[d] = cells / 2 + 1;
        hi.at[d] += cells / 2;
        hi.dims[d] = cells - cells / 2 + 1;
        Some((lo, hi))
    }
}

/// Nodes of a sub-block of `c` cells per axis, and the bytes of its largest buffer known
/// before it runs: the counts, 16 bytes a node.
pub(super) fn block_bytes(c: [usize; 3]) -> (u64, u64) {
    let nodes = c.iter().map(|&v| v as u64 + 1).product::<u64>();
    (nodes, COUNT_BYTES_PER_NODE * nodes)
}

fn fits(c: [usize; 3], limit: u64) -> bool {
    let (nodes, bytes) = block_bytes(c);
    nodes <= MAX_BLOCK_NODES && bytes <= limit
}

/// The largest `k` in `1..=max` with `ok(k)`, given `ok(1)` and `ok` monotone.
fn largest(max: usize, ok: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (1, max);
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if ok(mid) { lo = mid } else { hi = mid - 1 }
    }
    lo
}

/// Cut a tile of `dims` nodes (at least 2 per axis) into sub-blocks whose counts fit `limit`
/// bytes, in an order whose concatenated cell orders give the tile's cell order (see the
/// [parent module's docs](super)).
pub(super) fn plan(dims: [usize; 3], limit: u64) -> std::result::Result<Vec<SubBlock>, String> {
    let c = dims.map(|d| d - 1);
    let mut out = Vec::new();
    if !fits([1, 1, 1], limit) {
        return Err(format!(
            "a buffer limit of {limit} bytes cannot hold one cell"
        ));
    }
    let sub = |at: [usize; 3], cells: [usize; 3]| SubBlock {
        at,
        dims: cells.map(|v| v + 1),
    };
    if fits([c[0], c[1], 1], limit) {
        let bz = largest(c[2], |k| fits([c[0], c[1], k], limit));
        for z in (0..c[2]).step_by(bz) {
            out.push(sub([0, 0, z], [c[0], c[1], bz.min(c[2] - z)]));
        }
    } else if fits([c[0], 1, 1], limit) {
        let by = largest(c[1], |k| fits([c[0], k, 1], limit));
        for z in 0..c[2] {
            for y in (0..c[1]).step_by(by) {
                out.push(sub([0, y, z], [c[0], by.min(c[1] - y), 1]));
            }
        }
    } else {
        let bx = largest(c[0], |k| fits([k, 1, 1], limit));
        for z in 0..c[2] {
            for y in 0..c[1] {
                for x in (0..c[0]).step_by(bx) {
                    out.push(sub([x, y, z], [bx.min(c[0] - x), 1, 1]));
                }
            }
        }
    }
    Ok(out)
}
