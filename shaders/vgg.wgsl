// VGG relu3 forward and input gradient around the GEMM (core/src/gpu/networks/vgg.rs;
// CPU twins: vision/vgg.rs and vision/conv.rs). Layouts are CHW planes of
// h × w; `in_off` / `out_off` / `extra_off` are offsets in f32s into the bound
// buffers, so one buffer can hold several maps (the 768-channel features).
// One thread per output element; flat index gid.x + gid.y · nwg.x · 256.

struct VggParams {
    // channels of the plane stack the kernel walks
    c: u32,
    h: u32,
    w: u32,
    // band of output rows [y0, y1) for im2col / col2im
    y0: u32,
    y1: u32,
    in_off: u32,
    out_off: u32,
    extra_off: u32,
    // elements the dispatch covers
    len: u32,
    // bit 0: accumulate (col2im) / add `extra` (relu_back)
    flags: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: VggParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> aux: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

// the gradient a relu_back adds (relu3_1 and relu3_2 are features too)
@group(0) @binding(4) var<storage, read> extra: array<f32>;

fn mean_of(ch: u32) -> f32 {
    return select(select(0.406, 0.456, ch == 1u), 0.485, ch == 0u);
}

fn std_of(ch: u32) -> f32 {
    return select(select(0.225, 0.224, ch == 1u), 0.229, ch == 0u);
}

fn flat(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// HWC RGB image (src) → ImageNet-normalised CHW (dst). len = h·w·3.
@compute @workgroup_size(256)
fn normalize(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    let n = u.h * u.w;
    let ch = i / n;
    let p = i % n;
    dst[u.out_off + i] = (src[u.in_off + p * 3u + ch] - mean_of(ch)) / std_of(ch);
}

// Gradient of the normalised CHW input (src) → HWC image gradient (dst). len = h·w·3.
@compute @workgroup_size(256)
fn to_image(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    let p = i / 3u;
    let ch = i % 3u;
    dst[u.out_off + i] = src[u.in_off + ch * u.h * u.w + p] / std_of(ch);
}

// 3×3 zero-padded neighbourhoods of output rows [y0, y1): dst is
// (c·9) × ((y1 − y0)·w), row r = ci·9 + ky·3 + kx. len = c·9·(y1 − y0)·w.
@compute @workgroup_size(256)
fn im2col(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    let nb = (u.y1 - u.y0) * u.w;
    let r = i / nb;
    let q = i % nb;
    let ci = r / 9u;
    let tap = r % 9u;
    let y = u.y0 + q / u.w;
    let x = q % u.w;
    let sy = i32(y) + i32(tap / 3u) - 1;
    let sx = i32(x) + i32(tap % 3u) - 1;
    var v = 0.0;
    if sy >= 0 && sx >= 0 && sy < i32(u.h) && sx < i32(u.w) {
        v = src[u.in_off + (ci * u.h + u32(sy)) * u.w + u32(sx)];
    }
    dst[u.out_off + i] = v;
}

// The adjoint of im2col for the band [y0, y1): every input pixel of the rows
// the band touches gathers its (up to) nine taps. Overwrites dst unless
// flags bit 0 (several bands: dst cleared first, bands accumulate).
// len = c · (rows y0−1 … y1 clipped) · w.
@compute @workgroup_size(256)
fn col2im(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    let r0 = max(i32(u.y0) - 1, 0);
    let r1 = min(u.y1 + 1u, u.h);
    let rows = r1 - u32(r0);
    let plane = rows * u.w;
    let ci = i / plane;
    let sy = u32(r0) + (i % plane) / u.w;
    let sx = (i % plane) % u.w;
    let nb = (u.y1 - u.y0) * u.w;
    var acc = 0.0;
    for (var ky = 0u; ky < 3u; ky++) {
        // output row y with y + ky − 1 = sy
        let y = i32(sy) - i32(ky) + 1;
        if y < i32(u.y0) || y >= i32(u.y1) {
            continue;
        }
        for (var kx = 0u; kx < 3u; kx++) {
            let x = i32(sx) - i32(kx) + 1;
            if x < 0 || x >= i32(u.w) {
                continue;
            }
            let row = ci * 9u + ky * 3u + kx;
            acc += src[u.in_off + row * nb + (u32(y) - u.y0) * u.w + u32(x)];
        }
    }
    let at = u.out_off + (ci * u.h + sy) * u.w + sx;
    if (u.flags & 1u) != 0u {
        dst[at] += acc;
    } else {
        dst[at] = acc;
    }
}

// Index in the h × w plane of the maximum of 2×2 cell (oy, ox), the first
// one on ties in torch's order.
fn pool_winner(base: u32, oy: u32, ox: u32) -> u32 {
    let i0 = 2u * oy * u.w + 2u * ox;
    var best = i0;
    var cand = array<u32, 3>(i0 + 1u, i0 + u.w, i0 + u.w + 1u);
    for (var q = 0u; q < 3u; q++) {
        if src[base + cand[q]] > src[base + best] {
            best = cand[q];
        }
    }
    return best;
}

// 2×2 stride-2 max pool with floor semantics: src planes h × w → dst planes
// (h/2) × (w/2). len = c·(h/2)·(w/2).
@compute @workgroup_size(256)
fn pool(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    let ho = u.h / 2u;
    let wo = u.w / 2u;
    let ci = i / (ho * wo);
    let o = i % (ho * wo);
    let base = u.in_off + ci * u.h * u.w;
    dst[u.out_off + i] = src[base + pool_winner(base, o / wo, o % wo)];
}

// Pool backward: src is the pool's input (the saved activation), aux the
// gradient of its output; each input element takes its cell's gradient if
// it won the cell, else 0 (dropped odd rows and columns too). len = c·h·w.
@compute @workgroup_size(256)
fn pool_back(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    let ho = u.h / 2u;
    let wo = u.w / 2u;
    let n = u.h * u.w;
    let ci = i / n;
    let p = i % n;
    let oy = (p / u.w) / 2u;
    let ox = (p % u.w) / 2u;
    var v = 0.0;
    if oy < ho && ox < wo {
        let base = u.in_off + ci * n;
        if pool_winner(base, oy, ox) == p {
            v = aux[u.extra_off + (ci * ho + oy) * wo + ox];
        }
    }
    dst[u.out_off + i] = v;
}

// ReLU backward: dst = aux[extra_off + i] (+ extra[c + i] with flags bit 0,
// the gradient of relu3_1/relu3_2 as features) where the saved activation
// src[in_off + i] is positive, else 0. len = elements.
@compute @workgroup_size(256)
fn relu_back(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if i >= u.len {
        return;
    }
    var g = aux[u.extra_off + i];
    if (u.flags & 1u) != 0u {
        g += extra[u.c + i];
    }
    dst[u.out_off + i] = select(0.0, g, src[u.in_off + i] > 0.0);
}
