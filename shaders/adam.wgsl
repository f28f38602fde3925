// Adam on one flat parameter array (core/src/gpu/ops/adam.rs; CPU twin: style/adam.rs).
// p -= (lr / bc1) · m / (sqrt(v) / sqrt(bc2) + eps), PyTorch's bias correction.
// Element i of the state updates params[(i / group) * stride + i % group] by
// grads[(i / group) * grad_stride + i % group], so one kernel serves whole
// arrays (group = strides = 1) and the colour phase's DC coefficients inside
// the SH array (group 3, stride 3 × coefficients per Gaussian, grad_stride 3:
// the engine's gradient holds the DC alone). The updated value is raised to at
// least `floor` (the colour floor; the lowest f32 when off).

struct AdamParams {
    len: u32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    // lr / (1 - beta1^t)
    step_size: f32,
    // sqrt(1 - beta2^t)
    bc2_sqrt: f32,
    group: u32,
    stride: u32,
    floor: f32,
    grad_stride: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> u: AdamParams;
@group(0) @binding(1) var<storage, read_write> params: array<f32>;
@group(0) @binding(2) var<storage, read> grads: array<f32>;
@group(0) @binding(3) var<storage, read_write> m: array<f32>;
@group(0) @binding(4) var<storage, read_write> v: array<f32>;

@compute @workgroup_size(256)
fn step(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.len {
        return;
    }
    let j = (i / u.group) * u.stride + i % u.group;
    let g = grads[(i / u.group) * u.grad_stride + i % u.group];
    let mi = u.beta1 * m[i] + (1.0 - u.beta1) * g;
    let vi = u.beta2 * v[i] + (1.0 - u.beta2) * g * g;
    m[i] = mi;
    v[i] = vi;
    params[j] = max(params[j] - u.step_size * mi / (sqrt(vi) / u.bc2_sqrt + u.eps), u.floor);
}
