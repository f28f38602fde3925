//! `gast render`: PNG colour, PNG + EXR inverse depth of chosen or generated views;
//! or, with `--turntable N`, a turntable (frames and an animated GIF, see
//! [`crate::turntable`]), optionally before | after side by side with `--compare`.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;
use gast_core::Gaussians;
use gast_core::io::{write_depth_png, write_exr_depth, write_png_rgb};
use gast_core::raster::{self, RenderOptions};

use crate::progress;
use crate::turntable::{self, TurntableOptions};
use crate::views::{ViewArgs, camera_source, load_scene, refuse_photo_folder, views_for};

/// Arguments of `gast render`.
#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The scene: INRIA .ply, PlayCanvas .compressed.ply, .spz, or a SOG folder / meta.json.
    pub scene: PathBuf,
    /// Output folder (created; existing files are replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub views: ViewArgs,
    /// Background colour as r,g,b in [0, 1] (`0.5,0.5,0.5` or `0.5 0.5 0.5`).
    #[arg(long, value_delimiter = ',', num_args = 1..=3, default_values_t = [0.0, 0.0, 0.0],
          value_parser = crate::views::unit_channel)]
    pub background: Vec<f32>,
    /// Instead of the views, N frames on a ring around the scene (`turntable_NNN.png`)
    /// and a looping animated `turntable.gif`, `--size` pixels square. A forward-facing
    /// capture (its cameras beside it or `--cameras`, all looking one way, as LLFF's fern)
    /// gets a loop through its own cameras instead, NeRF's spiral; `--orbit` keeps the ring.
    #[arg(long, value_name = "N", value_parser = crate::views::view_count::<u32>())]
    pub turntable: Option<u32>,
    /// A second scene (e.g. the stylized one) shown beside SCENE in every
    /// turntable frame, from the same cameras: before | after.
    #[arg(long, value_name = "OTHER", requires = "turntable")]
    pub compare: Option<PathBuf>,
}

/// Renders every view and writes `NAME.png`, `NAME_depth.png` and `NAME_depth.exr`.
pub fn run(args: RenderArgs) -> anyhow::Result<ExitCode> {
    // clap counts `0.5,0.5,0.5` as one value before it splits it, so the
    // three channels are counted here.
    let &[r, g, b] = args.background.as_slice() else {
        anyhow::bail!("--background: expected three values r,g,b, found {:?}", args.background)
    };
    // The inputs are read before the folder is made, so a missing one leaves none.
    super::check_output_folder(&args.out, "--out")?;
    let scene = load_scene(&args.scene)?;
    let background = [r, g, b];
    if let Some(frames) = args.turntable {
        refuse_photo_folder(&args.out, "--out", None, &[])?;
        return run_turntable(&args, &scene, frames as usize, background);
    }
    let source = camera_source(&args.scene, &scene, args.views.cameras.as_deref(), args.views.orbit)?;
    let cameras = views_for(&scene, &ViewArgs { cameras: source.clone(), ..args.views.clone() })?;
    refuse_photo_folder(&args.out, "--out", source.as_deref(), &cameras)?;
    super::output_folder(&args.out, "--out")?;
    let opts = RenderOptions { background };
    let pb = progress::bar(cameras.len() as u64, "render");
    let start = std::time::Instant::now();
    for cam in &cameras {
        pb.set_message(cam.name.clone());
        let img = raster::render(&scene, cam, &opts);
        let stem = sanitize(&cam.name);
        write_png_rgb(&args.out.join(format!("{stem}.png")), img.width, img.height, &img.rgb)?;
        write_depth_png(
            &args.out.join(format!("{stem}_depth.png")),
            img.width,
            img.height,
            &img.inv_depth,
            &img.alpha,
        )?;
        write_exr_depth(&args.out.join(format!("{stem}_depth.exr")), img.width, img.height, &img.inv_depth)
            .with_context(|| format!("writing the depth of view {}", cam.name))?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    if source.is_none() {
        // Orbit views `orbit_000` …: an earlier, longer orbit's tail would sit beside them.
        let stale = gast_core::io::remove_series_tail(
            &args.out,
            "orbit_",
            &[".png", "_depth.png", "_depth.exr"],
            cameras.len(),
        )
        .map_err(|(path, e)| anyhow::anyhow!("{}: removing an earlier orbit's view: {e}", path.display()))?;
        if stale > 0 {
            eprintln!("removed {stale} files of orbit views {} and above, which an earlier render left", cameras.len());
        }
    }
    eprintln!(
        "rendered {} views of {} ({} Gaussians) into {} in {:.2} s",
        cameras.len(),
        args.scene.display(),
        scene.len(),
        args.out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}

/// Writes the turntable of `scene` (beside `--compare`'s scene when given).
fn run_turntable(
    args: &RenderArgs,
    scene: &Gaussians,
    frames: usize,
    background: [f32; 3],
) -> anyhow::Result<ExitCode> {
    let after = args.compare.as_deref().map(load_scene).transpose()?;
    // A forward-facing capture's own cameras give its loop (a ring would show its back).
    let training = match camera_source(&args.scene, scene, args.views.cameras.as_deref(), args.views.orbit)? {
        Some(path) => views_for(scene, &ViewArgs { cameras: Some(path), ..args.views.clone() })?,
        None => Vec::new(),
    };
    if gast_core::camera::forward_facing(&training).is_some() {
        eprintln!(
            "a forward-facing capture: the turntable loops through its {} cameras rather than circling the scene \
             (--orbit circles it)",
            training.len()
        );
    }
    let opts = TurntableOptions {
        training,
        frames,
        size: args.views.size,
        fov_y_degrees: args.views.fov,
        background,
        ..TurntableOptions::default()
    };
    let pb = progress::bar(frames as u64, "turntable");
    let start = std::time::Instant::now();
    let made = turntable::write(&args.out, scene, after.as_ref(), &opts, &mut |done, _| pb.set_position(done as u64))?;
    pb.finish_and_clear();
    eprintln!(
        "rendered a {}-frame turntable of {}{} ({}x{} px) in {:.2} s",
        made.frames.len(),
        args.scene.display(),
        args.compare.as_ref().map_or(String::new(), |p| format!(" beside {}", p.display())),
        made.width,
        made.height,
        start.elapsed().as_secs_f64()
    );
    println!("{}", made.gif.display());
    Ok(ExitCode::SUCCESS)
}

/// A file stem from a camera name (image names may hold folders and extensions).
fn sanitize(name: &str) -> String {
    let base = std::path::Path::new(name).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let s = crate::report::file_safe(&base);
    if s.is_empty() { "view".into() } else { s }
}
