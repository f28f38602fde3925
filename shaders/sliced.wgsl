// The sliced Wasserstein term on features (core/src/gpu/losses/sliced.rs;
// CPU twin: sliced_loss in style/sliced.rs). The projections R = Θ F (P × n,
// a GEMM before these kernels) of the covered positions are sorted within
// each direction, and each is pulled toward the style's projection quantile
// of its rank: L = (1/P) Σ_p (1/m) Σ_k (r_p,(k) − t_p,k)², m covered positions.
//
// The ranks come from two stable radix sorts of all P·n projections at once:
// `make_keys` keys each by its order-preserving bits (the uncovered positions
// by the largest key, so they rank last) and numbers it by its slot p·n + i;
// after the first sort `direction_keys` keys each by its direction, and the
// second sort, stable, groups the directions while keeping each one's
// values in order (ties in slot order, as the CPU's stable sort). Direction
// p then fills [p·n, (p+1)·n); `residual` reads the rank k of each from its
// place there, writes the gradient G = λ · 2 (r − t)/(m P) at the
// projection's own slot and (r − t)²/(m P) for the reduction. A GEMM then
// adds Θᵀ G to the features' gradient.

struct SlicedParams {
    // Feature positions n (the mask's length).
    positions: u32,
    // Directions P.
    projections: u32,
    // Style positions M of each direction's sorted projections.
    style_positions: u32,
    // λ
    weight: f32,
}

@group(0) @binding(0) var<uniform> u: SlicedParams;
@group(0) @binding(1) var<storage, read> proj: array<f32>;
@group(0) @binding(2) var<storage, read> cells: array<f32>;
@group(0) @binding(3) var<storage, read> counts: array<f32>;
@group(0) @binding(4) var<storage, read> sorted_style: array<f32>;
@group(0) @binding(5) var<storage, read_write> keys: array<u32>;
@group(0) @binding(6) var<storage, read_write> slots: array<u32>;
@group(0) @binding(7) var<storage, read_write> grad: array<f32>;
@group(0) @binding(8) var<storage, read_write> sq: array<f32>;

fn flat_id(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

@compute @workgroup_size(256)
fn make_keys(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let j = flat_id(gid, nwg);
    if j >= u.positions * u.projections {
        return;
    }
    let i = j % u.positions;
    var key = 0xFFFFFFFFu;
    if cells[i] > 0.0 {
        let b = bitcast<u32>(proj[j]);
        key = b | 0x80000000u;
        if (b & 0x80000000u) != 0u {
            key = ~b;
        }
    }
    keys[j] = key;
    slots[j] = j;
}

@compute @workgroup_size(256)
fn direction_keys(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let j = flat_id(gid, nwg);
    if j >= u.positions * u.projections {
        return;
    }
    keys[j] = slots[j] / u.positions;
}

// The sorted style projections of direction p at quantile q, linearly
// interpolated between sample s at (s + ½)/M, as the CPU's `quantile`.
fn quantile(p: u32, q: f32) -> f32 {
    let len = u.style_positions;
    let x = clamp(q * f32(len) - 0.5, 0.0, f32(len - 1u));
    let a = u32(floor(x));
    let b = min(a + 1u, len - 1u);
    let t = x - f32(a);
    let base = p * len;
    return sorted_style[base + a] * (1.0 - t) + sorted_style[base + b] * t;
}

@compute @workgroup_size(256)
fn residual(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let j = flat_id(gid, nwg);
    if j >= u.positions * u.projections {
        return;
    }
    let p = j / u.positions;
    let k = j - p * u.positions;
    let at = slots[j];
    let m = u32(counts[0] + 0.5);
    if k >= m || u.style_positions == 0u {
        grad[at] = 0.0;
        sq[j] = 0.0;
        return;
    }
    let scale = 1.0 / (f32(m) * f32(u.projections));
    let d = proj[at] - quantile(p, (f32(k) + 0.5) / f32(m));
    grad[at] = u.weight * 2.0 * d * scale;
    sq[j] = d * d * scale;
}
