// Depth Anything V2's DINOv2 backbone around the GEMM (core/src/gpu/networks/depth_net.rs;
// CPU twins: vision/depth/vit.rs and vision/depth/ops.rs). Token states are
// channel-major, `d × n` (one row per channel, one column per token, CLS
// first), as on the CPU. One thread per output element or per column; flat
// index gid.x + gid.y · nwg.x · 256.

struct NetParams {
    // channels (layer norm), or keys (softmax rows)
    d: u32,
    // columns of the array the kernel walks
    n: u32,
    // image size (patchify)
    h: u32,
    w: u32,
    // patch side (patchify)
    p: u32,
    // patch columns (patchify)
    cols: u32,
    // threads the dispatch covers
    len: u32,
    // layer-norm epsilon
    eps: f32,
}

@group(0) @binding(0) var<uniform> u: NetParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> aux: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

fn flat(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// The stride-p patch convolution's columns: image (src, 3 × h × w) → patches
// (dst, 3p² × rows·cols), row (c·p + ky)·p + kx, column py·cols + px.
// n = rows·cols, len = 3p²·n.
@compute @workgroup_size(256)
fn patchify(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let r = e / u.n;
    let t = e % u.n;
    let kx = r % u.p;
    let ky = (r / u.p) % u.p;
    let c = r / (u.p * u.p);
    let py = t / u.cols;
    let px = t % u.cols;
    dst[e] = src[(c * u.h + py * u.p + ky) * u.w + px * u.p + kx];
}

// Layer normalisation of each column of src (d × n) into dst, with the
// scale in aux[0..d] and the shift in aux[d..2d]; two passes as the CPU
// (mean, then the centred variance), channels summed in order. len = n.
@compute @workgroup_size(256)
fn layer_norm(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = flat(gid, nwg);
    if t >= u.len {
        return;
    }
    let fd = f32(u.d);
    var mean = 0.0;
    for (var c = 0u; c < u.d; c++) {
        mean += src[c * u.n + t];
    }
    mean /= fd;
    var var_sum = 0.0;
    for (var c = 0u; c < u.d; c++) {
        let v = src[c * u.n + t] - mean;
        var_sum += v * v;
    }
    let inv = 1.0 / sqrt(var_sum / fd + u.eps);
    for (var c = 0u; c < u.d; c++) {
        dst[c * u.n + t] = (src[c * u.n + t] - mean) * inv * aux[c] + aux[u.d + c];
    }
}

// Softmax down each column of a batch of d × n score blocks (keys × queries)
// in dst, in place. len = batches · n; thread (z, j) walks column j of block z.
@compute @workgroup_size(256)
fn softmax_columns(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let base = (e / u.n) * u.d * u.n + e % u.n;
    var m = -3.4e38;
    for (var i = 0u; i < u.d; i++) {
        m = max(m, dst[base + i * u.n]);
    }
    var sum = 0.0;
    for (var i = 0u; i < u.d; i++) {
        let v = exp(dst[base + i * u.n] - m);
        dst[base + i * u.n] = v;
        sum += v;
    }
    let inv = 1.0 / sum;
    for (var i = 0u; i < u.d; i++) {
        dst[base + i * u.n] *= inv;
    }
}

// The error function (Abramowitz & Stegun 7.1.26, absolute error below
// 1.5e-7), the CPU's formula.
fn erf(x: f32) -> f32 {
    let a = abs(x);
    let t = 1.0 / (1.0 + 0.3275911 * a);
    let poly = t * (0.2548296 + t * (-0.28449674 + t * (1.4214138 + t * (-1.4531521 + t * 1.0614054))));
    let y = 1.0 - poly * exp(-a * a);
    return select(y, -y, x < 0.0);
}

// Exact GELU of dst in place, as nn.GELU(). len = elements.
@compute @workgroup_size(256)
fn gelu(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let v = dst[e];
    dst[e] = 0.5 * v * (1.0 + erf(v * 0.70710678));
}
