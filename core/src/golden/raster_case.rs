//! The inputs of a golden rasterizer file (`golden/raster_*.safetensors` of the
//! shared data) as the studio's types. [`crate::golden`] runs the rasterizer
//! on this case and compares every output.

use glam::{Mat3, Vec3};

use super::file::{GoldenError, GoldenFile};
use crate::camera::Camera;
use crate::raster::RenderOptions;
use crate::scene::Gaussians;

/// One golden rasterizer case: the scene, camera, background and the
/// cotangents that define the gradients' loss `Σ rgb·c_rgb + Σ inv_depth·c_d`.
#[derive(Clone, Debug)]
pub struct GoldenRasterCase {
    /// The Gaussians (f64 inputs rounded to f32).
    pub gaussians: Gaussians,
    /// The camera.
    pub camera: Camera,
    /// The background.
    pub options: RenderOptions,
    /// Cotangent of the RGB image, `H·W·3`.
    pub cotangent_rgb: Vec<f32>,
    /// Cotangent of the inverse depth, `H·W`.
    pub cotangent_inv_depth: Vec<f32>,
}

/// Converts the inputs of a raster golden file, checking every shape.
pub fn raster_case(file: &GoldenFile) -> Result<GoldenRasterCase, GoldenError> {
    let format = |what: &str, expected: String, found: String| GoldenError::Format {
        path: file.path.clone(),
        what: what.into(),
        expected,
        found,
    };
    let n = *file.get("means")?.shape.first().ok_or_else(|| format("tensor means", "(N, 3)".into(), "()".into()))?;
    let sh = file.get("sh")?;
    let k = sh.shape.get(1).copied().unwrap_or(0);
    let sh_degree = match k {
        1 => 0,
        4 => 1,
        9 => 2,
        16 => 3,
        _ => return Err(format("tensor sh", "shape (N, 1|4|9|16, 3)".into(), format!("{:?}", sh.shape))),
    };
    let size = file.get_shaped("image_size", &[2])?.data.clone();
    let (h, w) = (size[0] as usize, size[1] as usize);
    let intr = &file.get_shaped("intrinsics", &[4])?.data;
    let r = &file.get_shaped("world_to_cam_R", &[3, 3])?.data;
    let t = &file.get_shaped("world_to_cam_t", &[3])?.data;
    let bg = &file.get_shaped("background", &[3])?.data;
    let rows = |name: &str, width: usize| -> Result<Vec<f32>, GoldenError> {
        Ok(file.get_shaped(name, &[n, width])?.to_f32())
    };
    let gaussians = Gaussians {
        means: rows("means", 3)?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        log_scales: rows("log_scales", 3)?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        quats: rows("quats", 4)?.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect(),
        opacity_logits: file.get_shaped("opacity_logits", &[n])?.to_f32(),
        sh_degree,
        sh: file.get_shaped("sh", &[n, k, 3])?.to_f32(),
    };
    let camera = Camera {
        name: file.path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        width: w as u32,
        height: h as u32,
        fx: intr[0] as f32,
        fy: intr[1] as f32,
        cx: intr[2] as f32,
        cy: intr[3] as f32,
        // The file's R is row-major; glam's arrays are column-major.
        rotation: Mat3::from_cols_array(&std::array::from_fn(|i| r[i] as f32)).transpose(),
        translation: Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32),
    };
    Ok(GoldenRasterCase {
        gaussians,
        camera,
        options: RenderOptions { background: [bg[0] as f32, bg[1] as f32, bg[2] as f32] },
        cotangent_rgb: file.get_shaped("cotangent_rgb", &[h, w, 3])?.to_f32(),
        cotangent_inv_depth: file.get_shaped("cotangent_inv_depth", &[h, w])?.to_f32(),
    })
}
