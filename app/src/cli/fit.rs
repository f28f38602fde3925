//! `gast fit`: a 3DGS scene fitted to a posed-image dataset (NeRF
//! transforms.json, COLMAP, LLFF poses_bounds.npy, cameras.json), so that
//! datasets without a Gaussian scene can be stylized. It starts from the
//! dataset's COLMAP SfM points when there are any, else from random Gaussians.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use gast_core::camera::{find_colmap_points, load_colmap_points};
use gast_core::fit::{self, FitConfig, load_posed_images, mean_psnr, psnr};
use gast_core::io::write_png_rgb;
use gast_core::raster::{self, RenderOptions};

use crate::checkpoint::{self, CHECKPOINT_SECONDS, DEFAULT_CHECKPOINT_S, Due, checkpoint_path};
use crate::progress;

/// Arguments of `gast fit`.
#[derive(Args, Debug)]
pub struct FitArgs {
    /// The dataset: a folder with transforms*.json, COLMAP sparse/0 + images/,
    /// LLFF poses_bounds.npy + images_8/ (or images_4/, images/), or
    /// cameras.json + images/ (or the camera file itself).
    pub dataset: PathBuf,
    /// The images folder, relative to the dataset folder (e.g. `images_4`):
    /// looked in first for every camera's image. For LLFF it also picks the
    /// images the poses pair with (default: images_8, else images_4, else images).
    #[arg(long)]
    pub images: Option<String>,
    /// Start from random Gaussians even when the dataset has COLMAP SfM points
    /// (sparse/0/points3D.bin or .txt).
    #[arg(long)]
    pub random_init: bool,
    /// The fitted scene, written atomically; its name picks the format: .ply
    /// (INRIA), .compressed.ply, .spz or .sog.
    #[arg(long)]
    pub out: PathBuf,
    /// Optimisation steps (one view each).
    #[arg(long)]
    pub iterations: Option<u32>,
    /// Working resolution: longer image side in pixels, 16 to 8,192 (never above the photos' own).
    #[arg(long, value_parser = crate::views::image_side())]
    pub resolution: Option<u32>,
    /// Initial number of Gaussians (1 to 20,000,000).
    #[arg(long, value_parser = crate::views::within(gast_core::fit::INITIAL_GAUSSIANS))]
    pub gaussians: Option<usize>,
    /// SH degree of the result (0 to 3).
    #[arg(long, value_parser = crate::views::within(gast_core::scene::SH_DEGREES))]
    pub sh_degree: Option<u32>,
    /// Use at most this many views, evenly spread (0: all).
    #[arg(long, default_value_t = 0)]
    pub views: usize,
    /// Turn densification (clone/split) off; low-opacity pruning still happens at the end.
    #[arg(long)]
    pub no_densify: bool,
    /// Seed of the initial points and the view order.
    #[arg(long)]
    pub seed: Option<u64>,
    /// A preset file (JSON FitConfig, missing fields take their defaults); flags override it.
    #[arg(long)]
    pub preset: Option<PathBuf>,
    /// Hold every K-th view out of the fit (as the 3DGS trainer's `--eval`, K = 8)
    /// and report its PSNR apart; previews then show held-out views. 0: use all.
    #[arg(long, default_value_t = 0)]
    pub holdout_every: usize,
    /// Write a few renders beside their ground truth into this folder.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// Every this many seconds of fitting, write the scene as it stands to a
    /// checkpoint beside the output (`fern.ply` → `fern.checkpoint.ply`, INRIA
    /// .ply whatever the output's format, with cameras.json and the fit's
    /// optimiser state), so a fit killed or crashed loses at most this much;
    /// the checkpoint is removed once the output is written. 0: none.
    #[arg(long, default_value_t = DEFAULT_CHECKPOINT_S, value_parser = crate::views::within(CHECKPOINT_SECONDS))]
    pub checkpoint_every: u64,
    /// Go on from the checkpoint beside the output, left by a fit that was
    /// killed, crashed or stopped with Ctrl-C: from its iteration, with the
    /// same dataset and settings (the same flags), which it checks; with
    /// the optimiser's state it keeps, the result is the fit run through's.
    #[arg(long)]
    pub resume: bool,
}

impl FitArgs {
    /// The preset (or the defaults) with the flags applied.
    pub fn config(&self) -> anyhow::Result<FitConfig> {
        let mut c = match &self.preset {
            Some(p) => {
                let text =
                    std::fs::read_to_string(p).with_context(|| format!("could not read the preset {}", p.display()))?;
                FitConfig::from_json(&text)
                    .with_context(|| format!("{}: expected a FitConfig JSON preset", p.display()))?
            }
            None => FitConfig::default(),
        };
        if let Some(v) = self.iterations {
            c.iterations = v;
        }
        if let Some(v) = self.resolution {
            c.resolution = v;
        }
        if let Some(v) = self.gaussians {
            c.initial_gaussians = v;
        }
        if let Some(v) = self.sh_degree {
            c.sh_degree = v;
        }
        if let Some(v) = self.seed {
            c.seed = v;
        }
        if self.no_densify {
            c.densify.enabled = false;
        }
        let problems = c.problems();
        if !problems.is_empty() {
            let from = self.preset.as_ref().map(|p| format!("{} with the flags: ", p.display())).unwrap_or_default();
            anyhow::bail!("{from}invalid fit settings: {}", problems.join("; "));
        }
        Ok(c)
    }
}

/// The working resolution of an LLFF fit when none is given: the longer side
/// of the dataset's `images_8` (the LLFF convention: 4032 / 8).
const LLFF_RESOLUTION: u32 = 504;

/// Loads the dataset, fits, writes the scene and the previews.
pub fn run(args: FitArgs) -> anyhow::Result<ExitCode> {
    let mut cfg = args.config()?;
    // The output's name is checked before the fit, not after it.
    anyhow::ensure!(
        !args.out.is_dir(),
        "{}: expected the fitted scene's file name (e.g. fit.ply), found a folder",
        args.out.display()
    );
    super::convert::check_output_name(&args.out)?;
    gast_core::io::refuse_read_only(&args.out).with_context(|| args.out.display().to_string())?;
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        super::check_output_folder(parent, "--out")?;
    }
    // An LLFF capture's own small images (images_8, 504 px for fern) are what
    // its evaluations use: fit at their size unless told otherwise (fern: 25.3
    // dB held out in about 5 min on 2 cores, against the default 200 px).
    let llff = args.dataset.join("poses_bounds.npy").is_file()
        || args.dataset.file_name().is_some_and(|n| n == "poses_bounds.npy");
    if llff && args.resolution.is_none() && args.preset.is_none() && args.images.is_none() {
        cfg.resolution = LLFF_RESOLUTION;
        eprintln!("LLFF capture: fitting at {LLFF_RESOLUTION} px, the size of its images_8 (--resolution overrides)");
    }
    // Checked before the images load: a resume with other settings, or without a checkpoint, is refused at once.
    let resume_from = if args.resume { Some(resumable(&args, &mut cfg)?) } else { None };
    if !args.resume {
        checkpoint::warn_of_a_checkpoint(&checkpoint_path(&args.out), "fit");
    }
    let t0 = Instant::now();
    let data = load_posed_images(&args.dataset, args.images.as_deref(), cfg.resolution, args.views, cfg.background)
        .with_context(|| format!("could not load the posed images of {}", args.dataset.display()))?;
    for w in &data.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(dir) = &args.preview {
        // Refused before the fit: the previews' `view0_truth.png`, … and
        // `sheet.png` would mix with the photos, and an LLFF folder pairs
        // its images with the poses by count.
        crate::views::refuse_among_photos(dir, "--preview", &data.image_folders, &args.dataset)?;
        super::check_output_folder(dir, "--preview")?;
    }
    let all_cameras: Vec<gast_core::Camera> = data.views.iter().map(|(c, _)| c.clone()).collect();
    let k = args.holdout_every;
    let views_and_alphas = data.views.into_iter().zip(data.alphas).enumerate();
    let (held, fitted): (Vec<_>, Vec<_>) = views_and_alphas.partition(|(i, _)| k > 0 && i % k == 0);
    let held: Vec<_> = held.into_iter().map(|(_, (v, _))| v).collect();
    let (views, alphas): (Vec<_>, Vec<_>) = fitted.into_iter().map(|(_, va)| va).unzip();
    let with_alpha = alphas.iter().filter(|a: &&Option<Vec<f32>>| a.is_some()).count();
    let Some((first, _)) = views.first() else {
        let found = match held.len() {
            0 => "none".to_owned(),
            n => format!("{n} view(s), all held out by --holdout-every {k}"),
        };
        anyhow::bail!("{}: expected at least one view to fit, found {found}", args.dataset.display())
    };
    let (initial, start, state) = match resume_from {
        Some(start) => {
            let path = checkpoint_path(&args.out);
            let scene = gast_core::scene::load(&path)
                .with_context(|| format!("could not read the checkpoint {} to resume from", path.display()))?;
            let (state, said) = fit_state(&path, &scene, start, views.len());
            eprintln!("resuming from iteration {start} of {}: {} ({said})", cfg.iterations, path.display());
            (scene, start, state)
        }
        None => (initial_scene(&args, &views, &cfg)?, 0, None),
    };
    eprintln!(
        "loaded {} views ({} held out) of {} at {}×{} in {:.1} s; fitting {} iterations from {} Gaussians",
        views.len(),
        held.len(),
        args.dataset.display(),
        first.width,
        first.height,
        t0.elapsed().as_secs_f64(),
        cfg.iterations - start,
        initial.len()
    );

    if with_alpha > 0 && cfg.random_background {
        eprintln!(
            "{with_alpha} of the {} fitted views with an alpha channel: each iteration composites them on a random colour, so empty \
             space stays transparent (\"random_background\": false in a --preset keeps the plain background)",
            views.len()
        );
    }
    let t_fit = Instant::now();
    // Over the iterations this run does (its pace and time left are this run's).
    let pb = progress::bar(u64::from(cfg.iterations - start), "fit");
    let mut smoothed = None::<f32>;
    // Ctrl-C stops the fit after its current iteration and writes the scene as it is.
    let interrupt = super::interrupt::interrupt();
    let mut stopped_at = None;
    let mut checkpoint = Checkpoint::new(&args, &cfg, &all_cameras);
    interrupt.begin();
    let scene = fit::fit_resumed(&views, &alphas, initial, &cfg, start, state, &mut |p, run| {
        let l = smoothed.map_or(p.loss, |s| 0.98 * s + 0.02 * p.loss);
        smoothed = Some(l);
        if p.iteration % 10 == 0 || p.iteration == p.iterations {
            progress::advance_to(&pb, u64::from(p.iteration - start));
            pb.set_message(format!("L1 {l:.4}, {} Gaussians", p.gaussians));
        }
        if interrupt.asked() && p.iteration < p.iterations {
            // Kept, so that the same command with --resume goes on from here.
            stopped_at = Some((p.iteration, checkpoint.write(run)));
            return ControlFlow::Break(());
        }
        if p.iteration < p.iterations
            && let Some(line) = checkpoint.maybe_write(p, run)
        {
            // Not `pb.println`: a hidden bar (output not a terminal) drops its lines.
            pb.suspend(|| eprintln!("{line}"));
        }
        ControlFlow::Continue(())
    });
    interrupt.end();
    pb.finish_and_clear();
    if let Some((n, written)) = &stopped_at {
        eprintln!(
            "stopped at iteration {n} of {} (Ctrl-C): writing the scene as it is; Ctrl-C again quits at once",
            cfg.iterations
        );
        match written {
            Ok(()) => eprintln!(
                "checkpoint: iteration {n} written to {}; the same command with --resume goes on from it",
                checkpoint.path.display()
            ),
            Err(e) => eprintln!("warning: the checkpoint at iteration {n} was not written: {e:#}"),
        }
    }
    let fit_s = t_fit.elapsed().as_secs_f64();

    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        super::output_folder(parent, "--out")?;
    }
    super::convert::save_scene(&args.out, &scene, &super::convert::SaveArgs::default())?;
    let psnr_all = mean_psnr(&scene, &views, cfg.background);
    eprintln!(
        "wrote {} ({} Gaussians) after fitting for {:.1} s; mean PSNR over the {} training views {:.2} dB",
        args.out.display(),
        scene.len(),
        fit_s,
        views.len(),
        psnr_all
    );
    // Held-out views included, at the working size.
    for line in crate::views::write_cameras_beside(&args.out, &args.dataset, &all_cameras)? {
        eprintln!("{line}");
    }
    if stopped_at.is_none() {
        checkpoint.remove();
    }
    if !held.is_empty() {
        eprintln!(
            "mean PSNR over the {} held-out views {:.2} dB",
            held.len(),
            mean_psnr(&scene, &held, cfg.background)
        );
    }

    if let Some(dir) = &args.preview {
        write_previews(dir, &scene, if held.is_empty() { &views } else { &held }, cfg.background)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// What a checkpoint's `.json` beside its scene records: enough to go on
/// (`--resume`) and to refuse going on with other settings.
#[derive(serde::Serialize, serde::Deserialize, Debug, PartialEq)]
struct CheckpointInfo {
    /// Iterations done when the scene was written.
    iteration: u32,
    /// The dataset fitted (its absolute path where it resolves).
    dataset: PathBuf,
    /// The fit's settings (after the flags and the LLFF resolution).
    config: FitConfig,
    /// `--holdout-every` and `--views`: which views it fits.
    holdout_every: usize,
    views: usize,
    /// `--images` and `--random-init`.
    images: Option<String>,
    random_init: bool,
}

/// The iteration `--resume` goes on from: the checkpoint beside `--out`
/// must exist and record the same settings as `cfg` and the flags that pick
/// the views; else an error that says what differs.
///
/// A record without `random_background` was written by a build that fitted
/// every view on the plain background: the fit goes on so (`cfg` is set to
/// it, saying so), rather than switching halfway through, or refusing a
/// fern fit that the setting does not touch.
fn resumable(args: &FitArgs, cfg: &mut FitConfig) -> anyhow::Result<u32> {
    let path = checkpoint_path(&args.out);
    let mut record: serde_json::Value = checkpoint::read_record(&args.out, &path, "fit")?;
    let plain =
        record.pointer("/config").and_then(|c| c.as_object()).is_some_and(|c| !c.contains_key("random_background"));
    if plain && let Some(config) = record.pointer_mut("/config").and_then(|c| c.as_object_mut()) {
        config.insert("random_background".to_owned(), serde_json::Value::Bool(false));
    }
    let info: CheckpointInfo = serde_json::from_value(record)
        .with_context(|| format!("{}: expected a fit checkpoint's record", checkpoint::record_path(&path).display()))?;
    if plain && cfg.random_background {
        eprintln!(
            "{}: the checkpoint comes from a build that fitted on the plain background; the fit goes on so \
             (views with alpha are not composited on random colours)",
            path.display()
        );
        cfg.random_background = false;
    }
    checkpoint::refuse_other_settings(&path, &info, &Checkpoint::new(args, cfg, &[]).info(info.iteration))?;
    Ok(info.iteration)
}

/// The fit's checkpoints ([`FitArgs::checkpoint_every`]): the scene as it
/// stands, written atomically to [`checkpoint_path`] with the cameras beside
/// it, and removed once the output is written.
struct Checkpoint<'a> {
    path: PathBuf,
    due: Due,
    args: &'a FitArgs,
    cfg: &'a FitConfig,
    cameras: &'a [gast_core::Camera],
    written: bool,
}

impl<'a> Checkpoint<'a> {
    fn new(args: &'a FitArgs, cfg: &'a FitConfig, cameras: &'a [gast_core::Camera]) -> Self {
        Self {
            path: checkpoint_path(&args.out),
            due: Due::every(args.checkpoint_every),
            args,
            cfg,
            cameras,
            written: false,
        }
    }

    /// What this fit's checkpoint at `iteration` records.
    fn info(&self, iteration: u32) -> CheckpointInfo {
        CheckpointInfo {
            iteration,
            dataset: self.args.dataset.canonicalize().unwrap_or_else(|_| self.args.dataset.clone()),
            config: self.cfg.clone(),
            holdout_every: self.args.holdout_every,
            views: self.args.views,
            images: self.args.images.clone(),
            random_init: self.args.random_init,
        }
    }

    /// Writes the fit as it stands when the interval has passed since the
    /// last one (or the fit's start); returns what to tell the user. A
    /// failed write is a warning: the fit goes on, and its output is
    /// written (or fails, saying why) at the end as before.
    fn maybe_write(&mut self, p: fit::FitProgress, run: &fit::FitRun<'_>) -> Option<String> {
        if !self.due.now() {
            return None;
        }
        let t = Instant::now();
        let result = self.write(run);
        self.due.written();
        Some(match result {
            Ok(()) => format!(
                "checkpoint: iteration {} of {} written to {} in {:.0} ms",
                p.iteration,
                p.iterations,
                self.path.display(),
                t.elapsed().as_secs_f64() * 1e3
            ),
            Err(e) => format!("warning: the checkpoint at iteration {} was not written: {e:#}", p.iteration),
        })
    }

    /// Writes the fit's scene as it stands (before the final pruning), its
    /// state and its record ([`checkpoint::write_with_record`]), and the
    /// cameras beside it once.
    fn write(&mut self, run: &fit::FitRun<'_>) -> anyhow::Result<()> {
        let state = run.state();
        let write = |w: &mut dyn std::io::Write| state.write_to(w);
        checkpoint::write_with_record(&self.path, run.scene(), Some(&write), &self.info(state.iteration))?;
        if !self.written {
            // Once: the checkpoint is a scene the studio and `gast stylize` open with its cameras.
            crate::views::write_cameras_beside(&self.path, &self.args.dataset, self.cameras)?;
        }
        self.written = true;
        Ok(())
    }

    /// Removes the checkpoint (scene and record) once the output holds the
    /// whole fit; also the one a resumed fit went on from.
    fn remove(&self) {
        checkpoint::remove(&self.path);
    }
}

/// The fit's state beside the checkpoint `path` of `scene` after `start`
/// iterations over `views` views, and what to say of it: kept, or why the
/// moments, statistics and view order start afresh (none written, as by
/// older versions, or unreadable, or not this scene's: the fit still goes on).
fn fit_state(path: &Path, scene: &gast_core::Gaussians, start: u32, views: usize) -> (Option<fit::FitState>, String) {
    let at = checkpoint::moments_path(path);
    let read = std::fs::read(&at)
        .map_err(|e| e.to_string())
        .and_then(|b| fit::FitState::from_safetensors(&b))
        .and_then(|s| s.check(scene, start, views).map(|()| s));
    match read {
        Ok(state) => (Some(state), "with the fit's optimiser state, statistics and view order".into()),
        Err(_) if !at.exists() => {
            (None, format!("the optimiser's moments and the view order start afresh: no {}", at.display()))
        }
        Err(e) => (None, format!("the optimiser's moments and the view order start afresh: {}: {e}", at.display())),
    }
}

/// The dataset's SfM points as Gaussians when it has `points3D` (and
/// `--random-init` is not given), else random ones; says which on stderr.
fn initial_scene(
    args: &FitArgs,
    views: &[(gast_core::Camera, Vec<f32>)],
    cfg: &FitConfig,
) -> anyhow::Result<gast_core::Gaussians> {
    let found = if args.random_init { None } else { find_colmap_points(&args.dataset) };
    if let Some(path) = found {
        let points = load_colmap_points(&path)
            .with_context(|| format!("could not read the SfM points of {}", args.dataset.display()))?;
        if !points.is_empty() {
            eprintln!("initialisation: {} SfM points from {}", points.len(), path.display());
            return Ok(fit::initial_scene_from_points(&points, cfg));
        }
        eprintln!("warning: {} holds no points; starting from random Gaussians", path.display());
    }
    let why = if args.random_init { "--random-init" } else { "no COLMAP points3D.bin/.txt in the dataset" };
    eprintln!("initialisation: {} random Gaussians in the cameras' common view ({why})", cfg.initial_gaussians.max(1));
    let cameras: Vec<_> = views.iter().map(|(c, _)| c.clone()).collect();
    Ok(fit::initial_scene(&cameras, cfg))
}

/// Renders four views spread over the dataset, writes each render and its
/// ground truth, and `sheet.png` with one row per view (truth left, render right).
fn write_previews(
    dir: &std::path::Path,
    scene: &gast_core::Gaussians,
    views: &[(gast_core::Camera, Vec<f32>)],
    background: [f32; 3],
) -> anyhow::Result<()> {
    super::output_folder(dir, "--preview")?;
    let opts = RenderOptions { background };
    let n = views.len().min(4);
    let (w, h) = (views[0].0.width as usize, views[0].0.height as usize);
    let mut sheet = vec![0.0f32; n * h * 2 * w * 3];
    for k in 0..n {
        let (cam, gt) = &views[k * views.len() / n];
        let img = raster::render(scene, cam, &opts);
        let stem = format!("view{k}");
        write_png_rgb(&dir.join(format!("{stem}_render.png")), cam.width, cam.height, &img.rgb)?;
        write_png_rgb(&dir.join(format!("{stem}_truth.png")), cam.width, cam.height, gt)?;
        eprintln!("preview {stem} ({}): PSNR {:.2} dB", cam.name, psnr(&img.rgb, gt));
        if (cam.width as usize, cam.height as usize) != (w, h) {
            continue;
        }
        for y in 0..h {
            let row = (k * h + y) * 2 * w * 3;
            sheet[row..row + 3 * w].copy_from_slice(&gt[y * w * 3..(y + 1) * w * 3]);
            sheet[row + 3 * w..row + 6 * w].copy_from_slice(&img.rgb[y * w * 3..(y + 1) * w * 3]);
        }
    }
    write_png_rgb(&dir.join("sheet.png"), (2 * w) as u32, (n * h) as u32, &sheet)?;
    eprintln!("previews in {} (sheet.png: ground truth left, render right)", dir.display());
    Ok(())
}
