//! Posed photographs for the fitter: cameras from any camera file the project
//! reads, the images they name, composited on the background and shrunk to
//! the working resolution.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::camera::{self, Camera, CameraError};
use crate::vision::resize::resize_area;

/// Why posed images could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum FitDataError {
    /// The camera file could not be read.
    #[error(transparent)]
    Cameras(#[from] CameraError),
    /// No image file was found for a camera.
    #[error("{dataset}: expected an image for camera {camera:?}, found none of: {tried}")]
    MissingImage {
        /// The dataset path.
        dataset: PathBuf,
        /// The camera's name.
        camera: String,
        /// The paths tried, comma-separated.
        tried: String,
    },
    /// An image could not be decoded.
    #[error("{path}: expected an image (PNG, JPEG or WebP), found: {message}")]
    Image {
        /// The image file.
        path: PathBuf,
        /// The decoder's message.
        message: String,
    },
}

/// Posed images at a working resolution.
#[derive(Clone, Debug, Default)]
pub struct PosedImages {
    /// One camera and its RGB image (`height × width × 3`, in `[0, 1]`) per view.
    pub views: Vec<(Camera, Vec<f32>)>,
    /// Per view, the image's alpha (`height × width`, in `[0, 1]`) when it
    /// has a channel that is not opaque everywhere (NeRF-synthetic's RGBA
    /// photos): the fit composites such views on a random background
    /// ([`super::FitConfig::random_background`]).
    pub alphas: Vec<Option<Vec<f32>>>,
    /// Things the camera reader had to approximate, one line each.
    pub warnings: Vec<String>,
    /// The folders the images were read from, and an LLFF dataset's other
    /// image folders (canonical, each once: [`photo_folders`]), so that no
    /// output is written among the photos.
    pub image_folders: Vec<PathBuf>,
}

/// Extensions tried when a camera's name has none (NeRF-synthetic `./train/r_0`).
const EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG", "webp"];

/// Where the image of the camera named `name` can be: in the `images` folder
/// when one is named (relative to the dataset folder, e.g. `images_4`), beside
/// the camera file (transforms.json `file_path`, LLFF's `images_8/…`), in
/// `images/` (COLMAP, the INRIA layout), with or without an added extension.
/// The first existing candidate wins.
pub fn image_candidates(dataset: &Path, images: Option<&str>, name: &str) -> Vec<PathBuf> {
    let root =
        if dataset.is_dir() { dataset.to_path_buf() } else { dataset.parent().unwrap_or(Path::new(".")).to_path_buf() };
    let mut bases: Vec<PathBuf> = images.map(|d| root.join(d)).into_iter().collect();
    bases.extend([root.clone(), root.join("images")]);
    // A COLMAP folder given directly (`…/sparse/0`): its images are two levels up.
    for up in root.ancestors().skip(1).take(2) {
        bases.push(up.join("images"));
    }
    let name = name.strip_prefix("./").unwrap_or(name);
    let mut out = Vec::new();
    for b in &bases {
        out.push(b.join(name));
        for e in EXTENSIONS {
            out.push(b.join(format!("{name}.{e}")));
        }
    }
    out
}

/// The image of the camera named `name`: the first of its
/// [`image_candidates`] that is a file.
pub fn find_image(dataset: &Path, images: Option<&str>, name: &str) -> Result<PathBuf, FitDataError> {
    let candidates = image_candidates(dataset, images, name);
    candidates.iter().find(|p| p.is_file()).cloned().ok_or_else(|| FitDataError::MissingImage {
        dataset: dataset.to_path_buf(),
        camera: name.to_string(),
        tried: candidates.iter().take(4).map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ") + ", …",
    })
}

/// The folders (canonical, each once) that hold the photos of the cameras
/// named `names` in `dataset`, for the cameras whose photo is there, and
/// every LLFF image folder (`images_8`, `images_4`, `images`: the same
/// photos at other sizes, under the same names) of an LLFF dataset: what no
/// command should write its outputs among.
pub fn photo_folders<'a>(dataset: &Path, names: impl IntoIterator<Item = &'a str>) -> Vec<PathBuf> {
    let found = (names.into_iter()).filter_map(|name| find_image(dataset, None, name).ok());
    canonical_folders(dataset, found.filter_map(|path| path.parent().map(Path::to_path_buf)))
}

/// `folders` and, for an LLFF dataset, its image folders that exist, made
/// canonical, sorted and each kept once.
fn canonical_folders(dataset: &Path, folders: impl Iterator<Item = PathBuf>) -> Vec<PathBuf> {
    let root = if dataset.is_dir() { dataset } else { dataset.parent().unwrap_or(Path::new(".")) };
    let llff: Vec<PathBuf> = if root.join(camera::POSES_BOUNDS).is_file() {
        camera::LLFF_IMAGE_FOLDERS.iter().map(|f| root.join(f)).collect()
    } else {
        Vec::new()
    };
    let mut folders: Vec<PathBuf> = folders.chain(llff).filter_map(|d| std::fs::canonicalize(d).ok()).collect();
    folders.sort();
    folders.dedup();
    folders
}

/// Reads an image as RGB in `[0, 1]`, compositing any alpha channel on `background`.
pub fn read_rgb(path: &Path, background: [f32; 3]) -> Result<(u32, u32, Vec<f32>), FitDataError> {
    read_rgba(path, background).map(|(w, h, rgb, _)| (w, h, rgb))
}

/// An image's width, height, RGB composited on a background, and its alpha
/// when some pixel is not opaque.
type Composited = (u32, u32, Vec<f32>, Option<Vec<f32>>);

/// [`read_rgb`], and the image's alpha when some pixel is not opaque.
fn read_rgba(path: &Path, background: [f32; 3]) -> Result<Composited, FitDataError> {
    let img =
        crate::io::open_image(path).map_err(|message| FitDataError::Image { path: path.to_path_buf(), message })?;
    let rgba = img.to_rgba32f();
    let (w, h) = rgba.dimensions();
    let mut rgb = Vec::with_capacity(w as usize * h as usize * 3);
    let mut alpha = Vec::with_capacity(w as usize * h as usize);
    for px in rgba.pixels() {
        let a = px.0[3].clamp(0.0, 1.0);
        for (&v, &b) in px.0[..3].iter().zip(&background) {
            rgb.push(v.clamp(0.0, 1.0) * a + b * (1.0 - a));
        }
        alpha.push(a);
    }
    let see_through = alpha.iter().any(|&a| a < 1.0);
    Ok((w, h, rgb, see_through.then_some(alpha)))
}

/// Loads the cameras of `dataset` (any source [`camera::load`] reads) and
/// their images, looked for first in the folder `images` when it is named
/// (which also picks an LLFF dataset's images folder, see
/// [`camera::load_with_images`]), keeping `max_views` of them evenly spread (all when 0),
/// composited on `background` and area-resized so the longer side is at most
/// `resolution` pixels. A camera whose image has another size than the camera
/// file says is rescaled to the image first.
pub fn load_posed_images(
    dataset: &Path,
    images: Option<&str>,
    resolution: u32,
    max_views: usize,
    background: [f32; 3],
) -> Result<PosedImages, FitDataError> {
    let set = camera::load_with_images(dataset, images)?;
    let n = set.cameras.len();
    let keep: Vec<usize> = if max_views == 0 || max_views >= n {
        (0..n).collect()
    } else {
        (0..max_views).map(|i| i * n / max_views).collect()
    };
    let views = keep
        .par_iter()
        .map(|&i| {
            let cam = &set.cameras[i];
            let path = find_image(dataset, images, &cam.name)?;
            let (w, h, rgb, alpha) = read_rgba(&path, background)?;
            let folder = path.parent().map(Path::to_path_buf);
            let stretched = stretch_warning(&path, cam, w, h);
            let full = if (w, h) == (cam.width, cam.height) { cam.clone() } else { cam.scaled_to(w, h) };
            let work = full.downscaled_to_max_side(resolution.max(1));
            let resize = |v: Vec<f32>, channels: usize| {
                if (work.width, work.height) == (w, h) {
                    v
                } else {
                    resize_area(&v, h as usize, w as usize, channels, work.height as usize, work.width as usize)
                }
            };
            let (img, alpha) = (resize(rgb, 3), alpha.map(|a| resize(a, 1)));
            Ok(((work, img), alpha, folder, stretched))
        })
        .collect::<Result<Vec<_>, FitDataError>>()?;
    let image_folders = canonical_folders(dataset, views.iter().filter_map(|(_, _, f, _)| f.clone()));
    let mut warnings = set.warnings;
    let stretched: Vec<String> = views.iter().filter_map(|(_, _, _, s)| s.clone()).collect();
    if let Some(first) = stretched.first() {
        let more = stretched.len() - 1;
        warnings.push(if more == 0 { first.clone() } else { format!("{first}; and {more} more image(s) like it") });
    }
    let (views, alphas) = views.into_iter().map(|(v, a, _, _)| (v, a)).unzip();
    Ok(PosedImages { views, alphas, warnings, image_folders })
}

/// A warning when the image at `path` (`w × h`) has another shape than its
/// camera says, by more than 1 % in aspect: rescaling the camera to it then
/// stretches its focal lengths unequally, right only if the image itself was
/// stretched, and usually a sign of a cropped or wrong image. Another size
/// of the same shape (a downscaled images folder) is the normal case.
fn stretch_warning(path: &Path, cam: &Camera, w: u32, h: u32) -> Option<String> {
    let (sx, sy) = (f64::from(w) / f64::from(cam.width), f64::from(h) / f64::from(cam.height));
    ((sx / sy - 1.0).abs() > 0.01).then(|| {
        format!(
            "{}: expected an image of its camera's shape ({}x{}, {}), found {w}x{h}: the camera is stretched to it \
             (width ×{sx:.3}, height ×{sy:.3}), right only if the image was stretched too",
            path.display(),
            cam.width,
            cam.height,
            cam.name
        )
    })
}
