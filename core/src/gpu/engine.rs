//! One whole optimisation step on the GPU: the GPU twin of
//! [`crate::session::Session::step`]'s CPU path, with nothing read back but
//! a few loss scalars.
//!
//! The session keeps what is the same on both devices (the schedule, the view
//! sampler, colour matching, culling, Stage 1 of the style) and hands the step
//! to a [`GpuEngine`] when it runs on the GPU. The engine holds the optimised
//! Gaussians and the frozen colour-matched ones (`G^c`) in device buffers, the
//! Adam states, the style's features, per-view targets (the content features,
//! the inverse depth and the object focus of `G^c`), and one [`ViewPlan`] of
//! scratch buffers per image size. A step records, in one command encoder: render → clamp →
//! 0.5× downscale; the depth map and the edge map; three VGG forwards; GCFM;
//! content; the two VGG backwards and the image-space adjoints; TV and the
//! depth regulariser; the rasterizer's backward; the parameter regularisers
//! and Adam. It then reads back the scalars buffer: the loss terms and the
//! number of (tile, splat) pairs the render needed.

use crate::style::config::ParamRegulariser;
use std::collections::HashMap;

use super::Encoder;
use super::adam::AdamKernel;
use super::assignment::GpuAssignment;
use super::bind_cache::BindCache;
use super::content::ContentColumns;
use super::step_loss::{StepInputs, StepLossKernels, StepLossPlan, slot};
use super::{
    GcfmSubset, GpuAdam, GpuContext, GpuError, GpuFocus, GpuGaussians, GpuGrads, GpuLeak, GpuRaster, GpuStyle,
    RasterKernels, RefLoss, Search,
};
use crate::camera::Camera;
use crate::eval::stability::CoveredColour;
use crate::raster::{RenderOptions, ShGrads};
use crate::scene::Gaussians;
use crate::style::StyleConfig;
use crate::style::config::LossWeights;
use crate::style::focus::{coverage_mask, gather_positions};
use crate::style::gcfm::StyleFeatures;
use crate::style::outside::outside_mask;
use crate::style::palette::{Palette, palette_of};
use crate::style::schedule::Phase;
use crate::style::terms::LossTerms;
use crate::vision::Vgg;

/// Headroom over the pairs the colour-matched scene needs in its busiest view.
const PAIR_HEADROOM: f64 = 1.5;

/// Kernels compiled once per engine.
struct Kernels {
    raster: RasterKernels,
    loss: StepLossKernels,
    adam: AdamKernel,
}

/// The rasterizer's workspace and the loss's plan for one image size.
struct ViewPlan {
    raster: GpuRaster,
    loss: StepLossPlan,
}

/// What a view's steps compare against, computed once from `G^c`.
struct ViewTarget {
    /// The content features of `G^c`'s render: with the object focus on a
    /// view that covers part of the feature grid, the covered positions'
    /// columns alone (placed by `content_columns`), as the CPU engine keeps.
    content: wgpu::Buffer,
    content_columns: Option<wgpu::Buffer>,
    inv_depth: wgpu::Buffer,
    /// What `G^c` covers from the view (`None` when it covers no feature
    /// position: the losses then look at the whole frame, as on the CPU).
    focus: Option<GpuFocus>,
    /// `G^c`'s covered colour from the view (the colour watch's reference).
    colour: CoveredColour,
    /// The view's last searched GCFM matches and the steps that used them,
    /// when the matching keeps them for several visits
    /// ([`crate::style::MatchingConfig::reuse`], as the CPU session does).
    kept: Option<(wgpu::Buffer, u32)>,
    /// The GCFM search of the covered feature positions only, when the
    /// focus covers at most [`SUBSET_SHARE`] of them.
    subset: Option<GcfmSubset>,
    /// The covered feature positions (with `focus`).
    covered_at: Option<Vec<u32>>,
    /// Their bounding box (feature cells): VGG runs on the window around it.
    window: Option<crate::vision::vgg_cone::Region>,
    /// The background hold's reference ([`RefLoss::hold_reference`]), made
    /// on the first step with λ_out > 0.
    hold: Option<wgpu::Buffer>,
    /// `G^c`'s palette over the covered pixels (λ_pal's reference).
    palette: Palette,
}

/// Mixed into the session's seed for the assignment terms' draws.
const ASSIGN_SEED: u64 = 0xa551_9e00;

/// Above this share of covered feature positions, the object focus searches
/// every position (the gather would cost more than it saves).
const SUBSET_SHARE: f64 = 0.75;

/// One Adam state per parameter group, colour and geometry phases.
struct Optimisers {
    color: GpuAdam,
    means: GpuAdam,
    scales: GpuAdam,
    quats: GpuAdam,
    opacity: GpuAdam,
}

impl Optimisers {
    /// Every group, in the order of [`crate::session::moments::GROUPS`].
    fn groups(&self) -> [&GpuAdam; 5] {
        [&self.color, &self.means, &self.scales, &self.quats, &self.opacity]
    }

    /// [`Optimisers::groups`], to set.
    fn groups_mut(&mut self) -> [&mut GpuAdam; 5] {
        [&mut self.color, &mut self.means, &mut self.scales, &mut self.quats, &mut self.opacity]
    }
}

/// The optimisation state on the device and the step that advances it.
pub struct GpuEngine {
    ctx: GpuContext,
    k: Kernels,
    style: GpuStyle,
    g: GpuGaussians,
    g_ref: GpuGaussians,
    grads: GpuGrads,
    regs: [RefLoss; 3],
    opt: Optimisers,
    plans: HashMap<(u32, u32), ViewPlan>,
    targets: Vec<Option<ViewTarget>>,
    scalars: wgpu::Buffer,
    weights: LossWeights,
    background: [f32; 3],
    /// Whether the losses focus on the object ([`GpuEngine::set_object_focus`]).
    object_focus: bool,
    /// (tile, splat) pairs each new plan's rasterizer holds.
    pair_capacity: usize,
    /// Bytes of device memory the engine allocated.
    bytes: u64,
    /// Warnings for the session to pass on (a render that ran out of pair room).
    warnings: Vec<String>,
    /// One modality's gathered columns for the subset searches (grown to the largest).
    subset_scratch: Option<wgpu::Buffer>,
    /// The assignment terms' workspace, made at the first step with λ_as or λ_asc on.
    assign: Option<GpuAssignment>,
    /// The phase leak's sums ([`StyleConfig::phase_leak`]), made at the first step that leaks.
    leak: Option<GpuLeak>,
    /// The host's share of the last step ([`GpuEngine::host_times`]).
    host: HostTimes,
    /// The steps' bind groups, kept from one step to the next (lent to the
    /// thread while a step records; emptied where the engine drops buffers).
    bind_cache: BindCache,
}

/// What the host spent of one GPU step: the time the device's part timings
/// do not cover.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HostTimes {
    /// The assignment terms' pairing on the host (0 without them).
    pub pairing_ms: f32,
    /// Waiting on the device: for the gathered columns, then for the step's scalars.
    pub wait_ms: f32,
    /// Recording the step's commands (bind groups, passes, uploads): the
    /// host's own work, the same on any adapter, that the device idles
    /// through while the step waits for its scalars at the end.
    pub record_ms: f32,
    /// Handing the command buffers to the queue (`Queue::submit`).
    pub submit_ms: f32,
    /// Bind groups the step made; its other dispatches took groups kept
    /// from earlier steps ([`super::BindCache`]).
    pub bind_groups: u32,
    /// Compute passes the step's dispatches ran in (one per run of
    /// dispatches between copies; one per dispatch with `GAST_GPU_PASSES=each`).
    pub passes: u32,
}

impl GpuEngine {
    /// Uploads the optimised Gaussians (`G^c` restricted to what the cameras
    /// see), the network and the style's features, and sizes the rasterizer
    /// on the busiest of `cameras`.
    pub fn new(
        ctx: &GpuContext,
        vgg: &Vgg,
        g_ref: &Gaussians,
        style: &StyleFeatures,
        cameras: &[Camera],
        config: &StyleConfig,
    ) -> Result<Self, GpuError> {
        let before = ctx.allocated_bytes();
        let k = Kernels {
            raster: RasterKernels::new(ctx),
            loss: StepLossKernels::new(ctx, vgg),
            adam: AdamKernel::new(ctx),
        };
        let g = GpuGaussians::upload(ctx, g_ref);
        let g_ref_gpu = GpuGaussians::upload(ctx, g_ref);
        // The colour steps the DC alone: the backward writes no other SH coefficient's gradient.
        let grads = GpuGrads::with_sh(ctx, &g, ShGrads::Dc);
        let n = g_ref.len();
        let w = &config.weights;
        let reg = |per: usize, weight: f32, offset: usize| match config.param_regulariser {
            ParamRegulariser::Norm => RefLoss::param_l2(ctx, &k.loss.losses, &k.loss.reduce, per * n, weight, offset),
            ParamRegulariser::MeanSquare => {
                RefLoss::param_mean_square(ctx, &k.loss.losses, &k.loss.reduce, per * n, n, weight, offset)
            }
        };
        let regs = [
            reg(1, w.opacity, slot::REG_OPACITY)?,
            reg(3, w.scale, slot::REG_SCALE)?,
            reg(4, w.rotation, slot::REG_ROTATION)?,
        ];
        let sh_stride = (g_ref.sh_coeffs() * 3) as u32;
        let opt = Optimisers {
            color: GpuAdam::strided(ctx, 3 * n, 3, sh_stride, config.adam).with_grad_stride(3),
            means: GpuAdam::new(ctx, 3 * n, config.adam),
            scales: GpuAdam::new(ctx, 3 * n, config.adam),
            quats: GpuAdam::new(ctx, 4 * n, config.adam),
            opacity: GpuAdam::new(ctx, n, config.adam),
        };
        let pair_capacity = busiest_view(ctx, &k.raster, &g_ref_gpu, cameras, config)?;
        let mut gpu_style = GpuStyle::new(ctx, style);
        gpu_style.upload_sliced(ctx, style, &config.weights);
        let style = gpu_style;
        let mut engine = Self {
            ctx: ctx.clone(),
            k,
            style,
            g,
            g_ref: g_ref_gpu,
            grads,
            regs,
            opt,
            plans: HashMap::new(),
            targets: (0..cameras.len()).map(|_| None).collect(),
            scalars: ctx.zeros("engine.scalars", slot::LEN),
            weights: config.weights,
            background: config.background,
            object_focus: false,
            pair_capacity: ((pair_capacity as f64 * PAIR_HEADROOM) as usize).max(4096),
            bytes: 0,
            warnings: Vec::new(),
            subset_scratch: None,
            assign: None,
            leak: None,
            host: HostTimes::default(),
            bind_cache: BindCache::default(),
        };
        engine.bytes = ctx.allocated_bytes().saturating_sub(before);
        Ok(engine)
    }

    /// The context the engine runs on.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Device memory the engine has allocated (parameters, optimiser state,
    /// targets, scratch), in bytes.
    pub fn memory_bytes(&self) -> u64 {
        self.bytes
    }

    /// The optimised Gaussians on the device (for a viewer sharing the device).
    pub fn gaussians(&self) -> &GpuGaussians {
        &self.g
    }

    /// Reads the optimised Gaussians back (snapshots, export).
    pub fn download(&self) -> Result<Gaussians, GpuError> {
        self.g.download(&self.ctx)
    }

    /// Sets the optimised Gaussians to `g` (as many, same SH degree as at
    /// [`GpuEngine::new`]): a resumed run's state. The optimiser's moments
    /// are left as they are.
    pub fn set_gaussians(&mut self, g: &Gaussians) {
        self.g.write(&self.ctx, g);
    }

    /// Each parameter group's optimiser state, read back, in the order of
    /// [`crate::session::moments::GROUPS`].
    pub fn optimiser_state(&self) -> Result<Vec<crate::style::adam::AdamState>, GpuError> {
        self.opt.groups().into_iter().map(|a| a.state(&self.ctx)).collect()
    }

    /// Goes on from `groups` (as [`GpuEngine::optimiser_state`] gives them).
    pub fn set_optimiser_state(&mut self, groups: &[crate::style::adam::AdamState]) -> Result<(), String> {
        let adams = self.opt.groups_mut();
        if groups.len() != adams.len() {
            return Err(format!("expected {} parameter groups, found {}", adams.len(), groups.len()));
        }
        for (adam, g) in adams.into_iter().zip(groups) {
            adam.set_state(&self.ctx, g)?;
        }
        Ok(())
    }

    /// The phase leak's sums read back (`None` before the first leaking step
    /// or with the leak off), in the order of the optimiser's groups.
    pub fn leak_sums(&self) -> Result<Option<Vec<Vec<f32>>>, GpuError> {
        self.leak.as_ref().map(|l| l.read(&self.ctx)).transpose()
    }

    /// Goes on from the phase leak's sums `sums` (as [`GpuEngine::leak_sums`]
    /// gives them): a resumed run's, before its first step.
    pub fn set_leak_sums(&mut self, sums: &[Vec<f32>]) -> Result<(), String> {
        let leak = self.leak.get_or_insert_with(|| GpuLeak::new(&self.ctx, &self.grads));
        leak.write(&self.ctx, sums)
    }

    /// Warnings raised since the last call.
    pub fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.warnings)
    }

    /// New style features (a new texture scale or depth polarity), with the
    /// sliced targets `weights` turns on.
    pub fn set_style(&mut self, style: &StyleFeatures, weights: &LossWeights) {
        let before = self.ctx.allocated_bytes();
        self.style = GpuStyle::new(&self.ctx, style);
        self.style.upload_sliced(&self.ctx, style, weights);
        // GCFM workspaces depend on the style's size: rebuild the plans; the
        // views' subset searches and kept matches belong to the old style, so
        // their targets are made anew at their next visit.
        self.plans.clear();
        self.targets.iter_mut().for_each(|t| *t = None);
        self.bind_cache.clear();
        self.bytes += self.ctx.allocated_bytes().saturating_sub(before);
    }

    /// Forgets every view's kept matches (the matching settings changed).
    pub fn forget_matches(&mut self) {
        for t in self.targets.iter_mut().flatten() {
            t.kept = None;
        }
        self.bind_cache.clear();
    }

    /// Empties the phase leak's sums (the leak was turned on or off).
    pub fn reset_leak(&mut self) {
        self.leak = None;
        self.bind_cache.clear();
    }

    /// New cameras (a new working resolution or background): per-view targets are recomputed.
    pub fn reset_views(&mut self, views: usize, background: [f32; 3]) {
        // Plans are per image size: the old size's are not needed any more.
        self.plans.clear();
        self.targets = (0..views).map(|_| None).collect();
        self.background = background;
        self.bind_cache.clear();
    }

    /// Uploads the style's sliced targets that `weights` turns on and the
    /// engine has not uploaded yet (a slider turned λ_sw or λ_swd on): call
    /// before the first step with those weights.
    pub fn upload_style_terms(&mut self, style: &StyleFeatures, weights: &LossWeights) {
        let before = self.ctx.allocated_bytes();
        self.style.upload_sliced(&self.ctx, style, weights);
        self.bytes += self.ctx.allocated_bytes().saturating_sub(before);
    }

    /// Whether the next steps' GCFM, content, TV and depth normalisation look
    /// only at what the colour-matched scene covers from each view (the
    /// session's resolved [`crate::style::Focus`]), or at the whole frame.
    pub fn set_object_focus(&mut self, on: bool) {
        self.object_focus = on;
    }

    /// The share of the frame's feature positions VGG runs on with the
    /// object focus (its window, [`StepLossPlan::fit_window`]), the largest
    /// over the image sizes met; `None` while every plan runs the whole frame.
    pub fn vgg_window_share(&self) -> Option<f64> {
        let share = |p: &ViewPlan| {
            let (fh, fw) = p.loss.feature_size();
            p.loss.window_size().map(|s| s.share(fh, fw))
        };
        self.plans.values().filter_map(share).reduce(f64::max)
    }

    /// The host's share of the last step: its pairing and its waits on the device.
    pub fn host_times(&self) -> HostTimes {
        self.host
    }

    /// The run's step `step` (its index: the assignment terms' draws are
    /// seeded by it) from view `view` seen by `cam` in `phase`; the parts run
    /// back to back on the device, so no stage timings come back (`gast bench
    /// step --device gpu` times them separately), only the host's share
    /// ([`GpuEngine::host_times`]).
    pub fn step(
        &mut self,
        step: u32,
        view: usize,
        cam: &Camera,
        phase: Phase,
        config: &StyleConfig,
        extent: f32,
    ) -> Result<LossTerms, GpuError> {
        let size = (cam.width, cam.height);
        if self.plans.get(&size).is_some_and(|p| !p.loss.fits(&config.weights)) {
            // λ_GC is baked into the GCFM workspace's uniforms; a sliced term
            // turned on needs its workspace.
            self.plans.clear();
        }
        // This step's weights (λ_mean may sit out the geometry steps).
        let w = config.weights_for(phase);
        // The view's plan and targets (which do not depend on the weights).
        self.warm_target(view, cam, &w)?;
        if w != self.weights {
            self.set_weights(&w);
        }
        let Some(Some(target)) = self.targets.get(view) else {
            return Err(GpuError::TooLarge(format!("no target for view {view}")));
        };
        let Some(plan) = self.plans.get_mut(&size) else {
            return Err(GpuError::TooLarge(format!("no plan for {}×{}", size.0, size.1)));
        };
        plan.loss.set_relief(&self.ctx, &self.k.loss, config.depth_relief_px as usize)?;
        let plan = &*plan;
        // The phase leak: a colour step then takes the depth map's gradient
        // too, which reaches the geometry, whose next step applies it.
        let leaking = config.leaks_between_phases();
        if !leaking {
            if self.leak.take().is_some() {
                self.bind_cache.clear();
            }
        } else if self.leak.is_none() {
            self.leak = Some(GpuLeak::new(&self.ctx, &self.grads));
        }
        let (ctx, k) = (&self.ctx, &self.k);
        let allocated = ctx.allocated_bytes();
        let lent = std::mem::take(&mut self.bind_cache).lend(ctx);
        let (started, binds, passes) = (std::time::Instant::now(), ctx.bind_groups_made(), ctx.passes_begun());
        let mut host = HostTimes::default();
        let submit = |host: &mut HostTimes, enc: Encoder| {
            let t = std::time::Instant::now();
            let index = ctx.submit_indexed(enc);
            host.submit_ms += t.elapsed().as_secs_f32() * 1e3;
            index
        };
        let opts = RenderOptions { background: self.background };
        let geometry = phase.updates_geometry();
        let mut enc = ctx.encoder("engine.step");
        enc.clear_buffer(&self.scalars, 0, None);
        plan.raster.forward(ctx, &k.raster, &mut enc, &self.g, cam, &opts);
        let focus = if self.object_focus { target.focus.as_ref() } else { None };
        let inputs = StepInputs {
            rgb_raw: &plan.raster.rgb,
            inv_depth: &plan.raster.inv_depth,
            edge: None,
            content: Some(&target.content),
            content_columns: target.content_columns.as_ref(),
            depth_ref: geometry.then_some(&target.inv_depth),
            // The hold acts with the object focus only, as on the CPU.
            hold: if self.object_focus { target.hold.as_ref() } else { None },
            depth_grad: geometry || (leaking && phase == Phase::Color),
            focus,
            window: focus.and(target.window).filter(|_| config.vgg_window),
            scalars: &self.scalars,
        };
        let holding = inputs.hold.is_some();
        // The palette hold acts with the object focus only, as on the CPU.
        let palette_held = w.palette > 0.0 && focus.is_some();
        if palette_held {
            plan.loss.set_palette_reference(ctx, &target.palette);
        }
        // Matches kept from this view's last visits (copied in), or searched.
        let reuse = config.matching.reuse.max(1);
        let kept = target.kept.as_ref().filter(|(_, uses)| *uses < reuse);
        if let Some((m, _)) = kept {
            enc.copy_buffer_to_buffer(m, 0, plan.loss.matches(), 0, m.size());
        }
        let searched = kept.is_none();
        let search = match (kept, focus.and(target.subset.as_ref()), &self.subset_scratch) {
            (Some(_), _, _) => Search::Kept,
            (None, Some(subset), Some(scratch)) => Search::Subset { subset, scratch },
            _ => Search::Every,
        };
        plan.loss.record_rgb_features(ctx, &k.loss, &mut enc, &inputs);
        // The assignment terms: the drawn columns gathered from the RGB
        // features and submitted first, the depth and edge maps' features and
        // the feature-space losses submitted behind them, so the device runs
        // those and the GCFM search while the host pairs the columns; the
        // pull's gradient joins in the backward pass's submission.
        let assigning = w.assignment > 0.0 || w.assignment_cosine > 0.0;
        let mut gathered = None;
        if assigning {
            let n = plan.loss.positions();
            let covered: Vec<usize> = match focus.and(target.covered_at.as_ref()) {
                Some(at) => at.iter().map(|&i| i as usize).collect(),
                None => (0..n).collect(),
            };
            let style = &self.style;
            let a =
                self.assign.get_or_insert_with(|| GpuAssignment::new(ctx, style.channels(), config.seed ^ ASSIGN_SEED));
            // Seeded by the step, so that a run resumed at a step draws as the whole run did.
            a.reseed(config.seed ^ ASSIGN_SEED ^ u64::from(step).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            a.record_gather(ctx, &mut enc, plan.loss.rgb_features(), n, covered, style.modality(0), style.positions());
            gathered = Some(submit(&mut host, enc));
            enc = ctx.encoder("engine.step.feature_losses");
        }
        plan.loss.record_other_features(ctx, &k.loss, &mut enc, &inputs);
        plan.loss.record_feature_losses(ctx, &k.loss, &mut enc, &self.style, &inputs, search);
        // The depth's backward pass does not need the pairing: it is recorded
        // first, so with the assignment terms it is submitted before the host
        // waits and the device runs it while the host pairs. (It writes its
        // own buffers and slots: the order leaves the results as they were.)
        plan.loss.record_backward_depth(ctx, &k.loss, &mut enc, &inputs);
        if gathered.is_some() {
            submit(&mut host, enc);
            enc = ctx.encoder("engine.step.backward");
        }
        let assign = if assigning { self.assign.as_ref() } else { None };
        plan.loss.record_backward_rgb(ctx, &k.loss, &mut enc, &inputs, assign);
        let keep = if searched && reuse > 1 {
            // The buffer of an earlier search of this view, or a new one.
            let m = match &target.kept {
                Some((m, _)) => m.clone(),
                None => ctx.zeros("engine.target.matches", (plan.loss.matches().size() / 4) as usize),
            };
            enc.copy_buffer_to_buffer(plan.loss.matches(), 0, &m, 0, m.size());
            Some((m, 1))
        } else {
            kept.map(|(m, uses)| (m.clone(), uses + 1))
        };
        let (v_rgb, v_inv_depth) = (plan.loss.v_rgb(), plan.loss.v_inv_depth());
        plan.raster.backward(ctx, &k.raster, &mut enc, &self.g, v_rgb, v_inv_depth, &self.grads);

        // The phase's parameters: regularisers on the raw geometry, then Adam.
        let lr = &config.lr;
        if phase.updates_color() {
            if let Some(leak) = &self.leak {
                leak.take_color(ctx, &mut enc, &self.grads);
            }
            self.opt.color.set_floor(config.color_floor.then_some(crate::style::DC_FLOOR));
            self.opt.color.step(ctx, &k.adam, &mut enc, &self.g.sh, &self.grads.v_sh, lr.color);
        }
        if geometry {
            let (g, r, v) = (&self.g, &self.g_ref, &self.grads);
            self.regs[0].record(
                ctx,
                &mut enc,
                &g.opacity_logits,
                &r.opacity_logits,
                &v.v_opacity_logits,
                &self.scalars,
            );
            self.regs[1].record(ctx, &mut enc, &g.log_scales, &r.log_scales, &v.v_log_scales, &self.scalars);
            self.regs[2].record(ctx, &mut enc, &g.quats, &r.quats, &v.v_quats, &self.scalars);
            if let Some(leak) = &self.leak {
                leak.take_geometry(ctx, &mut enc, v);
            }
            self.opt.means.step(ctx, &k.adam, &mut enc, &g.means, &v.v_means, lr.means_per_extent * extent);
            self.opt.scales.step(ctx, &k.adam, &mut enc, &g.log_scales, &v.v_log_scales, lr.scales);
            self.opt.quats.step(ctx, &k.adam, &mut enc, &g.quats, &v.v_quats, lr.quats);
            self.opt.opacity.step(ctx, &k.adam, &mut enc, &g.opacity_logits, &v.v_opacity_logits, lr.opacity);
        }
        if let Some(leak) = &self.leak {
            // What this step's backward left on the other phase's parameters.
            match phase {
                Phase::Color => leak.add_geometry(ctx, &mut enc, &self.grads),
                Phase::Geometry => leak.add_color(ctx, &mut enc, &self.grads),
                Phase::Joint => {}
            }
        }
        enc.copy_buffer_to_buffer(plan.raster.pair_count(), 0, &self.scalars, (slot::PAIRS * 4) as u64, 4);
        // The pull's gradient is uploaded before this submission runs: the
        // host records the backward pass above while the device still works
        // on the submissions before, then waits for the gathered columns and
        // pairs them.
        let mut pulled = None;
        if let (Some(gathered), Some(a)) = (gathered, self.assign.as_mut()) {
            pulled = Some(a.pull(ctx, gathered, (w.assignment_cosine, w.assignment), config.assign_block as usize)?);
            (host.wait_ms, host.pairing_ms) = a.last_pull_ms();
        }
        submit(&mut host, enc);
        if let Some(Some(t)) = self.targets.get_mut(view) {
            t.kept = keep;
        }
        self.bytes += self.ctx.allocated_bytes().saturating_sub(allocated);

        let waited = std::time::Instant::now();
        let s: Vec<f32> = ctx.read(&self.scalars)?;
        host.wait_ms += waited.elapsed().as_secs_f32() * 1e3;
        let total = started.elapsed().as_secs_f32() * 1e3;
        host.record_ms = (total - host.wait_ms - host.pairing_ms - host.submit_ms).max(0.0);
        host.bind_groups = u32::try_from(ctx.bind_groups_made() - binds).unwrap_or(u32::MAX);
        host.passes = u32::try_from(ctx.passes_begun() - passes).unwrap_or(u32::MAX);
        self.host = host;
        self.bind_cache = lent.finish();
        let pairs = s[slot::PAIRS].to_bits() as usize;
        if pairs > plan.raster.capacity() {
            self.grow_pairs(size, pairs);
        }
        let mut terms = LossTerms {
            gcfm: s[slot::GCFM + 3],
            content: s[slot::CONTENT],
            tv: s[slot::TV],
            depth: if geometry { s[slot::DEPTH] } else { 0.0 },
            feature_mean: if w.feature_mean > 0.0 { s[slot::FEATURE_MEAN] } else { 0.0 },
            outside: if w.outside > 0.0 && holding { s[slot::OUTSIDE] } else { 0.0 },
            palette: if palette_held { s[slot::PALETTE] } else { 0.0 },
            sliced: if w.sliced > 0.0 { s[slot::SLICED] } else { 0.0 },
            sliced_depth: if w.sliced_depth > 0.0 && geometry { s[slot::SLICED_DEPTH] } else { 0.0 },
            assignment: pulled.as_ref().map_or(0.0, |a| a.l2),
            assignment_cosine: pulled.as_ref().map_or(0.0, |a| a.cosine),
            ..LossTerms::default()
        };
        if geometry {
            terms.reg_opacity = s[slot::REG_OPACITY];
            terms.reg_scale = s[slot::REG_SCALE];
            terms.reg_rotation = s[slot::REG_ROTATION];
        }
        terms.total = terms.weighted(&w);
        Ok(terms)
    }

    /// A render needed more (tile, splat) pairs than its workspace holds: the
    /// step dropped the farthest splats of the fullest tiles. Later steps get room.
    fn grow_pairs(&mut self, size: (u32, u32), pairs: usize) {
        self.warnings.push(format!(
            "a {}×{} render needed {pairs} tile-splat pairs, more than the {} reserved; that step dropped some, later steps get room",
            size.0,
            size.1,
            self.plans.get(&size).map_or(0, |p| p.raster.capacity())
        ));
        self.pair_capacity = (pairs as f64 * PAIR_HEADROOM) as usize;
        self.plans.remove(&size);
        self.bind_cache.clear();
    }

    fn set_weights(&mut self, w: &LossWeights) {
        let ctx = &self.ctx;
        for plan in self.plans.values_mut() {
            plan.loss.set_weights(ctx, w);
        }
        self.regs[0].set_weight(ctx, w.opacity);
        self.regs[1].set_weight(ctx, w.scale);
        self.regs[2].set_weight(ctx, w.rotation);
        self.weights = *w;
    }

    fn plan(&self, cam: &Camera, w: &LossWeights) -> Result<ViewPlan, GpuError> {
        let ctx = &self.ctx;
        Ok(ViewPlan {
            raster: GpuRaster::new(ctx, self.g.len, cam.width, cam.height, self.pair_capacity)?
                .with_grad_sh(ShGrads::Dc),
            loss: StepLossPlan::new(ctx, &self.k.loss, &self.style, cam.height as usize, cam.width as usize, w)?,
        })
    }

    /// The content features and inverse depth of `G^c` from view `view`, once.
    /// Makes the plan for `cam`'s size and view `view`'s targets if they do
    /// not exist yet: each step calls it, and benchmarks call it for every view
    /// first so that they time steady steps.
    pub fn warm_target(&mut self, view: usize, cam: &Camera, weights: &LossWeights) -> Result<(), GpuError> {
        let size = (cam.width, cam.height);
        if !self.plans.contains_key(&size) {
            let before = self.ctx.allocated_bytes();
            let plan = self.plan(cam, weights)?;
            self.plans.insert(size, plan);
            self.bytes += self.ctx.allocated_bytes().saturating_sub(before);
        }
        // A target holding the object's content columns alone serves the
        // object focus only: turned to the frame (a slider), it is made again.
        if !self.object_focus
            && self.targets.get(view).is_some_and(|t| t.as_ref().is_some_and(|t| t.content_columns.is_some()))
        {
            self.targets[view] = None;
        }
        if self.targets.get(view).is_none_or(Option::is_none) {
            let before = self.ctx.allocated_bytes();
            self.make_target(view, cam, weights.outside > 0.0)?;
            self.bytes += self.ctx.allocated_bytes().saturating_sub(before);
        }
        // The plan's VGG window holds this view's covered box (a plan made
        // anew, after a view's target, fits it here).
        let window = self.targets[view].as_ref().and_then(|t| t.window);
        if let (Some(b), Some(plan)) = (window, self.plans.get_mut(&size)) {
            let before = self.ctx.allocated_bytes();
            plan.loss.fit_window(&self.ctx, &self.k.loss, b);
            self.bytes += self.ctx.allocated_bytes().saturating_sub(before);
        }
        // λ_out turned on after the target was made (a slider): its hold now.
        if weights.outside > 0.0 && self.targets[view].as_ref().is_some_and(|t| t.hold.is_none()) {
            let before = self.ctx.allocated_bytes();
            let hold = self.make_hold(cam)?;
            if let Some(t) = self.targets[view].as_mut() {
                t.hold = Some(hold);
            }
            self.bytes += self.ctx.allocated_bytes().saturating_sub(before);
        }
        Ok(())
    }

    /// The background hold's reference of the view `cam`, `G^c` rendered
    /// again (the target's own render is gone by now).
    fn make_hold(&self, cam: &Camera) -> Result<wgpu::Buffer, GpuError> {
        let size = (cam.width, cam.height);
        let Some(plan) = self.plans.get(&size) else {
            return Err(GpuError::TooLarge(format!("no plan for {}×{}", size.0, size.1)));
        };
        let (ctx, k) = (&self.ctx, &self.k);
        let opts = RenderOptions { background: self.background };
        let mut enc = ctx.encoder("engine.hold");
        plan.raster.forward(ctx, &k.raster, &mut enc, &self.g_ref, cam, &opts);
        ctx.submit(enc);
        let (rgb, alpha) = self.read_render(cam)?;
        let clamped: Vec<f32> = rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        Ok(self.hold_of(&clamped, &alpha))
    }

    /// The hold's reference from `G^c`'s render (`clamped` to [0, 1]): its
    /// colours and the pixels it leaves empty ([`crate::style::outside`]),
    /// uploaded as `[r, g, b, k]` per pixel.
    fn hold_of(&self, clamped: &[f32], alpha: &[f32]) -> wgpu::Buffer {
        self.ctx.upload("engine.target.hold", &RefLoss::hold_reference(clamped, &outside_mask(alpha)))
    }

    /// The targets of `view` from `G^c`'s render, with the hold's when `hold`.
    fn make_target(&mut self, view: usize, cam: &Camera, hold: bool) -> Result<(), GpuError> {
        let size = (cam.width, cam.height);
        let Some(plan) = self.plans.get(&size) else {
            return Err(GpuError::TooLarge(format!("no plan for {}×{}", size.0, size.1)));
        };
        let (ctx, k) = (&self.ctx, &self.k);
        let opts = RenderOptions { background: self.background };
        let inv_depth = ctx.zeros("engine.target.inv_depth", (cam.width * cam.height) as usize);
        let mut enc = ctx.encoder("engine.target");
        plan.raster.forward(ctx, &k.raster, &mut enc, &self.g_ref, cam, &opts);
        let held = plan.loss.record_content_target_in_place(ctx, &k.loss, &mut enc, &plan.raster.rgb);
        enc.copy_buffer_to_buffer(&plan.raster.inv_depth, 0, &inv_depth, 0, u64::from(cam.width * cam.height) * 4);
        let focus = plan.loss.record_focus(ctx, &k.loss, &mut enc, &plan.raster.alpha)?;
        ctx.submit(enc);
        // One scalar per view, once: a view the scene does not cover falls back to the frame.
        let covered = focus.covered_cells(ctx)?;
        let focus = (covered > 0).then_some(focus);
        // The covered positions' list, read once: with few of them, the GCFM
        // search looks at those only; the assignment terms draw from them;
        // their bounding box places VGG's window.
        let positions = plan.loss.positions();
        let (covered_at, window) = match &focus {
            Some(f) => {
                let covered = f.covered_mask(ctx)?;
                let (fh, fw) = plan.loss.feature_size();
                let at: Vec<u32> = (0..positions as u32).filter(|&x| covered[x as usize]).collect();
                (Some(at), crate::style::window::covered_box(&covered, fh, fw))
            }
            None => (None, None),
        };
        // The content target out of the plan's buffer: with the object focus
        // on part of the grid, the covered columns alone (read back once).
        let partial = covered_at.as_ref().filter(|at| self.object_focus && at.len() < positions);
        let (content, content_columns) = match partial {
            Some(at) => {
                let whole: Vec<f32> = ctx.read(held)?;
                let kept: Vec<usize> = at.iter().map(|&p| p as usize).collect();
                let part = gather_positions(&whole, whole.len() / positions.max(1), positions, &kept);
                let columns = ContentColumns::of(at, positions);
                (ctx.upload("engine.target.content", &part), Some(ctx.upload("engine.target.columns", &columns)))
            }
            None => {
                let content = ctx.zeros("engine.target.content", plan.loss.feature_len());
                let mut enc = ctx.encoder("engine.target.content");
                enc.copy_buffer_to_buffer(held, 0, &content, 0, (plan.loss.feature_len() * 4) as u64);
                ctx.submit(enc);
                (content, None)
            }
        };
        let subset = match &covered_at {
            Some(at) if (covered as f64) <= SUBSET_SHARE * positions as f64 => {
                Some(plan.loss.gcfm_subset(ctx, &k.loss, &self.style, at))
            }
            _ => None,
        };
        let need = subset.as_ref().map_or(0, |s| s.scratch_len(plan.loss.feature_len() / positions.max(1)));
        if need > self.subset_scratch.as_ref().map_or(0, |b| (b.size() / 4) as usize) {
            self.subset_scratch = Some(ctx.zeros("engine.subset_scratch", need));
        }
        // One read-back of G^c's render serves the colour watch and the hold.
        let (rgb, alpha) = self.read_render(cam)?;
        let colour = CoveredColour::of(&rgb, &alpha);
        let clamped: Vec<f32> = rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        let palette = palette_of(&clamped, &coverage_mask(&alpha, cam.height as usize, cam.width as usize));
        let hold = hold.then(|| self.hold_of(&clamped, &alpha));
        if view >= self.targets.len() {
            self.targets.resize_with(view + 1, || None);
        }
        self.targets[view] = Some(ViewTarget {
            content,
            content_columns,
            inv_depth,
            focus,
            colour,
            kept: None,
            subset,
            covered_at,
            window,
            hold,
            palette,
        });
        Ok(())
    }

    /// The covered colour ([`CoveredColour::of`]) of the last render at
    /// `cam`'s size: the last step's, read back (`h·w·16` bytes).
    pub fn rendered_colour(&self, cam: &Camera) -> Result<CoveredColour, GpuError> {
        let (rgb, alpha) = self.read_render(cam)?;
        Ok(CoveredColour::of(&rgb, &alpha))
    }

    /// The last render at `cam`'s size, read back: its colour (before the
    /// clamp) and alpha.
    fn read_render(&self, cam: &Camera) -> Result<(Vec<f32>, Vec<f32>), GpuError> {
        let size = (cam.width, cam.height);
        let Some(plan) = self.plans.get(&size) else {
            return Err(GpuError::TooLarge(format!("no plan for {}×{}", size.0, size.1)));
        };
        let n = u64::from(cam.width) * u64::from(cam.height);
        let rgb: Vec<f32> = self.ctx.read_range(&plan.raster.rgb, 0, n * 12)?;
        let alpha: Vec<f32> = self.ctx.read_range(&plan.raster.alpha, 0, n * 4)?;
        Ok((rgb, alpha))
    }

    /// `G^c`'s covered colour from `view`, once its target exists.
    pub fn reference_colour(&self, view: usize) -> Option<CoveredColour> {
        self.targets.get(view)?.as_ref().map(|t| t.colour)
    }
}

/// The most (tile, splat) pairs `g` needs in any of `cameras` (one render each, read back once).
fn busiest_view(
    ctx: &GpuContext,
    k: &RasterKernels,
    g: &GpuGaussians,
    cameras: &[Camera],
    config: &StyleConfig,
) -> Result<usize, GpuError> {
    let opts = RenderOptions { background: config.background };
    let mut most = 0;
    let mut raster: Option<GpuRaster> = None;
    for cam in cameras {
        let r = match raster.take() {
            Some(r) if (r.width, r.height) == (cam.width, cam.height) => {
                let mut enc = ctx.encoder("engine.size");
                r.forward(ctx, k, &mut enc, g, cam, &opts);
                ctx.submit(enc);
                if r.pairs(ctx)? <= r.capacity() { r } else { GpuRaster::fitted(ctx, k, g, cam, &opts)? }
            }
            _ => GpuRaster::fitted(ctx, k, g, cam, &opts)?,
        };
        most = most.max(r.pairs(ctx)?);
        raster = Some(r);
    }
    Ok(most)
}
