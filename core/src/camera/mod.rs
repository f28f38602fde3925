//! Pinhole cameras with the conventions of the golden files, and the camera
//! files users bring (COLMAP, INRIA `cameras.json`, NeRF `transforms.json`).
//!
//! Convention: world-to-camera `x_c = R x_w + t`; the camera looks down +z with
//! x right and y down; `u = fx·x/z + cx`, `v = fy·y/z + cy`; pixel (row i, col j)
//! has its centre at `(j + 0.5, i + 0.5)`.

use glam::{Mat3, Vec3};

/// A pinhole camera (distortion-free), world-to-camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// A name for reports (image file name, `orbit_007`, …).
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length in pixels, x.
    pub fx: f32,
    /// Focal length in pixels, y.
    pub fy: f32,
    /// Principal point, x (pixels, continuous coordinates).
    pub cx: f32,
    /// Principal point, y.
    pub cy: f32,
    /// World-to-camera rotation `R`.
    pub rotation: Mat3,
    /// World-to-camera translation `t`.
    pub translation: Vec3,
}

impl Camera {
    /// The camera centre in world space, `−Rᵀ t`.
    pub fn center(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// A point in world space expressed in camera space.
    pub fn world_to_camera(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// `tan` of half the horizontal and vertical field of view.
    pub fn tan_half_fov(&self) -> (f32, f32) {
        (0.5 * self.width as f32 / self.fx, 0.5 * self.height as f32 / self.fy)
    }
}
