//! Checking the project's numerics against independent reference files.
//!
//! The golden files (safetensors, every tensor float64) hold the inputs of a
//! computation and its expected outputs. [`check_file`] recognises the kind of
//! file from its tensor names, runs the project's own code on the inputs and
//! compares every output it can, with the tolerances of the issue tracker:
//! images to an absolute error, gradients relative to the tensor's largest
//! magnitude, loss values relative to their own magnitude, matches exactly.
//! The tests and `gast check golden` share this one implementation.

use std::path::{Path, PathBuf};

mod file;
mod raster_case;

pub use file::{GoldenError, GoldenFile, GoldenKind, Tensor};
pub use raster_case::{GoldenRasterCase, raster_case};

/// How an output is judged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// Worst absolute error at most this.
    Abs(f64),
    /// Worst absolute error at most this times the largest reference magnitude.
    RelToMax(f64),
    /// Every value must be equal.
    Exact,
}

impl std::fmt::Display for Tolerance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Tolerance::Abs(t) => write!(f, "abs < {t:e}"),
            Tolerance::RelToMax(t) => write!(f, "rel < {t:e}"),
            Tolerance::Exact => write!(f, "exact"),
        }
    }
}

/// The comparison of one output with its reference.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputCheck {
    /// Output name (the reference tensor's name).
    pub name: String,
    /// Worst absolute error.
    pub max_abs: f64,
    /// Largest reference magnitude.
    pub max_ref: f64,
    /// `max_abs / max_ref` (the error relative to the largest magnitude).
    pub rel: f64,
    /// How it is judged.
    pub tolerance: Tolerance,
    /// Whether it is within the tolerance.
    pub passed: bool,
}

/// Compares `actual` with the reference tensor `expected` (same number of values).
pub fn compare(name: &str, actual: &[f64], expected: &Tensor, tolerance: Tolerance) -> OutputCheck {
    let mut max_abs = 0.0f64;
    let mut any_nan = actual.len() != expected.data.len();
    for (a, e) in actual.iter().zip(&expected.data) {
        let d = (a - e).abs();
        if d.is_nan() {
            any_nan = true;
        }
        max_abs = max_abs.max(d);
    }
    if any_nan {
        max_abs = f64::INFINITY;
    }
    let max_ref = expected.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let rel = if max_ref > 0.0 { max_abs / max_ref } else { max_abs };
    let passed = match tolerance {
        Tolerance::Abs(t) => max_abs < t,
        Tolerance::RelToMax(t) => rel <= t,
        Tolerance::Exact => max_abs == 0.0,
    };
    OutputCheck { name: name.to_string(), max_abs, max_ref, rel, tolerance, passed }
}

/// Widens f32 results for [`compare`].
pub fn widen(values: &[f32]) -> Vec<f64> {
    values.iter().map(|&v| v as f64).collect()
}

/// What checking a file may need besides the file itself.
#[derive(Clone, Debug, Default)]
pub struct CheckContext {
    /// VGG weights for the `losses_*` files (else the usual resolution: `$GAST_WEIGHTS`,
    /// the caches, a download).
    pub weights: Option<PathBuf>,
    /// Run the rasterizer, the losses and the depth network on this GPU
    /// (`--device gpu`) instead of the CPU; the colour transfer runs on the
    /// CPU either way.
    pub gpu: Option<crate::gpu::GpuContext>,
    /// How VGG computes its convolutions for the `losses_*` files.
    pub conv: crate::vision::ConvAlgo,
}

/// Reads a golden file, runs the project's code on its inputs and compares every output.
pub fn check_file(path: &Path, ctx: &CheckContext) -> Result<Vec<OutputCheck>, GoldenError> {
    let file = GoldenFile::read(path)?;
    match file.kind() {
        Some(GoldenKind::Raster) => check_raster(&file, ctx.gpu.as_ref()),
        Some(GoldenKind::Losses) => check_losses(&file, ctx),
        Some(GoldenKind::Color) => check_color(&file),
        Some(GoldenKind::Depth) => check_depth(&file, ctx.gpu.as_ref()),
        None => Err(GoldenError::Format {
            path: path.to_path_buf(),
            what: "tensor names".into(),
            expected:
                "a raster (out_rgb, means, …), losses (gcfm_loss, …), colour (content_pixels, A, …) or depth (input_pixel_values, out_predicted_depth) golden file"
                    .into(),
            found: file.tensors.keys().cloned().collect::<Vec<_>>().join(", "),
        }),
    }
}

/// Loss values: within 1e-4 of their own magnitude.
const LOSS_TOL: Tolerance = Tolerance::RelToMax(1e-4);
/// Gradients: within 1e-3 of the tensor's largest magnitude.
const GRAD_TOL: Tolerance = Tolerance::RelToMax(1e-3);

/// The depth network's output: within 1e-4 of its largest magnitude.
const DEPTH_TOL: Tolerance = Tolerance::RelToMax(1e-4);

/// Builds the network from the file's own weights and config metadata and
/// runs it on `input_pixel_values`, on `gpu` when one is given.
fn check_depth(file: &GoldenFile, gpu: Option<&crate::gpu::GpuContext>) -> Result<Vec<OutputCheck>, GoldenError> {
    let model = crate::vision::depth::DepthAnything::load_with_metadata_config(&file.path)
        .map_err(|e| GoldenError::Run { path: file.path.clone(), message: e.to_string() })?;
    let x = file.get("input_pixel_values")?;
    let (h, w) = match x.shape[..] {
        [1, 3, h, w] => (h, w),
        _ => {
            return Err(GoldenError::Format {
                path: file.path.clone(),
                what: "tensor input_pixel_values".into(),
                expected: "shape [1, 3, H, W]".into(),
                found: format!("shape {:?}", x.shape),
            });
        }
    };
    let p = model.config().patch_size;
    if !h.is_multiple_of(p) || !w.is_multiple_of(p) {
        return Err(GoldenError::Format {
            path: file.path.clone(),
            what: "tensor input_pixel_values".into(),
            expected: format!("sides that are multiples of the patch size {p}"),
            found: format!("{h}×{w}"),
        });
    }
    let expected = file.get_shaped("out_predicted_depth", &[1, h, w])?;
    let out = match gpu {
        Some(c) => crate::gpu::GpuDepthNet::new(c, model)
            .forward(c, &x.to_f32(), h, w)
            .map_err(|e| GoldenError::Run { path: file.path.clone(), message: e.to_string() })?,
        None => model.forward(&x.to_f32(), h, w),
    };
    Ok(vec![compare("out_predicted_depth", &widen(&out), expected, DEPTH_TOL)])
}

fn check_losses(file: &GoldenFile, ctx: &CheckContext) -> Result<Vec<OutputCheck>, GoldenError> {
    use crate::style::config::LossWeights;
    use crate::style::step::{RenderedMaps, StyleTargets, content_target, step_loss};
    use crate::vision::Vgg;

    let run_err = |message: String| GoldenError::Run { path: file.path.clone(), message };
    let input = |name: &str| file.get(name);
    let rgb_t = input("render_rgb")?;
    let [h, w, 3] = rgb_t.shape[..] else {
        return Err(GoldenError::Format {
            path: file.path.clone(),
            what: "tensor render_rgb".into(),
            expected: "shape (H, W, 3)".into(),
            found: format!("{:?}", rgb_t.shape),
        });
    };
    let style_t = input("style_rgb")?;
    let [hs, ws, 3] = style_t.shape[..] else {
        return Err(GoldenError::Format {
            path: file.path.clone(),
            what: "tensor style_rgb".into(),
            expected: "shape (h, w, 3)".into(),
            found: format!("{:?}", style_t.shape),
        });
    };
    let weights_path = crate::vision::download::resolve_weights(ctx.weights.as_deref(), &mut |_, _| {})
        .map_err(|e| run_err(format!("VGG weights: {e}")))?;
    let vgg = Vgg::load(&weights_path).map_err(|e| run_err(format!("VGG weights: {e}")))?.with_conv(ctx.conv);

    let rgb = rgb_t.to_f32();
    let mut checks = Vec::new();
    let gpu = ctx.gpu.as_ref().map(|c| (c, crate::gpu::StepLossKernels::new(c, &vgg)));
    if let Ok(want) = file.get("vgg_relu3_of_render_rgb") {
        let f = match ctx.gpu.as_ref() {
            Some(c) => {
                use crate::style::step::FeatureNet as _;
                crate::gpu::GpuFeatureNet::new(c.clone(), &vgg).features(&rgb, h, w).data
            }
            None => vgg.features(&rgb, h, w).data,
        };
        checks.push(compare("vgg_relu3_of_render_rgb", &widen(&f), want, Tolerance::RelToMax(1e-4)));
    }
    let style = StyleTargets::new(
        &vgg,
        &style_t.to_f32(),
        &input("style_depth")?.to_f32(),
        &input("style_edge")?.to_f32(),
        hs,
        ws,
    );
    let inv_depth = input("render_inv_depth")?.to_f32();
    let edge = input("render_edge")?.to_f32();
    let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
    let none = LossWeights { gcfm: 0.0, content: 0.0, tv: 0.0, depth: 0.0, ..LossWeights::default() };
    let content_rgb = input("content_rgb")?.to_f32();
    let content = content_target(&vgg, &content_rgb, h, w);
    // The whole per-step loss on the chosen device, with or without the content target.
    let run = |with_content: bool, weights: LossWeights, depth_grad: bool| match &gpu {
        Some((c, k)) => {
            let content = with_content.then_some(content_rgb.as_slice());
            crate::gpu::step_loss_gpu(c, k, &style, maps, content, None, &weights, depth_grad, None)
                .map_err(|e| run_err(format!("GPU: {e}")))
        }
        None => Ok(step_loss(&vgg, &style, maps, with_content.then_some(&content), None, &weights, depth_grad)),
    };

    let g = run(false, LossWeights { gcfm: 1.0, ..none }, true)?;
    checks.push(compare("gcfm_loss", &[f64::from(g.terms.gcfm)], file.get("gcfm_loss")?, LOSS_TOL));
    checks.push(compare("grad_gcfm_rgb", &widen(&g.v_rgb), file.get("grad_gcfm_rgb")?, GRAD_TOL));
    checks.push(compare("grad_gcfm_inv_depth", &widen(&g.v_inv_depth), file.get("grad_gcfm_inv_depth")?, GRAD_TOL));
    let as_f64 = |v: &[u32]| v.iter().map(|&i| f64::from(i)).collect::<Vec<_>>();
    checks.push(compare("match_best", &as_f64(&g.matches.best), file.get("match_best")?, Tolerance::Exact));
    checks.push(compare("match_worst", &as_f64(&g.matches.worst), file.get("match_worst")?, Tolerance::Exact));

    let c = run(true, LossWeights { content: 1.0, ..none }, false)?;
    checks.push(compare("content_loss", &[f64::from(c.terms.content)], file.get("content_loss")?, LOSS_TOL));
    checks.push(compare("grad_content_rgb", &widen(&c.v_rgb), file.get("grad_content_rgb")?, GRAD_TOL));

    let t = run(false, LossWeights { tv: 1.0, ..none }, false)?;
    checks.push(compare("tv_loss", &[f64::from(t.terms.tv)], file.get("tv_loss")?, LOSS_TOL));
    // With every other weight zero, `v_rgb` is exactly ∂TV/∂rgb.
    checks.push(compare("grad_tv_rgb", &widen(&t.v_rgb), file.get("grad_tv_rgb")?, GRAD_TOL));
    Ok(checks)
}

fn check_color(file: &GoldenFile) -> Result<Vec<OutputCheck>, GoldenError> {
    use crate::style::color_transfer::ColorTransfer;
    let content = file.get("content_pixels")?.to_f32();
    let style = file.get("style_pixels")?.to_f32();
    let t = ColorTransfer::fit(&content, &style);
    let a: Vec<f64> = t.a.iter().flatten().map(|&v| f64::from(v)).collect();
    let b: Vec<f64> = t.b.iter().map(|&v| f64::from(v)).collect();
    Ok(vec![
        compare("A", &a, file.get_shaped("A", &[3, 3])?, Tolerance::Abs(1e-4)),
        compare("b", &b, file.get_shaped("b", &[3])?, Tolerance::Abs(1e-4)),
    ])
}

fn check_raster(file: &GoldenFile, gpu: Option<&crate::gpu::GpuContext>) -> Result<Vec<OutputCheck>, GoldenError> {
    use crate::raster::{backward, dense, forward};
    let case = raster_case(file)?;
    let (g, cam, opts) = (&case.gaussians, &case.camera, &case.options);
    let (v_rgb, v_inv_depth) = (&case.cotangent_rgb, &case.cotangent_inv_depth);
    let (img, grads) = match gpu {
        Some(c) => {
            let k = crate::gpu::RasterKernels::new(c);
            crate::gpu::render_and_backward_gpu(c, &k, g, cam, opts, v_rgb, v_inv_depth)
                .map_err(|e| GoldenError::Run { path: file.path.clone(), message: format!("GPU: {e}") })?
        }
        None => {
            let (img, state) = forward(g, cam, opts);
            let grads = backward(g, cam, opts, &state, v_rgb, v_inv_depth);
            (img, grads)
        }
    };
    let reference = dense::render(g, cam, opts);
    // Images to an absolute error, gradients relative to their largest magnitude.
    const IMAGE_TOL: Tolerance = Tolerance::Abs(1e-5);
    let ours: [(&str, &str, Vec<f32>, Tolerance); 11] = [
        ("out_rgb", "out_rgb", img.rgb, IMAGE_TOL),
        ("out_inv_depth", "out_inv_depth", img.inv_depth, IMAGE_TOL),
        ("out_alpha", "out_alpha", img.alpha, IMAGE_TOL),
        ("dense_out_rgb", "out_rgb", reference.rgb, IMAGE_TOL),
        ("dense_out_inv_depth", "out_inv_depth", reference.inv_depth, IMAGE_TOL),
        ("dense_out_alpha", "out_alpha", reference.alpha, IMAGE_TOL),
        ("grad_means", "grad_means", grads.v_means.as_flattened().to_vec(), GRAD_TOL),
        ("grad_log_scales", "grad_log_scales", grads.v_log_scales.as_flattened().to_vec(), GRAD_TOL),
        ("grad_quats", "grad_quats", grads.v_quats.as_flattened().to_vec(), GRAD_TOL),
        ("grad_opacity_logits", "grad_opacity_logits", grads.v_opacity_logits, GRAD_TOL),
        ("grad_sh", "grad_sh", grads.v_sh, GRAD_TOL),
    ];
    ours.into_iter()
        .map(|(name, want, got, tol)| {
            let mut c = compare(want, &widen(&got), file.get(want)?, tol);
            c.name = name.to_string();
            Ok(c)
        })
        .collect()
}
