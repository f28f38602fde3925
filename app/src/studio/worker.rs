//! Links the core session runner into the studio: a [`SessionStarter`] that
//! spawns a worker thread which resolves the VGG
//! weights (a download on first use, reported as a stage), builds the
//! optimisation cameras, resolves the style's depth (cached per style, see
//! [`super::style_depth`]) and runs the session. Nothing here runs on the UI thread.

use std::sync::Arc;

use gast_core::camera::{OrbitOptions, framed_orbit};
use gast_core::session::{Event, RunOptions, SessionInputs, spawn_run};
use gast_core::style::StyleConfig;
use gast_core::vision::Vgg;

use super::session_link::{SessionLink, SessionStarter, StartRequest};

/// Orbit views used when the scene came without training cameras.
const ORBIT_VIEWS: usize = 36;

/// Fits `config`'s run to about ten minutes on this CPU, as `gast stylize`
/// does without `--resolution`: never above the resolution and cycles set
/// (a small preset stays small), lower where the budget needs it; a whole
/// frame at the default texture scale takes the reference's ratio of style
/// to frame ([`gast_core::session::plan::frame_texture_scale`]). `style`:
/// the style image's (width, height); `gemm_gflops`: this machine's rate
/// ([`gast_core::session::plan::machine_gemm_gflops`]). Says what it chose,
/// and the seconds a step it expects.
pub(super) fn plan_for_cpu(
    scene: &gast_core::Gaussians,
    cameras: &[gast_core::Camera],
    style: [usize; 2],
    gemm_gflops: f64,
    config: &mut StyleConfig,
) -> (String, f64) {
    use gast_core::session::plan::{AUTO_RUN_BUDGET_S, StepModel, ViewsSurvey, auto_plan, fit_cycles, survey};
    let ViewsSurvey { span, object } = survey(scene, cameras, config.focus, config.background);
    // A whole frame at the default texture scale takes the reference's ratio (below).
    let scaled_texture = !object && config.texture_scale == StyleConfig::default().texture_scale;
    let model = StepModel::for_run(object, (!scaled_texture).then_some(config.texture_scale))
        .with_style(style[0], style[1])
        .with_gaussians(scene.len())
        .on_machine(gemm_gflops);
    let plan = auto_plan(span, model, config.cycles, config.steps_per_cycle, AUTO_RUN_BUDGET_S);
    let asked = (config.resolution, config.cycles);
    config.resolution = plan.resolution.min(config.resolution);
    let (cycles, seconds) =
        fit_cycles(model, config.resolution, config.cycles, config.steps_per_cycle, AUTO_RUN_BUDGET_S);
    config.cycles = cycles;
    let minutes = seconds / 60.0;
    // A whole frame keeps the reference's ratio of the style to the frame, as
    // in `gast stylize`, unless the texture scale was moved off its default.
    let texture = if scaled_texture {
        let scale = gast_core::session::plan::frame_texture_scale(config.resolution, config.texture_scale);
        let said = (scale != config.texture_scale).then(|| {
            format!(
                "; texture scale {scale} px, the reference's ratio of the style to a whole frame at {} px (asked {})",
                config.resolution, config.texture_scale
            )
        });
        config.texture_scale = scale;
        said.unwrap_or_default()
    } else {
        String::new()
    };
    let said = if (config.resolution, config.cycles) == asked {
        format!("about {minutes:.0} min on this CPU as set: {} px, {} cycles{texture}", asked.0, asked.1)
    } else {
        format!(
            "planned for about {minutes:.0} min on this CPU: {} px, {} cycles (asked {} px, {} cycles; untick \"fit \
             the run\" to keep them){texture}",
            config.resolution, config.cycles, asked.0, asked.1
        )
    };
    (said, model.seconds(config.resolution))
}

/// The studio's session starter.
pub fn starter() -> SessionStarter {
    Box::new(|req: StartRequest| {
        let StartRequest {
            scene,
            style,
            style_path,
            style_depth_image,
            mut config,
            cameras,
            waker,
            gpu,
            fit_budget,
            keep,
            resume,
        } = req;
        let handle = spawn_run(
            move |emit: &mut dyn FnMut(Event)| {
                let t = std::time::Instant::now();
                let style = Arc::unwrap_or_clone(style);
                let mut last = 0u64;
                let weights = gast_core::vision::resolve_weights(None, &mut |done, total| {
                    // A download: report every 5 MB so the status panel shows progress.
                    if done >= last + 5_000_000 {
                        last = done;
                        let of = total.map(|t| format!(" of {:.0} MB", t as f64 / 1e6)).unwrap_or_default();
                        emit(Event::Warning(format!("downloading VGG weights: {:.0} MB{of}", done as f64 / 1e6)));
                    }
                })
                .map_err(|e| e.to_string())?;
                let vgg = Arc::new(Vgg::load(&weights).map_err(|e| e.to_string())?);
                let cameras = if cameras.is_empty() {
                    let opts = OrbitOptions {
                        count: ORBIT_VIEWS,
                        width: config.resolution,
                        height: config.resolution,
                        ..OrbitOptions::default()
                    };
                    framed_orbit(&scene, &opts)
                } else {
                    cameras
                };
                emit(Event::Stage { name: "weights and cameras".into(), seconds: t.elapsed().as_secs_f64() });
                // A kept run goes on with the settings it was planned with.
                if fit_budget && gpu.is_none() && resume.is_none() {
                    let t = std::time::Instant::now();
                    let gflops = gast_core::session::plan::machine_gemm_gflops_once();
                    let (plan, seconds_per_step) =
                        plan_for_cpu(&scene, &cameras, [style.width, style.height], gflops, &mut config);
                    emit(Event::Stage { name: plan, seconds: t.elapsed().as_secs_f64() });
                    emit(Event::Planned { seconds_per_step });
                }
                let t = std::time::Instant::now();
                // On a software rasterizer the CPU's kernels are ~40× faster.
                let (style_depth, warning) = super::style_depth::source_for(
                    &style_path,
                    &style,
                    config.depth_provider,
                    style_depth_image.as_deref(),
                    gpu.as_ref().filter(|g| !g.is_software()),
                );
                if let Some(w) = warning {
                    emit(Event::Warning(w));
                }
                emit(Event::Stage { name: "style depth".into(), seconds: t.elapsed().as_secs_f64() });
                let resume = match resume {
                    Some(offer) => {
                        let t = std::time::Instant::now();
                        let (from, said) = offer.load()?;
                        emit(Event::Stage {
                            name: format!("read the kept run {} ({said})", offer.path.display()),
                            seconds: t.elapsed().as_secs_f64(),
                        });
                        Some(from)
                    }
                    None => None,
                };
                // The run's freed memory, kept by the allocator for its steps
                // (`memory::keep_freed`), goes back once the run has ended.
                let options = RunOptions {
                    resume,
                    keep: keep.map(|slot| slot.keeper()),
                    at_end: Some(Box::new(crate::memory::give_back_freed)),
                };
                Ok((SessionInputs { scene, cameras, style, style_depth, vgg, config, gpu }, options))
            },
            waker,
        );
        Ok(SessionLink::of(handle))
    })
}
