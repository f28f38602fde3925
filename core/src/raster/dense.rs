//! The slow, obvious reference: every pixel against every Gaussian, in `f64`,
//! no tiles and no culling beyond the near plane. It shares no code with the
//! fast path so that tests comparing the two compare two implementations.

use glam::{DMat3, DVec3};

use super::{Render, RenderOptions};
use crate::camera::Camera;
use crate::scene::Gaussians;

/// A dense render in `f64` (same layout as [`Render`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DenseRender {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Colour, `H × W × 3`.
    pub rgb: Vec<f64>,
    /// Inverse depth, `H × W`.
    pub inv_depth: Vec<f64>,
    /// Opacity, `H × W`.
    pub alpha: Vec<f64>,
}

impl DenseRender {
    /// Rounded to `f32`.
    pub fn to_render(&self) -> Render {
        let f = |v: &[f64]| v.iter().map(|&x| x as f32).collect();
        Render {
            width: self.width,
            height: self.height,
            rgb: f(&self.rgb),
            inv_depth: f(&self.inv_depth),
            alpha: f(&self.alpha),
        }
    }
}

/// Renders densely and rounds to `f32`.
pub fn render(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Render {
    render_f64(g, cam, opts).to_render()
}

/// One Gaussian on screen, `f64`.
struct Screen {
    z: f64,
    u: f64,
    v: f64,
    /// Inverse 2D covariance, full symmetric matrix entries.
    k: [f64; 3],
    opacity: f64,
    color: [f64; 3],
}

fn sh_basis(d: DVec3) -> [f64; 16] {
    let (x, y, z) = (d.x, d.y, d.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let c1 = 0.488_602_511_902_919_9;
    [
        0.282_094_791_773_878_14,
        -c1 * y,
        c1 * z,
        -c1 * x,
        1.092_548_430_592_079_2 * x * y,
        -1.092_548_430_592_079_2 * y * z,
        0.315_391_565_252_520_05 * (2.0 * zz - xx - yy),
        -1.092_548_430_592_079_2 * x * z,
        0.546_274_215_296_039_6 * (xx - yy),
        -0.590_043_589_926_643_5 * y * (3.0 * xx - yy),
        2.890_611_442_640_554 * x * y * z,
        -0.457_045_799_464_465_8 * y * (4.0 * zz - xx - yy),
        0.373_176_332_590_115_4 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        -0.457_045_799_464_465_8 * x * (4.0 * zz - xx - yy),
        1.445_305_721_320_277 * z * (xx - yy),
        -0.590_043_589_926_643_5 * x * (xx - 3.0 * yy),
    ]
}

fn to_screen(g: &Gaussians, i: usize, cam: &Camera) -> Option<Screen> {
    let r = cam.rotation.as_dmat3();
    let mean = DVec3::from(g.means[i].map(f64::from));
    let t = r * mean + cam.translation.as_dvec3();
    if t.z <= 0.2 {
        return None;
    }
    let q = g.quats[i].map(f64::from);
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    // Row-major entries of the rotation, transposed into glam's columns.
    let rot = DMat3::from_cols_array(&[
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    ])
    .transpose();
    let s = DMat3::from_diagonal(DVec3::from(g.log_scales[i].map(|v| f64::from(v).exp())));
    let sigma = rot * s * s * rot.transpose();

    let (fx, fy) = (f64::from(cam.fx), f64::from(cam.fy));
    let lim_x = 1.3 * 0.5 * f64::from(cam.width) / fx;
    let lim_y = 1.3 * 0.5 * f64::from(cam.height) / fy;
    let cx_ = (t.x / t.z).clamp(-lim_x, lim_x);
    let cy_ = (t.y / t.z).clamp(-lim_y, lim_y);
    // J as a 3×3 with a zero last row.
    let j = DMat3::from_cols(
        DVec3::new(fx / t.z, 0.0, 0.0),
        DVec3::new(0.0, fy / t.z, 0.0),
        DVec3::new(-fx * cx_ / t.z, -fy * cy_ / t.z, 0.0),
    );
    let m = j * r;
    let cov = m * sigma * m.transpose();
    let (a, b, c) = (cov.x_axis.x + 0.3, cov.y_axis.x, cov.y_axis.y + 0.3);
    let det = a * c - b * b;

    let dir = (mean - cam.center().as_dvec3()).normalize();
    let basis = sh_basis(dir);
    let sh = g.sh_of(i);
    let mut color = [0.5; 3];
    for (k, coef) in sh.chunks_exact(3).enumerate() {
        for ch in 0..3 {
            color[ch] += basis[k] * f64::from(coef[ch]);
        }
    }
    Some(Screen {
        z: t.z,
        u: fx * t.x / t.z + f64::from(cam.cx),
        v: fy * t.y / t.z + f64::from(cam.cy),
        k: [c / det, -b / det, a / det],
        opacity: 1.0 / (1.0 + (-f64::from(g.opacity_logits[i])).exp()),
        color: color.map(|v| v.max(0.0)),
    })
}

/// Renders every pixel against every Gaussian in `f64`.
pub fn render_f64(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> DenseRender {
    let mut screen: Vec<Screen> = (0..g.len()).filter_map(|i| to_screen(g, i, cam)).collect();
    screen.sort_by(|a, b| a.z.total_cmp(&b.z));
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut out = DenseRender {
        width: cam.width,
        height: cam.height,
        rgb: vec![0.0; 3 * w * h],
        inv_depth: vec![0.0; w * h],
        alpha: vec![0.0; w * h],
    };
    for i in 0..h {
        for j in 0..w {
            let (px, py) = (j as f64 + 0.5, i as f64 + 0.5);
            let mut t = 1.0;
            let mut rgb = [0.0; 3];
            let mut inv_depth = 0.0;
            for s in &screen {
                let (dx, dy) = (px - s.u, py - s.v);
                let power = -0.5 * (s.k[0] * dx * dx + s.k[2] * dy * dy) - s.k[1] * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let alpha = (s.opacity * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let next_t = t * (1.0 - alpha);
                if next_t < 1e-4 {
                    break;
                }
                for (acc, col) in rgb.iter_mut().zip(s.color) {
                    *acc += alpha * t * col;
                }
                inv_depth += alpha * t / s.z;
                t = next_t;
            }
            let q = i * w + j;
            for ((o, col), bg) in out.rgb[3 * q..3 * q + 3].iter_mut().zip(rgb).zip(opts.background) {
                *o = col + t * f64::from(bg);
            }
            out.inv_depth[q] = inv_depth;
            out.alpha[q] = 1.0 - t;
        }
    }
    out
}
