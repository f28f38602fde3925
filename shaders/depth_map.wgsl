// The depth map of one step: inverse depth min-max normalised per image and
// replicated to 3 channels, and its adjoint (core/src/gpu/losses/depth_map.rs; CPU
// twins: step_loss and min_max_backward in style/step.rs). Only the pixels in
// `mask` (1 or 0; all ones for the whole frame) count: the min and max are
// theirs, the map is 0 elsewhere and so is the gradient.
// stats: [min, max, Σg, Σg·d̃, #(x = min), #(x = max)], the first two from
// the forward's reductions, the rest from the backward's.

struct DepthParams {
    // Pixels.
    n: u32,
    // 1: the backward adds to v_out instead of overwriting it.
    accumulate: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: DepthParams;
@group(0) @binding(1) var<storage, read> inv_depth: array<f32>;
@group(0) @binding(2) var<storage, read> stats: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
@group(0) @binding(4) var<storage, read> v_map: array<f32>;
@group(0) @binding(5) var<storage, read> mask: array<f32>;

const BIG: f32 = 3.4e38;

fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

fn range() -> f32 {
    return stats[1] - stats[0] + 1e-8;
}

// The min's and max's inputs (out holds 2n): [d or +BIG | d or −BIG], BIG
// outside the mask, so that reductions over them give the covered range.
@compute @workgroup_size(256)
fn bounds(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.n {
        return;
    }
    let inside = mask[p] != 0.0;
    out[p] = select(BIG, inv_depth[p], inside);
    out[u.n + p] = select(-BIG, inv_depth[p], inside);
}

// out (n × 3) = (d − min) / (max − min + 1e-8) inside the mask, else 0, replicated.
@compute @workgroup_size(256)
fn normalize(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.n {
        return;
    }
    let v = select(0.0, (inv_depth[p] - stats[0]) / range(), mask[p] != 0.0);
    out[3u * p] = v;
    out[3u * p + 1u] = v;
    out[3u * p + 2u] = v;
}

// Four planes of per-pixel terms for the backward's sums (out holds 4n), 0
// outside the mask: g = Σ_k v_map[3p + k], g·d̃, [d = min], [d = max].
@compute @workgroup_size(256)
fn backward_terms(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.n {
        return;
    }
    let m = mask[p];
    let x = inv_depth[p];
    let g = m * (v_map[3u * p] + v_map[3u * p + 1u] + v_map[3u * p + 2u]);
    let dn = (x - stats[0]) / range();
    out[p] = g;
    out[u.n + p] = g * dn;
    out[2u * u.n + p] = select(0.0, m, x == stats[0]);
    out[3u * u.n + p] = select(0.0, m, x == stats[1]);
}

// ∂/∂d = g / r, plus the min's and max's gradients shared by their ties:
// ∂/∂max = −Σg·d̃ / r, ∂/∂min = (Σg·d̃ − Σg) / r.
@compute @workgroup_size(256)
fn backward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.n {
        return;
    }
    let r = range();
    let sum_v = stats[2];
    let sum_vd = stats[3];
    let n_lo = max(stats[4], 1.0);
    let n_hi = max(stats[5], 1.0);
    let x = inv_depth[p];
    let g = v_map[3u * p] + v_map[3u * p + 1u] + v_map[3u * p + 2u];
    var o = g / r;
    if x == stats[1] {
        o = o - sum_vd / r / n_hi;
    }
    if x == stats[0] {
        o = o + (sum_vd - sum_v) / r / n_lo;
    }
    if mask[p] == 0.0 {
        o = 0.0;
    }
    if u.accumulate == 1u {
        out[p] = out[p] + o;
    } else {
        out[p] = o;
    }
}
