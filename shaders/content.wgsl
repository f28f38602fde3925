// Content loss on features (core/src/gpu/content.rs; CPU twin:
// style/content.rs): L = mean((f − t)²) over all `len` elements; the
// gradient scale · 2(f − t)/len is added to `v` (which already holds the
// GCFM gradient of the same features).

struct ContentParams {
    len: u32,
    // partial sums (= workgroups of `accumulate`)
    parts: u32,
    // where the loss goes in the scalars buffer
    out_off: u32,
    _pad0: u32,
    scale: f32,
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
}

@group(0) @binding(0) var<uniform> u: ContentParams;
@group(0) @binding(1) var<storage, read> f: array<f32>;
@group(0) @binding(2) var<storage, read> t: array<f32>;
@group(0) @binding(3) var<storage, read_write> v: array<f32>;
@group(0) @binding(4) var<storage, read_write> partial: array<f32>;

var<workgroup> sums: array<f32, 256>;

fn tree_sum(i: u32) {
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride >>= 1u) {
        if i < stride {
            sums[i] += sums[i + stride];
        }
        workgroupBarrier();
    }
}

// Adds the gradient to v and leaves one partial sum of squares per workgroup.
@compute @workgroup_size(256)
fn accumulate(
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let g = wid.x + wid.y * nwg.x;
    let i = g * 256u + lid.x;
    var sq = 0.0;
    if i < u.len {
        let d = f[i] - t[i];
        v[i] += u.scale * 2.0 * d / f32(u.len);
        sq = d * d;
    }
    sums[lid.x] = sq;
    tree_sum(lid.x);
    if lid.x == 0u {
        partial[g] = sums[0];
    }
}

// One workgroup: the mean into partial[out_off] of the scalars buffer bound
// as `v` (binding 3); binding 4 holds the partial sums.
@compute @workgroup_size(256)
fn finish(@builtin(local_invocation_id) lid: vec3<u32>) {
    var acc = 0.0;
    for (var p = lid.x; p < u.parts; p += 256u) {
        acc += partial[p];
    }
    sums[lid.x] = acc;
    tree_sum(lid.x);
    if lid.x == 0u {
        v[u.out_off] = sums[0] / f32(max(u.len, 1u));
    }
}
