//! A looping camera path through a forward-facing capture (LLFF's fern,
//! flower, …): the views of such a scene all look one way, and a ring around
//! it shows mostly what no photo saw (its back, the floaters behind the
//! cameras). The path is the one NeRF renders these scenes with: a spiral
//! around the cameras' mean pose, as wide as they spread, looking at a point
//! at the scene's focus depth.

use glam::{Mat3, Vec3};

use super::Camera;

/// The largest angle between a view's direction and the mean direction for
/// a set of cameras to count as forward-facing.
const FORWARD_FACING_DEGREES: f32 = 45.0;

/// Whether every camera looks within [`FORWARD_FACING_DEGREES`] of the mean
/// view direction; that direction when so.
pub fn forward_facing(cameras: &[Camera]) -> Option<Vec3> {
    let forward = |c: &Camera| c.rotation.row(2);
    let mean = cameras.iter().map(forward).sum::<Vec3>().try_normalize()?;
    let cos = FORWARD_FACING_DEGREES.to_radians().cos();
    cameras.iter().all(|c| forward(c).dot(mean) >= cos).then_some(mean)
}

/// `count` cameras (`width × height`, the training cameras' vertical field of
/// view) on a loop through forward-facing `cameras` looking into `points`
/// (the scene's Gaussian means): two turns of a spiral around the cameras'
/// mean position, as wide as the 90th percentile of their spread along each
/// axis of their mean pose, moving in and out once, each view looking at the
/// point on the mean view direction at the scene's focus depth (NeRF's
/// `render_path_spiral`, its focus from the 10th and 90th percentiles of the
/// points' depths). `None` when the cameras are not forward-facing
/// ([`forward_facing`]) or no point lies in front of them.
pub fn forward_sweep(
    cameras: &[Camera],
    points: &[[f32; 3]],
    count: usize,
    width: u32,
    height: u32,
) -> Option<Vec<Camera>> {
    let forward = forward_facing(cameras)?;
    let n = cameras.len() as f32;
    let center = cameras.iter().map(Camera::center).sum::<Vec3>() / n;
    // Camera y points down; the mean up is against it.
    let up = -(cameras.iter().map(|c| c.rotation.row(1)).sum::<Vec3>() / n);
    let right = up.cross(forward).try_normalize().unwrap_or_else(|| forward.any_orthonormal_vector());
    let down = forward.cross(right);
    let axes = [right, down, forward];
    let mut depths: Vec<f32> =
        points.iter().map(|p| (Vec3::from(*p) - center).dot(forward)).filter(|d| d.is_finite() && *d > 0.0).collect();
    if depths.is_empty() {
        return None;
    }
    let near = percentile(&mut depths, 0.1) * 0.9;
    let far = percentile(&mut depths, 0.9) * 5.0;
    let focus = 1.0 / (0.25 / near + 0.75 / far);
    let radii: [f32; 3] = std::array::from_fn(|k| {
        let mut spread: Vec<f32> = cameras.iter().map(|c| (c.center() - center).dot(axes[k]).abs()).collect();
        percentile(&mut spread, 0.9)
    });
    let first = &cameras[0];
    let fov_y_degrees = 2.0 * (0.5 * first.height as f32 / first.fy).atan().to_degrees();
    let target = center + focus * forward;
    let count = count.max(1);
    Some(
        (0..count)
            .map(|i| {
                let t = std::f32::consts::TAU * 2.0 * i as f32 / count as f32;
                let offset = Mat3::from_cols(right, down, forward)
                    * Vec3::new(radii[0] * t.cos(), -radii[1] * t.sin(), radii[2] * (0.5 * t).sin());
                Camera::look_at(format!("sweep_{i:03}"), center + offset, target, up, width, height, fov_y_degrees)
            })
            .collect(),
    )
}

/// The value at fraction `q` of `v` once sorted (nearest rank).
fn percentile(v: &mut [f32], q: f32) -> f32 {
    v.sort_by(f32::total_cmp);
    v[((v.len() - 1) as f32 * q).round() as usize]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{OrbitLayout, OrbitOptions, orbit_cameras};

    /// Nine cameras on a 3×3 grid 0.2 apart, all looking along +z at a wall of points 4 to 6 ahead.
    fn capture() -> (Vec<Camera>, Vec<[f32; 3]>) {
        let cams = (0..9)
            .map(|i| {
                let eye = Vec3::new(0.2 * (i % 3) as f32 - 0.2, 0.2 * (i / 3) as f32 - 0.2, 0.0);
                Camera::look_at(format!("c{i}"), eye, eye + Vec3::Z, Vec3::NEG_Y, 400, 300, 50.0)
            })
            .collect();
        let points = (0..100)
            .map(|i| [(i % 10) as f32 * 0.3 - 1.5, (i / 10) as f32 * 0.3 - 1.5, 4.0 + (i % 7) as f32 / 3.0])
            .collect();
        (cams, points)
    }

    #[test]
    fn a_forward_capture_gets_a_loop_that_looks_into_the_scene() {
        let (cams, points) = capture();
        let path = forward_sweep(&cams, &points, 24, 128, 128).expect("forward-facing");
        assert_eq!(path.len(), 24);
        for c in &path {
            // Within the cameras' spread (0.2 from the middle) and looking ahead, at the focus.
            let p = c.center();
            assert!(p.x.abs() <= 0.2 + 1e-4 && p.y.abs() <= 0.2 + 1e-4 && p.z.abs() <= 0.2 + 1e-4, "{p}");
            assert!(c.rotation.row(2).dot(Vec3::Z) > 0.95);
            let focus = c.world_to_camera(Vec3::new(0.0, 0.0, 1.0 / (0.25 / (4.0 * 0.9) + 0.75 / (path_far(&points)))));
            assert!(focus.x.abs() < 1e-3 && focus.y.abs() < 1e-3 && focus.z > 0.0, "{focus}");
            assert_eq!((c.width, c.height), (128, 128));
            // The training cameras' vertical field of view.
            assert!((2.0 * (64.0 / c.fy).atan().to_degrees() - 50.0).abs() < 1e-3);
        }
        // It moves: the views are not all in one place, and the loop closes
        // (the last view is one step before the first).
        assert!(path[0].center().distance(path[6].center()) > 0.1);
        assert!(path[23].center().distance(path[0].center()) < path[0].center().distance(path[6].center()));
    }

    fn path_far(points: &[[f32; 3]]) -> f32 {
        let mut d: Vec<f32> = points.iter().map(|p| p[2]).collect();
        percentile(&mut d, 0.9) * 5.0
    }

    #[test]
    fn fern_is_forward_facing_and_lego_is_not() {
        use crate::vision::weights::tests::shared;
        let Some(fern) = shared("data/datasets/fern/poses_bounds.npy") else { return };
        let Some(lego) = shared("data/datasets/lego/transforms_train.json") else { return };
        let fern = crate::camera::load(fern.parent().expect("dataset folder")).expect("fern's cameras").cameras;
        let lego = crate::camera::load(&lego).expect("lego's cameras").cameras;
        assert_eq!(fern.len(), 20);
        assert!(forward_facing(&fern).is_some());
        assert!(forward_facing(&lego).is_none(), "lego's {} cameras surround the object", lego.len());
        // Points in front of fern's cameras at its depth bounds (about 1.4 to 18 in its units).
        let (_, points) = capture();
        let center = fern.iter().map(Camera::center).sum::<Vec3>() / fern.len() as f32;
        let forward = forward_facing(&fern).expect("forward-facing");
        let points: Vec<[f32; 3]> =
            points.iter().map(|p| (center + forward * (p[2] * 2.0) + Vec3::new(p[0], p[1], 0.0)).to_array()).collect();
        let path = forward_sweep(&fern, &points, 12, 64, 64).expect("a loop");
        for c in &path {
            assert!(c.rotation.row(2).dot(forward) > 0.9, "every view looks the captured way");
        }
    }

    #[test]
    fn cameras_around_an_object_are_not_forward_facing() {
        let (_, points) = capture();
        let ring = orbit_cameras(
            &points,
            &OrbitOptions {
                count: 12,
                layout: OrbitLayout::Ring { elevation_degrees: 20.0 },
                ..OrbitOptions::default()
            },
        );
        assert!(forward_facing(&ring).is_none());
        assert!(forward_sweep(&ring, &points, 24, 64, 64).is_none());
        assert!(forward_sweep(&[], &points, 24, 64, 64).is_none());
    }
}
