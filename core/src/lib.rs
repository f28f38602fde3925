//! GAST core: everything the studio and the command line compute, with no UI.
//!
//! Geometry-aware style transfer on 3D Gaussian Splatting scenes, as described
//! in `ALGORITHM.md` of the shared data: scenes and cameras in the formats users
//! bring, differentiable tile-based rasterizers, VGG features, the losses and
//! the decoupled colour/geometry optimisation, on the CPU and (`gpu`) on wgpu.

pub mod camera;
pub mod eval;
pub mod fit;
pub mod golden;
pub mod gpu;
pub mod io;
pub mod raster;
pub(crate) mod rng;
pub mod scene;
pub mod session;
pub mod settings;
pub mod stats;
pub mod style;
pub mod vision;

pub use camera::Camera;
pub use scene::Gaussians;
