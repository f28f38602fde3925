// The assignment terms' device side (core/src/gpu/losses/assignment.rs; CPU twin:
// assignment_loss in style/assignment.rs). The pairing itself (a Hungarian
// assignment of at most 512 rows) runs on the host; the device gathers the
// columns it pairs and adds back their gradient:
// - `gather`: out[c·r + t] = src[c·positions + cols[t]] (channel-major, CHW);
// - `scatter_add`: grad[c·positions + cols[t]] += g[c·r + t]. The columns
//   are distinct, so no two threads add to one element.

struct AssignParams {
    // Channels C.
    channels: u32,
    // Positions of the source (or the gradient's) feature maps.
    positions: u32,
    // Columns gathered or scattered, r.
    count: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> u: AssignParams;
@group(0) @binding(1) var<storage, read> cols: array<u32>;
@group(0) @binding(2) var<storage, read> src: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

fn index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// src: the feature maps; dst: the gathered C × r columns.
@compute @workgroup_size(256)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = index(gid, nwg);
    if i >= u.channels * u.count {
        return;
    }
    let c = i / u.count;
    let t = i % u.count;
    dst[i] = src[c * u.positions + cols[t]];
}

// src: the gathered C × r gradient; dst: the feature maps' gradient.
@compute @workgroup_size(256)
fn scatter_add(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = index(gid, nwg);
    if i >= u.channels * u.count {
        return;
    }
    let c = i / u.count;
    let t = i % u.count;
    let at = c * u.positions + cols[t];
    dst[at] = dst[at] + src[i];
}
