// Pass 0 of GPU marching cubes on a blended tile (src/extract/field.rs, src/extract/gpu/): the
// partition-of-unity field at the nodes of one sub-block, one thread per node, written where
// classify.wgsl reads it. Bit for bit Blend::eval: the blend is exact 64-bit integer
// arithmetic on fixed-point values; the one conversion to f32 is of an integer below 2^24,
// scaled by a power of two, both exact.

struct Field {
    sx: u32,        // sub-block nodes per axis
    sy: u32,
    sz: u32,
    n: u32,         // sub-block nodes
    groups_x: u32,
    ax: u32,        // sub-block offset in the tile, per axis
    ay: u32,
    az: u32,
    lox: i32,       // global node of the tile's node 0
    loy: i32,
    loz: i32,
    e: i32,         // leaf edge, overlap, detail nodes per axis
    ov: i32,
    dm: u32,
    cmx: i32,       // first leaf cell of the lookup box, per axis
    cmy: i32,
    cmz: i32,
    tx: u32,        // lookup box cells per axis
    ty: u32,
    tz: u32,
    cdx: u32,       // coarse sub-grid nodes along x and y
    cdy: u32,
    offy: u32,      // start of the y and z axis tables in `axes`
    offz: u32,
    unit: f32,      // the fixed-point unit, a power of two
    cshift: u32,    // shift of the coarse sum: 3·(WEIGHT_BITS − coarse_bits)
    slot_words: u32, // words of a pool slot: dm³ 16-bit details, two a word
    pad1: u32,
}

// field.rs WEIGHT_BITS, three axes.
const WEIGHT_SHIFT: u32 = 30u;
// field.rs FIELD_LIMIT.
const FIELD_LIMIT: i32 = 16777215;

@group(0) @binding(0) var<uniform> prm: Field;
// Per tile node and axis: (lower coarse node, its weight, the upper node's weight, 0).
@group(0) @binding(1) var<storage, read> axes: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> coarse: array<i32>;
@group(0) @binding(3) var<storage, read> own: array<i32>;
// Per leaf cell of the lookup box: its pool slot | its exponent << 24, 0xffffffff where there
// is no leaf.
@group(0) @binding(4) var<storage, read> slots: array<u32>;
// Leaf details, 16 bits each, two a word (the lower half first), slot_words a slot.
@group(0) @binding(5) var<storage, read> pool: array<u32>;
@group(0) @binding(6) var<storage, read_write> values: array<f32>;

const NONE: u32 = 0xffffffffu;

// The leaf cells (at most two) whose detail offset s = g − (e·c − ov) lies in 1..=dm−2 (the
// weights at 0 and dm−1 are zero), as (lowest cell, count, s of the lowest); g >= 0.
fn candidates(g: i32) -> vec3<i32> {
    let hi = (g + prm.ov - 1) / prm.e;
    let dm2 = i32(prm.dm) - 2;
    var lo = hi;
    if (g - (prm.e * (hi - 1) - prm.ov) <= dm2) {
        lo = hi - 1;
    }
    return vec3<i32>(lo, hi - lo + 1, g - (prm.e * lo - prm.ov));
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let i = (wid.y * prm.groups_x + wid.x) * 256u + li;
    if (i >= prm.n) {
        return;
    }
    // Tile node of this sub-block node.
    let t = vec3<u32>(
        i % prm.sx + prm.ax,
        (i / prm.sx) % prm.sy + prm.ay,
        i / (prm.sx * prm.sy) + prm.az,
    );
    let tabx = axes[t.x];
    let taby = axes[prm.offy + t.y];
    let tabz = axes[prm.offz + t.z];
    var wx = array<i64, 2>(i64(i32(tabx.y)), i64(i32(tabx.z)));
    var wy = array<i64, 2>(i64(i32(taby.y)), i64(i32(taby.z)));
    var wz = array<i64, 2>(i64(i32(tabz.y)), i64(i32(tabz.z)));
    var c = i64(0);
    for (var k = 0u; k < 8u; k++) {
        let dx = k & 1u;
        let dy = (k >> 1u) & 1u;
        let dz = k >> 2u;
        let ci = ((tabz.x + dz) * prm.cdy + taby.x + dy) * prm.cdx + tabx.x + dx;
        c += wz[dz] * wy[dy] * wx[dx] * i64(coarse[ci]);
    }
    let g = vec3<i32>(i32(t.x) + prm.lox, i32(t.y) + prm.loy, i32(t.z) + prm.loz);
    let kx = candidates(g.x);
    let ky = candidates(g.y);
    let kz = candidates(g.z);
    let dm = prm.dm;
    var acc = i64(0);
    for (var jz = 0; jz < kz.y; jz++) {
        let cz = u32(kz.x + jz - prm.cmz);
        let sz = u32(kz.z - jz * prm.e);
        for (var jy = 0; jy < ky.y; jy++) {
            let cy = u32(ky.x + jy - prm.cmy);
            let sy = u32(ky.z - jy * prm.e);
            let wzy = i64(own[sz]) * i64(own[sy]);
            for (var jx = 0; jx < kx.y; jx++) {
                let cx = u32(kx.x + jx - prm.cmx);
                let entry = slots[(cz * prm.ty + cy) * prm.tx + cx];
                if (entry != NONE) {
                    let sx = u32(kx.z - jx * prm.e);
                    let k = (sz * dm + sy) * dm + sx;
                    let word = pool[(entry & 0xffffffu) * prm.slot_words + k / 2u];
                    // The 16-bit half, sign-extended.
                    let d = bitcast<i32>(select(word << 16u, word & 0xffff0000u, (k & 1u) == 1u)) >> 16u;
                    acc += wzy * i64(own[sx]) * (i64(d) << (entry >> 24u));
                }
            }
        }
    }
    let n = ((c << prm.cshift) + acc) >> WEIGHT_SHIFT;
    let m = i32(clamp(n, i64(-FIELD_LIMIT), i64(FIELD_LIMIT)));
    values[i] = f32(m) * prm.unit;
}
