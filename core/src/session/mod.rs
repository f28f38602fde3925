//! One stylization run: configuration in, events and snapshots out.
//!
//! A front end (the studio's worker thread or the CLI) drives a session; the
//! session never drives a viewer. Small [`Event`]s go out on a crossbeam channel,
//! the newest Gaussians go into a latest-value [`Slot`], and [`Command`]s come in
//! between steps.

mod events;
mod prepare;
mod run;
mod slot;
mod stage1_cache;
mod worker;

pub use events::{Command, Event, LossTerms, StepReport, StepTimings};
pub use prepare::{
    PreparedStyle, ResolvedDepth, StyleDepthSource, StyleImage, ViewSurvey, prepare_style, scatter, subset,
    survey_views,
};
pub use run::{Session, SessionError, SessionInputs};
pub use slot::Slot;
pub use stage1_cache::{CacheOutcome, Stage1Cache, depth_key};
pub use worker::{SessionHandle, run_loop, spawn, spawn_with};

/// The newest state of the Gaussians, for viewers and exports.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// Steps done when the snapshot was taken.
    pub step: u32,
    /// The whole scene (Gaussians set aside by culling included).
    pub gaussians: crate::Gaussians,
}
