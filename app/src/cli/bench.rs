//! `gast bench …`: benchmarks that print figures. Timings are medians over
//! several views after a warm-up; memory is the process's peak resident set,
//! reset before each scene (Linux `clear_refs`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

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
            let views = views_for(&scene, &ViewArgs { cameras: None, views: args.views, size, fov: 50.0, framing: Framing::Full, crop: false })?;
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
    let views = views_for(scene, &ViewArgs { cameras: None, views: 1, size: 96, fov: 50.0, framing: Framing::Full, crop: false })?;
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
}

/// Per-step breakdown of the optimisation, the whole schedule's time, and memory.
pub fn run_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    use gast_core::session::{Event, Session, SessionInputs, StepReport, StyleDepthSource, StyleImage};
    use gast_core::style::{Phase, StyleConfig};

    let shared = shared_dir();
    let scene_path = args.scene.clone().unwrap_or_else(|| shared.join("data/scenes/guitar.compressed.ply"));
    let style_path = args.style.clone().unwrap_or_else(|| shared.join("data/styles/wave.jpg"));
    let weights = args.weights.clone().or_else(|| {
        let p = shared.join("data/weights/vgg19-conv3.safetensors");
        p.exists().then_some(p)
    });
    reset_peak_memory();
    let scene = load_scene(&scene_path)?;
    let style = StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    let vgg = std::sync::Arc::new(super::stylize::load_vgg(weights.as_deref())?);
    let config = StyleConfig { resolution: args.resolution, ..StyleConfig::default() };
    let views = views_for(&scene, &ViewArgs { cameras: None, views: args.views, size: args.resolution, fov: 50.0, framing: Framing::Full, crop: false })?;
    println!(
        "step benchmark: {} ({} Gaussians), style {}, {} views at {} px, {} threads",
        scene_path.display(),
        scene.len(),
        style_path.display(),
        views.len(),
        args.resolution,
        rayon::current_num_threads()
    );
    let inputs = SessionInputs {
        scene,
        cameras: views,
        style,
        style_depth: StyleDepthSource::Heuristic,
        vgg: vgg.clone(),
        config: config.clone(),
    };
    let mut session = Session::prepare(inputs, &mut |e| match e {
        Event::Stage { name, seconds } => println!("  prepare: {name:<20} {:>8.0} ms", seconds * 1e3),
        Event::Culled { total, kept } => println!("  culling: optimising {kept} of {total} Gaussians"),
        _ => {}
    })?;

    let schedule = config.schedule();
    let budget = if args.full { schedule.total_steps() } else { schedule.color_steps + args.geometry_steps };
    let mut reports: Vec<(StepReport, f64)> = Vec::new();
    let t_all = Instant::now();
    for _ in 0..budget {
        let t = Instant::now();
        let Some(r) = session.step() else { break };
        reports.push((r, t.elapsed().as_secs_f64() * 1e3));
    }
    let wall_all = t_all.elapsed().as_secs_f64();

    println!("\nper-step medians (ms); the first visit of a view also renders G^c and its content features once");
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
            "{:<10} {:>6} {:>8.1} {:>10.1} {:>9.1} {:>10.1} {:>10.1} {:>8.1} {:>9.1}",
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

    // One modality at the VGG input size (the render downscaled 0.5×), and the gemm floor.
    let side = (args.resolution / 2) as usize;
    let vt = gast_core::vision::vgg::bench(&vgg, side, side, 3);
    let gemm = gast_core::vision::gemm_gflops(256, 64 * 64, 2304, 3);
    let flops = vgg.forward_flops(side, side);
    println!("\none modality: {vt}");
    println!(
        "gemm floor: {gemm:.0} GFLOP/s measured (256×4096×2304); one VGG forward at {side}² is {:.2} GFLOP = {:.0} ms at that rate, measured {:.0} ms ({:.0}% of the floor's speed)",
        flops * 1e-9,
        flops / gemm / 1e6,
        vt.forward_s * 1e3,
        100.0 * (flops / gemm / 1e9) / vt.forward_s
    );

    let (peak, rss) = memory_mib();
    if args.full {
        println!("\nwhole schedule: {} steps in {:.1} s ({:.1} min)", reports.len(), wall_all, wall_all / 60.0);
    } else {
        let colour = per_phase.iter().find(|p| p.0 == Phase::Color).map_or(0.0, |p| p.1);
        let geometry = per_phase.iter().find(|p| p.0 == Phase::Geometry).map_or(0.0, |p| p.1);
        let est = (f64::from(schedule.cycles * schedule.color_steps) * colour
            + f64::from(schedule.cycles * schedule.geometry_steps) * geometry)
            / 1e3;
        println!(
            "\nwhole default schedule ({} colour + {} geometry steps), extrapolated from the medians: {:.0} s ({:.1} min); `--full` runs it",
            schedule.cycles * schedule.color_steps,
            schedule.cycles * schedule.geometry_steps,
            est,
            est / 60.0
        );
    }
    println!("memory: peak resident {peak:.0} MiB, now {rss:.0} MiB");
    Ok(ExitCode::SUCCESS)
}
