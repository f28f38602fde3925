//! Gaussian-splat scenes as struct-of-arrays, and the file formats they come in.
//!
//! One layout for every format: the rasterizer, the optimiser and the writers all
//! read the same flat arrays, and each reader converts into it once. SH
//! coefficients are stored band-major per Gaussian, `(N, (deg+1)², 3)`, the layout
//! of the golden files; the INRIA `.ply` stores `f_rest_*` channel-major and the
//! reader/writer transpose.

mod error;

pub use error::SceneError;

/// SH basis constant of band 0: rendered colour is `0.5 + C0 · c_0 + …`.
pub const SH_C0: f32 = 0.282_094_8;

/// Number of SH coefficients per colour channel for a degree (1, 4, 9, 16).
pub const fn sh_coeffs_for_degree(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// A set of 3D Gaussians, struct-of-arrays.
///
/// All arrays have `len()` entries except `sh`, which holds
/// `len() · sh_coeffs() · 3` floats laid out `[gaussian][coefficient][channel]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    /// Centres in world space.
    pub means: Vec<[f32; 3]>,
    /// Natural logarithm of the per-axis standard deviations.
    pub log_scales: Vec<[f32; 3]>,
    /// Rotations as quaternions (w, x, y, z); not necessarily normalised.
    pub quats: Vec<[f32; 4]>,
    /// Opacity before the sigmoid.
    pub opacity_logits: Vec<f32>,
    /// SH degree, 0 to 3.
    pub sh_degree: u32,
    /// SH coefficients, `[gaussian][coefficient][channel]`, `(deg+1)²` coefficients.
    pub sh: Vec<f32>,
}

impl Gaussians {
    /// An empty set with room for `n` Gaussians of the given SH degree.
    pub fn with_capacity(n: usize, sh_degree: u32) -> Self {
        Self {
            means: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            quats: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            sh_degree,
            sh: Vec::with_capacity(n * sh_coeffs_for_degree(sh_degree) * 3),
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per channel, `(sh_degree + 1)²`.
    pub fn sh_coeffs(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree)
    }

    /// The SH coefficients of Gaussian `i`, `sh_coeffs() · 3` floats.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let k = self.sh_coeffs() * 3;
        &self.sh[i * k..(i + 1) * k]
    }

    /// Checks that every array has the length the Gaussian count implies.
    pub fn check_consistent(&self) -> Result<(), String> {
        let n = self.len();
        let want_sh = n * self.sh_coeffs() * 3;
        if self.log_scales.len() != n
            || self.quats.len() != n
            || self.opacity_logits.len() != n
            || self.sh.len() != want_sh
            || self.sh_degree > 3
        {
            return Err(format!(
                "inconsistent arrays: {n} means, {} scales, {} quats, {} opacities, {} SH floats (want {want_sh}), degree {}",
                self.log_scales.len(),
                self.quats.len(),
                self.opacity_logits.len(),
                self.sh.len(),
                self.sh_degree
            ));
        }
        Ok(())
    }
}
