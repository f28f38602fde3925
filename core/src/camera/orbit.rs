//! Cameras generated around a scene that came without any (most downloadable
//! splats: `.ply`, `.spz`, SOG): views on a ring or a sphere band, all looking
//! at the scene's robust centre from far enough that its robust bounds fit.
//!
//! Trained splats carry floaters and far background Gaussians, so the plain
//! bounding box is useless: the bounds are the 2nd–98th percentile box per
//! axis and the target is the midpoint of that box, which a few far outliers
//! cannot move.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::Camera;

/// How the generated views are spread around the scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum OrbitLayout {
    /// One ring of evenly spaced azimuths at a fixed elevation (degrees above
    /// the horizontal plane, towards `up`).
    Ring {
        /// Elevation of the ring, degrees.
        elevation_degrees: f32,
    },
    /// A band of the sphere between two elevations, covered evenly (equal-area
    /// Fibonacci spiral): several elevations and interleaved azimuths.
    Sphere {
        /// Lowest elevation, degrees (negative looks up at the scene).
        min_elevation_degrees: f32,
        /// Highest elevation, degrees.
        max_elevation_degrees: f32,
    },
}

/// Options for [`orbit_cameras`]; every field has a default and the struct
/// serialises, so presets, CLI flags and GUI sliders share it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OrbitOptions {
    /// Number of views.
    pub count: usize,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Vertical field of view, degrees (used within 1°..=170°).
    pub fov_y_degrees: f32,
    /// The scene's up direction in world space. Most 3DGS scenes come from
    /// COLMAP, whose worlds are usually y-down, hence the default `[0, -1, 0]`.
    pub up: [f32; 3],
    /// Where the views are.
    pub layout: OrbitLayout,
    /// Distance factor (≥ 1): 1 puts the robust bounds' enclosing sphere
    /// exactly inside the narrower field of view; larger leaves a border.
    pub margin: f32,
}

impl Default for OrbitOptions {
    fn default() -> Self {
        Self {
            count: 36,
            width: 256,
            height: 256,
            fov_y_degrees: 50.0,
            up: [0.0, -1.0, 0.0],
            layout: OrbitLayout::Sphere { min_elevation_degrees: -30.0, max_elevation_degrees: 30.0 },
            margin: 1.1,
        }
    }
}

/// Robust bounds of a point set: per-axis percentiles and the box's midpoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobustBounds {
    /// Per-axis 2nd percentile.
    pub min: Vec3,
    /// Per-axis 98th percentile.
    pub max: Vec3,
    /// Midpoint of the box, the orbit target. (The per-axis median sits off
    /// centre on tall or lopsided objects, and the sphere about it that holds
    /// the box is then larger than needed: a guitar filled half the frame
    /// height about its median and three quarters about the midpoint.)
    pub center: Vec3,
}

impl RobustBounds {
    /// The eight corners of the box.
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        std::array::from_fn(|k| {
            Vec3::new(
                if k & 1 == 0 { a.x } else { b.x },
                if k & 2 == 0 { a.y } else { b.y },
                if k & 4 == 0 { a.z } else { b.z },
            )
        })
    }

    /// Radius of the smallest sphere about `center` that holds the box.
    pub fn radius(&self) -> f32 {
        self.corners().iter().map(|c| c.distance(self.center)).fold(0.0, f32::max)
    }
}

/// The robust bounds of `means` (points with a non-finite coordinate are
/// ignored), or `None` when no point is finite.
pub fn robust_bounds(means: &[[f32; 3]]) -> Option<RobustBounds> {
    let finite: Vec<&[f32; 3]> = means.iter().filter(|p| p.iter().all(|v| v.is_finite())).collect();
    if finite.is_empty() {
        return None;
    }
    let mut out = [[0.0f32; 3]; 2]; // [min, max] per axis
    let mut axis: Vec<f32> = Vec::with_capacity(finite.len());
    for a in 0..3 {
        axis.clear();
        axis.extend(finite.iter().map(|p| p[a]));
        for (slot, q) in [0.02f64, 0.98].into_iter().enumerate() {
            let k = (q * (axis.len() - 1) as f64).round() as usize;
            out[slot][a] = *axis.select_nth_unstable_by(k, f32::total_cmp).1;
        }
    }
    let (min, max) = (Vec3::from(out[0]), Vec3::from(out[1]));
    Some(RobustBounds { min, max, center: 0.5 * (min + max) })
}

/// `count` cameras looking at the robust centre of `means` (see the module
/// docs), at a distance where the robust bounds fit in every view with
/// `margin` to spare. Names are `orbit_000`, `orbit_001`, …. An empty or
/// all-non-finite point set orbits the origin at unit radius; a point set
/// without extent uses a unit radius too.
pub fn orbit_cameras(means: &[[f32; 3]], opts: &OrbitOptions) -> Vec<Camera> {
    let (center, radius) = match robust_bounds(means) {
        Some(b) => (b.center, b.radius()),
        None => (Vec3::ZERO, 1.0),
    };
    let radius = if radius.is_finite() && radius > 1e-6 { radius } else { 1.0 };
    let (w, h) = (opts.width.max(1), opts.height.max(1));
    let fov_y = if opts.fov_y_degrees.is_finite() { opts.fov_y_degrees.clamp(1.0, 170.0) } else { 50.0 };
    let tan_y = (0.5 * fov_y.to_radians()).tan();
    let tan_x = tan_y * w as f32 / h as f32;
    let half_fov = tan_x.min(tan_y).atan();
    let margin = if opts.margin.is_finite() { opts.margin.max(1.0) } else { 1.0 };
    let distance = margin * radius / half_fov.sin();

    let up = Vec3::from(opts.up).try_normalize().unwrap_or(Vec3::NEG_Y);
    // Azimuth 0 sits on the world's −z side (looking along +z, like an
    // unposed COLMAP camera) unless `up` is along z.
    let a = (Vec3::NEG_Z - up * up.dot(Vec3::NEG_Z))
        .try_normalize()
        .unwrap_or_else(|| (Vec3::X - up * up.dot(Vec3::X)).normalize());
    let b = up.cross(a);
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());

    (0..opts.count)
        .map(|i| {
            let (sin_el, azimuth) = match opts.layout {
                OrbitLayout::Ring { elevation_degrees } => {
                    (elevation_degrees.to_radians().sin(), std::f32::consts::TAU * i as f32 / opts.count as f32)
                }
                OrbitLayout::Sphere { min_elevation_degrees: lo, max_elevation_degrees: hi } => {
                    let s = (i as f32 + 0.5) / opts.count as f32;
                    let (lo, hi) = (lo.to_radians().sin(), hi.to_radians().sin());
                    (lo + (hi - lo) * s, golden * i as f32)
                }
            };
            let cos_el = (1.0 - sin_el * sin_el).max(0.0).sqrt();
            let dir = cos_el * (azimuth.cos() * a + azimuth.sin() * b) + sin_el * up;
            let eye = center + distance * dir;
            Camera::look_at(format!("orbit_{i:03}"), eye, center, up, w, h, fov_y)
        })
        .collect()
}
