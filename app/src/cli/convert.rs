//! `gast convert IN OUT`: any scene format the studio reads into any it
//! writes, the writer chosen by OUT's name, so a scene can go to the tool an
//! artist shares with (SuperSplat, PlayCanvas, Niantic's viewers).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use gast_core::Gaussians;
use gast_core::scene::{SaveOptions, SceneFormat};

use super::load_scene;
use crate::progress;

/// Options of the lossy writers, shared by `convert` and `stylize`.
#[derive(Args, Debug, Clone)]
pub struct SaveArgs {
    /// Version of a .spz output: 3 (gzip) or 4 (zstd).
    #[arg(long, default_value_t = 4)]
    pub spz_version: u32,
    /// Largest palette of a SOG output's higher SH bands (k-means beyond it), 1 to 65536.
    #[arg(long, default_value_t = 65_536)]
    pub sog_palette: usize,
}

impl SaveArgs {
    /// The core's options.
    pub fn options(&self) -> SaveOptions {
        SaveOptions { spz_version: self.spz_version, sog_palette: self.sog_palette }
    }
}

/// Arguments of `gast convert`.
#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// The scene: INRIA .ply, .compressed.ply, .spz, a SOG folder, meta.json or .sog.
    pub input: PathBuf,
    /// The output; its name picks the format: .ply, .compressed.ply, .spz, .sog,
    /// or a SOG folder (a name ending in /, an existing folder, or …/meta.json).
    pub output: PathBuf,
    #[command(flatten)]
    pub save: SaveArgs,
}

/// Checks that `path` names a format [`save_scene`] writes, before any long work.
pub fn check_output_name(path: &Path) -> anyhow::Result<()> {
    SceneFormat::from_output(path).map(|_| ()).context("cannot choose a scene format from the output's name")
}

/// Writes `scene` to `path` in the format its name asks for, with a progress bar.
pub fn save_scene(path: &Path, scene: &Gaussians, save: &SaveArgs) -> anyhow::Result<()> {
    let pb = progress::bar(1000, "write");
    let result = gast_core::scene::save_with_progress(path, scene, &save.options(), &mut |stage, done| {
        pb.set_message(stage.to_string());
        pb.set_position((done.clamp(0.0, 1.0) * 1000.0) as u64);
    });
    pb.finish_and_clear();
    result.with_context(|| format!("could not write the scene {}", path.display()))
}

/// Runs the conversion.
pub fn run(args: ConvertArgs) -> anyhow::Result<ExitCode> {
    check_output_name(&args.output)?;
    let start = Instant::now();
    let scene = load_scene(&args.input)?;
    let read_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    save_scene(&args.output, &scene, &args.save)?;
    eprintln!(
        "converted {} ({} Gaussians, SH degree {}) to {}: read {read_s:.2} s, write {:.2} s",
        args.input.display(),
        scene.len(),
        scene.sh_degree,
        args.output.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}
