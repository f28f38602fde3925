//! `gast bench …`: benchmarks that print figures. Timings are medians over
//! several views after a warm-up; memory is the process's peak resident set,
//! reset before each scene (Linux `clear_refs`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;
use gast_core::camera::Camera;
use gast_core::raster::{self, RenderOptions};

use super::{ViewArgs, load_scene, views_for};

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
            let views = views_for(&scene, &ViewArgs { cameras: None, views: args.views, size, fov: 50.0 })?;
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
    let views = views_for(scene, &ViewArgs { cameras: None, views: 1, size: 96, fov: 50.0 })?;
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
    /// The new settings, timed step by step beside the reference (im2col, exact matching).
    #[command(flatten)]
    pub fast: super::stylize::FastArgs,
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
pub fn run_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    use gast_core::session::{Event, Session, SessionInputs, StepReport, StyleDepthSource, StyleImage};
    use gast_core::style::{MatchMethod, Phase, StyleConfig};

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
    let old_config = StyleConfig { resolution: args.resolution, ..StyleConfig::default() };
    let mut new_config = old_config.clone();
    args.fast.apply(&mut new_config);
    let problems = new_config.problems();
    anyhow::ensure!(problems.is_empty(), "invalid parameters: {}", problems.join("; "));
    let views = views_for(&scene, &ViewArgs { cameras: None, views: args.views, size: args.resolution, fov: 50.0 })?;
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

    println!("\nper-step medians (ms); the first visit of a view also renders G^c and its content features once");
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
    let (n, m) = ((sh / 4 * (sw / 4)) as f64, old.style().targets.features.positions() as f64);
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
        "\nFLOPs of a geometry step (GFLOP; floor = at the measured gemm rate, {gemm:.0} GFLOP/s on 256×4096×2304):"
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
