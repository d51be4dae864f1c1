// Pass 1 of GPU marching cubes (src/extract/gpu/): classify cells, one thread per node.
//
// Node i is the lowest corner of cell i (nodes on the block's upper faces have no cell). The
// thread writes counts[i] = (new vertices, active, triangles, case | new-edge mask << 8) for
// cell i. A crossing edge's vertex is *new* in the first cell, in cell order (x fastest, then
// y, then z), that holds the edge: the cell whose offsets across the edge are 1, or 0 where
// the edge lies on the block's lower face in that axis. So the vertices of a block, numbered
// cell by cell and within a cell in the order of tables::case_edges, come in order of first
// use by the triangles: the CPU kernel's order. Pass 2 scans the first three components.
//
// Inside is `v < iso` with NaN outside, decided on the bit patterns (`key` below is monotone
// in the float order and maps −0 and +0 together), so no float compare, flush-to-zero mode or
// NaN handling of the GPU can change a case.

@group(0) @binding(0) var<uniform> blk: Block;
@group(0) @binding(1) var<storage, read> values: array<u32>;
@group(0) @binding(2) var<storage, read> tables: array<u32>;
@group(0) @binding(3) var<storage, read_write> counts: array<vec4<u32>>;

// Order-preserving map from f32 bits to u32 (−0 and +0 map to the same key).
fn key(b: u32) -> u32 {
    var v = b;
    if ((v & 0x7fffffffu) == 0u) {
        v = 0u;
    }
    if ((v & 0x80000000u) != 0u) {
        return ~v;
    }
    return v | 0x80000000u;
}

fn inside(i: u32) -> u32 {
    let b = values[i];
    let is_nan = (b & 0x7fffffffu) > 0x7f800000u;
    return select(0u, 1u, !is_nan && key(b) < blk.iso_key);
}

// The 4 edges along one axis (bit r: offsets r & 1, r >> 1 across it) that are new in a cell,
// given whether the cell is on the block's lower face in the two other axes.
fn new_group(low1: bool, low2: bool) -> u32 {
    var m = 8u;
    if (low1) {
        m |= 4u;
    }
    if (low2) {
        m |= 2u;
    }
    if (low1 && low2) {
        m |= 1u;
    }
    return m;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let i = thread_id(wid, li, blk.groups_x);
    if (i >= blk.n) {
        return;
    }
    let p = coords(i, blk);
    if (p.x + 1u >= blk.sx || p.y + 1u >= blk.sy || p.z + 1u >= blk.sz) {
        counts[i] = vec4<u32>(0u);
        return;
    }
    let sx = blk.sx;
    let sxy = blk.sx * blk.sy;
    // Corner c at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).
    let case_ = inside(i)
        | (inside(i + 1u) << 1u)
        | (inside(i + sx) << 2u)
        | (inside(i + sx + 1u) << 3u)
        | (inside(i + sxy) << 4u)
        | (inside(i + sxy + 1u) << 5u)
        | (inside(i + sxy + sx) << 6u)
        | (inside(i + sxy + sx + 1u) << 7u);
    let info = tables[CASE_INFO + case_];
    let lx = p.x == 0u;
    let ly = p.y == 0u;
    let lz = p.z == 0u;
    let fresh = (new_group(ly, lz) | (new_group(lx, lz) << 4u) | (new_group(lx, ly) << 8u))
        & (info >> 4u);
    let act = select(0u, 1u, case_ != 0u && case_ != 255u);
    counts[i] = vec4<u32>(countOneBits(fresh), act, info & 15u, case_ | (fresh << 8u));
}
