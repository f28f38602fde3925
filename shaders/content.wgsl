// Content loss on features (core/src/gpu/content.rs; CPU twin: style/content.rs):
// L = mean((f − t)²); grad += λ · 2(f − t)/n; sq holds (f − t)² for the reduction.

struct ContentParams {
    n: u32,
    // λ · 2 / n
    grad_scale: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: ContentParams;
@group(0) @binding(1) var<storage, read> f: array<f32>;
@group(0) @binding(2) var<storage, read> t: array<f32>;
@group(0) @binding(3) var<storage, read_write> grad: array<f32>;
@group(0) @binding(4) var<storage, read_write> sq: array<f32>;

@compute @workgroup_size(256)
fn content(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.n {
        return;
    }
    let d = f[i] - t[i];
    sq[i] = d * d;
    grad[i] = grad[i] + u.grad_scale * d;
}
