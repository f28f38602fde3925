//! The GPU rasterizer's backward pass (`shaders/raster_backward.wgsl`, then
//! `raster_project.wgsl`'s `project_backward`): reverse compositing per tile
//! to each Gaussian's screen-space gradient, accumulated with atomic adds,
//! then the per-Gaussian chain to the parameter gradients. The CPU twin is
//! `raster/backward.rs`; float atomics make the sum order vary, so the two
//! agree to rounding, not bit for bit.
//!
//! `raster_kernels.rs` compiles every raster kernel (this file's
//! `tile_backward` among them, for the device's accumulation) and this file
//! runs the backward ones on the forward pass's workspace.

use super::Commands;
use super::raster_forward::GpuRaster;
use super::raster_kernels::RasterKernels;
use super::raster_project::WORKGROUP;
use super::{GpuContext, GpuGaussians, GpuGrads, Kernel};
use crate::raster::TILE;

impl GpuRaster {
    /// Records the backward pass of the last recorded [`GpuRaster::forward`]
    /// (same Gaussians, camera and options) given `v_rgb = ∂L/∂rgb` (H·W·3)
    /// and `v_inv_depth = ∂L/∂inv_depth` (H·W). Every entry of `grads` is
    /// written: zero for Gaussians that no pixel composited; of the SH
    /// coefficients, those of the workspace's [`GpuRaster::with_grad_sh`].
    ///
    /// # Panics
    /// When `grads` holds other SH coefficients than the workspace writes (a caller bug).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut dyn Commands,
        g: &GpuGaussians,
        v_rgb: &wgpu::Buffer,
        v_inv_depth: &wgpu::Buffer,
        grads: &GpuGrads,
    ) {
        self.backward_tiles(ctx, k, encoder, v_rgb, v_inv_depth);
        self.backward_gaussians(ctx, k, encoder, g, grads);
    }

    /// The first half of [`GpuRaster::backward`]: reverse compositing to the splats' gradients.
    pub(crate) fn backward_tiles(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut dyn Commands,
        v_rgb: &wgpu::Buffer,
        v_inv_depth: &wgpu::Buffer,
    ) {
        encoder.encoder().clear_buffer(&self.v_splat, 0, None);
        k.tile_backward.dispatch(
            ctx,
            encoder,
            &[
                &self.uniform,
                &self.pair_values,
                &self.order,
                &self.splats,
                &self.ranges,
                &self.px_state,
                v_rgb,
                v_inv_depth,
                &self.v_splat,
            ],
            [self.width.div_ceil(TILE), self.height.div_ceil(TILE), self.splits],
        );
    }

    /// The second half of [`GpuRaster::backward`]: splat gradients to parameter gradients.
    pub(crate) fn backward_gaussians(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut dyn Commands,
        g: &GpuGaussians,
        grads: &GpuGrads,
    ) {
        assert_eq!(
            grads.sh_coeffs,
            self.grad_sh.for_degree(g.sh_degree),
            "GpuRaster::backward: the gradients hold other SH coefficients than {:?}",
            self.grad_sh
        );
        k.project.backward.dispatch(
            ctx,
            encoder,
            &[
                &self.uniform,
                &g.means,
                &g.log_scales,
                &g.quats,
                &g.opacity_logits,
                &g.sh,
                &self.v_splat,
                &grads.v_means,
                &grads.v_log_scales,
                &grads.v_quats,
                &grads.v_opacity_logits,
                &grads.v_sh,
            ],
            Kernel::groups_1d(self.n, WORKGROUP),
        );
    }
}
