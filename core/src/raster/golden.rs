//! The golden rasterizer cases (`golden/raster_deg*_seed*.safetensors` of the
//! shared data): loading them into the studio's types and comparing the
//! rasterizer against them.
//!
//! Shared by the integration test and the `gast check golden` command so that
//! both apply the same conversion and the same tolerances.

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Mat3, Vec3};
use safetensors::{Dtype, SafeTensors};

use super::{RenderOptions, backward, dense, forward};
use crate::camera::Camera;
use crate::scene::Gaussians;

/// Largest absolute error allowed on the images (`out_*`, fast and dense).
pub const IMAGE_TOL: f64 = 1e-5;
/// Largest absolute error allowed on a gradient, relative to the largest
/// magnitude in that reference tensor.
pub const GRAD_REL_TOL: f64 = 1e-3;

/// One golden case: the inputs in the studio's types, the cotangents that
/// define the loss, and the reference outputs.
#[derive(Clone, Debug)]
pub struct GoldenRasterCase {
    /// The Gaussians (`means`, `log_scales`, `quats`, `opacity_logits`, `sh`).
    pub gaussians: Gaussians,
    /// The camera (`world_to_cam_R`, `world_to_cam_t`, `intrinsics`, `image_size`).
    pub camera: Camera,
    /// The options (`background`).
    pub options: RenderOptions,
    /// `cotangent_rgb`, `H·W·3`: the loss is `Σ rgb·cot_rgb + Σ inv_depth·cot_inv_depth`.
    pub cotangent_rgb: Vec<f32>,
    /// `cotangent_inv_depth`, `H·W`.
    pub cotangent_inv_depth: Vec<f32>,
    /// Reference outputs by tensor name (`out_rgb`, `out_inv_depth`,
    /// `out_alpha`, `grad_means`, `grad_log_scales`, `grad_quats`,
    /// `grad_opacity_logits`, `grad_sh`), flattened row-major in the layouts of
    /// [`super::Render`] and [`super::Grads`].
    pub expected: BTreeMap<String, Vec<f64>>,
}

/// How one output compares with its reference.
#[derive(Clone, Debug, PartialEq)]
pub struct GoldenComparison {
    /// Which output: a reference tensor name, prefixed `dense_` for the dense renderer.
    pub name: String,
    /// Largest absolute difference.
    pub max_abs_err: f64,
    /// Largest absolute value in the reference.
    pub ref_max_abs: f64,
    /// The error allowed.
    pub tolerance: f64,
}

impl GoldenComparison {
    /// Whether the error is within tolerance.
    pub fn passed(&self) -> bool {
        self.max_abs_err <= self.tolerance
    }
}

fn tensor(st: &SafeTensors, path: &Path, name: &str, want: Option<&[usize]>) -> Result<Vec<f64>, String> {
    let t = st.tensor(name).map_err(|e| format!("{}: tensor {name}: {e}", path.display()))?;
    if t.dtype() != Dtype::F64 {
        return Err(format!("{}: tensor {name}: expected F64, found {:?}", path.display(), t.dtype()));
    }
    if let Some(w) = want
        && t.shape() != w
    {
        return Err(format!("{}: tensor {name}: expected shape {w:?}, found {:?}", path.display(), t.shape()));
    }
    Ok(t.data().chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).collect())
}

fn shape_of(st: &SafeTensors, path: &Path, name: &str) -> Result<Vec<usize>, String> {
    Ok(st.tensor(name).map_err(|e| format!("{}: tensor {name}: {e}", path.display()))?.shape().to_vec())
}

fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

fn triples<const K: usize>(v: &[f64]) -> Vec<[f32; K]> {
    v.chunks_exact(K).map(|c| std::array::from_fn(|k| c[k] as f32)).collect()
}

/// Loads a golden rasterizer case.
///
/// # Errors
/// A message naming the file and the tensor when the file cannot be read, a
/// tensor is missing, or a dtype or shape is not what the format says.
pub fn load_case(path: impl AsRef<Path>) -> Result<GoldenRasterCase, String> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let st = SafeTensors::deserialize(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    let mshape = shape_of(&st, path, "means")?;
    let n = *mshape.first().ok_or_else(|| format!("{}: means has no dimensions", path.display()))?;
    let sh_shape = shape_of(&st, path, "sh")?;
    let k = sh_shape.get(1).copied().unwrap_or(0);
    let deg = match k {
        1 => 0,
        4 => 1,
        9 => 2,
        16 => 3,
        _ => return Err(format!("{}: tensor sh: expected (N, 1|4|9|16, 3), found {sh_shape:?}", path.display())),
    };
    let size = tensor(&st, path, "image_size", Some(&[2]))?;
    let (h, w) = (size[0] as usize, size[1] as usize);
    let intr = tensor(&st, path, "intrinsics", Some(&[4]))?;
    let r = tensor(&st, path, "world_to_cam_R", Some(&[3, 3]))?;
    let t = tensor(&st, path, "world_to_cam_t", Some(&[3]))?;
    let bg = tensor(&st, path, "background", Some(&[3]))?;

    let gaussians = Gaussians {
        means: triples(&tensor(&st, path, "means", Some(&[n, 3]))?),
        log_scales: triples(&tensor(&st, path, "log_scales", Some(&[n, 3]))?),
        quats: triples(&tensor(&st, path, "quats", Some(&[n, 4]))?),
        opacity_logits: f32s(&tensor(&st, path, "opacity_logits", Some(&[n]))?),
        sh_degree: deg,
        sh: f32s(&tensor(&st, path, "sh", Some(&[n, k, 3]))?),
    };
    let camera = Camera {
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        width: w as u32,
        height: h as u32,
        fx: intr[0] as f32,
        fy: intr[1] as f32,
        cx: intr[2] as f32,
        cy: intr[3] as f32,
        // The file is row-major; glam is column-major.
        rotation: Mat3::from_cols_array(&std::array::from_fn(|i| r[i] as f32)).transpose(),
        translation: Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32),
    };
    let options = RenderOptions { background: [bg[0] as f32, bg[1] as f32, bg[2] as f32] };
    let cotangent_rgb = f32s(&tensor(&st, path, "cotangent_rgb", Some(&[h, w, 3]))?);
    let cotangent_inv_depth = f32s(&tensor(&st, path, "cotangent_inv_depth", Some(&[h, w]))?);

    let mut expected = BTreeMap::new();
    let shapes: [(&str, Vec<usize>); 8] = [
        ("out_rgb", vec![h, w, 3]),
        ("out_inv_depth", vec![h, w]),
        ("out_alpha", vec![h, w]),
        ("grad_means", vec![n, 3]),
        ("grad_log_scales", vec![n, 3]),
        ("grad_quats", vec![n, 4]),
        ("grad_opacity_logits", vec![n]),
        ("grad_sh", vec![n, k, 3]),
    ];
    for (name, shape) in shapes {
        expected.insert(name.to_string(), tensor(&st, path, name, Some(&shape))?);
    }
    Ok(GoldenRasterCase { gaussians, camera, options, cotangent_rgb, cotangent_inv_depth, expected })
}

impl GoldenRasterCase {
    /// Runs the fast forward and backward passes and the dense renderer, and
    /// compares every output with its reference: images within [`IMAGE_TOL`],
    /// gradients within [`GRAD_REL_TOL`] of the tensor's largest magnitude.
    pub fn compare(&self) -> Vec<GoldenComparison> {
        let (g, cam, opts) = (&self.gaussians, &self.camera, &self.options);
        let (img, state) = forward(g, cam, opts);
        let grads = backward(g, cam, opts, &state, &self.cotangent_rgb, &self.cotangent_inv_depth);
        let dense = dense::render(g, cam, opts);
        let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let flat4 = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let ours: [(&str, &str, Vec<f32>); 11] = [
            ("out_rgb", "out_rgb", img.rgb),
            ("out_inv_depth", "out_inv_depth", img.inv_depth),
            ("out_alpha", "out_alpha", img.alpha),
            ("dense_out_rgb", "out_rgb", dense.rgb),
            ("dense_out_inv_depth", "out_inv_depth", dense.inv_depth),
            ("dense_out_alpha", "out_alpha", dense.alpha),
            ("grad_means", "grad_means", flat3(&grads.v_means)),
            ("grad_log_scales", "grad_log_scales", flat3(&grads.v_log_scales)),
            ("grad_quats", "grad_quats", flat4(&grads.v_quats)),
            ("grad_opacity_logits", "grad_opacity_logits", grads.v_opacity_logits),
            ("grad_sh", "grad_sh", grads.v_sh),
        ];
        ours.into_iter()
            .map(|(name, reference, ours)| {
                let want = &self.expected[reference];
                let ref_max_abs = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                let max_abs_err = if ours.len() == want.len() {
                    ours.iter().zip(want).fold(0.0f64, |m, (&a, &b)| {
                        let d = (f64::from(a) - b).abs();
                        if d.is_nan() { f64::INFINITY } else { m.max(d) }
                    })
                } else {
                    f64::INFINITY
                };
                let tolerance = if reference.starts_with("grad_") { GRAD_REL_TOL * ref_max_abs } else { IMAGE_TOL };
                GoldenComparison { name: name.to_string(), max_abs_err, ref_max_abs, tolerance }
            })
            .collect()
    }
}
