//! One run of a study: a [`Session`] stepped through its whole schedule,
//! measured on the fixed evaluation views at chosen steps, then checked for
//! degeneration.
//!
//! Benchmarks, the stability study and the ablations are all lists of trials,
//! so one function does the stepping, the timing and the measuring for each,
//! and the time spent measuring is kept out of the time charted against quality.

use std::sync::Arc;
use std::time::Instant;

use super::measure::{EvalOptions, Evaluator, Measures};
use super::stability::{StabilityReport, StabilityThresholds, assess_stability};
use crate::scene::Gaussians;
use crate::session::{PreparedStyle, Session, SessionError, SessionInputs};

/// The mean of an RGB (HWC) image; black when it is empty.
pub fn mean_colour(rgb: &[f32]) -> [f32; 3] {
    let n = (rgb.len() / 3).max(1) as f64;
    std::array::from_fn(|ch| (rgb.iter().skip(ch).step_by(3).map(|&v| f64::from(v)).sum::<f64>() / n) as f32)
}

/// The measures of a scene after `step` steps.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Checkpoint {
    /// Steps done (0: the colour-matched input).
    pub step: u32,
    /// Wall-clock seconds of preparation plus stepping up to here (measuring excluded).
    pub seconds: f64,
    /// The measures.
    pub measures: Measures,
}

/// What a trial produced.
pub struct TrialOutcome {
    /// Seconds of preparation (colour matching, culling, style features).
    pub prepare_s: f64,
    /// Seconds spent measuring (not part of `seconds` of any checkpoint).
    pub measure_s: f64,
    /// Gaussians optimised (after culling) and in the scene.
    pub optimised: usize,
    /// The measures at each requested step that was reached, in order; the
    /// last is always the final scene.
    pub checkpoints: Vec<Checkpoint>,
    /// Total loss of every step.
    pub losses: Vec<f32>,
    /// Steps run (less than the schedule when the loss stopped being finite).
    pub steps: u32,
    /// Degenerations found in the final scene.
    pub stability: StabilityReport,
    /// The final scene (whole, culled Gaussians included).
    pub result: Gaussians,
    /// The evaluator, for sample renders from the same views.
    pub evaluator: Evaluator,
}

/// Runs `inputs` (with `style` prepared already, see
/// [`Session::prepare_with_style`]) to the end of its schedule, measuring at every step listed in
/// `checkpoints` (0 measures the colour-matched input) and at the end. A step
/// whose loss is not finite ends the run early: what follows would only
/// propagate NaNs. `progress(done, total)` is called after each step.
pub fn run_trial(
    inputs: SessionInputs,
    style: Option<PreparedStyle>,
    checkpoints: &[u32],
    eval: &EvalOptions,
    thresholds: &StabilityThresholds,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<TrialOutcome, SessionError> {
    let vgg = inputs.vgg.clone();
    let mut background = inputs.config.background;
    let t = Instant::now();
    let mut session = Session::prepare_with_style(inputs, style, &mut |_| {})?;
    let prepare_s = t.elapsed().as_secs_f64();

    if eval.over_style_colour {
        background = mean_colour(&session.style().maps.rgb);
    }
    let t = Instant::now();
    let matched = session.colour_matched();
    let evaluator = Evaluator::new(
        Arc::clone(&vgg),
        &session.style().targets.features,
        &matched,
        &EvalOptions { background, ..*eval },
    );
    let reference = evaluator.measure_reference();
    let mut measure_s = t.elapsed().as_secs_f64();

    let total = session.total_steps();
    let mut out = Vec::new();
    if checkpoints.contains(&0) {
        out.push(Checkpoint { step: 0, seconds: prepare_s, measures: reference });
    }
    let mut losses = Vec::with_capacity(total as usize);
    while let Some(report) = session.step() {
        losses.push(report.losses.total);
        let done = session.steps_done();
        progress(done, total);
        if !report.losses.total.is_finite() {
            break;
        }
        if done < total && checkpoints.contains(&done) {
            let t = Instant::now();
            let measures = evaluator.measure(&session.result());
            measure_s += t.elapsed().as_secs_f64();
            out.push(Checkpoint { step: done, seconds: prepare_s + session.elapsed_s(), measures });
        }
    }
    let t = Instant::now();
    let result = session.result();
    let measures = evaluator.measure(&result);
    let steps = session.steps_done();
    out.push(Checkpoint { step: steps, seconds: prepare_s + session.elapsed_s(), measures });
    let stability = assess_stability(
        &matched,
        &result,
        &losses,
        Some((reference.consistency_long, measures.consistency_long)),
        Some((reference.coverage, measures.coverage)),
        Some((reference.colour, measures.colour)),
        thresholds,
    );
    measure_s += t.elapsed().as_secs_f64();
    Ok(TrialOutcome {
        prepare_s,
        measure_s,
        optimised: session.optimised_count(),
        checkpoints: out,
        losses,
        steps,
        stability,
        result,
        evaluator,
    })
}
