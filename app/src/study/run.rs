//! The trial runner of `gast bench quality`: every trial of a grid, grouped
//! by scene and style so that each scene is loaded and each style's features
//! computed once, with a progress bar and one summary line per trial.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use gast_core::Gaussians;
use gast_core::eval::{EvalOptions, StabilityThresholds, TrialOutcome, run_trial};
use gast_core::session::{PreparedStyle, SessionInputs, StyleDepthSource, StyleImage, prepare_style};
use gast_core::vision::Vgg;

use super::grid::build_grid;
use super::{Record, RunSummary, Sizes, Study, StyleSource, TrialSpec};
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
) -> anyhow::Result<(RunSummary, Vec<(String, StyleImage)>)> {
    let grid = build_grid(&sizes, shared, studies)?;
    let total_steps: u64 = grid.trials.iter().map(|t| u64::from(t.config.schedule().total_steps())).sum();
    println!(
        "quality benchmark: {} trials ({} rows, {total_steps} steps) over {} scenes, {} threads; writing {}",
        grid.trials.len(),
        grid.rows.len(),
        grid.trials.iter().map(|t| t.scene).collect::<std::collections::BTreeSet<_>>().len(),
        rayon::current_num_threads(),
        out.display()
    );

    let started = Instant::now();
    let bar = crate::progress::bar(total_steps, "steps");
    let mut order: Vec<usize> = (0..grid.trials.len()).collect();
    order.sort_by(|&a, &b| {
        let (ta, tb) = (&grid.trials[a], &grid.trials[b]);
        (ta.scene, &ta.style).cmp(&(tb.scene, &tb.style))
    });
    let mut scenes: BTreeMap<usize, Gaussians> = BTreeMap::new();
    let mut styles: BTreeMap<StyleSource, (StyleImage, PreparedStyle)> = BTreeMap::new();
    let mut records = Vec::new();
    let eval = EvalOptions { resolution: sizes.eval_resolution, ..EvalOptions::default() };
    for &i in &order {
        let spec = &grid.trials[i];
        if !scenes.contains_key(&spec.scene) {
            scenes.clear(); // trials are grouped by scene: keep one in memory
            let path = shared.join(&sizes.scenes[spec.scene]);
            scenes.insert(spec.scene, load_scene(&path)?);
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
        let views = views_for(
            scene,
            &ViewArgs {
                cameras: None,
                views: sizes.views,
                size: spec.config.resolution,
                fov: 50.0,
                framing: spec.framing,
                crop: false,
            },
        )?;
        let inputs = SessionInputs {
            scene: scene.clone(),
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
        bar.suspend(|| println!("{}", summary_line(spec, &outcome)));
        records.push(Record::new(spec, &sizes.scenes[spec.scene], scene.len(), outcome));
    }
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    let styles_used: Vec<(String, StyleImage)> = styles.into_iter().map(|(s, (image, _))| (s.name(), image)).collect();
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
