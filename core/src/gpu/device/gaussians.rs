//! The Gaussians' parameters and their gradients as device buffers, in the
//! layouts of [`crate::scene::Gaussians`] and [`crate::raster::Grads`]: the
//! optimiser updates them in place, the rasterizer reads and writes them,
//! and they come back to the host only for snapshots and exports.

use super::{GpuContext, GpuError};
use crate::raster::{Grads, ShGrads};
use crate::scene::Gaussians;

/// One buffer per parameter group: `means` (N·3), `log_scales` (N·3), `quats`
/// (N·4), `opacity_logits` (N), `sh` (N·(deg+1)²·3).
#[derive(Debug)]
pub struct GpuGaussians {
    /// Number of Gaussians.
    pub len: usize,
    /// SH degree, 0 to 3.
    pub sh_degree: u32,
    /// Centres, `[x, y, z]` per Gaussian.
    pub means: wgpu::Buffer,
    /// Log standard deviations, three per Gaussian.
    pub log_scales: wgpu::Buffer,
    /// Quaternions `(w, x, y, z)`, unnormalised.
    pub quats: wgpu::Buffer,
    /// Opacity logits.
    pub opacity_logits: wgpu::Buffer,
    /// SH coefficients, `[gaussian][coefficient][channel]`.
    pub sh: wgpu::Buffer,
}

impl GpuGaussians {
    /// Uploads `g`.
    pub fn upload(ctx: &GpuContext, g: &Gaussians) -> Self {
        Self {
            len: g.len(),
            sh_degree: g.sh_degree,
            means: ctx.upload("gaussians.means", &g.means),
            log_scales: ctx.upload("gaussians.log_scales", &g.log_scales),
            quats: ctx.upload("gaussians.quats", &g.quats),
            opacity_logits: ctx.upload("gaussians.opacity_logits", &g.opacity_logits),
            sh: ctx.upload("gaussians.sh", &g.sh),
        }
    }

    /// Overwrites the parameters with `g`'s, which must have as many
    /// Gaussians and the same SH degree (the caller checks: a resumed run's
    /// state, [`crate::session::Session::resume_at`]).
    pub fn write(&self, ctx: &GpuContext, g: &Gaussians) {
        debug_assert!(g.len() == self.len && g.sh_degree == self.sh_degree);
        ctx.write(&self.means, &g.means);
        ctx.write(&self.log_scales, &g.log_scales);
        ctx.write(&self.quats, &g.quats);
        ctx.write(&self.opacity_logits, &g.opacity_logits);
        ctx.write(&self.sh, &g.sh);
    }

    /// SH coefficients per colour channel.
    pub fn sh_coeffs(&self) -> usize {
        crate::scene::sh_coeffs_for_degree(self.sh_degree)
    }

    /// Reads the parameters back.
    pub fn download(&self, ctx: &GpuContext) -> Result<Gaussians, GpuError> {
        let n = self.len;
        let k = self.sh_coeffs() * 3;
        Ok(Gaussians {
            means: read_rows(ctx, &self.means, n)?,
            log_scales: read_rows(ctx, &self.log_scales, n)?,
            quats: read_rows(ctx, &self.quats, n)?,
            opacity_logits: read_flat(ctx, &self.opacity_logits, n)?,
            sh_degree: self.sh_degree,
            sh: read_flat(ctx, &self.sh, n * k)?,
        })
    }
}

/// Gradients shaped like [`GpuGaussians`] (`v_means`, …), which the
/// rasterizer's backward pass writes.
#[derive(Debug)]
pub struct GpuGrads {
    /// Number of Gaussians.
    pub len: usize,
    /// SH coefficients per channel held (the first ones of each Gaussian:
    /// all of the scene's, or the DC alone).
    pub sh_coeffs: usize,
    /// `∂L/∂means`, N·3.
    pub v_means: wgpu::Buffer,
    /// `∂L/∂log_scales`, N·3.
    pub v_log_scales: wgpu::Buffer,
    /// `∂L/∂quats`, N·4.
    pub v_quats: wgpu::Buffer,
    /// `∂L/∂opacity_logits`, N.
    pub v_opacity_logits: wgpu::Buffer,
    /// `∂L/∂sh` of the coefficients held, N·`sh_coeffs`·3.
    pub v_sh: wgpu::Buffer,
}

impl GpuGrads {
    /// Gradient buffers for `g`, every SH coefficient's (contents unspecified
    /// until a backward pass writes them).
    pub fn new(ctx: &GpuContext, g: &GpuGaussians) -> Self {
        Self::with_sh(ctx, g, ShGrads::All)
    }

    /// Gradient buffers for `g` holding the SH coefficients `sh` (a
    /// stylization: the DC, 16 times less than all of a degree-3 scene's),
    /// for a [`GpuRaster`](crate::gpu::GpuRaster) made [`with_grad_sh`](crate::gpu::GpuRaster::with_grad_sh) the same.
    pub fn with_sh(ctx: &GpuContext, g: &GpuGaussians, sh: ShGrads) -> Self {
        let n = g.len;
        let sh_coeffs = sh.for_degree(g.sh_degree);
        Self {
            len: n,
            sh_coeffs,
            v_means: ctx.zeros("grads.v_means", 3 * n),
            v_log_scales: ctx.zeros("grads.v_log_scales", 3 * n),
            v_quats: ctx.zeros("grads.v_quats", 4 * n),
            v_opacity_logits: ctx.zeros("grads.v_opacity_logits", n),
            v_sh: ctx.zeros("grads.v_sh", n * sh_coeffs * 3),
        }
    }

    /// Reads the gradients back.
    pub fn download(&self, ctx: &GpuContext) -> Result<Grads, GpuError> {
        let n = self.len;
        Ok(Grads {
            v_means: read_rows(ctx, &self.v_means, n)?,
            v_log_scales: read_rows(ctx, &self.v_log_scales, n)?,
            v_quats: read_rows(ctx, &self.v_quats, n)?,
            v_opacity_logits: read_flat(ctx, &self.v_opacity_logits, n)?,
            v_sh: read_flat(ctx, &self.v_sh, n * self.sh_coeffs * 3)?,
        })
    }
}

/// The first `len` floats of `buffer`.
fn read_flat(ctx: &GpuContext, buffer: &wgpu::Buffer, len: usize) -> Result<Vec<f32>, GpuError> {
    if len == 0 {
        return Ok(Vec::new());
    }
    ctx.read_range(buffer, 0, (len * 4) as u64)
}

/// The first `rows` rows of `W` floats of `buffer`.
fn read_rows<const W: usize>(ctx: &GpuContext, buffer: &wgpu::Buffer, rows: usize) -> Result<Vec<[f32; W]>, GpuError> {
    let flat = read_flat(ctx, buffer, rows * W)?;
    Ok(flat.chunks_exact(W).map(|c| std::array::from_fn(|i| c[i])).collect())
}
