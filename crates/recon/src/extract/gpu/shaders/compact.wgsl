// Pass 3 of GPU marching cubes (src/extract/gpu/): compact the active cells, one thread per
// node. After pass 2, counts[i].y is the number of active cells before cell i; each active
// cell writes its node index there, in cell order. Passes 4 and 5 give one thread to each.

@group(0) @binding(0) var<uniform> blk: Block;
@group(0) @binding(1) var<storage, read> counts: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> cells: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let i = thread_id(wid, li, blk.groups_x);
    if (i >= blk.n) {
        return;
    }
    let c = counts[i];
    let case_ = c.w & 255u;
    if (case_ != 0u && case_ != 255u) {
        cells[c.y] = i;
    }
}
