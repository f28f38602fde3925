//! The feature-mean term on the GPU (`shaders/feature_mean.wgsl`): λ_mean's
//! twin of [`crate::style::feature_mean::feature_mean_loss`], over the feature
//! positions a [`GpuFocus`] covers (every one for the frame), whose count the
//! kernels read from the device.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, GpuFocus, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};

/// Threads per workgroup in `feature_mean.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `feature_mean.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct FeatureMeanParams {
    channels: u32,
    positions: u32,
    weight: f32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<FeatureMeanParams>() == 16);

/// The feature-mean term of `channels × positions` feature maps: its two
/// kernels, the per-channel scratch and the reduction.
#[derive(Debug)]
pub struct FeatureMeanLoss {
    means: Kernel,
    grad: Kernel,
    channels: usize,
    positions: usize,
    uniform: wgpu::Buffer,
    /// The style's per-channel means `μ^S` ([`crate::style::StyleFeatures::rgb_mean`]).
    style_mean: wgpu::Buffer,
    /// `μ_c − μ^S_c` per channel.
    dev: wgpu::Buffer,
    /// `(μ_c − μ^S_c)² / C` per channel, for the reduction.
    sq: wgpu::Buffer,
    reduction: Reduction,
}

impl FeatureMeanLoss {
    /// Plans the term over `channels × positions` feature maps (channel-major)
    /// against the style means `style_mean` with weight `weight`, its
    /// unweighted value going to `scalars[loss_offset]`.
    pub fn new(
        ctx: &GpuContext,
        reduce: &Arc<ReduceKernels>,
        style_mean: &[f32],
        positions: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let channels = style_mean.len().max(1);
        let positions = positions.max(1);
        let src = include_str!("../../../../shaders/feature_mean.wgsl");
        let binds = [
            Bind::Uniform,
            Bind::Read,
            Bind::Read,
            Bind::Read,
            Bind::Read,
            Bind::ReadWrite,
            Bind::ReadWrite,
            Bind::ReadWrite,
        ];
        let k = |entry: &str| Kernel::new(ctx, &format!("feature_mean.{entry}"), src, entry, &binds);
        Ok(Self {
            means: k("means"),
            grad: k("grad_add"),
            channels,
            positions,
            uniform: ctx.uniform("feature_mean.params", &Self::params(channels, positions, weight)),
            style_mean: ctx.upload("feature_mean.style_mean", style_mean),
            dev: ctx.zeros("feature_mean.dev", channels),
            sq: ctx.zeros("feature_mean.sq", channels),
            reduction: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, channels).to(loss_offset))?,
        })
    }

    fn params(channels: usize, positions: usize, weight: f32) -> FeatureMeanParams {
        FeatureMeanParams { channels: channels as u32, positions: positions as u32, weight, _pad: 0 }
    }

    /// Changes λ_mean (from the next submission on).
    pub fn set_weight(&self, ctx: &GpuContext, weight: f32) {
        let p = Self::params(self.channels, self.positions, weight);
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&p));
    }

    /// Records, over the positions `focus` covers, `v_features += λ·∂L/∂f`
    /// and `scalars[loss_offset] = L = (1/C) Σ_c (μ_c − μ^S_c)²`.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        features: &wgpu::Buffer,
        focus: &GpuFocus,
        v_features: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let b =
            [&self.uniform, features, focus.cells(), focus.counts(), &self.style_mean, &self.dev, &self.sq, v_features];
        self.means.dispatch(ctx, encoder, &b, [self.channels as u32, 1, 1]);
        self.grad.dispatch(ctx, encoder, &b, Kernel::groups_1d(self.channels * self.positions, WORKGROUP));
        self.reduction.record(ctx, encoder, &self.sq, scalars);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{check_masked_term, ctx, noise};
    use crate::style::feature_mean::feature_mean_loss;

    #[test]
    fn matches_the_cpu_feature_mean_term_and_accumulates() {
        let ctx = ctx();
        let reduce = ReduceKernels::new(ctx);
        for (c, positions, cover) in
            [(1usize, 1usize, 1.0f32), (7, 111, 1.0), (13, 6_364, 1.0), (7, 111, 0.3), (13, 6_364, 0.3), (5, 40, 0.0)]
        {
            let f = noise(c * positions, 1);
            let style_mean: Vec<f32> = noise(c, 2).iter().map(|v| 0.5 * v).collect();
            let cells: Vec<bool> = noise(positions, 4).iter().map(|&v| v.abs() < cover).collect();
            let loss = FeatureMeanLoss::new(ctx, &reduce, &style_mean, positions, 0.5, 3).expect("plan");
            let cpu = feature_mean_loss(&f, c, &style_mean, Some(&cells));
            check_masked_term(
                ctx,
                &format!("{c} × {positions}, cover {cover}"),
                &f,
                &cells,
                cpu,
                1e-5,
                |enc, fb, focus, gb, scalars| loss.record(ctx, enc, fb, focus, gb, scalars),
            );
        }
    }
}
