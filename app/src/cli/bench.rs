//! `gast bench …`: benchmarks that print figures. Timings are medians over
//! several views after a warm-up; memory is the process's peak resident set,
//! reset before each scene (Linux `clear_refs`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use gast_core::camera::Camera;
use gast_core::raster::{self, RenderOptions};

use super::{Framing, ViewArgs, load_scene, views_for};

/// Arguments of `gast bench raster`.
#[derive(Args, Debug)]
pub struct RasterArgs {
    /// Scenes to measure (default: playbot-sog and guitar from the shared data folder,
    /// `$GAST_SHARED` or `../shared`).
    pub scenes: Vec<PathBuf>,
    /// Image sizes (longer side, pixels).
    #[arg(long, value_delimiter = ',', default_values_t = [256u32, 512])]
    pub sizes: Vec<u32>,
    /// Orbit views per scene and size (each timed once after a warm-up).
    #[arg(long, default_value_t = 8)]
    pub views: usize,
}

/// The shared data folder: `$GAST_SHARED`, else `../shared`.
pub(super) fn shared_dir() -> PathBuf {
    std::env::var_os("GAST_SHARED").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("../shared"))
}

/// Peak and current resident memory of this process in MiB (0 where unknown).
pub fn memory_mib() -> (f64, f64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |key: &str| {
        status
            .lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<f64>().ok())
            .map_or(0.0, |kib| kib / 1024.0)
    };
    (field("VmHWM:"), field("VmRSS:"))
}

/// Resets the peak resident set size to the current one (Linux ≥ 4.0).
pub fn reset_peak_memory() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() { 0.0 } else { v[v.len() / 2] }
}

/// Times forward and backward on every scene and size, then the dense reference.
pub fn run_raster(args: RasterArgs) -> anyhow::Result<ExitCode> {
    let scenes = if args.scenes.is_empty() {
        let d = shared_dir().join("data/scenes");
        vec![d.join("playbot-sog"), d.join("guitar.compressed.ply")]
    } else {
        args.scenes.clone()
    };
    println!(
        "rasterizer benchmark: {} threads, {} orbit views per row, median ms",
        rayon::current_num_threads(),
        args.views
    );
    println!(
        "{:<24} {:>9} {:>6} {:>11} {:>12} {:>14} {:>10} {:>10}",
        "scene", "gaussians", "size", "forward ms", "backward ms", "Mgaussians/s", "peak MiB", "load s"
    );
    let opts = RenderOptions::default();
    let mut small = None;
    for path in &scenes {
        reset_peak_memory();
        let t = Instant::now();
        let scene = load_scene(path)?;
        let load_s = t.elapsed().as_secs_f64();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if small.is_none() {
            let step = (scene.len() / 2_000).max(1);
            let keep: Vec<u32> = (0..scene.len() as u32).step_by(step).take(2_000).collect();
            small = Some((name.clone(), gast_core::session::subset(&scene, &keep)));
        }
        for &size in &args.sizes {
            let views = views_for(
                &scene,
                &ViewArgs { cameras: None, views: args.views, size, fov: 50.0, framing: Framing::Full, crop: false },
            )?;
            let (fwd, bwd) = time_views(&scene, &views, &opts);
            let (peak, _) = memory_mib();
            println!(
                "{:<24} {:>9} {:>6} {:>11.1} {:>12.1} {:>14.1} {:>10.0} {:>10.2}",
                name,
                scene.len(),
                size,
                fwd,
                bwd,
                scene.len() as f64 / (fwd / 1e3) / 1e6,
                peak,
                load_s
            );
        }
    }
    if let Some((name, scene)) = small {
        dense_ratio(&name, &scene)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Median forward and backward milliseconds over the views (first view warms up).
fn time_views(scene: &gast_core::Gaussians, views: &[Camera], opts: &RenderOptions) -> (f64, f64) {
    let mut fwd = Vec::new();
    let mut bwd = Vec::new();
    for (i, cam) in views.iter().enumerate() {
        let t = Instant::now();
        let (img, state) = raster::forward(scene, cam, opts);
        let f = t.elapsed().as_secs_f64() * 1e3;
        let v_rgb: Vec<f32> = (0..img.rgb.len()).map(|k| ((k * 7919) % 13) as f32 / 13.0 - 0.5).collect();
        let v_depth: Vec<f32> = (0..img.inv_depth.len()).map(|k| ((k * 104_729) % 11) as f32 / 11.0 - 0.5).collect();
        let t = Instant::now();
        let grads = raster::backward(scene, cam, opts, &state, &v_rgb, &v_depth);
        let b = t.elapsed().as_secs_f64() * 1e3;
        std::hint::black_box(&grads);
        if i > 0 || views.len() == 1 {
            fwd.push(f);
            bwd.push(b);
        }
    }
    (median(fwd), median(bwd))
}

/// The dense reference against the tiled path on a small scene (every n-th
/// Gaussian of a real one), from an orbit view at 96².
fn dense_ratio(name: &str, scene: &gast_core::Gaussians) -> anyhow::Result<()> {
    let views = views_for(
        scene,
        &ViewArgs { cameras: None, views: 1, size: 96, fov: 50.0, framing: Framing::Full, crop: false },
    )?;
    let cam = &views[0];
    let opts = RenderOptions::default();
    let t = Instant::now();
    let tiled = raster::render(scene, cam, &opts);
    let t_tiled = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let dense = raster::dense::render(scene, cam, &opts);
    let t_dense = t.elapsed().as_secs_f64() * 1e3;
    let diff = tiled.rgb.iter().zip(&dense.rgb).fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    println!(
        "dense reference, {} Gaussians of {name} at 96x96: dense {t_dense:.1} ms, tiled {t_tiled:.2} ms, ratio {:.0}x, max |diff| {diff:.1e}",
        scene.len(),
        t_dense / t_tiled.max(1e-6)
    );
    Ok(())
}

/// Arguments of `gast bench step`.
#[derive(Args, Debug)]
pub struct StepArgs {
    /// Scene (default: guitar.compressed.ply from the shared data folder).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Style image (default: styles/wave.jpg from the shared data folder).
    #[arg(long)]
    pub style: Option<PathBuf>,
    /// VGG weights (default: the shared vgg19-conv3.safetensors, else the usual resolution).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Working resolution (longer side, pixels).
    #[arg(long, default_value_t = 256)]
    pub resolution: u32,
    /// Orbit views.
    #[arg(long, default_value_t = 36)]
    pub views: usize,
    /// Geometry steps to time after the first cycle's colour steps.
    #[arg(long, default_value_t = 20)]
    pub geometry_steps: u32,
    /// Run the whole default schedule (3,000 steps) instead of extrapolating from the timed steps.
    #[arg(long)]
    pub full: bool,
    /// Run exactly this many steps of the default schedule and report their measured time
    /// (overrides --geometry-steps and --full).
    #[arg(long)]
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
    /// Depth Anything V2 checkpoint for the style depth line (else $GAST_DEPTH_MODEL or the
    /// caches; never downloaded here).
    #[arg(long)]
    pub depth_model: Option<PathBuf>,
    /// The new settings, timed step by step beside the reference (im2col, exact matching);
    /// giving any of them runs that comparison on the CPU instead of the device runs.
    #[command(flatten)]
    pub fast: super::stylize::FastArgs,
}

/// What one device's run of the step benchmark measured.
struct StepRun {
    device: String,
    steps: usize,
    wall_s: f64,
    per_phase: Vec<(gast_core::style::Phase, f64)>,
    first_losses: Option<gast_core::session::LossTerms>,
}

/// Arguments of `gast bench depth`.
#[derive(Args, Debug)]
pub struct DepthArgs {
    /// Style image (default: styles/wave.jpg from the shared data folder).
    #[arg(long)]
    pub style: Option<PathBuf>,
    /// Depth Anything V2 checkpoint (else $GAST_DEPTH_MODEL or the caches; never downloaded here).
    #[arg(long)]
    pub depth_model: Option<PathBuf>,
    /// Forward passes at 518×518 to time (the median is printed).
    #[arg(long, default_value_t = 3)]
    pub reps: usize,
    /// Also print the wall time of each stage of one forward at 518×518 and
    /// one at the style's input size.
    #[arg(long)]
    pub stages: bool,
}

/// CPU time this process has used (user + system), from `/proc/self/stat`;
/// on a shared machine it tells what a pass costs when the wall clock cannot.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces) start at index 2.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

/// The style depth network's time per style, and its forward at 518×518.
pub fn run_depth(args: DepthArgs) -> anyhow::Result<ExitCode> {
    let style_path = args.style.clone().unwrap_or_else(|| shared_dir().join("data/styles/wave.jpg"));
    let style = gast_core::session::StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    println!("depth benchmark: style {}, {} threads", style_path.display(), rayon::current_num_threads());
    time_style_depth(&style, args.depth_model.as_deref(), args.reps.max(1), args.stages)?;
    Ok(ExitCode::SUCCESS)
}

/// Prints the depth network's time for one style (pre- and post-processing
/// included) and the median of `reps` forward passes at 518×518. Uses the
/// checkpoint found on this machine, else random weights at the Small model's
/// sizes (same cost, meaningless output), and says which.
fn time_style_depth(
    style: &gast_core::session::StyleImage,
    explicit: Option<&std::path::Path>,
    reps: usize,
    stages: bool,
) -> anyhow::Result<()> {
    use anyhow::Context;
    use gast_core::vision::depth::{DepthAnything, DepthConfig, DepthModelLocations, INPUT_SIZE, input_size};
    let t = Instant::now();
    let (model, what) = match DepthModelLocations::from_env(explicit).find() {
        Ok(p) => (
            DepthAnything::load_path(&p).with_context(|| format!("loading the depth model {}", p.display()))?,
            format!("checkpoint {}", p.display()),
        ),
        Err(_) => (
            DepthAnything::random(DepthConfig::small(), 1)?,
            "no checkpoint here: random weights at the Small model's sizes".to_string(),
        ),
    };
    let load_s = t.elapsed().as_secs_f64();
    let (h, w) = (style.height, style.width);
    let (ih, iw) = input_size(h, w, INPUT_SIZE, model.config().patch_size);
    let (t, c) = (Instant::now(), cpu_seconds());
    let _ = model.estimate_rgb(&style.to_f32(), h, w);
    let (per_style, per_style_cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    let x = vec![0.25f32; 3 * INPUT_SIZE * INPUT_SIZE];
    let (walls, cpus): (Vec<f64>, Vec<f64>) = (0..reps)
        .map(|_| {
            let (t, c) = (Instant::now(), cpu_seconds());
            let _ = model.forward(&x, INPUT_SIZE, INPUT_SIZE);
            (t.elapsed().as_secs_f64(), cpu_seconds() - c)
        })
        .unzip();
    println!(
        "style depth (Depth Anything V2, {what}): load {load_s:.2} s; per style {per_style:.2} s wall, {per_style_cpu:.2} s CPU ({w}×{h} image, network input {iw}×{ih}); forward at {INPUT_SIZE}×{INPUT_SIZE}: {:.2} s wall, {:.2} s CPU (medians of {reps})",
        median(walls),
        median(cpus)
    );
    if stages {
        let (_, square) = model.forward_timed(&x, INPUT_SIZE, INPUT_SIZE);
        let (_, style_sized) = model.forward_timed(&vec![0.25f32; 3 * ih * iw], ih, iw);
        println!("{:<24} {:>10} {:>10}", "stage (wall s)", format!("{INPUT_SIZE}×{INPUT_SIZE}"), format!("{iw}×{ih}"));
        for (name, s) in &square.stages {
            println!("{name:<24} {s:>10.3} {:>10.3}", style_sized.get(name));
        }
        println!("{:<24} {:>10.3} {:>10.3}", "total", square.total(), style_sized.total());
    }
    Ok(())
}

/// What both step benchmarks load: the scene, the style and the network.
struct StepInputs {
    scene_path: PathBuf,
    scene: gast_core::Gaussians,
    style_path: PathBuf,
    style: gast_core::session::StyleImage,
    vgg: std::sync::Arc<gast_core::vision::Vgg>,
}

/// Loads `args`' scene, style and weights (the shared data's guitar, wave and
/// VGG file by default), after resetting the peak-memory mark.
fn step_inputs(args: &StepArgs) -> anyhow::Result<StepInputs> {
    let shared = shared_dir();
    let scene_path = args.scene.clone().unwrap_or_else(|| shared.join("data/scenes/guitar.compressed.ply"));
    let style_path = args.style.clone().unwrap_or_else(|| shared.join("data/styles/wave.jpg"));
    let weights = args.weights.clone().or_else(|| {
        let p = shared.join("data/weights/vgg19-conv3.safetensors");
        p.exists().then_some(p)
    });
    reset_peak_memory();
    let scene = load_scene(&scene_path)?;
    let style = gast_core::session::StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    let vgg = std::sync::Arc::new(super::stylize::load_vgg(weights.as_deref())?);
    Ok(StepInputs { scene_path, scene, style_path, style, vgg })
}

/// Per-step breakdown of the optimisation, the whole schedule's time, and memory.
pub fn run_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    use gast_core::gpu::DeviceChoice;
    use gast_core::style::{Phase, StyleConfig};

    let f = &args.fast;
    if f.conv.is_some()
        || f.matching.is_some()
        || f.matching_dims.is_some()
        || f.matching_candidates.is_some()
        || f.matching_reuse.is_some()
    {
        return run_fast_step(args);
    }
    let StepInputs { scene_path, scene, style_path, style, vgg } = step_inputs(&args)?;
    let config = StyleConfig { resolution: args.resolution, focus: args.focus, ..StyleConfig::default() };
    let views = views_for(
        &scene,
        &ViewArgs {
            cameras: None,
            views: args.views,
            size: args.resolution,
            fov: 50.0,
            framing: Framing::Full,
            crop: false,
        },
    )?;
    println!(
        "step benchmark: {} ({} Gaussians), style {}, {} views at {} px, {} threads",
        scene_path.display(),
        scene.len(),
        style_path.display(),
        views.len(),
        args.resolution,
        rayon::current_num_threads()
    );
    let schedule = config.schedule();
    let budget = match args.steps {
        Some(n) => n,
        None if args.full => schedule.total_steps(),
        None => schedule.color_steps + args.geometry_steps,
    };
    if args.compare_focus {
        return compare_focus(
            &args,
            &StepInputs { scene_path, scene, style_path, style, vgg },
            &views,
            &config,
            budget,
        );
    }
    let devices: Vec<DeviceChoice> =
        if args.compare { vec![DeviceChoice::Cpu, DeviceChoice::Gpu] } else { vec![args.device] };
    let mut runs = Vec::new();
    for device in devices {
        let gpu = device.resolve().with_context(|| format!("--device {device}"))?;
        let run = time_steps(&scene, &views, &style, &vgg, &config, gpu, budget)?;
        runs.push(run);
    }
    if let [cpu, gpu] = &runs[..] {
        println!("\nCPU against GPU, the same {} steps in one process:", cpu.steps.min(gpu.steps));
        for (phase, cpu_ms) in &cpu.per_phase {
            if let Some((_, gpu_ms)) = gpu.per_phase.iter().find(|p| p.0 == *phase) {
                println!(
                    "  {:<9} step median: CPU {:>9.1} ms, GPU {:>8.2} ms, ratio {:>7.1}x",
                    format!("{phase:?}").to_lowercase(),
                    cpu_ms,
                    gpu_ms,
                    cpu_ms / gpu_ms.max(1e-9)
                );
            }
        }
        println!(
            "  whole run: CPU {:.1} s, GPU {:.2} s, ratio {:.1}x",
            cpu.wall_s,
            gpu.wall_s,
            cpu.wall_s / gpu.wall_s.max(1e-9)
        );
        if let (Some(a), Some(b)) = (cpu.first_losses, gpu.first_losses) {
            let rel = |x: f32, y: f32| f64::from((x - y).abs()) / f64::from(x.abs().max(1e-12));
            println!(
                "  first step's losses, relative difference: total {:.1e}, GCFM {:.1e}, content {:.1e}, TV {:.1e} ({} on the GPU)",
                rel(a.total, b.total),
                rel(a.gcfm, b.gcfm),
                rel(a.content, b.content),
                rel(a.tv, b.tv),
                gpu.device
            );
        }
    }
    let side = (args.resolution / 2) as usize;
    if runs.iter().any(|r| r.device.starts_with("CPU")) {
        // One modality at the VGG input size (the render downscaled 0.5×), and the gemm floor.
        let vt = gast_core::vision::vgg::bench(&vgg, side, side, 3);
        let gemm = gast_core::vision::gemm_gflops(256, 64 * 64, 2304, 3);
        let flops = vgg.forward_flops(side, side);
        println!("\none modality on the CPU: {vt}");
        println!(
            "gemm floor: {gemm:.0} GFLOP/s measured (256×4096×2304); one VGG forward at {side}² is {:.2} GFLOP = {:.0} ms at that rate, measured {:.0} ms ({:.0}% of the floor's speed)",
            flops * 1e-9,
            flops / gemm / 1e6,
            vt.forward_s * 1e3,
            100.0 * (flops / gemm / 1e9) / vt.forward_s
        );
    }
    time_style_depth(&style, args.depth_model.as_deref(), 1, false)?;
    if !runs.iter().all(|r| r.device.starts_with("CPU")) {
        let ctx = gast_core::gpu::DeviceChoice::Gpu.resolve()?.context("no GPU adapter for the per-part figures")?;
        gpu_parts(&ctx, &vgg, &scene, &views[0], args.resolution as usize)?;
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
    Ok(ExitCode::SUCCESS)
}

/// `gast bench step --compare-focus`: the same steps on one device with the
/// losses over the whole frame, then focused on the object, and the ratio of
/// their per-phase medians.
fn compare_focus(
    args: &StepArgs,
    inputs: &StepInputs,
    views: &[Camera],
    config: &gast_core::style::StyleConfig,
    budget: u32,
) -> anyhow::Result<ExitCode> {
    use gast_core::style::Focus;
    let mut runs = Vec::new();
    for focus in [Focus::Frame, Focus::Object] {
        println!("\nfocus {focus:?}:");
        let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
        let config = gast_core::style::StyleConfig { focus, ..config.clone() };
        runs.push(time_steps(&inputs.scene, views, &inputs.style, &inputs.vgg, &config, gpu, budget)?);
    }
    let [frame, object] = &runs[..] else { return Ok(ExitCode::FAILURE) };
    println!("\nframe against object focus on {}, the same {} steps in one process:", frame.device, frame.steps);
    for (phase, frame_ms) in &frame.per_phase {
        if let Some((_, object_ms)) = object.per_phase.iter().find(|p| p.0 == *phase) {
            println!(
                "  {:<9} step median: frame {:>9.2} ms, object {:>9.2} ms, object/frame {:.3}",
                format!("{phase:?}").to_lowercase(),
                frame_ms,
                object_ms,
                object_ms / frame_ms.max(1e-9)
            );
        }
    }
    println!(
        "  whole run: frame {:.2} s, object {:.2} s, object/frame {:.3}",
        frame.wall_s,
        object.wall_s,
        object.wall_s / frame.wall_s.max(1e-9)
    );
    Ok(ExitCode::SUCCESS)
}

/// Runs `budget` steps of a fresh session on `gpu` (the CPU when `None`) and
/// prints the per-phase table.
fn time_steps(
    scene: &gast_core::Gaussians,
    views: &[Camera],
    style: &gast_core::session::StyleImage,
    vgg: &std::sync::Arc<gast_core::vision::Vgg>,
    config: &gast_core::style::StyleConfig,
    gpu: Option<gast_core::gpu::GpuContext>,
    budget: u32,
) -> anyhow::Result<StepRun> {
    use gast_core::session::{Event, Session, SessionInputs, StepReport, StyleDepthSource};
    use gast_core::style::Phase;

    let inputs = SessionInputs {
        scene: scene.clone(),
        cameras: views.to_vec(),
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
    if let Some(bytes) = session.gpu_memory_bytes() {
        println!("  GPU memory allocated by the engine: {:.1} MiB", bytes as f64 / f64::from(1u32 << 20));
    }
    let warm = session.warm_view_targets().map_err(|e| anyhow::anyhow!("{device}: {e}"))?;
    println!(
        "  per-view targets (G^c render, content features) of {} views, once per run: {:.0} ms",
        views.len(),
        warm * 1e3
    );
    let pb = crate::progress::bar(u64::from(budget), "steps");
    let mut reports: Vec<(StepReport, f64)> = Vec::new();
    let t_all = Instant::now();
    for _ in 0..budget {
        let t = Instant::now();
        let Some(r) = session.step() else { break };
        reports.push((r, t.elapsed().as_secs_f64() * 1e3));
        pb.inc(1);
    }
    let wall_s = t_all.elapsed().as_secs_f64();
    pb.finish_and_clear();
    if let Some(why) = session.failure() {
        anyhow::bail!("{device}: the run stopped at {why}");
    }
    println!("per-step medians (ms), every view's targets computed before the timed steps");
    println!(
        "{:<10} {:>6} {:>8} {:>10} {:>9} {:>10} {:>10} {:>8} {:>9}",
        "phase", "steps", "render", "vgg fwd×3", "matching", "vgg bwd", "raster bwd", "adam", "step"
    );
    let mut per_phase = Vec::new();
    for phase in [Phase::Color, Phase::Geometry] {
        let rows: Vec<&(StepReport, f64)> = reports.iter().filter(|(r, _)| r.phase == phase).collect();
        if rows.is_empty() {
            continue;
        }
        let m = |f: &dyn Fn(&StepReport) -> f32| median(rows.iter().map(|(r, _)| f64::from(f(r))).collect());
        let wall = median(rows.iter().map(|(_, w)| *w).collect());
        per_phase.push((phase, wall));
        println!(
            "{:<10} {:>6} {:>8.1} {:>10.1} {:>9.1} {:>10.1} {:>10.1} {:>8.1} {:>9.2}",
            format!("{phase:?}").to_lowercase(),
            rows.len(),
            m(&|r| r.timings.render_ms),
            m(&|r| r.timings.features_ms),
            m(&|r| r.timings.matching_ms),
            m(&|r| r.timings.vgg_backward_ms),
            m(&|r| r.timings.raster_backward_ms),
            m(&|r| r.timings.update_ms),
            wall
        );
    }
    if session.gpu_memory_bytes().is_some() {
        println!("(on the GPU the parts run back to back in one submission; their times are below)");
    }
    Ok(StepRun { device, steps: reports.len(), wall_s, per_phase, first_losses: reports.first().map(|r| r.0.losses) })
}

/// Each GPU part of a step timed on its own at the benchmark's size.
fn gpu_parts(
    ctx: &gast_core::gpu::GpuContext,
    vgg: &gast_core::vision::Vgg,
    scene: &gast_core::Gaussians,
    cam: &Camera,
    resolution: usize,
) -> anyhow::Result<()> {
    use gast_core::gpu;
    println!("\nGPU parts on {} (median ms)", ctx.describe());
    let mut rows = gpu::bench_raster(ctx, scene, cam)?;
    let side = resolution / 2;
    rows.extend(gpu::bench_vgg(ctx, vgg, side, side, 5));
    let n = (side / 4) * (side / 4);
    rows.extend(gpu::bench_gcfm(ctx, 768, n, 4096, 5));
    rows.extend(gpu::bench_image_ops(ctx, &[resolution], scene.len(), 5)?);
    for (name, ms) in rows {
        println!("  {name:<36} {ms:>9.3}");
    }
    Ok(())
}

/// Medians of one phase: render, VGG forwards, matching, VGG backwards, raster backward, Adam, step (ms).
type PhaseRow = [f64; 7];

/// Per-phase medians of `reports` (each with its step's wall time in ms).
fn phase_rows(reports: &[(gast_core::session::StepReport, f64)]) -> Vec<(gast_core::style::Phase, usize, PhaseRow)> {
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

/// Per-step breakdown of the optimisation for the reference settings and the
/// new ones side by side (steps interleaved, so both see the same machine
/// load), their ratio, FLOP counts per stage against the gemm floor, the
/// whole schedule's time, and memory.
fn run_fast_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    use gast_core::session::{Event, Session, SessionInputs, StepReport, StyleDepthSource};
    use gast_core::style::{MatchMethod, Phase, StyleConfig};

    let StepInputs { scene_path, scene, style_path, style, vgg } = step_inputs(&args)?;
    let old_config = StyleConfig { resolution: args.resolution, focus: args.focus, ..StyleConfig::default() };
    let mut new_config = old_config.clone();
    args.fast.apply(&mut new_config);
    let problems = new_config.problems();
    anyhow::ensure!(problems.is_empty(), "invalid parameters: {}", problems.join("; "));
    let views = views_for(
        &scene,
        &ViewArgs {
            cameras: None,
            views: args.views,
            size: args.resolution,
            fov: 50.0,
            framing: super::Framing::Full,
            crop: false,
        },
    )?;
    let (cam_h, cam_w) = (views[0].height as usize, views[0].width as usize);
    let mc = new_config.matching;
    println!(
        "step benchmark: {} ({} Gaussians), style {}, {} views at {} px, {} threads",
        scene_path.display(),
        scene.len(),
        style_path.display(),
        views.len(),
        args.resolution,
        rayon::current_num_threads()
    );
    println!(
        "old: conv im2col, matching exact | new: conv {}, matching {} (dims {}, candidates {}, reuse {})",
        new_config.conv, mc.method, mc.dims, mc.candidates, mc.reuse
    );
    let inputs = SessionInputs {
        scene,
        cameras: views,
        style,
        style_depth: StyleDepthSource::Heuristic,
        vgg: vgg.clone(),
        config: old_config.clone(),
        gpu: None,
    };
    let print_event = |label: &str, e: Event| match e {
        Event::Stage { name, seconds } => println!("  {label} prepare: {name:<20} {:>8.0} ms", seconds * 1e3),
        Event::Culled { total, kept } => println!("  {label} culling: optimising {kept} of {total} Gaussians"),
        _ => {}
    };
    let mut old = Session::prepare(inputs.clone(), &mut |e| print_event("old", e))?;
    let mut new = Session::prepare_with_style(
        SessionInputs { config: new_config.clone(), ..inputs },
        Some(old.style().clone()),
        &mut |e| print_event("new", e),
    )?;
    new.audit_matches(if mc.method == MatchMethod::Exact { 0 } else { 5 });
    for (label, session) in [("old", &mut old), ("new", &mut new)] {
        let warm = session.warm_view_targets().map_err(anyhow::Error::msg)?;
        println!("  {label} per-view targets (G^c render, content features), once per run: {:.0} ms", warm * 1e3);
    }

    let schedule = old_config.schedule();
    let budget = if args.full { schedule.total_steps() } else { schedule.color_steps + args.geometry_steps };
    let mut reports: [Vec<(StepReport, f64)>; 2] = [Vec::new(), Vec::new()];
    let mut wall_all = [0.0f64; 2];
    for _ in 0..budget {
        for (k, session) in [&mut old, &mut new].into_iter().enumerate() {
            let before = session.elapsed_s();
            let Some(r) = session.step() else { continue };
            let wall = (session.elapsed_s() - before) * 1e3;
            wall_all[k] += wall / 1e3;
            reports[k].push((r, wall));
        }
    }

    println!("\nper-step medians (ms), every view's targets computed before the timed steps");
    println!(
        "{:<16} {:>6} {:>8} {:>10} {:>9} {:>10} {:>10} {:>8} {:>9}",
        "phase", "steps", "render", "vgg fwd×3", "matching", "vgg bwd", "raster bwd", "adam", "step"
    );
    let rows = [phase_rows(&reports[0]), phase_rows(&reports[1])];
    for (label, table) in ["old", "new"].iter().zip(&rows) {
        for (phase, steps, r) in table {
            println!(
                "{:<16} {steps:>6} {:>8.1} {:>10.1} {:>9.1} {:>10.1} {:>10.1} {:>8.1} {:>9.1}",
                format!("{label} {}", format!("{phase:?}").to_lowercase()),
                r[0],
                r[1],
                r[2],
                r[3],
                r[4],
                r[5],
                r[6]
            );
        }
    }
    for ((phase, _, o), (_, _, n)) in rows[0].iter().zip(&rows[1]) {
        let ratio: Vec<String> = o.iter().zip(n).map(|(a, b)| format!("{:.2}", a / b.max(1e-9))).collect();
        println!(
            "{:<16} {:>6} {:>8} {:>10} {:>9} {:>10} {:>10} {:>8} {:>9}",
            format!("old/new {}", format!("{phase:?}").to_lowercase()),
            "",
            ratio[0],
            ratio[1],
            ratio[2],
            ratio[3],
            ratio[4],
            ratio[5],
            ratio[6]
        );
    }
    if let Some((b, w, k)) = new.match_agreement() {
        println!(
            "new matching: {:.1}% of nearest and {:.1}% of farthest matches identical to the exact search ({k} audited steps)",
            b * 100.0,
            w * 100.0
        );
    }

    // FLOPs per stage (geometry step) against the gemm floor.
    let side = (args.resolution / 2) as usize;
    let gemm = gast_core::vision::gemm_gflops(256, 64 * 64, 2304, 3);
    let (sh, sw) = (cam_h / 2, cam_w / 2);
    let fwd_direct = vgg.forward_flops(sh, sw);
    let new_vgg = (*vgg).clone().with_conv(new_config.conv);
    let fwd_new = new_vgg.executed_forward_flops(sh, sw);
    // With the focus on the object only the covered positions are matched:
    // the mean covered share of the views stands for their number.
    let share = if old.focus_on_object() { f64::from(old.coverage()) } else { 1.0 };
    let (n, m) = (share * (sh / 4 * (sw / 4)) as f64, old.style().targets.features.positions() as f64);
    let d = 3.0 * gast_core::vision::vgg::FEATURE_CHANNELS as f64;
    let match_old = 2.0 * n * m * d;
    let match_new = match mc.method {
        MatchMethod::Exact => match_old,
        MatchMethod::Pca => {
            let l = f64::from(mc.dims).min(d);
            2.0 * n * d * l + 2.0 * n * m * l + 2.0 * 2.0 * f64::from(mc.candidates).min(m) * n * d
        }
    } / f64::from(mc.reuse.max(1));
    println!(
        "\nFLOPs of a geometry step (GFLOP; floor = at the measured gemm rate, {gemm:.0} GFLOP/s on 256×4096×2304; matching over {:.0}% of the positions, focus {}):",
        share * 100.0,
        if old.focus_on_object() { "object" } else { "frame" }
    );
    println!("{:<14} {:>10} {:>10} {:>10} {:>10}", "stage", "old GFLOP", "floor ms", "new GFLOP", "floor ms");
    for (name, o, nw) in [
        ("vgg fwd ×3", 3.0 * fwd_direct, 3.0 * fwd_new),
        ("matching", match_old, match_new),
        ("vgg bwd ×2", 2.0 * fwd_direct, 2.0 * fwd_new),
    ] {
        println!(
            "{name:<14} {:>10.2} {:>10.0} {:>10.2} {:>10.0}",
            o * 1e-9,
            o / gemm / 1e6,
            nw * 1e-9,
            nw / gemm / 1e6
        );
    }

    // One modality at the VGG input size, each convolution.
    for conv in gast_core::vision::ConvAlgo::ALL {
        let v = (*vgg).clone().with_conv(conv);
        println!("one modality, {conv}: {}", gast_core::vision::vgg::bench(&v, side, side, 3));
    }

    let (peak, rss) = memory_mib();
    for (k, label) in ["old", "new"].iter().enumerate() {
        if args.full {
            println!(
                "{label} whole schedule: {} steps in {:.1} s ({:.1} min)",
                reports[k].len(),
                wall_all[k],
                wall_all[k] / 60.0
            );
        } else {
            let per = |p: Phase| rows[k].iter().find(|r| r.0 == p).map_or(0.0, |r| r.2[6]);
            let est = (f64::from(schedule.cycles * schedule.color_steps) * per(Phase::Color)
                + f64::from(schedule.cycles * schedule.geometry_steps) * per(Phase::Geometry))
                / 1e3;
            println!(
                "{label} whole default schedule ({} colour + {} geometry steps), extrapolated from the medians: {:.0} s ({:.1} min)",
                schedule.cycles * schedule.color_steps,
                schedule.cycles * schedule.geometry_steps,
                est,
                est / 60.0
            );
        }
    }
    println!("memory: peak resident {peak:.0} MiB, now {rss:.0} MiB");
    Ok(ExitCode::SUCCESS)
}
