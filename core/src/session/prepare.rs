//! Preparing a run: the style image, colour matching of the scene, and setting
//! aside the Gaussians that no optimisation camera can see.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::stage1_cache::{CacheOutcome, Stage1Cache, depth_key};
pub use super::style_image::StyleImage;
use crate::camera::Camera;
use crate::gpu::{GpuContext, GpuDepthNet};
use crate::raster::{self, RenderOptions};
use crate::scene::Gaussians;
use crate::style::stage1::{StyleMaps, style_maps};
use crate::style::step::StyleTargets;
use crate::vision::Vgg;
use crate::vision::depth::{DepthAnything, DepthModelError, INPUT_SIZE, checkpoint_digest, resolve_depth_model};
use crate::vision::relief_depth::ReliefDepth;
use crate::vision::style_depth::{DepthImage, DepthPolarity, DepthProvider};

/// Where the style image's depth comes from.
#[derive(Clone, Debug, Default)]
pub enum StyleDepthSource {
    /// The built-in estimate that needs no weights ([`ReliefDepth`]: the
    /// style's luminance detail read as relief).
    #[default]
    Heuristic,
    /// A depth image the user supplied for this style.
    Image(DepthImage),
}

/// What [`StyleDepthSource::resolve`] settled on.
#[derive(Clone, Debug)]
pub struct ResolvedDepth {
    /// The source to use.
    pub source: StyleDepthSource,
    /// Why the choice could not be honoured (the heuristic is used), or a
    /// damaged cache file that was recomputed; for the CLI and the studio to show.
    pub warning: Option<String>,
    /// The Stage-1 cache file the learned depth was read from, when it was.
    pub cached: Option<PathBuf>,
    /// Why the learned network could not be used, when the heuristic stands
    /// in for it (the reason inside `warning`): `gast stylize` refuses a
    /// checkpoint named on its command line that fails so.
    pub learned_failure: Option<String>,
}

impl StyleDepthSource {
    /// The source `provider` asks for: the learned network's estimate of
    /// `style` (its checkpoint resolved from `model`, `$GAST_DEPTH_MODEL`, the
    /// caches, or a download reported through `progress`; the estimate read
    /// from `cache` when it holds one, else computed and written there), the
    /// user's `image`, or the heuristic. When the choice cannot be honoured
    /// the heuristic is used and the warning says why.
    /// Compute this once per style: the result serves every texture scale and polarity.
    pub fn resolve(
        provider: DepthProvider,
        image: Option<DepthImage>,
        model: Option<&Path>,
        cache: Option<&Stage1Cache>,
        style: &StyleImage,
        progress: &mut dyn FnMut(u64, Option<u64>),
    ) -> ResolvedDepth {
        Self::resolve_on(provider, image, model, cache, style, None, progress)
    }

    /// [`resolve`](Self::resolve) with the learned network on `gpu` when one
    /// is given (the session's GPU engine), else on the CPU.
    pub fn resolve_on(
        provider: DepthProvider,
        image: Option<DepthImage>,
        model: Option<&Path>,
        cache: Option<&Stage1Cache>,
        style: &StyleImage,
        gpu: Option<&GpuContext>,
        progress: &mut dyn FnMut(u64, Option<u64>),
    ) -> ResolvedDepth {
        let plain = |source, warning: Option<&str>| ResolvedDepth {
            source,
            warning: warning.map(str::to_string),
            cached: None,
            learned_failure: None,
        };
        match provider {
            DepthProvider::Heuristic => plain(Self::Heuristic, None),
            DepthProvider::Image => match image {
                Some(img) => {
                    let doubts = img.doubts(style.width, style.height);
                    plain(Self::Image(img), doubts.as_deref())
                }
                None => plain(
                    Self::Heuristic,
                    Some(
                        "no depth image was given for this style; using the built-in relief estimate (luminance detail)",
                    ),
                ),
            },
            DepthProvider::Learned => {
                let mut warnings = Vec::new();
                match learned_style_depth(style, model, cache, gpu, progress, &mut warnings) {
                    Ok((img, outcome)) => ResolvedDepth {
                        source: Self::Image(img),
                        warning: (!warnings.is_empty()).then(|| warnings.join("; ")),
                        cached: match outcome {
                            CacheOutcome::Hit(p) => Some(p),
                            CacheOutcome::Computed => None,
                        },
                        learned_failure: None,
                    },
                    Err(e) => ResolvedDepth {
                        learned_failure: Some(e.to_string()),
                        ..plain(
                            Self::Heuristic,
                            Some(&format!(
                                "learned style depth unavailable; using the built-in relief estimate (luminance detail): {e}"
                            )),
                        )
                    },
                }
            }
        }
    }
}

/// Depth Anything V2's relative inverse depth of `style`, at the network's
/// input size (near = larger); [`DepthImage`] resizes it to each texture scale.
/// The network runs on `gpu` when one is given ([`GpuDepthNet`]; the CPU
/// takes over, with a warning, if the device fails), else on the CPU.
/// With a `cache`, read from it when it holds this style's depth for this
/// checkpoint, else computed and written to it; what went wrong with the
/// cache (not an error) is pushed onto `warnings`.
///
/// The cache key does not name the device: the GPU pass equals the CPU one
/// to within 3e-7 of the depth's largest value on the golden and random
/// networks (`gpu::depth_net`'s tests hold it to 1e-4, the golden file's
/// criterion), far below anything the depth's min-max normalisation and the
/// GCFM loss can tell apart, so an entry computed on either serves both.
pub fn learned_style_depth(
    style: &StyleImage,
    model: Option<&Path>,
    cache: Option<&Stage1Cache>,
    gpu: Option<&GpuContext>,
    progress: &mut dyn FnMut(u64, Option<u64>),
    warnings: &mut Vec<String>,
) -> Result<(DepthImage, CacheOutcome), DepthModelError> {
    let path = resolve_depth_model(model, progress)?;
    let mut gpu_failure = None;
    let mut compute = || {
        let net = DepthAnything::load_path(&path)?;
        // The 8-bit image is read in place by the resize to the network's input.
        let (rgb, h, w) = (&style.rgb[..], style.height, style.width);
        let Some(ctx) = gpu else { return Ok(net.depth_image(rgb, h, w)) };
        let on_gpu = GpuDepthNet::new(ctx, net);
        Ok(on_gpu.depth_image(ctx, rgb, h, w).unwrap_or_else(|e| {
            gpu_failure = Some(format!("the depth network failed on the GPU ({e}); ran it on the CPU"));
            on_gpu.cpu().depth_image(rgb, h, w)
        }))
    };
    let result = match cache {
        None => compute().map(|d| (d, CacheOutcome::Computed)),
        Some(cache) => {
            let key = depth_key(style, &checkpoint_digest(&path)?, INPUT_SIZE);
            cache.depth_or_compute(&key, compute, warnings)
        }
    };
    warnings.extend(gpu_failure);
    result
}

/// The style's maps at texture scale and their features.
#[derive(Clone, Debug)]
pub struct PreparedStyle {
    /// RGB, depth and edge maps (for display and reports).
    pub maps: StyleMaps,
    /// Their VGG features, ready for matching.
    pub targets: StyleTargets,
}

/// Stage 1: the style's three maps at height `scale` and their features.
pub fn prepare_style(
    vgg: &Vgg,
    style: &StyleImage,
    scale: u32,
    depth: &StyleDepthSource,
    polarity: DepthPolarity,
    relief_px: u32,
) -> PreparedStyle {
    let maps = match depth {
        StyleDepthSource::Heuristic => {
            style_maps(&style.rgb, style.height, style.width, scale as usize, &ReliefDepth::default(), polarity)
        }
        StyleDepthSource::Image(img) => {
            style_maps(&style.rgb, style.height, style.width, scale as usize, img, polarity)
        }
    };
    // With the depth relief on, VGG sees the style depth's relief, as it sees the render's.
    let targets = if relief_px > 0 {
        let (h, w) = (maps.height, maps.width);
        let depth = crate::style::relief::relief_normalised(&maps.depth, h, w, None, relief_px as usize);
        crate::style::StyleTargets::new(vgg, &maps.rgb, &depth, &maps.edge, h, w)
    } else {
        maps.targets(vgg)
    };
    PreparedStyle { maps, targets }
}

/// What one pass over the optimisation cameras tells about the input scene.
pub struct ViewSurvey {
    /// RGB of every pixel the scene covers (alpha ≥ 0.5), flat triples: the
    /// content statistics of the colour transfer. The background is not scene
    /// content, and with a black background it would pull the mean towards black.
    pub covered_rgb: Vec<f32>,
    /// Per camera, how many of its pixels the scene covers (alpha ≥ 0.5).
    pub covered: Vec<usize>,
    /// For each Gaussian, whether some camera composites it with α ≥ 1/255
    /// before the pixel's transmittance runs out.
    pub seen: Vec<bool>,
}

/// Renders `g` once from every camera for both the colour statistics and the
/// visibility mask. (Visibility does not depend on colour, so it holds for the
/// colour-matched scene too.)
pub fn survey_views(g: &Gaussians, cameras: &[Camera], opts: &RenderOptions) -> ViewSurvey {
    let per_view: Vec<(Vec<f32>, Vec<bool>)> = cameras
        .par_iter()
        .map(|cam| {
            let (r, seen) = raster::render_and_contributing(g, cam, opts);
            let mut px = Vec::new();
            for (i, &a) in r.alpha.iter().enumerate() {
                if a >= 0.5 {
                    px.extend_from_slice(&r.rgb[3 * i..3 * i + 3]);
                }
            }
            (px, seen)
        })
        .collect();
    let mut seen = vec![false; g.len()];
    let mut covered_rgb = Vec::new();
    let mut covered = Vec::with_capacity(per_view.len());
    for (px, s) in per_view {
        covered.push(px.len() / 3);
        covered_rgb.extend(px);
        seen.iter_mut().zip(s).for_each(|(x, y)| *x |= y);
    }
    ViewSurvey { covered_rgb, covered, seen }
}

/// The Gaussians at `keep` (in order), a new set.
pub fn subset(g: &Gaussians, keep: &[u32]) -> Gaussians {
    let k = g.sh_coeffs() * 3;
    let mut out = Gaussians::with_capacity(keep.len(), g.sh_degree);
    for &i in keep {
        let i = i as usize;
        out.means.push(g.means[i]);
        out.log_scales.push(g.log_scales[i]);
        out.quats.push(g.quats[i]);
        out.opacity_logits.push(g.opacity_logits[i]);
        out.sh.extend_from_slice(&g.sh[i * k..(i + 1) * k]);
    }
    out
}

/// Writes the Gaussians of `part` back to positions `keep` of `full`.
pub fn scatter(full: &mut Gaussians, keep: &[u32], part: &Gaussians) {
    let k = full.sh_coeffs() * 3;
    for (j, &i) in keep.iter().enumerate() {
        let i = i as usize;
        full.means[i] = part.means[j];
        full.log_scales[i] = part.log_scales[j];
        full.quats[i] = part.quats[j];
        full.opacity_logits[i] = part.opacity_logits[j];
        full.sh[i * k..(i + 1) * k].copy_from_slice(&part.sh[j * k..(j + 1) * k]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_choice_falls_back_with_a_warning() {
        let style = StyleImage { width: 40, height: 28, rgb: (0..40 * 28 * 3).map(|i| (i * 7 % 251) as u8).collect() };
        let none = &mut |_: u64, _: Option<u64>| {};
        let r = StyleDepthSource::resolve(DepthProvider::Heuristic, None, None, None, &style, none);
        assert!(matches!(r.source, StyleDepthSource::Heuristic) && r.warning.is_none());
        let r = StyleDepthSource::resolve(DepthProvider::Image, None, None, None, &style, none);
        assert!(
            matches!(r.source, StyleDepthSource::Heuristic) && r.warning.is_some_and(|w| w.contains("no depth image"))
        );
        let absent = std::env::temp_dir().join("gast-no-such-depth-model");
        let r = StyleDepthSource::resolve(DepthProvider::Learned, None, Some(&absent), None, &style, none);
        let w = r.warning.unwrap_or_default();
        assert!(matches!(r.source, StyleDepthSource::Heuristic) && w.contains("gast-no-such-depth-model"), "{w}");
        // The golden file is a complete (small, random) checkpoint with its config inside.
        let Some(p) = crate::vision::weights::tests::shared("golden/depth/depth_seed1.safetensors") else { return };
        let r = StyleDepthSource::resolve(DepthProvider::Learned, None, Some(&p), None, &style, none);
        assert!(r.warning.is_none() && r.cached.is_none(), "{r:?}");
        let StyleDepthSource::Image(img) = r.source else { panic!("expected the learned depth") };
        // 28 × 40 is enlarged: the scale closer to 1 brings the longer side to
        // 518 (as transformers does), the height follows, snapped to 14.
        assert_eq!((img.height, img.width), (364, 518));
        assert!(img.values.iter().all(|v| v.is_finite()) && img.near_is_larger);
    }

    #[test]
    fn subset_then_scatter_restores_the_scene() {
        let mut g = Gaussians::with_capacity(4, 1);
        for i in 0..4 {
            let f = i as f32;
            g.means.push([f, 0.0, 1.0]);
            g.log_scales.push([-f; 3]);
            g.quats.push([1.0, f, 0.0, 0.0]);
            g.opacity_logits.push(f);
            g.sh.extend((0..12).map(|k| f + k as f32 * 0.01));
        }
        let keep = [1u32, 3];
        let mut part = subset(&g, &keep);
        assert_eq!(part.len(), 2);
        assert_eq!(part.means[1], [3.0, 0.0, 1.0]);
        part.opacity_logits[0] = 42.0;
        part.sh[12] = -1.0;
        let mut full = g.clone();
        scatter(&mut full, &keep, &part);
        assert_eq!(full.opacity_logits, vec![0.0, 42.0, 2.0, 3.0]);
        assert_eq!(full.sh[3 * 12], -1.0);
        assert_eq!(full.sh[..12], g.sh[..12]);
    }
}
