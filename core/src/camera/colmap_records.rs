//! The records of a COLMAP model (its camera models, cameras, images and
//! points) and the checks every reader applies to them, whichever encoding
//! (text in `colmap.rs` and `colmap_points.rs`, binary in `colmap_bin.rs`)
//! they were read from.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;

use super::CameraError;

/// How a model's first parameters map to the pinhole intrinsics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Focal {
    /// `f, cx, cy, …`
    Single,
    /// `fx, fy, cx, cy, …`
    Pair,
}

/// A COLMAP camera model: numeric id, name, parameter count, focal layout.
#[derive(Debug)]
pub(crate) struct Model {
    pub id: i32,
    pub name: &'static str,
    pub params: usize,
    pub focal: Focal,
}

/// Every model COLMAP defines (`colmap/sensor/models.h`). The first two are
/// pure pinholes; the others carry distortion, which is ignored with a warning.
pub(crate) const MODELS: [Model; 12] = [
    model(0, "SIMPLE_PINHOLE", 3, Focal::Single),
    model(1, "PINHOLE", 4, Focal::Pair),
    model(2, "SIMPLE_RADIAL", 4, Focal::Single),
    model(3, "RADIAL", 5, Focal::Single),
    model(4, "OPENCV", 8, Focal::Pair),
    model(5, "OPENCV_FISHEYE", 8, Focal::Pair),
    model(6, "FULL_OPENCV", 12, Focal::Pair),
    model(7, "FOV", 5, Focal::Pair),
    model(8, "SIMPLE_RADIAL_FISHEYE", 4, Focal::Single),
    model(9, "RADIAL_FISHEYE", 5, Focal::Single),
    model(10, "THIN_PRISM_FISHEYE", 12, Focal::Pair),
    model(11, "RAD_TAN_THIN_PRISM_FISHEYE", 16, Focal::Pair),
];

const fn model(id: i32, name: &'static str, params: usize, focal: Focal) -> Model {
    Model { id, name, params, focal }
}

pub(crate) fn known_models() -> String {
    MODELS.iter().map(|m| m.name).collect::<Vec<_>>().join(", ")
}

/// One record of `cameras.{bin,txt}`.
pub(crate) struct ColmapCamera {
    pub model: &'static Model,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

/// One record of `images.{bin,txt}`.
pub(crate) struct ColmapImage {
    pub id: u32,
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    pub camera_id: u32,
    pub name: String,
}

/// Checks a camera record's values, shared by the text and binary readers.
fn check_camera(path: &Path, id: u32, c: &ColmapCamera) -> Result<(), CameraError> {
    let rec = |f: &str| format!("camera {id}.{f}");
    if c.width == 0 || c.height == 0 {
        return Err(CameraError::format(
            path,
            rec("size"),
            "a positive width and height",
            format!("{}x{}", c.width, c.height),
        ));
    }
    let n_focal = if c.model.focal == Focal::Single { 1 } else { 2 };
    for (i, v) in c.params.iter().enumerate() {
        let bad = !v.is_finite() || (i < n_focal && *v <= 0.0);
        if bad {
            let what = if i < n_focal { "a positive finite focal length" } else { "a finite number" };
            return Err(CameraError::format(path, rec(&format!("params[{i}]")), what, v.to_string()));
        }
    }
    Ok(())
}

/// Checks an image record's pose, shared by the text and binary readers.
pub(crate) fn check_image(path: &Path, im: &ColmapImage) -> Result<(), CameraError> {
    let rec = |f: &str| format!("image {} ({}).{f}", im.id, im.name);
    let norm2: f64 = im.qvec.iter().map(|v| v * v).sum();
    if !(norm2.is_finite() && norm2 > 1e-12) {
        return Err(CameraError::format(path, rec("qvec"), "a finite non-zero quaternion", format!("{:?}", im.qvec)));
    }
    if im.tvec.iter().any(|v| !v.is_finite()) {
        return Err(CameraError::format(path, rec("tvec"), "finite numbers", format!("{:?}", im.tvec)));
    }
    Ok(())
}

pub(crate) fn insert_camera(
    path: &Path,
    map: &mut BTreeMap<u32, ColmapCamera>,
    id: u32,
    cam: ColmapCamera,
) -> Result<(), CameraError> {
    check_camera(path, id, &cam)?;
    if map.insert(id, cam).is_some() {
        return Err(CameraError::format(path, format!("camera {id}"), "unique camera ids", "a duplicate"));
    }
    Ok(())
}

/// SfM points: position and 8-bit RGB colour, in the file's order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColmapPoints {
    /// World positions.
    pub positions: Vec<Vec3>,
    /// Colours, one per position.
    pub colors: Vec<[u8; 3]>,
}

impl ColmapPoints {
    /// An empty set with room for `n` points.
    pub fn with_capacity(n: usize) -> Self {
        Self { positions: Vec::with_capacity(n), colors: Vec::with_capacity(n) }
    }

    /// The number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// Checks a point's position, shared by the text and binary readers.
pub(crate) fn check_point(path: &Path, record: &str, xyz: [f64; 3]) -> Result<Vec3, CameraError> {
    if xyz.iter().all(|v| v.is_finite() && v.abs() < f64::from(f32::MAX)) {
        Ok(Vec3::new(xyz[0] as f32, xyz[1] as f32, xyz[2] as f32))
    } else {
        Err(CameraError::format(path, format!("{record}.xyz"), "finite coordinates", format!("{xyz:?}")))
    }
}
