//! `gast bench …`: benchmarks that print figures. Timings are medians over
//! several views after a warm-up; memory is the process's peak resident set,
//! reset before each scene (Linux `clear_refs`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;
use gast_core::camera::Camera;
use gast_core::raster::{self, RenderOptions};

use crate::views::{Framing, ViewArgs, load_scene, views_for};

mod depth;
mod pairing;
mod step;
mod step_fast;

pub use depth::{DepthArgs, run_depth};
pub use pairing::{PairingArgs, run_pairing};
pub use step::StepArgs;

/// Arguments of `gast bench raster`.
#[derive(Args, Debug)]
pub struct RasterArgs {
    /// Scenes to measure (default: playbot-sog and guitar from the shared data folder,
    /// `$GAST_SHARED` or `../shared`).
    pub scenes: Vec<PathBuf>,
    /// Image sizes (longer side, pixels, 16 to 8,192).
    #[arg(long, value_delimiter = ',', default_values_t = [256u32, 512], value_parser = crate::views::image_side())]
    pub sizes: Vec<u32>,
    /// Orbit views per scene and size, 1 to 3,600 (each timed once after a warm-up).
    #[arg(long, default_value_t = 8, value_parser = crate::views::view_count::<usize>())]
    pub views: usize,
}

/// The scene, style and VGG weights a step-level benchmark runs on
/// (`gast bench step`, `gast bench pairing`).
#[derive(clap::Args, Debug, Clone)]
pub struct BenchData {
    /// Scene (default: guitar.compressed.ply from the shared data folder).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Style image (default: styles/wave.jpg from the shared data folder).
    #[arg(long)]
    pub style: Option<PathBuf>,
    /// VGG weights (default: the shared vgg19-conv3.safetensors, else the usual resolution).
    #[arg(long)]
    pub weights: Option<PathBuf>,
}

impl BenchData {
    /// The scene's and the style's paths and the weights' (when given or
    /// in the shared data folder), the shared data's guitar and wave by default.
    pub fn paths(&self) -> anyhow::Result<(PathBuf, PathBuf, Option<PathBuf>)> {
        let scene = match &self.scene {
            Some(p) => p.clone(),
            None => shared_input("data/scenes/guitar.compressed.ply", "--scene")?,
        };
        let style = match &self.style {
            Some(p) => p.clone(),
            None => shared_input("data/styles/wave.jpg", "--style")?,
        };
        Ok((scene, style, self.weights.clone().or_else(shared_weights)))
    }
}

/// `rel` in the shared data folder, a benchmark's default input: an error
/// that says where it was looked for and how to point elsewhere (`flag`, or
/// `$GAST_SHARED`) when it is not there.
pub(super) fn shared_input(rel: &str, flag: &str) -> anyhow::Result<PathBuf> {
    let dir = shared_dir();
    let path = dir.join(rel);
    anyhow::ensure!(
        path.exists(),
        "{}: expected the shared data's {rel}, the default input, found no such file; give {flag}, or set \
         GAST_SHARED to the shared data folder (without it, ../shared from the current folder)",
        path.display()
    );
    Ok(path)
}

/// The shared data's small VGG file, when the checkout has one beside it.
pub(super) fn shared_weights() -> Option<PathBuf> {
    let p = shared_dir().join("data/weights/vgg19-conv3.safetensors");
    p.is_file().then_some(p)
}

/// The shared data folder: `$GAST_SHARED`, else `../shared`.
pub(super) fn shared_dir() -> PathBuf {
    std::env::var_os("GAST_SHARED").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("../shared"))
}

/// `gast bench step`: issue 10's options beside the reference (`step_fast`),
/// re-used matches on a GPU, or the default settings' breakdown (`step`).
pub fn run_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    if let Some(code) = step::reuse_on_gpu(&args)? {
        return Ok(code);
    }
    if step::asks_fast(&args) {
        return step_fast::run_fast_step(args);
    }
    step::run_step(args)
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

/// The median of the timings `v`; 0 for none.
fn median(v: Vec<f64>) -> f64 {
    gast_core::stats::median(v).unwrap_or(0.0)
}

/// Times forward and backward on every scene and size, then the dense reference.
pub fn run_raster(args: RasterArgs) -> anyhow::Result<ExitCode> {
    let scenes = if args.scenes.is_empty() {
        vec![
            shared_input("data/scenes/playbot-sog", "scenes as arguments")?,
            shared_input("data/scenes/guitar.compressed.ply", "scenes as arguments")?,
        ]
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
                &ViewArgs {
                    cameras: None,
                    orbit: false,
                    views: args.views,
                    size,
                    fov: 50.0,
                    framing: Framing::Full,
                    crop: false,
                },
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
        &ViewArgs { cameras: None, orbit: false, views: 1, size: 96, fov: 50.0, framing: Framing::Full, crop: false },
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
