//! Command-line definitions (clap) and dispatch to one module per subcommand.

mod bench;
mod check;
pub mod convert;
mod demo;
mod fit;
mod interrupt;
pub mod quality;
mod render;
mod stylize;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::studio;
use crate::views::load_scene;

/// GAST Studio: geometry-aware style transfer for 3D Gaussian Splatting scenes.
///
/// Without a command, opens the studio on the demo scene and style; without a
/// desktop session, runs a short headless demo instead.
#[derive(Parser, Debug)]
#[command(name = "gast", version, about, long_about = None)]
pub struct Cli {
    /// What to do; the studio when absent.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// The subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Open the studio window, optionally with a scene and style images
    /// (drag files onto the window to open others).
    Studio {
        /// A scene (.ply, .compressed.ply, .spz, SOG); the demo scene when absent.
        scene: Option<PathBuf>,
        /// Style images, into the strip of recent styles (the last one
        /// selected, eight at most); the first demo style when none is given.
        styles: Vec<PathBuf>,
        /// Where runs compute: auto (a hardware GPU when there is one, else the
        /// CPU), cpu, or gpu (the window's adapter even when it is a software one).
        #[arg(long, default_value_t = gast_core::gpu::DeviceChoice::Auto)]
        device: gast_core::gpu::DeviceChoice,
        /// No window: draw the studio's frames offscreen on a graphics device of
        /// its own, with no display (a GPU server). It closes after
        /// GAST_STUDIO_EXIT_AFTER_FRAMES frames (30 without), after a scripted
        /// run (GAST_STUDIO_RUN_STEPS) when one is asked for, saving
        /// GAST_STUDIO_SCREENSHOT first when set.
        #[arg(long)]
        headless: bool,
    },
    /// Regenerate the demo assets (scene, styles, icon) into a folder.
    Assets {
        /// Destination folder.
        #[arg(long, default_value = "assets")]
        out: PathBuf,
    },
    /// Render a scene from its cameras or from generated orbit views: PNG colour,
    /// PNG and EXR inverse depth per view.
    Render(render::RenderArgs),
    /// Stylize a scene with a style image: colour matching, then the K-cycle
    /// colour/geometry optimisation; writes the stylized .ply, before/after
    /// renders with depth, and report.json.
    ///
    /// Ctrl-C during the steps stops the run after its current step and still
    /// writes the scene, the renders and the report (`stopped_at`); a second
    /// Ctrl-C quits at once. Every 5 minutes, and at Ctrl-C, the stylized
    /// scene goes to stylized.checkpoint.ply in the output folder; after a
    /// kill, a crash or Ctrl-C the same command with --resume goes on from it.
    Stylize(Box<stylize::StylizeArgs>),
    /// Convert a scene between INRIA .ply, PlayCanvas .compressed.ply, Niantic .spz
    /// and SOG (folder or .sog); the output's name picks the format.
    Convert(convert::ConvertArgs),
    /// Fit a 3DGS scene to posed images (transforms.json, COLMAP, LLFF poses_bounds.npy, cameras.json)
    /// with the CPU rasterizer; writes the .ply and optional preview renders.
    ///
    /// Ctrl-C during the fit stops it after its current iteration and still
    /// writes the scene as it is, with its cameras; a second Ctrl-C quits at
    /// once. Every 5 minutes, and at Ctrl-C, a checkpoint goes beside the
    /// output (fern.ply → fern.checkpoint.ply); after a kill or a crash the
    /// same command with --resume goes on from it.
    Fit(fit::FitArgs),
    /// Compare the project's numerics with reference files.
    #[command(subcommand)]
    Check(CheckCommand),
    /// Benchmarks that print figures (milliseconds, throughput, memory).
    #[command(subcommand)]
    Bench(BenchCommand),
}

/// `gast check …`
#[derive(Subcommand, Debug)]
pub enum CheckCommand {
    /// Run the project's code on the inputs of golden files (safetensors, float64)
    /// and print, per output, the worst absolute error and the error relative to the
    /// largest magnitude. Exits non-zero when any output is beyond its tolerance.
    Golden(check::GoldenArgs),
}

/// `gast bench …`
#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Forward and backward rasterizer timings on real scenes from orbit views.
    Raster(bench::RasterArgs),
    /// Per-step breakdown of the optimisation, the whole schedule's time, peak memory.
    Step(bench::StepArgs),
    /// The style depth network's time per style (Depth Anything V2: the checkpoint found
    /// here, else random weights at the Small model's sizes).
    Depth(bench::DepthArgs),
    /// The assignment terms' host pairing part by part (cost matrix, least-cost assignment,
    /// pulls) on the columns a step draws from real views: the work a GPU step waits for.
    Pairing(bench::PairingArgs),
    /// Speed against quality over a grid of modes, budgets, resolutions, N_g ratios and
    /// λ_GC on the shared scenes and the nine styles; the stability study; the paper's
    /// ablation tables. Writes a folder with an index.md, CSV/JSON tables, charts and renders
    /// (about 30 minutes on two cores; `--quick` takes a few).
    Quality(quality::QualityArgs),
    /// What the studio viewport pays per optimiser step to show a GPU run: a CPU
    /// snapshot against the copy from the engine's buffers (headless, any adapter).
    ViewportLive {
        #[command(flatten)]
        data: bench::BenchData,
        /// Updates to time, at least one (one optimiser step before each).
        #[arg(long, default_value_t = 5, value_parser = crate::views::at_least_one::<u32>)]
        reps: u32,
    },
    /// The studio viewport's frame time on the first GPU adapter (headless).
    Viewport {
        /// A scene; a synthetic scene of `--count` Gaussians when absent.
        scene: Option<PathBuf>,
        /// Gaussians in the synthetic scene, at least one.
        #[arg(long, default_value_t = 500_000, value_parser = crate::views::at_least_one::<usize>)]
        count: usize,
        /// Frames to time, at least one.
        #[arg(long, default_value_t = 10, value_parser = crate::views::at_least_one::<u32>)]
        frames: u32,
        /// Frame width in pixels (16 to 8,192).
        #[arg(long, default_value_t = 1280, value_parser = crate::views::image_side())]
        width: u32,
        /// Frame height in pixels (16 to 8,192).
        #[arg(long, default_value_t = 720, value_parser = crate::views::image_side())]
        height: u32,
    },
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let Some(command) = cli.command else {
        if !demo::desktop_session() {
            return demo::run();
        }
        studio::run_with(studio::StudioArgs::default(), Some(studio::worker::starter()))?;
        return Ok(ExitCode::SUCCESS);
    };
    match command {
        Command::Studio { scene, styles, device, headless } => {
            let args = studio::StudioArgs { scene, styles, device };
            if headless {
                studio::run_headless(args, Some(studio::worker::starter()))?;
            } else {
                anyhow::ensure!(demo::desktop_session(), "{}", demo::NO_DESKTOP);
                studio::run_with(args, Some(studio::worker::starter()))?;
            }
        }
        Command::Assets { out } => {
            for p in studio::assets::generate(&out)? {
                println!("wrote {}", p.display());
            }
        }
        Command::Render(args) => return render::run(args),
        Command::Check(CheckCommand::Golden(args)) => return check::run_golden(args),
        Command::Bench(BenchCommand::Raster(args)) => return bench::run_raster(args),
        Command::Bench(BenchCommand::Step(args)) => return bench::run_step(args),
        Command::Bench(BenchCommand::Depth(args)) => return bench::run_depth(args),
        Command::Bench(BenchCommand::Pairing(args)) => return bench::run_pairing(args),
        Command::Bench(BenchCommand::Quality(args)) => return quality::run(args),
        Command::Bench(BenchCommand::ViewportLive { data, reps }) => {
            let (scene, style, weights) = data.paths()?;
            let g = load_scene(&scene)?;
            let style = gast_core::session::StyleImage::open(&style).map_err(anyhow::Error::msg)?;
            let vgg = std::sync::Arc::new(stylize::load_vgg(weights.as_deref())?);
            println!("{}", studio::viewport::bench_live::run(g, style, vgg, reps)?);
        }
        Command::Bench(BenchCommand::Viewport { scene, count, frames, width, height }) => {
            println!("{}", studio::viewport::bench::run(scene.as_deref(), count, frames, width, height)?);
        }
        Command::Stylize(args) => return stylize::run(*args),
        Command::Fit(args) => return fit::run(args),
        Command::Convert(args) => return convert::run(args),
    }
    Ok(ExitCode::SUCCESS)
}

/// `config` when it is usable, else an error listing its problems
/// ([`gast_core::style::StyleConfig::problems`]), for `stylize` and `bench
/// step` to refuse before they load anything.
fn checked(config: gast_core::style::StyleConfig) -> anyhow::Result<gast_core::style::StyleConfig> {
    let problems = config.problems();
    anyhow::ensure!(problems.is_empty(), "invalid parameters: {}", problems.join("; "));
    Ok(config)
}

/// Refuses `path`, the JSON file the option `flag` writes (a preset, a
/// benchmark's record), when it exists and is not JSON: `--save-preset
/// wave.jpg` replaced the style image with JSON. Checked before any work.
pub(crate) fn replaceable_json(path: &std::path::Path, flag: &str) -> anyhow::Result<()> {
    if !path.exists() {
        return Ok(());
    }
    let is_json = std::fs::read(path)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<serde_json::Value>(&bytes).ok())
        .is_some_and(|v| v.is_object());
    anyhow::ensure!(
        is_json,
        "{flag} {}: expected a new file or a JSON file (an object) to replace, found a file that is not one; \
         it is left as it is: choose another name",
        path.display()
    );
    Ok(())
}

/// Checks that `dir`, the folder the option `flag` names, can become an
/// output folder, without making it: a file of that name is refused, saying
/// so (creating the folder said only "File exists"), and so is a folder
/// inside a read-only one ([`gast_core::io::refuse_read_only_folder`]). A
/// command checks this before its slow or fallible work and makes the folder
/// ([`output_folder`]) only before its first write, so a run that fails on
/// its inputs leaves no empty folder behind.
pub(crate) fn check_output_folder(dir: &std::path::Path, flag: &str) -> anyhow::Result<()> {
    anyhow::ensure!(
        !dir.exists() || dir.is_dir(),
        "{}: expected an output folder, found a file; choose another {flag}",
        dir.display()
    );
    // A folder yet to be made needs its nearest existing ancestor to be one.
    if let Some(file) =
        dir.ancestors().skip(1).filter(|a| !a.as_os_str().is_empty()).find(|a| a.exists()).filter(|a| !a.is_dir())
    {
        anyhow::bail!(
            "{}: expected an output folder to make, found the file {} in its path; choose another {flag}",
            dir.display(),
            file.display()
        );
    }
    anyhow::Context::with_context(gast_core::io::refuse_read_only_folder(dir), || {
        format!("could not use the output folder {}", dir.display())
    })
}

/// Makes `dir` (with its parents) unless it is a folder already, after
/// [`check_output_folder`]'s checks.
pub(crate) fn output_folder(dir: &std::path::Path, flag: &str) -> anyhow::Result<()> {
    check_output_folder(dir, flag)?;
    anyhow::Context::with_context(gast_core::io::create_folder(dir), || {
        format!("could not create the output folder {}", dir.display())
    })
}
