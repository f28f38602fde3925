//! The headless demo: what `gast` does where the studio cannot open a window.
//!
//! A new user's first command is `gast` with no arguments. On a laptop that
//! opens the studio; on a server, in a container or over SSH there is no
//! desktop session, and an error from the windowing library would leave them
//! with nothing to look at. So without a display `gast` says, in one sentence,
//! that the studio needs a desktop session, then runs a short stylization of
//! the demo scene with the demo style through `gast stylize` itself (same
//! progress bar, same outputs) and prints the folder it wrote. `gast studio`
//! asked for the window explicitly, so there the same sentence is an error.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Args as _, FromArgMatches as _};
use gast_core::vision::download::WeightsLocations;

use super::stylize::{self, StylizeArgs};
use crate::studio::assets;

/// The sentence that says why there is no window.
pub const NO_DESKTOP: &str = "the studio needs a desktop session, and none was found (DISPLAY, WAYLAND_DISPLAY and \
                              WAYLAND_SOCKET are unset); `gast studio --headless` draws it offscreen instead";

/// The display variables a Linux or BSD window needs one of.
const DISPLAY_VARS: [&str; 3] = ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"];

/// Whether a window can be opened: always on Windows and macOS, elsewhere only
/// with an X11 or Wayland display in the environment.
pub fn desktop_session() -> bool {
    if cfg!(any(target_os = "windows", target_os = "macos")) {
        return true;
    }
    DISPLAY_VARS.iter().any(|k| std::env::var_os(k).is_some_and(|v| !v.is_empty()))
}

/// The demo's settings, as `gast stylize` flags: 2 cycles of 100 steps at
/// 128 px on 12 orbit views with the object recipe (object focus, λ_asc 10,
/// λ_as 0.015: the focus study's winner, `docs/studies/focus.md`) and the
/// built-in relief depth (no download): about 30 s of optimisation on two
/// cores, enough for the style's waves to break the plate's checker into
/// streaks. 24 steps showed no change to the eye.
pub const DEMO_FLAGS: [&str; 20] = [
    "--cycles",
    "2",
    "--steps-per-cycle",
    "100",
    "--resolution",
    "128",
    "--texture-scale",
    "128",
    "--views",
    "12",
    "--preview-views",
    "4",
    "--focus",
    "object",
    "--lambda-assign-cos",
    "10",
    "--lambda-assign",
    "0.015",
    "--depth-provider",
    "heuristic",
];

/// Runs the demo and prints the folder of its outputs.
pub fn run() -> anyhow::Result<ExitCode> {
    eprintln!("{NO_DESKTOP}.");
    let out = output_folder()?;
    let (scene, style) = inputs(&out)?;
    eprintln!("headless demo: stylizing {} with {} into {}", scene.display(), style.display(), out.display());
    let mut argv: Vec<OsString> = vec!["gast stylize".into(), scene.into(), style.into(), "--out".into()];
    argv.push(out.clone().into());
    argv.extend(DEMO_FLAGS.iter().map(OsString::from));
    if let Some(w) = demo_weights() {
        argv.extend(["--weights".into(), w.into()]);
    }
    let matches = StylizeArgs::augment_args(clap::Command::new("gast stylize"))
        .try_get_matches_from(&argv)
        .context("the demo's stylize flags")?;
    let code = stylize::run(StylizeArgs::from_arg_matches(&matches)?).inspect_err(|_| {
        // A run that failed before writing (no weights offline) leaves no empty folder behind.
        let _ = std::fs::remove_dir(&out);
    })?;
    println!("the demo's outputs are in {}", out.display());
    Ok(code)
}

/// `gast-demo-<UTC time>` in the current folder, else in the temporary folder
/// when the current one is not writable (an absolute path either way).
fn output_folder() -> anyhow::Result<PathBuf> {
    let name = format!("gast-demo-{}", crate::report::utc_stamp());
    let here = std::env::current_dir().map(|d| d.join(&name));
    if let Ok(dir) = &here
        && gast_core::io::create_folder(dir).is_ok()
    {
        return Ok(dir.clone());
    }
    let dir = std::env::temp_dir().join(&name);
    gast_core::io::create_folder(&dir)
        .with_context(|| format!("could not create the demo's folder {}", dir.display()))?;
    Ok(dir)
}

/// The demo scene and first demo style: the committed assets of this source
/// tree when present, else generated into `out/assets`.
fn inputs(out: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
    let committed = assets::source_assets_dir();
    let (scene, style) = (committed.join(assets::DEMO_SCENE), committed.join(assets::DEMO_STYLES[0]));
    if scene.is_file() && style.is_file() {
        return Ok((scene, style));
    }
    let dir = out.join("assets");
    assets::generate(&dir)?;
    Ok((dir.join(assets::DEMO_SCENE), dir.join(assets::DEMO_STYLES[0])))
}

/// Weights already on this machine (`GAST_WEIGHTS`, the caches), else the
/// shared data's small VGG file when the checkout has one beside it; `None`
/// leaves the usual resolution (a one-time download) to `gast stylize`.
fn demo_weights() -> Option<PathBuf> {
    WeightsLocations::from_env(None).find().ok().or_else(super::bench::shared_weights)
}
