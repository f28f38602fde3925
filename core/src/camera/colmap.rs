//! COLMAP sparse models (`cameras` and `images`, binary or text), the poses
//! most 3DGS scenes were trained from.
//!
//! Only what a pinhole renderer needs is read: intrinsics, the world-to-camera
//! quaternion and translation, the camera id and the image name; the 2D points
//! are skipped. Binary counts come from the file, so every count is checked
//! against the bytes left before anything is allocated or looped over: a
//! corrupt count fails at once instead of exhausting memory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, Vec3};

use super::colmap_records::{ColmapCamera, ColmapImage, Focal, MODELS, check_image, insert_camera, known_models};
use super::{Camera, CameraError, CameraSet, colmap_bin};

/// Whether `dir` holds a COLMAP model (`cameras` and `images`, bin or txt).
pub(crate) fn has_colmap_files(dir: &Path) -> bool {
    let any = |stem: &str| ["bin", "txt"].iter().any(|e| dir.join(format!("{stem}.{e}")).is_file());
    any("cameras") && any("images")
}

/// Reads a COLMAP model. `path` is the scene folder (holding `sparse/0`), the
/// model folder itself, or one of its `cameras`/`images` `.bin`/`.txt` files
/// (then that encoding is preferred for both). Otherwise binary is preferred
/// over text, as COLMAP and the 3DGS trainer do. Cameras are sorted by image name.
pub fn load_colmap(path: impl AsRef<Path>) -> Result<CameraSet, CameraError> {
    let path = path.as_ref();
    let (dir, prefer) = if path.is_file() {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("bin");
        (path.parent().unwrap_or(Path::new(".")).to_path_buf(), if ext == "txt" { "txt" } else { "bin" })
    } else if path.join("sparse/0").is_dir() {
        (path.join("sparse/0"), "bin")
    } else {
        (path.to_path_buf(), "bin")
    };
    let cameras_path = pick(&dir, "cameras", prefer)?;
    let images_path = pick(&dir, "images", prefer)?;
    let cams = if is_bin(&cameras_path) {
        colmap_bin::read_cameras_bin(&cameras_path)?
    } else {
        read_cameras_txt(&cameras_path)?
    };
    let images =
        if is_bin(&images_path) { colmap_bin::read_images_bin(&images_path)? } else { read_images_txt(&images_path)? };
    assemble(&cameras_path, &images_path, &cams, images)
}

fn is_bin(p: &Path) -> bool {
    p.extension().is_some_and(|e| e == "bin")
}

fn pick(dir: &Path, stem: &str, prefer: &str) -> Result<PathBuf, CameraError> {
    let other = if prefer == "bin" { "txt" } else { "bin" };
    [prefer, other]
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
        .find(|p| p.is_file())
        .ok_or_else(|| CameraError::NotFound { path: dir.to_path_buf(), expected: format!("{stem}.bin or {stem}.txt") })
}

fn assemble(
    cameras_path: &Path,
    images_path: &Path,
    cams: &BTreeMap<u32, ColmapCamera>,
    mut images: Vec<ColmapImage>,
) -> Result<CameraSet, CameraError> {
    if images.is_empty() {
        return Err(CameraError::format(images_path, "images", "at least one registered image", "none"));
    }
    let mut warnings = Vec::new();
    for (id, c) in cams {
        if c.model.id > 1 {
            warnings.push(format!(
                "{}: camera {id} uses the {} model; its distortion parameters are ignored and its images are treated as undistorted pinhole images",
                cameras_path.display(),
                c.model.name
            ));
        }
    }
    images.sort_by(|a, b| a.name.cmp(&b.name).then(a.id.cmp(&b.id)));
    let mut cameras = Vec::with_capacity(images.len());
    for im in images {
        let cam = cams.get(&im.camera_id).ok_or_else(|| {
            CameraError::format(
                images_path,
                format!("image {} ({}).camera_id", im.id, im.name),
                format!("a camera id defined in {}", cameras_path.display()),
                im.camera_id.to_string(),
            )
        })?;
        let p = &cam.params;
        let (fx, fy, cx, cy) = match cam.model.focal {
            Focal::Single => (p[0], p[0], p[1], p[2]),
            Focal::Pair => (p[0], p[1], p[2], p[3]),
        };
        let [w, x, y, z] = im.qvec;
        let rotation = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize()).as_mat3();
        cameras.push(Camera {
            name: im.name,
            width: cam.width,
            height: cam.height,
            fx: fx as f32,
            fy: fy as f32,
            cx: cx as f32,
            cy: cy as f32,
            rotation,
            translation: Vec3::new(im.tvec[0] as f32, im.tvec[1] as f32, im.tvec[2] as f32),
        });
    }
    Ok(CameraSet { cameras, warnings, depth_bounds: Vec::new() })
}

// ---------------------------------------------------------------- text

fn read_text(path: &Path) -> Result<String, CameraError> {
    std::fs::read_to_string(path).map_err(|e| CameraError::io(path, e))
}

fn parse<T: std::str::FromStr>(path: &Path, record: &str, tok: Option<&str>, what: &str) -> Result<T, CameraError> {
    let tok = tok.ok_or_else(|| CameraError::format(path, record, what, "end of line"))?;
    tok.parse().map_err(|_| CameraError::format(path, record, what, format!("{tok:?}")))
}

fn read_cameras_txt(path: &Path) -> Result<BTreeMap<u32, ColmapCamera>, CameraError> {
    let text = read_text(path)?;
    let mut map = BTreeMap::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let rec = format!("line {}", n + 1);
        let mut t = line.split_whitespace();
        let id: u32 = parse(path, &format!("{rec}.CAMERA_ID"), t.next(), "an unsigned 32-bit camera id")?;
        let model_name = t.next().unwrap_or("");
        let model = MODELS.iter().find(|m| m.name == model_name).ok_or_else(|| CameraError::UnknownModel {
            path: path.to_path_buf(),
            camera_id: id.into(),
            model: model_name.into(),
            known: known_models(),
        })?;
        let width: u32 = parse(path, &format!("{rec}.WIDTH"), t.next(), "a pixel width")?;
        let height: u32 = parse(path, &format!("{rec}.HEIGHT"), t.next(), "a pixel height")?;
        let params: Vec<&str> = t.collect();
        if params.len() != model.params {
            return Err(CameraError::format(
                path,
                format!("{rec} (camera {id}).PARAMS"),
                format!("{} parameters for {}", model.params, model.name),
                params.len().to_string(),
            ));
        }
        let params = params
            .iter()
            .enumerate()
            .map(|(i, s)| parse(path, &format!("{rec} (camera {id}).PARAMS[{i}]"), Some(s), "a number"))
            .collect::<Result<Vec<f64>, _>>()?;
        insert_camera(path, &mut map, id, ColmapCamera { model, width, height, params })?;
    }
    Ok(map)
}

fn read_images_txt(path: &Path) -> Result<Vec<ColmapImage>, CameraError> {
    let text = read_text(path)?;
    let mut images = Vec::new();
    let mut lines = text.lines().enumerate();
    while let Some((n, line)) = lines.next() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let rec = format!("line {}", n + 1);
        let toks: Vec<&str> = line.split_whitespace().collect();
        if toks.len() < 10 {
            return Err(CameraError::format(
                path,
                &rec,
                "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (10 fields)",
                format!("{} fields", toks.len()),
            ));
        }
        let field = |name: &str| format!("{rec}.{name}");
        let id: u32 = parse(path, &field("IMAGE_ID"), Some(toks[0]), "an unsigned 32-bit image id")?;
        let mut q = [0.0; 4];
        for (i, v) in q.iter_mut().enumerate() {
            *v = parse(path, &field(&format!("QVEC[{i}]")), Some(toks[1 + i]), "a number")?;
        }
        let mut tv = [0.0; 3];
        for (i, v) in tv.iter_mut().enumerate() {
            *v = parse(path, &field(&format!("TVEC[{i}]")), Some(toks[5 + i]), "a number")?;
        }
        let camera_id: u32 = parse(path, &field("CAMERA_ID"), Some(toks[8]), "an unsigned 32-bit camera id")?;
        let im = ColmapImage { id, qvec: q, tvec: tv, camera_id, name: toks[9..].join(" ") };
        check_image(path, &im)?;
        images.push(im);
        // The next line lists the image's 2D points (possibly empty): skip it.
        lines.next();
    }
    Ok(images)
}
