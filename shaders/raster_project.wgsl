// Per-Gaussian projection and its backward pass (core/src/gpu/raster/raster_project.rs;
// CPU twin: core/src/raster/project.rs, whose formulas this follows line by line).
//
// `project`: camera transform, EWA covariance (+0.3 px², clamped Jacobian),
// conic, screen extent of the α ≥ 1/255 ellipse, SH colour clamped at 0; writes
// the 16-float splat of each Gaussian (by Gaussian index) and its depth sort key
// (u32::MAX when culled, so culled Gaussians sort last).
// `project_backward`: from the 10 screen-space gradients of each Gaussian to
// its parameter gradients (written, zeros where there is no gradient).

// `struct Cam` (the uniform block): shaders/raster_camera.wgsl, prepended by the Rust side.

@group(0) @binding(0) var<uniform> cam: Cam;
@group(0) @binding(1) var<storage, read> means: array<f32>;
@group(0) @binding(2) var<storage, read> log_scales: array<f32>;
@group(0) @binding(3) var<storage, read> quats: array<f32>;
@group(0) @binding(4) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(5) var<storage, read> sh: array<f32>;
// project: the splats, depth keys and Gaussian indices.
@group(0) @binding(6) var<storage, read_write> splats: array<f32>;
@group(0) @binding(7) var<storage, read_write> depth_keys: array<u32>;
@group(0) @binding(8) var<storage, read_write> order: array<u32>;
// project_backward: screen-space gradients in, parameter gradients out.
@group(0) @binding(6) var<storage, read> v_splat: array<f32>;
@group(0) @binding(7) var<storage, read_write> v_means: array<f32>;
@group(0) @binding(8) var<storage, read_write> v_log_scales: array<f32>;
@group(0) @binding(9) var<storage, read_write> v_quats: array<f32>;
@group(0) @binding(10) var<storage, read_write> v_opacity_logits: array<f32>;
@group(0) @binding(11) var<storage, read_write> v_sh: array<f32>;

const SH_C0: f32 = 0.28209479;
const SH_C1: f32 = 0.48860251;
const SH_C2_0: f32 = 1.0925484;
const SH_C2_1: f32 = -1.0925484;
const SH_C2_2: f32 = 0.31539157;
const SH_C2_3: f32 = -1.0925484;
const SH_C2_4: f32 = 0.5462742;
const SH_C3_0: f32 = -0.5900436;
const SH_C3_1: f32 = 2.8906114;
const SH_C3_2: f32 = -0.4570458;
const SH_C3_3: f32 = 0.37317633;
const SH_C3_4: f32 = -0.4570458;
const SH_C3_5: f32 = 1.4453057;
const SH_C3_6: f32 = -0.5900436;
const LOW_PASS: f32 = 0.3;
const NEAR_Z: f32 = 0.2;
const ALPHA_MIN: f32 = 0.003921569;
const EXTENT_REL: f32 = 1e-3;
const EXTENT_ABS: f32 = 1e-2;
const SPLAT: u32 = 16u;
const NO_KEY: u32 = 0xffffffffu;

fn index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}

fn quat_to_mat(q: vec4<f32>) -> mat3x3<f32> {
    let r = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + r * z), 2.0 * (x * z - r * y)),
        vec3<f32>(2.0 * (x * y - r * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + r * x)),
        vec3<f32>(2.0 * (x * z + r * y), 2.0 * (y * z - r * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

fn mean_of(i: u32) -> vec3<f32> {
    return vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
}

// Camera-space position R m + t.
fn to_camera(m: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(cam.r0.xyz, m), dot(cam.r1.xyz, m), dot(cam.r2.xyz, m)) + cam.trans.xyz;
}

struct Proj {
    t: vec3<f32>,
    rq: mat3x3<f32>,
    scale: vec3<f32>,
    qn: vec4<f32>,
    qnorm: f32,
    sigma: mat3x3<f32>,
    t0: vec3<f32>,
    t1: vec3<f32>,
    cxz: f32,
    cyz: f32,
    in_x: bool,
    in_y: bool,
    cov: vec3<f32>,
}

// The shared intermediates; `t.z <= NEAR_Z` means the Gaussian is culled.
fn proj_common(i: u32) -> Proj {
    var p: Proj;
    p.t = to_camera(mean_of(i));
    if p.t.z <= NEAR_Z {
        return p;
    }
    let q = vec4<f32>(quats[4u * i], quats[4u * i + 1u], quats[4u * i + 2u], quats[4u * i + 3u]);
    p.qnorm = sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    p.qn = q / p.qnorm;
    p.rq = quat_to_mat(p.qn);
    p.scale = exp(vec3<f32>(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]));
    let m = mat3x3<f32>(p.rq[0] * p.scale.x, p.rq[1] * p.scale.y, p.rq[2] * p.scale.z);
    p.sigma = m * transpose(m);
    let t = p.t;
    let xz = t.x / t.z;
    let yz = t.y / t.z;
    p.cxz = clamp(xz, -cam.lim_x, cam.lim_x);
    p.cyz = clamp(yz, -cam.lim_y, cam.lim_y);
    let j00 = cam.fx / t.z;
    let j02 = -cam.fx * p.cxz / t.z;
    let j11 = cam.fy / t.z;
    let j12 = -cam.fy * p.cyz / t.z;
    p.t0 = j00 * cam.r0.xyz + j02 * cam.r2.xyz;
    p.t1 = j11 * cam.r1.xyz + j12 * cam.r2.xyz;
    let st0 = p.sigma * p.t0;
    let st1 = p.sigma * p.t1;
    p.cov = vec3<f32>(dot(p.t0, st0) + LOW_PASS, dot(p.t0, st1), dot(p.t1, st1) + LOW_PASS);
    p.in_x = abs(xz) <= cam.lim_x;
    p.in_y = abs(yz) <= cam.lim_y;
    return p;
}

// The SH basis for the unit direction d.
fn sh_basis(d: vec3<f32>) -> array<f32, 16> {
    var y: array<f32, 16>;
    y[0] = SH_C0;
    let deg = cam.sh_degree;
    if deg == 0u {
        return y;
    }
    let x = d.x;
    let yv = d.y;
    let z = d.z;
    y[1] = -SH_C1 * yv;
    y[2] = SH_C1 * z;
    y[3] = -SH_C1 * x;
    if deg == 1u {
        return y;
    }
    let xx = x * x;
    let yy = yv * yv;
    let zz = z * z;
    y[4] = SH_C2_0 * x * yv;
    y[5] = SH_C2_1 * yv * z;
    y[6] = SH_C2_2 * (2.0 * zz - xx - yy);
    y[7] = SH_C2_3 * x * z;
    y[8] = SH_C2_4 * (xx - yy);
    if deg == 2u {
        return y;
    }
    y[9] = SH_C3_0 * yv * (3.0 * xx - yy);
    y[10] = SH_C3_1 * x * yv * z;
    y[11] = SH_C3_2 * yv * (4.0 * zz - xx - yy);
    y[12] = SH_C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    y[13] = SH_C3_4 * x * (4.0 * zz - xx - yy);
    y[14] = SH_C3_5 * z * (xx - yy);
    y[15] = SH_C3_6 * x * (xx - 3.0 * yy);
    return y;
}

// Σ_k w_k ∇Y_k(d).
fn sh_basis_grad(d: vec3<f32>, w: array<f32, 16>) -> vec3<f32> {
    let deg = cam.sh_degree;
    if deg == 0u {
        return vec3<f32>(0.0);
    }
    let x = d.x;
    let y = d.y;
    let z = d.z;
    var g = vec3<f32>(-SH_C1 * w[3], -SH_C1 * w[1], SH_C1 * w[2]);
    if deg == 1u {
        return g;
    }
    let xx = x * x;
    let yy = y * y;
    let zz = z * z;
    g += SH_C2_0 * w[4] * vec3<f32>(y, x, 0.0);
    g += SH_C2_1 * w[5] * vec3<f32>(0.0, z, y);
    g += SH_C2_2 * w[6] * vec3<f32>(-2.0 * x, -2.0 * y, 4.0 * z);
    g += SH_C2_3 * w[7] * vec3<f32>(z, 0.0, x);
    g += SH_C2_4 * w[8] * vec3<f32>(2.0 * x, -2.0 * y, 0.0);
    if deg == 2u {
        return g;
    }
    g += SH_C3_0 * w[9] * vec3<f32>(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
    g += SH_C3_1 * w[10] * vec3<f32>(y * z, x * z, x * y);
    g += SH_C3_2 * w[11] * vec3<f32>(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
    g += SH_C3_3 * w[12] * vec3<f32>(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
    g += SH_C3_4 * w[13] * vec3<f32>(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
    g += SH_C3_5 * w[14] * vec3<f32>(2.0 * x * z, -2.0 * y * z, xx - yy);
    g += SH_C3_6 * w[15] * vec3<f32>(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
    return g;
}

// Unit view direction and distance from the camera centre to the mean.
fn view_dir(i: u32) -> vec4<f32> {
    let v = mean_of(i) - cam.center.xyz;
    let len = length(v);
    return vec4<f32>(v / len, len);
}

// Raw colour 0.5 + SH·Y(d), before the clamp.
fn sh_color(i: u32, y: array<f32, 16>) -> vec3<f32> {
    var col = vec3<f32>(0.5);
    let base = i * cam.sh_coeffs * 3u;
    for (var k = 0u; k < cam.sh_coeffs; k = k + 1u) {
        col += y[k] * vec3<f32>(sh[base + 3u * k], sh[base + 3u * k + 1u], sh[base + 3u * k + 2u]);
    }
    return col;
}

// Pixels k in [lo, hi) with centre k + 0.5 in [a, b]: (first, last), empty when first > last.
fn centre_span(a: f32, b: f32, lo: u32, hi: u32) -> vec2<i32> {
    let first = max(i32(clamp(ceil(a - 0.5), -1e9, 1e9)), i32(lo));
    let last = min(i32(clamp(floor(b - 0.5), -1e9, 1e9)), i32(hi) - 1);
    return vec2<i32>(first, last);
}

fn cull(i: u32) {
    for (var f = 0u; f < SPLAT; f = f + 1u) {
        splats[i * SPLAT + f] = 0.0;
    }
    depth_keys[i] = NO_KEY;
}

@compute @workgroup_size(256)
fn project(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = index(gid, nwg);
    if i >= cam.n {
        return;
    }
    order[i] = i;
    let opacity = sigmoid(opacity_logits[i]);
    if !(opacity >= ALPHA_MIN) {
        cull(i);
        return;
    }
    let p = proj_common(i);
    if !(p.t.z > NEAR_Z) {
        cull(i);
        return;
    }
    let a = p.cov.x;
    let b = p.cov.y;
    let c = p.cov.z;
    let det = a * c - b * b;
    if !(det > 0.0) || !(abs(det) <= 3.4e38) {
        cull(i);
        return;
    }
    let conic = vec3<f32>(c / det, -b / det, a / det);
    let xy = vec2<f32>(cam.fx * p.t.x / p.t.z + cam.cx, cam.fy * p.t.y / p.t.z + cam.cy);
    if !(abs(xy.x) <= 3.4e38 && abs(xy.y) <= 3.4e38) {
        cull(i);
        return;
    }
    let cut = max(log(255.0 * opacity), 0.0);
    let ext = vec2<f32>(
        sqrt(2.0 * cut * a) * (1.0 + EXTENT_REL) + EXTENT_ABS,
        sqrt(2.0 * cut * c) * (1.0 + EXTENT_REL) + EXTENT_ABS,
    );
    let sx = centre_span(xy.x - ext.x, xy.x + ext.x, 0u, cam.width);
    let sy = centre_span(xy.y - ext.y, xy.y + ext.y, 0u, cam.height);
    if sx.x > sx.y || sy.x > sy.y {
        cull(i);
        return;
    }
    let dl = view_dir(i);
    let col = max(sh_color(i, sh_basis(dl.xyz)), vec3<f32>(0.0));
    let o = i * SPLAT;
    splats[o] = xy.x;
    splats[o + 1u] = xy.y;
    splats[o + 2u] = conic.x;
    splats[o + 3u] = conic.y;
    splats[o + 4u] = conic.z;
    splats[o + 5u] = opacity;
    splats[o + 6u] = col.x;
    splats[o + 7u] = col.y;
    splats[o + 8u] = col.z;
    splats[o + 9u] = 1.0 / p.t.z;
    splats[o + 10u] = p.t.z;
    splats[o + 11u] = cut;
    splats[o + 12u] = ext.x;
    splats[o + 13u] = ext.y;
    splats[o + 14u] = 1.0 / conic.x;
    splats[o + 15u] = conic.x * conic.z - conic.y * conic.y;
    // Positive floats order like their bits.
    depth_keys[i] = bitcast<u32>(p.t.z);
}

fn write_zero_grads(i: u32) {
    for (var c = 0u; c < 3u; c = c + 1u) {
        v_means[3u * i + c] = 0.0;
        v_log_scales[3u * i + c] = 0.0;
    }
    for (var c = 0u; c < 4u; c = c + 1u) {
        v_quats[4u * i + c] = 0.0;
    }
    v_opacity_logits[i] = 0.0;
    let base = i * cam.grad_sh_coeffs * 3u;
    for (var k = 0u; k < cam.grad_sh_coeffs * 3u; k = k + 1u) {
        v_sh[base + k] = 0.0;
    }
}

fn outer(u: vec3<f32>, v: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(u * v.x, u * v.y, u * v.z);
}

@compute @workgroup_size(256)
fn project_backward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = index(gid, nwg);
    if i >= cam.n {
        return;
    }
    var vs: array<f32, 10>;
    var has = false;
    for (var k = 0u; k < 10u; k = k + 1u) {
        vs[k] = v_splat[10u * i + k];
        has = has || vs[k] != 0.0;
    }
    let p = proj_common(i);
    if !has || !(p.t.z > NEAR_Z) {
        write_zero_grads(i);
        return;
    }
    let t = p.t;
    let z = t.z;
    let z2 = z * z;

    let op = sigmoid(opacity_logits[i]);
    v_opacity_logits[i] = vs[5] * op * (1.0 - op);

    // Colour → SH coefficients and view direction.
    let dl = view_dir(i);
    let d = dl.xyz;
    let y = sh_basis(d);
    let raw = sh_color(i, y);
    let v_col = select(vec3<f32>(0.0), vec3<f32>(vs[6], vs[7], vs[8]), raw > vec3<f32>(0.0));
    var w: array<f32, 16>;
    let base = i * cam.sh_coeffs * 3u;
    let v_base = i * cam.grad_sh_coeffs * 3u;
    for (var k = 0u; k < cam.sh_coeffs; k = k + 1u) {
        let coef = vec3<f32>(sh[base + 3u * k], sh[base + 3u * k + 1u], sh[base + 3u * k + 2u]);
        if k < cam.grad_sh_coeffs {
            v_sh[v_base + 3u * k] = y[k] * v_col.x;
            v_sh[v_base + 3u * k + 1u] = y[k] * v_col.y;
            v_sh[v_base + 3u * k + 2u] = y[k] * v_col.z;
        }
        w[k] = dot(coef, v_col);
    }
    let v_d = sh_basis_grad(d, w);
    var v_mean = (v_d - d * dot(d, v_d)) / dl.w;

    // Conic → 2D covariance.
    let a = p.cov.x;
    let b = p.cov.y;
    let c = p.cov.z;
    let det = a * c - b * b;
    let ka = c / det;
    let kb = -b / det;
    let kc = a / det;
    let ga = vs[2];
    let gb = 0.5 * vs[3];
    let gc = vs[4];
    let m00 = ka * ga + kb * gb;
    let m01 = ka * gb + kb * gc;
    let m10 = kb * ga + kc * gb;
    let m11 = kb * gb + kc * gc;
    let v00 = -(m00 * ka + m01 * kb);
    let v01a = -(m00 * kb + m01 * kc);
    let v10 = -(m10 * ka + m11 * kb);
    let v11 = -(m10 * kb + m11 * kc);
    let v01 = 0.5 * (v01a + v10);

    // cov2D = T Σ Tᵀ.
    let st0 = p.sigma * p.t0;
    let st1 = p.sigma * p.t1;
    let v_t0 = 2.0 * (v00 * st0 + v01 * st1);
    let v_t1 = 2.0 * (v01 * st0 + v11 * st1);
    let v_sigma = v00 * outer(p.t0, p.t0) + v01 * (outer(p.t0, p.t1) + outer(p.t1, p.t0)) + v11 * outer(p.t1, p.t1);

    // T rows → Jacobian entries → camera-space mean.
    let w0 = cam.r0.xyz;
    let w1 = cam.r1.xyz;
    let w2 = cam.r2.xyz;
    let vj00 = dot(v_t0, w0);
    let vj02 = dot(v_t0, w2);
    let vj11 = dot(v_t1, w1);
    let vj12 = dot(v_t1, w2);
    var v_t = vec3<f32>(0.0);
    v_t.z += -vj00 * cam.fx / z2 - vj11 * cam.fy / z2;
    v_t.z += vj02 * cam.fx * p.cxz / z2 + vj12 * cam.fy * p.cyz / z2;
    if p.in_x {
        v_t.x += vj02 * (-cam.fx / z) / z;
        v_t.z += vj02 * (-cam.fx / z) * (-t.x / z2);
    }
    if p.in_y {
        v_t.y += vj12 * (-cam.fy / z) / z;
        v_t.z += vj12 * (-cam.fy / z) * (-t.y / z2);
    }
    v_t.x += vs[0] * cam.fx / z;
    v_t.y += vs[1] * cam.fy / z;
    v_t.z += -(vs[0] * cam.fx * t.x + vs[1] * cam.fy * t.y) / z2 - vs[9] / z2;
    v_mean += w0 * v_t.x + w1 * v_t.y + w2 * v_t.z;
    v_means[3u * i] = v_mean.x;
    v_means[3u * i + 1u] = v_mean.y;
    v_means[3u * i + 2u] = v_mean.z;

    // Σ = M Mᵀ, M = R S.
    let m = mat3x3<f32>(p.rq[0] * p.scale.x, p.rq[1] * p.scale.y, p.rq[2] * p.scale.z);
    let v_m = 2.0 * v_sigma * m;
    let v_r = mat3x3<f32>(v_m[0] * p.scale.x, v_m[1] * p.scale.y, v_m[2] * p.scale.z);
    let v_s = vec3<f32>(dot(v_m[0], p.rq[0]), dot(v_m[1], p.rq[1]), dot(v_m[2], p.rq[2]));
    let v_ls = v_s * p.scale;
    v_log_scales[3u * i] = v_ls.x;
    v_log_scales[3u * i + 1u] = v_ls.y;
    v_log_scales[3u * i + 2u] = v_ls.z;

    // Rotation → normalised quaternion → raw quaternion; e(i, j) = v_r[j][i].
    let r = p.qn.x;
    let x = p.qn.y;
    let yq = p.qn.z;
    let zq = p.qn.w;
    let vq = vec4<f32>(
        2.0 * (-zq * v_r[1][0] + yq * v_r[2][0] + zq * v_r[0][1] - x * v_r[2][1] - yq * v_r[0][2] + x * v_r[1][2]),
        2.0 * (yq * v_r[1][0] + zq * v_r[2][0] + yq * v_r[0][1] - 2.0 * x * v_r[1][1] - r * v_r[2][1] + zq * v_r[0][2]
            + r * v_r[1][2] - 2.0 * x * v_r[2][2]),
        2.0 * (-2.0 * yq * v_r[0][0] + x * v_r[1][0] + r * v_r[2][0] + x * v_r[0][1] + zq * v_r[2][1] - r * v_r[0][2]
            + zq * v_r[1][2] - 2.0 * yq * v_r[2][2]),
        2.0 * (-2.0 * zq * v_r[0][0] - r * v_r[1][0] + x * v_r[2][0] + r * v_r[0][1] - 2.0 * zq * v_r[1][1]
            + yq * v_r[2][1] + x * v_r[0][2] + yq * v_r[1][2]),
    );
    let vq_n = (vq - p.qn * dot(p.qn, vq)) / p.qnorm;
    for (var k = 0u; k < 4u; k = k + 1u) {
        v_quats[4u * i + k] = vq_n[k];
    }
}
