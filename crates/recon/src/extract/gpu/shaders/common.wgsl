// Shared by the passes of GPU marching cubes (src/extract/gpu/); prepended to each shader.

// One block (sub-block of a tile) of sx × sy × sz nodes, x fastest: node i = (z·sy + y)·sx + x.
struct Block {
    sx: u32,
    sy: u32,
    sz: u32,
    n: u32,          // threads of this pass (nodes, or active cells)
    groups_x: u32,   // workgroups along x of the 2D dispatch grid
    iso_key: u32,    // key(iso), see classify.wgsl
    seam_mask: u32,  // faces shared with another block: bit 2·axis (lower), 2·axis + 1 (upper)
    pad: u32,
}

// The case tables, one array (tables::flat_table and tables::case_edges, see gpu/passes.rs):
// [0, 257): start of case c's triangle edges (absolute index into `tables`, 3 a triangle);
// [257, 514): start of case c's crossing edges in order of first use (tables::case_edges);
// [514, 770): case c's triangle count | crossing-edge mask << 4.
const USED_START: u32 = 257u;
const CASE_INFO: u32 = 514u;

// Bit 31 of a vertex record: the edge lies on a face shared with another block.
const SEAM: u32 = 0x80000000u;

fn thread_id(wid: vec3<u32>, li: u32, groups_x: u32) -> u32 {
    return (wid.y * groups_x + wid.x) * 256u + li;
}

// Offsets (x, y, z) of the lower node of cube edge e from the cell's lowest node: edge e runs
// along axis e / 4, its offsets in the two other axes (in axis order) are the bits of e % 4
// (tables::EDGE_CORNERS).
fn edge_offset(e: u32) -> vec3<u32> {
    let u = e & 1u;
    let v = (e >> 1u) & 1u;
    switch (e / 4u) {
        case 0u: {
            return vec3<u32>(0u, u, v);
        }
        case 1u: {
            return vec3<u32>(u, 0u, v);
        }
        default: {
            return vec3<u32>(u, v, 0u);
        }
    }
}

fn coords(i: u32, b: Block) -> vec3<u32> {
    return vec3<u32>(i % b.sx, (i / b.sx) % b.sy, i / (b.sx * b.sy));
}

fn index(p: vec3<u32>, b: Block) -> u32 {
    return (p.z * b.sy + p.y) * b.sx + p.x;
}
