//! Vision: the VGG feature extractor that the style losses compare images
//! with, and the image operations around it.
//!
//! GAST measures style and content in the relu3 feature space of an
//! ImageNet-trained VGG (ALGORITHM.md, Stage 1 and the GCFM loss). This module
//! finds and loads those weights ([`weights`], [`download`]), and runs the
//! network forward and backward on the CPU ([`vgg`]), its convolutions by
//! im2col or by Winograd's minimal filtering ([`winograd`]). Around it: Canny edges as
//! OpenCV computes them ([`canny`]), the JET colour map ([`colormap`]), area and
//! bilinear resizing with the adjoint of the bilinear one ([`resize`]), and
//! style-image depth ([`style_depth`]).
//!
//! Images are row-major HWC `f32` unless a function says otherwise; the golden
//! files and the rasterizer use the same layout.

pub mod canny;
pub mod colormap;
mod conv;
pub mod depth;
pub mod download;
mod pth;
pub mod relief_depth;
pub mod relief_styles;
pub mod resize;
pub mod style_depth;
pub mod vgg;
pub mod vgg_cone;
pub mod weights;
mod weights_file;
pub mod winograd;

pub(crate) use conv::matmul;
pub use conv::{ConvAlgo, gemm_gflops};
pub use download::resolve_weights;
pub use vgg::{Features, Vgg, VggState};
pub use weights::{VggWeights, WeightsError};
