//! The per-step stylisation loss, from rendered maps to pixel gradients.
//!
//! One function ([`step_loss`]) that the optimiser calls every step and that
//! `gast check golden` reuses: it downscales the render 0.5× (bilinear), builds
//! the depth map (inverse depth, min-max normalised per image, replicated to 3
//! channels) and the edge map (a constant, replicated), runs the feature network
//! on the three, computes GCFM and the content loss on the features, TV and the
//! optional depth regulariser on the maps, and returns each term with the
//! weighted gradients w.r.t. the rendered RGB and inverse depth. The network is
//! behind [`FeatureNet`] so the loss does not depend on how VGG is implemented
//! (and tests can use a small stand-in).

use super::assignment::{ASSIGN_BLOCK, assignment_loss};
use super::config::LossWeights;
use super::content::content_loss_masked;
use super::feature_mean::feature_mean_loss;
use super::focus::{feature_mask, gather_positions, scatter_positions};
use super::gcfm::{GcfmOutput, Matches, StyleFeatures, gcfm_loss_with_matches, match_features};
use super::outside::{Outside, outside_loss};
use super::palette::{Palette, palette_loss};
use super::regularizers::depth_l1;
use super::sliced::sliced_loss;
use super::terms::LossTerms;
use super::tv::tv_loss_masked;
use super::window::{FeatureWindow, covered_box};
use crate::vision::resize::{downscale_half, downscale_half_backward};
use crate::vision::vgg_cone::Region;

/// A CHW feature map.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureMap {
    /// Channels.
    pub channels: usize,
    /// Height.
    pub height: usize,
    /// Width.
    pub width: usize,
    /// `channels · height · width` values, channel-major.
    pub data: Vec<f32>,
}

/// Where the image-space losses look ([`super::focus`]), whether VGG runs
/// on the covered positions' window only ([`super::window`]), and the
/// assignment terms' block size.
#[derive(Clone, Copy, Debug)]
pub struct LossFocus<'a> {
    /// The covered pixels (`h × w`); `None` is the whole frame.
    pub mask: Option<&'a [bool]>,
    /// With a mask, run VGG's forwards and backwards on the window the covered
    /// positions' receptive fields span, not the whole frame, and inside it
    /// only on the cone of their box ([`FeatureNet::forward_within`]): the
    /// same losses and gradients up to rounding for less work. Exact for
    /// VGG's relu3 and any network whose receptive field is no larger.
    pub window: bool,
    /// The pixels the background hold keeps ([`super::outside`]); used when
    /// λ_out is above 0.
    pub outside: Option<Outside<'a>>,
    /// The colour-matched render's palette over `mask` ([`super::palette`]);
    /// used when λ_pal is above 0 and there is a mask.
    pub palette: Option<Palette>,
    /// Above 0: the depth map's relief at this radius in pixels goes to VGG
    /// instead of the min-max normalised depth ([`super::relief`]).
    pub relief_px: usize,
    /// Most rows of one least-cost block of the assignment terms' pairing
    /// ([`super::assignment`]; `StyleConfig::assign_block`).
    pub assign_block: usize,
}

impl Default for LossFocus<'_> {
    fn default() -> Self {
        Self { mask: None, window: false, outside: None, palette: None, relief_px: 0, assign_block: ASSIGN_BLOCK }
    }
}

/// A frozen feature extractor with an input gradient (VGG relu3_1..3).
pub trait FeatureNet: Sync {
    /// What [`FeatureNet::backward`] needs from a forward pass.
    type State: Send + Sync;
    /// Features of an RGB image (HWC, `h × w × 3`, values in [0, 1]).
    fn features(&self, rgb: &[f32], h: usize, w: usize) -> FeatureMap;
    /// Features plus the saved state for the backward pass.
    fn forward(&self, rgb: &[f32], h: usize, w: usize) -> (FeatureMap, Self::State);
    /// Gradient w.r.t. the input image (HWC) given the features' gradient.
    fn backward(&self, state: &Self::State, v_features: &[f32]) -> Vec<f32>;
    /// As [`FeatureNet::forward`] when only the features in the box `cells`
    /// of the feature grid are read (and only they get a gradient): a network
    /// may skip the rest, whose features are then unspecified. The default
    /// runs the whole forward.
    fn forward_within(&self, rgb: &[f32], h: usize, w: usize, cells: Region) -> (FeatureMap, Self::State) {
        let _ = cells;
        self.forward(rgb, h, w)
    }
    /// As [`FeatureNet::features`] when only those in `cells` are read.
    fn features_within(&self, rgb: &[f32], h: usize, w: usize, cells: Region) -> FeatureMap {
        let _ = cells;
        self.features(rgb, h, w)
    }
    /// As [`FeatureNet::features`] for a large image (the style at its
    /// texture scale): a network may compute it in bands so as to hold one
    /// band's activations at a time. The default runs the whole forward.
    fn features_banded(&self, rgb: &[f32], h: usize, w: usize) -> FeatureMap {
        self.features(rgb, h, w)
    }
}

/// The studio's network: VGG relu3_1..3 ([`crate::vision::Vgg`]).
impl FeatureNet for crate::vision::Vgg {
    type State = crate::vision::VggState;
    fn features(&self, rgb: &[f32], h: usize, w: usize) -> FeatureMap {
        let f = crate::vision::Vgg::features(self, rgb, h, w);
        FeatureMap { channels: f.c, height: f.h, width: f.w, data: f.data }
    }
    fn forward(&self, rgb: &[f32], h: usize, w: usize) -> (FeatureMap, Self::State) {
        let (f, s) = crate::vision::Vgg::forward(self, rgb, h, w);
        (FeatureMap { channels: f.c, height: f.h, width: f.w, data: f.data }, s)
    }
    fn backward(&self, state: &Self::State, v_features: &[f32]) -> Vec<f32> {
        crate::vision::Vgg::backward(self, state, v_features)
    }
    fn forward_within(&self, rgb: &[f32], h: usize, w: usize, cells: Region) -> (FeatureMap, Self::State) {
        let (f, s) = crate::vision::Vgg::forward_within(self, rgb, h, w, cells);
        (FeatureMap { channels: f.c, height: f.h, width: f.w, data: f.data }, s)
    }
    fn features_within(&self, rgb: &[f32], h: usize, w: usize, cells: Region) -> FeatureMap {
        let f = crate::vision::Vgg::features_within(self, rgb, h, w, cells);
        FeatureMap { channels: f.c, height: f.h, width: f.w, data: f.data }
    }
    fn features_banded(&self, rgb: &[f32], h: usize, w: usize) -> FeatureMap {
        let f = crate::vision::Vgg::features_banded(self, rgb, h, w);
        FeatureMap { channels: f.c, height: f.h, width: f.w, data: f.data }
    }
}

/// Everything about the style the per-step loss needs, computed once per
/// style image and scale.
#[derive(Clone, Debug)]
pub struct StyleTargets {
    /// Features of the style RGB, depth and edge maps.
    pub features: StyleFeatures,
}

/// Replicates a single-channel map to 3 interleaved channels.
pub fn replicate3(map: &[f32]) -> Vec<f32> {
    map.iter().flat_map(|&v| [v, v, v]).collect()
}

impl StyleTargets {
    /// Features of the style maps at their final size (no downscale): `rgb`
    /// HWC, `depth` and `edge` `h × w` (depth in [0, 1], edges in {0, 1}).
    pub fn new<N: FeatureNet>(net: &N, rgb: &[f32], depth: &[f32], edge: &[f32], h: usize, w: usize) -> Self {
        let inputs = [rgb.to_vec(), replicate3(depth), replicate3(edge)];
        let maps: Vec<FeatureMap> = {
            use rayon::prelude::*;
            inputs.par_iter().map(|img| net.features_banded(img, h, w)).collect()
        };
        let (c, fh, fw) = (maps[0].channels, maps[0].height, maps[0].width);
        let mut it = maps.into_iter().map(|m| m.data);
        let feats = std::array::from_fn(|_| it.next().unwrap_or_default());
        Self { features: StyleFeatures::new(feats, c, fh, fw) }
    }
}

/// The content target: features of the colour-matched render, downscaled 0.5×
/// like the rendered image.
pub fn content_target<N: FeatureNet>(net: &N, content_rgb: &[f32], h: usize, w: usize) -> FeatureMap {
    let (small, sh, sw) = downscale_half(content_rgb, h, w, 3);
    net.features(&small, sh, sw)
}

/// The rendered maps of one step (all `h × w`, RGB HWC).
#[derive(Clone, Copy, Debug)]
pub struct RenderedMaps<'a> {
    /// Rendered colour, clamped to [0, 1].
    pub rgb: &'a [f32],
    /// Rendered inverse depth `Σ α T / z`.
    pub inv_depth: &'a [f32],
    /// Edge map of the render ([`crate::vision::canny::render_edges`]), a constant.
    pub edge: &'a [f32],
    /// Height.
    pub height: usize,
    /// Width.
    pub width: usize,
}

/// The per-step loss: each term unweighted, the weighted total, and the
/// gradients of the weighted total.
#[derive(Clone, Debug)]
pub struct StepLoss {
    /// Where the time went.
    pub timings: StepLossTimings,
    /// Each term unweighted (0 where a term is off or its input missing) and
    /// the weighted `total`; the parameter regularisers are the session's, 0 here.
    pub terms: LossTerms,
    /// Gradient of `total` w.r.t. the rendered RGB (HWC).
    pub v_rgb: Vec<f32>,
    /// Gradient of `total` w.r.t. the rendered inverse depth (`h × w`).
    pub v_inv_depth: Vec<f32>,
    /// GCFM matches (flat indices into the style feature map).
    pub matches: Matches,
}

/// Milliseconds spent in the parts of [`step_loss`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepLossTimings {
    /// Downscale and VGG forward of the three rendered maps.
    pub features_ms: f32,
    /// Joint nearest/farthest matching and the feature-space losses.
    pub matching_ms: f32,
    /// VGG backward of the RGB (and depth) maps and the image-space adjoints.
    pub backward_ms: f32,
    /// The assignment terms' pairing, part of `matching_ms`.
    pub pairing_ms: f32,
}

/// The min and max of `d` over the positions in `mask` (all without one).
fn masked_range(d: &[f32], mask: Option<&[bool]>) -> (f32, f32) {
    let inside = |k: usize| mask.is_none_or(|m| m[k]);
    d.iter()
        .enumerate()
        .filter(|(k, _)| inside(*k))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), (_, &x)| (a.min(x), b.max(x)))
}

/// Min-max normalisation `(d − min)/(max − min + 1e-8)` over the positions in
/// `mask` (all without one; those outside are a constant 0) and its adjoint
/// (ties at the min or max share the gradient equally, as autodiff does).
pub(crate) fn min_max_backward(d: &[f32], v: &[f32], mask: Option<&[bool]>) -> Vec<f32> {
    let inside = |k: usize| mask.is_none_or(|m| m[k]);
    let (lo, hi) = masked_range(d, mask);
    let r = f64::from(hi - lo) + 1e-8;
    let (mut sum_v, mut sum_vd) = (0f64, 0f64);
    for (k, (&x, &g)) in d.iter().zip(v).enumerate() {
        if !inside(k) {
            continue;
        }
        let dn = f64::from(x - lo) / r;
        sum_v += f64::from(g);
        sum_vd += f64::from(g) * dn;
    }
    let ties = |t: f32| d.iter().enumerate().filter(|&(k, &x)| inside(k) && x == t).count().max(1) as f64;
    let (n_lo, n_hi) = (ties(lo), ties(hi));
    // ∂/∂max = −Σ g·d̃ / r ; ∂/∂min = (Σ g·d̃ − Σ g) / r.
    let g_hi = -sum_vd / r / n_hi;
    let g_lo = (sum_vd - sum_v) / r / n_lo;
    d.iter()
        .zip(v)
        .enumerate()
        .map(|(k, (&x, &g))| {
            if !inside(k) {
                return 0.0;
            }
            let mut o = f64::from(g) / r;
            if x == hi {
                o += g_hi;
            }
            if x == lo {
                o += g_lo;
            }
            o as f32
        })
        .collect()
}

/// The whole per-step loss from rendered maps. `content` is the content target
/// ([`content_target`]) and `depth_ref` the inverse depth of `G^c` from the same
/// view (geometry phase); either may be `None`. The depth map's VGG backward
/// runs only when `depth_grad` is set (a colour step does not use it; its
/// `v_inv_depth` then holds only the depth regulariser's gradient, if any).
/// Only `gcfm`, `content`, `tv` and `depth` of `weights` are used here; the
/// parameter regularisers act on the Gaussians, not on the maps.
pub fn step_loss<N: FeatureNet>(
    net: &N,
    style: &StyleTargets,
    maps: RenderedMaps<'_>,
    content: Option<&FeatureMap>,
    depth_ref: Option<&[f32]>,
    weights: &LossWeights,
    depth_grad: bool,
) -> StepLoss {
    step_loss_masked(net, style, maps, content, depth_ref, weights, depth_grad, None)
}

/// [`step_loss_masked`] with the exact GCFM matches.
#[allow(clippy::too_many_arguments)]
pub fn step_loss_masked<N: FeatureNet>(
    net: &N,
    style: &StyleTargets,
    maps: RenderedMaps<'_>,
    content: Option<&FeatureMap>,
    depth_ref: Option<&[f32]>,
    weights: &LossWeights,
    depth_grad: bool,
    mask: Option<&[bool]>,
) -> StepLoss {
    let exact = &mut |rendered: [&[f32]; 3], n: usize| match_features(&style.features, rendered, n);
    step_loss_with(
        net,
        style,
        maps,
        content,
        depth_ref,
        weights,
        depth_grad,
        LossFocus { mask, window: true, ..LossFocus::default() },
        exact,
    )
}

/// [`step_loss`] with the focus on the pixels in `mask` (`h × w`, see
/// [`super::focus`]): GCFM and content average over the feature positions
/// whose cell the mask covers ([`feature_mask`]), TV over the differences
/// inside it, and the depth map is min-max normalised over the covered pixels
/// (a constant 0 elsewhere). Uncovered positions get exactly zero gradient
/// from these terms. The style side and the depth regulariser, which anchors
/// the geometry everywhere, are unchanged. A mask that covers no feature
/// position falls back to the whole frame. The GCFM matches of the covered
/// positions come from `matcher` (given their RGB, depth and edge features and
/// their number): the exact search, an index, or matches kept from an earlier
/// visit of the view.
#[allow(clippy::too_many_arguments)]
pub fn step_loss_with<N: FeatureNet>(
    net: &N,
    style: &StyleTargets,
    maps: RenderedMaps<'_>,
    content: Option<&FeatureMap>,
    depth_ref: Option<&[f32]>,
    weights: &LossWeights,
    depth_grad: bool,
    focus: LossFocus<'_>,
    matcher: &mut dyn FnMut([&[f32]; 3], usize) -> Matches,
) -> StepLoss {
    use rayon::prelude::*;
    let (h, w) = (maps.height, maps.width);
    assert_eq!(maps.rgb.len(), h * w * 3, "step_loss: rgb size");
    assert_eq!(maps.inv_depth.len(), h * w, "step_loss: inverse depth size");
    assert_eq!(maps.edge.len(), h * w, "step_loss: edge size");
    if let Some(m) = focus.mask {
        assert_eq!(m.len(), h * w, "step_loss: mask size");
    }
    // The feature grid (VGG's input is the render halved, then two
    // floor-halving pools) and the covered positions on it. A mask that covers
    // none of them is dropped whole, the depth map's normalisation included,
    // as the GPU engine does: before, the depth was normalised over the mask
    // and its backward pass over the frame.
    let (fh, fw) = (h / 2 / 4, w / 2 / 4);
    let fmask = focus.mask.map(|m| feature_mask(m, h, w, fh, fw)).filter(|f| f.contains(&true));
    let mask = focus.mask.filter(|_| fmask.is_some());
    let mut timings = StepLossTimings::default();
    let t = std::time::Instant::now();

    // Depth map: min-max normalised, replicated to 3 channels.
    let (lo, hi) = masked_range(maps.inv_depth, mask);
    let r = hi - lo + 1e-8;
    let depth_n: Vec<f32> = maps
        .inv_depth
        .iter()
        .enumerate()
        .map(|(k, &x)| if mask.is_none_or(|m| m[k]) { (x - lo) / r } else { 0.0 })
        .collect();
    // Its relief instead, when asked (`super::relief`).
    let depth_rel = (focus.relief_px > 0).then(|| super::relief::relief(&depth_n, h, w, mask, focus.relief_px));
    let depth_n = match &depth_rel {
        Some(rel) => super::relief::centred(rel, mask),
        None => depth_n,
    };
    let images = [maps.rgb.to_vec(), replicate3(&depth_n), replicate3(maps.edge)];
    let downs: Vec<(Vec<f32>, usize, usize)> = images.iter().map(|im| downscale_half(im, h, w, 3)).collect();
    let (sh, sw) = (downs[0].1, downs[0].2);
    debug_assert_eq!((fh, fw), (sh / 4, sw / 4), "step_loss: the feature grid");
    let n = fh * fw;
    // The window of the input VGG needs for the covered positions.
    let cells = fmask.as_deref().filter(|_| focus.window).and_then(|f| covered_box(f, fh, fw));
    let window = cells.and_then(|b| FeatureWindow::around(b, fh, fw));

    // Features: RGB (and depth, when its gradient is wanted) keep their state
    // for the backward pass; edges are a constant.
    let fwd: Vec<(FeatureMap, Option<N::State>)> = downs
        .par_iter()
        .enumerate()
        .map(|(k, (img, _, _))| {
            let keep = k == 0 || (k == 1 && depth_grad);
            let run = |img: &[f32], ih: usize, iw: usize, cells: Option<Region>| match (cells, keep) {
                (None, true) => {
                    let (f, s) = net.forward(img, ih, iw);
                    (f, Some(s))
                }
                (None, false) => (net.features(img, ih, iw), None),
                (Some(c), true) => {
                    let (f, s) = net.forward_within(img, ih, iw, c);
                    (f, Some(s))
                }
                (Some(c), false) => (net.features_within(img, ih, iw, c), None),
            };
            let Some(win) = &window else {
                return run(img, sh, sw, cells);
            };
            let (part, ph, pw) = win.crop_image(img, sh, sw, 3);
            let (f, s) = run(&part, ph, pw, cells.map(|c| win.local(c)));
            let data = win.embed_features(&f.data, f.channels);
            (FeatureMap { channels: f.channels, height: fh, width: fw, data }, s)
        })
        .collect();
    timings.features_ms = t.elapsed().as_secs_f32() * 1e3;
    let t = std::time::Instant::now();
    debug_assert_eq!((fwd[0].0.height, fwd[0].0.width), (fh, fw), "step_loss: the feature grid");
    let feats = [&fwd[0].0.data, &fwd[1].0.data, &fwd[2].0.data];
    let out = match &fmask {
        None => {
            let rendered = feats.map(Vec::as_slice);
            gcfm_loss_with_matches(&style.features, rendered, n, matcher(rendered, n))
        }
        Some(f) => masked_gcfm(&style.features, feats.map(Vec::as_slice), fwd[0].0.channels, f, matcher),
    };

    // RGB features' gradient: GCFM plus content.
    let mut v_feat_rgb: Vec<f32> = out.v_rendered[0].iter().map(|v| v * weights.gcfm).collect();
    let mut content_value = 0.0;
    if let Some(ct) = content {
        let (l, g) = content_loss_masked(&fwd[0].0.data, &ct.data, fmask.as_deref());
        content_value = l;
        for (a, b) in v_feat_rgb.iter_mut().zip(g) {
            *a += weights.content * b;
        }
    }
    let mut feature_mean_value = 0.0;
    if weights.feature_mean > 0.0 {
        let (l, g) = feature_mean_loss(&fwd[0].0.data, fwd[0].0.channels, style.features.rgb_mean(), fmask.as_deref());
        feature_mean_value = l;
        for (a, b) in v_feat_rgb.iter_mut().zip(g) {
            *a += weights.feature_mean * b;
        }
    }
    let mut sliced_value = 0.0;
    if weights.sliced > 0.0 {
        let (l, g) = sliced_loss(&fwd[0].0.data, fwd[0].0.channels, style.features.sliced(0), fmask.as_deref());
        sliced_value = l;
        for (a, b) in v_feat_rgb.iter_mut().zip(g) {
            *a += weights.sliced * b;
        }
    }
    let (mut assignment_value, mut assignment_cosine_value) = (0.0, 0.0);
    if weights.assignment > 0.0 || weights.assignment_cosine > 0.0 {
        let paired = std::time::Instant::now();
        let a = assignment_loss(
            &fwd[0].0.data,
            fwd[0].0.channels,
            style.features.modality(0),
            fmask.as_deref(),
            weights.assignment_cosine,
            weights.assignment,
            focus.assign_block,
        );
        timings.pairing_ms = paired.elapsed().as_secs_f32() * 1e3;
        (assignment_value, assignment_cosine_value) = (a.l2, a.cosine);
        for (v, g) in v_feat_rgb.iter_mut().zip(a.grad) {
            *v += g;
        }
    }
    let mut v_feat_depth: Vec<f32> = out.v_rendered[1].iter().map(|v| v * weights.gcfm).collect();
    let mut sliced_depth_value = 0.0;
    if weights.sliced_depth > 0.0 && depth_grad {
        let target = style.features.sliced(1);
        let (l, g) = sliced_loss(&fwd[1].0.data, fwd[1].0.channels, target, fmask.as_deref());
        sliced_depth_value = l;
        for (a, b) in v_feat_depth.iter_mut().zip(g) {
            *a += weights.sliced_depth * b;
        }
    }
    timings.matching_ms = t.elapsed().as_secs_f32() * 1e3;
    let t = std::time::Instant::now();
    // Through VGG, on the window when the forward ran on it.
    let backward = |state: &N::State, v: &[f32]| match &window {
        None => net.backward(state, v),
        Some(win) => {
            let v_part = net.backward(state, &win.crop_features(v, fwd[0].0.channels));
            win.uncrop_image(&v_part, sh, sw, 3)
        }
    };
    let (v_small_rgb, v_small_depth) = rayon::join(
        || fwd[0].1.as_ref().map(|s| backward(s, &v_feat_rgb)),
        || fwd[1].1.as_ref().map(|s| backward(s, &v_feat_depth)),
    );
    let mut v_rgb = downscale_half_backward(&v_small_rgb.unwrap_or_else(|| vec![0.0; sh * sw * 3]), h, w, 3);
    let mut v_inv_depth = match v_small_depth {
        Some(v) => {
            let v_depth3 = downscale_half_backward(&v, h, w, 3);
            let v_depth_n: Vec<f32> = v_depth3.chunks_exact(3).map(|p| p[0] + p[1] + p[2]).collect();
            let v_depth_n = match &depth_rel {
                Some(rel) => {
                    let v_rel = super::relief::centred_backward(rel, &v_depth_n, mask);
                    super::relief::relief_backward(&v_rel, h, w, mask, focus.relief_px)
                }
                None => v_depth_n,
            };
            min_max_backward(maps.inv_depth, &v_depth_n, mask)
        }
        None => vec![0.0; h * w],
    };
    timings.backward_ms = t.elapsed().as_secs_f32() * 1e3;

    let (tv, v_tv) = tv_loss_masked(maps.rgb, h, w, 3, mask);
    for (a, b) in v_rgb.iter_mut().zip(v_tv) {
        *a += weights.tv * b;
    }
    let mut outside_value = 0.0;
    if let Some(held) = focus.outside.filter(|_| weights.outside > 0.0) {
        let (l, g) = outside_loss(maps.rgb, held);
        outside_value = l;
        for (a, b) in v_rgb.iter_mut().zip(g) {
            *a += weights.outside * b;
        }
    }
    let mut palette_value = 0.0;
    // On the covered pixels, when some feature position is covered (else the
    // losses look at the whole frame, and the hold sits out, as on the GPU).
    let covered = mask;
    if let (Some(reference), Some(mask)) = (focus.palette.filter(|_| weights.palette > 0.0), covered) {
        let (l, g) = palette_loss(maps.rgb, mask, &reference);
        palette_value = l;
        for (a, b) in v_rgb.iter_mut().zip(g) {
            *a += weights.palette * b;
        }
    }
    let mut depth_value = 0.0;
    if let Some(dref) = depth_ref {
        let (l, g) = depth_l1(maps.inv_depth, dref);
        depth_value = l;
        for (a, b) in v_inv_depth.iter_mut().zip(g) {
            *a += weights.depth * b;
        }
    }
    let mut terms = LossTerms {
        gcfm: out.loss,
        content: content_value,
        tv,
        depth: depth_value,
        feature_mean: feature_mean_value,
        outside: outside_value,
        palette: palette_value,
        sliced: sliced_value,
        sliced_depth: sliced_depth_value,
        assignment: assignment_value,
        assignment_cosine: assignment_cosine_value,
        ..LossTerms::default()
    };
    terms.total = terms.weighted(weights);
    StepLoss { timings, terms, v_rgb, v_inv_depth, matches: out.matches }
}

/// GCFM over the feature positions in `fmask` only: the rendered features of
/// those positions are gathered, matched and averaged, and the gradients
/// scattered back (zero elsewhere). Matches of uncovered positions are `u32::MAX`.
fn masked_gcfm(
    style: &StyleFeatures,
    rendered: [&[f32]; 3],
    channels: usize,
    fmask: &[bool],
    matcher: &mut dyn FnMut([&[f32]; 3], usize) -> Matches,
) -> GcfmOutput {
    let n = fmask.len();
    let idx: Vec<usize> = (0..n).filter(|&x| fmask[x]).collect();
    let parts = rendered.map(|f| gather_positions(f, channels, n, &idx));
    let covered = [&parts[0][..], &parts[1][..], &parts[2][..]];
    // Matches kept from an earlier visit of the view span every position
    // (u32::MAX where uncovered); the view's mask, and so `idx`, is the same.
    let mut found = matcher(covered, idx.len());
    if found.best.len() == n && idx.len() != n {
        found = Matches {
            best: idx.iter().map(|&x| found.best[x]).collect(),
            worst: idx.iter().map(|&x| found.worst[x]).collect(),
        };
    }
    let out = gcfm_loss_with_matches(style, covered, idx.len(), found);
    let spread = |m: &[u32]| {
        let mut all = vec![u32::MAX; n];
        idx.iter().zip(m).for_each(|(&x, &v)| all[x] = v);
        all
    };
    GcfmOutput {
        loss: out.loss,
        terms: out.terms,
        v_rendered: out.v_rendered.map(|v| scatter_positions(&v, channels, n, &idx)),
        matches: Matches { best: spread(&out.matches.best), worst: spread(&out.matches.worst) },
    }
}

#[cfg(test)]
#[path = "step_tests.rs"]
mod tests;
