//! Vision: the VGG feature extractor that the style losses compare images with.
//!
//! GAST measures style and content in the relu3 feature space of an
//! ImageNet-trained VGG (ALGORITHM.md, Stage 1 and the GCFM loss). This module
//! finds and loads those weights ([`weights`], [`download`]), and runs the
//! network forward and backward on the CPU ([`vgg`]).

mod conv;
pub mod download;
mod pth;
pub mod vgg;
pub mod weights;

pub use download::resolve_weights;
pub use vgg::{Features, Vgg, VggState};
pub use weights::{VggWeights, WeightsError};
