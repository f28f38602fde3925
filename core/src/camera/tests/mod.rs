//! Unit tests of the camera readers, writers and generators, on small
//! synthetic files written to a fresh temporary folder per test.

mod colmap;
mod json;
mod llff;
mod orbit;
mod points;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Mat3, Vec3};

use super::Camera;

/// A fresh, empty temporary folder for one test, removed when dropped.
struct TempDir(PathBuf);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn temp_dir(tag: &str) -> TempDir {
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "gast-camera-{tag}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("create temp dir");
    TempDir(d)
}

fn assert_close(a: &Camera, b: &Camera, tol: f32) {
    assert_eq!(a.name, b.name);
    assert_eq!((a.width, a.height), (b.width, b.height), "{}", a.name);
    for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
        assert!((x - y).abs() <= tol * x.abs().max(1.0), "{}: intrinsics {x} vs {y}", a.name);
    }
    assert!(a.rotation.abs_diff_eq(b.rotation, tol), "{}: {:?} vs {:?}", a.name, a.rotation, b.rotation);
    assert!(
        a.translation.abs_diff_eq(b.translation, tol * 10.0),
        "{}: {:?} vs {:?}",
        a.name,
        a.translation,
        b.translation
    );
}

#[test]
fn look_at_axes_and_projection() {
    // y-down world, camera on −z looking at the origin: identity rotation.
    let c = Camera::look_at("c", Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO, Vec3::NEG_Y, 200, 100, 60.0);
    assert!(c.rotation.abs_diff_eq(Mat3::IDENTITY, 1e-6), "{:?}", c.rotation);
    assert!(c.center().abs_diff_eq(Vec3::new(0.0, 0.0, -5.0), 1e-5));
    let p = c.project(Vec3::ZERO).expect("in front");
    assert!(p.abs_diff_eq(glam::Vec2::new(100.0, 50.0), 1e-4));
    // A point towards `up` appears in the upper half (smaller v), +x to the right.
    assert!(c.project(Vec3::new(0.0, -1.0, 0.0)).expect("in front").y < 50.0);
    assert!(c.project(Vec3::new(1.0, 0.0, 0.0)).expect("in front").x > 100.0);
    assert!(c.project(Vec3::new(0.0, 0.0, -6.0)).is_none());
    // Vertical field of view as asked, square pixels.
    let (tx, ty) = c.tan_half_fov();
    assert!((ty - 30f32.to_radians().tan()).abs() < 1e-6 && (tx - 2.0 * ty).abs() < 1e-5);
    // Looking along `up` still gives a rotation.
    let d = Camera::look_at("d", Vec3::new(0.0, 3.0, 0.0), Vec3::ZERO, Vec3::NEG_Y, 10, 10, 40.0);
    assert!((d.rotation.determinant() - 1.0).abs() < 1e-5 && d.rotation.is_finite());
    assert!(d.project(Vec3::ZERO).expect("in front").abs_diff_eq(glam::Vec2::splat(5.0), 1e-4));
}

#[test]
fn scaling_keeps_the_field_of_view() {
    let c = Camera::look_at("c", Vec3::new(1.0, 2.0, -5.0), Vec3::ZERO, Vec3::NEG_Y, 1600, 900, 50.0);
    let s = c.scaled_to(800, 450);
    assert_eq!((s.width, s.height), (800, 450));
    assert!((s.fx - c.fx / 2.0).abs() < 1e-4 && (s.cx - 400.0).abs() < 1e-4 && (s.cy - 225.0).abs() < 1e-4);
    let (a, b) = (c.tan_half_fov(), s.tan_half_fov());
    assert!((a.0 - b.0).abs() < 1e-6 && (a.1 - b.1).abs() < 1e-6);
    let p = Vec3::new(0.3, -0.2, 0.1);
    let (pc, ps) = (c.project(p).expect("front"), s.project(p).expect("front"));
    assert!((pc / 2.0).abs_diff_eq(ps, 1e-3));
    let m = c.downscaled_to_max_side(512);
    assert_eq!((m.width, m.height), (512, 288));
    assert_eq!(c.downscaled_to_max_side(4000), c);
}

#[test]
fn scene_extent_follows_the_camera_spread() {
    let cams: Vec<Camera> = [Vec3::new(2.0, 0.0, 0.0), Vec3::new(-2.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]
        .iter()
        .map(|&e| Camera::look_at("c", e, Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Y, 8, 8, 50.0))
        .collect();
    // Centroid (0, 1/3, 0); farthest centre at sqrt(4 + 1/9).
    let expect = 1.1 * (4.0f32 + 1.0 / 9.0).sqrt();
    assert!((super::scene_extent(&cams) - expect).abs() < 1e-5);
    assert_eq!(super::scene_extent(&cams[..1]), 1.1);
    assert_eq!(super::scene_extent(&[]), 1.1);
}

#[test]
fn load_reports_missing_and_unknown_inputs() {
    let d = temp_dir("load");
    let err = super::load(d.join("nope")).expect_err("missing path");
    assert!(matches!(err, super::CameraError::NotFound { .. }), "{err}");
    let err = super::load(&d).expect_err("empty folder");
    assert!(err.to_string().contains("sparse/0"), "{err}");
    std::fs::write(d.join("x.yaml"), "a: 1").expect("write");
    assert!(super::load(d.join("x.yaml")).is_err());
    std::fs::write(d.join("x.json"), "{\"a\": 1}").expect("write");
    let err = super::load(d.join("x.json")).expect_err("neither format");
    assert!(err.to_string().contains("frames"), "{err}");
}
