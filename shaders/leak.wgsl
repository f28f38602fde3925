// The reference's gradient leak between phases on the GPU (core/src/gpu/ops/leak.rs;
// CPU twin: take_leak and add_into in session/run_step.rs). Element i of the
// sum `acc` pairs with grads[(i / group) * stride + i % group], as in adam.wgsl:
// whole arrays (group = stride = 1) and the DC colour inside the SH array
// (group 3, stride 3 × coefficients per Gaussian).

struct LeakParams {
    len: u32,
    group: u32,
    stride: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> u: LeakParams;
@group(0) @binding(1) var<storage, read_write> grads: array<f32>;
@group(0) @binding(2) var<storage, read_write> acc: array<f32>;

fn paired(i: u32) -> u32 {
    return (i / u.group) * u.stride + i % u.group;
}

// The phase's first step after the other's: its gradient takes the sum, which empties.
@compute @workgroup_size(256)
fn take(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.len {
        return;
    }
    let j = paired(i);
    grads[j] = grads[j] + acc[i];
    acc[i] = 0.0;
}

// A step of the other phase: what its backward left on these parameters joins the sum.
@compute @workgroup_size(256)
fn add(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.len {
        return;
    }
    acc[i] = acc[i] + grads[paired(i)];
}
