//! The optimisation loop of one stylization run (Stage 2 of ALGORITHM.md):
//! the session, what it prepares and the state it keeps. One step of it, on
//! the CPU or the GPU engine, is `run_step.rs`.

use std::sync::Arc;
use std::time::Instant;

use super::colour_watch::ColourWatch;
use super::cpu_state::{CpuState, Optimisers};
use super::events::{Event, LossTerms, StepReport, StepTimings};
use super::moments::OptimiserState;
use super::prepare::{PreparedStyle, StyleDepthSource, StyleImage, prepare_style, scatter, subset, survey_views};
use super::view_target::{ContentTarget, ViewTarget};
use crate::camera::{Camera, scene_extent};
use crate::eval::stability::CoveredColour;
use crate::gpu::{GpuContext, GpuEngine, GpuError, LiveGaussians};
use crate::raster::{self, RenderOptions};
use crate::scene::Gaussians;
use crate::style::StyleConfig;
use crate::style::adam::Adam;
use crate::style::color_transfer::ColorTransfer;
use crate::style::config::ParamRegulariser;
use crate::style::focus::coverage_mask;
use crate::style::gcfm::{Matches, match_features};
use crate::style::matching::{MatchIndex, MatchMethod, agreement, find_matches};
use crate::style::outside::{Outside, outside_mask};
use crate::style::regularizers::{l2_distance, mean_square_distance};
use crate::style::step::{LossFocus, RenderedMaps, content_target, step_loss_with};
use crate::vision::Vgg;
use crate::vision::canny::render_edges;

/// Why a run could not start.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The configuration is unusable.
    #[error("invalid configuration: {}", .0.join("; "))]
    Config(Vec<String>),
    /// There is nothing to optimise from.
    #[error("{0}")]
    Input(String),
    /// The GPU engine could not start or failed.
    #[error("the GPU engine failed: {0}")]
    Gpu(#[from] GpuError),
}

/// Everything a run starts from.
#[derive(Clone)]
pub struct SessionInputs {
    /// The scene as loaded, shared: the session only reads it (a studio
    /// showing it, a study running it under many settings, keep theirs).
    pub scene: Arc<Gaussians>,
    /// Optimisation cameras (any resolution: they are rescaled to the working resolution).
    pub cameras: Vec<Camera>,
    /// The style image.
    pub style: StyleImage,
    /// Where the style's depth comes from.
    pub style_depth: StyleDepthSource,
    /// The VGG feature network.
    pub vgg: Arc<Vgg>,
    /// The run's parameters.
    pub config: StyleConfig,
    /// The GPU that runs the steps ([`crate::gpu::DeviceChoice::resolve`]);
    /// `None` runs them on the CPU engine.
    pub gpu: Option<GpuContext>,
}

/// `G^c` on the optimised Gaussians: `scene`'s at `keep`, colour-matched.
fn colour_matched_part(scene: &Gaussians, keep: &[u32], colour: &ColorTransfer) -> Gaussians {
    let mut part = subset(scene, keep);
    colour.apply_to_gaussians(&mut part);
    part
}

/// Gradients one phase's steps leave on the other phase's parameters
/// ([`StyleConfig::phase_leak`]), summed until that phase's next step adds
/// them to its own. Empty when the leak is off, and when the steps run on the
/// GPU engine, which keeps its own sums ([`crate::gpu::GpuLeak`]).
#[derive(Default)]
struct Leak {
    color: Vec<f32>,
    means: Vec<f32>,
    scales: Vec<f32>,
    quats: Vec<f32>,
    opacity: Vec<f32>,
}

impl Leak {
    /// The empty sums for `n` Gaussians when `config` asks for the leak (in
    /// decoupled mode: the ablations have no phases to leak between) and the
    /// CPU engine runs the steps (`on_gpu` false), else none.
    fn for_config(config: &StyleConfig, n: usize, on_gpu: bool) -> Self {
        if config.leaks_between_phases() && !on_gpu { Self::new(n) } else { Self::default() }
    }

    /// Whether the sums are kept (the leak is on).
    fn is_on(&self) -> bool {
        !self.means.is_empty()
    }

    fn new(n: usize) -> Self {
        Self {
            color: vec![0.0; 3 * n],
            means: vec![0.0; 3 * n],
            scales: vec![0.0; 3 * n],
            quats: vec![0.0; 4 * n],
            opacity: vec![0.0; n],
        }
    }

    /// The sums in the order of the optimiser's groups (`moments::GROUPS`).
    fn sums(&self) -> [&Vec<f32>; 5] {
        [&self.color, &self.means, &self.scales, &self.quats, &self.opacity]
    }

    /// [`Leak::sums`], to set.
    fn sums_mut(&mut self) -> [&mut Vec<f32>; 5] {
        [&mut self.color, &mut self.means, &mut self.scales, &mut self.quats, &mut self.opacity]
    }
}

/// One stylization run, stepped by its caller (the CLI or the studio's worker).
pub struct Session {
    config: StyleConfig,
    inputs_style: StyleImage,
    style_depth: StyleDepthSource,
    vgg: Arc<Vgg>,
    /// The scene the run starts from (as loaded, or split at
    /// [`StyleConfig::split_px`]). The whole colour-matched scene `G^c`, into
    /// which the optimised Gaussians are scattered on export, is `colour`
    /// applied to it, made when asked for rather than kept beside it.
    input: Arc<Gaussians>,
    /// Stage 0's colour matching.
    colour: ColorTransfer,
    /// Indices into `input` of the optimised Gaussians.
    keep: Vec<u32>,
    /// The CPU engine's Gaussians and optimiser; `None` on the GPU engine.
    cpu: Option<CpuState>,
    base_cameras: Vec<Camera>,
    cameras: Vec<Camera>,
    extent: f32,
    style: PreparedStyle,
    targets: Vec<Option<ViewTarget>>,
    /// The reference's gradient leak between phases (empty when off).
    leak: Leak,
    sampler: ViewSampler,
    step: u32,
    elapsed_s: f64,
    /// The GPU engine when the steps run there (it then holds the optimised
    /// Gaussians and their reference).
    engine: Option<Box<GpuEngine>>,
    /// The engine's buffers as a viewer on its device reads them, once asked for.
    live: Option<LiveGaussians>,
    /// Why stepping stopped early, if it did.
    failure: Option<String>,
    /// The style's matching index (when the config asks for one).
    index: Option<MatchIndex>,
    /// Per view, its last matches and the visits they have served.
    view_matches: Vec<Option<(Matches, u32)>>,
    /// Every how many steps an approximate search is compared with the exact one (0: never).
    audit_every: u32,
    /// Sums of the audited agreement fractions (nearest, farthest) and their count.
    audit: (f64, f64, u32),
    /// Mean share of the optimisation views' pixels the scene covers (alpha ≥ 0.5).
    coverage: f32,
    /// The object's colour in the steps' renders against `G^c`'s.
    colour_watch: ColourWatch,
}

impl Session {
    /// Prepares a run: colour matching, culling, style features. Reports each stage.
    pub fn prepare(inputs: SessionInputs, on_event: &mut dyn FnMut(Event)) -> Result<Self, SessionError> {
        Self::prepare_with_style(inputs, None, on_event)
    }

    /// As [`Session::prepare`], reusing the style's maps and features when
    /// `style` is given (a study runs one style under many settings; Stage 1
    /// is the slowest part of preparing). They must come from [`prepare_style`]
    /// with the same style image, texture scale, depth source and polarity as
    /// `inputs`.
    pub fn prepare_with_style(
        inputs: SessionInputs,
        style: Option<PreparedStyle>,
        on_event: &mut dyn FnMut(Event),
    ) -> Result<Self, SessionError> {
        let prepared = style;
        let SessionInputs { scene, cameras, style, style_depth, vgg, config, gpu } = inputs;
        let vgg = with_conv(vgg, config.conv);
        let problems = engine_problems(&config, gpu.is_some());
        if !problems.is_empty() {
            return Err(SessionError::Config(problems));
        }
        if scene.is_empty() {
            return Err(SessionError::Input("the scene has no Gaussians".into()));
        }
        if cameras.is_empty() {
            return Err(SessionError::Input("no optimisation cameras".into()));
        }
        if let Some(problem) = style.problem_at_scale(config.texture_scale) {
            return Err(SessionError::Input(problem));
        }
        let opts = RenderOptions { background: config.background };
        let work_cams: Vec<Camera> = cameras.iter().map(|c| c.with_longer_side(config.resolution)).collect();

        let scene = if config.split_px > 0.0 {
            let t = Instant::now();
            let cap = scene.len().saturating_mul(crate::style::config::SPLIT_MAX_FACTOR);
            let (split, r) = super::split::split_large(&scene, &work_cams, config.split_px, cap);
            let split = Arc::new(split);
            let capped = if r.capped { ", stopped at the cap" } else { "" };
            on_event(Event::Stage {
                name: format!(
                    "splitting to {} px: {} → {} Gaussians in {} passes{capped}",
                    config.split_px, r.before, r.after, r.passes
                ),
                seconds: t.elapsed().as_secs_f64(),
            });
            split
        } else {
            scene
        };
        let t = Instant::now();
        let survey = survey_views(&scene, &work_cams, &opts);
        let pixels: usize = work_cams.iter().map(|c| c.width as usize * c.height as usize).sum();
        let coverage = survey.covered_rgb.len() as f32 / 3.0 / pixels.max(1) as f32;
        let keep: Vec<u32> = survey.seen.iter().enumerate().filter(|(_, s)| **s).map(|(i, _)| i as u32).collect();
        if keep.is_empty() {
            return Err(SessionError::Input(format!(
                "none of the {} Gaussians is visible from the {} optimisation cameras",
                scene.len(),
                work_cams.len()
            )));
        }
        if survey.covered_rgb.is_empty() {
            // Nothing to match colours on or to stylize: Gaussians seen only
            // faintly, none making a pixel at least half opaque.
            return Err(SessionError::Input(format!(
                "the scene covers no pixel of the {} optimisation views (none is at least half opaque): \
                 expected cameras that look at this scene",
                work_cams.len()
            )));
        }
        let blind = survey.covered.iter().filter(|&&n| n == 0).count();
        if blind > 0 {
            on_event(Event::Warning(format!(
                "{blind} of the {} views show none of the scene (no pixel at least half opaque; the scene covers \
                 {:.1}% of all the views' pixels): their steps have next to nothing to stylize; expected cameras that look at this \
                 scene",
                work_cams.len(),
                100.0 * coverage
            )));
        }
        let config = config.resolved(coverage);
        let colour = ColorTransfer::fit(&survey.covered_rgb, &style.rgb);
        on_event(Event::Stage { name: "colour matching".into(), seconds: t.elapsed().as_secs_f64() });

        let t = Instant::now();
        let g_ref = colour_matched_part(&scene, &keep, &colour);
        on_event(Event::Culled { total: scene.len(), kept: keep.len() });
        on_event(Event::Stage { name: "visibility culling".into(), seconds: t.elapsed().as_secs_f64() });

        let t = Instant::now();
        let style_maps_ = match prepared {
            Some(p) => p,
            None => prepare_style(
                &vgg,
                &style,
                config.texture_scale,
                &style_depth,
                config.depth_polarity,
                config.depth_relief_px,
            ),
        };
        on_event(Event::Stage { name: "style features".into(), seconds: t.elapsed().as_secs_f64() });
        let t = Instant::now();
        let index = build_index(&style_maps_, &config);
        if index.is_some() {
            on_event(Event::Stage { name: "matching index".into(), seconds: t.elapsed().as_secs_f64() });
        }

        let n = keep.len();
        let extent = scene_extent(&work_cams);
        let sampler = ViewSampler::new(work_cams.len(), config.seed);
        let engine = match gpu {
            Some(ctx) => {
                let t = Instant::now();
                let e = GpuEngine::new(&ctx, &vgg, &g_ref, &style_maps_.targets.features, &work_cams, &config)?;
                on_event(Event::Stage {
                    name: format!(
                        "GPU upload on {} ({:.0} MiB)",
                        ctx.describe(),
                        e.memory_bytes() as f64 / (1u64 << 20) as f64
                    ),
                    seconds: t.elapsed().as_secs_f64(),
                });
                if config.matching.method != crate::style::MatchMethod::Exact {
                    on_event(Event::Warning(
                        "the GPU engine searches matches exactly (it keeps them for --matching-reuse visits); the matching index is a CPU option".into(),
                    ));
                }
                Some(Box::new(e))
            }
            None => None,
        };
        // The CPU engine's state, made only where it steps.
        let cpu = engine.is_none().then(|| {
            let opt = Optimisers {
                color: Adam::new(n * 3, config.adam),
                means: Adam::new(n * 3, config.adam),
                scales: Adam::new(n * 3, config.adam),
                quats: Adam::new(n * 4, config.adam),
                opacity: Adam::new(n, config.adam),
            };
            CpuState::new(g_ref, opt)
        });
        Ok(Self {
            targets: (0..work_cams.len()).map(|_| None).collect(),
            view_matches: (0..work_cams.len()).map(|_| None).collect(),
            colour_watch: ColourWatch::new(work_cams.len()),
            index,
            audit_every: 0,
            audit: (0.0, 0.0, 0),
            base_cameras: cameras,
            cameras: work_cams,
            input: scene,
            colour,
            keep,
            cpu,
            extent,
            style: style_maps_,
            inputs_style: style,
            style_depth,
            vgg,
            leak: Leak::for_config(&config, n, engine.is_some()),
            sampler,
            step: 0,
            elapsed_s: 0.0,
            engine,
            live: None,
            failure: None,
            coverage,
            config,
        })
    }

    /// The parameters in use.
    pub fn config(&self) -> &StyleConfig {
        &self.config
    }

    /// Steps done.
    pub fn steps_done(&self) -> u32 {
        self.step
    }

    /// The whole step budget under the current configuration.
    pub fn total_steps(&self) -> u32 {
        self.config.schedule().total_steps()
    }

    /// Whether every scheduled step has run.
    pub fn is_done(&self) -> bool {
        self.step >= self.total_steps()
    }

    /// Seconds spent stepping.
    pub fn elapsed_s(&self) -> f64 {
        self.elapsed_s
    }

    /// The optimisation cameras at the working resolution.
    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    /// The style's maps at texture scale and their features (for inspection).
    pub fn style(&self) -> &PreparedStyle {
        &self.style
    }

    /// The colour-matched scene before optimisation (`G^c`, whole), made
    /// anew from the run's input at each call.
    pub fn colour_matched(&self) -> Gaussians {
        let mut full = (*self.input).clone();
        self.colour.apply_to_gaussians(&mut full);
        full
    }

    /// [`Session::colour_matched`] for a run that is over: the session (its
    /// optimised Gaussians and their reference, the optimiser's moments, the
    /// per-view targets, a GPU engine) is let go first, so that `G^c` is
    /// never made beside them (the peak of `gast stylize` on a large scene).
    pub fn into_colour_matched(self) -> Gaussians {
        let (input, colour) = (Arc::clone(&self.input), self.colour);
        drop(self);
        let mut full = Arc::unwrap_or_clone(input);
        colour.apply_to_gaussians(&mut full);
        full
    }

    /// The scene the run started from: as loaded, or split at
    /// [`StyleConfig::split_px`].
    pub fn input(&self) -> &Arc<Gaussians> {
        &self.input
    }

    /// Mean share of the optimisation views' pixels the input scene covers.
    pub fn coverage(&self) -> f32 {
        self.coverage
    }

    /// Whether the losses focus on the object (the configured focus, with
    /// `auto` resolved by [`Session::coverage`]).
    pub fn focus_on_object(&self) -> bool {
        self.config.focus.is_object(self.coverage)
    }

    /// Number of Gaussians being optimised.
    pub fn optimised_count(&self) -> usize {
        self.keep.len()
    }

    /// The whole scene with the current optimised Gaussians in place (read
    /// back from the GPU when the steps run there); the colour-matched scene
    /// where a GPU engine's Gaussians cannot be read back.
    pub fn result(&self) -> Gaussians {
        let downloaded = self.engine.as_ref().and_then(|e| e.download().ok());
        let Some(g) = downloaded.as_ref().or(self.cpu.as_ref().map(|c| &c.g)) else {
            return self.colour_matched();
        };
        // `G^c` where nothing is optimised (the culled Gaussians); the rest is
        // overwritten by the optimised ones.
        let mut out = (*self.input).clone();
        self.colour.apply_to_gaussians_except(&mut out, &self.keep);
        scatter(&mut out, &self.keep, g);
        out
    }

    /// The GPU engine's buffers for a viewer on the same device, made on the
    /// first call (it copies the whole scene once); `None` on the CPU engine.
    /// Their step count follows [`Session::steps_done`].
    pub fn live(&mut self) -> Option<LiveGaussians> {
        let engine = self.engine.as_ref()?;
        if self.live.is_none() {
            let (base, keep) = (Arc::new(self.colour_matched()), Arc::new(self.keep.clone()));
            let live = LiveGaussians::new(engine.context(), engine.gaussians(), base, keep);
            live.publish(u64::from(self.step));
            self.live = Some(live);
        }
        self.live.clone()
    }

    /// Whether [`Session::live`] has handed the engine's buffers to a viewer.
    pub fn is_shared_live(&self) -> bool {
        self.live.is_some()
    }

    /// Where the steps run: the GPU adapter's description, or the CPU.
    pub fn device(&self) -> String {
        match &self.engine {
            Some(e) => e.context().describe(),
            None => format!("CPU ({} threads)", rayon::current_num_threads()),
        }
    }

    /// GPU memory the engine allocated, in bytes (`None` on the CPU).
    pub fn gpu_memory_bytes(&self) -> Option<u64> {
        self.engine.as_ref().map(|e| e.memory_bytes())
    }

    /// The share of the frame VGG runs on in the GPU engine's object focus
    /// ([`GpuEngine::vgg_window_share`]; `None` on the CPU or on whole frames).
    pub fn gpu_vgg_window_share(&self) -> Option<f64> {
        self.engine.as_ref().and_then(|e| e.vgg_window_share())
    }

    /// Why stepping stopped before the schedule ended (a GPU failure), if it did.
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// Warnings the GPU engine raised since the last call.
    pub fn take_warnings(&mut self) -> Vec<String> {
        self.engine.as_mut().map(|e| e.take_warnings()).unwrap_or_default()
    }

    /// Takes new parameters from the next step on. A new texture scale or depth
    /// polarity recomputes the style features (and the matching index); a new
    /// resolution the cameras and per-view targets; any of these, or new
    /// matching settings, forgets the kept matches. Adam state is kept. The
    /// split ([`StyleConfig::split_px`]) is made when a run is prepared; a new
    /// value takes effect on the next run.
    pub fn set_config(&mut self, config: StyleConfig) -> Result<(), SessionError> {
        let config = config.resolved(self.coverage);
        let mut problems = engine_problems(&config, self.engine.is_some());
        problems.extend(self.inputs_style.problem_at_scale(config.texture_scale));
        if !problems.is_empty() {
            return Err(SessionError::Config(problems));
        }
        let restyled = config.texture_scale != self.config.texture_scale
            || config.depth_polarity != self.config.depth_polarity
            || config.depth_relief_px != self.config.depth_relief_px;
        if restyled {
            self.style = prepare_style(
                &self.vgg,
                &self.inputs_style,
                config.texture_scale,
                &self.style_depth,
                config.depth_polarity,
                config.depth_relief_px,
            );
            if let Some(e) = &mut self.engine {
                e.set_style(&self.style.targets.features, &config.weights);
            }
        }
        if let Some(e) = &mut self.engine {
            e.upload_style_terms(&self.style.targets.features, &config.weights);
        }
        self.vgg = with_conv(self.vgg.clone(), config.conv);
        if restyled
            || config.matching.method != self.config.matching.method
            || config.matching.dims != self.config.matching.dims
        {
            self.index = build_index(&self.style, &config);
        }
        if restyled || config.matching != self.config.matching {
            self.view_matches.iter_mut().for_each(|m| *m = None);
            if let Some(e) = &mut self.engine {
                e.forget_matches();
            }
        }
        if config.resolution != self.config.resolution || config.background != self.config.background {
            self.cameras = self.base_cameras.iter().map(|c| c.with_longer_side(config.resolution)).collect();
            self.targets.iter_mut().for_each(|t| *t = None);
            self.colour_watch.reset();
            if let Some(e) = &mut self.engine {
                e.reset_views(self.cameras.len(), config.background);
            }
            self.view_matches.iter_mut().for_each(|m| *m = None);
        }
        if config.leaks_between_phases() != self.config.leaks_between_phases() {
            // Turned on or off: the sums start empty (the GPU engine's too).
            self.leak = Leak::for_config(&config, self.keep.len(), self.engine.is_some());
            if let Some(e) = &mut self.engine {
                e.reset_leak();
            }
        }
        self.config = config;
        Ok(())
    }

    /// The optimiser's state: every parameter group's steps and moments
    /// (read back from the GPU when the steps run there), which a checkpoint
    /// keeps so that a resumed run updates as the whole run would have.
    pub fn optimiser_state(&self) -> Result<OptimiserState, String> {
        let (groups, leak) = match (&self.cpu, &self.engine) {
            (Some(cpu), _) => {
                let leak = if self.leak.is_on() { self.leak.sums().map(Clone::clone).to_vec() } else { Vec::new() };
                (cpu.opt.groups().map(|a| a.state()).to_vec(), leak)
            }
            (None, Some(engine)) => {
                let groups = engine.optimiser_state().map_err(|e| e.to_string())?;
                (groups, engine.leak_sums().map_err(|e| e.to_string())?.unwrap_or_default())
            }
            (None, None) => return Err("the run has no optimiser".into()),
        };
        Ok(OptimiserState { step: self.step, groups, leak })
    }

    /// Goes on from `step` with `scene` as the run's state: a run resumed from
    /// the checkpoint of an earlier one with the same inputs and settings
    /// (`scene` is that run's [`Session::result`], whole). The optimised
    /// Gaussians take its values, the views are drawn as that run's were
    /// from `step` on, and with `moments` (that run's
    /// [`Session::optimiser_state`] at `step`) the optimiser goes on as it
    /// was; without, its moments start afresh (Adam's bias correction makes
    /// its first updates full-sized again). The phase leak's sums go on from
    /// `moments` where it holds them and the run leaks (else they start
    /// empty); the kept matches (`--matching-reuse`) start afresh. At the
    /// schedule's last step the run is done (its state is the result).
    /// Before the first step only.
    pub fn resume_at(
        &mut self,
        scene: &Gaussians,
        step: u32,
        moments: Option<&OptimiserState>,
    ) -> Result<(), SessionError> {
        if self.step > 0 {
            return Err(SessionError::Input(format!(
                "a run resumes before its first step, not after step {}",
                self.step
            )));
        }
        if scene.len() != self.input.len() || scene.sh_degree != self.input.sh_degree {
            return Err(SessionError::Input(format!(
                "expected a scene of {} Gaussians of SH degree {} to resume from (the run's input), found {} of \
                 degree {}",
                self.input.len(),
                self.input.sh_degree,
                scene.len(),
                scene.sh_degree
            )));
        }
        if step > self.total_steps() {
            return Err(SessionError::Input(format!(
                "expected a step within the schedule's {} to resume from, found {step}",
                self.total_steps()
            )));
        }
        if let Some(m) = moments.filter(|m| m.step != step) {
            return Err(SessionError::Input(format!(
                "expected the optimiser's state at step {step}, found one at step {}",
                m.step
            )));
        }
        if let Some(m) = moments {
            // Checked whole before any of it is taken.
            let n = self.keep.len();
            let sizes = [3 * n, 3 * n, 3 * n, 4 * n, n];
            let fits = m.groups.len() == sizes.len()
                && m.groups.iter().zip(sizes).all(|(g, len)| g.m.len() == len && g.v.len() == len);
            if !fits {
                let found: Vec<String> = m.groups.iter().map(|g| format!("{}/{}", g.m.len(), g.v.len())).collect();
                return Err(SessionError::Input(format!(
                    "the optimiser's state does not fit: expected moments of {sizes:?} parameters (the groups {}), \
                     found {}",
                    super::moments::GROUPS.join(", "),
                    found.join(", ")
                )));
            }
            let leak_fits = m.leak.is_empty()
                || (m.leak.len() == sizes.len() && m.leak.iter().zip(sizes).all(|(s, len)| s.len() == len));
            if !leak_fits {
                let found: Vec<usize> = m.leak.iter().map(Vec::len).collect();
                return Err(SessionError::Input(format!(
                    "the optimiser's state does not fit: expected the phase leak's sums of {sizes:?} parameters, \
                     found {found:?}"
                )));
            }
        }
        let leak = moments.map(|m| m.leak.as_slice()).filter(|l| !l.is_empty() && self.config.leaks_between_phases());
        let part = subset(scene, &self.keep);
        let moments_problem = |e: String| SessionError::Input(format!("the optimiser's state does not fit: {e}"));
        if let Some(cpu) = &mut self.cpu {
            if let Some(m) = moments {
                for (adam, g) in cpu.opt.groups_mut().into_iter().zip(&m.groups) {
                    adam.set_state(g.clone()).map_err(moments_problem)?;
                }
            }
            if let Some(sums) = leak.filter(|_| self.leak.is_on()) {
                for (to, from) in self.leak.sums_mut().into_iter().zip(sums) {
                    to.clone_from(from);
                }
            }
            cpu.g = part;
            if self.input.sh_degree > 0 {
                cpu.take_higher_bands(&colour_matched_part(&self.input, &self.keep, &self.colour));
            }
        } else if let Some(engine) = &mut self.engine {
            if let Some(m) = moments {
                engine.set_optimiser_state(&m.groups).map_err(moments_problem)?;
            }
            if let Some(sums) = leak {
                engine.set_leak_sums(sums).map_err(moments_problem)?;
            }
            engine.set_gaussians(&part);
        }
        for _ in 0..step {
            self.sampler.next();
        }
        self.step = step;
        if let Some(live) = &self.live {
            live.publish(u64::from(self.step));
        }
        Ok(())
    }

    /// Computes the per-view targets (the render of `G^c`, its content
    /// features and coverage) of every view that has none yet, as each view's
    /// first step would; returns the seconds it took. Benchmarks call it so
    /// their step medians are those of the steady state, not of first visits.
    pub fn warm_view_targets(&mut self) -> Result<f64, String> {
        let t = Instant::now();
        // The engine keeps what the focus reads, as its steps would.
        let object = self.focus_on_object();
        if let Some(engine) = &mut self.engine {
            engine.set_object_focus(object);
        }
        for view in 0..self.cameras.len() {
            match &mut self.engine {
                Some(engine) => engine
                    .warm_target(view, &self.cameras[view], &self.config.weights)
                    .map_err(|e| format!("view {view}: {e}"))?,
                None => self.make_target(view),
            }
        }
        Ok(t.elapsed().as_secs_f64())
    }

    /// The CPU engine's targets of `view`, computed on its first visit; the
    /// hold's part on the first visit with λ_out > 0 (a slider may turn it on
    /// after the other targets exist); the whole content map on the first
    /// visit without the object focus after one with it.
    fn make_target(&mut self, view: usize) {
        let want_hold = self.config.weights.outside > 0.0;
        let object = self.focus_on_object();
        let complete = |t: &ViewTarget| (t.outside.is_some() || !want_hold) && t.content.serves(object);
        if self.targets[view].as_ref().is_some_and(complete) {
            return;
        }
        let Some(cpu) = &mut self.cpu else { return };
        let opts = RenderOptions { background: self.config.background };
        let cam = &self.cameras[view];
        let (h, w) = (cam.height as usize, cam.width as usize);
        let r = cpu.with_reference(|g_ref| raster::render(g_ref, cam, &opts));
        let rgb: Vec<f32> = r.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        if let Some(t) = self.targets[view].as_mut() {
            if !t.content.serves(object) {
                t.content = ContentTarget::keep(content_target(&*self.vgg, &rgb, h, w), &t.coverage, h, w, object);
            }
            if want_hold && t.outside.is_none() {
                t.outside = Some((outside_mask(&r.alpha), rgb));
            }
            return;
        }
        self.colour_watch.set_reference(view, CoveredColour::of(&rgb, &r.alpha));
        let outside = want_hold.then(|| (outside_mask(&r.alpha), rgb.clone()));
        let coverage = coverage_mask(&r.alpha, h, w);
        let content = ContentTarget::keep(content_target(&*self.vgg, &rgb, h, w), &coverage, h, w, object);
        self.targets[view] = Some(ViewTarget {
            content,
            palette: crate::style::palette::palette_of(&rgb, &coverage),
            coverage,
            inv_depth: r.inv_depth,
            outside,
        });
    }

    /// Compares every `every`-th step's approximate matches with the exact
    /// search (0: never; exact runs have nothing to compare). The comparison's
    /// time is left out of the step's timings.
    pub fn audit_matches(&mut self, every: u32) {
        self.audit_every = every;
    }

    /// The mean share of a whole-frame VGG pass's multiply-adds that a CPU
    /// step's passes do, over the views whose targets are made: less than 1
    /// with object focus, where VGG computes only the cone of the covered
    /// positions (`style::window`, `vision::vgg_cone`); 1 with the losses over
    /// the whole frame or `vgg_window` off; `None` before any target exists.
    pub fn vgg_work_share(&self) -> Option<f32> {
        let object = self.focus_on_object() && self.config.vgg_window;
        let shares: Vec<f32> = self
            .targets
            .iter()
            .zip(&self.cameras)
            .filter_map(|(t, cam)| t.as_ref().map(|t| (t, cam.height as usize, cam.width as usize)))
            .map(|(t, h, w)| {
                let (sh, sw) = (h / 2, w / 2);
                let (fh, fw) = (sh / 4, sw / 4);
                if !object || t.coverage.len() != h * w || fh * fw == 0 {
                    return 1.0;
                }
                let fmask = crate::style::focus::feature_mask(&t.coverage, h, w, fh, fw);
                crate::style::window::covered_box(&fmask, fh, fw)
                    .map_or(1.0, |cells| crate::vision::vgg_cone::work_share(cells, (sh, sw)) as f32)
            })
            .collect();
        (!shares.is_empty()).then(|| shares.iter().sum::<f32>() / shares.len() as f32)
    }

    /// The object's colour in the steps' latest renders against the
    /// colour-matched state's ([`ColourWatch`]); `None` before any view is read.
    pub fn colour_reading(&self) -> Option<super::ColourReading> {
        self.colour_watch.reading()
    }

    /// Mean fractions of matches identical to the exact search (nearest,
    /// farthest) over the audited steps, and their number.
    pub fn match_agreement(&self) -> Option<(f64, f64, u32)> {
        let (b, w, k) = self.audit;
        (k > 0).then(|| (b / f64::from(k), w / f64::from(k), k))
    }
}

/// The matching index the configuration asks for, over the style's features.
fn build_index(style: &PreparedStyle, config: &StyleConfig) -> Option<MatchIndex> {
    (config.matching.method == MatchMethod::Pca)
        .then(|| MatchIndex::build(&style.targets.features, config.matching.dims as usize))
}

/// The network computing its convolutions with `conv` (the same one when it already does).
fn with_conv(vgg: Arc<Vgg>, conv: crate::vision::ConvAlgo) -> Arc<Vgg> {
    if vgg.conv() == conv { vgg } else { Arc::new((*vgg).clone().with_conv(conv)) }
}

/// Views in shuffled order without replacement, refilled when empty (seeded).
struct ViewSampler {
    order: Vec<usize>,
    n: usize,
    rng: u64,
}

impl ViewSampler {
    fn new(n: usize, seed: u64) -> Self {
        Self { order: Vec::new(), n, rng: seed ^ 0x9E37_79B9_7F4A_7C15 }
    }

    fn next_u64(&mut self) -> u64 {
        // SplitMix64.
        self.rng = self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn next(&mut self) -> usize {
        if self.order.is_empty() {
            self.order = (0..self.n).collect();
            for i in (1..self.order.len()).rev() {
                let j = (self.next_u64() % (i as u64 + 1)) as usize;
                self.order.swap(i, j);
            }
            self.order.reverse();
        }
        self.order.pop().unwrap_or(0)
    }
}

/// The configuration's problems ([`StyleConfig::problems`]), and what the
/// GPU engine does not compute yet when the steps run there.
fn engine_problems(config: &StyleConfig, on_gpu: bool) -> Vec<String> {
    let mut out = config.problems();
    if on_gpu {
        for c in config.cpu_only() {
            out.push(format!(
                "{} runs on the CPU engine only so far: use the CPU (--device cpu) or {}",
                c.detail, c.off
            ));
        }
    }
    out
}

#[path = "run_step.rs"]
mod run_step;
