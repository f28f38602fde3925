//! Pinhole cameras with the conventions of the golden files, and the camera
//! files users bring (COLMAP, INRIA `cameras.json`, NeRF `transforms.json`,
//! LLFF `poses_bounds.npy`), or cameras generated around a scene that came
//! without any. COLMAP's SfM points (`points3D`) are read here too, since they
//! share the cameras' files and world frame.
//!
//! Every reader converts to one convention so the rasterizer and the losses
//! never need to know where a camera came from: world-to-camera
//! `x_c = R x_w + t`; the camera looks down +z with x right and y down;
//! `u = fx·x/z + cx`, `v = fy·y/z + cy`; pixel (row i, col j) has its centre at
//! `(j + 0.5, i + 0.5)`. Lens distortion is not modelled: distorted COLMAP
//! models load as pinholes with a warning in [`CameraSet::warnings`].

mod colmap;
mod colmap_bin;
mod colmap_points;
mod colmap_records;
mod colmap_write;
mod error;
mod framing;
mod inria;
mod llff;
mod npy;
mod orbit;
mod sweep;
#[cfg(test)]
mod tests;
mod transforms;

use std::path::{Path, PathBuf};

use glam::{Mat3, Vec2, Vec3};

/// The longer image sides, in pixels, that renders, runs and fits accept:
/// 16 leaves VGG's relu3 a 4 × 4 grid; 8,192 is past any display, and a
/// frame's buffers stay within a few GB.
pub const IMAGE_SIDES: std::ops::RangeInclusive<u32> = 16..=8192;

pub use colmap::load_colmap;
pub use colmap_points::{ColmapPoints, find_colmap_points, load_colmap_points};
pub use colmap_write::{write_colmap_binary, write_colmap_text};
pub use error::CameraError;
pub use framing::{crop_view, fit_view, framed_orbit, framing_subject, subject_span};
pub use inria::{load_inria, write_inria};
pub use llff::{LLFF_IMAGE_FOLDERS, POSES_BOUNDS, load_llff};
pub use orbit::{OrbitLayout, OrbitOptions, RobustBounds, orbit_cameras, robust_bounds};
pub use sweep::{forward_facing, forward_sweep};
pub use transforms::load_transforms;

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

impl Camera {
    /// A camera from a camera-to-world pose: `c2w` has the camera's x (right),
    /// y (down) and z (forward) axes as columns, `center` is its position.
    #[allow(clippy::too_many_arguments)]
    pub fn from_camera_to_world(
        name: impl Into<String>,
        width: u32,
        height: u32,
        fx: f32,
        fy: f32,
        cx: f32,
        cy: f32,
        c2w: Mat3,
        center: Vec3,
    ) -> Self {
        let rotation = c2w.transpose();
        Self { name: name.into(), width, height, fx, fy, cx, cy, rotation, translation: -(rotation * center) }
    }

    /// A camera at `eye` looking at `target`, with `up` pointing up on screen
    /// (the camera's y axis, which points down, is as close to `−up` as the
    /// view direction allows). Square pixels, principal point at the image
    /// centre, vertical field of view `fov_y_degrees`. When `up` is parallel to
    /// the view direction another perpendicular is chosen.
    pub fn look_at(
        name: impl Into<String>,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        width: u32,
        height: u32,
        fov_y_degrees: f32,
    ) -> Self {
        let z = (target - eye).try_normalize().unwrap_or(Vec3::Z);
        let down = -up.try_normalize().unwrap_or(Vec3::NEG_Y);
        let x = down.cross(z).try_normalize().unwrap_or_else(|| z.any_orthonormal_vector());
        let y = z.cross(x);
        let fy = 0.5 * height as f32 / (0.5 * fov_y_degrees.to_radians()).tan();
        let (w, h) = (width as f32, height as f32);
        Self::from_camera_to_world(name, width, height, fy, fy, 0.5 * w, 0.5 * h, Mat3::from_cols(x, y, z), eye)
    }

    /// The pixel position of a world point, or `None` when it is at or behind
    /// the camera plane (`z ≤ 0`). The position may lie outside the image.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let c = self.world_to_camera(p);
        (c.z > 0.0).then(|| self.pixel_of(c))
    }

    /// The pixel position of a camera-space point `c` (in front of the
    /// camera: `c.z > 0`, which the caller checks), for a caller that holds
    /// the camera-space point already. The position may lie outside the image.
    pub fn pixel_of(&self, c: Vec3) -> Vec2 {
        Vec2::new(self.fx * c.x / c.z + self.cx, self.fy * c.y / c.z + self.cy)
    }

    /// The same camera at another resolution: focal lengths and principal
    /// point scale with the image, so the field of view is unchanged.
    pub fn scaled_to(&self, width: u32, height: u32) -> Self {
        let sx = width as f32 / self.width.max(1) as f32;
        let sy = height as f32 / self.height.max(1) as f32;
        Self { width, height, fx: self.fx * sx, fy: self.fy * sy, cx: self.cx * sx, cy: self.cy * sy, ..self.clone() }
    }

    /// The camera at a working resolution whose longer side is at most
    /// `max_side`, keeping the aspect ratio (sides rounded, at least 1 pixel).
    /// A camera already small enough is returned unchanged, never enlarged.
    pub fn downscaled_to_max_side(&self, max_side: u32) -> Self {
        if self.width.max(self.height) <= max_side {
            return self.clone();
        }
        self.with_longer_side(max_side)
    }

    /// The camera rescaled so that its longer image side is `side` pixels
    /// (larger or smaller), keeping the aspect ratio (sides rounded, at least 1
    /// pixel): a working resolution for optimisation, inspection or export.
    pub fn with_longer_side(&self, side: u32) -> Self {
        let longest = self.width.max(self.height);
        if longest == 0 {
            return self.clone();
        }
        let s = f64::from(side) / f64::from(longest);
        let px = |v: u32| ((f64::from(v) * s).round() as u32).max(1);
        self.scaled_to(px(self.width), px(self.height))
    }
}

/// Reads and parses a JSON camera file; errors name the file.
pub(crate) fn read_json(path: &Path) -> Result<serde_json::Value, CameraError> {
    let text = std::fs::read_to_string(path).map_err(|e| CameraError::io(path, e))?;
    serde_json::from_str(&text).map_err(|source| CameraError::Json {
        path: path.to_path_buf(),
        record: "document".into(),
        source,
    })
}

/// Cameras read from a file, with what the reader had to approximate.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraSet {
    /// The cameras, in the file's order (COLMAP: sorted by image name).
    pub cameras: Vec<Camera>,
    /// Things the user should know (ignored distortion, re-orthonormalised
    /// poses, …), one line each, naming the file.
    pub warnings: Vec<String>,
    /// Near and far scene depth per camera where the file gives them (LLFF),
    /// else empty.
    pub depth_bounds: Vec<[f32; 2]>,
}

/// The scene extent used to scale the geometry learning rate (ALGORITHM.md,
/// as in 3DGS): 1.1 × the largest distance of a camera centre from the
/// centroid of the camera centres. With no cameras, or all centres at one
/// point (a single camera), there is no spread to measure and the result is 1.1
/// (a unit radius), so learning rates stay finite and non-zero.
pub fn scene_extent(cameras: &[Camera]) -> f32 {
    if cameras.is_empty() {
        return 1.1;
    }
    let centers: Vec<Vec3> = cameras.iter().map(Camera::center).collect();
    let centroid = centers.iter().copied().sum::<Vec3>() / centers.len() as f32;
    let radius = centers.iter().map(|c| c.distance(centroid)).fold(0.0f32, f32::max);
    if radius.is_finite() && radius > 1e-6 { 1.1 * radius } else { 1.1 }
}

/// Reads cameras from any supported source, detecting the format from the path:
/// - a folder holding `sparse/0/` (or `sparse/`) with COLMAP files, or the
///   COLMAP folder itself (`cameras.{bin,txt}` and `images.{bin,txt}`; a
///   model without `images` is not one, e.g. LLFF's `sparse/0` with only
///   `cameras.bin` and `points3D.bin`);
/// - a folder holding `poses_bounds.npy` (LLFF, images from `images_8`,
///   `images_4` or `images`, the first that exists: see [`load_llff`]);
/// - a folder holding `cameras.json` (INRIA 3DGS trainer output);
/// - a folder holding `transforms.json` or, failing that, `transforms_train.json`
///   or another `transforms*.json` (NeRF / nerfstudio);
/// - a `.json` file, told apart by content (a list is `cameras.json`, an object
///   with `frames` is `transforms.json`);
/// - a COLMAP `cameras`/`images` `.bin` or `.txt` file (its sibling is read too);
/// - an LLFF `.npy` file.
pub fn load(path: impl AsRef<Path>) -> Result<CameraSet, CameraError> {
    load_with_images(path, None)
}

/// As [`load`], naming the images folder of an LLFF dataset (`images_4`, …,
/// relative to the dataset folder), which decides the cameras' image names
/// and sizes. The other formats name their images themselves and ignore it.
pub fn load_with_images(path: impl AsRef<Path>, images: Option<&str>) -> Result<CameraSet, CameraError> {
    let path = path.as_ref();
    let (set, source) = load_any(path, images)?;
    single_precision(&source, &set)?;
    Ok(set)
}

/// The training cameras that travel with a scene file: those of its own
/// folder (what `gast fit` writes, a dataset holding the scene) or, for the
/// INRIA trainer's `point_cloud/iteration_N/point_cloud.ply`, the model
/// folder's `cameras.json`. `None` when neither folder holds a camera file;
/// an error when one does and it cannot be read. With the set comes the
/// folder it was found in.
pub fn beside_scene(scene: &Path) -> Option<Result<(CameraSet, PathBuf), CameraError>> {
    let here = |p: &Path| if p.as_os_str().is_empty() { Path::new(".").to_path_buf() } else { p.to_path_buf() };
    let named = |p: &Path, f: &dyn Fn(&str) -> bool| p.file_name().and_then(|n| n.to_str()).is_some_and(f);
    let parent = scene.parent()?;
    let model = parent
        .parent()
        .filter(|pc| named(parent, &|n| n.starts_with("iteration_")) && named(pc, &|n| n == "point_cloud"))
        .and_then(Path::parent);
    let parent = here(parent);
    for dir in std::iter::once(parent).chain(model.map(here)) {
        match load(&dir) {
            Err(CameraError::NotFound { path, .. }) if path == dir => continue,
            Ok(set) if set.cameras.is_empty() => continue,
            found => return Some(found.map(|set| (set, dir))),
        }
    }
    None
}

/// The readers check the file's numbers as read (f64); a finite one past
/// f32's range (a position of 1e39) became infinite in the camera, which
/// rendered nothing and said nothing.
fn single_precision(path: &Path, set: &CameraSet) -> Result<(), CameraError> {
    for (i, c) in set.cameras.iter().enumerate() {
        let parts = [
            ("focal length", c.fx.is_finite() && c.fy.is_finite()),
            ("principal point", c.cx.is_finite() && c.cy.is_finite()),
            ("rotation", c.rotation.is_finite()),
            ("position", c.translation.is_finite()),
        ];
        if let Some((what, _)) = parts.iter().find(|(_, ok)| !ok) {
            return Err(CameraError::format(
                path,
                format!("camera {i} ({})", c.name),
                format!("a {what} within single precision (magnitudes below 3.4e38)"),
                "one that overflows it",
            ));
        }
    }
    Ok(())
}

/// The cameras, and the file (or COLMAP folder) they were read from.
fn load_any(path: &Path, images: Option<&str>) -> Result<(CameraSet, PathBuf), CameraError> {
    if path.is_dir() {
        return load_dir(path, images);
    }
    if !path.exists() {
        return Err(CameraError::NotFound { path: path.to_path_buf(), expected: EXPECTED.into() });
    }
    let set = match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("json") => load_json(path),
        Some("bin" | "txt") => load_colmap(path),
        Some("npy") => load_llff(path, images),
        other => Err(CameraError::format(
            path,
            "file name",
            "a .json, .bin, .txt or .npy camera file",
            other.map_or("no extension".to_string(), |e| format!("a .{e} file")),
        )),
    }?;
    Ok((set, path.to_path_buf()))
}

const EXPECTED: &str = "sparse/0/{cameras,images}.{bin,txt}, poses_bounds.npy, cameras.json or transforms*.json";

/// The kinds of camera file a folder may hold, in the order [`camera_file_in`] looks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraFileKind {
    /// A COLMAP model (`cameras` and `images`, `.bin` or `.txt`).
    Colmap,
    /// LLFF `poses_bounds.npy`.
    Llff,
    /// An INRIA `cameras.json`.
    Inria,
    /// A NeRF `transforms*.json`.
    Transforms,
}

/// The cameras a folder holds, as a camera load of the folder finds them:
/// a COLMAP model in `sparse/0`, `sparse` or the folder itself, else
/// `poses_bounds.npy`, else `cameras.json`, else a `transforms*.json`; with
/// the file (or COLMAP folder).
pub fn camera_file_in(dir: &Path) -> Option<(CameraFileKind, PathBuf)> {
    for d in [dir.join("sparse/0"), dir.join("sparse"), dir.to_path_buf()] {
        if colmap::has_colmap_files(&d) {
            return Some((CameraFileKind::Colmap, d));
        }
    }
    if dir.join(POSES_BOUNDS).is_file() {
        return Some((CameraFileKind::Llff, dir.join(POSES_BOUNDS)));
    }
    let inria = dir.join("cameras.json");
    if inria.is_file() {
        return Some((CameraFileKind::Inria, inria));
    }
    find_transforms(dir).map(|t| (CameraFileKind::Transforms, t))
}

fn load_dir(dir: &Path, images: Option<&str>) -> Result<(CameraSet, PathBuf), CameraError> {
    let Some((kind, file)) = camera_file_in(dir) else {
        return Err(CameraError::NotFound { path: dir.to_path_buf(), expected: EXPECTED.into() });
    };
    let set = match kind {
        CameraFileKind::Colmap => load_colmap(&file)?,
        CameraFileKind::Llff => load_llff(dir, images)?,
        CameraFileKind::Inria => load_inria(&file)?,
        CameraFileKind::Transforms => load_transforms(&file)?,
    };
    Ok((set, file))
}

/// `transforms.json`, else `transforms_train.json`, else the first `transforms*.json` by name.
fn find_transforms(dir: &Path) -> Option<PathBuf> {
    for name in ["transforms.json", "transforms_train.json"] {
        let p = dir.join(name);
        if p.is_file() {
            return Some(p);
        }
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("transforms") && n.ends_with(".json"))
        })
        .collect();
    found.sort();
    found.into_iter().next()
}

fn load_json(path: &Path) -> Result<CameraSet, CameraError> {
    let value = read_json(path)?;
    match &value {
        serde_json::Value::Array(_) => inria::from_value(path, value),
        serde_json::Value::Object(o) if o.contains_key("frames") => transforms::from_value(path, value),
        other => Err(CameraError::format(
            path,
            "document",
            "a list of cameras (cameras.json) or an object with `frames` (transforms.json)",
            json_kind(other),
        )),
    }
}

/// A short description of a JSON value's kind, for error messages.
pub(crate) fn json_kind(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Object(_) => "an object without `frames`",
        other => json_type(other),
    }
}

/// What a JSON value is, for error messages: "a string", "a list", ….
fn json_type(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "a list",
        serde_json::Value::Object(_) => "an object",
    }
}

/// What a field of a JSON camera record holds.
#[derive(Clone, Copy)]
pub(crate) enum Field {
    /// Any number.
    Number,
    /// A whole number from 0 up.
    Count,
    /// A string.
    Text,
    /// A list of this many numbers.
    Numbers(usize),
    /// A list of lists of numbers (a pose matrix whose shape its reader checks).
    Rows,
    /// A list of this many rows of this many numbers.
    Matrix(usize, usize),
}

impl Field {
    /// What the field holds, for messages.
    fn expected(self) -> String {
        match self {
            Field::Number => "a number".into(),
            Field::Count => "a whole number of pixels".into(),
            Field::Text => "a string".into(),
            Field::Numbers(n) => format!("a list of {n} numbers"),
            Field::Rows => "a list of rows of numbers".into(),
            Field::Matrix(r, c) => format!("a {r}x{c} matrix ({r} lists of {c} numbers)"),
        }
    }
}

/// Checks the `fields` present in the record `value` (an object; null reads
/// as absent) before serde reads it, so that a wrong type names its field:
/// serde_json's `from_value` names none ("invalid type: string, expected
/// f64"), and through `#[serde(flatten)]` not even the record's. A missing
/// field, and a value that is not an object, are left to serde, which names both.
pub(crate) fn check_fields(
    path: &Path,
    record: &str,
    value: &serde_json::Value,
    fields: &[(&str, Field)],
) -> Result<(), CameraError> {
    check_fields_of(path, record, value, fields, &[])
}

/// As [`check_fields`], with the fields that are `required` refused when
/// null too (serde's "invalid type: null" named none of them).
pub(crate) fn check_fields_of(
    path: &Path,
    record: &str,
    value: &serde_json::Value,
    fields: &[(&str, Field)],
    required: &[&str],
) -> Result<(), CameraError> {
    let Some(object) = value.as_object() else { return Ok(()) };
    if let Some((name, field)) =
        fields.iter().find(|(name, _)| required.contains(name) && object.get(*name).is_some_and(|v| v.is_null()))
    {
        return Err(CameraError::format(path, format!("{record}.{name}"), field.expected(), "null"));
    }
    let numbers = |v: &serde_json::Value, n: Option<usize>| {
        v.as_array().is_some_and(|a| n.is_none_or(|n| a.len() == n) && a.iter().all(serde_json::Value::is_number))
    };
    for &(name, field) in fields {
        let Some(v) = object.get(name).filter(|v| !v.is_null()) else { continue };
        let fits = match field {
            Field::Number => v.is_number(),
            Field::Count => v.is_u64() && v.as_u64().is_some_and(|n| n <= u64::from(u32::MAX)),
            Field::Text => v.is_string(),
            Field::Numbers(n) => numbers(v, Some(n)),
            Field::Rows => v.as_array().is_some_and(|rows| rows.iter().all(|r| numbers(r, None))),
            Field::Matrix(r, c) => {
                v.as_array().is_some_and(|rows| rows.len() == r && rows.iter().all(|row| numbers(row, Some(c))))
            }
        };
        if !fits {
            let expected = field.expected();
            let found = match v {
                serde_json::Value::Array(_) => {
                    let text = v.to_string();
                    if text.chars().count() > 60 {
                        format!("{}…", text.chars().take(60).collect::<String>())
                    } else {
                        text
                    }
                }
                serde_json::Value::Number(n) => n.to_string(),
                other => json_type(other).to_string(),
            };
            return Err(CameraError::format(path, format!("{record}.{name}"), expected, found));
        }
    }
    Ok(())
}

/// A rotation made (Gram–Schmidt on the columns) from a pose matrix read
/// from a file, with how far the file's matrix was from it (largest entry
/// difference). Scaled or sheared poses are corrected, reflections and
/// non-finite matrices are errors.
pub(crate) fn rotation_from(path: &Path, record: &str, m: glam::DMat3) -> Result<(Mat3, f64), CameraError> {
    // The readers' axis flips keep the determinant, so it reads as the file's own.
    let bad = || {
        let found = if m.is_finite() {
            format!("a matrix whose determinant is {}", m.determinant())
        } else {
            "a matrix with non-finite entries".to_string()
        };
        CameraError::format(path, record, "a 3x3 rotation (orthonormal, determinant +1)", found)
    };
    if !m.is_finite() || m.determinant() <= 1e-9 {
        return Err(bad());
    }
    let x = m.x_axis.try_normalize().ok_or_else(bad)?;
    let y = (m.y_axis - x * x.dot(m.y_axis)).try_normalize().ok_or_else(bad)?;
    let r = glam::DMat3::from_cols(x, y, x.cross(y));
    let dev = (r - m).to_cols_array().iter().fold(0.0f64, |a, v| a.max(v.abs()));
    Ok((r.as_mat3(), dev))
}

/// A warning for poses that had to be re-orthonormalised, or `None`.
pub(crate) fn orthonormal_warning(path: &Path, corrected: usize, worst: f64) -> Option<String> {
    (corrected > 0).then(|| {
        format!(
            "{}: {corrected} camera rotation(s) were not orthonormal (largest entry off by {worst:.2e}) and were re-orthonormalised (Gram–Schmidt on the columns)",
            path.display()
        )
    })
}

/// Above this entry difference a pose's rotation is reported as corrected.
pub(crate) const ORTHONORMAL_TOLERANCE: f64 = 1e-3;
