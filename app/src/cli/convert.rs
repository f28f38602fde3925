//! `gast convert IN OUT`: any scene format the studio reads into any it
//! writes, the writer chosen by OUT's name, so a scene can go to the tool an
//! artist shares with (SuperSplat, PlayCanvas, Niantic's viewers).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use gast_core::Gaussians;
use gast_core::scene::{SaveOptions, Strength};

use crate::progress;
use crate::views::load_scene;

/// Options of the lossy writers, shared by `convert` and `stylize`; refused
/// outside their ranges as they are parsed, before a run (the writer checks
/// them again, after the run).
#[derive(Args, Debug, Clone)]
pub struct SaveArgs {
    /// Version of a .spz output: 3 (gzip) or 4 (zstd).
    #[arg(long, default_value_t = SaveOptions::default().spz_version,
          value_parser = crate::views::within(gast_core::scene::SPZ_VERSIONS))]
    pub spz_version: u32,
    /// Largest palette of a SOG output's higher SH bands (k-means beyond it), 1 to 65536.
    #[arg(long, default_value_t = SaveOptions::default().sog_palette,
          value_parser = crate::views::within(gast_core::scene::SOG_PALETTES))]
    pub sog_palette: usize,
}

impl Default for SaveArgs {
    fn default() -> Self {
        let o = SaveOptions::default();
        Self { spz_version: o.spz_version, sog_palette: o.sog_palette }
    }
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
    /// or a SOG folder (a name ending in /, an existing folder not named as a file
    /// format's, or …/meta.json).
    pub output: PathBuf,
    #[command(flatten)]
    pub save: SaveArgs,
    /// Blend the input (a stylized scene) back toward this one before writing:
    /// the `colour_matched.ply` that `gast stylize` writes beside its result
    /// (or the scene it started from). Needs --strength, or --colour-strength
    /// and --shape-strength.
    #[arg(long, value_name = "SCENE")]
    pub blend: Option<PathBuf>,
    #[command(flatten)]
    pub strength: StrengthArgs,
}

/// How much of a stylization to keep (`gast stylize`, `gast convert --blend`).
#[derive(Args, Debug, Clone, Default)]
pub struct StrengthArgs {
    /// Share of the stylization kept, in percent, colour and shape alike:
    /// 0 is the colour-matched scene, 100 the stylized one (exact at both ends).
    #[arg(long, value_name = "PERCENT", value_parser = percent)]
    pub strength: Option<f32>,
    /// Share of the colour change kept (SH coefficients), percent; overrides --strength.
    #[arg(long, value_name = "PERCENT", value_parser = percent)]
    pub colour_strength: Option<f32>,
    /// Share of the shape change kept (means, scales, rotations, opacities), percent; overrides --strength.
    #[arg(long, value_name = "PERCENT", value_parser = percent)]
    pub shape_strength: Option<f32>,
}

impl StrengthArgs {
    /// The strengths as fractions; `None` when no flag was given.
    pub fn strength(&self) -> Option<Strength> {
        let both = self.strength;
        if both.is_none() && self.colour_strength.is_none() && self.shape_strength.is_none() {
            return None;
        }
        let pick = |one: Option<f32>| one.or(both).unwrap_or(100.0) / 100.0;
        Some(Strength { colour: pick(self.colour_strength), shape: pick(self.shape_strength) })
    }
}

/// A percentage from 0 to 100 (a trailing `%` is allowed).
fn percent(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .trim_end_matches('%')
        .parse()
        .map_err(|_| format!("expected a percentage from 0 to 100, found {s:?}"))?;
    if (0.0..=100.0).contains(&v) { Ok(v) } else { Err(format!("expected a percentage from 0 to 100, found {v}")) }
}

/// `stylized` blended toward `matched` by `strength`, with the files named in the error.
pub fn blended(
    matched: &Gaussians,
    stylized: &Gaussians,
    strength: Strength,
    matched_path: &Path,
) -> anyhow::Result<Gaussians> {
    gast_core::scene::blend(matched, stylized, strength)
        .with_context(|| format!("cannot blend toward {}", matched_path.display()))
}

/// Checks that `path` names a format [`save_scene`] writes, and that an
/// existing folder as a SOG output holds no other files of its names, before
/// any long work.
pub fn check_output_name(path: &Path) -> anyhow::Result<()> {
    match gast_core::scene::check_output(path) {
        Ok(_) => Ok(()),
        Err(e @ gast_core::scene::SceneError::UnknownFormat { .. }) => {
            Err(anyhow::Error::new(e).context("cannot choose a scene format from the output's name"))
        }
        Err(e) => Err(e.into()),
    }
}

/// Refuses an output that is the input scene itself (the same file, or the
/// SOG folder of its `meta.json`): writing it would replace the original with
/// a re-encoding of itself, lossy for the compressed formats.
pub fn check_not_the_input(input: &Path, output: &Path) -> anyhow::Result<()> {
    let Ok(out) = output.canonicalize() else { return Ok(()) };
    let Ok(inp) = input.canonicalize() else { return Ok(()) };
    let folder = inp.file_name().is_some_and(|n| n == "meta.json").then(|| inp.parent()).flatten();
    anyhow::ensure!(
        out != inp && Some(out.as_path()) != folder,
        "{}: expected an output other than the input scene, found the input itself (it would be replaced by a re-encoding of itself; choose another name)",
        output.display()
    );
    Ok(())
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
    check_not_the_input(&args.input, &args.output)?;
    let start = Instant::now();
    let mut scene = load_scene(&args.input)?;
    match (&args.blend, args.strength.strength()) {
        (Some(path), Some(strength)) => {
            let matched = load_scene(path)?;
            scene = blended(&matched, &scene, strength, path)?;
            eprintln!(
                "blended toward {}: colour {:.0}%, shape {:.0}%",
                path.display(),
                strength.colour * 100.0,
                strength.shape * 100.0
            );
        }
        (Some(_), None) => anyhow::bail!("--blend needs --strength (or --colour-strength and --shape-strength)"),
        (None, Some(_)) => anyhow::bail!("--strength needs --blend SCENE: the scene to blend toward"),
        (None, None) => {}
    }
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
