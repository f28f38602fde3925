//! The viewport camera and its controls, with the habits of Brush and
//! SuperSplat: orbit around a target (left drag), pan (right or middle drag),
//! zoom (wheel), fly (WASD + QE while the right button is held), fit to the
//! scene's robust bounds, reset, and snap to a listed camera.

use gast_core::camera::{OrbitOptions, orbit_cameras, robust_bounds};
use gast_core::{Camera, Gaussians};
use glam::{Mat3, Vec3};

/// Which world axis points up in the scene (captures differ; COLMAP scenes are usually −Y).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpAxis {
    /// −Y up (COLMAP / INRIA captures; the demo scene).
    NegY,
    /// +Y up.
    PosY,
    /// +Z up.
    PosZ,
}

impl UpAxis {
    /// The unit vector.
    pub fn vector(self) -> Vec3 {
        match self {
            UpAxis::NegY => Vec3::NEG_Y,
            UpAxis::PosY => Vec3::Y,
            UpAxis::PosZ => Vec3::Z,
        }
    }
}

/// The viewport camera: a pose that orbits around a target point.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewState {
    /// The point orbits turn around.
    pub target: Vec3,
    /// Distance from the eye to the target.
    pub distance: f32,
    /// Camera-to-world rotation; columns are the camera's right, down and forward axes.
    pub cam_to_world: Mat3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// World up.
    pub up: UpAxis,
    /// Fly speed in scene units per second (scaled with the scene).
    pub fly_speed: f32,
}

impl Default for ViewState {
    fn default() -> Self {
        let mut v = Self {
            target: Vec3::ZERO,
            distance: 4.0,
            cam_to_world: Mat3::IDENTITY,
            fov_y: 50f32.to_radians(),
            up: UpAxis::NegY,
            fly_speed: 1.0,
        };
        v.look_from_direction(Vec3::new(0.6, -0.35, -1.0));
        v
    }
}

/// Rotation of `angle` radians around `axis` (unit).
fn rot(axis: Vec3, angle: f32) -> Mat3 {
    Mat3::from_axis_angle(axis.normalize_or(Vec3::Y), angle)
}

impl ViewState {
    /// The camera's forward axis in world space.
    pub fn forward(&self) -> Vec3 {
        self.cam_to_world.z_axis
    }

    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        self.target - self.forward() * self.distance
    }

    /// Points the camera at the target from `offset` direction (eye = target + offset·distance), upright.
    pub fn look_from_direction(&mut self, offset: Vec3) {
        let forward = (-offset).normalize_or(Vec3::Z);
        let down = -self.up.vector();
        let mut right = down.cross(forward);
        if right.length_squared() < 1e-8 {
            right = forward.any_orthonormal_vector();
        }
        let right = right.normalize();
        let down = forward.cross(right);
        self.cam_to_world = Mat3::from_cols(right, down, forward);
    }

    /// Frames the robust bounds of `g` (2nd–98th percentiles, median centre) from a
    /// three-quarter view.
    pub fn fit(&mut self, g: &Gaussians) {
        let (center, radius) = match robust_bounds(&g.means) {
            Some(b) => (b.center, b.radius().max(1e-3)),
            None => (Vec3::ZERO, 1.0),
        };
        self.target = center;
        self.distance = 0.9 * radius / (0.5 * self.fov_y).tan();
        self.fly_speed = radius;
        let up = self.up.vector();
        let side = up.any_orthonormal_vector();
        self.look_from_direction((side * 0.8 + up.cross(side) * 0.6 + up * 0.45).normalize());
    }

    /// Orbits: `dx` turns around the world up axis, `dy` tilts around the camera's right axis (radians).
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        let yaw = rot(self.up.vector(), -dx);
        let c = yaw * self.cam_to_world;
        let pitched = rot(c.x_axis, dy) * c;
        // Refuse to tilt over the pole.
        if pitched.z_axis.dot(self.up.vector()).abs() < 0.995 {
            self.cam_to_world = pitched;
        } else {
            self.cam_to_world = c;
        }
        self.reorthonormalize();
    }

    /// Pans by a screen-space offset in pixels for a viewport `height` pixels high.
    pub fn pan(&mut self, dx_px: f32, dy_px: f32, height: f32) {
        let per_px = 2.0 * self.distance * (0.5 * self.fov_y).tan() / height.max(1.0);
        self.target -= self.cam_to_world.x_axis * dx_px * per_px + self.cam_to_world.y_axis * dy_px * per_px;
    }

    /// Zooms by a wheel amount (positive = closer).
    pub fn zoom(&mut self, amount: f32) {
        self.distance = (self.distance * (-amount * 0.0015).exp()).clamp(1e-4, 1e6);
    }

    /// Moves eye and target together: `right`, `up` and `forward` in units of `fly_speed · seconds`.
    pub fn fly(&mut self, right: f32, up: f32, forward: f32, seconds: f32) {
        let step = self.fly_speed * seconds;
        self.target += (self.cam_to_world.x_axis * right - self.cam_to_world.y_axis * up
            + self.cam_to_world.z_axis * forward)
            * step;
    }

    /// Takes a listed camera's pose and vertical field of view; the target is put
    /// `self.distance` ahead, or at the depth of `focus` when given.
    pub fn snap_to(&mut self, cam: &Camera, focus: Option<Vec3>) {
        let c2w = cam.rotation.transpose();
        let eye = cam.center();
        let forward = c2w.z_axis;
        if let Some(f) = focus {
            self.distance = (f - eye).dot(forward).max(1e-3);
        }
        self.cam_to_world = c2w;
        self.target = eye + forward * self.distance;
        self.fov_y = 2.0 * (0.5 * cam.height as f32 / cam.fy).atan();
    }

    fn reorthonormalize(&mut self) {
        let f = self.cam_to_world.z_axis.normalize();
        let r = self.cam_to_world.y_axis.cross(f).normalize();
        let d = f.cross(r);
        self.cam_to_world = Mat3::from_cols(r, d, f);
    }

    /// The pinhole camera of this view for a `width × height` pixel viewport.
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        let (w, h) = (width.max(1), height.max(1));
        let fy = 0.5 * h as f32 / (0.5 * self.fov_y).tan();
        let rotation = self.cam_to_world.transpose();
        let translation = -(rotation * self.eye());
        Camera {
            name: "viewport".into(),
            width: w,
            height: h,
            fx: fy,
            fy,
            cx: 0.5 * w as f32,
            cy: 0.5 * h as f32,
            rotation,
            translation,
        }
    }
}

/// `n` orbit cameras around the robust bounds of `g` (`gast_core::camera::orbit_cameras`
/// on a sphere band), the list the view can snap to.
pub fn orbit_ring(g: &Gaussians, up: UpAxis, n: usize, width: u32, height: u32) -> Vec<Camera> {
    let opts = OrbitOptions { count: n, width, height, up: up.vector().to_array(), ..OrbitOptions::default() };
    orbit_cameras(&g.means, &opts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_projects_to_the_centre_and_up_is_up() {
        let mut v = ViewState { target: Vec3::new(1.0, 2.0, 3.0), ..ViewState::default() };
        v.orbit(0.3, 0.2);
        let cam = v.camera(200, 100);
        let p = cam.world_to_camera(v.target);
        assert!((cam.fx * p.x / p.z + cam.cx - 100.0).abs() < 1e-3);
        assert!((cam.fy * p.y / p.z + cam.cy - 50.0).abs() < 1e-3);
        // A point above the target appears above the centre (smaller v).
        let q = cam.world_to_camera(v.target + v.up.vector() * 0.1);
        assert!(cam.fy * q.y / q.z + cam.cy < 50.0);
        let before = v.clone();
        let snap_cam = v.camera(200, 100);
        let mut w = ViewState::default();
        w.snap_to(&snap_cam, Some(before.target));
        assert!((w.eye() - before.eye()).length() < 1e-3);
    }
}
