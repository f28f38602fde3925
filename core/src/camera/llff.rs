//! LLFF `poses_bounds.npy` (Mildenhall et al. 2019), the pose file of the
//! forward-facing scenes NeRF and 3DGS evaluate on (fern, flower, …), read as
//! it is so those datasets need no conversion.
//!
//! The file is a float64 array of shape `(N, 17)`, one row per image. A row is
//! a 3×5 matrix stored row-major, then the near and far depth bounds. The
//! matrix is `[R | t | hwf]`: columns 0–2 are the camera-to-world rotation
//! with its columns in LLFF's order (down, right, backwards), column 3 is the
//! camera centre and column 4 is (height, width, focal) of the full-resolution
//! photos. As NeRF's `load_llff.py` does, the rotation is first put in OpenGL
//! order (right, up, back) = `[col1, −col0, col2]`, then converted like a
//! `transforms.json` pose.
//!
//! The file names no images: row `i` belongs to the `i`-th image (sorted by
//! file name) of the images folder, `images_8`, `images_4` or `images` (the
//! release's downscales by 8 and 4, and the full photos). The first of those
//! that exists is used unless the caller names one. The cameras take the size
//! of their image file, and the focal scales with it (÷8 for `images_8`).

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};

use super::transforms::from_opengl;
use super::{Camera, CameraError, CameraSet, ORTHONORMAL_TOLERANCE, npy, orthonormal_warning, rotation_from};

/// The images folders tried, in order, when none is named: the smallest first,
/// since the studio works at a few hundred pixels.
pub const LLFF_IMAGE_FOLDERS: [&str; 3] = ["images_8", "images_4", "images"];

/// The pose file's name in an LLFF dataset folder.
pub const POSES_BOUNDS: &str = "poses_bounds.npy";

/// Extensions of the image files a folder's listing keeps (case-insensitive).
const IMAGE_EXTENSIONS: [&str; 4] = ["png", "jpg", "jpeg", "webp"];

/// Reads an LLFF dataset: `path` is its folder or its `poses_bounds.npy`.
/// `images` names the images folder relative to the dataset folder (e.g.
/// `images_4`); `None` picks the first of [`LLFF_IMAGE_FOLDERS`] that exists.
/// Cameras are named by their image's path relative to the dataset folder
/// (`images_8/image000.png`), in row order; [`CameraSet::depth_bounds`] holds
/// each row's near and far.
pub fn load_llff(path: impl AsRef<Path>, images: Option<&str>) -> Result<CameraSet, CameraError> {
    let path = path.as_ref();
    let npy_path = if path.is_dir() { path.join(POSES_BOUNDS) } else { path.to_path_buf() };
    let root = npy_path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let (rows, values) = npy::read_f64_matrix(&npy_path, 17)?;
    let folder = images_folder(&root, images)?;
    let files = image_files(&folder)?;
    if files.len() != rows {
        return Err(CameraError::format(
            &folder,
            "image files",
            format!("{rows} images (.png/.jpg/.jpeg/.webp), one per row of {}", npy_path.display()),
            files.len().to_string(),
        ));
    }

    let (mut corrected, mut worst, mut mismatched) = (0, 0.0f64, 0);
    let mut cameras = Vec::with_capacity(rows);
    let mut depth_bounds = Vec::with_capacity(rows);
    for (i, (row, file)) in values.chunks_exact(17).zip(&files).enumerate() {
        let record = format!("row {i}");
        if let Some(v) = row.iter().find(|v| !v.is_finite()) {
            return Err(CameraError::format(&npy_path, &record, "finite numbers", v.to_string()));
        }
        let col = |j: usize| DVec3::new(row[j], row[5 + j], row[10 + j]);
        let [full_h, full_w, focal] = col(4).to_array();
        if !(full_h >= 1.0 && full_w >= 1.0 && focal > 0.0) {
            return Err(CameraError::format(
                &npy_path,
                format!("{record}.hwf"),
                "a positive height, width and focal length",
                format!("{full_h}, {full_w}, {focal}"),
            ));
        }
        let (width, height) = image::image_dimensions(file).map_err(|e| {
            CameraError::format(file, "image header", "a readable PNG, JPEG or WebP header", e.to_string())
        })?;
        let (sx, sy) = (f64::from(width) / full_w, f64::from(height) / full_h);
        if (sx / sy - 1.0).abs() > 0.01 {
            mismatched += 1;
        }
        let c2w_gl = DMat3::from_cols(col(1), -col(0), col(2));
        let (c2w, dev) = rotation_from(&npy_path, &format!("{record}.rotation"), from_opengl(c2w_gl))?;
        if dev > ORTHONORMAL_TOLERANCE {
            corrected += 1;
            worst = worst.max(dev);
        }
        let name = file.strip_prefix(&root).unwrap_or(file).to_string_lossy().replace('\\', "/");
        cameras.push(Camera::from_camera_to_world(
            name,
            width,
            height,
            (focal * sx) as f32,
            (focal * sy) as f32,
            0.5 * width as f32,
            0.5 * height as f32,
            c2w,
            col(3).as_vec3(),
        ));
        depth_bounds.push([row[15] as f32, row[16] as f32]);
    }
    let mut warnings: Vec<String> = orthonormal_warning(&npy_path, corrected, worst).into_iter().collect();
    if mismatched > 0 {
        warnings.push(format!(
            "{}: {mismatched} image(s) in {} have another aspect ratio than the poses' height and width; the focal is scaled per axis",
            npy_path.display(),
            folder.display()
        ));
    }
    Ok(CameraSet { cameras, warnings, depth_bounds })
}

/// The images folder: the one named, or the first of [`LLFF_IMAGE_FOLDERS`].
fn images_folder(root: &Path, images: Option<&str>) -> Result<PathBuf, CameraError> {
    match images {
        Some(name) => {
            let dir = root.join(name);
            if dir.is_dir() {
                Ok(dir)
            } else {
                Err(CameraError::NoFolder { path: dir, expected: "the images folder asked for".into() })
            }
        }
        None => {
            LLFF_IMAGE_FOLDERS.iter().map(|n| root.join(n)).find(|d| d.is_dir()).ok_or_else(|| CameraError::NotFound {
                path: root.to_path_buf(),
                expected: format!("an images folder beside {POSES_BOUNDS} ({})", LLFF_IMAGE_FOLDERS.join(", ")),
            })
        }
    }
}

/// The image files of a folder, sorted by name (as `load_llff.py` does).
fn image_files(dir: &Path) -> Result<Vec<PathBuf>, CameraError> {
    let entries = std::fs::read_dir(dir).map_err(|e| CameraError::io(dir, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let p = entry.map_err(|e| CameraError::io(dir, e))?.path();
        let is_image = p
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        if is_image && p.is_file() {
            files.push(p);
        }
    }
    files.sort();
    Ok(files)
}
