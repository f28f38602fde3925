//! Geometry change against the input scene, measured on renders from the same
//! camera before and after stylization.
//!
//! Geometry-aware style transfer is allowed to move surfaces a little (that is
//! the point of the geometry phase) but not to destroy them; two views of that
//! are the change of the rendered inverse depth and the change of the surface
//! orientation, whose normals come from finite differences of the rendered
//! depth back-projected into camera space. Only pixels covered in both renders
//! (alpha ≥ [`COVERED_ALPHA`]) count, since the depth of a mostly transparent
//! pixel is not a surface.

use glam::Vec3;

use crate::Camera;
use crate::raster::Render;

/// Alpha at or above which a pixel counts as covered by a surface.
pub const COVERED_ALPHA: f32 = 0.5;

/// The depth of pixel `i` (`alpha / inv_depth`, along the camera's z axis),
/// or `None` when the pixel is not covered or has no finite positive depth.
pub fn pixel_depth(render: &Render, i: usize) -> Option<f32> {
    let (a, inv) = (*render.alpha.get(i)?, *render.inv_depth.get(i)?);
    let z = a / inv;
    (a >= COVERED_ALPHA && inv > 0.0 && z.is_finite() && z > 0.0).then_some(z)
}

/// The camera-space point seen through the centre of pixel `(x, y)` at depth `z`.
pub fn back_project(cam: &Camera, x: usize, y: usize, z: f32) -> Vec3 {
    let u = (x as f32 + 0.5 - cam.cx) / cam.fx;
    let v = (y as f32 + 0.5 - cam.cy) / cam.fy;
    Vec3::new(u * z, v * z, z)
}

/// Inverse-depth change `mean |D_after − D_before| / mean D_before` over pixels
/// where both alphas are ≥ 0.5 (unitless, relative); 0 when no pixel qualifies.
pub fn inverse_depth_change(before: &[f32], after: &[f32], alpha_before: &[f32], alpha_after: &[f32]) -> f32 {
    let n = before.len().min(after.len()).min(alpha_before.len()).min(alpha_after.len());
    let (mut diff, mut base) = (0.0f64, 0.0f64);
    for i in 0..n {
        if alpha_before[i] >= COVERED_ALPHA && alpha_after[i] >= COVERED_ALPHA {
            diff += (after[i] - before[i]).abs() as f64;
            base += before[i].abs() as f64;
        }
    }
    if base == 0.0 { 0.0 } else { (diff / base) as f32 }
}

/// Camera-space unit normals of a render, one per pixel (row-major), `None`
/// where it cannot be measured. With `P(x, y)` the back-projected point of
/// pixel `(x, y)` (see [`pixel_depth`], [`back_project`]), the normal is
/// `normalize((P(x+1, y) − P(x, y)) × (P(x, y+1) − P(x, y)))`, turned to face
/// the camera (`n · P < 0`); it needs the pixel and its right and lower
/// neighbours covered. The last column and row have none. Exact for planes.
pub fn depth_normals(render: &Render, cam: &Camera) -> Vec<Option<Vec3>> {
    let (w, h) = (render.width as usize, render.height as usize);
    let point = |x: usize, y: usize| pixel_depth(render, y * w + x).map(|z| back_project(cam, x, y, z));
    let mut out = vec![None; w * h];
    for y in 0..h.saturating_sub(1) {
        for x in 0..w.saturating_sub(1) {
            let (Some(p), Some(px), Some(py)) = (point(x, y), point(x + 1, y), point(x, y + 1)) else {
                continue;
            };
            let Some(n) = (px - p).cross(py - p).try_normalize() else {
                continue;
            };
            out[y * w + x] = Some(if n.dot(p) > 0.0 { -n } else { n });
        }
    }
    out
}

/// How much the surface orientation changed between two renders from the same camera.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NormalChange {
    /// `mean_x ∠(n_before(x), n_after(x))` in degrees, over the pixels with
    /// a normal in both renders; 0 when there are none.
    pub mean_degrees: f32,
    /// The number of pixels that had a normal in both renders.
    pub pixels: usize,
}

/// The mean angular change of the depth normals ([`depth_normals`]) between a
/// render before and one after, both from `cam`.
pub fn normal_change(before: &Render, after: &Render, cam: &Camera) -> NormalChange {
    if (before.width, before.height) != (after.width, after.height) {
        return NormalChange::default();
    }
    let (nb, na) = (depth_normals(before, cam), depth_normals(after, cam));
    let (mut sum, mut pixels) = (0.0f64, 0usize);
    for (b, a) in nb.iter().zip(&na) {
        if let (Some(b), Some(a)) = (b, a) {
            // atan2(|b × a|, b · a): exact 0 for equal vectors, where acos of a rounded dot is not.
            sum += f64::from(b.cross(*a).length().atan2(b.dot(*a)).to_degrees());
            pixels += 1;
        }
    }
    let mean_degrees = if pixels == 0 { 0.0 } else { (sum / pixels as f64) as f32 };
    NormalChange { mean_degrees, pixels }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(w: u32, h: u32) -> Camera {
        Camera::look_at("c", Vec3::ZERO, Vec3::Z, Vec3::NEG_Y, w, h, 60.0)
    }

    /// A render of the plane `n · X = d` (camera space), fully covered,
    /// with pixels whose ray misses the plane left uncovered.
    fn plane_render(cam: &Camera, n: Vec3, d: f32) -> Render {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut r = Render::zeros(cam.width, cam.height);
        for y in 0..h {
            for x in 0..w {
                let ray = back_project(cam, x, y, 1.0);
                let inv = n.dot(ray) / d; // 1/z on the plane
                if inv > 0.0 {
                    r.inv_depth[y * w + x] = inv;
                    r.alpha[y * w + x] = 1.0;
                }
            }
        }
        r
    }

    #[test]
    fn inverse_depth_change_skips_uncovered_pixels() {
        let d = [1.0f32, 2.0, 4.0];
        let alpha = [1.0f32, 1.0, 0.0];
        // Third pixel ignored: |1.5-1| + |2-2| over 1 + 2.
        assert!((inverse_depth_change(&d, &[1.5, 2.0, 9.0], &alpha, &alpha) - 0.5 / 3.0).abs() < 1e-6);
        assert_eq!(inverse_depth_change(&d, &d, &[0.0; 3], &alpha), 0.0);
        assert_eq!(inverse_depth_change(&[], &[], &[], &[]), 0.0);
    }

    #[test]
    fn normals_of_planes_and_their_angle() {
        let cam = camera(24, 16);
        let facing = plane_render(&cam, Vec3::Z, 3.0);
        let normals = depth_normals(&facing, &cam);
        let n = normals[5 * 24 + 7].expect("covered pixel has a normal");
        assert!(n.distance(Vec3::NEG_Z) < 1e-4, "{n}");
        assert!(normals[23].is_none() && normals[15 * 24].is_none(), "no right / lower neighbour");

        let tilt = 30f32.to_radians();
        let tilted = plane_render(&cam, Vec3::new(tilt.sin(), 0.0, tilt.cos()), 3.0);
        let change = normal_change(&facing, &tilted, &cam);
        assert_eq!(change.pixels, 23 * 15);
        assert!((change.mean_degrees - 30.0).abs() < 0.05, "{change:?}");
        assert!(normal_change(&facing, &facing, &cam).mean_degrees < 0.05);
    }

    #[test]
    fn degenerate_renders_have_no_normals() {
        let cam = camera(1, 1);
        let r = Render::zeros(1, 1);
        assert_eq!(depth_normals(&r, &cam), vec![None]);
        assert_eq!(normal_change(&r, &r, &cam), NormalChange::default());
        let empty = Render::zeros(0, 0);
        assert!(depth_normals(&empty, &camera(0, 0)).is_empty());
        assert_eq!(normal_change(&empty, &Render::zeros(2, 2), &cam), NormalChange::default());
    }
}
