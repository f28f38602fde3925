//! One stylization run: configuration in, events and snapshots out.
//!
//! A front end (the studio's worker thread or the CLI) drives a session; the
//! session never drives a viewer. Small [`Event`]s go out on a crossbeam channel,
//! the newest Gaussians go into a latest-value [`Slot`], and [`Command`]s come in
//! between steps.

mod colour_watch;
mod cpu_state;
mod events;
pub mod moments;
pub mod plan;
mod prepare;
mod run;
mod slot;
pub mod split;
mod stage1_cache;
mod style_image;
mod view_target;
mod worker;

pub use colour_watch::{ColourReading, ColourWatch};
pub use events::{Command, Event, LossTerms, StepReport, StepTimings};
pub use moments::OptimiserState;
pub use prepare::{
    PreparedStyle, ResolvedDepth, StyleDepthSource, StyleImage, ViewSurvey, prepare_style, scatter, subset,
    survey_views,
};
pub use run::{Session, SessionError, SessionInputs};
pub use slot::Slot;
pub use stage1_cache::{CacheOutcome, Stage1Cache, depth_key};
pub use worker::{
    KEEP_SHARE, KeepWrite, Keeper, ResumeFrom, RunOptions, SessionHandle, run_loop, spawn, spawn_run, spawn_with,
};

use crate::camera::Camera;
use crate::style::{StyleConfig, StyleMaps};

/// The newest state of the Gaussians, for viewers and exports.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// Steps done when the snapshot was taken.
    pub step: u32,
    /// The whole scene (Gaussians set aside by culling included).
    pub gaussians: crate::Gaussians,
}

/// Where a prepared run starts from, published once by the worker right after
/// preparation: what a front end needs, beside the newest [`Snapshot`], to
/// draw the run's before / colour-matched / after pictures (the contact sheet).
#[derive(Clone, Debug)]
pub struct RunStart {
    /// The colour-matched scene before optimisation (`G^c`, whole).
    pub colour_matched: crate::Gaussians,
    /// The optimisation cameras at the working resolution.
    pub cameras: Vec<Camera>,
    /// The style's maps at texture scale.
    pub style_maps: StyleMaps,
    /// The parameters the run started with.
    pub config: StyleConfig,
    /// Mean share of the optimisation views' pixels the input scene covers.
    pub coverage: f32,
    /// Whether the losses focus on the object (`auto` resolved).
    pub focus_on_object: bool,
}

impl RunStart {
    /// The start of a prepared session.
    pub fn of(session: &Session) -> Self {
        Self {
            colour_matched: session.colour_matched(),
            cameras: session.cameras().to_vec(),
            style_maps: session.style().maps.clone(),
            config: session.config().clone(),
            coverage: session.coverage(),
            focus_on_object: session.focus_on_object(),
        }
    }
}
