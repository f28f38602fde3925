//! The palette hold on the GPU (`shaders/palette.wgsl`): λ_pal's twin of
//! [`crate::style::palette::palette_loss`], over the pixels a [`super::focus::GpuFocus`]
//! covers; the reference palette is written per view before the step.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};
use crate::style::palette::Palette;

/// Threads per workgroup in `palette.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `palette.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct PaletteParams {
    pixels: u32,
    weight: f32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<PaletteParams>() == 16);

/// The palette hold of `pixels`-pixel RGB renders: its two kernels, the
/// reference, the per-channel scratch and the reduction.
#[derive(Debug)]
pub struct PaletteLoss {
    stats: Kernel,
    grad: Kernel,
    pixels: usize,
    uniform: wgpu::Buffer,
    /// `μ^c` then `σ^c` per channel ([`PaletteLoss::set_reference`]).
    reference: wgpu::Buffer,
    /// Per channel the gradient's coefficients and the mean.
    coef: wgpu::Buffer,
    /// Per channel `(μ − μ^c)² + (σ − σ^c)²`, for the reduction.
    sq: wgpu::Buffer,
    reduction: Reduction,
}

impl PaletteLoss {
    /// Plans the term over `pixels`-pixel renders with weight `weight`, its
    /// unweighted value going to `scalars[loss_offset]`.
    pub fn new(
        ctx: &GpuContext,
        reduce: &Arc<ReduceKernels>,
        pixels: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let pixels = pixels.max(1);
        let src = include_str!("../../../../shaders/palette.wgsl");
        let binds =
            [Bind::Uniform, Bind::Read, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::ReadWrite, Bind::ReadWrite];
        let k = |entry: &str| Kernel::new(ctx, &format!("palette.{entry}"), src, entry, &binds);
        Ok(Self {
            stats: k("stats"),
            grad: k("grad_add"),
            pixels,
            uniform: ctx.uniform("palette.params", &Self::params(pixels, weight)),
            reference: ctx.zeros("palette.reference", 6),
            coef: ctx.zeros("palette.coef", 9),
            sq: ctx.zeros("palette.sq", 3),
            reduction: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, 3).to(loss_offset))?,
        })
    }

    fn params(pixels: usize, weight: f32) -> PaletteParams {
        PaletteParams { pixels: pixels as u32, weight, _pad: [0; 2] }
    }

    /// Changes λ_pal (from the next submission on).
    pub fn set_weight(&self, ctx: &GpuContext, weight: f32) {
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&Self::params(self.pixels, weight)));
    }

    /// The colour-matched render's palette of the view the next submission
    /// steps on.
    pub fn set_reference(&self, ctx: &GpuContext, reference: &Palette) {
        ctx.queue.write_buffer(&self.reference, 0, bytemuck::cast_slice(reference));
    }

    /// Records, over the pixels in `mask` (`pixels` floats, 1 or 0),
    /// `v_rgb += λ·∂L/∂rgb` and `scalars[loss_offset] = L`.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        rgb: &wgpu::Buffer,
        mask: &wgpu::Buffer,
        v_rgb: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let b = [&self.uniform, rgb, mask, &self.reference, &self.coef, &self.sq, v_rgb];
        self.stats.dispatch(ctx, encoder, &b, [3, 1, 1]);
        self.grad.dispatch(ctx, encoder, &b, Kernel::groups_1d(3 * self.pixels, WORKGROUP));
        self.reduction.record(ctx, encoder, &self.sq, scalars);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::palette::{palette_loss, palette_of};

    #[test]
    fn matches_the_cpu_palette_hold_and_accumulates() {
        let ctx = ctx();
        let reduce = ReduceKernels::new(ctx);
        for (pixels, cover) in [(1usize, 1.0f32), (111, 1.0), (6_364, 0.3), (65_536, 0.5), (40, -1.0)] {
            let label = format!("{pixels} pixels, cover {cover}");
            let rgb: Vec<f32> = noise(3 * pixels, 1).iter().map(|v| 0.5 + 0.5 * v).collect();
            let mask: Vec<bool> = noise(pixels, 4).iter().map(|&v| v < cover).collect();
            let other: Vec<f32> = noise(3 * pixels, 2).iter().map(|v| 0.4 + 0.3 * v).collect();
            let reference = palette_of(&other, &vec![true; pixels]);
            let (want, grad) = palette_loss(&rgb, &mask, &reference);

            let loss = PaletteLoss::new(ctx, &reduce, pixels, 0.5, 3).expect("plan");
            loss.set_reference(ctx, &reference);
            // Small, so that adding to it keeps the gradient's digits.
            let g0: Vec<f32> = noise(3 * pixels, 3).iter().map(|v| 1e-3 * v).collect();
            let (rb, gb) = (ctx.upload("rgb", &rgb), ctx.upload("g", &g0));
            let mb = ctx.upload("mask", &mask.iter().map(|&m| f32::from(u8::from(m))).collect::<Vec<_>>());
            let scalars = ctx.upload("scalars", &noise(8, 4));
            let mut enc = ctx.encoder("palette test");
            loss.record(ctx, &mut enc, &rb, &mb, &gb, &scalars);
            ctx.submit(enc);
            let got: Vec<f32> = ctx.read(&scalars).expect("scalars");
            assert!((got[3] - want).abs() <= 1e-4 * want.abs().max(1e-6), "{label}: {} vs {want}", got[3]);
            let g: Vec<f32> = ctx.read(&gb).expect("grad");
            let scale = grad.iter().fold(1e-9f32, |m, v| m.max(v.abs()));
            for i in 0..3 * pixels {
                let want_g = g0[i] + 0.5 * grad[i];
                assert!((g[i] - want_g).abs() <= 1e-3 * scale + 1e-3 * f32::EPSILON, "{label}: element {i}");
                if !mask[i / 3] {
                    assert_eq!(g[i], g0[i], "{label}: element {i} is outside the mask");
                }
            }
        }
    }
}
