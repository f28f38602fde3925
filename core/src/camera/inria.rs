//! The INRIA 3DGS trainer's `cameras.json`, written next to every trained
//! `point_cloud.ply`: often the only cameras that travel with a scene.
//!
//! Convention, verified against the trainer's `camera_to_JSON`
//! (`utils/camera_utils.py`): it builds the world-to-camera matrix `[R_w2c | t]`,
//! inverts it, and writes the inverse's translation as `position` (the camera
//! centre) and its 3x3 block row by row as `rotation`, i.e. the
//! camera-to-world rotation whose columns are the camera's x (right), y (down)
//! and z (forward) axes in world space — already our camera axes, since the
//! trainer uses COLMAP's. `fx`/`fy` come from the field of view; the principal
//! point is the image centre (the trainer assumes it). The project's writer
//! adds `cx`/`cy` for a camera whose principal point is off the centre, and
//! its reader takes them when present; other readers ignore the two keys.

use std::path::Path;

use glam::{DMat3, DVec3};
use serde::Deserialize;

use super::{
    CameraError, CameraSet, Field, ORTHONORMAL_TOLERANCE, check_fields_of, orthonormal_warning, rotation_from,
};
use crate::Camera;

#[derive(Deserialize)]
struct Entry {
    img_name: String,
    width: u32,
    height: u32,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
    cx: Option<f64>,
    cy: Option<f64>,
}

/// Reads an INRIA 3DGS `cameras.json` (a list of
/// `{id, img_name, width, height, position, rotation, fx, fy}`, with the
/// principal point `cx`/`cy` where given, else the image centre), in file order.
pub fn load_inria(path: impl AsRef<Path>) -> Result<CameraSet, CameraError> {
    let path = path.as_ref();
    from_value(path, super::read_json(path)?)
}

/// Reads a parsed `cameras.json` document.
pub(crate) fn from_value(path: &Path, value: serde_json::Value) -> Result<CameraSet, CameraError> {
    let serde_json::Value::Array(items) = value else {
        return Err(CameraError::format(path, "document", "a list of cameras", super::json_kind(&value)));
    };
    if items.is_empty() {
        return Err(CameraError::format(path, "document", "at least one camera", "an empty list"));
    }
    let (mut corrected, mut worst) = (0, 0.0f64);
    let mut cameras = Vec::with_capacity(items.len());
    for (i, item) in items.into_iter().enumerate() {
        let record = format!("cameras[{i}]");
        let fields = [
            ("img_name", Field::Text),
            ("width", Field::Count),
            ("height", Field::Count),
            ("position", Field::Numbers(3)),
            ("rotation", Field::Matrix(3, 3)),
            ("fx", Field::Number),
            ("fy", Field::Number),
            ("cx", Field::Number),
            ("cy", Field::Number),
        ];
        let required = ["img_name", "width", "height", "position", "rotation", "fx", "fy"];
        check_fields_of(path, &record, &item, &fields, &required)?;
        let e: Entry = serde_json::from_value(item).map_err(|source| CameraError::Json {
            path: path.to_path_buf(),
            record: record.clone(),
            source,
        })?;
        let rec = |f: &str| format!("{record} ({}).{f}", e.img_name);
        if e.width == 0 || e.height == 0 {
            let found = format!("{}x{}", e.width, e.height);
            return Err(CameraError::format(path, rec("width/height"), "a positive image size", found));
        }
        for (name, f) in [("fx", e.fx), ("fy", e.fy)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(CameraError::format(path, rec(name), "a positive focal length", f.to_string()));
            }
        }
        let center = DVec3::from_array(e.position);
        if !center.is_finite() {
            return Err(CameraError::format(path, rec("position"), "finite numbers", format!("{:?}", e.position)));
        }
        // `rotation` is written row by row; glam builds matrices from columns.
        let c2w = DMat3::from_cols_array_2d(&e.rotation).transpose();
        let (c2w, dev) = rotation_from(path, &rec("rotation"), c2w)?;
        if dev > ORTHONORMAL_TOLERANCE {
            corrected += 1;
            worst = worst.max(dev);
        }
        // JSON numbers are finite; one past f32's range is refused by the
        // loaders' single-precision check.
        let (w, h) = (e.width as f32, e.height as f32);
        let (cx, cy) = (e.cx.map_or(0.5 * w, |p| p as f32), e.cy.map_or(0.5 * h, |p| p as f32));
        cameras.push(Camera::from_camera_to_world(
            e.img_name,
            e.width,
            e.height,
            e.fx as f32,
            e.fy as f32,
            cx,
            cy,
            c2w,
            center.as_vec3(),
        ));
    }
    let warnings = orthonormal_warning(path, corrected, worst).into_iter().collect();
    Ok(CameraSet { cameras, warnings, depth_bounds: Vec::new() })
}

/// Writes `cameras` as an INRIA 3DGS `cameras.json` (the layout
/// [`load_inria`] reads, so viewers and trainers that read the trainer's
/// output read it too), through a temporary file renamed over `path`.
/// The format keeps no principal point (its readers take the image centre):
/// a camera whose principal point is more than half a pixel off centre gets
/// `cx`/`cy` keys, which [`load_inria`] reads and other readers ignore. The
/// result is the number of such cameras, for the caller to say that other
/// tools will see them centred.
pub fn write_inria(path: impl AsRef<Path>, cameras: &[Camera]) -> Result<usize, CameraError> {
    let path = path.as_ref();
    let mut off_centre = 0;
    let entries: Vec<serde_json::Value> = (cameras.iter().enumerate())
        .map(|(id, c)| {
            // The camera-to-world rotation row by row: its rows are the
            // world-to-camera rotation's columns.
            let c2w = c.rotation.as_dmat3().to_cols_array_2d();
            let off = (c.cx - 0.5 * c.width as f32).abs() > 0.5 || (c.cy - 0.5 * c.height as f32).abs() > 0.5;
            let mut entry = serde_json::json!({
                "id": id,
                "img_name": c.name,
                "width": c.width,
                "height": c.height,
                "position": c.center().as_dvec3().to_array(),
                "rotation": c2w,
                "fy": f64::from(c.fy),
                "fx": f64::from(c.fx),
            });
            if off {
                off_centre += 1;
                entry["cx"] = f64::from(c.cx).into();
                entry["cy"] = f64::from(c.cy).into();
            }
            entry
        })
        .collect();
    let bytes = serde_json::to_vec(&entries).map_err(|e| CameraError::io(path, std::io::Error::other(e)))?;
    crate::io::replace_with(path, |w| std::io::Write::write_all(w, &bytes)).map_err(|e| CameraError::io(path, e))?;
    Ok(off_centre)
}
