//! A slow, obvious CPU splatter with the viewport shaders' exact rules (EWA
//! with the 0.3 px low-pass and the 1.3·tan(half-fov) clamp, 3-sigma extent,
//! α = min(0.99, o·exp(−½dᵀΣ⁻¹d)), α < 1/255 skipped, front to back, stop at
//! T < 1e-4). The GPU test compares the viewport against it; the inspection
//! panel uses it until `gast_core::raster::render` is merged in.

use gast_core::{Camera, Gaussians};
use glam::{Mat3, Quat, Vec3};

/// One Gaussian in screen space.
#[derive(Clone, Copy, Debug)]
pub struct Splat2d {
    /// Centre in pixels.
    pub center: [f32; 2],
    /// Conic (xx, xy, yy).
    pub conic: [f32; 3],
    /// 3-sigma radius in pixels.
    pub radius: f32,
    /// View depth.
    pub depth: f32,
    /// Opacity after the sigmoid.
    pub opacity: f32,
    /// View-dependent colour.
    pub color: [f32; 3],
}

/// The outputs of a render, row-major.
#[derive(Clone, Debug)]
pub struct CpuRender {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGB over the background, `w·h·3`.
    pub rgb: Vec<f32>,
    /// Expected inverse depth `Σ α T / z`, `w·h`.
    pub inv_depth: Vec<f32>,
    /// Accumulated alpha `1 − T`, `w·h`.
    #[cfg_attr(not(test), allow(dead_code))]
    pub alpha: Vec<f32>,
}

const C1: f32 = 0.488_602_5;
const C2: [f32; 5] = [1.092_548_4, -1.092_548_4, 0.315_391_57, -1.092_548_4, 0.546_274_24];
const C3: [f32; 7] = [-0.590_043_6, 2.890_611_4, -0.457_045_8, 0.373_176_33, -0.457_045_8, 1.445_305_7, -0.590_043_6];

/// `max(0, 0.5 + Σ Y_lm(dir) c_lm)` for `sh` laid out `[coef][channel]`.
pub fn sh_color(sh: &[f32], degree: u32, d: Vec3) -> [f32; 3] {
    let c = |k: usize| Vec3::new(sh[3 * k], sh[3 * k + 1], sh[3 * k + 2]);
    let mut r = gast_core::scene::SH_C0 * c(0);
    if degree >= 1 {
        let (x, y, z) = (d.x, d.y, d.z);
        r += -C1 * y * c(1) + C1 * z * c(2) - C1 * x * c(3);
        if degree >= 2 {
            let (xx, yy, zz, xy, yz, xz) = (x * x, y * y, z * z, x * y, y * z, x * z);
            r += C2[0] * xy * c(4) + C2[1] * yz * c(5) + C2[2] * (2.0 * zz - xx - yy) * c(6) + C2[3] * xz * c(7) + C2[4] * (xx - yy) * c(8);
            if degree >= 3 {
                r += C3[0] * y * (3.0 * xx - yy) * c(9)
                    + C3[1] * xy * z * c(10)
                    + C3[2] * y * (4.0 * zz - xx - yy) * c(11)
                    + C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * c(12)
                    + C3[4] * x * (4.0 * zz - xx - yy) * c(13)
                    + C3[5] * z * (xx - yy) * c(14)
                    + C3[6] * x * (xx - 3.0 * yy) * c(15);
            }
        }
    }
    let r = (r + Vec3::splat(0.5)).max(Vec3::ZERO);
    [r.x, r.y, r.z]
}

/// Projects Gaussian `i`; `None` when it is behind the near plane, degenerate or off screen.
pub fn project(g: &Gaussians, i: usize, cam: &Camera) -> Option<Splat2d> {
    let mean = Vec3::from_array(g.means[i]);
    let tc = cam.world_to_camera(mean);
    if tc.z <= super::sort::NEAR {
        return None;
    }
    let [w, x, y, z] = g.quats[i];
    let q = Quat::from_xyzw(x, y, z, w).normalize();
    let rg = Mat3::from_quat(q);
    let s = Vec3::from_array(g.log_scales[i]).exp();
    let m = rg * Mat3::from_diagonal(s);
    let sigma = m * m.transpose();
    let (tanx, tany) = cam.tan_half_fov();
    let (limx, limy) = (1.3 * tanx, 1.3 * tany);
    let txz = (tc.x / tc.z).clamp(-limx, limx) * tc.z;
    let tyz = (tc.y / tc.z).clamp(-limy, limy) * tc.z;
    let iz = 1.0 / tc.z;
    let j0 = Vec3::new(cam.fx * iz, 0.0, -cam.fx * txz * iz * iz);
    let j1 = Vec3::new(0.0, cam.fy * iz, -cam.fy * tyz * iz * iz);
    // Rows of T = J·R.
    let rt = cam.rotation.transpose();
    let t0 = rt * j0;
    let t1 = rt * j1;
    let a = t0.dot(sigma * t0) + 0.3;
    let b = t0.dot(sigma * t1);
    let c = t1.dot(sigma * t1) + 0.3;
    let det = a * c - b * b;
    if det <= 0.0 {
        return None;
    }
    let mid = 0.5 * (a + c);
    let lambda = mid + (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil();
    let u = cam.fx * tc.x * iz + cam.cx;
    let v = cam.fy * tc.y * iz + cam.cy;
    if u + radius < 0.0 || v + radius < 0.0 || u - radius > cam.width as f32 || v - radius > cam.height as f32 {
        return None;
    }
    let dir = (mean - cam.center()).normalize_or_zero();
    Some(Splat2d {
        center: [u, v],
        conic: [c / det, -b / det, a / det],
        radius,
        depth: tc.z,
        opacity: 1.0 / (1.0 + (-g.opacity_logits[i]).exp()),
        color: sh_color(g.sh_of(i), g.sh_degree, dir),
    })
}

/// Renders `g` from `cam` over `background`.
pub fn render(g: &Gaussians, cam: &Camera, background: [f32; 3]) -> CpuRender {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut splats: Vec<Splat2d> = (0..g.len()).filter_map(|i| project(g, i, cam)).collect();
    splats.sort_by(|a, b| a.depth.total_cmp(&b.depth));
    let mut color = vec![0.0f32; w * h * 3];
    let mut trans = vec![1.0f32; w * h];
    let mut inv_depth = vec![0.0f32; w * h];
    for s in &splats {
        let x0 = (s.center[0] - s.radius).floor().max(0.0) as usize;
        let x1 = ((s.center[0] + s.radius).ceil().max(0.0) as usize).min(w);
        let y0 = (s.center[1] - s.radius).floor().max(0.0) as usize;
        let y1 = ((s.center[1] + s.radius).ceil().max(0.0) as usize).min(h);
        for py in y0..y1 {
            for px in x0..x1 {
                let p = py * w + px;
                let t = trans[p];
                if t < 1e-4 {
                    continue;
                }
                let dx = px as f32 + 0.5 - s.center[0];
                let dy = py as f32 + 0.5 - s.center[1];
                if dx.abs() > s.radius || dy.abs() > s.radius {
                    continue;
                }
                let power = -0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let alpha = (s.opacity * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let wgt = alpha * t;
                for ch in 0..3 {
                    color[p * 3 + ch] += s.color[ch] * wgt;
                }
                inv_depth[p] += wgt / s.depth;
                trans[p] = t * (1.0 - alpha);
            }
        }
    }
    for p in 0..w * h {
        for ch in 0..3 {
            color[p * 3 + ch] += background[ch] * trans[p];
        }
    }
    let alpha = trans.iter().map(|t| 1.0 - t).collect();
    CpuRender { width: cam.width, height: cam.height, rgb: color, inv_depth, alpha }
}

/// Gradient magnitude (Sobel) of the luminance of an RGB image, normalised to [0, 1].
pub fn sobel_edges(width: u32, height: u32, rgb: &[f32]) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    let lum: Vec<f32> = rgb.chunks_exact(3).map(|c| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]).collect();
    let at = |x: isize, y: isize| lum[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize];
    let mut out = vec![0.0f32; w * h];
    let mut max = 0.0f32;
    for y in 0..h as isize {
        for x in 0..w as isize {
            let gx = at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1) - at(x - 1, y - 1) - 2.0 * at(x - 1, y) - at(x - 1, y + 1);
            let gy = at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1) - at(x - 1, y - 1) - 2.0 * at(x, y - 1) - at(x + 1, y - 1);
            let m = (gx * gx + gy * gy).sqrt();
            max = max.max(m);
            out[y as usize * w + x as usize] = m;
        }
    }
    if max > 0.0 {
        out.iter_mut().for_each(|v| *v /= max);
    }
    out
}
