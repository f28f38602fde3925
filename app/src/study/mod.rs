//! The studies of `gast bench quality`, in one place: their definitions here
//! (the studies, the grid's sizes, one trial's specification, the rows that
//! read trials, what a run records), the grid of trials each study asks for
//! ([`grid`]), the trial runner ([`run`]) and its journal of finished trials
//! ([`journal`]), the geometry study ([`geometry`], [`geometry_run`]) and the
//! pages a run writes ([`pages`]).
//! The command (`cli::quality`) parses its arguments and calls in here.

use std::path::PathBuf;

pub mod adopt;
pub mod geometry;
pub mod geometry_run;
pub mod grid;
pub mod journal;
pub mod pages;
pub mod run;

use clap::ValueEnum;
use gast_core::eval::{Checkpoint, Degeneration, TrialOutcome};
use gast_core::session::StyleImage;
use gast_core::style::{Mode, StyleConfig};
use serde::{Deserialize, Serialize};

/// Labels of the focus study's arms and of its noise-floor run.
pub const FOCUS_FRAME: &str = "frame";
/// See [`FOCUS_FRAME`].
pub const FOCUS_OBJECT: &str = "object";
/// See [`FOCUS_FRAME`]: the frame arm with another view order.
pub const FOCUS_SEED: &str = "frame, seed 1";
/// See [`FOCUS_FRAME`]: object focus's fitted views alone (the paper's
/// whole-frame losses on them; `focus_halves` of [`Sizes`]).
pub const FOCUS_FITTED_VIEWS: &str = "fitted views, frame losses";
/// See [`FOCUS_FITTED_VIEWS`]: object focus's masked losses alone, on the plain orbit.
pub const FOCUS_MASKED_LOSSES: &str = "orbit, masked losses";

/// Labels of the defaults study's arms: `--preset paper` (the base), the
/// shipped defaults, and the paper's arm with another view order (the seed floor).
pub const DEFAULTS_PAPER: &str = "paper";
/// See [`DEFAULTS_PAPER`].
pub const DEFAULTS_NEW: &str = "defaults";
/// See [`DEFAULTS_PAPER`].
pub const DEFAULTS_SEED: &str = "paper, seed 1";
/// Steps per cycle of the defaults study: the paper's (and `gast stylize`'s) 100.
pub const DEFAULTS_CYCLE: u32 = 100;

/// The studies of the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Study {
    /// The decoupled default on every scene × style pair.
    Pairs,
    /// The four optimisation modes over growing step budgets (the paper's first ablation).
    Modes,
    /// Working resolutions.
    Resolution,
    /// The geometry share N_g / (N_c + N_g) of each cycle (the paper's N_g ablation).
    Ratio,
    /// The GCFM weight λ_GC.
    LambdaGc,
    /// Settings pushed until they fail: high learning rates, geometry-only, long runs, extreme styles.
    Stress,
    /// Winograd convolutions, the matching index and re-used matches against the exact
    /// default, at a fixed step budget and at twice it (to compare at equal wall time).
    Fast,
    /// Frame against object focus (plain orbit and whole-frame losses against
    /// fitted views and masked losses) on every scene × style pair, measured on
    /// the object's pixels of the fitted evaluation ring; with `focus_halves`
    /// of [`Sizes`] also each half alone. Runs only when named.
    Focus,
    /// The decoupled default at 1,000 steps on every pair, watched by the
    /// colour-collapse detector; on the first scene × block2 also object focus,
    /// colour learning rates 1e-3 and 1e-4, the colour floor, a tenth of
    /// the means' learning rate and a hundred times λ_cont (`collapse_arms`,
    /// `collapse_object_on_every_pair` and `collapse_content_on_every_pair`
    /// of [`Sizes`] choose). Runs only when named.
    Collapse,
    /// Does the shape take the style's structure? A fit of fern × the nine
    /// styles, decoupled against colour-only, geometry-only and the
    /// mean-square tether, the depth measures after every cycle
    /// ([`geometry`]). Runs only when named.
    Geometry,
    /// The shipped defaults (`StyleConfig::default()`: focus auto, the object
    /// recipe, the relief depth, views framed as `gast stylize` frames them)
    /// against `--preset paper` (the plain orbit, whole-frame losses) on every
    /// scene × style pair, measured on the object's pixels of the fitted
    /// ring; the paper's arm twice on the first style (the seed floor).
    /// Runs only when named.
    Defaults,
}

impl Study {
    /// The studies of a run without `--studies`, in report order (the long
    /// focus and collapse studies run only when named).
    pub const ALL: [Study; 7] =
        [Study::Modes, Study::Ratio, Study::LambdaGc, Study::Resolution, Study::Fast, Study::Pairs, Study::Stress];
}

/// A style: a file, or an extreme one made for the stress study.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum StyleSource {
    /// An image file.
    File(PathBuf),
    /// Uniform random RGB noise (no structure at any scale).
    Noise,
    /// A black-and-white checkerboard of 16-pixel squares (extreme contrast and edges).
    Checker,
    /// One flat grey (no variance at all: colour matching collapses the scene's colours).
    Flat,
}

impl StyleSource {
    /// A short name for tables and file names.
    pub fn name(&self) -> String {
        match self {
            StyleSource::File(p) => p.file_stem().map_or("style".into(), |s| s.to_string_lossy().into_owned()),
            StyleSource::Noise => "noise".into(),
            StyleSource::Checker => "checker".into(),
            StyleSource::Flat => "flat".into(),
        }
    }

    /// The image.
    pub fn image(&self) -> anyhow::Result<StyleImage> {
        let (w, h) = (256usize, 256usize);
        let generated = |f: &dyn Fn(usize, usize, usize) -> u8| StyleImage {
            width: w,
            height: h,
            rgb: (0..w * h * 3).map(|i| f(i / 3 % w, i / 3 / w, i % 3)).collect(),
        };
        Ok(match self {
            StyleSource::File(p) => StyleImage::open(p).map_err(anyhow::Error::msg)?,
            StyleSource::Noise => {
                let mut state = 0x9e37_79b9_7f4a_7c15u64;
                let bytes: Vec<u8> = (0..w * h * 3)
                    .map(|_| {
                        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                        (state >> 56) as u8
                    })
                    .collect();
                StyleImage { width: w, height: h, rgb: bytes }
            }
            StyleSource::Checker => generated(&|x, y, _| if (x / 16 + y / 16) % 2 == 0 { 0 } else { 255 }),
            StyleSource::Flat => generated(&|_, _, _| 128),
        })
    }
}

/// The sizes of a grid (full or `--quick`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Sizes {
    /// Working resolution of every study but `resolution` (longer side, px).
    pub resolution: u32,
    /// Evaluation resolution (longer side, px).
    pub eval_resolution: u32,
    /// Orbit views to optimise from.
    pub views: usize,
    /// Steps per cycle (N_c + N_g), the paper's 100 scaled down so short budgets still alternate.
    pub steps_per_cycle: u32,
    /// Budget of the scene × style pairs.
    pub pair_budget: u32,
    /// Budget of the mode curves of the first curve style (measured at every doubling from one cycle).
    pub curve_budget: u32,
    /// Budget of the ratio, λ_GC, resolution and stress rows.
    pub ablation_budget: u32,
    /// Budget of the long stress run.
    pub long_budget: u32,
    /// Working resolutions of the resolution study.
    pub resolutions: Vec<u32>,
    /// Scene files (relative to the shared folder).
    pub scenes: Vec<String>,
    /// Style files (relative to the shared folder).
    pub styles: Vec<String>,
    /// Styles of the mode curves and ablations.
    pub curve_styles: Vec<String>,
    /// Budget of each arm of the focus study.
    #[serde(default)]
    pub focus_budget: u32,
    /// Budget of the collapse study's runs (steps per cycle: the default 100).
    #[serde(default)]
    pub collapse_budget: u32,
    /// Working resolution of the collapse study (the issue saw the collapse at 256 px).
    #[serde(default)]
    pub collapse_resolution: u32,
    /// Render the evaluation ring over each style's mean colour instead of
    /// black ([`gast_core::eval::EvalOptions::over_style_colour`]).
    #[serde(default)]
    pub eval_over_style_colour: bool,
    /// Which runs of the collapse study to make ([`COLLAPSE_ARMS`]; all by default).
    #[serde(default = "all_collapse_arms")]
    pub collapse_arms: Vec<String>,
    /// Run the collapse study's "object focus" arm on every pair, not only
    /// on the first scene × block2.
    #[serde(default)]
    pub collapse_object_on_every_pair: bool,
    /// Run the collapse study's [`COLLAPSE_CONTENT`] arm on every pair.
    #[serde(default)]
    pub collapse_content_on_every_pair: bool,
    /// Also run the focus study's two halves apart on every pair: the fitted
    /// views with the paper's whole-frame losses, and the plain orbit with
    /// the masked losses (which half buys what).
    #[serde(default)]
    pub focus_halves: bool,
    /// The focus study's object arm as a patch of the frame arm's settings
    /// (a JSON object of preset keys, [`StyleConfig::patched`]), over object
    /// focus on fitted views; e.g. `{"resolution": 512, "weights":
    /// {"feature_mean": 100}, "lr": {"color": 0.05}}`. Empty: object focus
    /// with the frame arm's settings (the object recipe follows from the
    /// defaults).
    #[serde(default)]
    pub focus_object: serde_json::Value,
    /// Steps of each arm of the defaults study (cycles of [`DEFAULTS_CYCLE`]).
    #[serde(default = "defaults_budget")]
    pub defaults_budget: u32,
    /// Working resolution of both arms of the defaults study.
    #[serde(default = "defaults_resolution")]
    pub defaults_resolution: u32,
    /// Seconds of CPU time each arm of the defaults study is planned for, in
    /// place of `defaults_budget` and `defaults_resolution`: each arm then
    /// runs what `gast stylize` plans with no `--resolution` or `--cycles`
    /// (the scene's span in its views, the arm's focus, [`gast_core::session::plan::auto_plan`];
    /// 600 is its default run), so both arms get the same wait.
    #[serde(default)]
    pub defaults_plan_s: Option<f64>,
    /// The defaults study's candidate arm as a patch of the shipped defaults
    /// (a JSON object of preset keys, [`StyleConfig::patched`]): a recipe
    /// tried against `--preset paper` before it ships, e.g. `{"weights":
    /// {"palette": 100}}`. Empty: the shipped defaults.
    #[serde(default)]
    pub defaults_patch: serde_json::Value,
}

fn defaults_budget() -> u32 {
    200
}

/// 192 px, the object arm's resolution in the focus study that chose the
/// recipe. At 96 px (the first run, `docs/studies/defaults.md`) the object
/// spans too few relu3 positions and defaults beat paper on 4 of 9 styles on
/// guitar; at 192 px on 8 of 9. The 57 trials take about 90 min on two cores.
fn defaults_resolution() -> u32 {
    192
}

/// The collapse study's runs: the decoupled default on every pair; the others
/// on the first scene × block2 (object focus and λ_cont 0.1 on every pair when asked).
pub const COLLAPSE_ARMS: [&str; 7] = [
    "decoupled",
    "object focus",
    "colour floor",
    "lr colour 1e-3",
    "lr colour 1e-4",
    "lr means 1e-5",
    COLLAPSE_CONTENT,
];

/// The collapse study's arm with λ_cont = 0.1, a hundred times the
/// reference's: the content loss (relu3 features of the colour-matched
/// render) is the term that holds the object's appearance, and at 1e-3 it is
/// too weak to stop the moving means from bringing dark Gaussians forward.
pub const COLLAPSE_CONTENT: &str = "content 0.1";

fn all_collapse_arms() -> Vec<String> {
    COLLAPSE_ARMS.iter().map(|s| s.to_string()).collect()
}

/// A settings file's JSON object laid over `full`: its keys replace full's,
/// a key full does not have is an error naming the known ones.
pub fn merged_from_file<T: Serialize + serde::de::DeserializeOwned>(
    path: &std::path::Path,
    full: &T,
    what: &str,
) -> anyhow::Result<T> {
    use anyhow::Context as _;
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read the {what}", path.display()))?;
    let mut value = serde_json::to_value(full).with_context(|| format!("the full {what} as JSON"))?;
    let given: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: expected a JSON object of {what}", path.display()))?;
    let (Some(base), Some(given)) = (value.as_object_mut(), given.as_object()) else {
        anyhow::bail!("{}: expected a JSON object of {what}, found {given}", path.display());
    };
    for (k, v) in given {
        if !base.contains_key(k) {
            anyhow::bail!("{}: unknown key {k:?} of the {what} (known: {})", path.display(), known_keys(base));
        }
        base.insert(k.clone(), v.clone());
    }
    serde_json::from_value(value).with_context(|| format!("{}: not valid {what}", path.display()))
}

const ALL_STYLES: [&str; 9] =
    ["block2", "fire", "galaxy", "hydrangea", "mosaic", "particle", "starry", "stone", "wave"];

impl Sizes {
    /// The full grid: about half an hour on two cores.
    pub fn full() -> Self {
        Self {
            resolution: 128,
            eval_resolution: 192,
            views: 36,
            steps_per_cycle: 20,
            pair_budget: 40,
            curve_budget: 160,
            ablation_budget: 80,
            long_budget: 240,
            resolutions: vec![64, 128, 192],
            scenes: vec![
                "data/scenes/guitar.compressed.ply".into(),
                "data/scenes/biker.compressed.ply".into(),
                "data/scenes/playbot-sog".into(),
            ],
            styles: ALL_STYLES.iter().map(|s| format!("data/styles/{s}.jpg")).collect(),
            curve_styles: vec!["data/styles/wave.jpg".into(), "data/styles/block2.jpg".into()],
            focus_budget: 200,
            collapse_budget: 1000,
            collapse_resolution: 256,
            eval_over_style_colour: false,
            collapse_arms: all_collapse_arms(),
            collapse_object_on_every_pair: false,
            collapse_content_on_every_pair: false,
            focus_halves: false,
            focus_object: serde_json::Value::Null,
            defaults_budget: defaults_budget(),
            defaults_resolution: defaults_resolution(),
            defaults_plan_s: None,
            defaults_patch: serde_json::Value::Null,
        }
    }

    /// Sizes from a JSON file with the fields of this struct (as `results.json`
    /// records them under `sizes`), e.g. one scene and three styles to run a
    /// study on a subset; missing fields take the full grid's values.
    pub fn from_file(path: &std::path::Path) -> anyhow::Result<Self> {
        let sizes: Self = merged_from_file(path, &Self::full(), "grid sizes")?;
        if let Err(e) = StyleConfig::default().patched(&sizes.focus_object) {
            anyhow::bail!("{}: focus_object: {e}", path.display());
        }
        if let Err(e) = StyleConfig::default().patched(&sizes.defaults_patch) {
            anyhow::bail!("{}: defaults_patch: {e}", path.display());
        }
        if let Some(bad) = sizes.collapse_arms.iter().find(|a| !COLLAPSE_ARMS.contains(&a.as_str())) {
            anyhow::bail!("{}: unknown collapse arm {bad:?} (known: {})", path.display(), COLLAPSE_ARMS.join(", "));
        }
        Ok(sizes)
    }

    /// The `--quick` grid: the guitar, two styles, small images, a few minutes.
    pub fn quick() -> Self {
        Self {
            resolution: 64,
            eval_resolution: 96,
            views: 12,
            steps_per_cycle: 10,
            pair_budget: 10,
            curve_budget: 20,
            ablation_budget: 10,
            long_budget: 40,
            resolutions: vec![48, 64],
            scenes: vec!["data/scenes/guitar.compressed.ply".into()],
            styles: vec!["data/styles/wave.jpg".into(), "data/styles/block2.jpg".into()],
            curve_styles: vec!["data/styles/wave.jpg".into()],
            focus_budget: 10,
            collapse_budget: 100,
            collapse_resolution: 64,
            eval_over_style_colour: false,
            collapse_arms: all_collapse_arms(),
            collapse_object_on_every_pair: false,
            collapse_content_on_every_pair: false,
            focus_halves: false,
            focus_object: serde_json::Value::Null,
            defaults_budget: 100,
            defaults_resolution: 64,
            defaults_plan_s: None,
            defaults_patch: serde_json::Value::Null,
        }
    }
}

fn known_keys(m: &serde_json::Map<String, serde_json::Value>) -> String {
    m.keys().cloned().collect::<Vec<_>>().join(", ")
}

/// One run of the grid.
#[derive(Clone, Debug)]
pub struct TrialSpec {
    /// Unique, file-name-safe id.
    pub id: String,
    /// Index into the scenes.
    pub scene: usize,
    /// The style.
    pub style: StyleSource,
    /// The run's parameters (its budget is the largest any row asks).
    pub config: StyleConfig,
    /// Multiplier applied to every default learning rate (stress rows).
    pub lr_scale: f32,
    /// Steps to measure at (0 is the colour-matched input).
    pub checkpoints: Vec<u32>,
    /// How the optimisation views frame the scene.
    pub framing: crate::views::Framing,
    /// Whether the evaluation ring is fitted to the object ([`gast_core::eval::EvalOptions::fit_to_object`]).
    pub eval_on_object: bool,
}

/// One row of a study: a trial read at a step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Row {
    /// The study.
    pub study: Study,
    /// The row's label in the study's table.
    pub label: String,
    /// The trial's id.
    pub trial: String,
    /// The step it is read at (its budget).
    pub step: u32,
}

/// The label of the decoupled run with another view order (seed 1).
pub const SEED_LABEL: &str = "decoupled, seed 1";

/// The paper's name of a mode.
pub fn mode_label(mode: Mode) -> &'static str {
    match mode {
        Mode::Decoupled => "decoupled",
        Mode::Joint => "joint",
        Mode::ColorOnly => "colour-only",
        Mode::GeometryOnly => "geometry-only",
    }
}

/// One trial as reported.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Record {
    /// The trial's id.
    pub id: String,
    /// Scene file, relative to the shared folder.
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Gaussians optimised (seen by an optimisation camera).
    pub optimised: usize,
    /// Style name.
    pub style: String,
    /// Mode.
    pub mode: String,
    /// Geometry share of a cycle.
    pub ratio_geo: f32,
    /// λ_GC.
    pub lambda_gc: f32,
    /// Learning-rate multiplier.
    pub lr_scale: f32,
    /// Working resolution, px.
    pub resolution: u32,
    /// Steps per cycle.
    pub steps_per_cycle: u32,
    /// Scheduled steps.
    pub budget: u32,
    /// Steps run.
    pub steps: u32,
    /// Preparation seconds.
    pub prepare_s: f64,
    /// Measuring seconds (not in any checkpoint's time).
    pub measure_s: f64,
    /// No detector fired.
    pub stable: bool,
    /// What the detectors found.
    pub issues: Vec<Degeneration>,
    /// Measures along the way.
    pub checkpoints: Vec<Checkpoint>,
    /// Sample sheet of the final scene (input, result, their depths).
    #[serde(skip)]
    pub sample: (u32, u32, Vec<f32>),
    /// The journal this trial was taken from (`--from`), when another run ran it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from: Option<String>,
}

impl Record {
    /// The record of `spec`'s run.
    pub fn new(spec: &TrialSpec, scene: &str, gaussians: usize, o: TrialOutcome) -> Self {
        let sample = o.evaluator.sample_sheet(&o.result, 0);
        Self {
            id: spec.id.clone(),
            scene: scene.to_string(),
            gaussians,
            optimised: o.optimised,
            style: spec.style.name(),
            mode: mode_label(spec.config.mode).into(),
            ratio_geo: spec.config.ratio_geo,
            lambda_gc: spec.config.weights.gcfm,
            lr_scale: spec.lr_scale,
            resolution: spec.config.resolution,
            steps_per_cycle: spec.config.steps_per_cycle,
            budget: spec.config.schedule().total_steps(),
            steps: o.steps,
            prepare_s: o.prepare_s,
            measure_s: o.measure_s,
            stable: o.stability.is_healthy(),
            issues: o.stability.issues,
            checkpoints: o.checkpoints,
            sample,
            from: None,
        }
    }

    /// Seconds the trial took: preparing and optimising (its last
    /// checkpoint's time), then measuring.
    pub fn seconds(&self) -> f64 {
        self.checkpoints.last().map_or(self.prepare_s, |c| c.seconds) + self.measure_s
    }

    /// The checkpoint at `step`, or the last one when the run stopped earlier.
    pub fn at(&self, step: u32) -> Option<&Checkpoint> {
        self.checkpoints.iter().find(|c| c.step == step).or_else(|| self.checkpoints.last().filter(|c| c.step < step))
    }
}

/// What `results.json` holds: enough to rewrite every table, chart and the index.
#[derive(Debug, Serialize, Deserialize)]
pub struct RunSummary {
    /// The command line that ran the grid.
    #[serde(default)]
    pub command: String,
    /// Worker threads.
    #[serde(default)]
    pub threads: usize,
    /// The grid's sizes.
    pub sizes: Sizes,
    /// Wall-clock seconds of the whole run.
    pub wall_s: f64,
    /// Every study's rows.
    pub rows: Vec<Row>,
    /// Every trial.
    pub trials: Vec<Record>,
}

/// A record of trial `id` on guitar × `style`: `before` at step 0, `after` at its budget of 200.
#[cfg(test)]
pub(crate) fn test_record(
    id: &str,
    style: &str,
    before: gast_core::eval::Measures,
    after: gast_core::eval::Measures,
) -> Record {
    let at = |step, measures| gast_core::eval::Checkpoint { step, seconds: 0.0, measures };
    Record {
        id: id.into(),
        scene: "data/scenes/guitar.compressed.ply".into(),
        gaussians: 10,
        optimised: 10,
        style: style.into(),
        mode: "decoupled".into(),
        ratio_geo: 0.9,
        lambda_gc: 2.0,
        lr_scale: 1.0,
        resolution: 128,
        steps_per_cycle: 20,
        budget: 200,
        steps: 200,
        prepare_s: 0.0,
        measure_s: 0.0,
        stable: true,
        issues: Vec::new(),
        checkpoints: vec![at(0, before), at(200, after)],
        sample: (0, 0, Vec::new()),
        from: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_committed_settings_file_is_valid_sizes() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/studies");
        let json_in = |dir: &std::path::Path| -> Vec<std::path::PathBuf> {
            std::fs::read_dir(dir)
                .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect::<Vec<_>>())
                .unwrap_or_default()
                .into_iter()
                .filter(|p| p.extension().is_some_and(|x| x == "json"))
                .collect()
        };
        let mut files = json_in(&dir);
        files.extend(json_in(&dir.join("settings")));
        assert!(!files.is_empty(), "no settings file under {}", dir.display());
        for f in files {
            // The geometry study's own (`--studies geometry --sizes`) are named after it.
            if f.file_name().is_some_and(|n| n.to_string_lossy().starts_with("geometry_")) {
                let sizes = geometry::GeometrySizes::from_file(&f).unwrap_or_else(|e| panic!("{e:#}"));
                assert!(!sizes.arms.is_empty() && !sizes.styles.is_empty(), "{}", f.display());
                continue;
            }
            let sizes = Sizes::from_file(&f).unwrap_or_else(|e| panic!("{e:#}"));
            assert!(!sizes.scenes.is_empty() && !sizes.styles.is_empty(), "{}", f.display());
        }
    }

    #[test]
    fn every_study_row_names_a_committed_settings_file() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let pages = std::fs::read_dir(root.join("docs/studies")).expect("docs/studies");
        let mut named = 0;
        for page in pages.filter_map(|e| e.ok().map(|e| e.path())) {
            let is_page = page.extension().is_some_and(|x| x == "md");
            if !is_page || page.file_name().is_some_and(|n| n == "README.md") {
                continue;
            }
            let text = std::fs::read_to_string(&page).expect("page");
            for (at, _) in text.match_indices("--sizes ") {
                let file: String = text[at + 8..].chars().take_while(|c| !c.is_whitespace() && *c != '`').collect();
                assert!(root.join(&file).is_file(), "{}: `--sizes {file}` names no committed file", page.display());
                named += 1;
            }
        }
        assert!(named > 0, "no study row names a settings file");
    }

    #[test]
    fn sizes_from_a_file_override_the_full_grid_and_refuse_unknown_fields() {
        let dir = std::env::temp_dir().join(format!("gast-sizes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("sizes.json");
        std::fs::write(&path, r#"{"scenes": ["data/scenes/guitar.compressed.ply"], "focus_budget": 120}"#)
            .expect("write");
        let s = Sizes::from_file(&path).expect("sizes");
        assert_eq!(s.scenes, vec!["data/scenes/guitar.compressed.ply".to_string()]);
        assert_eq!(s.focus_budget, 120);
        assert_eq!(s.styles.len(), 9, "missing fields keep the full grid's");
        assert_eq!(s.resolution, Sizes::full().resolution);

        std::fs::write(&path, r#"{"focus_budgets": 120}"#).expect("write");
        let e = format!("{:#}", Sizes::from_file(&path).expect_err("unknown field"));
        assert!(e.contains("sizes.json") && e.contains("focus_budgets") && e.contains("focus_budget"), "{e}");
        std::fs::write(&path, r#"{"focus_budget": "many"}"#).expect("write");
        let e = format!("{:#}", Sizes::from_file(&path).expect_err("wrong type"));
        assert!(e.contains("sizes.json") && e.contains("not valid grid sizes"), "{e}");
        std::fs::write(&path, r#"{"collapse_arms": ["decoupled", "lr means 1e-6"]}"#).expect("write");
        let e = format!("{:#}", Sizes::from_file(&path).expect_err("unknown arm"));
        assert!(e.contains("sizes.json") && e.contains("lr means 1e-6") && e.contains("lr means 1e-5"), "{e}");
        std::fs::write(&path, "[1, 2]").expect("write");
        let e = format!("{:#}", Sizes::from_file(&path).expect_err("not an object"));
        assert!(e.contains("expected a JSON object"), "{e}");
        let e = format!("{:#}", Sizes::from_file(&dir.join("missing.json")).expect_err("missing"));
        assert!(e.contains("missing.json") && e.contains("cannot read"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
