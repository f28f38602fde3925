//! The content loss on the GPU (`shaders/content.wgsl`): the mean squared
//! difference between the render's features and the colour-matched scene's
//! from the same view, as [`crate::style::content::content_loss_masked`]:
//! over the feature positions a [`GpuFocus`] covers (every one for the frame),
//! whose count the kernel reads from the device. A target may hold the
//! covered positions' columns alone ([`ContentColumns`]), as the CPU engine
//! keeps with the object focus.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, GpuFocus, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};

/// Threads per workgroup in `content.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `content.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ContentParams {
    n: u32,
    positions: u32,
    weight: f32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<ContentParams>() == 16);

/// Where a content target's columns lie (`content.wgsl`'s `columns`): for
/// each feature position its column in the target, [`ContentColumns::NONE`]
/// where it has none, then the number of columns.
pub struct ContentColumns;

impl ContentColumns {
    /// A position the target holds no column of.
    pub const NONE: u32 = u32::MAX;

    /// The columns of a target holding the positions `kept` (ascending) of
    /// `positions`.
    pub fn of(kept: &[u32], positions: usize) -> Vec<u32> {
        let mut out = vec![Self::NONE; positions + 1];
        for (column, &p) in kept.iter().enumerate() {
            out[p as usize] = column as u32;
        }
        out[positions] = kept.len() as u32;
        out
    }

    /// The columns of a whole map: every position its own.
    pub fn whole(positions: usize) -> Vec<u32> {
        (0..=positions as u32).collect()
    }
}

/// The content loss of `n`-float feature maps: its kernel, scratch and reduction.
#[derive(Debug)]
pub struct ContentLoss {
    kernel: Kernel,
    n: usize,
    positions: usize,
    uniform: wgpu::Buffer,
    sq: wgpu::Buffer,
    /// [`ContentColumns::whole`]: the columns of a whole-map target.
    whole: wgpu::Buffer,
    reduction: Reduction,
}

impl ContentLoss {
    /// Plans the loss over `n`-float feature maps of `positions` positions
    /// (channel-major) with weight `weight`, its unweighted value going to
    /// `scalars[loss_offset]`.
    pub fn new(
        ctx: &GpuContext,
        reduce: &Arc<ReduceKernels>,
        n: usize,
        positions: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let positions = positions.max(1);
        let kernel = Kernel::new(
            ctx,
            "content",
            include_str!("../../../../shaders/content.wgsl"),
            "content",
            &[
                Bind::Uniform,
                Bind::Read,
                Bind::Read,
                Bind::ReadWrite,
                Bind::ReadWrite,
                Bind::Read,
                Bind::Read,
                Bind::Read,
            ],
        );
        Ok(Self {
            kernel,
            n,
            positions,
            uniform: ctx.uniform("content.params", &Self::params(n, positions, weight)),
            sq: ctx.zeros("content.sq", n),
            whole: ctx.upload("content.whole", &ContentColumns::whole(positions)),
            reduction: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, n).to(loss_offset))?,
        })
    }

    fn params(n: usize, positions: usize, weight: f32) -> ContentParams {
        ContentParams { n: n as u32, positions: positions as u32, weight, _pad: 0 }
    }

    /// Changes λ (from the next submission on).
    pub fn set_weight(&self, ctx: &GpuContext, weight: f32) {
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&Self::params(self.n, self.positions, weight)));
    }

    /// Records, over the positions `focus` covers, `v_features += λ·2(f − t)/count`
    /// and `scalars[loss_offset] = mean((f − t)²)` (`count` = covered positions × channels).
    /// `columns` places the target's columns ([`ContentColumns::of`]; a whole map without).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        features: &wgpu::Buffer,
        target: &wgpu::Buffer,
        columns: Option<&wgpu::Buffer>,
        focus: &GpuFocus,
        v_features: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let groups = Kernel::groups_1d(self.n, WORKGROUP);
        let columns = columns.unwrap_or(&self.whole);
        let b = [&self.uniform, features, target, v_features, &self.sq, focus.cells(), focus.counts(), columns];
        self.kernel.dispatch(ctx, encoder, &b, groups);
        self.reduction.record(ctx, encoder, &self.sq, scalars);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{cells_focus, ctx, noise};
    use crate::style::content::content_loss_masked;
    use crate::style::focus::gather_positions;

    #[test]
    fn matches_the_cpu_content_loss_and_accumulates() {
        let ctx = ctx();
        let reduce = ReduceKernels::new(ctx);
        for (c, positions, masked) in
            [(1usize, 1usize, false), (7, 111, false), (11, 6_364, false), (7, 111, true), (11, 6_364, true)]
        {
            let n = c * positions;
            let (f, t, g0) = (noise(n, 1), noise(n, 2), noise(n, 3));
            let cells: Vec<bool> = noise(positions, 4).iter().map(|&v| !masked || v > 0.2).collect();
            let loss = ContentLoss::new(ctx, &reduce, n, positions, 0.5, 3).expect("plan");
            let (fb, tb, gb) = (ctx.upload("f", &f), ctx.upload("t", &t), ctx.upload("g", &g0));
            let focus = cells_focus(ctx, &cells);
            let scalars = ctx.upload("scalars", &noise(8, 4));
            ctx.write(&loss.sq, &noise(n, 5));
            let mut enc = ctx.encoder("content test");
            // The whole target, or the covered positions' columns alone.
            let kept: Vec<u32> = (0..positions as u32).filter(|&p| cells[p as usize]).collect();
            let part = gather_positions(&t, c, positions, &kept.iter().map(|&p| p as usize).collect::<Vec<_>>());
            let (pb, cb) = (ctx.upload("part", &part), ctx.upload("columns", &ContentColumns::of(&kept, positions)));
            let (target, columns) = if masked { (&pb, Some(&cb)) } else { (&tb, None) };
            loss.record(ctx, &mut enc, &fb, target, columns, &focus, &gb, &scalars);
            ctx.submit(enc);
            let (want, grad) = content_loss_masked(&f, &t, masked.then_some(cells.as_slice()));
            let got: Vec<f32> = ctx.read(&scalars).expect("scalars");
            assert!((got[3] - want).abs() <= 1e-5 * want.abs().max(1e-6), "n {n}: {} vs {want}", got[3]);
            let g: Vec<f32> = ctx.read(&gb).expect("grad");
            let worst = (0..n).map(|i| (g[i] - (g0[i] + 0.5 * grad[i])).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-6, "n {n}: gradient off by {worst}");
            for i in (0..n).filter(|i| !cells[i % positions]) {
                assert_eq!(g[i], g0[i], "n {n}: element {i} is outside the mask");
            }
        }
    }
}
