//! The style engine: colour transfer, the losses, the optimiser and its schedule.

pub mod adam;
pub mod config;
pub mod schedule;

pub use config::StyleConfig;
pub use schedule::{Mode, Phase, Schedule};
