// Depth Anything V2's DPT neck and head around the GEMM (core/src/gpu/networks/depth_dpt.rs;
// CPU twins: vision/depth/dpt.rs and vision/depth/ops.rs). Maps are CHW
// planes. One thread per output element; flat index gid.x + gid.y · nwg.x · 256.

struct DptParams {
    // input channels, height, width
    c: u32,
    h: u32,
    w: u32,
    // kernel side (im2col) or upsampling factor (conv_up)
    k: u32,
    stride: u32,
    pad: u32,
    // output height and width
    oh: u32,
    ow: u32,
    // first output row of an im2col band, and the band's pixels
    y0: u32,
    nb: u32,
    // threads the dispatch covers
    len: u32,
    // im2col: bit 0 = ReLU of the input; head: bit 0 = metric (sigmoid)
    flags: u32,
    // head output scale (max_depth, or 1)
    scale: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> u: DptParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> aux: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

fn flat(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// Columns of a k × k convolution with stride and zero padding for the
// output rows [y0, y0 + nb / ow): src (c × h × w) → dst (c·k·k × nb), row
// (c·k + ky)·k + kx. len = c·k·k·nb.
@compute @workgroup_size(256)
fn im2col(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let r = e / u.nb;
    let q = e % u.nb;
    let oy = u.y0 + q / u.ow;
    let ox = q % u.ow;
    let kx = r % u.k;
    let ky = (r / u.k) % u.k;
    let ch = r / (u.k * u.k);
    let iy = i32(oy * u.stride + ky) - i32(u.pad);
    let ix = i32(ox * u.stride + kx) - i32(u.pad);
    var v = 0.0;
    if iy >= 0 && ix >= 0 && iy < i32(u.h) && ix < i32(u.w) {
        v = src[(ch * u.h + u32(iy)) * u.w + u32(ix)];
        if (u.flags & 1u) != 0u {
            v = max(v, 0.0);
        }
    }
    dst[e] = v;
}

// The transposed convolution whose kernel equals its stride f (= k): the
// product src (c·f·f × h·w, row (o·f + ky)·f + kx) painted into dst
// (c × h·f × w·f) plus the bias aux[o]. len = c·h·f·w·f.
@compute @workgroup_size(256)
fn conv_up(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let f = u.k;
    let ow = u.w * f;
    let oh = u.h * f;
    let o = e / (oh * ow);
    let y = (e / ow) % oh;
    let x = e % ow;
    let row = (o * f + y % f) * f + x % f;
    dst[e] = src[row * u.h * u.w + (y / f) * u.w + x / f] + aux[o];
}

// Bilinear resampling of every plane of src (c × h × w) to dst (c × oh × ow)
// with the taps the CPU computes: aux holds (i0, i1, w0, w1) for each output
// row, then for each output column. len = c·oh·ow.
@compute @workgroup_size(256)
fn resize(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let ch = e / (u.oh * u.ow);
    let y = (e / u.ow) % u.oh;
    let x = e % u.ow;
    let ty = 4u * y;
    let tx = 4u * (u.oh + x);
    let base = ch * u.h * u.w;
    let y0 = base + u32(aux[ty]) * u.w;
    let y1 = base + u32(aux[ty + 1u]) * u.w;
    let x0 = u32(aux[tx]);
    let x1 = u32(aux[tx + 1u]);
    let wx0 = aux[tx + 2u];
    let wx1 = aux[tx + 3u];
    let top = wx0 * src[y0 + x0] + wx1 * src[y0 + x1];
    let bottom = wx0 * src[y1 + x0] + wx1 * src[y1 + x1];
    dst[e] = aux[ty + 2u] * top + aux[ty + 3u] * bottom;
}

// dst += src. len = elements.
@compute @workgroup_size(256)
fn add(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    dst[e] += src[e];
}

// The head's output activation in place: relative depth max(v, 0)·scale,
// metric depth scale·sigmoid(v). len = pixels.
@compute @workgroup_size(256)
fn head_out(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat(gid, nwg);
    if e >= u.len {
        return;
    }
    let v = dst[e];
    if (u.flags & 1u) != 0u {
        dst[e] = u.scale / (1.0 + exp(-v));
    } else {
        dst[e] = max(v, 0.0) * u.scale;
    }
}
