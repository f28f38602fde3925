// The render's clamp to [0, 1] and the 0.5× bilinear downscale, forward and
// backward (core/src/gpu/ops/resize.rs; CPU twins: the clamp in session/run.rs,
// vision/resize.rs downscale_half and downscale_half_backward).
// Images are HWC row-major with `c` interleaved channels.

struct ResizeParams {
    // Source height, width and channels.
    h: u32,
    w: u32,
    c: u32,
    // Output height and width: floor(h / 2), floor(w / 2).
    oh: u32,
    ow: u32,
    // 1: the backward adds to its output instead of overwriting it.
    accumulate: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: ResizeParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// dst = clamp(src, 0, 1) over h·w·c values.
@compute @workgroup_size(256)
fn clamp01(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_index(gid, nwg);
    if i >= u.h * u.w * u.c {
        return;
    }
    dst[i] = clamp(src[i], 0.0, 1.0);
}

// The clamp's adjoint, in place: dst (the gradient) is zeroed where the raw
// value src lies outside [0, 1] (NaN included).
@compute @workgroup_size(256)
fn clamp01_backward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_index(gid, nwg);
    if i >= u.h * u.w * u.c {
        return;
    }
    let raw = src[i];
    if !(raw >= 0.0 && raw <= 1.0) {
        dst[i] = 0.0;
    }
}

// PyTorch's bilinear with scale_factor 0.5 samples at 2·i + 0.5: taps 2i and
// 2i + 1 with weights ½, ½ (odd sizes drop the last row or column). Written
// as the CPU writes it, wy0·(wx0·p00 + wx1·p01) + wy1·(wx0·p10 + wx1·p11);
// every product by ½ is exact, so the result is the CPU's bit for bit.
@compute @workgroup_size(256)
fn downscale(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = flat_index(gid, nwg);
    if t >= u.oh * u.ow * u.c {
        return;
    }
    let k = t % u.c;
    let j = (t / u.c) % u.ow;
    let i = t / (u.c * u.ow);
    let row0 = (2u * i) * u.w;
    let row1 = (2u * i + 1u) * u.w;
    let x0 = 2u * j;
    let p00 = src[(row0 + x0) * u.c + k];
    let p01 = src[(row0 + x0 + 1u) * u.c + k];
    let p10 = src[(row1 + x0) * u.c + k];
    let p11 = src[(row1 + x0 + 1u) * u.c + k];
    dst[t] = 0.5 * (0.5 * p00 + 0.5 * p01) + 0.5 * (0.5 * p10 + 0.5 * p11);
}

// The adjoint: every source value inside the 2·oh × 2·ow block gets ¼ of its
// output's gradient (the CPU's (wy·wx)·g), the dropped row/column 0.
@compute @workgroup_size(256)
fn downscale_backward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = flat_index(gid, nwg);
    if t >= u.h * u.w * u.c {
        return;
    }
    let k = t % u.c;
    let x = (t / u.c) % u.w;
    let y = t / (u.c * u.w);
    var g = 0.0;
    if y < 2u * u.oh && x < 2u * u.ow {
        g = 0.25 * src[((y / 2u) * u.ow + x / 2u) * u.c + k];
    }
    if u.accumulate == 1u {
        dst[t] = dst[t] + g;
    } else {
        dst[t] = g;
    }
}
