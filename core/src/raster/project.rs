//! Per-Gaussian projection (camera transform, EWA covariance, SH colour,
//! screen extent) and its backward pass, in `f32`.
//!
//! Both directions recompute the same intermediates from the parameters, so
//! the saved state holds only the 2D splats; the backward pass of one Gaussian
//! needs nothing from any other.

use glam::{Mat3, Vec3};

use super::splat::{ALPHA_MIN, EXTENT_ABS, EXTENT_REL, Splat};
use crate::camera::Camera;

/// Real SH basis constants of 3DGS, band 0.
pub(crate) const SH_C0: f32 = 0.282_094_79;
/// Band 1.
pub(crate) const SH_C1: f32 = 0.488_602_51;
/// Band 2.
pub(crate) const SH_C2: [f32; 5] = [1.092_548_4, -1.092_548_4, 0.315_391_57, -1.092_548_4, 0.546_274_2];
/// Band 3.
pub(crate) const SH_C3: [f32; 7] =
    [-0.590_043_6, 2.890_611_4, -0.457_045_8, 0.373_176_33, -0.457_045_8, 1.445_305_7, -0.590_043_6];

/// Variance added to the 2D covariance diagonal (anti-aliasing low-pass), px².
pub(crate) const LOW_PASS: f32 = 0.3;
/// Gaussians with camera `z` at or below this are skipped.
pub(crate) const NEAR_Z: f32 = 0.2;
/// The Jacobian clamps `x/z`, `y/z` to this multiple of `tan(half-fov)`.
pub(crate) const FOV_CLAMP: f32 = 1.3;

/// The camera quantities every Gaussian needs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CamConsts {
    pub rot: Mat3,
    pub trans: Vec3,
    pub center: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub lim_x: f32,
    pub lim_y: f32,
    pub width: u32,
    pub height: u32,
}

impl CamConsts {
    pub fn new(cam: &Camera) -> Self {
        let (tx, ty) = cam.tan_half_fov();
        Self {
            rot: cam.rotation,
            trans: cam.translation,
            center: cam.center(),
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            lim_x: FOV_CLAMP * tx,
            lim_y: FOV_CLAMP * ty,
            width: cam.width,
            height: cam.height,
        }
    }
}

/// Rotation matrix of a normalised quaternion `(w, x, y, z)`.
fn quat_to_mat(q: [f32; 4]) -> Mat3 {
    let [r, x, y, z] = q;
    Mat3::from_cols(
        Vec3::new(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + r * z), 2.0 * (x * z - r * y)),
        Vec3::new(2.0 * (x * y - r * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + r * x)),
        Vec3::new(2.0 * (x * z + r * y), 2.0 * (y * z - r * x), 1.0 - 2.0 * (x * x + y * y)),
    )
}

fn normalize_quat(q: [f32; 4]) -> ([f32; 4], f32) {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    ([q[0] / n, q[1] / n, q[2] / n, q[3] / n], n)
}

/// The SH basis `Y_k(d)` for `k < (deg+1)²` (the rest left zero).
pub(crate) fn sh_basis(d: Vec3, deg: u32) -> [f32; 16] {
    let mut y = [0.0; 16];
    y[0] = SH_C0;
    if deg == 0 {
        return y;
    }
    let (x, yv, z) = (d.x, d.y, d.z);
    y[1] = -SH_C1 * yv;
    y[2] = SH_C1 * z;
    y[3] = -SH_C1 * x;
    if deg == 1 {
        return y;
    }
    let (xx, yy, zz) = (x * x, yv * yv, z * z);
    y[4] = SH_C2[0] * x * yv;
    y[5] = SH_C2[1] * yv * z;
    y[6] = SH_C2[2] * (2.0 * zz - xx - yy);
    y[7] = SH_C2[3] * x * z;
    y[8] = SH_C2[4] * (xx - yy);
    if deg == 2 {
        return y;
    }
    y[9] = SH_C3[0] * yv * (3.0 * xx - yy);
    y[10] = SH_C3[1] * x * yv * z;
    y[11] = SH_C3[2] * yv * (4.0 * zz - xx - yy);
    y[12] = SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    y[13] = SH_C3[4] * x * (4.0 * zz - xx - yy);
    y[14] = SH_C3[5] * z * (xx - yy);
    y[15] = SH_C3[6] * x * (xx - 3.0 * yy);
    y
}

/// `Σ_k w_k ∇Y_k(d)`, the gradient of a weighted basis sum w.r.t. the
/// (unnormalised) direction components.
pub(crate) fn sh_basis_grad(d: Vec3, deg: u32, w: &[f32; 16]) -> Vec3 {
    if deg == 0 {
        return Vec3::ZERO;
    }
    let (x, y, z) = (d.x, d.y, d.z);
    let mut g = Vec3::new(-SH_C1 * w[3], -SH_C1 * w[1], SH_C1 * w[2]);
    if deg == 1 {
        return g;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    g += SH_C2[0] * w[4] * Vec3::new(y, x, 0.0);
    g += SH_C2[1] * w[5] * Vec3::new(0.0, z, y);
    g += SH_C2[2] * w[6] * Vec3::new(-2.0 * x, -2.0 * y, 4.0 * z);
    g += SH_C2[3] * w[7] * Vec3::new(z, 0.0, x);
    g += SH_C2[4] * w[8] * Vec3::new(2.0 * x, -2.0 * y, 0.0);
    if deg == 2 {
        return g;
    }
    g += SH_C3[0] * w[9] * Vec3::new(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
    g += SH_C3[1] * w[10] * Vec3::new(y * z, x * z, x * y);
    g += SH_C3[2] * w[11] * Vec3::new(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
    g += SH_C3[3] * w[12] * Vec3::new(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
    g += SH_C3[4] * w[13] * Vec3::new(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
    g += SH_C3[5] * w[14] * Vec3::new(2.0 * x * z, -2.0 * y * z, xx - yy);
    g += SH_C3[6] * w[15] * Vec3::new(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
    g
}

/// The parameters of one Gaussian, borrowed from [`crate::scene::Gaussians`].
#[derive(Clone, Copy)]
pub(crate) struct GaussianRef<'a> {
    pub mean: [f32; 3],
    pub log_scale: [f32; 3],
    pub quat: [f32; 4],
    pub opacity_logit: f32,
    pub sh: &'a [f32],
    pub deg: u32,
}

/// Intermediates shared by the forward and backward projection.
struct Proj {
    t: Vec3,
    rq: Mat3,
    scale: Vec3,
    qn: [f32; 4],
    qnorm: f32,
    sigma: Mat3,
    /// Rows of `J W`.
    t0: Vec3,
    t1: Vec3,
    /// Clamped `x/z`, `y/z`, and whether each is inside the clamp.
    cxz: f32,
    cyz: f32,
    in_x: bool,
    in_y: bool,
    cov: [f32; 3],
}

#[inline(always)]
fn proj_common(g: &GaussianRef, cc: &CamConsts) -> Option<Proj> {
    let t = cc.rot * Vec3::from(g.mean) + cc.trans;
    if t.z <= NEAR_Z {
        return None;
    }
    let (qn, qnorm) = normalize_quat(g.quat);
    let rq = quat_to_mat(qn);
    let scale = Vec3::from(g.log_scale).exp();
    let m = Mat3::from_cols(rq.x_axis * scale.x, rq.y_axis * scale.y, rq.z_axis * scale.z);
    let sigma = m * m.transpose();
    let (xz, yz) = (t.x / t.z, t.y / t.z);
    let cxz = xz.clamp(-cc.lim_x, cc.lim_x);
    let cyz = yz.clamp(-cc.lim_y, cc.lim_y);
    let (j00, j02) = (cc.fx / t.z, -cc.fx * cxz / t.z);
    let (j11, j12) = (cc.fy / t.z, -cc.fy * cyz / t.z);
    let w = cc.rot;
    let (w0, w1, w2) = (w.row(0), w.row(1), w.row(2));
    let t0 = j00 * w0 + j02 * w2;
    let t1 = j11 * w1 + j12 * w2;
    let st0 = sigma * t0;
    let st1 = sigma * t1;
    let cov = [t0.dot(st0) + LOW_PASS, t0.dot(st1), t1.dot(st1) + LOW_PASS];
    Some(Proj {
        t,
        rq,
        scale,
        qn,
        qnorm,
        sigma,
        t0,
        t1,
        cxz,
        cyz,
        in_x: xz.abs() <= cc.lim_x,
        in_y: yz.abs() <= cc.lim_y,
        cov,
    })
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Raw colour `0.5 + SH·Y(d)` (before the clamp) and the basis used.
#[inline(always)]
fn sh_color(g: &GaussianRef, cc: &CamConsts) -> ([f32; 3], [f32; 16], Vec3, f32) {
    let v = Vec3::from(g.mean) - cc.center;
    let len = v.length();
    let d = v / len;
    let y = sh_basis(d, g.deg);
    let mut col = [0.5f32; 3];
    for (k, coef) in g.sh.chunks_exact(3).enumerate() {
        for c in 0..3 {
            col[c] += y[k] * coef[c];
        }
    }
    (col, y, d, len)
}

/// Projects one Gaussian; `None` when it cannot reach α ≥ 1/255 in any pixel
/// (behind the near plane, too transparent, or off screen).
pub(crate) fn project(g: &GaussianRef, cc: &CamConsts) -> Option<Splat> {
    let opacity = sigmoid(g.opacity_logit);
    if opacity < ALPHA_MIN || opacity.is_nan() {
        return None;
    }
    let p = proj_common(g, cc)?;
    let [a, b, c] = p.cov;
    let det = a * c - b * b;
    if det <= 0.0 || !det.is_finite() {
        return None;
    }
    let conic = [c / det, -b / det, a / det];
    let xy = [cc.fx * p.t.x / p.t.z + cc.cx, cc.fy * p.t.y / p.t.z + cc.cy];
    if !(xy[0].is_finite() && xy[1].is_finite()) {
        return None;
    }
    let cut = (255.0 * opacity).ln().max(0.0);
    let ext = [
        (2.0 * cut * a).sqrt() * (1.0 + EXTENT_REL) + EXTENT_ABS,
        (2.0 * cut * c).sqrt() * (1.0 + EXTENT_REL) + EXTENT_ABS,
    ];
    let mut splat = Splat {
        xy,
        conic,
        opacity,
        color: [0.0; 3],
        inv_z: 1.0 / p.t.z,
        depth: p.t.z,
        cut,
        ext,
        inv_a: 1.0 / conic[0],
        det_conic: conic[0] * conic[2] - conic[1] * conic[1],
    };
    let (ja, jb, ia, ib) = splat.pixel_rect(0, cc.width, 0, cc.height);
    if ja > jb || ia > ib {
        return None;
    }
    let (col, ..) = sh_color(g, cc);
    splat.color = col.map(|x| x.max(0.0));
    Some(splat)
}

/// Gradient of the loss w.r.t. one splat's screen parameters, in the order
/// `[x, y, A, B, C, opacity, r, g, b, inv_z]`.
pub(crate) type SplatGrad = [f32; 10];

/// Gradients of one Gaussian's parameters.
pub(crate) struct GaussianGrad<'a> {
    pub v_mean: &'a mut [f32; 3],
    pub v_log_scale: &'a mut [f32; 3],
    pub v_quat: &'a mut [f32; 4],
    pub v_opacity_logit: &'a mut f32,
    pub v_sh: &'a mut [f32],
}

/// Backward of [`project`]: from the splat gradient to the Gaussian's
/// parameter gradients (written, not accumulated).
pub(crate) fn project_backward(g: &GaussianRef, cc: &CamConsts, vs: &SplatGrad, out: GaussianGrad) {
    let Some(p) = proj_common(g, cc) else { return };
    let t = p.t;
    let (z, z2) = (t.z, t.z * t.z);

    // Opacity.
    let op = sigmoid(g.opacity_logit);
    *out.v_opacity_logit = vs[5] * op * (1.0 - op);

    // Colour → SH coefficients and view direction.
    let (raw, y, d, len) = sh_color(g, cc);
    let v_col: [f32; 3] = std::array::from_fn(|c| if raw[c] > 0.0 { vs[6 + c] } else { 0.0 });
    // The direction's weights count every coefficient; `out.v_sh` takes
    // the first ones, as many as it holds.
    let mut w = [0.0f32; 16];
    for (k, coef) in g.sh.chunks_exact(3).enumerate() {
        for c in 0..3 {
            w[k] += coef[c] * v_col[c];
        }
    }
    for (k, vk) in out.v_sh.chunks_exact_mut(3).enumerate() {
        for c in 0..3 {
            vk[c] = y[k] * v_col[c];
        }
    }
    let v_d = sh_basis_grad(d, g.deg, &w);
    let mut v_mean = (v_d - d * d.dot(v_d)) / len;

    // Conic → 2D covariance: V = −K G K with G the symmetric-matrix gradient.
    let [a, b, c] = p.cov;
    let det = a * c - b * b;
    let (ka, kb, kc) = (c / det, -b / det, a / det);
    let (ga, gb, gc) = (vs[2], 0.5 * vs[3], vs[4]);
    // K G
    let (m00, m01, m10, m11) = (ka * ga + kb * gb, ka * gb + kb * gc, kb * ga + kc * gb, kb * gb + kc * gc);
    // −(K G) K
    let v00 = -(m00 * ka + m01 * kb);
    let v01 = -(m00 * kb + m01 * kc);
    let v10 = -(m10 * ka + m11 * kb);
    let v11 = -(m10 * kb + m11 * kc);
    let v01 = 0.5 * (v01 + v10);

    // cov2D = T Σ Tᵀ: gradients w.r.t. Σ and the rows of T = J W.
    let st0 = p.sigma * p.t0;
    let st1 = p.sigma * p.t1;
    let v_t0 = 2.0 * (v00 * st0 + v01 * st1);
    let v_t1 = 2.0 * (v01 * st0 + v11 * st1);
    let outer = |u: Vec3, v: Vec3| Mat3::from_cols(u * v.x, u * v.y, u * v.z);
    let v_sigma = v00 * outer(p.t0, p.t0) + v01 * (outer(p.t0, p.t1) + outer(p.t1, p.t0)) + v11 * outer(p.t1, p.t1);

    // T rows → Jacobian entries → camera-space mean.
    let wr = cc.rot;
    let (w0, w1, w2) = (wr.row(0), wr.row(1), wr.row(2));
    let (vj00, vj02) = (v_t0.dot(w0), v_t0.dot(w2));
    let (vj11, vj12) = (v_t1.dot(w1), v_t1.dot(w2));
    let mut v_t = Vec3::ZERO;
    // J00 = fx/z, J02 = −fx·cx/z with cx = clamp(x/z).
    v_t.z += -vj00 * cc.fx / z2 - vj11 * cc.fy / z2;
    v_t.z += vj02 * cc.fx * p.cxz / z2 + vj12 * cc.fy * p.cyz / z2;
    if p.in_x {
        // d cx/dx = 1/z, d cx/dz = −x/z²
        v_t.x += vj02 * (-cc.fx / z) / z;
        v_t.z += vj02 * (-cc.fx / z) * (-t.x / z2);
    }
    if p.in_y {
        v_t.y += vj12 * (-cc.fy / z) / z;
        v_t.z += vj12 * (-cc.fy / z) * (-t.y / z2);
    }
    // Projected mean and inverse depth.
    v_t.x += vs[0] * cc.fx / z;
    v_t.y += vs[1] * cc.fy / z;
    v_t.z += -(vs[0] * cc.fx * t.x + vs[1] * cc.fy * t.y) / z2 - vs[9] / z2;
    v_mean += wr.transpose() * v_t;
    *out.v_mean = v_mean.to_array();

    // Σ = M Mᵀ, M = R S.
    let m = Mat3::from_cols(p.rq.x_axis * p.scale.x, p.rq.y_axis * p.scale.y, p.rq.z_axis * p.scale.z);
    let v_m = 2.0 * v_sigma * m;
    let v_r = Mat3::from_cols(v_m.x_axis * p.scale.x, v_m.y_axis * p.scale.y, v_m.z_axis * p.scale.z);
    let v_s = Vec3::new(v_m.x_axis.dot(p.rq.x_axis), v_m.y_axis.dot(p.rq.y_axis), v_m.z_axis.dot(p.rq.z_axis));
    *out.v_log_scale = (v_s * p.scale).to_array();

    // Rotation → normalised quaternion → raw quaternion.
    let e = |i: usize, j: usize| v_r.col(j)[i];
    let [r, x, y, z] = p.qn;
    let vq = [
        2.0 * (-z * e(0, 1) + y * e(0, 2) + z * e(1, 0) - x * e(1, 2) - y * e(2, 0) + x * e(2, 1)),
        2.0 * (y * e(0, 1) + z * e(0, 2) + y * e(1, 0) - 2.0 * x * e(1, 1) - r * e(1, 2) + z * e(2, 0) + r * e(2, 1)
            - 2.0 * x * e(2, 2)),
        2.0 * (-2.0 * y * e(0, 0) + x * e(0, 1) + r * e(0, 2) + x * e(1, 0) + z * e(1, 2) - r * e(2, 0) + z * e(2, 1)
            - 2.0 * y * e(2, 2)),
        2.0 * (-2.0 * z * e(0, 0) - r * e(0, 1) + x * e(0, 2) + r * e(1, 0) - 2.0 * z * e(1, 1)
            + y * e(1, 2)
            + x * e(2, 0)
            + y * e(2, 1)),
    ];
    let dot = r * vq[0] + x * vq[1] + y * vq[2] + z * vq[3];
    *out.v_quat = std::array::from_fn(|k| (vq[k] - p.qn[k] * dot) / p.qnorm);
}
