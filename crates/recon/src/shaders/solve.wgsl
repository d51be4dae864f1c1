// The screened leaf solve on the device, for a batch of leaves of one grid size (n³ nodes,
// n a power of two or three times one): the FFT Poisson solve and the preconditioned conjugate gradients of
// `fft_solve.rs`, every leaf's work independent of the others in the batch (see
// `gpu_solve.rs` for the order of the dispatches and what differs from the CPU).
//
// Vectors: `vecs[v * P.stride + b * P.nn + i]` for vector v (X, R, Z, P, LP, DIV), leaf b,
// node i (x fastest). Complex work grid: `cpx[b * P.nn + i]`. Per-leaf scalars:
// `scal[b * 16 + slot]` (slots in `gpu_solve.rs`). Samples (aggregates) of all leaves in one
// list: `idx[P.s_node + 8a + c]` the global node (leaf base included) of corner c of sample
// a, `sw[9a + c]` its weight, `sw[9a + 8]` the sample's γ; `sdyn[2a]` the value gathered at
// it, `sdyn[2a + 1]` its coefficient. The transposed lists: touched node t at
// `idx[P.t_node + t]`, its entries `idx[P.t_ent + e]` (8a + c) for e in
// `idx[P.t_start + t] .. idx[P.t_start + t + 1]`, in sample order.

struct Params {
    n: u32,
    // log2 of the power-of-two factor m of n = radix·m.
    log2n: u32,
    nn: u32,
    batch: u32,
    axis: u32,
    inverse: u32,
    // Bit 0: read the real vector `src` (first pass); bit 1: write the real part, scaled by
    // 1/n³, to vector `dst` (last pass).
    ends: u32,
    all: u32,
    src: u32,
    dst: u32,
    va: u32,
    vb: u32,
    mode: u32,
    slot: u32,
    count: u32,
    gx: u32,
    stride: u32,
    s_node: u32,
    s_leaf: u32,
    t_node: u32,
    t_start: u32,
    t_ent: u32,
    tw: u32,
    k2: u32,
    filt: u32,
    h1: u32,
    tol2: f32,
    shift: f32,
    max_iter: f32,
    // 1, or 3 where n = 3m.
    radix: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read_write> vecs: array<f32>;
@group(0) @binding(2) var<storage, read_write> cpx: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> consts: array<f32>;
@group(0) @binding(4) var<storage, read_write> idx: array<u32>;
@group(0) @binding(5) var<storage, read_write> sw: array<f32>;
@group(0) @binding(6) var<storage, read_write> sdyn: array<f32>;
@group(0) @binding(7) var<storage, read_write> scal: array<f32>;

const WG: u32 = 256u;
// Scalar slots (see gpu_solve.rs).
const GSUM: u32 = 0u;
const C: u32 = 1u;
const MU: u32 = 2u;
const RZ: u32 = 3u;
const RZ0: u32 = 4u;
const PLP: u32 = 5u;
const A: u32 = 6u;
const BETA: u32 = 7u;
const ACTIVE: u32 = 8u;
const ITER: u32 = 9u;
const SG: u32 = 10u;
const SGS: u32 = 11u;
const SGSS: u32 = 12u;
const RZNEW: u32 = 13u;

fn running(b: u32) -> bool {
    return P.all == 1u || scal[b * 16u + ACTIVE] > 0.5;
}

// One index of a 1D range per thread over a (gx, gy, batch) dispatch: the leaf is the z
// group, the index within it runs over x and y groups.
fn flat_index(wg: vec3<u32>, t: u32) -> u32 {
    return (wg.y * P.gx + wg.x) * WG + t;
}

var<workgroup> sh: array<vec2<f32>, 512>;
var<workgroup> go: u32;

// L = max(1, 512 / n) lines of n values along `P.axis` per workgroup (every thread one
// butterfly a stage for n ≤ 512): lines g·L .. g·L + L − 1 of leaf wg.z, g from wg.x and
// wg.y, line l running over (l mod n, l div n) of the two other axes, x before y. The last
// workgroup's lines beyond the n² of a leaf are transformed in workgroup memory only. Each
// line, n = R·m with m = 2^P.log2n and R = P.radix (1 or 3), is R radix-2
// decimation-in-time FFTs of length m in workgroup memory, of the nodes i ≡ r (mod R) each
// (bit-reversed loads, log2 m stages), then for R = 3 one radix-3 stage that combines them:
// X[k + qm] = Σ_r ω^{rk} F_r[k] ω₃^{rq}. The twiddles exp(∓2πik/n), k < n, are tabulated on
// the host in f64. Loads and stores of lines along y and z go line-fastest, so neighbouring
// threads touch neighbouring x.
@compute @workgroup_size(256)
fn fft(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let b = wg.z;
    if t == 0u {
        go = select(0u, 1u, running(b));
    }
    if workgroupUniformLoad(&go) == 0u {
        return;
    }
    let n = P.n;
    let lines = max(1u, 512u / n);
    let first = (wg.y * P.gx + wg.x) * lines;
    // A 2D grid of workgroups may have more than the n² / L needed.
    if first >= n * n {
        return;
    }
    let radix = P.radix;
    let m = n / radix;
    let shift = 32u - P.log2n;
    let total = lines * n;
    for (var e = t; e < total; e += WG) {
        let ji = line_element(e, lines);
        let j = ji.x;
        let i = ji.y;
        if first + j >= n * n {
            continue;
        }
        let at = line_at(b, first + j, i);
        var v: vec2<f32>;
        if (P.ends & 1u) != 0u {
            v = vec2<f32>(vecs[P.src * P.stride + at], 0.0);
        } else {
            v = cpx[at];
        }
        sh[j * n + (i % radix) * m + (reverseBits(i / radix) >> shift)] = v;
    }
    workgroupBarrier();
    let sign = select(1.0, -1.0, P.inverse == 1u);
    let halfm = m / 2u;
    let halfn = n / 2u;
    for (var s = 1u; s <= P.log2n; s++) {
        let half = 1u << (s - 1u);
        // Twiddle k of this stage: exp(∓2πik/2^s), entry k·n/2^s of the table.
        let stride = n >> s;
        for (var q = t; q < lines * halfn; q += WG) {
            let j = q / halfn;
            let bq = q % halfn;
            let blk = bq / halfm;
            let bf = bq % halfm;
            let k = bf & (half - 1u);
            let i0 = j * n + blk * m + ((bf >> (s - 1u)) << s) + k;
            let i1 = i0 + half;
            let ti = P.tw + 2u * (k * stride);
            let w = vec2<f32>(consts[ti], sign * consts[ti + 1u]);
            let u = sh[i0];
            let x = sh[i1];
            let v = vec2<f32>(x.x * w.x - x.y * w.y, x.x * w.y + x.y * w.x);
            sh[i0] = u + v;
            sh[i1] = u - v;
        }
        workgroupBarrier();
    }
    if radix == 3u {
        // ω₃ = exp(∓2πi/3): entry m of the table.
        let w3 = vec2<f32>(consts[P.tw + 2u * m], sign * consts[P.tw + 2u * m + 1u]);
        for (var q = t; q < lines * m; q += WG) {
            let j = q / m;
            let k = q % m;
            let i0 = j * n + k;
            let t1 = P.tw + 2u * k;
            let t2 = P.tw + 2u * (2u * k);
            let w1 = vec2<f32>(consts[t1], sign * consts[t1 + 1u]);
            let w2 = vec2<f32>(consts[t2], sign * consts[t2 + 1u]);
            let f0 = sh[i0];
            let f1 = cmul(sh[i0 + m], w1);
            let f2 = cmul(sh[i0 + 2u * m], w2);
            let a1 = cmul(f1, w3);
            let a2 = cmul(f2, w3);
            sh[i0] = f0 + f1 + f2;
            sh[i0 + m] = f0 + a1 + cmul(a2, w3);
            sh[i0 + 2u * m] = f0 + cmul(a1, w3) + a2;
        }
        workgroupBarrier();
    }
    let scale = 1.0 / f32(P.nn);
    for (var e = t; e < total; e += WG) {
        let ji = line_element(e, lines);
        let j = ji.x;
        let i = ji.y;
        if first + j >= n * n {
            continue;
        }
        let at = line_at(b, first + j, i);
        if (P.ends & 2u) != 0u {
            vecs[P.dst * P.stride + at] = sh[j * n + i].x * scale;
        } else {
            cpx[at] = sh[j * n + i];
        }
    }
}

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// Element e of a workgroup's lines as (line, node): lines along x node-fastest, lines along
// y and z line-fastest (neighbouring lines are neighbouring x).
fn line_element(e: u32, lines: u32) -> vec2<u32> {
    if P.axis == 0u {
        return vec2<u32>(e / P.n, e % P.n);
    }
    return vec2<u32>(e % lines, e / lines);
}

// Node i of line l (of n²) along `P.axis` in leaf b.
fn line_at(b: u32, l: u32, i: u32) -> u32 {
    let n = P.n;
    let l0 = l % n;
    let l1 = l / n;
    var at: u32;
    if P.axis == 0u {
        at = (l1 * n + l0) * n + i;
    } else if P.axis == 1u {
        at = (l1 * n + i) * n + l0;
    } else {
        at = (i * n + l1) * n + l0;
    }
    return b * P.nn + at;
}

fn fold(m: u32) -> u32 {
    return select(P.n - m, m, m <= P.n / 2u);
}

// The spectrum times the Poisson filter (mode 0: the table, zero at k = 0) or the
// preconditioner 1/(|k|² + μ) (mode 1).
@compute @workgroup_size(256)
fn mul(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let b = wg.z;
    let i = flat_index(wg, t);
    if i >= P.nn || !running(b) {
        return;
    }
    let n = P.n;
    let fx = fold(i % n);
    let fy = fold((i / n) % n);
    let fz = fold(i / (n * n));
    var m: f32;
    if P.mode == 0u {
        m = consts[P.filt + (fz * P.h1 + fy) * P.h1 + fx];
    } else {
        m = 1.0 / (consts[P.k2 + fz] + consts[P.k2 + fy] + consts[P.k2 + fx] + scal[b * 16u + MU]);
    }
    let at = b * P.nn + i;
    cpx[at] = cpx[at] * m;
}

// Element-wise vector updates of leaf wg.z. Mode 0: R = 0. Mode 1: P = Z, LP = R − μZ.
// Mode 2: X += aP, R −= a·LP. Mode 3: P = Z + βP, LP = (R − μZ) + β·LP.
@compute @workgroup_size(256)
fn vop(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let b = wg.z;
    let i = flat_index(wg, t);
    if i >= P.nn || !running(b) {
        return;
    }
    let s = P.stride;
    let at = b * P.nn + i;
    let sc = b * 16u;
    let xi = at;
    let ri = s + at;
    let zi = 2u * s + at;
    let pi = 3u * s + at;
    let li = 4u * s + at;
    if P.mode == 0u {
        vecs[ri] = 0.0;
    } else if P.mode == 1u {
        vecs[pi] = vecs[zi];
        vecs[li] = vecs[ri] - scal[sc + MU] * vecs[zi];
    } else if P.mode == 2u {
        let a = scal[sc + A];
        vecs[xi] = vecs[xi] + a * vecs[pi];
        vecs[ri] = vecs[ri] - a * vecs[li];
    } else {
        let beta = scal[sc + BETA];
        let mu = scal[sc + MU];
        let z = vecs[zi];
        vecs[pi] = z + beta * vecs[pi];
        vecs[li] = (vecs[ri] - mu * z) + beta * vecs[li];
    }
}

// Per sample (all leaves): the vector `src` interpolated at it.
@compute @workgroup_size(256)
fn gather(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let a = flat_index(wg, t);
    if a >= P.count {
        return;
    }
    let first = idx[P.s_node + 8u * a];
    if !running(first / P.nn) {
        return;
    }
    var s = 0.0;
    for (var c = 0u; c < 8u; c++) {
        s += sw[9u * a + c] * vecs[P.src * P.stride + idx[P.s_node + 8u * a + c]];
    }
    sdyn[2u * a] = s;
}

// Per sample: its coefficient. Mode 0: −γ(s − c). Mode 1: −aγs.
@compute @workgroup_size(256)
fn coef(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let a = flat_index(wg, t);
    if a >= P.count {
        return;
    }
    let b = idx[P.s_node + 8u * a] / P.nn;
    if !running(b) {
        return;
    }
    let g = sw[9u * a + 8u];
    let s = sdyn[2u * a];
    if P.mode == 0u {
        sdyn[2u * a + 1u] = -g * (s - scal[b * 16u + C]);
    } else {
        sdyn[2u * a + 1u] = -scal[b * 16u + A] * g * s;
    }
}

// Per touched node: R += Σ coefficient · weight over its entries, in sample order.
@compute @workgroup_size(256)
fn scatter(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let k = flat_index(wg, t);
    if k >= P.count {
        return;
    }
    let node = idx[P.t_node + k];
    if !running(node / P.nn) {
        return;
    }
    var acc = 0.0;
    for (var e = idx[P.t_start + k]; e < idx[P.t_start + k + 1u]; e++) {
        let ent = idx[P.t_ent + e];
        acc += sdyn[2u * (ent >> 3u) + 1u] * sw[9u * (ent >> 3u) + (ent & 7u)];
    }
    vecs[P.stride + node] = vecs[P.stride + node] + acc;
}

var<workgroup> red: array<vec3<f32>, 256>;

// Tree sum of `red` into red[0].
fn reduce(t: u32) {
    for (var w = WG / 2u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if t < w {
            red[t] += red[t + w];
        }
    }
    workgroupBarrier();
}

// Σ va·vb over leaf wg.z's nodes, in two passes with fixed orders: workgroup wg.x of
// G = P.count sums the nodes of its chunk of ⌈n³/G⌉ into partial `P.batch·16 + b·G + g`,
// then `vsum` adds a leaf's G partials in order into slot P.slot.
@compute @workgroup_size(256)
fn vdot(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let b = wg.z;
    if t == 0u {
        go = select(0u, 1u, running(b));
    }
    if workgroupUniformLoad(&go) == 0u {
        return;
    }
    let chunk = (P.nn + P.count - 1u) / P.count;
    let lo = wg.x * chunk;
    let hi = min(lo + chunk, P.nn);
    let oa = P.va * P.stride + b * P.nn;
    let ob = P.vb * P.stride + b * P.nn;
    var acc = 0.0;
    for (var i = lo + t; i < hi; i += WG) {
        acc += vecs[oa + i] * vecs[ob + i];
    }
    red[t] = vec3<f32>(acc, 0.0, 0.0);
    reduce(t);
    if t == 0u {
        scal[P.batch * 16u + b * P.count + wg.x] = red[0].x;
    }
}

@compute @workgroup_size(64)
fn vsum(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    if b >= P.batch || !running(b) {
        return;
    }
    var acc = 0.0;
    for (var g = 0u; g < P.count; g++) {
        acc += scal[P.batch * 16u + b * P.count + g];
    }
    scal[b * 16u + P.slot] = acc;
}

// One workgroup per leaf: Σγ, Σγs, Σγs² over its samples.
@compute @workgroup_size(256)
fn ssum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let b = wg.x;
    if t == 0u {
        go = select(0u, 1u, running(b));
    }
    if workgroupUniformLoad(&go) == 0u {
        return;
    }
    var acc = vec3<f32>(0.0);
    for (var a = idx[P.s_leaf + b] + t; a < idx[P.s_leaf + b + 1u]; a += WG) {
        let g = sw[9u * a + 8u];
        let s = sdyn[2u * a];
        acc += vec3<f32>(g, g * s, g * s * s);
    }
    red[t] = acc;
    reduce(t);
    if t == 0u {
        scal[b * 16u + SG] = red[0].x;
        scal[b * 16u + SGS] = red[0].y;
        scal[b * 16u + SGSS] = red[0].z;
    }
}

// One thread per leaf: the conjugate gradients' scalars. Mode 0 (after the unscreened solve
// and a gather of it): Σγ, the constant c, the shift μ; a leaf without samples ends here.
// Mode 1 (after Z = M⁻¹R and RZNEW = R·Z): the start. Mode 2 (after PLP = P·LP and the sums
// of a gather of P): the step a, or the end when the curvature is not positive. Mode 3
// (after RZNEW): β, and the end when the residual has fallen enough or the iterations ran
// out.
@compute @workgroup_size(64)
fn scalars(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    if b >= P.batch {
        return;
    }
    let s = b * 16u;
    if P.mode == 0u {
        let gsum = scal[s + SG];
        scal[s + GSUM] = gsum;
        if gsum > 0.0 {
            scal[s + C] = scal[s + SGS] / gsum;
            scal[s + MU] = P.shift * gsum / f32(P.nn);
            scal[s + ACTIVE] = 1.0;
        } else {
            scal[s + ACTIVE] = 0.0;
        }
        scal[s + ITER] = 0.0;
        return;
    }
    if scal[s + ACTIVE] < 0.5 {
        return;
    }
    if P.mode == 1u {
        let rz = scal[s + RZNEW];
        scal[s + RZ] = rz;
        scal[s + RZ0] = rz;
        scal[s + ACTIVE] = select(0.0, 1.0, rz > P.tol2 * rz && P.max_iter > 0.0);
    } else if P.mode == 2u {
        let pap = scal[s + PLP] + scal[s + SGSS];
        if pap > 0.0 {
            scal[s + A] = scal[s + RZ] / pap;
        } else {
            scal[s + ACTIVE] = 0.0;
        }
    } else {
        let rz = scal[s + RZNEW];
        scal[s + BETA] = rz / scal[s + RZ];
        scal[s + RZ] = rz;
        let it = scal[s + ITER] + 1.0;
        scal[s + ITER] = it;
        scal[s + ACTIVE] = select(0.0, 1.0, rz > P.tol2 * scal[s + RZ0] && it < P.max_iter);
    }
}
