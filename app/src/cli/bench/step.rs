//! `gast bench step`: one optimisation step part by part on a device (or two,
//! `--compare`), the focus's cost (`--compare-focus`), the assignment terms'
//! (`--compare-assign`), the palette hold's (`--compare-palette`), the depth
//! relief's and the phase leak's (`--compare-relief PX`), what re-used
//! matches buy on a GPU (`--matching-reuse N` alone with a GPU device), the whole
//! schedule's time and memory.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;
use gast_core::camera::Camera;

use anyhow::Context as _;

use super::depth::time_style_depth;
use super::{median, memory_mib, reset_peak_memory};
use crate::views::{Framing, ViewArgs, load_scene, views_for};

/// Arguments of `gast bench step`.
#[derive(Args, Debug)]
pub struct StepArgs {
    #[command(flatten)]
    pub data: super::BenchData,
    /// Working resolution (longer side, pixels).
    #[arg(long, default_value_t = 256)]
    pub resolution: u32,
    /// The style's texture scale (its height in pixels, 16 to 4,096, as `gast stylize
    /// --texture-scale`): a whole-frame `gast stylize` at 256 px takes 64 by default.
    #[arg(long, default_value_t = 256, value_parser = crate::views::within(gast_core::style::TEXTURE_SCALES))]
    pub texture_scale: u32,
    /// Orbit views (1 to 3,600).
    #[arg(long, default_value_t = 36, value_parser = crate::views::view_count::<usize>())]
    pub views: usize,
    /// The scene's own cameras instead of an orbit (a camera file or folder as
    /// `gast stylize --cameras` takes: COLMAP sparse/0, poses_bounds.npy, ...),
    /// at --resolution on the longer side: fern's 20 LLFF views at 1,008×756.
    #[arg(long, value_name = "PATH")]
    pub cameras: Option<PathBuf>,
    /// Orbit framing: full (the paper's orbit, the object as the scene's extent frames it) or
    /// object (each view fitted to the object, as `gast stylize` does by default).
    #[arg(long, value_enum, default_value_t = Framing::Full)]
    pub framing: Framing,
    /// Geometry steps to time after the first cycle's colour steps.
    #[arg(long, default_value_t = 20)]
    pub geometry_steps: u32,
    /// Run the whole default schedule (3,000 steps) instead of extrapolating from the timed steps.
    #[arg(long)]
    pub full: bool,
    /// Run exactly this many steps of the default schedule and report their measured time
    /// (overrides --geometry-steps and --full), at least one.
    #[arg(long, value_parser = crate::views::at_least_one::<u32>)]
    pub steps: Option<u32>,
    /// Where the steps run: auto (a hardware GPU when there is one, else the CPU), cpu, or gpu
    /// (any adapter, lavapipe included).
    #[arg(long, default_value_t = gast_core::gpu::DeviceChoice::Auto)]
    pub device: gast_core::gpu::DeviceChoice,
    /// Run the same steps on the CPU and on the GPU (any adapter) in this process and print the ratio.
    #[arg(long)]
    pub compare: bool,
    /// Which pixels the losses average over: frame, object or auto (auto: the object when it
    /// covers less than half of the views).
    #[arg(long, default_value = "auto")]
    pub focus: gast_core::style::Focus,
    /// Run the same steps on --device twice in this process, with the losses over the whole
    /// frame and focused on the object, and print what the focus costs.
    #[arg(long, conflicts_with = "compare")]
    pub compare_focus: bool,
    /// Run the same steps on --device twice in this process, without and with the assignment
    /// terms (λ_asc 10, λ_as 0.015: the focus study's object recipe), and print what they cost.
    #[arg(long, conflicts_with_all = ["compare", "compare_focus"])]
    pub compare_assign: bool,
    /// Run the same steps on --device twice in this process, without and with the depth's
    /// sliced Wasserstein term (λ_swd 1: the frame recipe's), and print what it costs
    /// (give --focus frame: the term is the full-frame default).
    #[arg(long, conflicts_with_all = ["compare", "compare_focus", "compare_assign"])]
    pub compare_sliced_depth: bool,
    /// Run the same steps on --device twice in this process, without and with the palette
    /// hold (λ_pal 100, the object recipe's), and print what it costs (give
    /// --focus object: the hold reads the object's pixels).
    #[arg(long, conflicts_with_all = ["compare", "compare_focus", "compare_assign", "compare_sliced_depth"])]
    pub compare_palette: bool,
    /// Run the same steps on --device twice in this process with the assignment terms on
    /// (λ_asc 10, λ_as 0.015), their pairing in one block of up to 512 rows and in blocks of
    /// --assign-block (default 256), and print what the blocks save.
    #[arg(long, conflicts_with_all = [
        "compare", "compare_focus", "compare_assign", "compare_sliced_depth", "compare_palette"
    ])]
    pub compare_assign_block: bool,
    /// The depth relief's radius for every run (`gast stylize --depth-relief PX`; 0, the
    /// default, is off): with --compare, the first step's losses of both engines with it.
    #[arg(long, value_name = "PX", conflicts_with = "compare_relief")]
    pub depth_relief: Option<u32>,
    /// The reference's gradient leak between phases for every run (`gast stylize --phase-leak`).
    #[arg(long, conflicts_with = "compare_relief")]
    pub phase_leak: Option<bool>,
    /// Run the same steps on --device three times in this process: without the depth relief,
    /// with it at this radius (`gast stylize --depth-relief PX`), and with it and the phase
    /// leak (`--phase-leak true`), and print what each costs against the first. Give --steps
    /// past the first cycle's 10 colour steps (30: 20 geometry steps) to time both phases.
    #[arg(long, value_name = "PX", conflicts_with_all = [
        "compare", "compare_focus", "compare_assign", "compare_sliced_depth", "compare_palette",
        "compare_assign_block"
    ])]
    pub compare_relief: Option<u32>,
    /// Depth Anything V2 checkpoint for the style depth line (else $GAST_DEPTH_MODEL or the
    /// caches; never downloaded here).
    #[arg(long)]
    pub depth_model: Option<PathBuf>,
    /// The new settings, timed step by step beside the reference (im2col, exact matching);
    /// giving any of them runs that comparison on the CPU instead of the device runs, except
    /// --matching-reuse alone with a GPU device (gpu, or auto on a hardware GPU): the GPU
    /// engine's steps searching every visit, then keeping the matches.
    #[command(flatten)]
    pub fast: super::super::stylize::FastArgs,
    /// Also write what was measured (each run's device, steps, wall time, per-phase step
    /// medians and GPU memory) to this JSON file, for scripts such as `tools/gpu-check`
    /// (the device runs and the `--compare*` arms; not the fast-settings comparison).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Time the steps alone: leave out the per-part timings after them (the GPU parts, the
    /// CPU's VGG against its GEMM floor, the style depth network), which on a software adapter
    /// take longer than the steps.
    #[arg(long)]
    pub no_parts: bool,
    /// Timed repetitions of each part, after a warm-up (the GEMMs and the CPU's VGG take at most
    /// 3): 1 checks that the parts run, as the GPU check's dry run does on lavapipe.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u16).range(1..=100))]
    pub part_reps: u16,
}

/// Per-step medians of the host's share of a GPU step (ms; zeros on the CPU).
#[derive(Clone, Copy, Debug)]
struct HostMedians {
    pairing: f64,
    waits: f64,
    record: f64,
    submit: f64,
    bind_groups: f64,
    passes: f64,
}

/// What one device's run of the step benchmark measured.
struct StepRun {
    device: String,
    steps: usize,
    wall_s: f64,
    per_phase: Vec<(gast_core::style::Phase, f64)>,
    /// Per phase, the medians of the host's share of a GPU step.
    host_per_phase: Vec<(gast_core::style::Phase, HostMedians)>,
    first_losses: Option<gast_core::session::LossTerms>,
    gpu_memory_mib: Option<f64>,
    /// The share of the frame the GPU engine's VGG runs on (its object window).
    vgg_window_share: Option<f64>,
    targets_s: f64,
}

impl StepRun {
    /// The run as the `--json` file's record, under `label`.
    fn to_json(&self, label: &str) -> serde_json::Value {
        let phase = |p: gast_core::style::Phase| self.per_phase.iter().find(|x| x.0 == p).map(|x| x.1);
        let host = |p: gast_core::style::Phase| self.host_per_phase.iter().find(|x| x.0 == p).map(|x| x.1);
        let (colour, geometry) = (host(gast_core::style::Phase::Color), host(gast_core::style::Phase::Geometry));
        serde_json::json!({
            "label": label,
            "device": self.device,
            "steps": self.steps,
            "wall_s": self.wall_s,
            "ms_per_step": self.wall_s * 1e3 / self.steps.max(1) as f64,
            "colour_step_median_ms": phase(gast_core::style::Phase::Color),
            "geometry_step_median_ms": phase(gast_core::style::Phase::Geometry),
            "colour_pairing_median_ms": colour.map(|h| h.pairing),
            "geometry_pairing_median_ms": geometry.map(|h| h.pairing),
            "colour_device_wait_median_ms": colour.map(|h| h.waits),
            "geometry_device_wait_median_ms": geometry.map(|h| h.waits),
            "colour_record_median_ms": colour.map(|h| h.record),
            "geometry_record_median_ms": geometry.map(|h| h.record),
            "colour_submit_median_ms": colour.map(|h| h.submit),
            "geometry_submit_median_ms": geometry.map(|h| h.submit),
            "colour_bind_groups": colour.map(|h| h.bind_groups),
            "geometry_bind_groups": geometry.map(|h| h.bind_groups),
            "colour_passes": colour.map(|h| h.passes),
            "geometry_passes": geometry.map(|h| h.passes),
            "gpu_memory_mib": self.gpu_memory_mib,
            "vgg_window_share": self.vgg_window_share,
            "targets_s": self.targets_s,
        })
    }
}

/// Writes `--json`'s file: the benchmark's settings and every run, atomically.
fn write_json(args: &StepArgs, runs: &[(&str, &StepRun)]) -> anyhow::Result<()> {
    let Some(path) = &args.json else { return Ok(()) };
    let (peak, _) = memory_mib();
    let doc = serde_json::json!({
        "scene": args.data.scene.as_ref().map(|p| p.display().to_string()),
        "resolution": args.resolution,
        "views": args.views,
        "framing": format!("{:?}", args.framing).to_lowercase(),
        "peak_resident_mib": peak,
        "runs": runs.iter().map(|(l, r)| r.to_json(l)).collect::<Vec<_>>(),
    });
    let text = serde_json::to_string_pretty(&doc)?;
    gast_core::io::write_bytes(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// What both step benchmarks load: the scene, its orbit views, the style and the network.
pub(super) struct StepInputs {
    pub(super) scene: std::sync::Arc<gast_core::Gaussians>,
    pub(super) views: Vec<Camera>,
    pub(super) style: gast_core::session::StyleImage,
    pub(super) vgg: std::sync::Arc<gast_core::vision::Vgg>,
}

/// Loads `args`' scene, style and weights (the shared data's guitar, wave and
/// VGG file by default), after resetting the peak-memory mark, makes the
/// orbit views and prints the benchmark's first line.
pub(super) fn step_inputs(args: &StepArgs) -> anyhow::Result<StepInputs> {
    let (scene_path, style_path, weights) = args.data.paths()?;
    reset_peak_memory();
    let scene = load_scene(&scene_path)?;
    let style = gast_core::session::StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    let vgg = std::sync::Arc::new(super::super::stylize::load_vgg(weights.as_deref())?);
    let views = views_for(
        &scene,
        &ViewArgs {
            cameras: args.cameras.clone(),
            orbit: false,
            views: args.views,
            size: args.resolution,
            fov: 50.0,
            framing: args.framing,
            crop: false,
        },
    )?;
    let framing = match &args.cameras {
        Some(path) => format!("the cameras of {}", path.display()),
        None => format!("{:?} framing", args.framing),
    };
    println!(
        "step benchmark: {} ({} Gaussians), style {}, {} views at {} px ({framing}), {} threads",
        scene_path.display(),
        scene.len(),
        style_path.display(),
        views.len(),
        args.resolution,
        rayon::current_num_threads()
    );
    Ok(StepInputs { scene: std::sync::Arc::new(scene), views, style, vgg })
}

/// With `--matching-reuse` alone and a GPU: the engine with and without
/// re-used matches ([`compare_reuse_gpu`]); `None` otherwise.
pub(super) fn reuse_on_gpu(args: &StepArgs) -> anyhow::Result<Option<ExitCode>> {
    let f = &args.fast;
    let reuse_only = f.conv.is_none()
        && f.matching.is_none()
        && f.matching_dims.is_none()
        && f.matching_candidates.is_none()
        && f.vgg_window.is_none()
        && f.assign_block.is_none();
    if let (Some(reuse), true, false) = (
        f.matching_reuse,
        reuse_only,
        args.compare
            || args.compare_focus
            || args.compare_assign
            || args.compare_sliced_depth
            || args.compare_palette
            || args.compare_assign_block
            || args.compare_relief.is_some(),
    ) && let Some(ctx) = args.device.resolve().with_context(|| format!("--device {}", args.device))?
    {
        return compare_reuse_gpu(args, ctx, reuse).map(Some);
    }
    Ok(None)
}

/// Whether any of issue 10's options is given (`step_fast` times them beside the reference).
pub(super) fn asks_fast(args: &StepArgs) -> bool {
    let f = &args.fast;
    f.conv.is_some()
        || f.matching.is_some()
        || f.matching_dims.is_some()
        || f.matching_candidates.is_some()
        || f.matching_reuse.is_some()
        || f.vgg_window.is_some()
}

/// The default settings at `--resolution` and `--focus`, with `--assign-block`
/// (the one choice of [`super::super::stylize::FastArgs`] these runs take: the
/// others go to `step_fast`), `--depth-relief` and `--phase-leak`, checked.
fn step_config(args: &StepArgs) -> anyhow::Result<gast_core::style::StyleConfig> {
    let mut config = gast_core::style::StyleConfig {
        resolution: args.resolution,
        texture_scale: args.texture_scale,
        focus: args.focus,
        ..gast_core::style::StyleConfig::default()
    };
    config.assign_block = args.fast.assign_block.unwrap_or(config.assign_block);
    config.depth_relief_px = args.depth_relief.unwrap_or(config.depth_relief_px);
    config.phase_leak = args.phase_leak.unwrap_or(config.phase_leak);
    crate::cli::checked(config)
}

/// Per-step breakdown of the optimisation, the whole schedule's time, and
/// memory, with the default settings (`bench::run_step` dispatches).
pub(super) fn run_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    use gast_core::gpu::DeviceChoice;
    use gast_core::style::{Phase, StyleConfig};

    // Checked before the scene, the style and VGG are loaded.
    if let Some(path) = &args.json {
        crate::cli::replaceable_json(path, "--json")?;
    }
    let config = step_config(&args)?;
    let inputs = step_inputs(&args)?;
    let schedule = config.schedule();
    let budget = match args.steps {
        Some(n) => n,
        None if args.full => schedule.total_steps(),
        None => schedule.color_steps + args.geometry_steps,
    };
    if args.compare_focus {
        return compare_focus(&args, &inputs, &config, budget);
    }
    if args.compare_assign {
        let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
        // The object recipe would switch the terms on in the arm without them.
        let off = StyleConfig { object_recipe: false, ..config.clone() };
        let mut on = off.clone();
        (on.weights.assignment_cosine, on.weights.assignment) =
            (gast_core::style::config::OBJECT_RECIPE_ASSIGN_COS, gast_core::style::config::OBJECT_RECIPE_ASSIGN);
        return compare_arms(&args, &inputs, &[("without", off), ("λ_asc 10 + λ_as 0.015", on)], gpu, budget);
    }
    if args.compare_assign_block {
        let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
        let mut blocks = StyleConfig { object_recipe: false, ..config.clone() };
        (blocks.weights.assignment_cosine, blocks.weights.assignment) =
            (gast_core::style::config::OBJECT_RECIPE_ASSIGN_COS, gast_core::style::config::OBJECT_RECIPE_ASSIGN);
        let one = StyleConfig { assign_block: gast_core::style::assignment::ASSIGN_MAX as u32, ..blocks.clone() };
        let label = format!("blocks of {}", blocks.assign_block);
        return compare_arms(&args, &inputs, &[("one block", one), (label.as_str(), blocks)], gpu, budget);
    }
    if args.compare_sliced_depth {
        let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
        let off = StyleConfig { frame_recipe: false, ..config.clone() };
        let mut on = off.clone();
        on.weights.sliced_depth = gast_core::style::config::FRAME_RECIPE_SLICED_DEPTH;
        return compare_arms(&args, &inputs, &[("without", off), ("λ_swd 1", on)], gpu, budget);
    }
    if args.compare_palette {
        let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
        use gast_core::style::config::{OBJECT_RECIPE_ASSIGN, OBJECT_RECIPE_ASSIGN_COS, OBJECT_RECIPE_PALETTE};
        // The object recipe without its hold, then with it: the recipe itself would fill λ_pal in both.
        let mut off = StyleConfig { object_recipe: false, ..config.clone() };
        (off.weights.assignment_cosine, off.weights.assignment) = (OBJECT_RECIPE_ASSIGN_COS, OBJECT_RECIPE_ASSIGN);
        let mut on = off.clone();
        on.weights.palette = OBJECT_RECIPE_PALETTE;
        return compare_arms(&args, &inputs, &[("without", off), ("λ_pal 100", on)], gpu, budget);
    }
    if let Some(px) = args.compare_relief {
        let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
        let relief = crate::cli::checked(StyleConfig { depth_relief_px: px, ..config.clone() })?;
        let leak = StyleConfig { phase_leak: true, ..relief.clone() };
        let (with, with_leak) = (format!("relief {px} px"), format!("relief {px} px + phase leak"));
        let arms = [("without", config.clone()), (with.as_str(), relief), (with_leak.as_str(), leak)];
        return compare_arms(&args, &inputs, &arms, gpu, budget);
    }
    let devices: Vec<DeviceChoice> =
        if args.compare { vec![DeviceChoice::Cpu, DeviceChoice::Gpu] } else { vec![args.device] };
    let mut runs = Vec::new();
    for device in devices {
        let gpu = device.resolve().with_context(|| format!("--device {device}"))?;
        let run = time_steps(&inputs, &config, gpu, budget)?;
        runs.push(run);
    }
    if let [cpu, gpu] = &runs[..] {
        println!("\nCPU against GPU, the same {} steps in one process:", cpu.steps.min(gpu.steps));
        print_against(("GPU", gpu), ("CPU", cpu));
        if let (Some(a), Some(b)) = (cpu.first_losses, gpu.first_losses) {
            // Relative to the larger of the two, and to at least 1e-6: a term both engines
            // leave at rounding noise (content 2e-10 against 0 on the first step) reads ~0.
            let rel = |x: f32, y: f32| f64::from((x - y).abs()) / f64::from(x.abs().max(y.abs()).max(1e-6));
            println!(
                "  first step's losses, relative difference: total {:.1e}, GCFM {:.1e}, content {:.1e}, TV {:.1e}, depth {:.1e} ({} on the GPU)",
                rel(a.total, b.total),
                rel(a.gcfm, b.gcfm),
                rel(a.content, b.content),
                rel(a.tv, b.tv),
                rel(a.depth, b.depth),
                gpu.device
            );
        }
    }
    if !args.no_parts {
        print_parts(&args, &inputs, &runs)?;
    }
    for run in &runs {
        let total = f64::from(schedule.total_steps());
        if run.steps as u32 >= schedule.total_steps() {
            println!(
                "\nwhole schedule on {}: {} steps in {:.1} s ({:.1} min), measured",
                run.device,
                run.steps,
                run.wall_s,
                run.wall_s / 60.0
            );
        } else if args.steps.is_some() {
            println!(
                "\n{} steps on {} in {:.2} s measured ({:.2} ms a step; the default schedule has {total} steps)",
                run.steps,
                run.device,
                run.wall_s,
                run.wall_s * 1e3 / run.steps.max(1) as f64
            );
        } else {
            let colour = run.per_phase.iter().find(|p| p.0 == Phase::Color).map_or(0.0, |p| p.1);
            let geometry = run.per_phase.iter().find(|p| p.0 == Phase::Geometry).map_or(0.0, |p| p.1);
            let est = (f64::from(schedule.cycles * schedule.color_steps) * colour
                + f64::from(schedule.cycles * schedule.geometry_steps) * geometry)
                / 1e3;
            println!(
                "\nwhole default schedule on {} ({} colour + {} geometry steps), extrapolated from the medians: {:.0} s ({:.1} min); `--steps 3000` measures it",
                run.device,
                schedule.cycles * schedule.color_steps,
                schedule.cycles * schedule.geometry_steps,
                est,
                est / 60.0
            );
        }
    }
    let (peak, rss) = memory_mib();
    println!("memory: peak resident {peak:.0} MiB, now {rss:.0} MiB");
    let labelled: Vec<(&str, &StepRun)> =
        runs.iter().map(|r| (if r.device.starts_with("CPU") { "cpu" } else { "gpu" }, r)).collect();
    write_json(&args, &labelled)?;
    Ok(ExitCode::SUCCESS)
}

/// `gast bench step --compare-focus`: the same steps on one device with the
/// losses over the whole frame, then focused on the object, and the ratio of
/// their per-phase medians.
fn compare_focus(
    args: &StepArgs,
    inputs: &StepInputs,
    config: &gast_core::style::StyleConfig,
    budget: u32,
) -> anyhow::Result<ExitCode> {
    use gast_core::style::{Focus, StyleConfig};
    let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
    let arms = [
        ("frame", StyleConfig { focus: Focus::Frame, ..config.clone() }),
        ("object", StyleConfig { focus: Focus::Object, ..config.clone() }),
    ];
    compare_arms(args, inputs, &arms, gpu, budget)
}

/// The same steps on one device with two or more configurations (`arms`, the
/// reference first), and the ratio of each one's per-phase medians to the
/// reference's.
fn compare_arms(
    args: &StepArgs,
    inputs: &StepInputs,
    arms: &[(&str, gast_core::style::StyleConfig)],
    gpu: Option<gast_core::gpu::GpuContext>,
    budget: u32,
) -> anyhow::Result<ExitCode> {
    let mut runs = Vec::new();
    for (label, config) in arms {
        println!("\n{label}:");
        runs.push(time_steps(inputs, config, gpu.clone(), budget)?);
    }
    let (Some(a), Some((la, _))) = (runs.first(), arms.first()) else { return Ok(ExitCode::FAILURE) };
    for (b, (lb, _)) in runs.iter().zip(arms).skip(1) {
        println!("\n{la} against {lb} on {}, the same {} steps in one process:", a.device, a.steps);
        print_against((la, a), (lb, b));
    }
    let labelled: Vec<(&str, &StepRun)> = arms.iter().map(|(l, _)| *l).zip(&runs).collect();
    write_json(args, &labelled)?;
    Ok(ExitCode::SUCCESS)
}

/// Two runs of the same steps side by side: each phase's step median and the
/// whole run's time, and the ratio `other / reference`.
fn print_against((la, a): (&str, &StepRun), (lb, b): (&str, &StepRun)) {
    for (phase, a_ms) in &a.per_phase {
        if let Some((_, b_ms)) = b.per_phase.iter().find(|p| p.0 == *phase) {
            println!(
                "  {:<9} step median: {la} {:>9.2} ms, {lb} {:>9.2} ms, {lb}/{la} {:.3}",
                format!("{phase:?}").to_lowercase(),
                a_ms,
                b_ms,
                b_ms / a_ms.max(1e-9)
            );
        }
    }
    println!(
        "  whole run: {la} {:.2} s, {lb} {:.2} s, {lb}/{la} {:.3}",
        a.wall_s,
        b.wall_s,
        b.wall_s / a.wall_s.max(1e-9)
    );
}

/// `gast bench step --matching-reuse N` on a GPU: the GPU engine's steps
/// searching at every visit, then keeping each view's matches for N visits.
fn compare_reuse_gpu(args: &StepArgs, ctx: gast_core::gpu::GpuContext, reuse: u32) -> anyhow::Result<ExitCode> {
    use gast_core::style::{MatchingConfig, StyleConfig};
    let config = step_config(args)?;
    let inputs = step_inputs(args)?;
    let schedule = config.schedule();
    let budget = args.steps.unwrap_or(schedule.color_steps + args.geometry_steps);
    let kept = StyleConfig { matching: MatchingConfig { reuse, ..MatchingConfig::default() }, ..config.clone() };
    let label = format!("reuse {reuse}");
    compare_arms(args, &inputs, &[("reuse 1", config), (label.as_str(), kept)], Some(ctx), budget)
}

/// Runs `budget` steps of a fresh session on `gpu` (the CPU when `None`) and
/// prints the per-phase table.
fn time_steps(
    step_inputs: &StepInputs,
    config: &gast_core::style::StyleConfig,
    gpu: Option<gast_core::gpu::GpuContext>,
    budget: u32,
) -> anyhow::Result<StepRun> {
    use gast_core::session::{Event, Session, SessionInputs, StepReport, StyleDepthSource};
    use gast_core::style::Phase;

    let StepInputs { scene, views, style, vgg } = step_inputs;
    let inputs = SessionInputs {
        scene: std::sync::Arc::clone(scene),
        cameras: views.clone(),
        style: style.clone(),
        style_depth: StyleDepthSource::Heuristic,
        vgg: vgg.clone(),
        config: config.clone(),
        gpu,
    };
    let mut session = Session::prepare(inputs, &mut |e| match e {
        Event::Stage { name, seconds } => println!("  prepare: {name:<20} {:>8.0} ms", seconds * 1e3),
        Event::Culled { total, kept } => println!("  culling: optimising {kept} of {total} Gaussians"),
        _ => {}
    })?;
    let device = session.device();
    println!("\n{device}");
    let warm = session.warm_view_targets().map_err(|e| anyhow::anyhow!("{device}: {e}"))?;
    println!(
        "  per-view targets (G^c render, content features) of {} views, once per run: {:.0} ms",
        views.len(),
        warm * 1e3
    );
    let vgg_window_share = session.gpu_vgg_window_share();
    if let Some(share) = vgg_window_share {
        println!(
            "  VGG on the object's window: {:.0}% of the frame's feature positions (GAST_VGG_WINDOW=0: the whole frame)",
            share * 1e2
        );
    }
    let pb = crate::progress::bar(u64::from(budget), "steps");
    let mut reports: Vec<(StepReport, f64)> = Vec::new();
    let t_all = Instant::now();
    for _ in 0..budget {
        let t = Instant::now();
        let Some(r) = session.step() else { break };
        reports.push((r, t.elapsed().as_secs_f64() * 1e3));
        crate::progress::tick(&pb);
    }
    let wall_s = t_all.elapsed().as_secs_f64();
    pb.finish_and_clear();
    // After the steps: the VGG window and the buffers made on first use are in.
    let gpu_memory_mib = session.gpu_memory_bytes().map(|b| b as f64 / f64::from(1u32 << 20));
    if let Some(mib) = gpu_memory_mib {
        println!("  GPU memory allocated by the engine over the run: {mib:.1} MiB");
    }
    if let Some(why) = session.failure() {
        anyhow::bail!("{device}: the run stopped at {why}");
    }
    println!("per-step medians (ms), every view's targets computed before the timed steps");
    println!(
        "{:<10} {:>6} {:>8} {:>10} {:>9} {:>10} {:>10} {:>8} {:>8} {:>8} {:>8} {:>8} {:>6} {:>6} {:>9}",
        "phase",
        "steps",
        "render",
        "vgg fwd×3",
        "matching",
        "vgg bwd",
        "raster bwd",
        "adam",
        "pairing",
        "waits",
        "record",
        "submit",
        "binds",
        "passes",
        "step"
    );
    let (mut per_phase, mut host_per_phase) = (Vec::new(), Vec::new());
    for phase in [Phase::Color, Phase::Geometry] {
        let rows: Vec<&(StepReport, f64)> = reports.iter().filter(|(r, _)| r.phase == phase).collect();
        if rows.is_empty() {
            continue;
        }
        let m = |f: &dyn Fn(&StepReport) -> f32| median(rows.iter().map(|(r, _)| f64::from(f(r))).collect());
        let wall = median(rows.iter().map(|(_, w)| *w).collect());
        per_phase.push((phase, wall));
        let host = HostMedians {
            pairing: m(&|r| r.timings.pairing_ms),
            waits: m(&|r| r.timings.device_wait_ms),
            record: m(&|r| r.timings.record_ms),
            submit: m(&|r| r.timings.submit_ms),
            bind_groups: m(&|r| r.timings.bind_groups as f32),
            passes: m(&|r| r.timings.passes as f32),
        };
        host_per_phase.push((phase, host));
        println!(
            "{:<10} {:>6} {:>8.1} {:>10.1} {:>9.1} {:>10.1} {:>10.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>6.0} {:>6.0} {:>9.2}",
            format!("{phase:?}").to_lowercase(),
            rows.len(),
            m(&|r| r.timings.render_ms),
            m(&|r| r.timings.features_ms),
            m(&|r| r.timings.matching_ms),
            m(&|r| r.timings.vgg_backward_ms),
            m(&|r| r.timings.raster_backward_ms),
            m(&|r| r.timings.update_ms),
            host.pairing,
            host.waits,
            host.record,
            host.submit,
            host.bind_groups,
            host.passes,
            wall
        );
    }
    if session.gpu_memory_bytes().is_some() {
        println!(
            "(on the GPU the parts run back to back in one submission; their times are below; \
             \"pairing\" is the host's, \"waits\" the host waiting on the device, \"record\" the host \
             recording the step's commands, \"submit\" handing them to the queue, \"binds\" the bind \
             groups made (a dispatch reuses the one an earlier step made for its buffers), \"passes\" the compute passes they ran in)"
        );
    }
    Ok(StepRun {
        device,
        steps: reports.len(),
        wall_s,
        per_phase,
        host_per_phase,
        first_losses: reports.first().map(|r| r.0.losses),
        gpu_memory_mib,
        vgg_window_share,
        targets_s: warm,
    })
}

/// Each GPU part of a step timed on its own at the benchmark's size, `reps`
/// times after a warm-up (the GEMMs at most 3).
fn gpu_parts(
    ctx: &gast_core::gpu::GpuContext,
    vgg: &gast_core::vision::Vgg,
    scene: &gast_core::Gaussians,
    cam: &Camera,
    resolution: usize,
    reps: usize,
) -> anyhow::Result<()> {
    use gast_core::gpu;
    println!("\nGPU parts on {} (median ms)", ctx.describe());
    let mut rows = gpu::bench_raster(ctx, scene, cam)?;
    let side = resolution / 2;
    rows.extend(gpu::bench_vgg(ctx, vgg, side, side, reps));
    let n = (side / 4) * (side / 4);
    rows.extend(gpu::bench_gcfm(ctx, 768, n, 4096, reps));
    // The GEMM at the step's shapes in both tilings (`GAST_GEMM_TILE` picks
    // one for the parts above; auto takes 128² where the grid stays full).
    for (rows_a, cols_b, inner) in [(n, 4096, 256), (1152, n, 256), (256, n, 1152)] {
        for tile in [gpu::GemmTile::Narrow, gpu::GemmTile::Wide] {
            rows.extend(gpu::bench_gemm(ctx, rows_a, cols_b, inner, reps.min(3), tile));
        }
    }
    rows.extend(gpu::bench_image_ops(ctx, &[resolution], scene.len(), reps)?);
    for (name, ms) in rows {
        println!("  {name:<36} {ms:>9.3}");
    }
    Ok(())
}

/// The per-part timings after the steps (left out by `--no-parts`): one VGG
/// modality against the CPU's GEMM floor where a run was on the CPU, the
/// style depth network, and the GPU parts where a run was on the GPU.
fn print_parts(args: &StepArgs, inputs: &StepInputs, runs: &[StepRun]) -> anyhow::Result<()> {
    let side = (args.resolution / 2) as usize;
    if runs.iter().any(|r| r.device.starts_with("CPU")) {
        // One modality at the VGG input size (the render downscaled 0.5×), and the gemm floor.
        let reps = usize::from(args.part_reps).min(3);
        let vt = gast_core::vision::vgg::bench(&inputs.vgg, side, side, reps);
        let gemm = gast_core::vision::gemm_gflops(256, 64 * 64, 2304, reps);
        let flops = inputs.vgg.forward_flops(side, side);
        println!("\none modality on the CPU: {vt}");
        println!(
            "gemm floor: {gemm:.0} GFLOP/s measured (256×4096×2304); one VGG forward at {side}² is {:.2} GFLOP = {:.0} ms at that rate, measured {:.0} ms ({:.0}% of the floor's speed)",
            flops * 1e-9,
            flops / gemm / 1e6,
            vt.forward_s * 1e3,
            100.0 * (flops / gemm / 1e9) / vt.forward_s
        );
    }
    time_style_depth(&inputs.style, args.depth_model.as_deref(), 1, false, false)?;
    if !runs.iter().all(|r| r.device.starts_with("CPU")) {
        let ctx = gast_core::gpu::DeviceChoice::Gpu.resolve()?.context("no GPU adapter for the per-part figures")?;
        let (scene, view) = (&inputs.scene, &inputs.views[0]);
        gpu_parts(&ctx, &inputs.vgg, scene, view, args.resolution as usize, usize::from(args.part_reps))?;
    }
    Ok(())
}

/// Medians of one phase: render, VGG forwards, matching, VGG backwards, raster backward, Adam, step (ms).
pub(super) type PhaseRow = [f64; 7];

/// Per-phase medians of `reports` (each with its step's wall time in ms).
pub(super) fn phase_rows(
    reports: &[(gast_core::session::StepReport, f64)],
) -> Vec<(gast_core::style::Phase, usize, PhaseRow)> {
    use gast_core::style::Phase;
    let mut out = Vec::new();
    for phase in [Phase::Color, Phase::Geometry] {
        let rows: Vec<_> = reports.iter().filter(|(r, _)| r.phase == phase).collect();
        if rows.is_empty() {
            continue;
        }
        let m = |f: &dyn Fn(&gast_core::session::StepTimings) -> f32| {
            median(rows.iter().map(|(r, _)| f64::from(f(&r.timings))).collect())
        };
        let row = [
            m(&|t| t.render_ms),
            m(&|t| t.features_ms),
            m(&|t| t.matching_ms),
            m(&|t| t.vgg_backward_ms),
            m(&|t| t.raster_backward_ms),
            m(&|t| t.update_ms),
            median(rows.iter().map(|(_, w)| *w).collect()),
        ];
        out.push((phase, rows.len(), row));
    }
    out
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        step: StepArgs,
    }

    /// `--cameras` takes the scene's own views (fern's 20 LLFF cameras, 4:3)
    /// at `--resolution` on the longer side, as `gast stylize --cameras` does.
    #[test]
    fn the_step_benchmark_takes_the_scenes_own_cameras() {
        let shared = gast_tests::shared_dir();
        let (scene, fern) = (shared.join("data/scenes/guitar.compressed.ply"), shared.join("data/datasets/fern"));
        let (weights, style) =
            (shared.join("data/weights/vgg19-conv3.safetensors"), shared.join("data/styles/wave.jpg"));
        if !(scene.is_file() && fern.is_dir() && weights.is_file() && style.is_file()) {
            assert!(std::env::var("CI").is_err(), "no shared data at {} (CI: a failure)", shared.display());
            eprintln!(
                "SKIPPED the_step_benchmark_takes_the_scenes_own_cameras: no shared data at {}",
                shared.display()
            );
            return;
        }
        let arg = |p: &PathBuf| p.to_string_lossy().into_owned();
        let cli = Cli::try_parse_from([
            "bench-step".to_string(),
            "--scene".into(),
            arg(&scene),
            "--weights".into(),
            arg(&weights),
            "--style".into(),
            arg(&style),
            "--cameras".into(),
            arg(&fern),
            "--resolution".into(),
            "64".into(),
        ])
        .expect("the flags parse");
        let inputs = step_inputs(&cli.step).expect("the inputs load");
        assert_eq!(inputs.views.len(), 20, "fern's LLFF cameras");
        assert!(
            inputs.views.iter().all(|c| (c.width, c.height) == (64, 48)),
            "{:?}",
            (inputs.views[0].width, inputs.views[0].height)
        );
    }
}
