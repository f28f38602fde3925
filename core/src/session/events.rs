//! The small typed messages between a running session and its front end.
//!
//! Commands go in (pause, resume, stop, new parameters), events come out (one
//! per step, plus stage changes, warnings and the end). Both are small; the
//! Gaussians themselves travel through the snapshot [`Slot`](super::Slot).

use serde::{Deserialize, Serialize};

pub use crate::style::terms::LossTerms;
use crate::style::{Phase, StyleConfig};

/// What a front end asks of a running session; applied between steps.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Stop stepping until `Resume`.
    Pause,
    /// Pause once this many more steps are done (as `Pause` then), however
    /// late the sender would have seen them: a scripted run's exact pause.
    PauseAfter(u32),
    /// Continue after `Pause`.
    Resume,
    /// End the run after the current step (the result so far is kept).
    Stop,
    /// Use new parameters from the next step on (weights, rates, ratio, cycles, mode).
    SetConfig(Box<StyleConfig>),
}

/// Time spent in each part of a step, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StepTimings {
    /// Rasterizer forward.
    pub render_ms: f32,
    /// Edge map, downscale, VGG forward of the rendered maps.
    pub features_ms: f32,
    /// Nearest/farthest matching and the feature-space losses.
    pub matching_ms: f32,
    /// VGG backward of the rendered maps.
    pub vgg_backward_ms: f32,
    /// Rasterizer backward.
    pub raster_backward_ms: f32,
    /// Regularisers and Adam.
    pub update_ms: f32,
    /// The assignment terms' host pairing (cost matrix, assignment, pulls);
    /// on the CPU part of `matching_ms`, on the GPU engine host work the
    /// device's GCFM search (and on geometry steps the depth's backward
    /// pass) runs beside.
    #[serde(default)]
    pub pairing_ms: f32,
    /// GPU engine: how long the host waited on the device within the step
    /// (for the gathered columns the pairing reads, and for the step's
    /// scalars at its end). 0 on the CPU.
    #[serde(default)]
    pub device_wait_ms: f32,
    /// GPU engine: the host recording the step's commands (the rest of the
    /// step's host time beside the pairing, the waits and the submits). 0 on
    /// the CPU.
    #[serde(default)]
    pub record_ms: f32,
    /// GPU engine: handing the step's command buffers to the queue. 0 on the CPU.
    #[serde(default)]
    pub submit_ms: f32,
    /// GPU engine: bind groups the step made (the others kept from earlier steps). 0 on the CPU.
    #[serde(default)]
    pub bind_groups: u32,
    /// GPU engine: compute passes the step's dispatches ran in. 0 on the CPU.
    #[serde(default)]
    pub passes: u32,
}

/// One optimisation step's report.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepReport {
    /// Step index from 0.
    pub iter: u32,
    /// Total steps of the run.
    pub total: u32,
    /// Cycle index from 0.
    pub cycle: u32,
    /// Phase of the step.
    pub phase: Phase,
    /// The view used.
    pub view: u32,
    /// Loss terms.
    pub losses: LossTerms,
    /// Where the time went.
    pub timings: StepTimings,
    /// Seconds since the optimisation started (pauses excluded).
    pub elapsed_s: f64,
    /// The object's colour against the colour-matched state's
    /// ([`super::ColourWatch`]); `None` before any view is read.
    pub colour: Option<super::ColourReading>,
}

/// What a running session reports.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A preparation stage finished (`name`, seconds it took).
    Stage {
        /// Stage name (colour matching, style features, culling, …).
        name: String,
        /// Seconds.
        seconds: f64,
    },
    /// Gaussians that no optimisation camera sees were set aside (kept in the export).
    Culled {
        /// Gaussians in the scene.
        total: usize,
        /// Gaussians being optimised.
        kept: usize,
    },
    /// The run was planned to a time budget: the seconds a step is expected
    /// to take, which an estimate of the time left can use until the steps'
    /// own pace is known (each view's first step also makes its targets).
    Planned {
        /// Expected seconds a step.
        seconds_per_step: f64,
    },
    /// One step done.
    Step(StepReport),
    /// Something the user should know that does not stop the run.
    Warning(String),
    /// The run is paused.
    Paused,
    /// The run resumed.
    Resumed,
    /// New parameters were taken.
    ConfigApplied,
    /// The run ended: all steps done (`completed`) or stopped early.
    Finished {
        /// Whether every scheduled step ran.
        completed: bool,
        /// Steps run.
        steps: u32,
        /// Seconds of optimisation.
        seconds: f64,
    },
    /// The run could not continue.
    Failed(String),
}
