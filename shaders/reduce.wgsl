// Deterministic reductions (core/src/gpu/ops/reduce.rs; CPU twins: the folds in
// style/step.rs, vision/canny.rs, style/tv.rs, style/regularizers.rs).
// Two levels, no atomics, no subgroups: `partial` gives each of `groups`
// workgroups per lane a fixed strided slice and a tree in workgroup memory;
// `finish` folds the partials of each lane with the same tree. The order of
// every addition depends only on the sizes, so the result is reproducible.

struct ReduceParams {
    // Elements per lane; lane l reads input[l * len .. (l + 1) * len].
    len: u32,
    // 0 sum, 1 min, 2 max, 3 sum of squares.
    op: u32,
    // First-level workgroups per lane (at most 256).
    groups: u32,
    // The result of lane l goes to out[out_offset + l].
    out_offset: u32,
    // 1: take the square root of the result (an L2 norm).
    sqrt_result: u32,
    // The result is multiplied by this (after the square root).
    scale: f32,
    // Lane 0 starts at input[in_offset].
    in_offset: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: ReduceParams;
@group(0) @binding(1) var<storage, read> input: array<f32>;
@group(0) @binding(2) var<storage, read_write> partials: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;

const WG: u32 = 256u;
var<workgroup> acc_wg: array<f32, 256>;

fn combine(a: f32, b: f32) -> f32 {
    switch u.op {
        case 1u: { return min(a, b); }
        case 2u: { return max(a, b); }
        default: { return a + b; }
    }
}

// Tree over the workgroup's 256 values; the result ends in acc_wg[0].
fn tree(l: u32) {
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s >> 1u) {
        if l < s {
            acc_wg[l] = combine(acc_wg[l], acc_wg[l + s]);
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(256)
fn partial(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let lane = wid.y;
    let base = u.in_offset + lane * u.len;
    // Min and max start from the lane's first element (a neutral value that
    // needs no infinity); sums from zero.
    var acc = 0.0;
    if (u.op == 1u || u.op == 2u) && u.len > 0u {
        acc = input[base];
    }
    let stride = u.groups * WG;
    for (var i = wid.x * WG + lid.x; i < u.len; i = i + stride) {
        var x = input[base + i];
        if u.op == 3u {
            x = x * x;
        }
        acc = combine(acc, x);
    }
    acc_wg[lid.x] = acc;
    tree(lid.x);
    if lid.x == 0u {
        partials[lane * u.groups + wid.x] = acc_wg[0];
    }
}

@compute @workgroup_size(256)
fn finish(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let lane = wid.y;
    let base = lane * u.groups;
    var acc = 0.0;
    if u.op == 1u || u.op == 2u {
        acc = partials[base];
    }
    for (var i = lid.x; i < u.groups; i = i + WG) {
        acc = combine(acc, partials[base + i]);
    }
    acc_wg[lid.x] = acc;
    tree(lid.x);
    if lid.x == 0u {
        var r = acc_wg[0];
        if u.sqrt_result == 1u {
            r = sqrt(r);
        }
        out[u.out_offset + lane] = r * u.scale;
    }
}
