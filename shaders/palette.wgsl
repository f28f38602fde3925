// The palette hold on an RGB render (core/src/gpu/losses/palette.rs; CPU
// twin: palette_loss in style/palette.rs): over the covered pixels, per
// channel c the mean μ_c and deviation σ_c, d_c = μ_c − μ^c_c and
// e_c = σ_c − σ^c_c against the colour-matched render's, L = Σ_c d_c² + e_c²
// and grad += λ · (2 d_c / n + 2 e_c (x − μ_c) / (n σ_c)) at every covered
// pixel (the second part 0 for a flat channel). The render is HWC; mask is
// the pixel mask (1 covered, 0 not, see focus.wgsl). Two passes: `stats`
// (one workgroup per channel) writes the channel's coefficients and its
// share of L for the reduction, `grad_add` adds the gradient.

struct PaletteParams {
    // Pixels (the mask's length).
    pixels: u32,
    // λ
    weight: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: PaletteParams;
@group(0) @binding(1) var<storage, read> rgb: array<f32>;
@group(0) @binding(2) var<storage, read> mask: array<f32>;
// μ^c then σ^c per channel (6 floats).
@group(0) @binding(3) var<storage, read> reference: array<f32>;
// Per channel: a = 2d/n, b = 2e/(nσ), μ (9 floats).
@group(0) @binding(4) var<storage, read_write> coef: array<f32>;
// Per channel d² + e², for the reduction.
@group(0) @binding(5) var<storage, read_write> sq: array<f32>;
@group(0) @binding(6) var<storage, read_write> grad: array<f32>;

var<workgroup> s1: array<f32, 256>;
var<workgroup> s2: array<f32, 256>;
var<workgroup> sn: array<f32, 256>;

// One workgroup per channel: masked sums of x, x² and the count by a
// strided sum and a tree.
@compute @workgroup_size(256)
fn stats(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = wid.x;
    var a = 0.0;
    var b = 0.0;
    var n = 0.0;
    for (var p = lid; p < u.pixels; p = p + 256u) {
        let m = mask[p];
        let x = rgb[3u * p + c];
        a = a + m * x;
        b = b + m * x * x;
        n = n + m;
    }
    s1[lid] = a;
    s2[lid] = b;
    sn[lid] = n;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride = stride / 2u) {
        if lid < stride {
            s1[lid] = s1[lid] + s1[lid + stride];
            s2[lid] = s2[lid] + s2[lid + stride];
            sn[lid] = sn[lid] + sn[lid + stride];
        }
        workgroupBarrier();
    }
    if lid == 0u {
        let count = sn[0];
        var ca = 0.0;
        var cb = 0.0;
        var mu = 0.0;
        var l = 0.0;
        if count > 0.0 {
            mu = s1[0] / count;
            let sigma = sqrt(max(s2[0] / count - mu * mu, 0.0));
            let d = mu - reference[c];
            let e = sigma - reference[3u + c];
            l = d * d + e * e;
            ca = 2.0 * d / count;
            if sigma > 1e-6 {
                cb = 2.0 * e / (count * sigma);
            }
        }
        coef[3u * c] = ca;
        coef[3u * c + 1u] = cb;
        coef[3u * c + 2u] = mu;
        sq[c] = l;
    }
}

@compute @workgroup_size(256)
fn grad_add(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i >= 3u * u.pixels {
        return;
    }
    let p = i / 3u;
    let c = i % 3u;
    if mask[p] == 0.0 {
        return;
    }
    grad[i] = grad[i] + u.weight * (coef[3u * c] + coef[3u * c + 1u] * (rgb[i] - coef[3u * c + 2u]));
}
