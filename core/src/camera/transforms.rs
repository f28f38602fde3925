//! NeRF-synthetic and nerfstudio `transforms.json`: the format of the classic
//! NeRF datasets and of most phone-capture pipelines.
//!
//! `frames[].transform_matrix` is camera-to-world in the OpenGL/Blender
//! convention (the camera looks down −z with y up); ours looks down +z with y
//! down, so the camera's y and z axes are negated. Intrinsics come either from
//! `camera_angle_x` (and optionally `camera_angle_y`) or from
//! `fl_x, fl_y, cx, cy, w, h`, at the top level or per frame (a frame's values
//! win). When the image size is not given, it is read from the header of the
//! frame's image, whose `file_path` may lack its extension (NeRF-synthetic).

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use serde::Deserialize;

use super::{
    CameraError, CameraSet, Field, ORTHONORMAL_TOLERANCE, check_fields, check_fields_of, orthonormal_warning,
    rotation_from,
};
use crate::Camera;

/// Intrinsics that may appear at the top level or in a frame.
#[derive(Clone, Debug, Default, Deserialize)]
struct Intrinsics {
    camera_angle_x: Option<f64>,
    camera_angle_y: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
}

impl Intrinsics {
    /// `self`'s values where present, else `base`'s.
    fn over(self, base: &Intrinsics) -> Intrinsics {
        macro_rules! pick {
            ($($f:ident),*) => { Intrinsics { $($f: self.$f.or(base.$f)),* } };
        }
        pick!(camera_angle_x, camera_angle_y, fl_x, fl_y, cx, cy, w, h, k1, k2, k3, k4, p1, p2)
    }

    fn has_distortion(&self) -> bool {
        [self.k1, self.k2, self.k3, self.k4, self.p1, self.p2].iter().any(|v| v.is_some_and(|v| v != 0.0))
    }
}

#[derive(Deserialize)]
struct Document {
    #[serde(flatten)]
    intrinsics: Intrinsics,
    frames: Vec<serde_json::Value>,
}

#[derive(Deserialize)]
struct Frame {
    file_path: Option<String>,
    transform_matrix: Vec<Vec<f64>>,
    #[serde(flatten)]
    intrinsics: Intrinsics,
}

/// Reads a NeRF / nerfstudio `transforms*.json`, in frame order.
pub fn load_transforms(path: impl AsRef<Path>) -> Result<CameraSet, CameraError> {
    let path = path.as_ref();
    from_value(path, super::read_json(path)?)
}

/// The fields of [`Intrinsics`], which a frame or the document may hold.
const INTRINSIC_FIELDS: [(&str, Field); 14] = [
    ("camera_angle_x", Field::Number),
    ("camera_angle_y", Field::Number),
    ("fl_x", Field::Number),
    ("fl_y", Field::Number),
    ("cx", Field::Number),
    ("cy", Field::Number),
    ("w", Field::Number),
    ("h", Field::Number),
    ("k1", Field::Number),
    ("k2", Field::Number),
    ("k3", Field::Number),
    ("k4", Field::Number),
    ("p1", Field::Number),
    ("p2", Field::Number),
];

/// Reads a parsed `transforms.json` document.
pub(crate) fn from_value(path: &Path, value: serde_json::Value) -> Result<CameraSet, CameraError> {
    check_fields(path, "document", &value, &INTRINSIC_FIELDS)?;
    let doc: Document = serde_json::from_value(value).map_err(|source| CameraError::Json {
        path: path.to_path_buf(),
        record: "document".into(),
        source,
    })?;
    if doc.frames.is_empty() {
        return Err(CameraError::format(path, "frames", "at least one frame", "an empty list"));
    }
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let (mut corrected, mut worst, mut distorted) = (0, 0.0f64, 0);
    let mut cameras = Vec::with_capacity(doc.frames.len());
    for (i, item) in doc.frames.into_iter().enumerate() {
        let record = format!("frames[{i}]");
        check_fields(path, &record, &item, &INTRINSIC_FIELDS)?;
        let frame_fields = [("file_path", Field::Text), ("transform_matrix", Field::Rows)];
        check_fields_of(path, &record, &item, &frame_fields, &["transform_matrix"])?;
        let frame: Frame = serde_json::from_value(item).map_err(|source| CameraError::Json {
            path: path.to_path_buf(),
            record: record.clone(),
            source,
        })?;
        let intr = frame.intrinsics.over(&doc.intrinsics);
        distorted += usize::from(intr.has_distortion());
        let name = frame
            .file_path
            .as_deref()
            .map(|p| p.strip_prefix("./").unwrap_or(p).to_string())
            .unwrap_or_else(|| format!("frame_{i:04}"));

        let (width, height) = match (intr.w, intr.h) {
            (Some(w), Some(h)) => (pixels(path, &format!("{record}.w"), w)?, pixels(path, &format!("{record}.h"), h)?),
            _ => image_size(path, &base_dir, &record, frame.file_path.as_deref())?,
        };
        let (w, h) = (f64::from(width), f64::from(height));
        // A field of view in radians: 0 or past π has no pinhole focal length.
        for (f, a) in [("camera_angle_x", intr.camera_angle_x), ("camera_angle_y", intr.camera_angle_y)] {
            if let Some(a) = a.filter(|a| !(*a > 0.0 && *a < std::f64::consts::PI)) {
                let expected = "a field of view in radians between 0 and π (exclusive)";
                return Err(CameraError::format(path, format!("{record}.{f}"), expected, a.to_string()));
            }
        }
        let from_angle = |angle: f64, side: f64| 0.5 * side / (0.5 * angle).tan();
        let fx = intr
            .fl_x
            .or(intr.camera_angle_x.map(|a| from_angle(a, w)))
            .or(intr.fl_y)
            .or(intr.camera_angle_y.map(|a| from_angle(a, h)))
            .ok_or_else(|| {
                CameraError::format(
                    path,
                    &record,
                    "a focal length: fl_x/fl_y or camera_angle_x/camera_angle_y",
                    "none of them",
                )
            })?;
        let fy = intr.fl_y.or(intr.camera_angle_y.map(|a| from_angle(a, h))).unwrap_or(fx);
        let (cx, cy) = (intr.cx.unwrap_or(0.5 * w), intr.cy.unwrap_or(0.5 * h));
        for (f, v) in [("fl_x", fx), ("fl_y", fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CameraError::format(
                    path,
                    format!("{record}.{f}"),
                    "a positive finite focal length",
                    v.to_string(),
                ));
            }
        }
        for (f, v) in [("cx", cx), ("cy", cy)] {
            if !v.is_finite() {
                return Err(CameraError::format(path, format!("{record}.{f}"), "a finite number", v.to_string()));
            }
        }

        let (c2w_gl, center) = pose(path, &record, &frame.transform_matrix)?;
        let c2w = from_opengl(c2w_gl);
        let (c2w, dev) = rotation_from(path, &format!("{record}.transform_matrix"), c2w)?;
        if dev > ORTHONORMAL_TOLERANCE {
            corrected += 1;
            worst = worst.max(dev);
        }
        cameras.push(Camera::from_camera_to_world(
            name,
            width,
            height,
            fx as f32,
            fy as f32,
            cx as f32,
            cy as f32,
            c2w,
            center.as_vec3(),
        ));
    }
    let mut warnings: Vec<String> = orthonormal_warning(path, corrected, worst).into_iter().collect();
    if distorted > 0 {
        warnings.push(format!(
            "{}: {distorted} frame(s) have lens distortion coefficients (k1…k4, p1, p2); they are ignored and the images are treated as undistorted pinhole images",
            path.display()
        ));
    }
    Ok(CameraSet { cameras, warnings, depth_bounds: Vec::new() })
}

/// A camera-to-world rotation with OpenGL camera axes as columns (x right,
/// y up, looking down −z) in ours (x right, y down, +z forward): the y and z
/// columns are negated.
pub(crate) fn from_opengl(c2w_gl: DMat3) -> DMat3 {
    DMat3::from_cols(c2w_gl.x_axis, -c2w_gl.y_axis, -c2w_gl.z_axis)
}

/// The 3x3 rotation block and translation of a 4x4 (or 3x4) row-major matrix.
fn pose(path: &Path, record: &str, m: &[Vec<f64>]) -> Result<(DMat3, DVec3), CameraError> {
    let shape =
        |m: &[Vec<f64>]| format!("{} rows of lengths {:?}", m.len(), m.iter().map(Vec::len).collect::<Vec<_>>());
    if !(m.len() == 3 || m.len() == 4) || m.iter().take(3).any(|r| r.len() != 4) {
        return Err(CameraError::format(path, format!("{record}.transform_matrix"), "a 4x4 (or 3x4) matrix", shape(m)));
    }
    let col = |j: usize| DVec3::new(m[0][j], m[1][j], m[2][j]);
    let t = col(3);
    if !t.is_finite() {
        return Err(CameraError::format(
            path,
            format!("{record}.transform_matrix"),
            "finite numbers",
            format!("{m:?}"),
        ));
    }
    Ok((DMat3::from_cols(col(0), col(1), col(2)), t))
}

fn pixels(path: &Path, record: &str, v: f64) -> Result<u32, CameraError> {
    if v.is_finite() && v >= 1.0 && v <= f64::from(u32::MAX) && v.fract() == 0.0 {
        Ok(v as u32)
    } else {
        Err(CameraError::format(path, record, "a positive whole number of pixels", v.to_string()))
    }
}

/// The size of a frame's image, read from its header. `file_path` is relative
/// to the json's folder and may lack its extension.
fn image_size(path: &Path, base: &Path, record: &str, file: Option<&str>) -> Result<(u32, u32), CameraError> {
    let file = file.ok_or_else(|| {
        CameraError::format(path, record, "an image size (w and h) or a file_path to read it from", "neither")
    })?;
    let direct = base.join(file.strip_prefix("./").unwrap_or(file));
    let mut candidates = std::iter::once(direct.clone()).chain(
        ["png", "jpg", "jpeg", "webp", "PNG", "JPG", "JPEG"]
            .iter()
            .map(|e| PathBuf::from(format!("{}.{e}", direct.display()))),
    );
    let found = candidates.find(|p| p.is_file()).ok_or_else(|| CameraError::NotFound {
        path: direct.clone(),
        expected: format!(
            "the image of {record} (file_path {file:?}, with or without .png/.jpg/.webp) to read its size, since the json gives no w and h"
        ),
    })?;
    image::image_dimensions(&found).map_err(|e| {
        CameraError::format(
            &found,
            format!("image header of {record}"),
            "a readable PNG, JPEG or WebP header",
            e.to_string(),
        )
    })
}
