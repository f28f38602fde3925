//! The style engine: Stage 0 colour transfer, the style-side maps (Stage 1),
//! the GCFM contrastive feature matching, content, total variation and the
//! geometry regularisers (each with its gradient), the per-step loss that ties
//! them to the VGG features of the rendered maps, and the optimiser with its
//! K-cycle schedule.
//!
//! Definitions follow `ALGORITHM.md` of the shared data; the golden numbers in
//! `golden/losses_seed1.safetensors` and `golden/color_seed1.safetensors` check them.

pub mod adam;
pub mod assignment;
pub mod color_transfer;
pub mod config;
pub mod content;
pub mod distinct;
pub mod feature_mean;
pub mod focus;
pub mod gcfm;
pub mod matching;
pub mod min_cost;
pub mod outside;
pub mod palette;
pub mod regularizers;
pub mod relief;
pub mod schedule;
pub mod sliced;
pub mod stage1;
pub mod step;
pub mod terms;
pub mod tv;
pub mod window;

pub use color_transfer::ColorTransfer;
pub use config::{DC_FLOOR, RESOLUTIONS, StyleConfig, TEXTURE_SCALES};
pub use feature_mean::MeanSteps;
pub use focus::Focus;
pub use gcfm::{GcfmOutput, Matches, StyleFeatures};
pub use matching::{MatchIndex, MatchMethod, MatchingConfig};
pub use schedule::{Mode, Phase, Schedule};
pub use stage1::{StyleMaps, style_maps};
pub use step::{FeatureNet, LossFocus, RenderedMaps, StepLoss, StyleTargets, step_loss, step_loss_masked};
