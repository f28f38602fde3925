//! The per-step loss on the GPU: the twin of [`crate::style::step::step_loss`]
//! from a rendered image to the gradients w.r.t. that image, recorded into
//! one command encoder.
//!
//! [`StepLossPlan`] holds the scratch buffers and planned launches for one
//! image size: the clamp, the 0.5× downscale, the depth map (and its relief,
//! [`DepthRelief`], while one is asked), the edge map,
//! three VGG forwards, GCFM, content, the feature-mean and sliced terms where
//! their weights are on, the two VGG backwards and the image-space adjoints,
//! TV and the depth regulariser. The engine ([`super::GpuEngine`])
//! records it between the rasterizer's forward and backward passes;
//! [`step_loss_gpu`] runs it on uploaded maps (the golden checks). With a
//! [`GpuFocus`] (the object focus), GCFM, content, TV and the depth map's
//! normalisation look only at what it covers, as
//! [`crate::style::step::step_loss_masked`] does; without one, at the whole
//! frame (an all-ones focus the plan keeps).

use std::sync::Arc;

use super::Commands;
use super::assignment::GpuAssignment;
use super::content::ContentLoss;
use super::feature_mean::FeatureMeanLoss;
use super::palette::PaletteLoss;
use super::{
    CannyKernels, Clamp01, DepthMap, DepthMapKernels, DepthRelief, DepthReliefKernels, Downscale, EdgeMap,
    FocusKernels, GcfmSubset, GcfmWorkspace, GpuContext, GpuError, GpuFocus, GpuGcfm, GpuStyle, GpuVgg, GpuVggState,
    GpuVggWorkspace, LossKernels, ReduceKernels, RefLoss, ResizeKernels, Search, SlicedKernels, SlicedLoss, TvLoss,
    VggWindow, WindowKernel, WindowSize,
};
use crate::style::config::LossWeights;
use crate::style::gcfm::Matches;
use crate::style::step::{RenderedMaps, StepLoss, StepLossTimings, StyleTargets, replicate3};
use crate::style::terms::LossTerms;
use crate::vision::Vgg;
use crate::vision::vgg_cone::Region;

use super::vgg_window::MAX_SHARE as MAX_WINDOW_SHARE;

/// Where each loss value lives in a scalars buffer (in 4-byte words).
pub mod slot {
    /// GCFM: RGB, depth, edge, sum (four words, unweighted).
    pub const GCFM: usize = 0;
    /// Content (unweighted).
    pub const CONTENT: usize = 4;
    /// TV (unweighted).
    pub const TV: usize = 5;
    /// Depth L1 (unweighted).
    pub const DEPTH: usize = 6;
    /// ‖o − o^c‖.
    pub const REG_OPACITY: usize = 7;
    /// ‖s − s^c‖.
    pub const REG_SCALE: usize = 8;
    /// ‖q − q^c‖.
    pub const REG_ROTATION: usize = 9;
    /// (tile, splat) pairs the render needed (a `u32`).
    pub const PAIRS: usize = 10;
    /// The feature-mean term (unweighted; written only when λ_mean > 0).
    pub const FEATURE_MEAN: usize = 11;
    /// The background hold (unweighted; written only when λ_out > 0 and a view holds pixels).
    pub const OUTSIDE: usize = 12;
    /// The sliced Wasserstein term on the RGB features (unweighted; written only when λ_sw > 0).
    pub const SLICED: usize = 13;
    /// The same on the depth features (unweighted; written only when λ_swd > 0 on steps taking the depth's gradient).
    pub const SLICED_DEPTH: usize = 14;
    /// The palette hold (unweighted; written only when λ_pal > 0 with an object focus).
    pub const PALETTE: usize = 15;
    /// Words in all.
    pub const LEN: usize = 16;
}

/// The kernels of the loss, compiled once per context (with the network's weights).
#[derive(Debug)]
pub struct StepLossKernels {
    pub(crate) resize: Arc<ResizeKernels>,
    pub(crate) depth: Arc<DepthMapKernels>,
    /// The depth relief's, compiled when a plan first needs them.
    relief: std::sync::OnceLock<Arc<DepthReliefKernels>>,
    pub(crate) canny: Arc<CannyKernels>,
    pub(crate) losses: Arc<LossKernels>,
    pub(crate) reduce: Arc<ReduceKernels>,
    pub(crate) focus: Arc<FocusKernels>,
    pub(crate) vgg: GpuVgg,
    pub(crate) gcfm: GpuGcfm,
    pub(crate) sliced: Arc<SlicedKernels>,
    pub(crate) window: WindowKernel,
}

impl StepLossKernels {
    /// Compiles every kernel and uploads `vgg`'s convolutions.
    pub fn new(ctx: &GpuContext, vgg: &Vgg) -> Self {
        Self {
            resize: ResizeKernels::new(ctx),
            depth: DepthMapKernels::new(ctx),
            relief: std::sync::OnceLock::new(),
            canny: CannyKernels::new(ctx),
            losses: LossKernels::new(ctx),
            reduce: ReduceKernels::new(ctx),
            focus: FocusKernels::new(ctx),
            vgg: GpuVgg::new(ctx, vgg),
            gcfm: GpuGcfm::new(ctx),
            sliced: SlicedKernels::new(ctx),
            window: WindowKernel::new(ctx),
        }
    }

    /// The depth relief's kernels, compiled on the first call.
    fn relief(&self, ctx: &GpuContext) -> &Arc<DepthReliefKernels> {
        self.relief.get_or_init(|| DepthReliefKernels::new(ctx))
    }
}

/// Scratch buffers and planned launches of the loss for `h × w` renders.
#[derive(Debug)]
pub struct StepLossPlan {
    clamp: Clamp01,
    down: Downscale,
    depth_map: DepthMap,
    /// The depth map's relief ([`StepLossPlan::set_relief`]), planned only while it is on.
    relief: Option<DepthRelief>,
    edges: EdgeMap,
    tv: TvLoss,
    depth_l1: RefLoss,
    hold: RefLoss,
    /// Whether λ_out is above 0 (the hold is recorded only then).
    hold_on: bool,
    palette: PaletteLoss,
    /// Whether λ_pal is above 0 (the palette hold is recorded only then, and
    /// only with an object focus).
    palette_on: bool,
    vgg_ws: GpuVggWorkspace,
    /// VGG states of the RGB, depth and edge maps (the edge state doubles as
    /// the scratch of [`StepLossPlan::record_content_target`]); with a
    /// window, their features buffers hold the window's features put back.
    states: [GpuVggState; 3],
    /// VGG on the object's window ([`StepLossPlan::fit_window`]), at the
    /// largest size this plan's views have needed.
    window: Option<VggWindow>,
    /// Whether the plan runs VGG on the whole frame only: its VGG input is
    /// not four whole pixels a feature cell, `GAST_VGG_WINDOW=0`, or a view
    /// needed more than `MAX_WINDOW_SHARE` of the frame.
    window_off: bool,
    gcfm_ws: GcfmWorkspace,
    content: ContentLoss,
    feature_mean: FeatureMeanLoss,
    /// Whether λ_mean is above 0 (the term is recorded only then).
    feature_mean_on: bool,
    /// λ_sw's and λ_swd's terms (RGB, depth), planned only when the weight
    /// was above 0 (a plan without one is remade when it turns on,
    /// [`StepLossPlan::fits`]), recorded only while it is.
    sliced: [Option<SlicedLoss>; 2],
    sliced_on: [bool; 2],
    /// λ_GC baked into the GCFM workspace.
    gcfm_weight: f32,
    /// The whole frame (all-ones masks), the focus when none is given.
    frame: GpuFocus,
    /// Render and feature sizes, `(h, w)` and `(fh, fw)`.
    sizes: [(usize, usize); 2],
    rgb: wgpu::Buffer,
    depth3: wgpu::Buffer,
    edge3: wgpu::Buffer,
    small: [wgpu::Buffer; 3],
    v_feat: [wgpu::Buffer; 2],
    v_small: [wgpu::Buffer; 2],
    v_rgb: wgpu::Buffer,
    v_depth3: wgpu::Buffer,
    v_inv_depth: wgpu::Buffer,
    feature_len: usize,
}

impl StepLossPlan {
    /// Plans the loss of `h × w` renders against `style` with `weights`.
    pub fn new(
        ctx: &GpuContext,
        k: &StepLossKernels,
        style: &GpuStyle,
        h: usize,
        w: usize,
        weights: &LossWeights,
    ) -> Result<Self, GpuError> {
        let (sh, sw) = (h / 2, w / 2);
        let states = [GpuVggState::new(ctx, sh, sw), GpuVggState::new(ctx, sh, sw), GpuVggState::new(ctx, sh, sw)];
        let (fh, fw) = states[0].feature_size();
        let positions = fh * fw;
        let feature_len = positions * crate::vision::vgg::FEATURE_CHANNELS;
        Ok(Self {
            clamp: Clamp01::new(ctx, &k.resize, h * w * 3),
            down: Downscale::new(ctx, &k.resize, h, w, 3),
            depth_map: DepthMap::new(ctx, &k.depth, &k.reduce, h, w)?,
            relief: None,
            edges: EdgeMap::new(ctx, &k.canny, &k.reduce, h, w)?,
            tv: TvLoss::new(ctx, &k.losses, &k.reduce, h, w, 3, weights.tv, slot::TV)?,
            depth_l1: RefLoss::depth_l1(ctx, &k.losses, &k.reduce, h * w, weights.depth, slot::DEPTH)?,
            hold: RefLoss::hold(ctx, &k.losses, &k.reduce, h * w, weights.outside, slot::OUTSIDE)?,
            hold_on: weights.outside > 0.0,
            palette: PaletteLoss::new(ctx, &k.reduce, h * w, weights.palette, slot::PALETTE)?,
            palette_on: weights.palette > 0.0,
            vgg_ws: k.vgg.workspace(ctx, sh, sw),
            gcfm_ws: k.gcfm.workspace(ctx, style, positions, slot::GCFM, weights.gcfm),
            content: ContentLoss::new(ctx, &k.reduce, feature_len, positions, weights.content, slot::CONTENT)?,
            feature_mean: FeatureMeanLoss::new(
                ctx,
                &k.reduce,
                style.rgb_mean(),
                positions,
                weights.feature_mean,
                slot::FEATURE_MEAN,
            )?,
            feature_mean_on: weights.feature_mean > 0.0,
            sliced: [
                sliced_term(ctx, k, style, 0, weights.sliced, positions, slot::SLICED)?,
                sliced_term(ctx, k, style, 1, weights.sliced_depth, positions, slot::SLICED_DEPTH)?,
            ],
            sliced_on: [weights.sliced > 0.0, weights.sliced_depth > 0.0],
            gcfm_weight: weights.gcfm,
            frame: GpuFocus::frame(ctx, h, w, fh, fw),
            sizes: [(h, w), (fh, fw)],
            states,
            window: None,
            window_off: !windows_allowed([(h, w), (fh, fw)]),
            rgb: ctx.zeros("loss.rgb", h * w * 3),
            depth3: ctx.zeros("loss.depth3", h * w * 3),
            edge3: ctx.zeros("loss.edge3", h * w * 3),
            small: std::array::from_fn(|_| ctx.zeros("loss.small", sh * sw * 3)),
            v_feat: std::array::from_fn(|_| ctx.zeros("loss.v_feat", feature_len)),
            v_small: std::array::from_fn(|_| ctx.zeros("loss.v_small", sh * sw * 3)),
            v_rgb: ctx.zeros("loss.v_rgb", h * w * 3),
            v_depth3: ctx.zeros("loss.v_depth3", h * w * 3),
            v_inv_depth: ctx.zeros("loss.v_inv_depth", h * w),
            feature_len,
        })
    }

    /// Floats of one feature map (768 × h/8 × w/8), the size of a content target.
    pub fn feature_len(&self) -> usize {
        self.feature_len
    }

    /// The relu3 feature grid of a render, rows × columns.
    pub fn feature_size(&self) -> (usize, usize) {
        self.sizes[1]
    }

    /// Makes the object-focus VGG window hold the covered box `b` (feature
    /// cells) of a view: grows it when `b` with its margin does not fit,
    /// or turns windows off for this plan when the window would cover more
    /// than `MAX_WINDOW_SHARE` (0.8) of the frame. The engine calls it when it
    /// makes a view's targets; [`StepInputs::window`] then names the box.
    pub fn fit_window(&mut self, ctx: &GpuContext, k: &StepLossKernels, b: Region) {
        if self.window_off || self.window.as_ref().is_some_and(|w| w.holds(b)) {
            return;
        }
        let (fh, fw) = self.sizes[1];
        let size = WindowSize::grown(self.window.as_ref().map(VggWindow::size), b, fh, fw);
        self.window = None;
        if size.share(fh, fw) > MAX_WINDOW_SHARE {
            self.window_off = true;
        } else {
            self.window = Some(VggWindow::new(ctx, &k.vgg, (fh, fw), size));
        }
    }

    /// Turns the VGG window off (the whole frame, as before it existed), or
    /// back on for the views fitted after.
    pub fn set_window_enabled(&mut self, on: bool) {
        self.window = None;
        self.window_off = !on || !windows_allowed(self.sizes);
    }

    /// Which of the RGB, depth and edge maps' whole-frame VGG states have
    /// made their activations (a pass ran on the whole frame).
    #[cfg(test)]
    fn whole_frame_activations(&self) -> [bool; 3] {
        self.states.each_ref().map(GpuVggState::has_activations)
    }

    /// The VGG window's size, when the plan has one.
    pub fn window_size(&self) -> Option<WindowSize> {
        self.window.as_ref().map(VggWindow::size)
    }

    /// The window this step's VGG passes run on, placed over the view's
    /// covered box (its copies' uniforms written for the next submission),
    /// or `None` for the whole frame.
    fn window_for(&self, ctx: &GpuContext, inputs: &StepInputs<'_>) -> Option<&VggWindow> {
        let b = inputs.window.filter(|_| inputs.focus.is_some())?;
        let win = self.window.as_ref().filter(|w| w.holds(b))?;
        win.place(ctx, b);
        Some(win)
    }

    /// VGG's forward pass of map `m` (0 RGB, 1 depth, 2 edge) into `states[m]`'s features.
    fn vgg_forward(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        win: Option<&VggWindow>,
        m: usize,
    ) {
        match win {
            Some(win) => win.forward(ctx, &k.window, &k.vgg, enc, m, &self.small[m], self.states[m].features()),
            None => k.vgg.forward(ctx, enc, &self.vgg_ws, &self.small[m], &self.states[m]),
        }
    }

    /// VGG's backward pass of map `m` (0 RGB, 1 depth), `v_feat[m]` to `v_small[m]`.
    fn vgg_backward(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        win: Option<&VggWindow>,
        m: usize,
    ) {
        match win {
            Some(win) => win.backward(ctx, &k.window, &k.vgg, enc, m, &self.v_feat[m], &self.v_small[m]),
            None => k.vgg.backward(ctx, enc, &self.vgg_ws, &self.states[m], &self.v_feat[m], &self.v_small[m]),
        }
    }

    /// Makes VGG see the depth map's relief at `radius` pixels instead of the
    /// normalised depth ([`crate::style::relief`]; 0: the depth, as the
    /// paper), from the next recording on. Its workspace is planned when it
    /// turns on or its radius changes, and dropped when it turns off.
    pub fn set_relief(&mut self, ctx: &GpuContext, k: &StepLossKernels, radius: usize) -> Result<(), GpuError> {
        if radius == 0 {
            self.relief = None;
        } else if self.relief.as_ref().is_none_or(|r| r.radius() != radius) {
            let (h, w) = self.sizes[0];
            self.relief = Some(DepthRelief::new(ctx, k.relief(ctx), &k.reduce, h, w, radius)?);
        }
        Ok(())
    }

    /// Whether this plan serves `w`: the λ_GC it was made with (baked into
    /// the GCFM workspace), and the sliced terms planned where their weight is on.
    pub fn fits(&self, w: &LossWeights) -> bool {
        self.gcfm_weight == w.gcfm
            && (w.sliced == 0.0 || self.sliced[0].is_some())
            && (w.sliced_depth == 0.0 || self.sliced[1].is_some())
    }

    /// Changes λ_TV, λ_d, λ_cont, λ_mean, λ_out and λ_pal (from the next submission on).
    pub fn set_weights(&mut self, ctx: &GpuContext, w: &LossWeights) {
        self.palette.set_weight(ctx, w.palette);
        self.palette_on = w.palette > 0.0;
        self.tv.set_weight(ctx, w.tv);
        self.depth_l1.set_weight(ctx, w.depth);
        self.hold.set_weight(ctx, w.outside);
        self.hold_on = w.outside > 0.0;
        self.content.set_weight(ctx, w.content);
        self.feature_mean.set_weight(ctx, w.feature_mean);
        self.feature_mean_on = w.feature_mean > 0.0;
        for (m, weight) in [w.sliced, w.sliced_depth].into_iter().enumerate() {
            if let Some(term) = &self.sliced[m] {
                term.set_weight(ctx, weight);
            }
            self.sliced_on[m] = weight > 0.0 && self.sliced[m].is_some();
        }
    }

    /// The palette hold's reference for the next submission: the
    /// colour-matched render's palette of the view it steps on.
    pub fn set_palette_reference(&self, ctx: &GpuContext, reference: &crate::style::palette::Palette) {
        self.palette.set_reference(ctx, reference);
    }

    /// After [`StepLossPlan::record`]: the gradient w.r.t. the raw render's
    /// colour (the clamp's mask applied), `h × w × 3`.
    pub fn v_rgb(&self) -> &wgpu::Buffer {
        &self.v_rgb
    }

    /// After [`StepLossPlan::record`]: the gradient w.r.t. the inverse depth, `h × w`.
    pub fn v_inv_depth(&self) -> &wgpu::Buffer {
        &self.v_inv_depth
    }

    /// After [`StepLossPlan::record`]: the GCFM matches (`y+` of every
    /// rendered feature position, then `y−`).
    pub fn matches(&self) -> &wgpu::Buffer {
        self.gcfm_ws.matches()
    }

    /// After [`StepLossPlan::record_features`]: the RGB render's features,
    /// `channels × positions` (channel-major).
    pub fn rgb_features(&self) -> &wgpu::Buffer {
        self.states[0].features()
    }

    /// Feature positions of a render (relu3 height × width).
    pub fn positions(&self) -> usize {
        self.gcfm_ws.positions()
    }

    /// The GCFM search of this plan's rendered positions at `positions` only
    /// ([`GpuGcfm::subset`]).
    pub fn gcfm_subset(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        style: &GpuStyle,
        positions: &[u32],
    ) -> GcfmSubset {
        k.gcfm.subset(ctx, &self.gcfm_ws, style, positions)
    }

    /// Records the object focus of a render with alpha `alpha` (`h × w`):
    /// the masks and counts the loss uses with it ([`GpuFocus::from_alpha`]).
    pub fn record_focus(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        alpha: &wgpu::Buffer,
    ) -> Result<GpuFocus, GpuError> {
        GpuFocus::from_alpha(ctx, &k.focus, &k.reduce, enc, alpha, self.sizes[0], self.sizes[1])
    }

    /// Records into `out` (`feature_len` floats) the content target of a raw
    /// render: the features of the clamped, downscaled image.
    pub fn record_content_target(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        rgb_raw: &wgpu::Buffer,
        out: &wgpu::Buffer,
    ) {
        let held = self.record_content_target_in_place(ctx, k, enc, rgb_raw);
        enc.encoder().copy_buffer_to_buffer(held, 0, out, 0, (self.feature_len * 4) as u64);
    }

    /// Records the content target of a raw render as
    /// [`StepLossPlan::record_content_target`] does, but leaves it in the
    /// plan's own buffer, which it returns: valid until the plan's next VGG
    /// pass (the engine copies it or reads back the columns it keeps).
    pub fn record_content_target_in_place(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        rgb_raw: &wgpu::Buffer,
    ) -> &wgpu::Buffer {
        self.clamp.forward(ctx, enc, rgb_raw, &self.rgb);
        self.down.forward(ctx, enc, &self.rgb, &self.small[0]);
        k.vgg.forward(ctx, enc, &self.vgg_ws, &self.small[0], &self.states[2]);
        self.states[2].features()
    }

    /// Records the whole loss of one render ([`StepInputs`]); `search`
    /// where the GCFM matches come from (a search of every position or of a
    /// subset, or the ones [`StepLossPlan::matches`] holds). The unweighted
    /// terms go to the inputs' `scalars` ([`slot`]), the gradients of the
    /// weighted total to [`StepLossPlan::v_rgb`] and [`StepLossPlan::v_inv_depth`].
    pub fn record(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        style: &GpuStyle,
        inputs: &StepInputs<'_>,
        search: Search<'_>,
    ) {
        self.record_features(ctx, k, enc, inputs);
        self.record_feature_losses(ctx, k, enc, style, inputs, search);
        self.record_backward(ctx, k, enc, inputs, None);
    }

    /// The first of [`StepLossPlan::record`]'s three parts: the three maps VGG sees and
    /// their features ([`StepLossPlan::rgb_features`] holds the RGB ones):
    /// [`StepLossPlan::record_rgb_features`] then
    /// [`StepLossPlan::record_other_features`].
    pub fn record_features(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        inputs: &StepInputs<'_>,
    ) {
        self.record_rgb_features(ctx, k, enc, inputs);
        self.record_other_features(ctx, k, enc, inputs);
    }

    /// The RGB map VGG sees and its features, all the assignment terms'
    /// gather needs: the engine submits it with the gather, so the host
    /// pairs while the device goes on with the other maps.
    pub fn record_rgb_features(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        inputs: &StepInputs<'_>,
    ) {
        self.clamp.forward(ctx, enc, inputs.rgb_raw, &self.rgb);
        self.down.forward(ctx, enc, &self.rgb, &self.small[0]);
        self.vgg_forward(ctx, k, enc, self.window_for(ctx, inputs), 0);
    }

    /// After [`StepLossPlan::record_rgb_features`]: the depth and edge maps
    /// VGG sees and their features.
    pub fn record_other_features(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        inputs: &StepInputs<'_>,
    ) {
        let focus = inputs.focus.unwrap_or(&self.frame);
        self.depth_map.forward(ctx, enc, inputs.inv_depth, focus.pixels(), &self.depth3);
        if let Some(relief) = &self.relief {
            relief.forward(ctx, enc, focus.pixels(), &self.depth3);
        }
        self.down.forward(ctx, enc, &self.depth3, &self.small[1]);
        match inputs.edge {
            Some(e) => self.down.forward(ctx, enc, e, &self.small[2]),
            None => {
                self.edges.record(ctx, enc, &self.rgb, &self.edge3);
                self.down.forward(ctx, enc, &self.edge3, &self.small[2]);
            }
        }
        let win = self.window_for(ctx, inputs);
        for m in 1..3 {
            self.vgg_forward(ctx, k, enc, win, m);
        }
    }

    /// After [`StepLossPlan::record_features`] (in this encoder or an
    /// earlier submission): the losses in feature space and their gradients
    /// w.r.t. the features: GCFM (gradients scaled by λ_GC), then content,
    /// the feature-mean term and the sliced terms (λ_sw on the RGB features on
    /// every step, λ_swd on the depth's where its gradient is taken). The
    /// engine submits them apart from [`StepLossPlan::record_backward`] when
    /// the assignment terms pair on the host in between.
    pub fn record_feature_losses(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        style: &GpuStyle,
        inputs: &StepInputs<'_>,
        search: Search<'_>,
    ) {
        let (focus, scalars) = (inputs.focus.unwrap_or(&self.frame), inputs.scalars);
        let feats = [self.states[0].features(), self.states[1].features(), self.states[2].features()];
        k.gcfm.record(ctx, enc, &self.gcfm_ws, style, feats, focus, &self.v_feat[0], &self.v_feat[1], scalars, search);
        if let Some(target) = inputs.content {
            self.content.record(ctx, enc, feats[0], target, inputs.content_columns, focus, &self.v_feat[0], scalars);
        }
        if self.feature_mean_on {
            self.feature_mean.record(ctx, enc, feats[0], focus, &self.v_feat[0], scalars);
        }
        for (m, wanted) in [(0, true), (1, inputs.depth_grad)] {
            let term = self.sliced[m].as_ref().filter(|_| wanted && self.sliced_on[m]);
            if let (Some(term), Some(target)) = (term, style.sliced(m)) {
                term.record(ctx, enc, target, feats[m], focus, &self.v_feat[m], scalars);
            }
        }
    }

    /// After [`StepLossPlan::record_feature_losses`]: the gradients back to
    /// the render, [`StepLossPlan::record_backward_rgb`] then
    /// [`StepLossPlan::record_backward_depth`].
    pub fn record_backward(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        inputs: &StepInputs<'_>,
        assign: Option<&GpuAssignment>,
    ) {
        self.record_backward_rgb(ctx, k, enc, inputs, assign);
        self.record_backward_depth(ctx, k, enc, inputs);
    }

    /// After [`StepLossPlan::record_feature_losses`]: the assignment terms'
    /// gradient added to the RGB features' (`assign`), then the RGB
    /// gradient through VGG back to the render, with TV, the hold, the
    /// palette hold (with an object focus, against
    /// [`StepLossPlan::set_palette_reference`]) and the clamp's mask on the way.
    pub fn record_backward_rgb(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        inputs: &StepInputs<'_>,
        assign: Option<&GpuAssignment>,
    ) {
        let (object, scalars) = (inputs.focus, inputs.scalars);
        let focus = object.unwrap_or(&self.frame);
        if let Some(a) = assign {
            a.record_scatter(ctx, enc, &self.v_feat[0]);
        }
        self.vgg_backward(ctx, k, enc, self.window_for(ctx, inputs), 0);
        self.down.backward(ctx, enc, &self.v_small[0], &self.v_rgb, false);
        self.tv.record(ctx, enc, &self.rgb, focus, &self.v_rgb, scalars);
        if let Some(reference) = inputs.hold.filter(|_| self.hold_on) {
            self.hold.record(ctx, enc, &self.rgb, reference, &self.v_rgb, scalars);
        }
        if let Some(object) = object.filter(|_| self.palette_on) {
            self.palette.record(ctx, enc, &self.rgb, object.pixels(), &self.v_rgb, scalars);
        }
        self.clamp.backward(ctx, enc, inputs.rgb_raw, &self.v_rgb);
    }

    /// After [`StepLossPlan::record_feature_losses`]: the depth features'
    /// gradient back to the inverse depth (zero when the inputs' `depth_grad`
    /// is off), and the depth terms. It does not depend on the assignment
    /// terms, so the engine records it before it waits for their host pairing.
    pub fn record_backward_depth(
        &self,
        ctx: &GpuContext,
        k: &StepLossKernels,
        enc: &mut dyn Commands,
        inputs: &StepInputs<'_>,
    ) {
        let focus = inputs.focus.unwrap_or(&self.frame);
        if inputs.depth_grad {
            self.vgg_backward(ctx, k, enc, self.window_for(ctx, inputs), 1);
            self.down.backward(ctx, enc, &self.v_small[1], &self.v_depth3, false);
            let pixels = focus.pixels();
            if let Some(relief) = &self.relief {
                relief.backward(ctx, enc, pixels, &self.v_depth3);
            }
            self.depth_map.backward(ctx, enc, inputs.inv_depth, pixels, &self.v_depth3, &self.v_inv_depth, false);
        } else {
            enc.encoder().clear_buffer(&self.v_inv_depth, 0, None);
        }
        if let Some(d) = inputs.depth_ref {
            self.depth_l1.record(ctx, enc, inputs.inv_depth, d, &self.v_inv_depth, inputs.scalars);
        }
    }
}

/// What one step's loss reads and writes beside its plan: the render's maps,
/// the view's targets, the focus and the scalars.
#[derive(Clone, Copy, Debug)]
pub struct StepInputs<'a> {
    /// The render's colour, `h × w × 3`, before the clamp.
    pub rgb_raw: &'a wgpu::Buffer,
    /// The render's inverse depth, `h × w`.
    pub inv_depth: &'a wgpu::Buffer,
    /// The render's edge map (`h × w × 3`) when given, else computed from the clamped render.
    pub edge: Option<&'a wgpu::Buffer>,
    /// The content target ([`StepLossPlan::record_content_target`]) when the step uses one.
    pub content: Option<&'a wgpu::Buffer>,
    /// Where its columns lie when it holds the covered positions' alone
    /// ([`super::content::ContentColumns::of`]); `None` for a whole map.
    pub content_columns: Option<&'a wgpu::Buffer>,
    /// The inverse depth of `G^c`, when the depth regulariser acts.
    pub depth_ref: Option<&'a wgpu::Buffer>,
    /// The background hold's reference ([`RefLoss::hold_reference`]), used when λ_out > 0.
    pub hold: Option<&'a wgpu::Buffer>,
    /// Whether the depth map's gradient is taken (geometry steps).
    pub depth_grad: bool,
    /// The object focus ([`StepLossPlan::record_focus`]); the whole frame without one.
    pub focus: Option<&'a GpuFocus>,
    /// With the focus, the bounding box of its covered feature cells: VGG
    /// then runs on the window around it, when the plan has one that holds
    /// it ([`StepLossPlan::fit_window`]); else, or without it, on the whole frame.
    pub window: Option<Region>,
    /// Where the unweighted terms go ([`slot`]).
    pub scalars: &'a wgpu::Buffer,
}

/// Whether a plan for `h × w` renders (relu3 grid `fh × fw`) may run VGG on
/// a window: its VGG input (the half-size render) is four whole pixels a
/// feature cell, so a window's pools fall as the frame's, and
/// `GAST_VGG_WINDOW` is not `0`.
fn windows_allowed([(h, w), (fh, fw)]: [(usize, usize); 2]) -> bool {
    h / 2 == 4 * fh && w / 2 == 4 * fw && !std::env::var("GAST_VGG_WINDOW").is_ok_and(|v| v == "0")
}

/// The sliced term of modality `m` (0 RGB, 1 depth) when its weight is on.
fn sliced_term(
    ctx: &GpuContext,
    k: &StepLossKernels,
    style: &GpuStyle,
    m: usize,
    weight: f32,
    positions: usize,
    at: usize,
) -> Result<Option<SlicedLoss>, GpuError> {
    if weight <= 0.0 {
        return Ok(None);
    }
    let target = style.sliced(m).ok_or_else(|| {
        GpuError::TooLarge(format!(
            "the sliced term {m} is on but its style target was not uploaded (GpuStyle::upload_sliced)"
        ))
    })?;
    SlicedLoss::new(ctx, &k.sliced, &k.reduce, target, positions, weight, at).map(Some)
}

/// The whole per-step loss of uploaded maps on the GPU, read back: the twin
/// of [`crate::style::step::step_loss_masked`] (same arguments, but the
/// content target is the colour-matched *image*, whose features are computed
/// here, and the focus is given by the alpha its mask is made from,
/// [`crate::style::focus::coverage_mask`]). A focus that covers no feature
/// position falls back to the whole frame, as on the CPU. For checks against
/// the CPU and the golden files, not for the loop.
#[allow(clippy::too_many_arguments)]
pub fn step_loss_gpu(
    ctx: &GpuContext,
    k: &StepLossKernels,
    style: &StyleTargets,
    maps: RenderedMaps<'_>,
    content_rgb: Option<&[f32]>,
    depth_ref: Option<&[f32]>,
    weights: &LossWeights,
    depth_grad: bool,
    focus_alpha: Option<&[f32]>,
) -> Result<StepLoss, GpuError> {
    step_loss_gpu_windowed(ctx, k, style, maps, content_rgb, depth_ref, weights, depth_grad, focus_alpha, true)
        .map(|(loss, _)| loss)
}

/// [`step_loss_gpu`], with VGG on the focus's window where the plan allows
/// one (`window`, as the engine and the CPU do) or on the whole frame; with
/// the plan it ran on.
#[allow(clippy::too_many_arguments)]
pub(crate) fn step_loss_gpu_windowed(
    ctx: &GpuContext,
    k: &StepLossKernels,
    style: &StyleTargets,
    maps: RenderedMaps<'_>,
    content_rgb: Option<&[f32]>,
    depth_ref: Option<&[f32]>,
    weights: &LossWeights,
    depth_grad: bool,
    focus_alpha: Option<&[f32]>,
    window: bool,
) -> Result<(StepLoss, StepLossPlan), GpuError> {
    let (h, w) = (maps.height, maps.width);
    let mut gstyle = GpuStyle::new(ctx, &style.features);
    gstyle.upload_sliced(ctx, &style.features, weights);
    let mut plan = StepLossPlan::new(ctx, k, &gstyle, h, w, weights)?;
    plan.set_window_enabled(window);
    let rgb = ctx.upload("loss.in.rgb", maps.rgb);
    let inv_depth = ctx.upload("loss.in.inv_depth", maps.inv_depth);
    let edge = ctx.upload("loss.in.edge", &replicate3(maps.edge));
    let scalars = ctx.zeros("loss.scalars", slot::LEN);
    let focus = match focus_alpha {
        Some(a) => {
            let mut enc = ctx.encoder("step_loss_gpu.focus");
            let f = plan.record_focus(ctx, k, &mut enc, &ctx.upload("loss.in.alpha", a))?;
            ctx.submit(enc);
            (f.covered_cells(ctx)? > 0).then_some(f)
        }
        None => None,
    };
    let mut covered_cells = None;
    let mut window_box = None;
    if let Some(f) = &focus {
        let covered = f.covered_mask(ctx)?;
        let (fh, fw) = plan.feature_size();
        window_box = crate::style::window::covered_box(&covered, fh, fw);
        if let Some(b) = window_box {
            plan.fit_window(ctx, k, b);
        }
        covered_cells = Some(covered);
    }
    let mut enc = ctx.encoder("step_loss_gpu");
    let content = content_rgb.map(|c| {
        let image = ctx.upload("loss.in.content", c);
        let target = ctx.zeros("loss.content_target", plan.feature_len());
        plan.record_content_target(ctx, k, &mut enc, &image, &target);
        target
    });
    let dref = depth_ref.map(|d| ctx.upload("loss.in.depth_ref", d));
    let inputs = StepInputs {
        rgb_raw: &rgb,
        inv_depth: &inv_depth,
        edge: Some(&edge),
        content: content.as_ref(),
        content_columns: None,
        depth_ref: dref.as_ref(),
        hold: None,
        depth_grad,
        focus: focus.as_ref(),
        window: window_box,
        scalars: &scalars,
    };
    plan.record(ctx, k, &mut enc, &gstyle, &inputs, Search::Every);
    ctx.submit(enc);
    let s: Vec<f32> = ctx.read(&scalars)?;
    let mut m: Vec<u32> = ctx.read(plan.matches())?;
    let n = m.len() / 2;
    if let Some(covered) = &covered_cells {
        // As the CPU: no matches where the focus does not look.
        for x in (0..n).filter(|&x| !covered[x]) {
            (m[x], m[n + x]) = (u32::MAX, u32::MAX);
        }
    }
    let gcfm = s[slot::GCFM + 3];
    let content_value = if content.is_some() { s[slot::CONTENT] } else { 0.0 };
    let depth_value = if dref.is_some() { s[slot::DEPTH] } else { 0.0 };
    let tv = s[slot::TV];
    let feature_mean = if weights.feature_mean > 0.0 { s[slot::FEATURE_MEAN] } else { 0.0 };
    let mut terms = LossTerms {
        gcfm,
        content: content_value,
        tv,
        depth: depth_value,
        feature_mean,
        sliced: if weights.sliced > 0.0 { s[slot::SLICED] } else { 0.0 },
        sliced_depth: if weights.sliced_depth > 0.0 && depth_grad { s[slot::SLICED_DEPTH] } else { 0.0 },
        ..LossTerms::default()
    };
    terms.total = terms.weighted(weights);
    let loss = StepLoss {
        timings: StepLossTimings::default(),
        // No background hold in this check helper (nor in its CPU twin), nor
        // the assignment terms (the engine's own, `GpuAssignment`).
        terms,
        v_rgb: ctx.read(plan.v_rgb())?,
        v_inv_depth: ctx.read(plan.v_inv_depth())?,
        matches: Matches { best: m[..n].to_vec(), worst: m[n..2 * n].to_vec() },
    };
    Ok((loss, plan))
}

#[cfg(test)]
#[path = "step_loss_tests.rs"]
mod tests;
