// The feature-mean term on features (core/src/gpu/losses/feature_mean.rs; CPU twin:
// feature_mean_loss in style/feature_mean.rs): over the covered positions,
// μ_c = mean of channel c, d_c = μ_c − μ^S_c, L = (1/C) Σ_c d_c² and
// grad += λ · 2 d_c / (C · count) at every covered position of channel c.
// Features are channel-major (c × positions); cells is the position mask
// (all ones for the whole frame) and counts[0] the number of covered
// positions (see focus.wgsl). Two passes: `means` (one workgroup per channel)
// writes d_c and d_c²/C for the reduction, `grad` adds the gradient.

struct FeatureMeanParams {
    // Channels C.
    channels: u32,
    // Feature positions (the mask's length).
    positions: u32,
    // λ
    weight: f32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> u: FeatureMeanParams;
@group(0) @binding(1) var<storage, read> f: array<f32>;
@group(0) @binding(2) var<storage, read> cells: array<f32>;
@group(0) @binding(3) var<storage, read> counts: array<f32>;
@group(0) @binding(4) var<storage, read> style_mean: array<f32>;
@group(0) @binding(5) var<storage, read_write> dev: array<f32>;
@group(0) @binding(6) var<storage, read_write> sq: array<f32>;
@group(0) @binding(7) var<storage, read_write> grad: array<f32>;

var<workgroup> partial: array<f32, 256>;

// One workgroup per channel: the masked mean by a strided sum and a tree.
@compute @workgroup_size(256)
fn means(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = wid.x;
    let base = c * u.positions;
    var s = 0.0;
    for (var p = lid; p < u.positions; p = p + 256u) {
        s = s + f[base + p] * cells[p];
    }
    partial[lid] = s;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride = stride / 2u) {
        if lid < stride {
            partial[lid] = partial[lid] + partial[lid + stride];
        }
        workgroupBarrier();
    }
    if lid == 0u {
        var d = 0.0;
        if counts[0] > 0.0 {
            d = partial[0] / counts[0] - style_mean[c];
        }
        dev[c] = d;
        sq[c] = d * d / f32(u.channels);
    }
}

@compute @workgroup_size(256)
fn grad_add(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.channels * u.positions || counts[0] <= 0.0 {
        return;
    }
    let c = i / u.positions;
    let p = i % u.positions;
    let scale = 2.0 / (f32(u.channels) * counts[0]);
    grad[i] = grad[i] + u.weight * scale * dev[c] * cells[p];
}
