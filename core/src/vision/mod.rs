//! Image operations the style engine needs around the VGG network: Canny edges
//! as OpenCV computes them, the JET colour map, area and bilinear resizing (with
//! the adjoint of the bilinear one), and style-image depth.
//!
//! Images are row-major HWC `f32` unless a function says otherwise; the golden
//! files and the rasterizer use the same layout.

pub mod canny;
pub mod colormap;
pub mod resize;
pub mod style_depth;
