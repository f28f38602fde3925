// Depth keys for the viewport's GPU sort (app/src/studio/viewport/splat_sort.rs):
// after the projection pass, every splat gets the key ~bits(z) (farther first
// once sorted ascending; positive floats order like their bits) and culled
// splats (zero extent) the largest key, so they gather at the end where the
// draw turns them into degenerate quads. `order` is reset to the identity,
// which the stable radix sort (core/src/gpu/ops/sort.rs) then permutes.

struct Projected {
    center_extent: vec4<f32>,
    conic_opacity: vec4<f32>,
    color_depth: vec4<f32>,
};

struct KeyParams {
    n: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

@group(0) @binding(0) var<uniform> u: KeyParams;
@group(0) @binding(1) var<storage, read> projected: array<Projected>;
@group(0) @binding(2) var<storage, read_write> keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> order: array<u32>;

@compute @workgroup_size(256)
fn depth_keys(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.n {
        return;
    }
    let p = projected[i];
    var key = 0xffffffffu;
    if p.center_extent.z > 0.0 {
        key = ~bitcast<u32>(p.color_depth.w);
    }
    keys[i] = key;
    order[i] = i;
}
