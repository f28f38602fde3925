//! Measures of a stylization, each with its formula and units, for reports,
//! benchmarks and the automatic detection of runs that went wrong.
//!
//! One file per concept, so each measure can be read and checked on its own:
//! - [`style`]: how close the render's VGG features are to the style's (Gram,
//!   mean–std, sliced Wasserstein, nearest-neighbour cosine);
//! - [`sliced`]: which part of a sliced Wasserstein distance moved (the mean,
//!   the shape, or only the features' lengths);
//! - [`content`]: how far the features moved from the colour-matched render;
//! - [`consistency`]: whether views agree once warped into each other;
//! - [`geometry`]: how much depth and surface orientation changed;
//! - [`stability`]: detectors of degenerate optimisation (NaN, exploding
//!   scales, vanishing opacity, Gaussians leaving the scene, inconsistency);
//! - [`measure`]: all of the above on one fixed ring of views, for comparing runs;
//! - [`trial`]: one run stepped to its budget and measured along the way.

pub mod consistency;
pub mod content;
pub mod depth_structure;
pub mod geometry;
pub mod measure;
pub mod sliced;
pub mod stability;
pub mod style;
pub mod trial;

pub use consistency::{Consistency, ViewPairs, pick_view_pairs, warp_consistency, warp_consistency_masked};
pub use content::{ContentDistance, content_distance, content_distance_masked};
pub use geometry::{NormalChange, depth_normals, inverse_depth_change, normal_change};
pub use measure::{EvalOptions, Evaluator, Measures};
pub use sliced::{SlicedBreakdown, SlicedParts};
pub use stability::{
    CoveredColour, Degeneration, DegenerationKind, StabilityReport, StabilityThresholds, assess_stability,
};
pub use style::{
    NearestStyle, StyleReference, gram_distance, gram_matrix, mean_std_distance, nn_cosine_distance,
    sliced_wasserstein_distance,
};
pub use trial::{Checkpoint, TrialOutcome, run_trial};
