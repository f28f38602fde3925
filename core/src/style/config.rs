//! One configuration struct for a stylization run.
//!
//! The same struct is filled from command-line flags, loaded from and saved to
//! preset files (JSON), and edited by the studio's sliders; every field has the
//! default of ALGORITHM.md, so a partial preset file is valid.

use serde::{Deserialize, Serialize};

use super::adam::AdamConfig;
pub use super::feature_mean::MeanSteps;
use super::focus::Focus;
pub use super::matching::{MatchMethod, MatchingConfig};
use super::schedule::{Mode, Phase, Schedule};
pub use super::terms::LossWeights;
use super::terms::Term;
pub use crate::vision::ConvAlgo;
pub use crate::vision::style_depth::{DepthPolarity, DepthProvider};

/// The lowest DC colour coefficient [`StyleConfig::color_floor`] allows: the
/// channel's base colour `0.5 + C0·f_dc` is then at least 0.
pub const DC_FLOOR: f32 = -0.5 / crate::scene::SH_C0;

/// Learning rates per parameter group.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LearningRates {
    /// SH DC coefficients (colour phase).
    pub color: f32,
    /// Means, as a factor of the scene extent (lr = factor · extent).
    pub means_per_extent: f32,
    /// Log-scales.
    pub scales: f32,
    /// Quaternions.
    pub quats: f32,
    /// Opacity logits.
    pub opacity: f32,
}

impl Default for LearningRates {
    fn default() -> Self {
        Self { color: 0.01, means_per_extent: 1e-4, scales: 0.005, quats: 0.001, opacity: 0.05 }
    }
}

/// Everything that defines one stylization run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct StyleConfig {
    /// Number of cycles `K`.
    pub cycles: u32,
    /// Steps per cycle `N_c + N_g`.
    pub steps_per_cycle: u32,
    /// Geometry share of each cycle, `N_g / (N_c + N_g)`.
    pub ratio_geo: f32,
    /// Decoupled (default) or an ablation.
    pub mode: Mode,
    /// Loss weights.
    pub weights: LossWeights,
    /// Learning rates.
    pub lr: LearningRates,
    /// Adam hyper-parameters.
    pub adam: AdamConfig,
    /// Texture scale: the style image's height in pixels (128 / 256 / 512 = 0.5× / 1× / 2×).
    pub texture_scale: u32,
    /// Working resolution: the longer side of the optimisation renders, in pixels.
    pub resolution: u32,
    /// Background colour of the renders.
    pub background: [f32; 3],
    /// Style depth polarity.
    pub depth_polarity: DepthPolarity,
    /// Where the style's depth comes from: `learned`, `image` or `heuristic`.
    pub depth_provider: DepthProvider,
    /// Seed of the view shuffling.
    pub seed: u64,
    /// How VGG's convolutions are computed: both exact up to rounding; Winograd
    /// (the default) does 4× fewer multiplies, im2col is the reference.
    pub conv: ConvAlgo,
    /// How the GCFM matches are searched (exact by default) and how long they are kept.
    pub matching: MatchingConfig,
    /// Which pixels GCFM, content and TV average over (the whole frame, the
    /// object, or the object when it covers less than half of the views).
    pub focus: Focus,
    /// After each colour step, raise every Gaussian's DC colour so that no
    /// channel renders below 0 (`0.5 + C0·f_dc ≥ 0`), out of the clamp's dead
    /// zone where no gradient reaches it again. Off in the reference.
    pub color_floor: bool,
    /// With object focus, run VGG only on the part of each layer the covered
    /// feature positions depend on, not the whole frame (`style::window`,
    /// `vision::vgg_cone`): the same losses up to rounding. On by default;
    /// off to measure what it buys.
    pub vgg_window: bool,
    /// Which steps λ_mean acts on: every step (the default) or the colour steps.
    pub feature_mean_steps: MeanSteps,
    /// The form of the parameter regularisers λ_α, λ_s, λ_r: the paper's norm
    /// over all Gaussians (the default) or a per-Gaussian mean square.
    pub param_regulariser: ParamRegulariser,
    /// Where the losses focus on the object (`focus object`, or `auto` on an
    /// object), switch on the assignment terms at the weights that won the
    /// focus study ([`OBJECT_RECIPE_ASSIGN_COS`], [`OBJECT_RECIPE_ASSIGN`];
    /// `docs/studies/focus.md`: the object beat the frame on 9, 8 and 9 of the
    /// nine styles on guitar, biker and playbot) when both are 0, and the
    /// palette hold at [`OBJECT_RECIPE_PALETTE`] when λ_pal is 0
    /// (`docs/studies/defaults.md`: without it guitar × stone darkens into a
    /// colour collapse at the default budget). On by default; off in the
    /// `paper` preset. See [`StyleConfig::resolved`].
    pub object_recipe: bool,
    /// Where the losses take the whole frame (`focus frame`, or `auto` on a
    /// full-frame scene), switch on the depth's sliced Wasserstein term at
    /// [`FRAME_RECIPE_SLICED_DEPTH`] when λ_swd is 0 (`docs/geometry.md`: on
    /// fern it tiles the depth with the style's blocks where GCFM alone
    /// leaves it smooth; on objects it adds nothing yet). On by default; off
    /// in the `paper` preset. See [`StyleConfig::resolved`].
    pub frame_recipe: bool,
    /// Carry each phase's gradients on the other phase's parameters over to
    /// that phase's next step, as the reference does: its colour steps'
    /// `backward()` also fills the geometry's gradients (of GCFM on RGB and
    /// depth, content and TV, with no depth or parameter regulariser), which
    /// sum over the `N_c` colour steps and are applied on the cycle's first
    /// geometry step; the geometry steps' colour gradients likewise on the
    /// next colour step. Off by default; `docs/geometry.md` measures it.
    pub phase_leak: bool,
    /// Before optimising, split every Gaussian whose standard deviation spans
    /// more than this many pixels in some view at the working resolution
    /// (`session::split`), at most up to [`SPLIT_MAX_FACTOR`] times the
    /// scene's count: room for the style's relief on large smooth surfaces.
    /// 0 (the default) keeps the scene as it is.
    pub split_px: f32,
    /// Above 0: both depth maps (the render's, min-max normalised, and the
    /// style's) minus their blur of this radius in pixels, centred on 0.5,
    /// before VGG (`style::relief`): relief compared with
    /// relief where the layout would take the render's 0–1 range. 0 (the
    /// default, the paper): the min-max normalised depth. Both engines.
    pub depth_relief_px: u32,
    /// Most rows of one least-cost block of the assignment terms' pairing
    /// (`style::assignment`): a step's up to 512 drawn rows are dealt into
    /// interleaved blocks of at most this many, each paired one-to-one on
    /// its own (in parallel), since one assignment of `r` rows costs up to
    /// `r³` serial work. 256 (the default) splits only past 256 rows; 512
    /// pairs every step's rows in one assignment, as before 2026-11-30.
    pub assign_block: u32,
}

/// A setting the GPU engine does not compute yet ([`StyleConfig::cpu_only`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CpuOnly {
    /// Its short name (`λ_sw`, `the phase leak`).
    pub name: String,
    /// Its name with its value and what it is, for an error.
    pub detail: String,
    /// How to turn it off.
    pub off: &'static str,
}

/// The most Gaussians [`StyleConfig::split_px`] may make, as a multiple of the scene's.
pub const SPLIT_MAX_FACTOR: usize = 8;
/// Most steps a run may take (`cycles × steps_per_cycle`): 1,000 times the
/// default schedule, far below the 4.3 billion where the u32 step count
/// overflows.
pub const MAX_STEPS: u64 = 3_000_000;

/// The style's texture scales a run takes (its height in pixels, `texture_scale`).
pub const TEXTURE_SCALES: std::ops::RangeInclusive<u32> = 16..=4096;

/// The working resolutions a run takes (the views' longer side in pixels, `resolution`).
pub const RESOLUTIONS: std::ops::RangeInclusive<u32> = 16..=4096;

/// λ_swd of the frame recipe ([`StyleConfig::frame_recipe`]).
pub const FRAME_RECIPE_SLICED_DEPTH: f32 = 1.0;

/// λ_asc of the object recipe ([`StyleConfig::object_recipe`]).
pub const OBJECT_RECIPE_ASSIGN_COS: f32 = 10.0;
/// λ_as of the object recipe ([`StyleConfig::object_recipe`]).
pub const OBJECT_RECIPE_ASSIGN: f32 = 0.015;
/// λ_pal of the object recipe ([`StyleConfig::object_recipe`]).
pub const OBJECT_RECIPE_PALETTE: f32 = 100.0;

/// The form of the geometry phase's parameter regularisers
/// ([`crate::style::regularizers`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ParamRegulariser {
    /// `λ‖x − x^c‖₂` over all Gaussians (the paper and the reference). Its
    /// gradient has length λ whatever the deviation, so no parameter moves
    /// unless the loss's gradient over all Gaussians is longer than λ (a group
    /// lasso): on fern it holds opacity, scale and rotation at the
    /// colour-matched values.
    #[default]
    Norm,
    /// `λ·mean_i ‖x_i − x_i^c‖²` (per Gaussian, squared): a tether whose pull
    /// grows with each Gaussian's own deviation, so small changes cost little
    /// and runaway ones a lot, at any number of Gaussians. Both engines.
    MeanSquare,
}

impl std::str::FromStr for ParamRegulariser {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "norm" => Ok(Self::Norm),
            "mean-square" => Ok(Self::MeanSquare),
            _ => Err(format!("expected norm or mean-square, found {s:?}")),
        }
    }
}

impl Default for StyleConfig {
    fn default() -> Self {
        Self {
            cycles: 30,
            steps_per_cycle: 100,
            ratio_geo: 0.9,
            mode: Mode::Decoupled,
            weights: LossWeights::default(),
            lr: LearningRates::default(),
            adam: AdamConfig::default(),
            texture_scale: 256,
            resolution: 256,
            background: [0.0; 3],
            depth_polarity: DepthPolarity::NearBright,
            depth_provider: DepthProvider::Learned,
            seed: 0,
            conv: ConvAlgo::Winograd,
            matching: MatchingConfig::default(),
            focus: Focus::default(),
            color_floor: false,
            vgg_window: true,
            feature_mean_steps: MeanSteps::default(),
            param_regulariser: ParamRegulariser::default(),
            object_recipe: true,
            frame_recipe: true,
            phase_leak: false,
            split_px: 0.0,
            depth_relief_px: 0,
            assign_block: super::assignment::ASSIGN_BLOCK as u32,
        }
    }
}

impl StyleConfig {
    /// The reference's behaviour (`--preset paper`): whole-frame losses, the
    /// style depth near dark as the reference inverts it, the norm
    /// regularisers, no object or frame recipe; every other value is the default.
    pub fn paper() -> Self {
        Self {
            focus: super::focus::Focus::Frame,
            depth_polarity: DepthPolarity::NearDark,
            param_regulariser: ParamRegulariser::Norm,
            object_recipe: false,
            frame_recipe: false,
            ..Self::default()
        }
    }

    /// The configuration a run with views of mean coverage `coverage` uses:
    /// with [`StyleConfig::object_recipe`] on and losses on the object, both
    /// assignment weights take the recipe's values when both are 0, and λ_pal
    /// takes the recipe's when it is 0; with
    /// [`StyleConfig::frame_recipe`] on, losses on the whole frame and λ_swd
    /// 0, λ_swd takes the recipe's.
    pub fn resolved(&self, coverage: f32) -> Self {
        let mut c = self.clone();
        let object = c.focus.is_object(coverage);
        let w = &mut c.weights;
        if c.object_recipe && object && w.assignment == 0.0 && w.assignment_cosine == 0.0 {
            w.assignment = OBJECT_RECIPE_ASSIGN;
            w.assignment_cosine = OBJECT_RECIPE_ASSIGN_COS;
        }
        if c.object_recipe && object && w.palette == 0.0 {
            w.palette = OBJECT_RECIPE_PALETTE;
        }
        if c.frame_recipe && !object && w.sliced_depth == 0.0 {
            w.sliced_depth = FRAME_RECIPE_SLICED_DEPTH;
        }
        c
    }

    /// The loss weights a run at `coverage` uses that differ from those set,
    /// because a recipe lifts them ([`StyleConfig::resolved`]): (the term,
    /// the value the run uses), in the order of the terms. The studio shows
    /// them under their sliders and `gast stylize` prints them.
    pub fn recipe_lifts(&self, coverage: f32) -> Vec<(&'static Term, f32)> {
        self.resolved(coverage).weights.differing(&self.weights).collect()
    }

    /// What this configuration asks that the GPU engine does not compute yet
    /// (a term whose row says `gpu: false`; none today): the session's
    /// GPU refusal and `gast stylize --device auto`'s choice of the CPU read it.
    pub fn cpu_only(&self) -> Vec<CpuOnly> {
        (self.weights.cpu_only())
            .map(|(t, v)| CpuOnly {
                name: t.symbol.into(),
                detail: format!("{} = {v} ({})", t.symbol, t.name()),
                off: "set it to 0",
            })
            .collect()
    }

    /// Whether the phases leak gradients into each other: the phase leak in
    /// decoupled mode (the ablations have no phases to leak between).
    pub fn leaks_between_phases(&self) -> bool {
        self.phase_leak && self.mode == Mode::Decoupled
    }

    /// The step plan this configuration implies.
    pub fn schedule(&self) -> Schedule {
        Schedule::from_ratio(self.cycles, self.steps_per_cycle, self.ratio_geo, self.mode)
    }

    /// The loss weights of a step in `phase`: λ_mean is 0 on the steps
    /// [`StyleConfig::feature_mean_steps`] leaves out.
    pub fn weights_for(&self, phase: Phase) -> LossWeights {
        let mut w = self.weights;
        if !self.feature_mean_steps.acts_in(phase) {
            w.feature_mean = 0.0;
        }
        w
    }

    /// Reads a preset: a JSON object of the settings' keys, the missing ones
    /// taking their defaults; an unknown key (a typo such as `"weights":
    /// {"gcmf": 3}`) or anything but an object is refused
    /// ([`crate::settings::from_json`]).
    pub fn from_json(text: &str) -> Result<Self, serde_json::Error> {
        crate::settings::from_json(text)
    }

    /// This configuration with a partial one merged over it: `patch` is a
    /// JSON object of the preset's keys (nested objects merge key by key,
    /// e.g. `{"focus": "object", "weights": {"assignment_cosine": 10}}`).
    /// A key the preset does not have is refused, naming it.
    pub fn patched(&self, patch: &serde_json::Value) -> Result<Self, String> {
        crate::settings::patched(self, patch)
    }

    /// The preset as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Problems that make the configuration unusable, as sentences (empty when fine).
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.steps_per_cycle == 0 || self.cycles == 0 {
            out.push(format!(
                "cycles and steps per cycle must be positive (found {} and {})",
                self.cycles, self.steps_per_cycle
            ));
        }
        let steps = u64::from(self.cycles) * u64::from(self.steps_per_cycle);
        if steps > MAX_STEPS {
            out.push(format!(
                "cycles × steps per cycle must be at most {MAX_STEPS} steps, found {} × {} = {steps}",
                self.cycles, self.steps_per_cycle
            ));
        }
        if !(0.0..=1.0).contains(&self.ratio_geo) {
            out.push(format!("ratio_geo must lie in [0, 1], found {}", self.ratio_geo));
        }
        if !TEXTURE_SCALES.contains(&self.texture_scale) {
            out.push(format!("texture_scale must lie in {TEXTURE_SCALES:?} pixels, found {}", self.texture_scale));
        }
        if !RESOLUTIONS.contains(&self.resolution) {
            out.push(format!("resolution must lie in {RESOLUTIONS:?} pixels, found {}", self.resolution));
        }
        let mc = self.matching;
        if mc.dims == 0 || mc.candidates == 0 || mc.reuse == 0 {
            out.push(format!(
                "matching dims, candidates and reuse must be positive (found {}, {} and {})",
                mc.dims, mc.candidates, mc.reuse
            ));
        }
        if !(self.split_px == 0.0 || (1.0..=4096.0).contains(&self.split_px)) {
            out.push(format!("split_px must be 0 (off) or lie in 1..=4096 pixels, found {}", self.split_px));
        }
        if !(16..=super::assignment::ASSIGN_MAX as u32).contains(&self.assign_block) {
            out.push(format!(
                "assign_block must lie in 16..={} rows, found {}",
                super::assignment::ASSIGN_MAX,
                self.assign_block
            ));
        }
        if self.depth_relief_px > 1024 {
            out.push(format!("depth_relief_px must be 0 (off) or at most 1024 pixels, found {}", self.depth_relief_px));
        }
        let lr = self.lr;
        let weights = self.weights.terms().map(|(t, v)| (format!("weights.{}", t.key), v));
        for (name, v) in weights.into_iter().chain([
            ("lr.color".to_string(), lr.color),
            ("lr.means_per_extent".to_string(), lr.means_per_extent),
            ("lr.scales".to_string(), lr.scales),
            ("lr.quats".to_string(), lr.quats),
            ("lr.opacity".to_string(), lr.opacity),
        ]) {
            if !(v.is_finite() && v >= 0.0) {
                out.push(format!("{name} must be a finite non-negative number, found {v}"));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_patch_sets_only_what_it_names_and_refuses_unknown_keys() {
        let base = StyleConfig::default();
        let patch =
            serde_json::json!({"resolution": 512, "weights": {"assignment_cosine": 4.0}, "lr": {"color": 0.05}});
        let c = base.patched(&patch).expect("patch");
        assert_eq!((c.resolution, c.weights.assignment_cosine, c.lr.color), (512, 4.0, 0.05));
        assert_eq!(StyleConfig { resolution: base.resolution, ..c.clone() }.weights.gcfm, base.weights.gcfm);
        assert_eq!(c.lr.opacity, base.lr.opacity);
        assert_eq!(base.patched(&serde_json::json!({})).expect("empty"), base);
        assert_eq!(base.patched(&serde_json::Value::Null).expect("none"), base);
        let e = base.patched(&serde_json::json!({"weights": {"nope": 1}})).expect_err("unknown");
        assert!(e.contains("weights.nope"), "{e}");
        assert!(base.patched(&serde_json::json!({"resolution": "big"})).is_err());
        assert!(base.patched(&serde_json::json!([1])).is_err());
    }

    #[test]
    fn lambda_mean_acts_on_the_steps_asked_for() {
        let on = LossWeights { feature_mean: 7.0, ..LossWeights::default() };
        let every = StyleConfig { weights: on, ..StyleConfig::default() };
        assert_eq!(every.feature_mean_steps, MeanSteps::Every);
        for phase in [Phase::Color, Phase::Geometry, Phase::Joint] {
            assert_eq!(every.weights_for(phase), on);
        }
        let c = StyleConfig { feature_mean_steps: MeanSteps::Colour, ..every };
        assert_eq!(c.weights_for(Phase::Color), on);
        assert_eq!(c.weights_for(Phase::Joint), on);
        assert_eq!(c.weights_for(Phase::Geometry), LossWeights { feature_mean: 0.0, ..on });
        assert_eq!("every".parse::<MeanSteps>(), Ok(MeanSteps::Every));
        assert_eq!("colour".parse::<MeanSteps>(), Ok(MeanSteps::Colour));
        assert!("geometry".parse::<MeanSteps>().is_err_and(|e| e.contains("colour or every")));
        let preset = StyleConfig::from_json(r#"{"feature_mean_steps": "colour"}"#).expect("a preset");
        assert_eq!(preset.feature_mean_steps, MeanSteps::Colour);
    }

    #[test]
    fn every_setting_runs_on_both_engines_and_the_leak_needs_phases() {
        assert!(StyleConfig::default().cpu_only().is_empty());
        let mut c = StyleConfig { phase_leak: true, depth_relief_px: 8, ..StyleConfig::default() };
        c.weights.sliced = 2.0;
        c.weights.assignment_cosine = 10.0;
        assert!(c.cpu_only().is_empty(), "{:?}", c.cpu_only().into_iter().map(|x| x.name).collect::<Vec<_>>());
        assert!(c.leaks_between_phases());
        for mode in [Mode::Joint, Mode::ColorOnly, Mode::GeometryOnly] {
            assert!(
                !StyleConfig { mode, ..c.clone() }.leaks_between_phases(),
                "{mode:?} has no phases to leak between"
            );
        }
        assert!(
            StyleConfig { depth_relief_px: 5000, ..StyleConfig::default() }.problems()[0].contains("depth_relief_px")
        );
        for bad in [0, 15, 513] {
            let c = StyleConfig { assign_block: bad, ..StyleConfig::default() };
            assert!(c.problems()[0].contains("assign_block must lie in 16..=512 rows"), "{bad}");
        }
        let preset = StyleConfig::from_json(r#"{"assign_block": 512}"#).expect("a preset");
        assert!(preset.problems().is_empty() && preset.assign_block == 512);
    }

    #[test]
    fn the_recipe_lifts_name_each_lifted_weight_with_the_value_the_run_uses() {
        let c = StyleConfig::default();
        let symbols = |lifts: Vec<(&Term, f32)>| lifts.into_iter().map(|(t, v)| (t.symbol, v)).collect::<Vec<_>>();
        assert_eq!(
            symbols(c.recipe_lifts(0.2)),
            vec![("λ_pal", OBJECT_RECIPE_PALETTE), ("λ_as", OBJECT_RECIPE_ASSIGN), ("λ_asc", OBJECT_RECIPE_ASSIGN_COS)]
        );
        assert_eq!(symbols(c.recipe_lifts(0.9)), vec![("λ_swd", FRAME_RECIPE_SLICED_DEPTH)]);
        let mut hold = c.clone();
        hold.weights.palette = 7.0;
        assert_eq!(hold.recipe_lifts(0.2).len(), 2, "a weight the user set is not lifted");
        assert!(StyleConfig::paper().recipe_lifts(0.2).is_empty());
        assert!(StyleConfig::paper().recipe_lifts(0.9).is_empty());
    }

    #[test]
    fn each_recipe_applies_only_on_its_focus_and_only_where_its_terms_are_off() {
        use crate::style::focus::Focus;
        let c = StyleConfig::default();
        let on_object = c.resolved(0.2);
        assert_eq!((on_object.weights.assignment, on_object.weights.assignment_cosine), (0.015, 10.0));
        assert_eq!(on_object.weights.palette, OBJECT_RECIPE_PALETTE);
        assert_eq!(on_object.weights.sliced_depth, 0.0, "no frame recipe on an object");
        let on_frame = c.resolved(0.9);
        assert_eq!(on_frame.weights.sliced_depth, FRAME_RECIPE_SLICED_DEPTH);
        let mut want = c.clone();
        want.weights.sliced_depth = FRAME_RECIPE_SLICED_DEPTH;
        assert_eq!(on_frame, want, "a full frame gets λ_swd and nothing else");
        let frame = StyleConfig { focus: Focus::Frame, ..c.clone() };
        assert_eq!(frame.resolved(0.2).weights.assignment, 0.0, "frame focus on an object: no object recipe");
        assert_eq!(frame.resolved(0.2).weights.sliced_depth, FRAME_RECIPE_SLICED_DEPTH);
        let off = StyleConfig { object_recipe: false, frame_recipe: false, ..c.clone() };
        assert_eq!(off.resolved(0.2), off);
        assert_eq!(off.resolved(0.9), off);
        let mut chosen = c.clone();
        chosen.weights.assignment = 0.5;
        chosen.weights.palette = 7.0;
        chosen.weights.sliced_depth = 0.25;
        assert_eq!(chosen.resolved(0.2), chosen, "a weight the user set is kept");
        assert_eq!(chosen.resolved(0.9), chosen, "a weight the user set is kept");
        // The hold and the assignment pair fill apart: either set leaves the other to the recipe.
        let mut pair = c.clone();
        pair.weights.assignment = 0.5;
        assert_eq!(pair.resolved(0.2).weights.palette, OBJECT_RECIPE_PALETTE);
        assert_eq!(pair.resolved(0.2).weights.assignment_cosine, 0.0);
        let mut hold = c.clone();
        hold.weights.palette = 7.0;
        assert_eq!(hold.resolved(0.2).weights.palette, 7.0);
        assert_eq!(hold.resolved(0.2).weights.assignment_cosine, OBJECT_RECIPE_ASSIGN_COS);
        assert_eq!(hold.resolved(0.9).weights.palette, 7.0, "no hold added on a full frame");
        assert_eq!(c.resolved(0.9).weights.palette, 0.0, "no hold on a full frame");
        let paper = StyleConfig::paper();
        assert_eq!(paper.resolved(0.2), paper);
        assert_eq!(paper.resolved(0.9), paper);
        assert_eq!(
            (paper.focus, paper.depth_polarity, paper.object_recipe, paper.frame_recipe),
            (Focus::Frame, DepthPolarity::NearDark, false, false)
        );
        // Old presets (no key) get the recipes; the keys round-trip.
        let old = StyleConfig::from_json("{}").expect("a preset");
        assert!(old.object_recipe && old.frame_recipe);
        let back = StyleConfig::from_json(&paper.to_json()).expect("a preset");
        assert!(!back.object_recipe && !back.frame_recipe);
    }

    #[test]
    fn defaults_follow_the_algorithm() {
        let c = StyleConfig::default();
        let s = c.schedule();
        assert_eq!((s.cycles, s.color_steps, s.geometry_steps), (30, 10, 90));
        assert_eq!(c.weights.gcfm, 2.0);
        assert_eq!(c.weights.depth, 10.0);
        assert_eq!(c.lr.opacity, 0.05);
        assert!(c.problems().is_empty());
    }

    #[test]
    fn presets_round_trip_and_fill_defaults() {
        let c = StyleConfig {
            mode: Mode::Joint,
            weights: LossWeights { tv: 0.5, ..LossWeights::default() },
            ..StyleConfig::default()
        };
        assert_eq!(StyleConfig::from_json(&c.to_json()).expect("parse"), c);
        let partial = StyleConfig::from_json(r#"{"cycles": 3, "weights": {"gcfm": 1.5}}"#).expect("parse");
        assert_eq!(partial.cycles, 3);
        assert_eq!(partial.weights.gcfm, 1.5);
        assert_eq!(partial.weights.depth, 10.0);
        // A wrong value names its setting (serde's message alone names none).
        for (text, said) in [
            (r#"{"mode": "sideways"}"#, r#"not valid settings: "mode": unknown variant `sideways`"#),
            (
                r#"{"cycles": 3, "steps_per_cycle": "ten"}"#,
                r#""steps_per_cycle": invalid type: string "ten", expected u32"#,
            ),
            (r#"{"weights": {"gcfm": 1, "depth": [1]}}"#, r#""weights.depth": invalid type: sequence, expected f32"#),
            (r#"{"background": [0, 0]}"#, r#""background": invalid length 2"#),
        ] {
            let e = StyleConfig::from_json(text).expect_err(text).to_string();
            assert!(e.contains(said), "{text} → {e}");
        }
        let typo = StyleConfig::from_json(r#"{"weights": {"gcmf": 3}}"#).expect_err("a typo");
        assert!(typo.to_string().contains("unknown setting \"weights.gcmf\""), "{typo}");
        let array = StyleConfig::from_json("[1, 2]").expect_err("an array");
        assert!(array.to_string().contains("expected a JSON object of settings, found an array"), "{array}");
        let long = StyleConfig::from_json(r#"{"steps_per_cycle": 4000000000}"#).expect("a preset");
        assert_eq!(
            long.problems(),
            ["cycles × steps per cycle must be at most 3000000 steps, found 30 × 4000000000 = 120000000000"]
        );
        let bad = StyleConfig { ratio_geo: 2.0, ..StyleConfig::default() };
        assert_eq!(bad.problems().len(), 1);
    }
}
