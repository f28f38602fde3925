//! The style engine's losses: Stage 0 colour transfer, the GCFM contrastive
//! feature matching, content, total variation and the geometry regularisers,
//! each with its gradient, and the per-step loss that ties them to the VGG
//! features of the rendered maps.
//!
//! Definitions follow `ALGORITHM.md` of the shared data; the golden numbers in
//! `golden/losses_seed1.safetensors` check them (see `tests/losses_golden.rs`).

pub mod color_transfer;
pub mod content;
pub mod gcfm;
pub mod regularizers;
pub mod stage1;
pub mod step;
pub mod tv;

pub use color_transfer::ColorTransfer;
pub use gcfm::{GcfmOutput, Matches, StyleFeatures};
pub use stage1::{StyleMaps, style_maps};
pub use step::{FeatureNet, LossWeights, RenderedMaps, StepLoss, StyleTargets, step_loss};
