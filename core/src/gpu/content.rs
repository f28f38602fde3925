//! The content loss on the GPU (`shaders/content.wgsl`): the mean squared
//! difference between the render's features and the colour-matched scene's
//! from the same view, as [`crate::style::content::content_loss`].

use std::sync::Arc;

use super::{Bind, GpuContext, GpuError, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};

/// Threads per workgroup in `content.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `content.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ContentParams {
    n: u32,
    grad_scale: f32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<ContentParams>() == 16);

/// The content loss of `n`-float feature maps: its kernel, scratch and reduction.
#[derive(Debug)]
pub struct ContentLoss {
    kernel: Kernel,
    n: usize,
    uniform: wgpu::Buffer,
    sq: wgpu::Buffer,
    reduction: Reduction,
}

impl ContentLoss {
    /// Plans the loss over `n` features with weight `weight`, its unweighted
    /// value going to `scalars[loss_offset]`.
    pub fn new(
        ctx: &GpuContext,
        reduce: &Arc<ReduceKernels>,
        n: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let inv = if n > 0 { (1.0 / n as f64) as f32 } else { 0.0 };
        let kernel = Kernel::new(
            ctx,
            "content",
            include_str!("../../../shaders/content.wgsl"),
            "content",
            &[Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::ReadWrite],
        );
        Ok(Self {
            kernel,
            n,
            uniform: ctx.uniform("content.params", &Self::params(n, weight)),
            sq: ctx.zeros("content.sq", n),
            reduction: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, n).to(loss_offset).scaled(inv))?,
        })
    }

    fn params(n: usize, weight: f32) -> ContentParams {
        let scale = if n > 0 { (2.0 / n as f64) as f32 } else { 0.0 };
        ContentParams { n: n as u32, grad_scale: weight * scale, _pad: [0; 2] }
    }

    /// Changes λ (from the next submission on).
    pub fn set_weight(&self, ctx: &GpuContext, weight: f32) {
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&Self::params(self.n, weight)));
    }

    /// Records `v_features += λ·2(f − t)/n` and `scalars[loss_offset] = mean((f − t)²)`.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        features: &wgpu::Buffer,
        target: &wgpu::Buffer,
        v_features: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let groups = Kernel::groups_1d(self.n, WORKGROUP);
        self.kernel.dispatch(ctx, encoder, &[&self.uniform, features, target, v_features, &self.sq], groups);
        self.reduction.record(ctx, encoder, &self.sq, scalars);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::content::content_loss;

    #[test]
    fn matches_the_cpu_content_loss_and_accumulates() {
        let ctx = ctx();
        let reduce = ReduceKernels::new(ctx);
        for n in [1usize, 777, 70_001] {
            let (f, t, g0) = (noise(n, 1), noise(n, 2), noise(n, 3));
            let loss = ContentLoss::new(ctx, &reduce, n, 0.5, 3).expect("plan");
            let (fb, tb, gb) = (ctx.upload("f", &f), ctx.upload("t", &t), ctx.upload("g", &g0));
            let scalars = ctx.upload("scalars", &noise(8, 4));
            let mut enc = ctx.encoder("content test");
            loss.record(ctx, &mut enc, &fb, &tb, &gb, &scalars);
            ctx.submit(enc);
            let (want, grad) = content_loss(&f, &t);
            let got: Vec<f32> = ctx.read(&scalars).expect("scalars");
            assert!((got[3] - want).abs() <= 1e-5 * want.abs().max(1e-6), "n {n}: {} vs {want}", got[3]);
            let g: Vec<f32> = ctx.read(&gb).expect("grad");
            let worst = (0..n).map(|i| (g[i] - (g0[i] + 0.5 * grad[i])).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-6, "n {n}: gradient off by {worst}");
        }
    }
}
