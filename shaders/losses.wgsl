// The step's image and parameter losses with their gradients
// (core/src/gpu/losses/losses.rs; CPU twins: style/tv.rs tv_loss,
// style/regularizers.rs depth_l1 and l2_distance, style/outside.rs
// outside_loss). Each kernel adds its
// weighted gradient to `grad` and writes per-element terms to `scratch`,
// which reduce.wgsl sums into the caller's scalars buffer (unweighted).

struct LossParams {
    // TV: image height, width, channels; n = element count (all kernels).
    h: u32,
    w: u32,
    c: u32,
    n: u32,
    // λ, applied to the gradient.
    weight: f32,
    // Depth L1: 1 / n.
    kh: f32,
    // Unused.
    kv: f32,
    // Parameter L2: index of its norm in `scalars`.
    norm_index: u32,
}

@group(0) @binding(0) var<uniform> u: LossParams;
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read> x_ref: array<f32>;
@group(0) @binding(3) var<storage, read_write> grad: array<f32>;
@group(0) @binding(4) var<storage, read_write> scratch: array<f32>;
@group(0) @binding(5) var<storage, read> scalars: array<f32>;

fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// TV = (mean(Δ_h²) + mean(Δ_v²)) / 2 over an HWC image, the means over the
// differences whose two pixels are both covered: x_ref is the pixel mask
// (h × w, 1 or 0; all ones for the whole frame) and scalars the focus's
// counts ([1] horizontal, [2] vertical covered pairs, see focus.wgsl). Each
// value's gradient gathers the differences it takes part in (no scatter, no
// atomics). scratch: [Δ_h² · kh/2 | Δ_v² · kv/2], 2n values summing to the loss.
@compute @workgroup_size(256)
fn tv(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat_index(gid, nwg);
    if e >= u.n {
        return;
    }
    let wc = u.w * u.c;
    let p = e / u.c;
    let j = p % u.w;
    let i = p / u.w;
    let m = x_ref[p];
    var kh = 0.0;
    var kv = 0.0;
    if scalars[1] > 0.0 {
        kh = 1.0 / (scalars[1] * f32(u.c));
    }
    if scalars[2] > 0.0 {
        kv = 1.0 / (scalars[2] * f32(u.c));
    }
    let v = x[e];
    var g = 0.0;
    var sh = 0.0;
    var sv = 0.0;
    if i > 0u {
        g = g + kv * m * x_ref[p - u.w] * (v - x[e - wc]);
    }
    if j > 0u {
        g = g + kh * m * x_ref[p - 1u] * (v - x[e - u.c]);
    }
    if j + 1u < u.w {
        let d = (x[e + u.c] - v) * m * x_ref[p + 1u];
        g = g - kh * d;
        sh = d * d;
    }
    if i + 1u < u.h {
        let d = (x[e + wc] - v) * m * x_ref[p + u.w];
        g = g - kv * d;
        sv = d * d;
    }
    grad[e] = grad[e] + u.weight * g;
    scratch[e] = sh * (0.5 * kh);
    scratch[u.n + e] = sv * (0.5 * kv);
}

// Depth L1 = mean|D − D^c|, subgradient sign(D − D^c) / n (0 on equality).
// scratch: |D − D^c| (the reduction scales by 1/n).
@compute @workgroup_size(256)
fn depth_l1(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.n {
        return;
    }
    let a = x[p];
    let b = x_ref[p];
    var g = 0.0;
    if a > b {
        g = u.kh;
    } else if a < b {
        g = -u.kh;
    }
    grad[p] = grad[p] + u.weight * g;
    scratch[p] = abs(a - b);
}

// Parameter L2, first half: scratch = x − x^c (its norm is a reduction).
@compute @workgroup_size(256)
fn param_diff(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_index(gid, nwg);
    if i >= u.n {
        return;
    }
    scratch[i] = x[i] - x_ref[i];
}

// Parameter L2, second half: grad += λ (x − x^c) / ‖x − x^c‖, nothing where the norm is 0.
@compute @workgroup_size(256)
fn param_grad(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_index(gid, nwg);
    if i >= u.n {
        return;
    }
    let norm = scalars[u.norm_index];
    if norm > 0.0 {
        grad[i] = grad[i] + u.weight * ((x[i] - x_ref[i]) * (1.0 / norm));
    }
}

// Parameter mean square's gradient: grad += λ·kh·(x − x^c), kh = 2/(number of
// Gaussians); its value, kh/2·Σ(x − x^c)², is param_diff's reduction of squares.
@compute @workgroup_size(256)
fn param_sq_grad(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_index(gid, nwg);
    if i >= u.n {
        return;
    }
    grad[i] = grad[i] + u.weight * (u.kh * (x[i] - x_ref[i]));
}

// The background hold = Σ over held channels of k·(I − I^c)², with x_ref a
// per-pixel [r, g, b, k] of the colour-matched render and k = 1/(3·held
// pixels) where the pixel is held, 0 elsewhere (core/src/gpu/engine.rs
// builds it once per view). grad += λ·2k(I − I^c); scratch: k·(I − I^c)².
@compute @workgroup_size(256)
fn hold(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = flat_index(gid, nwg);
    if e >= u.n {
        return;
    }
    let p = e / 3u;
    let k = x_ref[4u * p + 3u];
    let d = x[e] - x_ref[4u * p + e % 3u];
    grad[e] = grad[e] + u.weight * 2.0 * k * d;
    scratch[e] = k * d * d;
}
