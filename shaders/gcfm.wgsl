// GCFM on the GPU (core/src/gpu/losses/gcfm.rs; CPU twin: style/gcfm.rs).
// Features are CHW: rendered c × n (n positions), style c × m. The joint
// scores ⟨r(x), s(y)⟩ of a chunk of rendered rows come from the GEMM; here:
// the arg-extrema per row, the per-position cosines and coefficients, the
// gradient, and the loss terms. The loss and the gradient count only the
// positions in `cells` (1 or 0; all ones for the whole frame), averaging over
// their number counts[0] (see focus.wgsl); the search runs for every row
// (argext) or, with a subset of the positions, only for those (gather,
// argext_at), and the rows outside the mask are not used.

struct GcfmParams {
    n: u32,
    m: u32,
    c: u32,
    // first rendered row of the chunk (argext)
    x0: u32,
    // rows in the chunk (argext); elements (grad)
    len: u32,
    // modality 0 RGB, 1 depth, 2 edge (stats, grad)
    modality: u32,
    // first f32 of the four scalars (reduce)
    out_off: u32,
    _pad0: u32,
    // factor on the gradient (the loss weight)
    scale: f32,
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
}

@group(0) @binding(0) var<uniform> u: GcfmParams;
@group(0) @binding(1) var<storage, read> ra: array<f32>;
@group(0) @binding(2) var<storage, read> rb: array<f32>;
@group(0) @binding(3) var<storage, read_write> matches: array<u32>;
@group(0) @binding(4) var<storage, read> rc: array<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;
@group(0) @binding(6) var<storage, read> cells: array<f32>;
@group(0) @binding(7) var<storage, read> counts: array<f32>;

// 1 / the number of covered positions (0 for none).
fn inv_count() -> f32 {
    if counts[0] > 0.0 {
        return 1.0 / counts[0];
    }
    return 0.0;
}

const EPS: f32 = 1e-8;

var<workgroup> best_v: array<f32, 256>;
var<workgroup> best_i: array<u32, 256>;
var<workgroup> worst_v: array<f32, 256>;
var<workgroup> worst_i: array<u32, 256>;

// The arg-extrema of chunk row `row` of the scores ra (len × m) scaled by
// the style's joint 1/norm rb (m): (argmax y+, argmin y−), the first index on
// ties; every thread of the workgroup calls it and gets the result.
fn row_extrema(row: u32, t: u32) -> vec2<u32> {
    var bv = -3.4e38;
    var bi = 0xffffffffu;
    var wv = 3.4e38;
    var wi = 0xffffffffu;
    for (var y = t; y < u.m; y += 256u) {
        let s = ra[row * u.m + y] * rb[y];
        if s > bv {
            bv = s;
            bi = y;
        }
        if s < wv {
            wv = s;
            wi = y;
        }
    }
    best_v[t] = bv;
    best_i[t] = bi;
    worst_v[t] = wv;
    worst_i[t] = wi;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride >>= 1u) {
        if t < stride {
            let ov = best_v[t + stride];
            let oi = best_i[t + stride];
            if ov > best_v[t] || (ov == best_v[t] && oi < best_i[t]) {
                best_v[t] = ov;
                best_i[t] = oi;
            }
            let pv = worst_v[t + stride];
            let pi = worst_i[t + stride];
            if pv < worst_v[t] || (pv == worst_v[t] && pi < worst_i[t]) {
                worst_v[t] = pv;
                worst_i[t] = pi;
            }
        }
        workgroupBarrier();
    }
    let r = vec2<u32>(min(best_i[0], u.m - 1u), min(worst_i[0], u.m - 1u));
    workgroupBarrier();
    return r;
}

// One workgroup per rendered row of the chunk: ra = scores (len × m), rb =
// the style's joint 1/norm (m). matches[x] = argmax (y+), matches[n + x] =
// argmin (y−) of the scaled scores, the first index on ties.
@compute @workgroup_size(256)
fn argext(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = row_extrema(wid.x, lid.x);
    if lid.x == 0u {
        let x = u.x0 + wid.x;
        matches[x] = r.x;
        matches[u.n + x] = r.y;
    }
}

// argext over a subset of the rendered positions (the object focus's covered
// ones): chunk row j is position rc[x0 + j] (u32 bits), whose matches it writes.
@compute @workgroup_size(256)
fn argext_at(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = row_extrema(wid.x, lid.x);
    if lid.x == 0u {
        let x = bitcast<u32>(rc[u.x0 + wid.x]);
        matches[x] = r.x;
        matches[u.n + x] = r.y;
    }
}

// The subset's columns of one modality: out (c × len) = ra (c × n) at the
// positions rc[0..len] (u32 bits), one thread per element.
@compute @workgroup_size(256)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.c * u.len {
        return;
    }
    let ch = i / u.len;
    let j = i % u.len;
    out[i] = ra[ch * u.n + bitcast<u32>(rc[j])];
}

// One thread per rendered position x of one modality: ra = rendered (c × n),
// rb = style (c × m), rc = the style's 1/(‖s‖ + ε) (m). Writes out[4x..4x+4] =
// (loss at x, α+, α−, β) with the gradient
// v(x) = −α+ s(y+) + α− s(y−) + β r(x) (CPU: style/gcfm.rs modality_loss);
// all four 0 outside the mask.
@compute @workgroup_size(256)
fn stats(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    if x >= u.n {
        return;
    }
    let o = 4u * (u.modality * u.n + x);
    if cells[x] == 0.0 {
        out[o] = 0.0;
        out[o + 1u] = 0.0;
        out[o + 2u] = 0.0;
        out[o + 3u] = 0.0;
        return;
    }
    let yb = matches[x];
    let yw = matches[u.n + x];
    var dot_b = 0.0;
    var dot_w = 0.0;
    var sq = 0.0;
    for (var ch = 0u; ch < u.c; ch++) {
        let v = ra[ch * u.n + x];
        dot_b = fma(v, rb[ch * u.m + yb], dot_b);
        dot_w = fma(v, rb[ch * u.m + yw], dot_w);
        sq = fma(v, v, sq);
    }
    let inv_n = inv_count();
    let nr = sqrt(sq);
    let ar = 1.0 / (nr + EPS);
    let sb = rc[yb];
    let sw = rc[yw];
    let cos_b = dot_b * ar * sb;
    let cos_w = dot_w * ar * sw;
    var beta = 0.0;
    if nr > 0.0 {
        beta = inv_n * (ar * ar / nr) * (dot_b * sb - dot_w * sw);
    }
    out[o] = (1.0 - cos_b) + (1.0 + cos_w);
    out[o + 1u] = inv_n * sb * ar;
    out[o + 2u] = inv_n * sw * ar;
    out[o + 3u] = beta;
}

// One thread per element (ch, x) of one modality's gradient: ra = rendered,
// rb = style, rc = the modality's stats. out = scale · v. len = c · n.
@compute @workgroup_size(256)
fn grad(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.len {
        return;
    }
    let ch = i / u.n;
    let x = i % u.n;
    let s_b = rb[ch * u.m + matches[x]];
    let s_w = rb[ch * u.m + matches[u.n + x]];
    let o = 4u * (u.modality * u.n + x);
    out[i] = u.scale * (-rc[o + 1u] * s_b + rc[o + 2u] * s_w + rc[o + 3u] * ra[i]);
}

var<workgroup> partial: array<f32, 256>;

// One workgroup: ra = the three modalities' stats (3 · n · 4). out[out_off + k]
// = the loss of modality k (mean over the covered x), out[out_off + 3] = their sum.
@compute @workgroup_size(256)
fn reduce(@builtin(local_invocation_id) lid: vec3<u32>) {
    let t = lid.x;
    var total = 0.0;
    for (var k = 0u; k < 3u; k++) {
        var acc = 0.0;
        for (var x = t; x < u.n; x += 256u) {
            acc += ra[4u * (k * u.n + x)];
        }
        partial[t] = acc;
        workgroupBarrier();
        for (var stride = 128u; stride > 0u; stride >>= 1u) {
            if t < stride {
                partial[t] += partial[t + stride];
            }
            workgroupBarrier();
        }
        let term = partial[0] * inv_count();
        total += term;
        if t == 0u {
            out[u.out_off + k] = term;
        }
        workgroupBarrier();
    }
    if t == 0u {
        out[u.out_off + 3u] = total;
    }
}
