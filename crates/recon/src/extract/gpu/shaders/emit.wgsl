// Passes 4 and 5 of GPU marching cubes (src/extract/gpu/), one thread per active cell
// (node index i = cells[t]).
//
// `vertices`: the cell writes one record per vertex that is new in it (classify.wgsl), at
// counts[i].x on, in the order of tables::case_edges: the block-local edge id 3·node + axis,
// with bit 31 set when the edge lies on a face shared with another block. Every crossing edge
// of the block gets exactly one record (Timokhin & Mikhaylyuk 2020: no vertex stored twice),
// and records come in the CPU kernel's vertex order. It also writes the bits of the edge's two
// node values to ends[at], for tiles whose field was built on the device (field.wgsl): the host
// computes the position from them with the CPU's formula.
//
// `triangles`: the cell writes the triangles of its case, in table order, from triangle
// counts[i].z on, as indices into the records: the vertex of an edge is found in the edge's
// first cell f, at counts[f].x + (new edges of f before it in f's case_edges order).

@group(0) @binding(0) var<uniform> blk: Block;
@group(0) @binding(1) var<storage, read> counts: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> cells: array<u32>;
@group(0) @binding(3) var<storage, read> tables: array<u32>;
@group(0) @binding(4) var<storage, read_write> out: array<u32>;
// `vertices` only.
@group(0) @binding(5) var<storage, read> values: array<u32>;
@group(0) @binding(6) var<storage, read_write> ends: array<vec2<u32>>;

// Whether the edge from node p along `axis` lies on a face shared with another block.
fn on_seam(p: vec3<u32>, axis: u32) -> bool {
    let hi = vec3<u32>(blk.sx - 1u, blk.sy - 1u, blk.sz - 1u);
    var s = false;
    for (var d = 0u; d < 3u; d++) {
        if (d != axis) {
            s = s || (p[d] == 0u && (blk.seam_mask & (1u << (2u * d))) != 0u);
            s = s || (p[d] == hi[d] && (blk.seam_mask & (2u << (2u * d))) != 0u);
        }
    }
    return s;
}

@compute @workgroup_size(256)
fn vertices(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let t = thread_id(wid, li, blk.groups_x);
    if (t >= blk.n) {
        return;
    }
    let i = cells[t];
    let c = counts[i];
    let case_ = c.w & 255u;
    let fresh = c.w >> 8u;
    let p = coords(i, blk);
    var at = c.x;
    for (var k = tables[USED_START + case_]; k < tables[USED_START + case_ + 1u]; k++) {
        let e = tables[k];
        if ((fresh & (1u << e)) != 0u) {
            let q = p + edge_offset(e);
            let axis = e / 4u;
            let a = index(q, blk);
            var step = 1u;
            if (axis == 1u) {
                step = blk.sx;
            } else if (axis == 2u) {
                step = blk.sx * blk.sy;
            }
            out[at] = (3u * a + axis) | select(0u, SEAM, on_seam(q, axis));
            ends[at] = vec2<u32>(values[a], values[a + step]);
            at += 1u;
        }
    }
}

@compute @workgroup_size(256)
fn triangles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let t = thread_id(wid, li, blk.groups_x);
    if (t >= blk.n) {
        return;
    }
    let i = cells[t];
    let c = counts[i];
    let case_ = c.w & 255u;
    let p = coords(i, blk);
    var at = 3u * c.z;
    for (var k = tables[case_]; k < tables[case_ + 1u]; k++) {
        let e = tables[k];
        let axis = e / 4u;
        let q = p + edge_offset(e);
        // The edge's first cell: one lower across the edge, except on the block's lower faces.
        var f = max(q, vec3<u32>(1u)) - vec3<u32>(1u);
        f[axis] = q[axis];
        let o = q - f;
        var ef = 4u * axis;
        switch (axis) {
            case 0u: {
                ef += o.y + 2u * o.z;
            }
            case 1u: {
                ef += o.x + 2u * o.z;
            }
            default: {
                ef += o.x + 2u * o.y;
            }
        }
        let cf = counts[index(f, blk)];
        let case_f = cf.w & 255u;
        let fresh_f = cf.w >> 8u;
        var id = cf.x;
        for (var m = tables[USED_START + case_f]; m < tables[USED_START + case_f + 1u]; m++) {
            let g = tables[m];
            if (g == ef) {
                break;
            }
            id += (fresh_f >> g) & 1u;
        }
        out[at] = id;
        at += 1u;
    }
}
