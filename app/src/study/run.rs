//! The trial runner of `gast bench quality`: every trial of a grid, grouped
//! by scene and style so that each scene is loaded and each style's features
//! computed once, with a progress bar and one summary line per trial. Each
//! finished trial goes to the output folder's journal ([`super::journal`]),
//! from which the same command resumes.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use gast_core::eval::{EvalOptions, StabilityThresholds, TrialOutcome, run_trial};
use gast_core::session::plan::{StepModel, ViewsSurvey, auto_plan, survey};
use gast_core::session::{PreparedStyle, SessionInputs, StyleDepthSource, StyleImage, prepare_style};
use gast_core::vision::Vgg;
use gast_core::{Camera, Gaussians};

use super::adopt::take;
use super::grid::build_grid;
use super::journal::Journal;
use super::pages::quality::write_sample;
use super::{Record, Row, RunSummary, Sizes, Study, StyleSource, TrialSpec};
use crate::views::{ViewArgs, load_scene, views_for};

/// Runs the grid of `sizes` restricted to `studies` (scenes and styles read
/// under `shared`), printing a line per trial; returns what the run records
/// and the style images used (for the report's thumbnails).
pub fn run_grid(
    sizes: Sizes,
    studies: &[Study],
    shared: &Path,
    vgg: &Arc<Vgg>,
    out: &Path,
    from: &[PathBuf],
) -> anyhow::Result<(RunSummary, Vec<(String, StyleImage)>)> {
    let mut grid = build_grid(&sizes, shared, studies)?;
    let key = serde_json::json!({ "sizes": &sizes, "studies": studies });
    let (mut journal, mut records) = Journal::open(out, &key)?;
    let mut done: BTreeSet<String> = records.iter().map(|r| r.id.clone()).collect();
    // Trials other runs finished the same way (`--from`), journalled here as if run here.
    for dir in from {
        let taken = take(&key, &grid, &sizes.scenes, dir, &done)?;
        println!("  taking {} finished trials from {}", taken.len(), dir.join(super::journal::JOURNAL).display());
        for (other_id, r) in taken {
            copy_sample(dir, &other_id, out, &r.id)?;
            journal.push(&r)?;
            done.insert(r.id.clone());
            records.push(r);
        }
    }
    let todo = |t: &&TrialSpec| !done.contains(&t.id);
    let total_steps: u64 = grid.trials.iter().filter(todo).map(|t| u64::from(t.config.schedule().total_steps())).sum();
    println!(
        "quality benchmark: {} trials ({} rows, {total_steps} steps) over {} scenes, {} threads; writing {}",
        grid.trials.iter().filter(todo).count(),
        grid.rows.len(),
        grid.trials.iter().map(|t| t.scene).collect::<BTreeSet<_>>().len(),
        rayon::current_num_threads(),
        out.display()
    );
    if !records.is_empty() {
        println!(
            "  resuming: {} of {} trials already finished in {}",
            records.len(),
            grid.trials.len(),
            out.join(super::journal::JOURNAL).display()
        );
    }
    // The defaults study's arms that run what `gast stylize` plans (`defaults_plan_s`).
    let planned: BTreeSet<String> = match sizes.defaults_plan_s {
        Some(_) => grid.rows.iter().filter(|r| r.study == Study::Defaults).map(|r| r.trial.clone()).collect(),
        None => BTreeSet::new(),
    };

    let started = Instant::now();
    let resumed_s: f64 = records.iter().map(Record::seconds).sum();
    let bar = crate::progress::bar(total_steps, "steps");
    let mut order: Vec<usize> = (0..grid.trials.len()).filter(|&i| !done.contains(&grid.trials[i].id)).collect();
    order.sort_by(|&a, &b| {
        let (ta, tb) = (&grid.trials[a], &grid.trials[b]);
        (ta.scene, &ta.style).cmp(&(tb.scene, &tb.style))
    });
    let mut scenes: BTreeMap<usize, Arc<Gaussians>> = BTreeMap::new();
    let mut styles: BTreeMap<StyleSource, (StyleImage, PreparedStyle)> = BTreeMap::new();
    let eval = EvalOptions { resolution: sizes.eval_resolution, ..EvalOptions::default() };
    for &i in &order {
        let mut spec = grid.trials[i].clone();
        if !scenes.contains_key(&spec.scene) {
            scenes.clear(); // trials are grouped by scene: keep one in memory
            let path = shared.join(&sizes.scenes[spec.scene]);
            scenes.insert(spec.scene, Arc::new(load_scene(&path)?));
        }
        let Some(scene) = scenes.get(&spec.scene) else { continue };
        if !styles.contains_key(&spec.style) {
            let image = spec.style.image().with_context(|| format!("style {}", spec.style.name()))?;
            let c = &spec.config;
            let prepared = prepare_style(
                vgg,
                &image,
                c.texture_scale,
                &StyleDepthSource::Heuristic,
                c.depth_polarity,
                c.depth_relief_px,
            );
            styles.insert(spec.style.clone(), (image, prepared));
        }
        let Some((image, prepared)) = styles.get(&spec.style) else { continue };
        let framing = spec.framing;
        let view_args = |size: u32| ViewArgs {
            cameras: None,
            orbit: false,
            views: sizes.views,
            size,
            fov: 50.0,
            framing,
            crop: false,
        };
        let mut views = views_for(scene, &view_args(spec.config.resolution))?;
        if let Some(budget_s) = sizes.defaults_plan_s.filter(|_| planned.contains(&spec.id)) {
            let (before, after) = plan_arm(&mut spec, scene, &views, [image.width, image.height], budget_s);
            bar.set_length((bar.length().unwrap_or(0) + u64::from(after)).saturating_sub(u64::from(before)));
            views = views_for(scene, &view_args(spec.config.resolution))?;
        }
        let inputs = SessionInputs {
            scene: Arc::clone(scene),
            cameras: views,
            style: image.clone(),
            style_depth: StyleDepthSource::Heuristic,
            vgg: Arc::clone(vgg),
            config: spec.config.clone(),
            gpu: None,
        };
        bar.set_message(spec.id.clone());
        let base = bar.position();
        let outcome = run_trial(
            inputs,
            Some(prepared.clone()),
            &spec.checkpoints,
            &EvalOptions {
                fit_to_object: spec.eval_on_object,
                over_style_colour: sizes.eval_over_style_colour,
                ..eval
            },
            &StabilityThresholds::default(),
            &mut |done, _| bar.set_position(base + u64::from(done)),
        )
        .with_context(|| format!("trial {}", spec.id))?;
        bar.set_position(base + u64::from(spec.config.schedule().total_steps()));
        bar.suspend(|| println!("{}", summary_line(&spec, &outcome)));
        let record = Record::new(&spec, &sizes.scenes[spec.scene], scene.len(), outcome);
        write_sample(out, &record)?;
        journal.push(&record)?;
        records.push(record);
    }
    bar.finish_and_clear();
    for r in &records {
        if let Some(spec) = grid.trials.iter().find(|t| t.id == r.id) {
            read_at_budget(&mut grid.rows, spec.config.schedule().total_steps(), r);
        }
    }
    // The resumed trials' own seconds stand in for the earlier processes' wall time.
    let wall = started.elapsed().as_secs_f64() + resumed_s;
    let mut styles_used: Vec<(String, StyleImage)> = Vec::new();
    for spec in &grid.trials {
        let name = spec.style.name();
        if styles_used.iter().all(|(n, _)| *n != name) {
            let image = match styles.remove(&spec.style) {
                Some((image, _)) => image,
                None => spec.style.image().with_context(|| format!("style {name}"))?,
            };
            styles_used.push((name, image));
        }
    }
    let run = RunSummary {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        threads: rayon::current_num_threads(),
        sizes,
        wall_s: wall,
        rows: grid.rows,
        trials: records,
    };
    Ok((run, styles_used))
}

/// Sets `spec`'s working resolution and cycles to what `gast stylize` plans
/// for a CPU run of `budget_s` seconds with no `--resolution` or `--cycles`:
/// the subject's span in `views` and the losses' focus (auto decides on the
/// views' coverage) pick the step model, [`auto_plan`] the rest. The
/// checkpoint at the old budget moves to the new one. Returns the steps
/// scheduled before and after.
fn plan_arm(spec: &mut TrialSpec, scene: &Gaussians, views: &[Camera], style: [usize; 2], budget_s: f64) -> (u32, u32) {
    let before = spec.config.schedule().total_steps();
    let ViewsSurvey { span, object } = survey(scene, views, spec.config.focus, spec.config.background);
    let model = StepModel::for_run(object, Some(spec.config.texture_scale))
        .with_style(style[0], style[1])
        .with_gaussians(scene.len());
    let plan = auto_plan(span, model, spec.config.cycles, spec.config.steps_per_cycle, budget_s);
    spec.config.resolution = plan.resolution;
    spec.config.cycles = plan.cycles;
    let after = spec.config.schedule().total_steps();
    for c in spec.checkpoints.iter_mut().filter(|c| **c == before) {
        *c = after;
    }
    (before, after)
}

/// Points the rows that read trial `r` at its planned budget `scheduled`
/// to the budget it ran (they differ where the runner planned the arm).
fn read_at_budget(rows: &mut [Row], scheduled: u32, r: &Record) {
    for row in rows.iter_mut().filter(|row| row.trial == r.id && row.step == scheduled) {
        row.step = r.budget;
    }
}

fn summary_line(spec: &TrialSpec, o: &TrialOutcome) -> String {
    let last = o.checkpoints.last().map(|c| c.measures).unwrap_or_default();
    let health = if o.stability.is_healthy() {
        "stable".to_string()
    } else {
        o.stability.issues.iter().map(|d| format!("{:?}", d.kind)).collect::<Vec<_>>().join("+")
    };
    format!(
        "{:<44} {:>4} steps {:>6.1} s  SW {:>7.4}  NN {:.4}  long RMSE {:.4}  {health}",
        spec.id,
        o.steps,
        o.checkpoints.last().map_or(0.0, |c| c.seconds),
        last.sliced_wasserstein,
        last.nn_cosine,
        last.consistency_long
    )
}

/// Copies the sample render (colour-matched, result, their depths) of the
/// trial `other_id` of the run in `from` into `out`'s `renders/` as `id`'s;
/// the journal does not carry it. A folder without it leaves the page
/// without that render.
fn copy_sample(from: &Path, other_id: &str, out: &Path, id: &str) -> anyhow::Result<()> {
    let src = from.join("renders").join(format!("{other_id}.png"));
    if !src.is_file() {
        return Ok(());
    }
    let bytes = std::fs::read(&src).with_context(|| format!("could not read {}", src.display()))?;
    let dir = out.join("renders");
    gast_core::io::create_folder(&dir).with_context(|| format!("could not create {}", dir.display()))?;
    Ok(gast_core::io::write_bytes(&dir.join(format!("{id}.png")), &bytes)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::{DEFAULTS_NEW, DEFAULTS_PAPER};
    use gast_core::session::plan::AUTO_RUN_BUDGET_S;
    use std::path::PathBuf;

    /// The defaults study's arm `label` as the grid specifies it.
    fn arm(grid: &super::super::grid::Grid, label: &str) -> TrialSpec {
        let row = grid.rows.iter().find(|r| r.label == label).expect("the arm's row");
        grid.trials.iter().find(|t| t.id == row.trial).expect("the row's trial").clone()
    }

    #[test]
    fn each_defaults_arm_runs_what_stylize_plans_for_ten_minutes_on_this_cpu() {
        let shared = std::env::var_os("GAST_SHARED")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
        let sizes = Sizes {
            scenes: vec!["data/scenes/guitar.compressed.ply".into()],
            styles: vec!["data/styles/wave.jpg".into()],
            defaults_plan_s: Some(AUTO_RUN_BUDGET_S),
            ..Sizes::quick()
        };
        let mut grid = build_grid(&sizes, &shared, &[Study::Defaults]).expect("grid");
        let scene = load_scene(&shared.join(&sizes.scenes[0])).expect("the shared guitar (set GAST_SHARED)");
        let mut planned = Vec::new();
        let wave = [4200, 2000];
        for label in [DEFAULTS_NEW, DEFAULTS_PAPER] {
            let mut spec = arm(&grid, label);
            // Unplanned, each arm holds its preset's schedule: 30 cycles of 100 steps.
            let scheduled = spec.config.schedule().total_steps();
            assert_eq!(scheduled, 3000, "{label}");
            let views = views_for(
                &scene,
                &ViewArgs {
                    cameras: None,
                    orbit: false,
                    views: sizes.views,
                    size: spec.config.resolution,
                    fov: 50.0,
                    framing: spec.framing,
                    crop: false,
                },
            )
            .expect("views");
            let (_, steps) = plan_arm(&mut spec, &scene, &views, wave, AUTO_RUN_BUDGET_S);
            assert_eq!(steps, spec.config.schedule().total_steps(), "{label}");
            let moved = steps == scheduled || !spec.checkpoints.contains(&scheduled);
            assert!(spec.checkpoints.contains(&steps) && moved, "{label}: measured at the budget it runs");
            let r = Record {
                budget: steps,
                id: spec.id.clone(),
                ..crate::study::test_record("x", "wave", Default::default(), Default::default())
            };
            read_at_budget(&mut grid.rows, scheduled, &r);
            let row = grid.rows.iter().find(|row| row.trial == spec.id).expect("row");
            assert_eq!(row.step, steps, "{label}: the row reads the trial at the budget it ran");
            planned.push((spec.config.resolution, steps));
        }
        // The defaults (object focus on guitar) fit 20 of the 30 cycles in
        // ten minutes at 256 px (0.29 s a step); the paper's whole-frame
        // losses with wave (4,200 × 2,000) at texture scale 256 (0.51 s a
        // step; 0.48 measured on 2026-12-01) fit 11 at the same resolution.
        assert_eq!(planned, [(256, 2000), (256, 1100)]);
    }
}
