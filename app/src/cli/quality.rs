//! `gast bench quality`: speed against quality over a grid of settings, the
//! stability study and the paper's ablations, on the shared scenes and styles.
//! This is the command's face (its arguments, the weights, the output
//! folder); the studies themselves, their grid, trial runner and pages, are
//! [`crate::study`].

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use clap::Args;

use super::bench::shared_dir;
use crate::study::geometry::GeometrySizes;
use crate::study::pages::quality::{read_summary, rewrite_report, write_report};
use crate::study::run::run_grid;
use crate::study::{Sizes, Study};

/// Arguments of `gast bench quality`.
#[derive(Args, Debug)]
pub struct QualityArgs {
    /// Output folder (default: `gast-quality-<UTC date and time>` in the current folder).
    /// Each finished trial is journalled there (`trials.jsonl`): the same
    /// command with the same folder resumes a run that was stopped.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// A small subset (the guitar, two styles, short budgets, small images) that
    /// runs in a few minutes; for checking the pipeline, not for conclusions.
    #[arg(long)]
    pub quick: bool,
    /// Only these studies (default: all).
    #[arg(long, value_delimiter = ',')]
    pub studies: Vec<Study>,
    /// VGG weights (default: the shared vgg19-conv3.safetensors, else the usual resolution).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// The grid's sizes from a JSON file (the fields of `sizes` in results.json;
    /// missing ones take the full grid's): scenes, styles, budgets and
    /// resolutions, e.g. to run a study on a subset. With `--studies geometry`
    /// alone, the geometry study's sizes (its `arms`, `styles`, `resolution`, …).
    #[arg(long, value_name = "FILE", conflicts_with = "quick")]
    pub sizes: Option<PathBuf>,
    /// Redraw the tables, charts and index of an earlier run's folder from its
    /// results.json, without running anything.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["quick", "studies", "out", "sizes"])]
    pub report: Option<PathBuf>,
    /// Take finished trials from other runs' folders (their `trials.jsonl`) instead of running
    /// them: a trial whose scene and arm such a journal holds, when that run's grid differs
    /// from this one only in its scenes (a run of one scene joins a grid of three), its styles
    /// (a run of a few styles joins a run of nine), or in `defaults_patch` (a candidate
    /// recipe's run takes paper's arms and its seed twin, which the patch leaves alone).
    /// Each taken trial names its journal in results.json (`from`);
    /// a grid that differs in anything else is refused, naming what differs.
    #[arg(long, value_name = "DIR", value_delimiter = ',', conflicts_with_all = ["quick", "report"])]
    pub from: Vec<PathBuf>,
    /// The geometry study's scene: a fit of the fern (`gast fit
    /// ../shared/data/datasets/fern --holdout-every 8 --resolution 504 --out fern.ply`).
    /// Default: fit one into the output folder first (a few minutes).
    #[arg(long, value_name = "PLY")]
    pub scene: Option<PathBuf>,
}

/// Runs the grid and writes the report.
pub fn run(args: QualityArgs) -> anyhow::Result<ExitCode> {
    if let Some(dir) = &args.report {
        let geometry_dir = dir.join("geometry");
        if geometry_dir.join("results.json").exists() {
            let run = crate::study::pages::geometry::read(&geometry_dir)?;
            let (path, verdict) = crate::study::pages::geometry::write(&geometry_dir, &run)?;
            println!("geometry study: {verdict}\nreport: {}", path.display());
            if !dir.join("results.json").exists() {
                return Ok(ExitCode::SUCCESS);
            }
        }
        let run = read_summary(dir)?;
        let index = rewrite_report(dir, &run)?;
        for line in crate::study::pages::focus::write_focus_report(dir, &run)? {
            println!("{line}");
        }
        println!("report: {}", index.display());
        return Ok(ExitCode::SUCCESS);
    }
    let shared = shared_dir();
    let studies = if args.studies.is_empty() { Study::ALL.to_vec() } else { args.studies.clone() };
    // A sizes file is the geometry study's when it runs alone, else the grid's.
    let geometry_only = studies == [Study::Geometry];
    let sizes = match &args.sizes {
        Some(path) if !geometry_only => Sizes::from_file(path)?,
        _ if args.quick => Sizes::quick(),
        _ => Sizes::full(),
    };
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(format!("gast-quality-{}", crate::report::utc_stamp())));
    super::check_output_folder(&out, "--out")?;
    let weights = args.weights.clone().or_else(super::bench::shared_weights);
    let vgg = Arc::new(super::stylize::load_vgg(weights.as_deref())?);
    super::output_folder(&out, "--out")?;
    if studies.contains(&Study::Geometry) {
        let mut g = match &args.sizes {
            Some(path) if geometry_only => GeometrySizes::from_file(path)?,
            _ if args.quick => GeometrySizes::quick(),
            _ => GeometrySizes::full(),
        };
        if args.scene.is_some() {
            g.scene = args.scene.clone();
        }
        let dir = out.join("geometry");
        let run = crate::study::geometry_run::run(&g, &shared, &vgg, &dir, &fit_photos)?;
        let (path, verdict) = crate::study::pages::geometry::write(&dir, &run)?;
        println!("geometry study in {:.1} min: {verdict}\nreport: {}", run.wall_s / 60.0, path.display());
    }
    let studies: Vec<Study> = studies.into_iter().filter(|&s| s != Study::Geometry).collect();
    if studies.is_empty() {
        return Ok(ExitCode::SUCCESS);
    }
    let (run, styles_used) = run_grid(sizes, &studies, &shared, &vgg, &out, &args.from)?;
    let wall = run.wall_s;
    let index = write_report(&out, &run, &styles_used)?;
    for line in crate::study::pages::focus::write_focus_report(&out, &run)? {
        println!("{line}");
    }
    println!("{} trials in {:.1} min; report: {}", run.trials.len(), wall / 60.0, index.display());
    Ok(ExitCode::SUCCESS)
}

/// `gast fit DATASET --holdout-every 8 --resolution 504 --iterations N --out PLY`,
/// for the geometry study's scene.
fn fit_photos(dataset: &Path, out: &Path, iterations: u32) -> anyhow::Result<()> {
    let args = super::fit::FitArgs {
        dataset: dataset.to_path_buf(),
        images: None,
        random_init: false,
        out: out.to_path_buf(),
        iterations: Some(iterations),
        resolution: Some(504),
        gaussians: None,
        sh_degree: None,
        views: 0,
        no_densify: false,
        seed: None,
        preset: None,
        holdout_every: 8,
        preview: None,
        checkpoint_every: crate::checkpoint::DEFAULT_CHECKPOINT_S,
        resume: false,
    };
    super::fit::run(args).map(|_| ())
}
