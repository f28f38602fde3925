// Tiled f32 matrix product with strides (core/src/gpu/gemm.rs; CPU twin:
// vision/conv.rs `matmul`).
//
//   C(i, j) = act(alpha · Σ_p A(i, p) · B(p, j) + [C(i, j)] + [bias(i)])
//
// with A(i, p) = a[a_off + i·a_rs + p·a_cs], B(p, j) = b[b_off + p·b_rs + j·b_cs],
// C(i, j) = c[c_off + i·c_rs + j]: the strides express A·B, Aᵀ·B and A·Bᵀ.
// Batches run along workgroup z with per-batch offsets `*_bs`.
// `gemm`: a 64×64 block of C per workgroup of 16×16 threads, 4×4 outputs
// per thread, K in slices of 16 staged in workgroup memory. `gemm_wide`: a
// 128×128 block, 8×8 outputs per thread, K in slices of 8 (twice the
// multiply-adds per value read from workgroup memory; for products large
// enough to fill the device with its four times fewer workgroups).
// A thread's outputs are rows ty + 16·qi and columns tx + 16·qj of the block.

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

var<workgroup> As: array<f32, 1024>; // [TK][TM]
var<workgroup> Bs: array<f32, 1024>; // [TK][TN]

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

    // Row qi of this thread's 4×4 block in acc{qi}, columns tx + 16·qj in
    // its components: registers, no indexed private arrays (which software
    // rasterizers spill to memory).
    var acc0 = vec4<f32>(0.0);
    var acc1 = vec4<f32>(0.0);
    var acc2 = vec4<f32>(0.0);
    var acc3 = vec4<f32>(0.0);
    let tiles = (u.k + TK - 1u) / TK;
    for (var kt = 0u; kt < tiles; kt++) {
        let p0 = kt * TK;
        for (var r = 0u; r < 4u; r++) {
            // Element t + 256·r of the TK × TM slices of A and B.
            let ea = slice_at(t + r * 256u, a_along_i, TK, TM);
            As[ea.x * TM + ea.y] = a_at(a_base, i0 + ea.y, p0 + ea.x);
            let eb = slice_at(t + r * 256u, b_along_j, TK, TN);
            Bs[eb.x * TN + eb.y] = b_at(b_base, p0 + eb.x, j0 + eb.y);
        }
        workgroupBarrier();
        for (var p = 0u; p < TK; p++) {
            let ao = p * TM + ty;
            let bo = p * TN + tx;
            let bv = vec4<f32>(Bs[bo], Bs[bo + 16u], Bs[bo + 32u], Bs[bo + 48u]);
            acc0 = fma(vec4<f32>(As[ao]), bv, acc0);
            acc1 = fma(vec4<f32>(As[ao + 16u]), bv, acc1);
            acc2 = fma(vec4<f32>(As[ao + 32u]), bv, acc2);
            acc3 = fma(vec4<f32>(As[ao + 48u]), bv, acc3);
        }
        workgroupBarrier();
    }
    store_row(i0 + ty, j0 + tx, c_base, acc0);
    store_row(i0 + ty + 16u, j0 + tx, c_base, acc1);
    store_row(i0 + ty + 32u, j0 + tx, c_base, acc2);
    store_row(i0 + ty + 48u, j0 + tx, c_base, acc3);
}

const WM: u32 = 128u;
const WK: u32 = 8u;

var<workgroup> Aw: array<f32, 1024>; // [WK][WM]
var<workgroup> Bw: array<f32, 1024>; // [WK][WM]

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

    // Row qi in r{qi}l (columns qj 0..3) and r{qi}h (qj 4..7).
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
    let tiles = (u.k + WK - 1u) / WK;
    for (var kt = 0u; kt < tiles; kt++) {
        let p0 = kt * WK;
        for (var r = 0u; r < 4u; r++) {
            let ea = slice_at(t + r * 256u, a_along_i, WK, WM);
            Aw[ea.x * WM + ea.y] = a_at(a_base, i0 + ea.y, p0 + ea.x);
            let eb = slice_at(t + r * 256u, b_along_j, WK, WM);
            Bw[eb.x * WM + eb.y] = b_at(b_base, p0 + eb.x, j0 + eb.y);
        }
        workgroupBarrier();
        for (var p = 0u; p < WK; p++) {
            let ao = p * WM + ty;
            let bo = p * WM + tx;
            let bl = vec4<f32>(Bw[bo], Bw[bo + 16u], Bw[bo + 32u], Bw[bo + 48u]);
            let bh = vec4<f32>(Bw[bo + 64u], Bw[bo + 80u], Bw[bo + 96u], Bw[bo + 112u]);
            let a0 = vec4<f32>(Aw[ao]);
            let a1 = vec4<f32>(Aw[ao + 16u]);
            let a2 = vec4<f32>(Aw[ao + 32u]);
            let a3 = vec4<f32>(Aw[ao + 48u]);
            let a4 = vec4<f32>(Aw[ao + 64u]);
            let a5 = vec4<f32>(Aw[ao + 80u]);
            let a6 = vec4<f32>(Aw[ao + 96u]);
            let a7 = vec4<f32>(Aw[ao + 112u]);
            r0l = fma(a0, bl, r0l);
            r0h = fma(a0, bh, r0h);
            r1l = fma(a1, bl, r1l);
            r1h = fma(a1, bh, r1h);
            r2l = fma(a2, bl, r2l);
            r2h = fma(a2, bh, r2h);
            r3l = fma(a3, bl, r3l);
            r3h = fma(a3, bh, r3h);
            r4l = fma(a4, bl, r4l);
            r4h = fma(a4, bh, r4h);
            r5l = fma(a5, bl, r5l);
            r5h = fma(a5, bh, r5h);
            r6l = fma(a6, bl, r6l);
            r6h = fma(a6, bh, r6h);
            r7l = fma(a7, bl, r7l);
            r7h = fma(a7, bh, r7h);
        }
        workgroupBarrier();
    }
    let gi = i0 + ty;
    let gj = j0 + tx;
    store_row(gi, gj, c_base, r0l);
    store_row(gi, gj + 64u, c_base, r0h);
    store_row(gi + 16u, gj, c_base, r1l);
    store_row(gi + 16u, gj + 64u, c_base, r1h);
    store_row(gi + 32u, gj, c_base, r2l);
    store_row(gi + 32u, gj + 64u, c_base, r2h);
    store_row(gi + 48u, gj, c_base, r3l);
    store_row(gi + 48u, gj + 64u, c_base, r3h);
    store_row(gi + 64u, gj, c_base, r4l);
    store_row(gi + 64u, gj + 64u, c_base, r4h);
    store_row(gi + 80u, gj, c_base, r5l);
    store_row(gi + 80u, gj + 64u, c_base, r5h);
    store_row(gi + 96u, gj, c_base, r6l);
    store_row(gi + 96u, gj + 64u, c_base, r6h);
    store_row(gi + 112u, gj, c_base, r7l);
    store_row(gi + 112u, gj + 64u, c_base, r7h);
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

// The epilogue of one row of a thread's block: columns gj0 + 16·q.
fn store_row(gi: u32, gj0: u32, c_base: u32, v: vec4<f32>) {
    if gi >= u.m {
        return;
    }
    store(gi, gj0, c_base, v.x);
    store(gi, gj0 + 16u, c_base, v.y);
    store(gi, gj0 + 32u, c_base, v.z);
    store(gi, gj0 + 48u, c_base, v.w);
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
