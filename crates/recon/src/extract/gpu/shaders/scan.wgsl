// Pass 2 of GPU marching cubes (src/extract/gpu/): exclusive prefix sums, in place, of the
// first three components of `data` (the fourth is kept), so that the output position of every
// active edge, active cell and triangle is fixed by the scan, never by atomics.
//
// `scan_blocks`: workgroup `b` scans the BLOCK = 1024 items `b·BLOCK ..` (4 consecutive items
// per thread, then a Hillis–Steele scan of the 256 thread totals in workgroup memory) and
// writes the block's total to `sums[b]`. The host scans `sums` the same way (recursively,
// until one block is left, whose total is the grand total), then `add_block_sums` adds
// `sums[b]` to every item of block `b`.

struct Scan {
    n: u32,         // items in data
    groups_x: u32,  // workgroups along x of the 2D dispatch grid
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> prm: Scan;
@group(0) @binding(1) var<storage, read_write> data: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> sums: array<vec4<u32>>;

const WG: u32 = 256u;
const PER: u32 = 4u;
const BLOCK: u32 = 1024u;

var<workgroup> sh: array<vec3<u32>, 256>;

@compute @workgroup_size(256)
fn scan_blocks(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let b = wid.y * prm.groups_x + wid.x;
    let nblocks = (prm.n + BLOCK - 1u) / BLOCK;
    if (b >= nblocks) {
        return;
    }
    let base = b * BLOCK + li * PER;
    var item: array<vec4<u32>, 4>;
    var acc = vec3<u32>(0u);
    for (var k = 0u; k < PER; k++) {
        let idx = base + k;
        var v = vec4<u32>(0u);
        if (idx < prm.n) {
            v = data[idx];
        }
        item[k] = vec4<u32>(acc, v.w);
        acc += v.xyz;
    }
    sh[li] = acc;
    workgroupBarrier();
    for (var off = 1u; off < WG; off <<= 1u) {
        var t = sh[li];
        if (li >= off) {
            t += sh[li - off];
        }
        workgroupBarrier();
        sh[li] = t;
        workgroupBarrier();
    }
    var before = vec3<u32>(0u);
    if (li > 0u) {
        before = sh[li - 1u];
    }
    for (var k = 0u; k < PER; k++) {
        let idx = base + k;
        if (idx < prm.n) {
            data[idx] = vec4<u32>(item[k].xyz + before, item[k].w);
        }
    }
    if (li == WG - 1u) {
        sums[b] = vec4<u32>(sh[WG - 1u], 0u);
    }
}

@compute @workgroup_size(256)
fn add_block_sums(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let b = wid.y * prm.groups_x + wid.x;
    let nblocks = (prm.n + BLOCK - 1u) / BLOCK;
    if (b >= nblocks || b == 0u) {
        return;
    }
    let add = sums[b].xyz;
    for (var k = 0u; k < PER; k++) {
        let idx = b * BLOCK + k * WG + li;
        if (idx < prm.n) {
            let v = data[idx];
            data[idx] = vec4<u32>(v.xyz + add, v.w);
        }
    }
}
