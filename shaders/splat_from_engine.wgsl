// Copies the GPU engine's optimised Gaussians into the viewport's layout, in
// place, on the device: the viewport then draws a running optimisation with no
// round trip through the CPU. Two entry points, one pass each:
//   scatter_geometry: means, log-scales, quaternions and opacity logits (the
//     engine's flat f32 arrays) into three vec4 per Gaussian at keep[j];
//   scatter_sh: the SH coefficients up to the drawn degree as packed f16 pairs
//     in the viewport's two SH bindings (split at `split`).
// Every value moves as bits (f32 copied as u32), and f32 → f16 rounds to the
// nearest even as the CPU packer (the `half` crate) does, so the result equals
// a CPU snapshot uploaded by SplatRenderer::set_scene bit for bit.
// Launched by app/src/studio/viewport/splat_from_engine.rs.

struct Params {
    // optimised Gaussians, SH floats drawn per Gaussian, engine SH floats per Gaussian, u32 SH words per Gaussian
    counts: vec4<u32>,
    // split index of the viewport's SH bindings, unused ×3
    split: vec4<u32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keep: array<u32>;
@group(0) @binding(2) var<storage, read> means: array<u32>;
@group(0) @binding(3) var<storage, read> log_scales: array<u32>;
@group(0) @binding(4) var<storage, read> quats: array<u32>;
@group(0) @binding(5) var<storage, read> opacity_logits: array<u32>;
// The viewport's geometry: (mean, opacity logit), (log scale, 0), quaternion, as bits.
@group(0) @binding(6) var<storage, read_write> geom: array<u32>;
@group(0) @binding(7) var<storage, read> sh: array<u32>;
@group(0) @binding(8) var<storage, read_write> sh_a: array<u32>;
@group(0) @binding(9) var<storage, read_write> sh_b: array<u32>;

// The `half` crate's f32 → f16 conversion (round to nearest, ties to even;
// NaN keeps its top mantissa bits and stays NaN; overflow gives ±inf).
fn f16_bits(x: u32) -> u32 {
    let sign = (x & 0x80000000u) >> 16u;
    let exp = x & 0x7F800000u;
    let man = x & 0x007FFFFFu;
    if (exp == 0x7F800000u) {
        let nan_bit = select(0x0200u, 0u, man == 0u);
        return sign | 0x7C00u | nan_bit | (man >> 13u);
    }
    let half_exp = i32(exp >> 23u) - 127 + 15;
    if (half_exp >= 0x1F) {
        return sign | 0x7C00u;
    }
    if (half_exp <= 0) {
        if (14 - half_exp > 24) {
            return sign;
        }
        let m = man | 0x00800000u;
        var half_man = m >> u32(14 - half_exp);
        let round_bit = 1u << u32(13 - half_exp);
        if ((m & round_bit) != 0u && (m & (3u * round_bit - 1u)) != 0u) {
            half_man += 1u;
        }
        return sign | half_man;
    }
    let bits = sign | (u32(half_exp) << 10u) | (man >> 13u);
    let round_bit = 0x00001000u;
    if ((man & round_bit) != 0u && (man & (3u * round_bit - 1u)) != 0u) {
        return bits + 1u;
    }
    return bits;
}

fn index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    // 2D dispatch so that more than 65535 workgroups' worth of Gaussians fit.
    return gid.x + gid.y * nwg.x * 256u;
}

@compute @workgroup_size(256)
fn scatter_geometry(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let j = index(gid, nwg);
    if (j >= params.counts.x) {
        return;
    }
    let o = keep[j] * 12u;
    for (var c = 0u; c < 3u; c++) {
        geom[o + c] = means[j * 3u + c];
        geom[o + 4u + c] = log_scales[j * 3u + c];
    }
    geom[o + 3u] = opacity_logits[j];
    geom[o + 7u] = 0u;
    for (var c = 0u; c < 4u; c++) {
        geom[o + 8u + c] = quats[j * 4u + c];
    }
}

@compute @workgroup_size(256)
fn scatter_sh(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let j = index(gid, nwg);
    if (j >= params.counts.x) {
        return;
    }
    let per = params.counts.y;
    let stride = params.counts.z;
    let words = params.counts.w;
    let split = params.split.x;
    let i = keep[j];
    let src = j * stride;
    for (var k = 0u; k < words; k++) {
        let lo = f16_bits(sh[src + 2u * k]);
        var hi = 0u;
        if (2u * k + 1u < per) {
            hi = f16_bits(sh[src + 2u * k + 1u]);
        }
        let w = lo | (hi << 16u);
        if (i < split) {
            sh_a[i * words + k] = w;
        } else {
            sh_b[(i - split) * words + k] = w;
        }
    }
}
