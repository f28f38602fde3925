// Tiled f32 matrix product with strides (core/src/gpu/gemm.rs; CPU twin:
// vision/conv.rs `matmul`).
//
//   C(i, j) = act(alpha · Σ_p A(i, p) · B(p, j) + [C(i, j)] + [bias(i)])
//
// with A(i, p) = a[a_off + i·a_rs + p·a_cs], B(p, j) = b[b_off + p·b_rs + j·b_cs],
// C(i, j) = c[c_off + i·c_rs + j]: the strides express A·B, Aᵀ·B and A·Bᵀ.
// Batches run along workgroup z with per-batch offsets `*_bs`.
// A 64×64 block of C per workgroup of 16×16 threads, 4×4 outputs per thread,
// K in slices of 16 staged in workgroup memory.

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
            let e = t + r * 256u;
            // e indexes the 16 × 64 tile; pick (p, i) so consecutive threads
            // walk the contiguous direction of A.
            var pp: u32;
            var ii: u32;
            if a_along_i {
                pp = e / TM;
                ii = e % TM;
            } else {
                pp = e % TK;
                ii = e / TK;
            }
            let gi = i0 + ii;
            let gp = p0 + pp;
            var va = 0.0;
            if gi < u.m && gp < u.k {
                va = a[a_base + gi * u.a_rs + gp * u.a_cs];
            }
            As[pp * TM + ii] = va;
            var pb: u32;
            var jb: u32;
            if b_along_j {
                pb = e / TN;
                jb = e % TN;
            } else {
                pb = e % TK;
                jb = e / TK;
            }
            let gj = j0 + jb;
            let gq = p0 + pb;
            var vb = 0.0;
            if gj < u.n && gq < u.k {
                vb = b[b_base + gq * u.b_rs + gj * u.b_cs];
            }
            Bs[pb * TN + jb] = vb;
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
