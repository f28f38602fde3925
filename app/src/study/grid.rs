//! The grid of `gast bench quality`: the trials each study asks for and the
//! rows that read them. Rows that differ only in their budget share one
//! trial: with a constant learning rate and a schedule that repeats every
//! cycle, the first `B` steps of a longer run are exactly a run of budget
//! `B`, so one run measured at `B` answers both.

use std::path::Path;

use gast_core::style::{Focus, Mode, StyleConfig};

use super::{
    COLLAPSE_CONTENT, DEFAULTS_CYCLE, DEFAULTS_NEW, DEFAULTS_PAPER, DEFAULTS_SEED, FOCUS_FITTED_VIEWS, FOCUS_FRAME,
    FOCUS_MASKED_LOSSES, FOCUS_OBJECT, FOCUS_SEED, Row, SEED_LABEL, Sizes, Study, StyleSource, TrialSpec, mode_label,
};
use crate::views::Framing;

/// The whole grid: trials and the rows that read them.
#[derive(Default)]
pub struct Grid {
    /// Unique trials.
    pub trials: Vec<TrialSpec>,
    /// Rows of every study.
    pub rows: Vec<Row>,
}

impl Grid {
    /// Asks for `config` on (`scene`, `style`) read at its full budget (and at `extra` steps),
    /// sharing a trial with an earlier row that differs only in budget.
    fn want(
        &mut self,
        row: (Study, &str),
        scene: usize,
        style: &StyleSource,
        config: StyleConfig,
        lr_scale: f32,
        extra: &[u32],
    ) {
        self.want_framed(row, scene, style, config, lr_scale, extra, (Framing::Full, false));
    }

    /// [`Grid::want`] with the optimisation views' framing and whether the
    /// evaluation ring is fitted to the object.
    #[allow(clippy::too_many_arguments)]
    fn want_framed(
        &mut self,
        (study, label): (Study, &str),
        scene: usize,
        style: &StyleSource,
        config: StyleConfig,
        lr_scale: f32,
        extra: &[u32],
        (framing, eval_on_object): (Framing, bool),
    ) {
        let budget = config.schedule().total_steps();
        let same = |t: &TrialSpec| {
            t.scene == scene
                && t.framing == framing
                && t.eval_on_object == eval_on_object
                && t.style == *style
                && t.lr_scale == lr_scale
                && StyleConfig { cycles: 1, ..t.config.clone() } == StyleConfig { cycles: 1, ..config.clone() }
        };
        let i = match self.trials.iter().position(same) {
            Some(i) => {
                let t = &mut self.trials[i];
                t.config.cycles = t.config.cycles.max(config.cycles);
                i
            }
            None => {
                let id = format!("{:03}-{}", self.trials.len(), label_id(study, label, style));
                let checkpoints = vec![0];
                let (style, views) = (style.clone(), framing);
                self.trials.push(TrialSpec {
                    id,
                    scene,
                    style,
                    config,
                    lr_scale,
                    checkpoints,
                    framing: views,
                    eval_on_object,
                });
                self.trials.len() - 1
            }
        };
        let t = &mut self.trials[i];
        for &s in extra.iter().chain([&budget]) {
            if !t.checkpoints.contains(&s) {
                t.checkpoints.push(s);
            }
        }
        t.checkpoints.sort_unstable();
        self.rows.push(Row { study, label: label.into(), trial: t.id.clone(), step: budget });
    }
}

fn label_id(study: Study, label: &str, style: &StyleSource) -> String {
    crate::report::file_safe(&format!("{study:?}-{label}-{}", style.name()).to_lowercase())
}

/// The grid of `sizes` restricted to `studies`.
pub fn build_grid(sizes: &Sizes, shared: &Path, studies: &[Study]) -> anyhow::Result<Grid> {
    // Every study but focus keeps the paper's whole-frame losses, so its
    // figures stay comparable with earlier runs.
    let base = StyleConfig {
        resolution: sizes.resolution,
        steps_per_cycle: sizes.steps_per_cycle,
        focus: Focus::Frame,
        ..StyleConfig::default()
    };
    let cycles = |budget: u32| budget.div_ceil(sizes.steps_per_cycle).max(1);
    let file = |rel: &String| StyleSource::File(shared.join(rel));
    let curve_styles: Vec<StyleSource> = sizes.curve_styles.iter().map(file).collect();
    let main = curve_styles.first().cloned().unwrap_or(StyleSource::Checker);
    let mut g = Grid::default();
    let on = |s: Study| studies.contains(&s);
    let ablation = StyleConfig { cycles: cycles(sizes.ablation_budget), ..base.clone() };

    if on(Study::Modes) {
        // The first curve style runs the long curves; the others check them at the ablation budget.
        for (k, style) in curve_styles.iter().enumerate() {
            let budget = if k == 0 { sizes.curve_budget } else { sizes.ablation_budget };
            let doublings: Vec<u32> = std::iter::successors(Some(sizes.steps_per_cycle), |s| Some(s * 2))
                .take_while(|s| *s < budget)
                .collect();
            for mode in Mode::ALL {
                let config = StyleConfig { mode, cycles: cycles(budget), ..base.clone() };
                g.want((Study::Modes, mode_label(mode)), 0, style, config, 1.0, &doublings);
            }
            // The same run with another view order: the spread between the two is
            // the noise floor against which the report reads every difference.
            let config = StyleConfig { seed: 1, cycles: cycles(budget), ..base.clone() };
            g.want((Study::Modes, SEED_LABEL), 0, style, config, 1.0, &doublings);
        }
    }
    if on(Study::Ratio) {
        for style in &curve_styles {
            for ratio in [0.0f32, 0.3, 0.6, 0.9, 1.0] {
                let config = StyleConfig { ratio_geo: ratio, ..ablation.clone() };
                g.want((Study::Ratio, &format!("{:.0}", ratio * 100.0)), 0, style, config, 1.0, &[]);
            }
        }
    }
    if on(Study::LambdaGc) {
        for style in &curve_styles {
            for l in [0.0f32, 2.0, 4.0] {
                let mut config = ablation.clone();
                config.weights.gcfm = l;
                g.want((Study::LambdaGc, &format!("{l}")), 0, style, config, 1.0, &[]);
            }
        }
    }
    if on(Study::Resolution) {
        let quarter: Vec<u32> = [4u32, 2].iter().map(|d| sizes.ablation_budget / d).filter(|s| *s > 0).collect();
        for &r in &sizes.resolutions {
            let config = StyleConfig { resolution: r, ..ablation.clone() };
            g.want((Study::Resolution, &format!("{r} px")), 0, &main, config, 1.0, &quarter);
        }
    }
    if on(Study::Fast) {
        for style in &curve_styles {
            for (label, config) in fast_options(&ablation) {
                let budget = config.schedule().total_steps();
                let doubled = StyleConfig { cycles: config.cycles * 2, ..config.clone() };
                g.want((Study::Fast, &format!("{label} @ {budget}")), 0, style, config, 1.0, &[]);
                g.want((Study::Fast, &format!("{label} @ {}", 2 * budget)), 0, style, doubled, 1.0, &[]);
            }
        }
    }
    if on(Study::Pairs) {
        for scene in 0..sizes.scenes.len() {
            for style in &sizes.styles {
                let config = StyleConfig { cycles: cycles(sizes.pair_budget), ..base.clone() };
                g.want((Study::Pairs, "decoupled"), scene, &file(style), config, 1.0, &[]);
            }
        }
    }
    if on(Study::Stress) {
        for (mode, scale) in [
            (Mode::Joint, 1.0),
            (Mode::Joint, 10.0),
            (Mode::Joint, 30.0),
            (Mode::Joint, 100.0),
            (Mode::Decoupled, 1.0),
            (Mode::Decoupled, 10.0),
            (Mode::Decoupled, 30.0),
            (Mode::Decoupled, 100.0),
            (Mode::GeometryOnly, 30.0),
            (Mode::GeometryOnly, 100.0),
        ] {
            let config = StyleConfig { mode, lr: scaled_lr(scale), ..ablation.clone() };
            g.want((Study::Stress, &format!("{} lr×{scale}", mode_label(mode))), 0, &main, config, scale, &[]);
        }
        let long = StyleConfig { cycles: cycles(sizes.long_budget), ..base.clone() };
        let quarter: Vec<u32> = [4u32, 2].iter().map(|d| sizes.long_budget / d).collect();
        g.want((Study::Stress, "decoupled long"), 0, &main, long, 1.0, &quarter);
        for extreme in [StyleSource::Noise, StyleSource::Checker, StyleSource::Flat] {
            for mode in [Mode::Decoupled, Mode::Joint] {
                let config = StyleConfig { mode, ..ablation.clone() };
                g.want(
                    (Study::Stress, &format!("{} {}", mode_label(mode), extreme.name())),
                    0,
                    &extreme,
                    config,
                    1.0,
                    &[],
                );
            }
        }
    }
    focus_studies(&mut g, sizes, shared, studies, &base)?;
    Ok(g)
}

/// The rows of the focus and collapse studies (see [`Study::Focus`], [`Study::Collapse`]).
fn focus_studies(
    g: &mut Grid,
    sizes: &Sizes,
    shared: &Path,
    studies: &[Study],
    base: &StyleConfig,
) -> anyhow::Result<()> {
    let file = |rel: &String| StyleSource::File(shared.join(rel));
    let fitted = (Framing::Object, true);
    let plain_on_object = (Framing::Full, true);
    if studies.contains(&Study::Focus) {
        let cycles = sizes.focus_budget.div_ceil(sizes.steps_per_cycle).max(1);
        let frame = StyleConfig { cycles, ..base.clone() };
        // `Sizes::from_file` refuses a bad patch with its file; sizes built in code meet it here.
        let object = StyleConfig { focus: Focus::Object, ..frame.clone() }
            .patched(&sizes.focus_object)
            .map_err(|e| anyhow::anyhow!("the focus study's object arm: focus_object: {e}"))?;
        for scene in 0..sizes.scenes.len() {
            for (k, style) in sizes.styles.iter().enumerate() {
                let style = file(style);
                g.want_framed((Study::Focus, FOCUS_FRAME), scene, &style, frame.clone(), 1.0, &[], plain_on_object);
                g.want_framed((Study::Focus, FOCUS_OBJECT), scene, &style, object.clone(), 1.0, &[], fitted);
                if sizes.focus_halves {
                    g.want_framed((Study::Focus, FOCUS_FITTED_VIEWS), scene, &style, frame.clone(), 1.0, &[], fitted);
                    g.want_framed(
                        (Study::Focus, FOCUS_MASKED_LOSSES),
                        scene,
                        &style,
                        object.clone(),
                        1.0,
                        &[],
                        plain_on_object,
                    );
                }
                if k == 0 {
                    let seed = StyleConfig { seed: 1, ..frame.clone() };
                    g.want_framed((Study::Focus, FOCUS_SEED), scene, &style, seed, 1.0, &[], plain_on_object);
                }
            }
        }
    }
    if studies.contains(&Study::Defaults) {
        // Both arms as a user gets them: `--preset paper` on the plain orbit,
        // the shipped defaults on the views `gast stylize` frames; the
        // budget and resolution are the study's, the rest is each preset's.
        // With `defaults_plan_s` each arm keeps its preset's schedule here
        // and the runner plans it on the scene's views ([`super::run`]).
        let sized = |c: StyleConfig| match sizes.defaults_plan_s {
            Some(_) => StyleConfig { steps_per_cycle: DEFAULTS_CYCLE, ..c },
            None => StyleConfig {
                resolution: sizes.defaults_resolution,
                steps_per_cycle: DEFAULTS_CYCLE,
                cycles: sizes.defaults_budget.div_ceil(DEFAULTS_CYCLE).max(1),
                ..c
            },
        };
        let candidate = StyleConfig::default()
            .patched(&sizes.defaults_patch)
            .map_err(|e| anyhow::anyhow!("the defaults study's candidate arm: defaults_patch: {e}"))?;
        let (paper, defaults) = (sized(StyleConfig::paper()), sized(candidate));
        for scene in 0..sizes.scenes.len() {
            for (k, style) in sizes.styles.iter().enumerate() {
                let style = file(style);
                g.want_framed(
                    (Study::Defaults, DEFAULTS_PAPER),
                    scene,
                    &style,
                    paper.clone(),
                    1.0,
                    &[],
                    plain_on_object,
                );
                g.want_framed((Study::Defaults, DEFAULTS_NEW), scene, &style, defaults.clone(), 1.0, &[], fitted);
                if k == 0 {
                    let seed = StyleConfig { seed: 1, ..paper.clone() };
                    g.want_framed((Study::Defaults, DEFAULTS_SEED), scene, &style, seed, 1.0, &[], plain_on_object);
                }
            }
        }
    }
    if studies.contains(&Study::Collapse) {
        let steps = 100;
        let default = StyleConfig {
            resolution: sizes.collapse_resolution,
            steps_per_cycle: steps,
            cycles: sizes.collapse_budget.div_ceil(steps).max(1),
            ..base.clone()
        };
        let total = default.schedule().total_steps();
        let quarters: Vec<u32> = [4u32, 2].iter().map(|d| total / d).filter(|s| *s > 0).collect();
        let wanted = |label: &str| sizes.collapse_arms.iter().any(|a| a == label);
        let every_pair = |label: &str| {
            label == "decoupled"
                || (label == "object focus" && sizes.collapse_object_on_every_pair)
                || (label == COLLAPSE_CONTENT && sizes.collapse_content_on_every_pair)
        };
        let block2 = sizes.styles.iter().find(|s| s.contains("block2")).or(sizes.styles.first()).cloned();
        if let Some(block2) = block2 {
            let mut arms = vec![
                ("object focus".to_string(), StyleConfig { focus: Focus::Object, ..default.clone() }, fitted),
                ("colour floor".to_string(), StyleConfig { color_floor: true, ..default.clone() }, plain_on_object),
            ];
            for lr in [1e-3f32, 1e-4] {
                let mut c = default.clone();
                c.lr.color = lr;
                arms.push((format!("lr colour {lr:e}"), c, plain_on_object));
            }
            // The geometry steps' moving means darken the object (frozen
            // means keep its luminance, frozen opacity, scales or rotations
            // do not): a tenth of the reference's learning rate of the means.
            let mut c = default.clone();
            c.lr.means_per_extent = 1e-5;
            arms.push(("lr means 1e-5".to_string(), c, plain_on_object));
            let mut c = default.clone();
            c.weights.content = 0.1;
            arms.push((COLLAPSE_CONTENT.to_string(), c, plain_on_object));
            arms.insert(0, ("decoupled".to_string(), default.clone(), plain_on_object));
            for (label, config, framing) in arms.into_iter().filter(|a| wanted(&a.0)) {
                for scene in 0..sizes.scenes.len() {
                    for style in &sizes.styles {
                        if every_pair(&label) || (scene == 0 && *style == block2) {
                            g.want_framed(
                                (Study::Collapse, &label),
                                scene,
                                &file(style),
                                config.clone(),
                                1.0,
                                &quarters,
                                framing,
                            );
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

fn scaled_lr(scale: f32) -> gast_core::style::config::LearningRates {
    let d = gast_core::style::config::LearningRates::default();
    gast_core::style::config::LearningRates {
        color: d.color * scale,
        means_per_extent: d.means_per_extent * scale,
        scales: d.scales * scale,
        quats: d.quats * scale,
        opacity: d.opacity * scale,
    }
}

/// The settings of the `fast` study: the exact default, its seed-1 twin (the
/// noise floor), and each option of issue 10 alone and together.
fn fast_options(base: &StyleConfig) -> Vec<(&'static str, StyleConfig)> {
    use gast_core::style::{MatchMethod, MatchingConfig};
    use gast_core::vision::ConvAlgo;
    let pca = MatchingConfig { method: MatchMethod::Pca, ..MatchingConfig::default() };
    let reuse = MatchingConfig { reuse: 3, ..MatchingConfig::default() };
    let all = MatchingConfig { reuse: 3, ..pca };
    // The reference: im2col convolutions and the exact search.
    let base = &StyleConfig { conv: ConvAlgo::Im2col, ..base.clone() };
    vec![
        ("exact", base.clone()),
        ("exact, seed 1", StyleConfig { seed: 1, ..base.clone() }),
        ("winograd", StyleConfig { conv: ConvAlgo::Winograd, ..base.clone() }),
        ("pca 128/32", StyleConfig { matching: pca, ..base.clone() }),
        ("reuse 3", StyleConfig { matching: reuse, ..base.clone() }),
        ("winograd + pca + reuse 3", StyleConfig { conv: ConvAlgo::Winograd, matching: all, ..base.clone() }),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use gast_core::style::MeanSteps;

    #[test]
    fn rows_that_differ_only_in_budget_share_a_trial() {
        let g = build_grid(&Sizes::full(), Path::new("/shared"), &Study::ALL).expect("grid");
        // The decoupled wave run of the mode curves also answers ratio 90, λ_GC 2,
        // 128 px, the stress baseline and the guitar × wave pair.
        let decoupled = g
            .rows
            .iter()
            .find(|r| r.study == Study::Modes && r.label == "decoupled")
            .map(|r| r.trial.clone())
            .expect("a decoupled mode row");
        let sharing: Vec<Study> = g.rows.iter().filter(|r| r.trial == decoupled).map(|r| r.study).collect();
        for s in
            [Study::Modes, Study::Ratio, Study::LambdaGc, Study::Resolution, Study::Fast, Study::Pairs, Study::Stress]
        {
            assert!(sharing.contains(&s), "{s:?} does not reuse the decoupled run: {sharing:?}");
        }
        let t = g.trials.iter().find(|t| t.id == decoupled).expect("trial");
        assert_eq!(t.checkpoints, vec![0, 20, 40, 60, 80, 120, 160, 240]);
        // Every row's step is one of its trial's checkpoints and within its budget.
        for r in &g.rows {
            let t = g.trials.iter().find(|t| t.id == r.trial).expect("trial of row");
            assert!(t.checkpoints.contains(&r.step) && r.step <= t.config.schedule().total_steps(), "{r:?}");
        }
        let ids: std::collections::HashSet<&str> = g.trials.iter().map(|t| t.id.as_str()).collect();
        assert_eq!(ids.len(), g.trials.len());
    }

    #[test]
    fn the_collapse_study_has_its_arms_each_changing_one_setting() {
        let sizes = Sizes::full();
        let g = build_grid(&sizes, Path::new("/shared"), &[Study::Collapse]).expect("grid");
        let config_of = |label: &str| {
            let rows: Vec<_> = g.rows.iter().filter(|r| r.study == Study::Collapse && r.label == label).collect();
            let t = g.trials.iter().find(|t| t.id == rows[0].trial).expect("trial");
            (rows.len(), t.config.clone(), t.style.clone())
        };
        let (pairs, default, _) = config_of("decoupled");
        assert_eq!(pairs, sizes.scenes.len() * sizes.styles.len(), "the default on every pair");
        assert_eq!(default.schedule().total_steps(), sizes.collapse_budget);
        assert_eq!(default.resolution, sizes.collapse_resolution);
        let arms = [
            ("object focus", StyleConfig { focus: Focus::Object, ..default.clone() }),
            ("colour floor", StyleConfig { color_floor: true, ..default.clone() }),
        ];
        let mut lrs = Vec::new();
        for (label, color, means) in
            [("lr colour 1e-3", 1e-3, 1e-4), ("lr colour 1e-4", 1e-4, 1e-4), ("lr means 1e-5", 0.01, 1e-5)]
        {
            let mut c = default.clone();
            c.lr.color = color;
            c.lr.means_per_extent = means;
            lrs.push((label, c));
        }
        let mut content = default.clone();
        content.weights.content = 0.1;
        lrs.push((COLLAPSE_CONTENT, content));
        for (label, want) in arms.into_iter().chain(lrs) {
            let (n, config, style) = config_of(label);
            assert_eq!(n, 1, "{label}: one run");
            assert!(format!("{style:?}").contains("block2"), "{label} runs on block2: {style:?}");
            assert_eq!(format!("{config:?}"), format!("{want:?}"), "{label}");
        }
        // Only object focus, on every pair.
        let only =
            Sizes { collapse_arms: vec!["object focus".into()], collapse_object_on_every_pair: true, ..sizes.clone() };
        let g = build_grid(&only, Path::new("/shared"), &[Study::Collapse]).expect("grid");
        assert_eq!(g.rows.len(), sizes.scenes.len() * sizes.styles.len());
        assert!(g.rows.iter().all(|r| r.label == "object focus"), "{:?}", g.rows);
        assert!(g.trials.iter().all(|t| t.config.focus == Focus::Object));
        // The default and λ_cont 0.1, both on every pair.
        let both = Sizes {
            collapse_arms: vec!["decoupled".into(), COLLAPSE_CONTENT.into()],
            collapse_content_on_every_pair: true,
            ..sizes.clone()
        };
        let g = build_grid(&both, Path::new("/shared"), &[Study::Collapse]).expect("grid");
        let content_rows = g.rows.iter().filter(|r| r.label == COLLAPSE_CONTENT).count();
        assert_eq!((g.rows.len(), content_rows), (2 * pairs, pairs));
    }

    #[test]
    fn the_defaults_study_compares_the_shipped_defaults_with_the_paper_preset() {
        let sizes = Sizes::full();
        let g = build_grid(&sizes, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let pairs = sizes.scenes.len() * sizes.styles.len();
        let trials_of = |label: &str| -> Vec<TrialSpec> {
            g.rows
                .iter()
                .filter(|r| r.study == Study::Defaults && r.label == label)
                .map(|r| g.trials.iter().find(|t| t.id == r.trial).expect("trial").clone())
                .collect()
        };
        let (paper, defaults, seed) = (trials_of(DEFAULTS_PAPER), trials_of(DEFAULTS_NEW), trials_of(DEFAULTS_SEED));
        assert_eq!((paper.len(), defaults.len(), seed.len()), (pairs, pairs, sizes.scenes.len()));
        // Each arm is its preset with only the study's budget and resolution set.
        let sized = |c: StyleConfig| StyleConfig {
            resolution: sizes.defaults_resolution,
            steps_per_cycle: DEFAULTS_CYCLE,
            cycles: sizes.defaults_budget / DEFAULTS_CYCLE,
            ..c
        };
        assert!(paper.iter().all(|t| t.config == sized(StyleConfig::paper()) && t.framing == Framing::Full));
        assert!(defaults.iter().all(|t| t.config == sized(StyleConfig::default()) && t.framing == Framing::Object));
        assert!(paper.iter().chain(&defaults).chain(&seed).all(|t| t.eval_on_object));
        assert_eq!(seed[0].config.seed, 1);
        // It runs only when named.
        let g = build_grid(&sizes, Path::new("/shared"), &Study::ALL).expect("grid");
        assert!(!g.rows.iter().any(|r| r.study == Study::Defaults));

        // A candidate recipe patches the defaults arm alone; a bad patch names its key.
        use gast_core::style::config::LossWeights;
        let patch = serde_json::json!({ "weights": { "palette": 100.0 } });
        let tried = Sizes { defaults_patch: patch, ..sizes.clone() };
        let g = build_grid(&tried, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let of = |label: &str| g.rows.iter().filter(|r| r.label == label).map(|r| r.trial.clone()).collect::<Vec<_>>();
        let config = |id: &String| g.trials.iter().find(|t| &t.id == id).expect("trial").config.clone();
        let want = StyleConfig { weights: LossWeights { palette: 100.0, ..Default::default() }, ..Default::default() };
        assert!(of(DEFAULTS_NEW).iter().all(|id| config(id) == sized(want.clone())));
        assert!(of(DEFAULTS_PAPER).iter().all(|id| config(id) == sized(StyleConfig::paper())));
        let bad = Sizes { defaults_patch: serde_json::json!({ "weights": { "nope": 1 } }), ..sizes.clone() };
        let e = build_grid(&bad, Path::new("/shared"), &[Study::Defaults]).err().expect("a bad patch");
        assert!(e.to_string().contains("defaults_patch") && e.to_string().contains("nope"), "{e}");
    }

    #[test]
    fn the_focus_halves_each_take_one_half_of_object_focus() {
        let sizes = Sizes { focus_halves: true, ..Sizes::full() };
        let g = build_grid(&sizes, Path::new("/shared"), &[Study::Focus]).expect("grid");
        let trial_of = |label: &str| {
            let rows: Vec<_> = g.rows.iter().filter(|r| r.study == Study::Focus && r.label == label).collect();
            assert_eq!(rows.len(), sizes.scenes.len() * sizes.styles.len(), "{label} on every pair");
            g.trials.iter().find(|t| t.id == rows[0].trial).expect("trial").clone()
        };
        let (frame, object) = (trial_of(FOCUS_FRAME), trial_of(FOCUS_OBJECT));
        let (fitted, masked) = (trial_of(FOCUS_FITTED_VIEWS), trial_of(FOCUS_MASKED_LOSSES));
        // The fitted views with frame's losses, the orbit with object's losses.
        assert_eq!((fitted.framing, format!("{:?}", fitted.config)), (object.framing, format!("{:?}", frame.config)));
        assert_eq!((masked.framing, format!("{:?}", masked.config)), (frame.framing, format!("{:?}", object.config)));
        assert_ne!(frame.framing, object.framing);
        assert!([&frame, &object, &fitted, &masked].iter().all(|t| t.eval_on_object));
        // Without the flag, neither half runs.
        let g = build_grid(&Sizes::full(), Path::new("/shared"), &[Study::Focus]).expect("grid");
        assert!(!g.rows.iter().any(|r| r.label == FOCUS_FITTED_VIEWS || r.label == FOCUS_MASKED_LOSSES));
    }

    #[test]
    fn the_object_arm_takes_its_own_resolution_when_given() {
        let config = |sizes: &Sizes, label: &str| {
            let g = build_grid(sizes, Path::new("/shared"), &[Study::Focus]).expect("grid");
            let row = g.rows.iter().find(|r| r.label == label).expect("row").trial.clone();
            g.trials.iter().find(|t| t.id == row).expect("trial").config.clone()
        };
        let trial = |sizes: &Sizes, label: &str| config(sizes, label).resolution;
        let same = Sizes::full();
        assert_eq!((trial(&same, FOCUS_FRAME), trial(&same, FOCUS_OBJECT)), (same.resolution, same.resolution));
        let apart = Sizes { resolution: 256, focus_object: serde_json::json!({"resolution": 512}), ..Sizes::full() };
        assert_eq!((trial(&apart, FOCUS_FRAME), trial(&apart, FOCUS_OBJECT)), (256, 512));
        assert_eq!(trial(&apart, FOCUS_SEED), 256);
        // The patch reaches the object arm only.
        let mean = Sizes {
            focus_object: serde_json::json!({
                "weights": {"feature_mean": 100.0, "outside": 30.0, "sliced": 7.0, "assignment": 3.0,
                            "assignment_cosine": 4.0, "tv": 0.5},
                "feature_mean_steps": "colour", "lr": {"color": 0.05}, "ratio_geo": 0.7
            }),
            ..Sizes::full()
        };
        let base = StyleConfig::default();
        for (label, want) in
            [(FOCUS_FRAME, [0.0; 5]), (FOCUS_SEED, [0.0; 5]), (FOCUS_OBJECT, [100.0, 30.0, 7.0, 3.0, 4.0])]
        {
            let c = config(&mean, label);
            let w = c.weights;
            assert_eq!([w.feature_mean, w.outside, w.sliced, w.assignment, w.assignment_cosine], want, "{label}");
            let object = label == FOCUS_OBJECT;
            let steps = if object { MeanSteps::Colour } else { base.feature_mean_steps };
            assert_eq!(c.feature_mean_steps, steps, "{label}");
            assert_eq!(c.lr.color, if object { 0.05 } else { base.lr.color }, "{label}");
            assert_eq!(c.lr.opacity, base.lr.opacity, "{label}");
            assert_eq!(c.ratio_geo, if object { 0.7 } else { base.ratio_geo }, "{label}");
            assert_eq!(c.weights.tv, if object { 0.5 } else { base.weights.tv }, "{label}");
        }
    }

    #[test]
    fn a_patch_that_does_not_apply_is_refused_not_dropped() {
        let bad = Sizes { focus_object: serde_json::json!({"weights": {"nope": 1.0}}), ..Sizes::full() };
        let err = build_grid(&bad, Path::new("/shared"), &[Study::Focus]).err().expect("a bad patch is refused");
        let text = format!("{err:#}");
        assert!(text.contains("focus_object") && text.contains("weights.nope"), "{text}");
        // Studies without an object arm never read the patch.
        assert!(build_grid(&bad, Path::new("/shared"), &[Study::Collapse]).is_ok());
    }
}
