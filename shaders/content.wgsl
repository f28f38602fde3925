// Content loss on features (core/src/gpu/losses/content.rs; CPU twin:
// content_loss_masked in style/content.rs): over the covered positions,
// L = mean((f − t)²) and grad += λ · 2(f − t)/count; sq holds (f − t)²/count
// there (0 elsewhere) for the reduction. Features are channel-major
// (c × positions); cells is the position mask (all ones for the whole frame)
// and counts[0] the number of covered positions (see focus.wgsl). The target
// may hold the covered positions' columns alone: columns[p] is position p's
// column in t (NONE where it has none, outside the mask) and
// columns[positions] the number of t's columns (positions for a whole map).

struct ContentParams {
    // Floats in a feature map (c × positions).
    n: u32,
    // Feature positions (the mask's length).
    positions: u32,
    // λ
    weight: f32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> u: ContentParams;
@group(0) @binding(1) var<storage, read> f: array<f32>;
@group(0) @binding(2) var<storage, read> t: array<f32>;
@group(0) @binding(3) var<storage, read_write> grad: array<f32>;
@group(0) @binding(4) var<storage, read_write> sq: array<f32>;
@group(0) @binding(5) var<storage, read> cells: array<f32>;
@group(0) @binding(6) var<storage, read> counts: array<f32>;
@group(0) @binding(7) var<storage, read> columns: array<u32>;

const NONE: u32 = 0xffffffffu;

@compute @workgroup_size(256)
fn content(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= u.n {
        return;
    }
    let covered = counts[0] * f32(u.n / u.positions);
    var inv = 0.0;
    if covered > 0.0 {
        inv = 1.0 / covered;
    }
    let p = i % u.positions;
    let column = columns[p];
    var held = 0.0;
    if column != NONE {
        held = t[(i / u.positions) * columns[u.positions] + column];
    }
    let d = (f[i] - held) * cells[p];
    sq[i] = d * d * inv;
    grad[i] = grad[i] + u.weight * 2.0 * inv * d;
}
