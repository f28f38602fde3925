//! `gast bench depth`: the style depth network's time per style and per
//! stage, on the CPU and (`--device gpu`) on the GPU engine.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use gast_core::gpu::{DeviceChoice, GpuContext, GpuDepthNet};
use gast_core::vision::depth::{DepthAnything, INPUT_SIZE, input_size};

use super::median;
use std::path::PathBuf;

/// Arguments of `gast bench depth`.
#[derive(Args, Debug)]
pub struct DepthArgs {
    /// Style image (default: styles/wave.jpg from the shared data folder).
    #[arg(long)]
    pub style: Option<PathBuf>,
    /// Depth Anything V2 checkpoint (else $GAST_DEPTH_MODEL or the caches; never downloaded here).
    #[arg(long)]
    pub depth_model: Option<PathBuf>,
    /// Forward passes at 518×518 to time, at least one (the median is printed).
    #[arg(long, default_value_t = 3, value_parser = crate::views::at_least_one::<usize>)]
    pub reps: usize,
    /// Also print the wall time of each stage of one forward at 518×518 and
    /// one at the style's input size.
    #[arg(long)]
    pub stages: bool,
    /// Also time the network on the GPU engine: `gpu` (any adapter, lavapipe
    /// included), `auto` (a hardware adapter if there is one), `cpu` (not).
    #[arg(long, default_value_t = DeviceChoice::Cpu)]
    pub device: DeviceChoice,
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
    let style_path = match &args.style {
        Some(p) => p.clone(),
        None => super::shared_input("data/styles/wave.jpg", "--style")?,
    };
    let style = gast_core::session::StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    println!("depth benchmark: style {}, {} threads", style_path.display(), rayon::current_num_threads());
    let gpu = args.device.resolve().with_context(|| format!("--device {}", args.device))?;
    let (model, cpu_forward) = time_style_depth(&style, args.depth_model.as_deref(), args.reps, args.stages, true)?;
    if let Some(ctx) = gpu {
        time_gpu_depth(&ctx, model, &style, args.reps, cpu_forward)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Prints the same figures for the network on the GPU engine (the estimate
/// for the style, then `reps` forwards at 518×518), and the ratios of the
/// CPU's forward to the GPU's, wall and process CPU time, both measured in
/// this process. On a software rasterizer the CPU-time ratio is the one to
/// read: both run on the same cores, whatever else the machine is doing.
fn time_gpu_depth(
    ctx: &GpuContext,
    model: DepthAnything,
    style: &gast_core::session::StyleImage,
    reps: usize,
    (cpu_wall, cpu_cpu): (f64, f64),
) -> anyhow::Result<()> {
    let t = Instant::now();
    let net = GpuDepthNet::new(ctx, model);
    let upload_s = t.elapsed().as_secs_f64();
    let (h, w) = (style.height, style.width);
    let (ih, iw) = input_size(h, w, INPUT_SIZE, net.cpu().config().patch_size);
    let on = || format!("the depth network on {}", ctx.describe());
    let (t, c) = (Instant::now(), cpu_seconds());
    net.depth_image(ctx, &style.rgb[..], h, w).with_context(on)?;
    let (per_style, per_style_cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    let x = vec![0.25f32; 3 * INPUT_SIZE * INPUT_SIZE];
    let mut walls = Vec::with_capacity(reps);
    let mut cpus = Vec::with_capacity(reps);
    for _ in 0..reps {
        let (t, c) = (Instant::now(), cpu_seconds());
        net.forward(ctx, &x, INPUT_SIZE, INPUT_SIZE).with_context(on)?;
        walls.push(t.elapsed().as_secs_f64());
        cpus.push(cpu_seconds() - c);
    }
    let (wall, cpu) = (median(walls), median(cpus));
    let software = if ctx.is_software() { "; software rasterizer: a CPU emulation, not a GPU figure" } else { "" };
    println!(
        "style depth on the GPU engine ({}{software}): weights upload + kernels {upload_s:.2} s; per style {per_style:.2} s wall, {per_style_cpu:.2} s CPU ({w}×{h} image, network input {iw}×{ih}); forward at {INPUT_SIZE}×{INPUT_SIZE}: {wall:.2} s wall, {cpu:.2} s CPU (medians of {reps}); CPU engine / GPU engine forward: {:.3} wall, {:.3} CPU time",
        ctx.describe(),
        cpu_wall / wall,
        cpu_cpu / cpu.max(1e-9),
    );
    Ok(())
}

/// Prints the depth network's time for one style (pre- and post-processing
/// included) and the median of `reps` forward passes at 518×518. Uses the
/// checkpoint found on this machine, else random weights at the Small model's
/// sizes (same cost, meaningless output), and says which. With `peak`, also
/// the peak resident memory while the estimate is made, which resets the
/// process's peak mark (`gast bench step` reports its steps' peak, so not
/// there). Returns the network and the median forward's wall and CPU seconds.
pub(super) fn time_style_depth(
    style: &gast_core::session::StyleImage,
    explicit: Option<&std::path::Path>,
    reps: usize,
    stages: bool,
    peak: bool,
) -> anyhow::Result<(DepthAnything, (f64, f64))> {
    use gast_core::vision::depth::{DepthConfig, DepthModelLocations};
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
    // What a run computes once per style: the estimate at the network's size.
    let (_, before_mib) = super::memory_mib();
    if peak {
        super::reset_peak_memory();
    }
    let (t, c) = (Instant::now(), cpu_seconds());
    let _ = model.depth_image(&style.rgb[..], h, w);
    let (per_style, per_style_cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    let (peak_mib, _) = super::memory_mib();
    let memory =
        if peak { format!(", peak resident {peak_mib:.0} MiB ({before_mib:.0} MiB before it)") } else { String::new() };
    let x = vec![0.25f32; 3 * INPUT_SIZE * INPUT_SIZE];
    let (walls, cpus): (Vec<f64>, Vec<f64>) = (0..reps)
        .map(|_| {
            let (t, c) = (Instant::now(), cpu_seconds());
            let _ = model.forward(&x, INPUT_SIZE, INPUT_SIZE);
            (t.elapsed().as_secs_f64(), cpu_seconds() - c)
        })
        .unzip();
    let forward = (median(walls), median(cpus));
    println!(
        "style depth (Depth Anything V2, {what}): load {load_s:.2} s; per style {per_style:.2} s wall, {per_style_cpu:.2} s CPU ({w}×{h} image, network input {iw}×{ih}){memory}; forward at {INPUT_SIZE}×{INPUT_SIZE}: {:.2} s wall, {:.2} s CPU (medians of {reps})",
        forward.0, forward.1
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
    Ok((model, forward))
}
