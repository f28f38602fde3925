// The depth map's relief on the GPU (core/src/gpu/losses/relief.rs; CPU twin:
// style/relief.rs): the min-max normalised depth d̃ minus its masked blur
// B d̃ = (1/n)·K(m·(1/n)·K(m·d̃)), K a box sum of radius r over rows then
// columns (clipped at the borders), m the 0/1 pixel mask, n = K m; centred
// on 0.5 by the peak |relief| over the mask; and the adjoint of both.
// stats: [max |relief|, Σ relief·g, #(pixels at the peak)], the first from the
// forward's reduction, the other two from the backward's.

struct ReliefParams {
    h: u32,
    w: u32,
    // Radius of the box, pixels.
    r: u32,
    // Stride of `src` in `rows` (3: channel 0 of an h × w × 3 map; else 1).
    stride: u32,
}

@group(0) @binding(0) var<uniform> u: ReliefParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> weight: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;
@group(0) @binding(4) var<storage, read> aux: array<f32>;
@group(0) @binding(5) var<storage, read> stats: array<f32>;

fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// M = max |relief| + 1e-8, as the CPU's `peak`.
fn peak() -> f32 {
    return stats[0] + 1e-8;
}

// dst[p] = Σ over the row's neighbours q within r of weight[q]·src[q·stride].
@compute @workgroup_size(256)
fn rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    let x = p % u.w;
    let row = p - x;
    let lo = row + select(0u, x - u.r, x > u.r);
    let hi = row + min(x + u.r, u.w - 1u);
    var s = 0.0;
    for (var q = lo; q <= hi; q++) {
        s += weight[q] * src[q * u.stride];
    }
    dst[p] = s;
}

// Σ over the column's neighbours q of pixel p within r of src[q].
fn column_sum(p: u32) -> f32 {
    let x = p % u.w;
    let y = p / u.w;
    let y_lo = select(0u, y - u.r, y > u.r);
    let y_hi = min(y + u.r, u.h - 1u);
    var s = 0.0;
    for (var yy = y_lo; yy <= y_hi; yy++) {
        s += src[yy * u.w + x];
    }
    return s;
}

// dst[p] = weight[p]·Σ over the column's neighbours q within r of src[q].
@compute @workgroup_size(256)
fn cols(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    dst[p] = weight[p] * column_sum(p);
}

// dst[p] = 1 / Σ over the column's neighbours of src (the rows' box sums of
// the mask), 0 where no covered pixel is near.
@compute @workgroup_size(256)
fn count_inverse(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    let s = column_sum(p);
    dst[p] = select(0.0, 1.0 / s, s > 0.0);
}

// The relief (dst holds 2n): dst[p] = m·(d̃ − B d̃) with d̃ = aux[3p] (the
// normalised map's channel 0) and B d̃ = src; dst[n + p] = its magnitude,
// for the peak's reduction.
@compute @workgroup_size(256)
fn relief(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = u.h * u.w;
    let p = flat_index(gid, nwg);
    if p >= n {
        return;
    }
    let rel = weight[p] * (aux[3u * p] - src[p]);
    dst[p] = rel;
    dst[n + p] = abs(rel);
}

// dst (n × 3) = 0.5 + relief / (2M), replicated; 0.5 where there is no relief.
@compute @workgroup_size(256)
fn centre(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    let v = 0.5 + src[p] / (2.0 * peak());
    dst[3u * p] = v;
    dst[3u * p + 1u] = v;
    dst[3u * p + 2u] = v;
}

// Two planes for the backward's sums (dst holds 2n), with g = Σ_k aux[3p + k]
// the centred map's gradient: relief·g, and 1 at a covered pixel at the peak.
@compute @workgroup_size(256)
fn centre_terms(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = u.h * u.w;
    let p = flat_index(gid, nwg);
    if p >= n {
        return;
    }
    let g = aux[3u * p] + aux[3u * p + 1u] + aux[3u * p + 2u];
    let rel = src[p];
    dst[p] = rel * g;
    dst[n + p] = select(0.0, 1.0, weight[p] != 0.0 && abs(rel) == stats[0]);
}

// The centring's adjoint: g / (2M) inside the mask, plus, at the peak, its
// share of −sign(relief)·Σ relief·g / (2M²), split among the ties; 0 outside.
@compute @workgroup_size(256)
fn centre_back(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    let m = peak();
    let g = aux[3u * p] + aux[3u * p + 1u] + aux[3u * p + 2u];
    let rel = src[p];
    var o = g / (2.0 * m);
    if abs(rel) == stats[0] {
        let g_peak = -stats[1] / (2.0 * m * m) / max(stats[2], 1.0);
        o += g_peak * select(-1.0, 1.0, rel >= 0.0);
    }
    dst[p] = select(0.0, o, weight[p] != 0.0);
}

// The relief's adjoint into channel 0 of an n × 3 map (the others 0, so the
// min-max backward's channel sum reads it): aux − src, with aux = m·v and
// src = Bᵀ(m·v).
@compute @workgroup_size(256)
fn relief_back(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    dst[3u * p] = aux[p] - src[p];
    dst[3u * p + 1u] = 0.0;
    dst[3u * p + 2u] = 0.0;
}
