//! `gast stylize`: one stylization run from the command line, with a progress
//! bar, then the stylized `.ply`, before/after renders and `report.json`.

use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use gast_core::eval::StabilityThresholds;
use gast_core::gpu::{GpuContext, GpuFeatureNet, GpuNearest};
use gast_core::io::write_bytes;
use gast_core::session::plan::{
    AUTO_RUN_BUDGET_S, MODEL_GEMM_GFLOPS, PIXELS_PER_FEATURE, Pace, REFERENCE_FRAME_RESOLUTION, StepModel, ViewsSurvey,
    auto_plan, auto_resolution_gpu, frame_texture_scale, machine_gemm_gflops_once, replan_cycles, step_time_hint,
    survey,
};
use gast_core::session::{Event, Session, SessionInputs, Stage1Cache, StepReport, StyleDepthSource, StyleImage};
use gast_core::style::StyleConfig;
use gast_core::vision::Vgg;
use gast_core::vision::style_depth::{DepthImage, DepthProvider};
use serde::Serialize;

use crate::checkpoint::{self, Due, checkpoint_path};
use crate::progress;
use crate::report::sheet;
use crate::views::{ViewArgs, camera_source, load_scene, refuse_photo_folder, views_for};

mod args;
mod previews;
mod resume;
pub use args::{FastArgs, StylizeArgs};
use previews::{Measures, PreviewMetrics, Summary, remove_stale_previews, write_previews};

/// The style's depth as the config's provider asks, with a progress bar for a
/// download of the depth network and a visible warning when it falls back to
/// the heuristic. The learned network runs on `gpu` when the run has one.
pub fn resolve_style_depth(
    config: &StyleConfig,
    style: &StyleImage,
    image: Option<&Path>,
    model: Option<&Path>,
    gpu: Option<&GpuContext>,
) -> anyhow::Result<StyleDepthSource> {
    let image = match image {
        Some(p) => Some(DepthImage::from_file(p)?),
        None => None,
    };
    let t = Instant::now();
    let pb = progress::bytes_bar("depth model");
    let cache = Stage1Cache::from_env();
    let resolved = StyleDepthSource::resolve_on(
        config.depth_provider,
        image,
        model,
        cache.as_ref(),
        style,
        gpu,
        &mut |done, total| {
            if let Some(t) = total {
                pb.set_length(t);
            }
            pb.set_position(done);
        },
    );
    pb.finish_and_clear();
    // A checkpoint the user named (the flag, or $GAST_DEPTH_MODEL) that
    // cannot be used is an error, not the built-in estimate with a warning,
    // before the run.
    let named = match model {
        Some(m) => Some(format!("--depth-model {}", m.display())),
        None => std::env::var_os("GAST_DEPTH_MODEL")
            .filter(|v| !v.is_empty())
            .map(|v| format!("$GAST_DEPTH_MODEL {} (unset it for the built-in estimate)", Path::new(&v).display())),
    };
    if let (Some(named), Some(why)) = (named, &resolved.learned_failure) {
        anyhow::bail!(
            "{named}: expected a Depth Anything V2 checkpoint (a folder with model.safetensors and config.json, or \
             the file), could not use it: {why}"
        );
    }
    if let Some(w) = &resolved.warning {
        eprintln!("warning: {w}");
    }
    if let Some(p) = &resolved.cached {
        eprintln!("  style depth (Depth Anything V2): from the Stage-1 cache {}", p.display());
    } else if config.depth_provider == DepthProvider::Learned && matches!(resolved.source, StyleDepthSource::Image(_)) {
        let on = gpu.map_or_else(|| "CPU".to_string(), GpuContext::describe);
        eprintln!("  style depth (Depth Anything V2 on {on}): {:.2} s", t.elapsed().as_secs_f64());
    } else if matches!(resolved.source, StyleDepthSource::Heuristic) {
        eprintln!("  style depth: the built-in relief estimate (the style's luminance detail read as relief)");
    } else if config.depth_provider == DepthProvider::Image {
        eprintln!("  style depth: the depth image given with --style-depth");
    }
    let source = resolved.source;
    Ok(source)
}

/// What a user reads when the colour watch sees the object's colours
/// collapse after `steps` steps (`loss`: the share of luminance or chroma
/// lost; `object`: whether the losses already focus on the object).
pub fn collapse_advice(steps: u32, loss: f32, object: bool) -> String {
    let focus = if object { "" } else { "--focus object, or " };
    format!(
        "after {steps} steps the object has lost {:.0}% of its colour-matched luminance or chroma (colour collapse); \
         the geometry steps' moving means bring dark Gaussians in front: try {focus}--lr-means 1e-5 (a tenth of the \
         default), or --lambda-content 0.1 (a hundred times the default: it holds the colour-matched look, but the \
         style's marks fade too)",
        loss * 100.0
    )
}

/// The message of a failed weights lookup; where no file was given and none
/// was found or fetched, it also names the flag that gives one.
fn with_weights_flag(e: &gast_core::vision::weights::WeightsError, explicit: bool) -> String {
    use gast_core::vision::weights::WeightsError as E;
    match e {
        E::NotFound { .. } | E::Download { .. } if !explicit => {
            format!("{e}; or pass --weights FILE (a torchvision VGG16 or VGG19 .pth or .safetensors)")
        }
        _ => e.to_string(),
    }
}

/// Loads the VGG weights the usual way, with a progress bar for a download.
pub fn load_vgg(explicit: Option<&Path>) -> anyhow::Result<Vgg> {
    let pb = progress::bytes_bar("weights");
    let path = gast_core::vision::download::resolve_weights(explicit, &mut |done, total| {
        if let Some(t) = total {
            pb.set_length(t);
        }
        pb.set_position(done);
    });
    pb.finish_and_clear();
    let path = path.map_err(|e| anyhow::anyhow!(with_weights_flag(&e, explicit.is_some())))?;
    let w = gast_core::vision::weights::VggWeights::load(&path)?;
    Ok(Vgg::from_weights(w))
}

#[derive(Serialize)]
struct Report {
    scene: String,
    style: String,
    config: StyleConfig,
    gaussians_total: usize,
    gaussians_optimised: usize,
    views: usize,
    stages_s: Vec<(String, f64)>,
    optimisation_s: f64,
    /// What came after the steps, in seconds: the scenes written, the preview
    /// views rendered and measured, the contact sheet.
    outputs_s: Vec<(String, f64)>,
    /// The step a Ctrl-C stopped the run at; `None`: the whole schedule ran.
    stopped_at: Option<u32>,
    /// The step this run went on from (`--resume`): `steps` and
    /// `optimisation_s` are this run's from there.
    resumed_from: Option<u32>,
    steps: Vec<StepReport>,
    preview: Vec<PreviewMetrics>,
    summary: Summary,
}

/// The colour-matched scene's name in the output folder (for `gast convert --blend`).
const MATCHED_NAME: &str = "colour_matched.ply";

/// The other files of fixed name a run writes into its output folder.
const SHEET_NAME: &str = "sheet.png";
const REPORT_NAME: &str = "report.json";
/// The style, its depth and its edges at texture scale.
const STYLE_NAMES: [&str; 3] = ["style.png", "style_depth.png", "style_edge.png"];

/// Writes the run's scene and optimiser's state after `record.step` of
/// `total` steps to the checkpoint `path` with its record (making the output
/// folder first); returns the line that says so, or why not: a failed
/// checkpoint is a warning, the run goes on.
fn write_checkpoint(path: &std::path::Path, session: &Session, record: &resume::Record, total: u32) -> String {
    let t = Instant::now();
    let step = record.step;
    match checkpoint::write_session(path, session, &session.result(), record) {
        Ok(without) => format!(
            "  checkpoint: step {step} of {total} written to {} in {:.0} ms{}",
            path.display(),
            t.elapsed().as_secs_f64() * 1e3,
            without.map(|e| format!(", without the optimiser's state ({e})")).unwrap_or_default()
        ),
        Err(e) => format!("  warning: the checkpoint at step {step} was not written: {e:#}"),
    }
}

/// `--scene-name` is a name inside the output folder with a format's ending:
/// `../x.ply` or `/tmp/x.ply` would write outside `--out`, and
/// [`MATCHED_NAME`] would replace the colour-matched scene.
fn check_scene_name(name: &std::path::Path) -> anyhow::Result<()> {
    let mut parts = name.components();
    let one_name = matches!(parts.next(), Some(std::path::Component::Normal(_))) && parts.next().is_none();
    anyhow::ensure!(
        one_name,
        "--scene-name {}: expected a file name inside the output folder (e.g. stylized.ply), found a path",
        name.display()
    );
    anyhow::ensure!(
        name != std::path::Path::new(MATCHED_NAME),
        "--scene-name {MATCHED_NAME}: expected another name, found the one the colour-matched scene is written under"
    );
    super::convert::check_output_name(name)
}

/// Whether a run writes a file of this name into its output folder: the
/// scenes, the sheet, the report, the style's maps and every preview view's
/// files (`view{k}_{tag}….png|exr`).
fn written_by_a_run(name: &std::path::Path, scene_name: &std::path::Path) -> bool {
    let fixed = [MATCHED_NAME, SHEET_NAME, REPORT_NAME].into_iter().chain(STYLE_NAMES);
    let text = name.to_string_lossy();
    let view = text.strip_prefix("view").is_some_and(|rest| rest.starts_with(|c: char| c.is_ascii_digit()))
        && (text.ends_with(".png") || text.ends_with(".exr"));
    let checkpoint = checkpoint_path(scene_name);
    name == scene_name
        || name == checkpoint
        || name == checkpoint::record_path(&checkpoint)
        || name == checkpoint::moments_path(&checkpoint)
        || fixed.into_iter().any(|f| name == std::path::Path::new(f))
        || view
}

/// The run's inputs (scene, style, style depth, preset) are not among the
/// files it writes into `--out`: a style taken from an earlier run's folder
/// (`out/stylize/style.png`) was replaced by this run's copy at texture scale.
/// The scene is held against the two scenes the run writes as `convert` holds
/// its input against its output (a SOG `meta.json` guards its folder too).
fn check_inputs_are_not_outputs(args: &StylizeArgs) -> anyhow::Result<()> {
    for written in [args.out.join(&args.scene_name), args.out.join(MATCHED_NAME)] {
        super::convert::check_not_the_input(&args.scene, &written)?;
    }
    let Ok(out) = args.out.canonicalize() else { return Ok(()) };
    let inputs = [Some(&args.scene), Some(&args.style), args.style_depth.as_ref(), args.preset.as_ref()];
    for input in inputs.into_iter().flatten() {
        let Ok(file) = input.canonicalize() else { continue };
        let Some(name) = file.file_name().map(std::path::Path::new) else { continue };
        if file.parent() == Some(out.as_path()) && written_by_a_run(name, &args.scene_name) {
            anyhow::bail!(
                "{}: expected an input outside what the run writes into {}, found one of its outputs ({}), which it would replace; copy it elsewhere or choose another --out",
                input.display(),
                args.out.display(),
                name.display()
            );
        }
    }
    Ok(())
}

/// Runs the stylization and writes the outputs.
pub fn run(args: StylizeArgs) -> anyhow::Result<ExitCode> {
    let t_all = Instant::now();
    let interrupt = super::interrupt::interrupt();
    check_scene_name(&args.scene_name)?;
    check_inputs_are_not_outputs(&args)?;
    let checkpoint = checkpoint_path(&args.out.join(&args.scene_name));
    // Checked before the slow work: a resume without a checkpoint is refused at once.
    let resume = if args.resume {
        Some(resume::Resume::read(&args, &checkpoint)?)
    } else {
        checkpoint::warn_of_a_checkpoint(&checkpoint, "stylization");
        None
    };
    if let Some(p) = &args.save_preset {
        super::replaceable_json(p, "--save-preset")?;
    }
    let config = args.config()?;
    let scene = load_scene(&args.scene)?;
    if scene.is_empty() {
        anyhow::bail!("{}: expected a scene with Gaussians to stylize, found none", args.scene.display());
    }
    let style = StyleImage::open(&args.style).map_err(anyhow::Error::msg)?;
    // The style file's bytes as read, which every checkpoint's record names.
    let style_file = crate::checkpoint::file_fingerprint(&args.style);
    if let Some(problem) = style.problem_at_scale(config.texture_scale) {
        anyhow::bail!("{}: {problem} (--texture-scale)", args.style.display());
    }
    let gpu = match args.device {
        // A setting the GPU engine does not compute (`StyleConfig::cpu_only`):
        // `auto` picks the CPU for it rather than failing (`gpu` still says why).
        gast_core::gpu::DeviceChoice::Auto if !config.cpu_only().is_empty() => {
            let on: Vec<String> = config.cpu_only().into_iter().map(|c| c.name).collect();
            eprintln!("{} runs on the CPU engine only so far: the steps run on the CPU", on.join(", "));
            None
        }
        // `gpu` refuses it now, before the depth model and the run, as the session would after them.
        gast_core::gpu::DeviceChoice::Gpu if !config.cpu_only().is_empty() => {
            let why: Vec<String> = (config.cpu_only().into_iter())
                .map(|c| format!("{} runs on the CPU engine only so far: use --device cpu or {}", c.detail, c.off))
                .collect();
            anyhow::bail!("--device gpu: {}", why.join("; "));
        }
        device => device.resolve().with_context(|| format!("--device {device}"))?,
    };
    // On a software rasterizer (lavapipe) the network's GEMMs run at about
    // 1 GFLOP/s, ~40× slower than the CPU kernels (`gast bench depth
    // --device gpu`): there the depth stays on the CPU.
    let depth_gpu = gpu.as_ref().filter(|g| !g.is_software());
    // The preview measures' VGG forwards and nearest-neighbour searches run there too.
    let preview_gpu = depth_gpu.cloned();
    // Everything that can fail fast is checked before the slow work (the depth
    // model's download, the run): the output folder, the cameras, the weights.
    // The folder is made only before the first write, after the run.
    super::check_output_folder(&args.out, "--out")?;
    let source = camera_source(&args.scene, &scene, args.cameras.as_deref(), args.orbit)?;
    let cameras = views_for(
        &scene,
        &ViewArgs {
            cameras: source.clone(),
            orbit: args.orbit,
            views: args.views,
            size: config.resolution,
            fov: args.fov,
            framing: args.framing,
            crop: args.crop,
        },
    )?;
    refuse_photo_folder(&args.out, "--out", source.as_deref(), &cameras)?;
    let mut config = config;
    let auto_resolution = args.resolution.is_none() && args.preset.is_none();
    let auto_texture = args.texture_scale.is_none() && args.preset.is_none();
    // A resumed run takes what the first run planned (below) rather than planning anew.
    let surveyed = (resume.is_none() && (auto_resolution || auto_texture))
        .then(|| survey(&scene, &cameras, config.focus, config.background));
    // A CPU plan's cycles rest on one machine's step times: after the first
    // cycle with a steady pace (`Pace`) the run takes the cycles that pace
    // fits, up to those asked for (`replan_cycles`), unless --cycles is
    // given. The model's seconds a step.
    let mut replan = None;
    if let Some(ViewsSurvey { span, object }) = surveyed.filter(|_| auto_resolution) {
        let (chosen, wanted, hint) = match &gpu {
            Some(g) => {
                let (chosen, wanted) = auto_resolution_gpu(span);
                (chosen, wanted, format!("steps run on {}", g.describe()))
            }
            None => {
                // On a whole frame the texture scale follows (below) unless it is given.
                let texture = (object || !auto_texture).then_some(config.texture_scale);
                // The model's times, halved per doubling where this machine's
                // matrix products run at least twice the model machine's.
                let gflops = machine_gemm_gflops_once();
                let model = StepModel::for_run(object, texture)
                    .with_style(style.width, style.height)
                    .with_gaussians(scene.len())
                    .on_machine(gflops);
                let plan = auto_plan(span, model, config.cycles, config.steps_per_cycle, AUTO_RUN_BUDGET_S);
                if args.cycles.is_none() {
                    replan = Some((config.cycles, model.seconds(plan.resolution)));
                }
                let fewer = if args.cycles.is_none() && plan.cycles < config.cycles {
                    config.cycles = plan.cycles;
                    format!(", {} cycles to fit", plan.cycles)
                } else {
                    String::new()
                };
                let total = model.seconds(plan.resolution) * f64::from(config.schedule().total_steps());
                let k = model.speed_up();
                let faster = if k > 1.0 {
                    format!(
                        ", its steps taken as {k:.0}× the model machine's pace (its matrix products ran {gflops:.0} \
                         GFLOP/s against {MODEL_GEMM_GFLOPS:.0})"
                    )
                } else {
                    String::new()
                };
                let hint = format!(
                    "{}{fewer}: about {:.0} min on this CPU{faster} (--resolution and --cycles override)",
                    step_time_hint(model, plan.resolution),
                    total / 60.0
                );
                (plan.resolution, plan.wanted, hint)
            }
        };
        eprintln!(
            "working resolution {chosen} px: the {} spans {:.0} relu3 positions across its longer side \
             (64 would need {wanted} px); {hint}",
            if object { "object" } else { "scene" },
            span * chosen as f32 / PIXELS_PER_FEATURE,
        );
        config.resolution = chosen;
    }
    // A whole frame keeps the reference's ratio of the style to the frame.
    if let Some(ViewsSurvey { object: false, .. }) = surveyed.filter(|_| auto_texture) {
        let scale = frame_texture_scale(config.resolution, config.texture_scale);
        if scale != config.texture_scale {
            eprintln!(
                "texture scale {scale} px: the style's height in the reference's ratio to a whole frame ({} px at \
                 {REFERENCE_FRAME_RESOLUTION} px), at this {} px working resolution (--texture-scale overrides)",
                config.texture_scale, config.resolution
            );
            config.texture_scale = scale;
            if let Some(problem) = style.problem_at_scale(scale) {
                anyhow::bail!("{}: {problem} (--texture-scale)", args.style.display());
            }
        }
    }
    // The checkpoint's state, once its record agrees with this run's inputs and settings.
    let resumed = match &resume {
        Some(r) => {
            r.take_planned(&args, &mut config);
            eprintln!(
                "working resolution {} px, texture scale {} px, {} cycles of {} steps: the plan of the run that \
                 left the checkpoint",
                config.resolution, config.texture_scale, config.cycles, config.steps_per_cycle
            );
            let now = resume::Record::of(&args, style_file.clone(), scene.len(), &cameras, &config, 0, None);
            Some((r.check_and_load(&now)?, r.record.step))
        }
        None => None,
    };
    if let Some(p) = &args.save_preset {
        write_bytes(p, config.to_json().as_bytes())?;
    }
    let vgg = Arc::new(load_vgg(args.weights.as_deref())?);
    let style_depth =
        resolve_style_depth(&config, &style, args.style_depth.as_deref(), args.depth_model.as_deref(), depth_gpu)?;
    eprintln!(
        "{}: {} Gaussians (SH degree {}), {} views; style {} ({}x{})",
        args.scene.display(),
        scene.len(),
        scene.sh_degree,
        cameras.len(),
        args.style.display(),
        style.width,
        style.height
    );

    let mut stages = Vec::new();
    let mut culled = (scene.len(), scene.len());
    // The session shares the scene, which the "before" previews draw.
    let scene = Arc::new(scene);
    // The settings as given to the session (its cycles as re-planned), which a checkpoint records.
    let mut asked = config.clone();
    let inputs = SessionInputs {
        scene: Arc::clone(&scene),
        cameras: cameras.clone(),
        style,
        style_depth,
        vgg: vgg.clone(),
        config: config.clone(),
        gpu,
    };
    let mut session = Session::prepare(inputs, &mut |e| match e {
        Event::Stage { name, seconds } => {
            eprintln!("  {name}: {seconds:.2} s");
            stages.push((name, seconds));
        }
        Event::Culled { total, kept } => {
            eprintln!("  optimising {kept} of {total} Gaussians ({} never visible from the cameras)", total - kept);
            culled = (total, kept);
        }
        Event::Warning(w) => eprintln!("warning: {w}"),
        _ => {}
    })?;

    // The weights a recipe lifts for this run (the studio shows the same under its sliders).
    let lifted = config.recipe_lifts(session.coverage());
    if !lifted.is_empty() {
        // Each with its name: "λ_pal 100 (palette hold)".
        let list =
            lifted.iter().map(|(t, v)| format!("{} {v} ({})", t.symbol, t.name())).collect::<Vec<_>>().join(", ");
        if session.focus_on_object() {
            eprintln!(
                "  object recipe: the losses are on the object, so the run uses {list}; --no-object-recipe or \
                 --preset paper for the paper's terms alone"
            );
        } else {
            eprintln!(
                "  frame recipe: the losses are on the whole frame, so the run uses {list}, the style's relief \
                 in the depth; --no-frame-recipe or --preset paper for the paper's terms alone"
            );
        }
    }
    let start = match resumed {
        Some((state, step)) => {
            let (moments, how) = checkpoint::read_moments(&checkpoint, step);
            session
                .resume_at(&state, step, moments.as_ref())
                .with_context(|| format!("could not resume from {}", checkpoint.display()))?;
            eprintln!("  resuming from step {step} of {}: {} ({how})", session.total_steps(), checkpoint.display());
            step
        }
        None => 0,
    };
    // A checkpoint written before the first cycle's re-plan leaves it to the
    // resumed run, with the seconds of steps before it (its pace counts them).
    let mut earlier_s = 0.0;
    if let Some(p) = resume.as_ref().and_then(|r| r.record.replan).filter(|_| args.cycles.is_none()) {
        replan = Some((p.most, p.model_s));
        earlier_s = p.elapsed_s;
    }
    let record = |asked: &StyleConfig, step: u32, replan: Option<(u32, f64)>, steps: &[StepReport]| {
        let elapsed_s = earlier_s + steps.last().map_or(0.0, |r| r.elapsed_s);
        let pending = replan.map(|(most, model_s)| resume::PendingReplan { most, model_s, elapsed_s });
        resume::Record::of(&args, style_file.clone(), scene.len(), &cameras, asked, step, pending)
    };
    let mut config = session.config().clone();
    let mut total = session.total_steps();
    // Over the steps this run does (its pace and time left are this run's), as `gast fit`'s.
    let pb = progress::bar(u64::from(total - start), "stylize");
    let mut steps = Vec::with_capacity(total as usize);
    let mut warned_collapse = false;
    let mut stopped_at = None;
    let mut due = Due::every(args.checkpoint_every);
    interrupt.begin();
    while let Some(r) = session.step() {
        let lum = r.colour.map_or(String::new(), |c| format!(" luminance {:.2}x", c.luminance_ratio()));
        pb.set_message(format!(
            "cycle {}/{} {:?} loss {:.4}{lum}",
            r.cycle + 1,
            config.cycles,
            r.phase,
            r.losses.total
        ));
        crate::progress::tick(&pb);
        if let Some(d) = r.colour.and_then(|c| c.collapse()).filter(|_| !warned_collapse) {
            warned_collapse = true;
            // Not `pb.println`: a hidden bar (output not a terminal) drops its lines.
            let advice = collapse_advice(r.iter + 1, d.value, session.focus_on_object());
            pb.suspend(|| eprintln!("warning: {advice}"));
        }
        if !r.losses.total.is_finite() {
            pb.abandon();
            anyhow::bail!("step {}: the loss became {}; stopping (try lower learning rates)", r.iter, r.losses.total);
        }
        steps.push(r);
        let per_cycle = config.schedule().steps_per_cycle();
        // At the end of the first cycle that has a steady pace (every view visited, then revisits).
        let at_cycle_end = session.steps_done() % per_cycle.max(1) == 0;
        // Over the whole run: a resumed one's steps and seconds before it counted.
        let pace = replan
            .filter(|_| at_cycle_end)
            .and_then(|_| Pace::read(steps.iter().map(|r| (r.view, r.elapsed_s))))
            .map(|p| Pace { steps: p.steps + start, elapsed_s: p.elapsed_s + earlier_s, ..p });
        if let (Some((most, model_s)), Some(pace @ Pace { steady_s: Some(steady), .. })) = (replan, pace) {
            replan = None;
            let fits = replan_cycles(pace, per_cycle, AUTO_RUN_BUDGET_S, most);
            if let Some(cycles) = fits.filter(|&c| c != config.cycles) {
                session.set_config(StyleConfig { cycles, ..config.clone() })?;
                config = session.config().clone();
                asked.cycles = cycles;
                total = session.total_steps();
                pb.set_length(u64::from(total - start));
                let minutes = (pace.elapsed_s + steady * f64::from(total - pace.steps)) / 60.0;
                let after = pace.cycles_said(per_cycle);
                pb.suspend(|| {
                    eprintln!(
                        "  re-planned after {after}: {cycles} cycles, about {minutes:.0} min of steps (its steps \
                         took {steady:.2} s after each view's first visit, the plan's model {model_s:.2} s; --cycles \
                         keeps a number)"
                    )
                });
            }
        }
        if interrupt.asked() && !session.is_done() {
            stopped_at = Some(session.steps_done());
            break;
        }
        if due.now() && !session.is_done() {
            let line =
                write_checkpoint(&checkpoint, &session, &record(&asked, session.steps_done(), replan, &steps), total);
            due.written();
            pb.suspend(|| eprintln!("{line}"));
        }
    }
    interrupt.end();
    pb.finish_and_clear();
    if let Some(n) = stopped_at {
        eprintln!("stopped at step {n} of {total} (Ctrl-C): writing what the run has; Ctrl-C again quits at once");
        // Kept, so that the same command with --resume goes on from here.
        let line = write_checkpoint(&checkpoint, &session, &record(&asked, n, replan, &steps), total);
        eprintln!("{line}; the same command with --resume goes on from it");
    }
    if let Some(why) = session.failure() {
        anyhow::bail!("the optimisation stopped at {why}");
    }
    let optimisation_s = session.elapsed_s();
    let done = session.steps_done();
    let resumed_at = if start > 0 { format!(" (steps {start} to {done}: resumed)") } else { String::new() };
    eprintln!(
        "  optimisation on {}: {} steps in {optimisation_s:.1} s ({:.3} s/step){resumed_at}",
        session.device(),
        done - start,
        optimisation_s / (done - start).max(1) as f64
    );

    // After the steps the work is the host's (renders, VGG measures, files):
    // each part is timed and said, so a minute of it is not a silent one.
    let mut outputs = Vec::new();
    let mut t_part = Instant::now();
    let part_took = |outputs: &mut Vec<(String, f64)>, name: &str, seconds: f64| {
        eprintln!("  {name}: {seconds:.1} s");
        outputs.push((name.to_string(), seconds));
    };
    let part_done = |outputs: &mut Vec<(String, f64)>, name: &str, t: &mut Instant| {
        part_took(outputs, name, t.elapsed().as_secs_f64());
        *t = Instant::now();
    };
    let result = session.result();
    // What the outputs, the previews and the sheet need, kept; the session (its
    // optimised Gaussians, per-view targets, the style's features, the
    // optimiser's state, a GPU engine's buffers) is let go before them, whose
    // VGG passes were added on top of it: guitar × wave at 576 px peaked at
    // 803 MB resident with it, 617 MB without. `G^c` is made once it is gone.
    let (cameras, maps) = (session.cameras().to_vec(), session.style().maps.clone());
    let (background, focus_on_object, coverage) = (config.background, session.focus_on_object(), session.coverage());
    let matched = session.into_colour_matched();
    super::output_folder(&args.out, "--out")?;
    // The run's scene first: where the disk has room for one scene only, it is
    // the one kept. Then the colour-matched scene, for `gast convert --blend`
    // to set a strength later.
    let matched_path = args.out.join(MATCHED_NAME);
    match args.strength.strength().filter(|s| !s.is_full()) {
        Some(strength) => {
            let blended = super::convert::blended(&matched, &result, strength, &matched_path)?;
            super::convert::save_scene(&args.out.join(&args.scene_name), &blended, &args.save)?;
            eprintln!(
                "  wrote the scene at colour strength {:.0}%, shape strength {:.0}% (the renders below show 100%)",
                strength.colour * 100.0,
                strength.shape * 100.0
            );
        }
        None => super::convert::save_scene(&args.out.join(&args.scene_name), &result, &args.save)?,
    }
    super::convert::save_scene(&matched_path, &matched, &super::convert::SaveArgs::default())?;
    // The cameras travel with the scene, for the studio and a rerun; an orbit is made again.
    if let Some(source) = &source {
        for line in crate::views::write_cameras_beside(&args.out.join(&args.scene_name), source, &cameras)? {
            eprintln!("  {line}");
        }
    }
    if stopped_at.is_none() {
        // The scene holds the whole run: the checkpoint (also one resumed from) has served.
        checkpoint::remove(&checkpoint);
    }
    part_done(&mut outputs, "scenes written", &mut t_part);
    let (matched, cameras, maps, views) = (&matched, &cameras[..], &maps, args.preview_views);
    let object = focus_on_object;
    let previews = match &preview_gpu {
        Some(ctx) => {
            eprintln!("  preview measures: VGG and nearest-neighbour searches on {}", ctx.describe());
            let (net, nearest) = (GpuFeatureNet::new(ctx.clone(), &vgg), GpuNearest::new(ctx.clone()));
            let nearest = Some(&nearest);
            write_previews(
                &args.out, &scene, matched, &result, cameras, maps, background, &net, nearest, views, object,
            )?
        }
        None => {
            write_previews(&args.out, &scene, matched, &result, cameras, maps, background, &*vgg, None, views, object)?
        }
    };
    for (name, seconds) in previews.parts {
        part_took(&mut outputs, name, seconds);
    }
    let stale = remove_stale_previews(&args.out, previews.renders.len())?;
    if stale > 0 {
        eprintln!(
            "  removed {stale} preview files of views {} and above, which an earlier run left in {}",
            previews.renders.len(),
            args.out.display()
        );
    }
    t_part = Instant::now();
    let preview = previews.metrics;
    let sheet_path = args.out.join(SHEET_NAME);
    let settings = sheet::settings_line(&config, (start, done), optimisation_s, focus_on_object, coverage);
    let title = format!(
        "{} x {}",
        args.scene.file_name().unwrap_or_default().to_string_lossy(),
        args.style.file_name().unwrap_or_default().to_string_lossy()
    );
    sheet::write_sheet(
        &sheet_path,
        &sheet::SheetContent {
            title,
            settings,
            style: sheet::maps_tiles(maps),
            // The preview views' renders: the same cameras, scenes and background.
            views: previews.renders,
        },
    )?;
    part_done(&mut outputs, "contact sheet drawn", &mut t_part);
    eprintln!("  contact sheet: {}", sheet_path.display());
    let m = Measures::mean(preview.iter().map(|p| &p.measures));
    let colour_collapse =
        gast_core::eval::stability::colour_collapse(m.colour_matched, m.colour_after, &StabilityThresholds::default());
    let summary = Summary { measures: m, colour_collapse };
    eprintln!(
        "  covered colour: luminance {:.3} -> {:.3}, chroma {:.3} -> {:.3} (colour-matched -> after); colour collapse: {}",
        m.colour_matched.luminance,
        m.colour_after.luminance,
        m.colour_matched.chroma,
        m.colour_after.chroma,
        summary
            .colour_collapse
            .as_ref()
            .map_or("no".to_string(), |d| format!("yes ({:.2} > {:.2})", d.value, d.threshold))
    );
    eprintln!(
        "  style distance (mean-std of VGG relu3) {:.4} -> {:.4} -> {:.4}; nearest-neighbour {:.4} -> {:.4} -> {:.4} \
         (input -> colour-matched -> after); inverse depth changed by {:.1}%",
        m.rgb.mean_std_before,
        m.rgb.mean_std_matched,
        m.rgb.mean_std_after,
        m.rgb.nn_distance_before,
        m.rgb.nn_distance_matched,
        m.rgb.nn_distance_after,
        100.0 * m.inverse_depth_change
    );
    if let Some(o) = m.on_object {
        eprintln!(
            "  on the object's positions: mean-std {:.4} -> {:.4} -> {:.4}; nearest-neighbour {:.4} -> {:.4} -> {:.4}",
            o.mean_std_before,
            o.mean_std_matched,
            o.mean_std_after,
            o.nn_distance_before,
            o.nn_distance_matched,
            o.nn_distance_after
        );
    }
    eprintln!(
        "  depth against the style's depth: nearest-neighbour {:.4} -> {:.4}, sliced Wasserstein {:.3} -> {:.3} (colour-matched -> after); relief energy {:.4} of the depth range",
        m.depth_style_matched.nn_cos,
        m.depth_style_after.nn_cos,
        m.depth_style_matched.sw,
        m.depth_style_after.sw,
        m.relief_energy
    );
    let report = Report {
        scene: args.scene.display().to_string(),
        style: args.style.display().to_string(),
        config,
        gaussians_total: culled.0,
        gaussians_optimised: culled.1,
        views: cameras.len(),
        stages_s: stages,
        optimisation_s,
        outputs_s: outputs,
        stopped_at,
        resumed_from: (start > 0).then_some(start),
        steps,
        preview,
        summary,
    };
    let json = serde_json::to_string_pretty(&report)?;
    write_bytes(&args.out.join(REPORT_NAME), json.as_bytes())?;
    eprintln!("wrote {} in {:.1} s", args.out.display(), t_all.elapsed().as_secs_f64());
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_weights_lookup_names_the_flag_only_when_none_was_given() {
        use gast_core::vision::weights::WeightsError;
        let download = WeightsError::Download { url: "https://example.org/vgg16.pth".into(), detail: "offline".into() };
        let m = with_weights_flag(&download, false);
        assert!(
            m.contains("https://example.org/vgg16.pth") && m.contains("offline") && m.contains("--weights FILE"),
            "{m}"
        );
        assert!(!with_weights_flag(&download, true).contains("--weights"));
        let bad = WeightsError::Format { path: "w.pth".into(), expected: "a zip".into(), found: "text".into() };
        assert_eq!(with_weights_flag(&bad, false), bad.to_string());
        // The flag the message names is one `stylize` takes.
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: StylizeArgs,
        }
        let cli =
            <Cli as clap::Parser>::try_parse_from(["stylize", "s.ply", "t.jpg", "--weights", "w.pth"]).expect("parses");
        assert_eq!(cli.args.weights.as_deref(), Some(Path::new("w.pth")));
    }

    /// `--preset paper` is the reference's configuration, flags still override
    /// it, and `--no-object-recipe` and `--no-frame-recipe` turn the recipes off.
    #[test]
    fn the_paper_preset_and_the_recipe_switch() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: StylizeArgs,
        }
        let parse = |extra: &[&str]| {
            let mut argv = vec!["stylize", "s.ply", "t.png"];
            argv.extend_from_slice(extra);
            <Cli as clap::Parser>::try_parse_from(argv).expect("parses").args.config().expect("config")
        };
        assert_eq!(parse(&["--preset", "paper"]), StyleConfig::paper());
        assert_eq!(parse(&["--preset", "paper", "--cycles", "3"]).cycles, 3);
        assert!(parse(&[]).object_recipe && parse(&[]).frame_recipe);
        assert!(!parse(&["--no-object-recipe"]).object_recipe);
        assert!(!parse(&["--no-frame-recipe"]).frame_recipe && parse(&["--no-frame-recipe"]).object_recipe);
    }

    /// The collapse warning's advice names flags `stylize` takes, with values it accepts.
    #[test]
    fn the_collapse_advice_names_real_flags() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: StylizeArgs,
        }
        assert!(!collapse_advice(300, 0.52, true).contains("--focus"), "the focus is on the object already");
        let advice = collapse_advice(300, 0.52, false);
        assert!(advice.contains("300 steps") && advice.contains("52%"), "{advice}");
        for (flag, value) in [("--focus", "object"), ("--lambda-content", "0.1"), ("--lr-means", "1e-5")] {
            assert!(advice.contains(&format!("{flag} {value}")), "{advice}");
            let parsed = <Cli as clap::Parser>::try_parse_from(["stylize", "scene.ply", "style.png", flag, value]);
            assert!(parsed.is_ok(), "{flag} {value}: {:?}", parsed.err());
        }
    }
}
