//! The content loss on the GPU (`shaders/content.wgsl`), repeating
//! [`crate::style::content::content_loss`]: `mean((φ − φ_c)²)` between the
//! render's features and the colour-matched render's (the per-view target),
//! its gradient added onto the features' gradient that GCFM wrote, so the VGG
//! backward runs once for both. Two launches: the elementwise gradient with
//! one partial sum per workgroup, then one workgroup for the mean.

use super::kernel::Launch;
use super::{Bind, GpuContext, Kernel};

/// Threads per workgroup of `content.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `content.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct ContentParams {
    len: u32,
    parts: u32,
    out_off: u32,
    _pad0: u32,
    scale: f32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<ContentParams>() == 32);

/// The compiled kernels.
#[derive(Debug)]
pub struct GpuContent {
    accumulate: Kernel,
    finish: Kernel,
    dummy: wgpu::Buffer,
}

/// Partial sums and launch uniforms for one feature size, made once.
#[derive(Debug)]
pub struct ContentWorkspace {
    partial: wgpu::Buffer,
    accumulate: Launch,
    finish: Launch,
}

impl GpuContent {
    /// Compiles `content.wgsl`.
    pub fn new(ctx: &GpuContext) -> Self {
        let src = include_str!("../../../shaders/content.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::ReadWrite];
        Self {
            accumulate: Kernel::new(ctx, "content.accumulate", src, "accumulate", &binds),
            finish: Kernel::new(ctx, "content.finish", src, "finish", &binds),
            dummy: ctx.zeros("content.dummy", 1),
        }
    }

    /// Scratch for features of `len` values; the run writes the (unweighted)
    /// loss at `scalars_offset` (in `f32`s) and adds `scale` (the loss
    /// weight) times the gradient to the features' gradient.
    pub fn workspace(&self, ctx: &GpuContext, len: usize, scalars_offset: usize, scale: f32) -> ContentWorkspace {
        let groups = Kernel::groups_1d(len, WORKGROUP);
        let parts = (groups[0] * groups[1]) as usize;
        let p = ContentParams {
            len: u32::try_from(len).unwrap_or(u32::MAX),
            parts: parts as u32,
            out_off: u32::try_from(scalars_offset).unwrap_or(u32::MAX),
            scale,
            ..Default::default()
        };
        ContentWorkspace {
            partial: ctx.zeros("content.partial", parts),
            accumulate: Launch { uniform: ctx.uniform("content.accumulate", &p), groups },
            finish: Launch { uniform: ctx.uniform("content.finish", &p), groups: [1, 1, 1] },
        }
    }

    /// Records the loss of `features` against `target` (same length) into
    /// `scalars` and adds its weighted gradient to `v_features`.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        ws: &ContentWorkspace,
        features: &wgpu::Buffer,
        target: &wgpu::Buffer,
        v_features: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let l = &ws.accumulate;
        self.accumulate.dispatch(ctx, enc, &[&l.uniform, features, target, v_features, &ws.partial], l.groups);
        let l = &ws.finish;
        self.finish.dispatch(ctx, enc, &[&l.uniform, &self.dummy, &self.dummy, scalars, &ws.partial], l.groups);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::content::content_loss;

    #[test]
    fn loss_and_accumulated_gradient_match_the_cpu() {
        let ctx = ctx();
        let content = GpuContent::new(ctx);
        let len = 768 * 7 * 9 + 5;
        let (f, t, v0) = (noise(len, 1), noise(len, 2), noise(len, 3));
        // A weight of `len` makes the gradient 2(f − t), as large as v's old values.
        let scale = len as f32;
        let ws = content.workspace(ctx, len, 3, scale);
        ctx.write(&ws.partial, &noise((ws.partial.size() / 4) as usize, 4));
        let (fb, tb, vb) = (ctx.upload("f", &f), ctx.upload("t", &t), ctx.upload("v", &v0));
        let scalars = ctx.upload("scalars", &noise(6, 5));
        let mut enc = ctx.encoder("content test");
        content.record(ctx, &mut enc, &ws, &fb, &tb, &vb, &scalars);
        ctx.submit(enc);
        let (want, grad) = content_loss(&f, &t);
        let got: Vec<f32> = ctx.read(&scalars).expect("scalars");
        assert!((got[3] - want).abs() <= 1e-4 * want, "loss {} vs CPU {want}", got[3]);
        let v: Vec<f32> = ctx.read(&vb).expect("gradient");
        let expect: Vec<f32> = v0.iter().zip(&grad).map(|(a, g)| a + scale * g).collect();
        let err = v.iter().zip(&expect).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        assert!(err < 1e-5, "gradient differs by {err}");
    }
}
