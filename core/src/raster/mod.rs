//! The differentiable tile-based CPU splat rasterizer.
//!
//! The semantics are those of the golden reference (`golden/README.md` of the
//! shared data) and of the original 3DGS rasterizer:
//!
//! - colour `max(0, 0.5 + SH·Y(d))`, `d` the unit direction from the camera
//!   centre to the mean (real SH basis of 3DGS, degree 0 to 3);
//! - EWA splatting `Σ2D = J W Σ Wᵀ Jᵀ + 0.3·I`, with `x/z` and `y/z` clamped to
//!   `±1.3·tan(half-fov)` inside the Jacobian;
//! - `α = min(0.99, σ(o)·exp(power))`, a Gaussian skipped at a pixel where
//!   `power > 0` or `α < 1/255`, and everywhere when `z ≤ 0.2`;
//! - front-to-back compositing by camera `z`, stopping before the Gaussian that
//!   would bring the transmittance below `1e-4`; `inv_depth = Σ wᵢ/zᵢ`,
//!   `alpha = Σ wᵢ`, background added as `T_final · bg`.
//!
//! Why the culling is exact rather than a 3σ box: each Gaussian covers the
//! ellipse `½ dᵀΣ2D⁻¹d ≤ ln(255·σ(o))`, which is precisely the set of pixels
//! where its α can reach 1/255, so the tiled result equals the dense one
//! (the [`dense`] module) and the independent reference, not just nearly.
//!
//! The fast path ([`forward()`], [`backward()`]) works in `f32` on 16×16 tiles:
//! project and cull in parallel, sort the splats once by depth, bin them into
//! the tiles their ellipse reaches, and composite the tiles in parallel, each
//! splat visiting only the pixels of its ellipse, row by row. The backward
//! pass walks each pixel's list in reverse as the 3DGS CUDA kernel does,
//! accumulates per (tile, Gaussian) pair without sharing, reduces per
//! Gaussian, then runs the per-Gaussian chain (conic → covariance →
//! quaternion/scale, projection, SH) in parallel.
//!
//! `f32` and `f64` can only disagree where a pixel sits within rounding of a
//! cut-off (α at 1/255, T at 1e-4); the tests count such ties separately.
//! [`crate::golden`] loads the independent reference cases and compares against them
//! (the integration test and `gast check golden` share it).

mod backward;
pub mod dense;
mod forward;
mod project;
mod splat;
mod state;
mod visibility;

use crate::scene::Gaussians;

pub use backward::{backward, backward_sh};
pub use forward::{forward, render};
pub use state::ForwardState;
pub use visibility::{contributing, render_and_contributing};

/// Side of a square screen tile in pixels.
pub const TILE: u32 = 16;

/// Options that change what a render shows (not how it is computed).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RenderOptions {
    /// Background colour, linear RGB in `[0, 1]`, added as `T_final · background`.
    pub background: [f32; 3],
}

impl Default for RenderOptions {
    /// A black background.
    fn default() -> Self {
        Self { background: [0.0; 3] }
    }
}

/// A rendered image with its inverse depth and opacity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Render {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Colour, `height × width × 3`, row-major.
    pub rgb: Vec<f32>,
    /// Expected inverse depth `Σ wᵢ/zᵢ`, `height × width`.
    pub inv_depth: Vec<f32>,
    /// Accumulated opacity `Σ wᵢ = 1 − T_final`, `height × width`.
    pub alpha: Vec<f32>,
}

impl Render {
    /// A black image with zero depth and opacity.
    pub fn zeros(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self { width, height, rgb: vec![0.0; 3 * n], inv_depth: vec![0.0; n], alpha: vec![0.0; n] }
    }
}

/// Gradients of a scalar loss with respect to every Gaussian parameter, in the
/// layout of [`Gaussians`]; `v_sh` holds the first coefficients of each
/// Gaussian that were asked for ([`ShGrads`]): all of `Gaussians::sh` from
/// [`backward()`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Grads {
    /// Gradient w.r.t. `Gaussians::means`.
    pub v_means: Vec<[f32; 3]>,
    /// Gradient w.r.t. `Gaussians::log_scales`.
    pub v_log_scales: Vec<[f32; 3]>,
    /// Gradient w.r.t. `Gaussians::quats` (the unnormalised quaternions).
    pub v_quats: Vec<[f32; 4]>,
    /// Gradient w.r.t. `Gaussians::opacity_logits`.
    pub v_opacity_logits: Vec<f32>,
    /// Gradient w.r.t. the SH coefficients asked for, per Gaussian (`3 ×
    /// coefficients` each, in the order of `Gaussians::sh`).
    pub v_sh: Vec<f32>,
}

/// Which SH coefficients' gradients a backward pass writes: the others are
/// neither computed nor held (a stylization steps the DC colour only, so a
/// scene of degree 3 would otherwise hold 16 times the gradient it uses).
/// The view direction's gradient through the colour, part of the means',
/// counts every coefficient whichever is asked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShGrads {
    /// Every coefficient (fitting, the golden checks).
    All,
    /// The DC coefficient (`Gaussians::sh`'s first three values of each Gaussian).
    Dc,
    /// None: a step that updates no colour.
    Skip,
}

impl ShGrads {
    /// Coefficients per Gaussian (each three values) for a scene of `g`'s degree.
    pub fn coefficients(self, g: &Gaussians) -> usize {
        self.for_degree(g.sh_degree)
    }

    /// Coefficients per Gaussian (each three values) for a scene of SH degree `degree`.
    pub fn for_degree(self, degree: u32) -> usize {
        match self {
            Self::All => crate::scene::sh_coeffs_for_degree(degree),
            Self::Dc => 1,
            Self::Skip => 0,
        }
    }
}

impl Grads {
    /// Zero gradients shaped like `g`.
    pub fn zeros_like(g: &Gaussians) -> Self {
        Self::zeros_for(g, ShGrads::All)
    }

    /// Zero gradients for `g` with the SH coefficients `sh`.
    pub fn zeros_for(g: &Gaussians, sh: ShGrads) -> Self {
        let n = g.len();
        Self {
            v_means: vec![[0.0; 3]; n],
            v_log_scales: vec![[0.0; 3]; n],
            v_quats: vec![[0.0; 4]; n],
            v_opacity_logits: vec![0.0; n],
            v_sh: vec![0.0; n * 3 * sh.coefficients(g)],
        }
    }
}

#[cfg(test)]
mod tests;
