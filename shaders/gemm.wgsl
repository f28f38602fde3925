// Tiled f32 matrix product with strides (core/src/gpu/ops/gemm.rs; CPU twin:
// vision/conv.rs `matmul`).
//
//   C(i, j) = act(alpha · Σ_p A(i, p) · B(p, j) + [C(i, j)] + [bias(i)])
//
// with A(i, p) = a[a_off + i·a_rs + p·a_cs], B(p, j) = b[b_off + p·b_rs + j·b_cs],
// C(i, j) = c[c_off + i·c_rs + j]: the strides express A·B, Aᵀ·B and A·Bᵀ.
// Batches run along workgroup z with per-batch offsets `*_bs`.
// `gemm`: a 64×64 block of C per workgroup of 16×16 threads, 4×4 outputs
// per thread (rows 4·ty + q, columns 4·tx + q), K in slices of 16 staged in
// workgroup memory. `gemm_wide`: a 128×128 block, 8×8 outputs per thread
// (rows and columns in two runs of four, 4·t + q and 64 + 4·t + q), K in
// slices of 8: twice the multiply-adds per value read from workgroup
// memory, for products large enough to fill the device with its four times
// fewer workgroups. Both read workgroup memory as vec4s (a thread's four
// consecutive rows or columns in one 16-byte read, where the earlier
// layout, rows ty + 16·q, took four 4-byte ones) and issue the next slice's
// global loads before the current slice's multiply-adds.

struct GemmParams {
    m: u32,
    n: u32,
    k: u32,
    a_off: u32,
    a_rs: u32,
    a_cs: u32,
    b_off: u32,
    b_rs: u32,
    b_cs: u32,
    c_off: u32,
    c_rs: u32,
    bias_off: u32,
    a_bs: u32,
    b_bs: u32,
    c_bs: u32,
    // bit 0: add the old C; bit 1: add bias(i); bit 2: ReLU.
    flags: u32,
    alpha: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> u: GemmParams;
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read> bias: array<f32>;
@group(0) @binding(4) var<storage, read_write> c: array<f32>;

const TM: u32 = 64u;
const TN: u32 = 64u;
const TK: u32 = 16u;

// [TK][TM] as vec4s: element (p, i) is As[p·16 + i/4][i % 4].
var<workgroup> As: array<vec4<f32>, 256>;
var<workgroup> Bs: array<vec4<f32>, 256>;

@compute @workgroup_size(16, 16)
fn gemm(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let tx = lid.x;
    let ty = lid.y;
    let t = ty * 16u + tx;
    let i0 = wid.y * TM;
    let j0 = wid.x * TN;
    let a_base = u.a_off + wid.z * u.a_bs;
    let b_base = u.b_off + wid.z * u.b_bs;
    let c_base = u.c_off + wid.z * u.c_bs;
    // A is usually contiguous along p (rows of weights) or along i (transposed):
    // load so that neighbouring threads read neighbouring addresses.
    let a_along_i = u.a_rs == 1u;
    let b_along_j = u.b_cs == 1u;

    // Rows 4·ty + qi in acc{qi}, columns 4·tx + qj in its components:
    // registers, no indexed private arrays (which software rasterizers
    // spill to memory).
    var acc0 = vec4<f32>(0.0);
    var acc1 = vec4<f32>(0.0);
    var acc2 = vec4<f32>(0.0);
    var acc3 = vec4<f32>(0.0);
    // The slice's elements this thread stages (t + 256·r, r = 0..3), read
    // from global memory a slice ahead.
    let ea0 = slice_at(t, a_along_i, TK, TM);
    let ea1 = slice_at(t + 256u, a_along_i, TK, TM);
    let ea2 = slice_at(t + 512u, a_along_i, TK, TM);
    let ea3 = slice_at(t + 768u, a_along_i, TK, TM);
    let eb0 = slice_at(t, b_along_j, TK, TN);
    let eb1 = slice_at(t + 256u, b_along_j, TK, TN);
    let eb2 = slice_at(t + 512u, b_along_j, TK, TN);
    let eb3 = slice_at(t + 768u, b_along_j, TK, TN);
    var pa0 = a_at(a_base, i0 + ea0.y, ea0.x);
    var pa1 = a_at(a_base, i0 + ea1.y, ea1.x);
    var pa2 = a_at(a_base, i0 + ea2.y, ea2.x);
    var pa3 = a_at(a_base, i0 + ea3.y, ea3.x);
    var pb0 = b_at(b_base, eb0.x, j0 + eb0.y);
    var pb1 = b_at(b_base, eb1.x, j0 + eb1.y);
    var pb2 = b_at(b_base, eb2.x, j0 + eb2.y);
    var pb3 = b_at(b_base, eb3.x, j0 + eb3.y);
    let tiles = (u.k + TK - 1u) / TK;
    for (var kt = 0u; kt < tiles; kt++) {
        As[ea0.x * 16u + ea0.y / 4u][ea0.y % 4u] = pa0;
        As[ea1.x * 16u + ea1.y / 4u][ea1.y % 4u] = pa1;
        As[ea2.x * 16u + ea2.y / 4u][ea2.y % 4u] = pa2;
        As[ea3.x * 16u + ea3.y / 4u][ea3.y % 4u] = pa3;
        Bs[eb0.x * 16u + eb0.y / 4u][eb0.y % 4u] = pb0;
        Bs[eb1.x * 16u + eb1.y / 4u][eb1.y % 4u] = pb1;
        Bs[eb2.x * 16u + eb2.y / 4u][eb2.y % 4u] = pb2;
        Bs[eb3.x * 16u + eb3.y / 4u][eb3.y % 4u] = pb3;
        workgroupBarrier();
        let p1 = (kt + 1u) * TK;
        if kt + 1u < tiles {
            pa0 = a_at(a_base, i0 + ea0.y, p1 + ea0.x);
            pa1 = a_at(a_base, i0 + ea1.y, p1 + ea1.x);
            pa2 = a_at(a_base, i0 + ea2.y, p1 + ea2.x);
            pa3 = a_at(a_base, i0 + ea3.y, p1 + ea3.x);
            pb0 = b_at(b_base, p1 + eb0.x, j0 + eb0.y);
            pb1 = b_at(b_base, p1 + eb1.x, j0 + eb1.y);
            pb2 = b_at(b_base, p1 + eb2.x, j0 + eb2.y);
            pb3 = b_at(b_base, p1 + eb3.x, j0 + eb3.y);
        }
        for (var p = 0u; p < TK; p++) {
            let av = As[p * 16u + ty];
            let bv = Bs[p * 16u + tx];
            acc0 = fma(vec4<f32>(av.x), bv, acc0);
            acc1 = fma(vec4<f32>(av.y), bv, acc1);
            acc2 = fma(vec4<f32>(av.z), bv, acc2);
            acc3 = fma(vec4<f32>(av.w), bv, acc3);
        }
        workgroupBarrier();
    }
    let gi = i0 + 4u * ty;
    let gj = j0 + 4u * tx;
    store_quad(gi, gj, c_base, acc0);
    store_quad(gi + 1u, gj, c_base, acc1);
    store_quad(gi + 2u, gj, c_base, acc2);
    store_quad(gi + 3u, gj, c_base, acc3);
}

const WM: u32 = 128u;
const WK: u32 = 8u;

// [WK][WM] as vec4s: element (p, i) is Aw[p·32 + i/4][i % 4], so a thread
// reads its four consecutive rows (or columns) in one 16-byte load.
var<workgroup> Aw: array<vec4<f32>, 256>;
var<workgroup> Bw: array<vec4<f32>, 256>;

@compute @workgroup_size(16, 16)
fn gemm_wide(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let tx = lid.x;
    let ty = lid.y;
    let t = ty * 16u + tx;
    let i0 = wid.y * WM;
    let j0 = wid.x * WM;
    let a_base = u.a_off + wid.z * u.a_bs;
    let b_base = u.b_off + wid.z * u.b_bs;
    let c_base = u.c_off + wid.z * u.c_bs;
    let a_along_i = u.a_rs == 1u;
    let b_along_j = u.b_cs == 1u;

    // This thread's rows are 4·ty + q and 64 + 4·ty + q, its columns
    // 4·tx + q and 64 + 4·tx + q (q = 0..3): row qi in r{qi}l (the low
    // columns) and r{qi}h (the high ones), rows 0..3 low, 4..7 high.
    var r0l = vec4<f32>(0.0);
    var r0h = vec4<f32>(0.0);
    var r1l = vec4<f32>(0.0);
    var r1h = vec4<f32>(0.0);
    var r2l = vec4<f32>(0.0);
    var r2h = vec4<f32>(0.0);
    var r3l = vec4<f32>(0.0);
    var r3h = vec4<f32>(0.0);
    var r4l = vec4<f32>(0.0);
    var r4h = vec4<f32>(0.0);
    var r5l = vec4<f32>(0.0);
    var r5h = vec4<f32>(0.0);
    var r6l = vec4<f32>(0.0);
    var r6h = vec4<f32>(0.0);
    var r7l = vec4<f32>(0.0);
    var r7h = vec4<f32>(0.0);
    // The slice's elements this thread stages (t + 256·r, r = 0..3), read
    // from global memory one slice ahead so the loads run under the
    // multiply-adds of the slice before.
    let ea0 = slice_at(t, a_along_i, WK, WM);
    let ea1 = slice_at(t + 256u, a_along_i, WK, WM);
    let ea2 = slice_at(t + 512u, a_along_i, WK, WM);
    let ea3 = slice_at(t + 768u, a_along_i, WK, WM);
    let eb0 = slice_at(t, b_along_j, WK, WM);
    let eb1 = slice_at(t + 256u, b_along_j, WK, WM);
    let eb2 = slice_at(t + 512u, b_along_j, WK, WM);
    let eb3 = slice_at(t + 768u, b_along_j, WK, WM);
    var pa0 = a_at(a_base, i0 + ea0.y, ea0.x);
    var pa1 = a_at(a_base, i0 + ea1.y, ea1.x);
    var pa2 = a_at(a_base, i0 + ea2.y, ea2.x);
    var pa3 = a_at(a_base, i0 + ea3.y, ea3.x);
    var pb0 = b_at(b_base, eb0.x, j0 + eb0.y);
    var pb1 = b_at(b_base, eb1.x, j0 + eb1.y);
    var pb2 = b_at(b_base, eb2.x, j0 + eb2.y);
    var pb3 = b_at(b_base, eb3.x, j0 + eb3.y);
    let tiles = (u.k + WK - 1u) / WK;
    for (var kt = 0u; kt < tiles; kt++) {
        Aw[ea0.x * 32u + ea0.y / 4u][ea0.y % 4u] = pa0;
        Aw[ea1.x * 32u + ea1.y / 4u][ea1.y % 4u] = pa1;
        Aw[ea2.x * 32u + ea2.y / 4u][ea2.y % 4u] = pa2;
        Aw[ea3.x * 32u + ea3.y / 4u][ea3.y % 4u] = pa3;
        Bw[eb0.x * 32u + eb0.y / 4u][eb0.y % 4u] = pb0;
        Bw[eb1.x * 32u + eb1.y / 4u][eb1.y % 4u] = pb1;
        Bw[eb2.x * 32u + eb2.y / 4u][eb2.y % 4u] = pb2;
        Bw[eb3.x * 32u + eb3.y / 4u][eb3.y % 4u] = pb3;
        workgroupBarrier();
        let p1 = (kt + 1u) * WK;
        if kt + 1u < tiles {
            pa0 = a_at(a_base, i0 + ea0.y, p1 + ea0.x);
            pa1 = a_at(a_base, i0 + ea1.y, p1 + ea1.x);
            pa2 = a_at(a_base, i0 + ea2.y, p1 + ea2.x);
            pa3 = a_at(a_base, i0 + ea3.y, p1 + ea3.x);
            pb0 = b_at(b_base, p1 + eb0.x, j0 + eb0.y);
            pb1 = b_at(b_base, p1 + eb1.x, j0 + eb1.y);
            pb2 = b_at(b_base, p1 + eb2.x, j0 + eb2.y);
            pb3 = b_at(b_base, p1 + eb3.x, j0 + eb3.y);
        }
        for (var p = 0u; p < WK; p++) {
            let al = Aw[p * 32u + ty];
            let ah = Aw[p * 32u + 16u + ty];
            let bl = Bw[p * 32u + tx];
            let bh = Bw[p * 32u + 16u + tx];
            r0l = fma(vec4<f32>(al.x), bl, r0l);
            r0h = fma(vec4<f32>(al.x), bh, r0h);
            r1l = fma(vec4<f32>(al.y), bl, r1l);
            r1h = fma(vec4<f32>(al.y), bh, r1h);
            r2l = fma(vec4<f32>(al.z), bl, r2l);
            r2h = fma(vec4<f32>(al.z), bh, r2h);
            r3l = fma(vec4<f32>(al.w), bl, r3l);
            r3h = fma(vec4<f32>(al.w), bh, r3h);
            r4l = fma(vec4<f32>(ah.x), bl, r4l);
            r4h = fma(vec4<f32>(ah.x), bh, r4h);
            r5l = fma(vec4<f32>(ah.y), bl, r5l);
            r5h = fma(vec4<f32>(ah.y), bh, r5h);
            r6l = fma(vec4<f32>(ah.z), bl, r6l);
            r6h = fma(vec4<f32>(ah.z), bh, r6h);
            r7l = fma(vec4<f32>(ah.w), bl, r7l);
            r7h = fma(vec4<f32>(ah.w), bh, r7h);
        }
        workgroupBarrier();
    }
    let gi = i0 + 4u * ty;
    let gj = j0 + 4u * tx;
    store_quad(gi, gj, c_base, r0l);
    store_quad(gi, gj + 64u, c_base, r0h);
    store_quad(gi + 1u, gj, c_base, r1l);
    store_quad(gi + 1u, gj + 64u, c_base, r1h);
    store_quad(gi + 2u, gj, c_base, r2l);
    store_quad(gi + 2u, gj + 64u, c_base, r2h);
    store_quad(gi + 3u, gj, c_base, r3l);
    store_quad(gi + 3u, gj + 64u, c_base, r3h);
    store_quad(gi + 64u, gj, c_base, r4l);
    store_quad(gi + 64u, gj + 64u, c_base, r4h);
    store_quad(gi + 65u, gj, c_base, r5l);
    store_quad(gi + 65u, gj + 64u, c_base, r5h);
    store_quad(gi + 66u, gj, c_base, r6l);
    store_quad(gi + 66u, gj + 64u, c_base, r6h);
    store_quad(gi + 67u, gj, c_base, r7l);
    store_quad(gi + 67u, gj + 64u, c_base, r7h);
}

// Element `e` of a `tk × tm` slice as (p, i): consecutive `e` walk i when the
// matrix is contiguous along it (`along`), else p.
fn slice_at(e: u32, along: bool, tk: u32, tm: u32) -> vec2<u32> {
    if along {
        return vec2<u32>(e / tm, e % tm);
    }
    return vec2<u32>(e % tk, e / tk);
}

// A(i, p) of the batch at `base`, 0 outside the matrix.
fn a_at(base: u32, i: u32, p: u32) -> f32 {
    if i < u.m && p < u.k {
        return a[base + i * u.a_rs + p * u.a_cs];
    }
    return 0.0;
}

// B(p, j) of the batch at `base`, 0 outside the matrix.
fn b_at(base: u32, p: u32, j: u32) -> f32 {
    if j < u.n && p < u.k {
        return b[base + p * u.b_rs + j * u.b_cs];
    }
    return 0.0;
}

// The epilogue of four consecutive columns gj0 .. gj0 + 3 of row gi.
fn store_quad(gi: u32, gj0: u32, c_base: u32, v: vec4<f32>) {
    if gi >= u.m {
        return;
    }
    store(gi, gj0, c_base, v.x);
    store(gi, gj0 + 1u, c_base, v.y);
    store(gi, gj0 + 2u, c_base, v.z);
    store(gi, gj0 + 3u, c_base, v.w);
}

fn store(gi: u32, gj: u32, c_base: u32, acc: f32) {
    if gj >= u.n {
        return;
    }
    let at = c_base + gi * u.c_rs + gj;
    var v = u.alpha * acc;
    if (u.flags & 1u) != 0u {
        v += c[at];
    }
    if (u.flags & 2u) != 0u {
        v += bias[u.bias_off + gi];
    }
    if (u.flags & 4u) != 0u {
        v = max(v, 0.0);
    }
    c[at] = v;
}
