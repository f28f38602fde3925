//! The render's clamp to [0, 1] and the 0.5× bilinear downscale on the GPU
//! (`shaders/resize.wgsl`), forward and backward.
//!
//! These sit between the rasterizer and VGG: the rendered colour is clamped
//! (its gradient masked outside [0, 1], as `session/run.rs` does on the CPU),
//! and every map is downscaled 0.5× with PyTorch's `scale_factor` convention
//! before the network ([`crate::vision::resize::downscale_half`]). The GPU
//! versions give the CPU's numbers bit for bit (every weight is ½ or ¼).

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, Kernel};

/// Threads per workgroup in `resize.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `resize.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ResizeParams {
    h: u32,
    w: u32,
    c: u32,
    oh: u32,
    ow: u32,
    accumulate: u32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<ResizeParams>() == 32);

/// The compiled entry points of `resize.wgsl`, shared by every plan of a context.
#[derive(Debug)]
pub struct ResizeKernels {
    clamp: Kernel,
    clamp_backward: Kernel,
    down: Kernel,
    down_backward: Kernel,
}

impl ResizeKernels {
    /// Compiles `resize.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/resize.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::ReadWrite];
        let k = |entry: &str| Kernel::new(ctx, &format!("resize.{entry}"), src, entry, &binds);
        Arc::new(Self {
            clamp: k("clamp01"),
            clamp_backward: k("clamp01_backward"),
            down: k("downscale"),
            down_backward: k("downscale_backward"),
        })
    }
}

/// The clamp of `len` rendered values to [0, 1] and its adjoint.
#[derive(Debug)]
pub struct Clamp01 {
    kernels: Arc<ResizeKernels>,
    len: usize,
    uniform: wgpu::Buffer,
}

impl Clamp01 {
    /// Plans the clamp of `len` values (an `h × w × 3` render: `len = 3hw`).
    pub fn new(ctx: &GpuContext, kernels: &Arc<ResizeKernels>, len: usize) -> Self {
        let params = ResizeParams { h: len as u32, w: 1, c: 1, oh: 0, ow: 0, accumulate: 0, _pad: [0; 2] };
        Self { kernels: Arc::clone(kernels), len, uniform: ctx.uniform("clamp01.params", &params) }
    }

    /// Records `out = clamp(raw, 0, 1)`.
    pub fn forward(&self, ctx: &GpuContext, encoder: &mut dyn Commands, raw: &wgpu::Buffer, out: &wgpu::Buffer) {
        let groups = Kernel::groups_1d(self.len, WORKGROUP);
        self.kernels.clamp.dispatch(ctx, encoder, &[&self.uniform, raw, out], groups);
    }

    /// Records the adjoint in place: `v` is zeroed where `raw` lies outside [0, 1].
    pub fn backward(&self, ctx: &GpuContext, encoder: &mut dyn Commands, raw: &wgpu::Buffer, v: &wgpu::Buffer) {
        let groups = Kernel::groups_1d(self.len, WORKGROUP);
        self.kernels.clamp_backward.dispatch(ctx, encoder, &[&self.uniform, raw, v], groups);
    }
}

/// The 0.5× bilinear downscale of an `h × w × c` image and its adjoint.
#[derive(Debug)]
pub struct Downscale {
    kernels: Arc<ResizeKernels>,
    h: usize,
    w: usize,
    c: usize,
    overwrite: wgpu::Buffer,
    accumulate: wgpu::Buffer,
}

impl Downscale {
    /// Plans the downscale of `h × w × c` images (`c` = 3 for RGB, 1 for a single map).
    pub fn new(ctx: &GpuContext, kernels: &Arc<ResizeKernels>, h: usize, w: usize, c: usize) -> Self {
        let params = |accumulate| ResizeParams {
            h: h as u32,
            w: w as u32,
            c: c as u32,
            oh: (h / 2) as u32,
            ow: (w / 2) as u32,
            accumulate,
            _pad: [0; 2],
        };
        Self {
            kernels: Arc::clone(kernels),
            h,
            w,
            c,
            overwrite: ctx.uniform("downscale.params", &params(0)),
            accumulate: ctx.uniform("downscale.params.acc", &params(1)),
        }
    }

    /// The output's height and width, `(floor(h/2), floor(w/2))`.
    pub fn out_size(&self) -> (usize, usize) {
        (self.h / 2, self.w / 2)
    }

    /// Records `small = downscale(src)` (`small` holds `floor(h/2) × floor(w/2) × c` values).
    pub fn forward(&self, ctx: &GpuContext, encoder: &mut dyn Commands, src: &wgpu::Buffer, small: &wgpu::Buffer) {
        let (oh, ow) = self.out_size();
        let groups = Kernel::groups_1d(oh * ow * self.c, WORKGROUP);
        self.kernels.down.dispatch(ctx, encoder, &[&self.overwrite, src, small], groups);
    }

    /// Records the adjoint: `v_src (=|+=) downscaleᵀ(v_small)`, overwriting
    /// `v_src` unless `accumulate` (every one of its `h × w × c` values is written).
    pub fn backward(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        v_small: &wgpu::Buffer,
        v_src: &wgpu::Buffer,
        accumulate: bool,
    ) {
        let uniform = if accumulate { &self.accumulate } else { &self.overwrite };
        let groups = Kernel::groups_1d(self.h * self.w * self.c, WORKGROUP);
        self.kernels.down_backward.dispatch(ctx, encoder, &[uniform, v_small, v_src], groups);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::vision::resize::{downscale_half, downscale_half_backward};

    fn max_abs(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
    }

    #[test]
    fn clamp_and_its_mask_match_the_cpu() {
        let ctx = ctx();
        let kernels = ResizeKernels::new(ctx);
        let n = 3 * 37 * 29;
        let raw: Vec<f32> = noise(n, 4).iter().map(|v| 0.5 + 0.8 * v).collect();
        let clamp = Clamp01::new(ctx, &kernels, n);
        let raw_buf = ctx.upload("raw", &raw);
        let out = ctx.upload("out", &noise(n, 5));
        let g = noise(n, 6);
        let v = ctx.upload("v", &g);
        let mut enc = ctx.encoder("clamp test");
        clamp.forward(ctx, &mut enc, &raw_buf, &out);
        clamp.backward(ctx, &mut enc, &raw_buf, &v);
        ctx.submit(enc);
        let want: Vec<f32> = raw.iter().map(|x| x.clamp(0.0, 1.0)).collect();
        assert_eq!(ctx.read::<f32>(&out).expect("read"), want);
        let want_v: Vec<f32> =
            raw.iter().zip(&g).map(|(&x, &gv)| if (0.0..=1.0).contains(&x) { gv } else { 0.0 }).collect();
        assert_eq!(ctx.read::<f32>(&v).expect("read"), want_v);
        assert!(want_v.contains(&0.0) && want.contains(&1.0), "the test covers both sides of the clamp");
    }

    #[test]
    fn downscale_forward_and_backward_match_the_cpu_at_odd_sizes() {
        let ctx = ctx();
        let kernels = ResizeKernels::new(ctx);
        for (s, &(h, w, c)) in
            [(9usize, 13usize, 3usize), (17, 11, 1), (64, 48, 3), (33, 65, 1), (2, 3, 3)].iter().enumerate()
        {
            let seed = 10 * s as u64;
            let img = noise(h * w * c, seed);
            let down = Downscale::new(ctx, &kernels, h, w, c);
            let (oh, ow) = down.out_size();
            let (want, wh, ww) = downscale_half(&img, h, w, c);
            assert_eq!((oh, ow), (wh, ww));
            let src = ctx.upload("src", &img);
            let small = ctx.upload("small", &noise(oh * ow * c, seed + 1));
            let v_small = noise(oh * ow * c, seed + 2);
            let v_small_buf = ctx.upload("v_small", &v_small);
            let before = noise(h * w * c, seed + 3);
            let v_over = ctx.upload("v_over", &before);
            let v_acc = ctx.upload("v_acc", &before);
            let mut enc = ctx.encoder("downscale test");
            down.forward(ctx, &mut enc, &src, &small);
            down.backward(ctx, &mut enc, &v_small_buf, &v_over, false);
            down.backward(ctx, &mut enc, &v_small_buf, &v_acc, true);
            ctx.submit(enc);
            let got = ctx.read::<f32>(&small).expect("read");
            assert_eq!(got, want, "{h}×{w}×{c}: the forward differs from the CPU's");
            let v_want = downscale_half_backward(&v_small, h, w, c);
            let over = ctx.read::<f32>(&v_over).expect("read");
            assert!(max_abs(&over, &v_want) < 1e-7, "{h}×{w}×{c}: backward");
            let acc_want: Vec<f32> = before.iter().zip(&v_want).map(|(a, b)| a + b).collect();
            let acc = ctx.read::<f32>(&v_acc).expect("read");
            assert!(max_abs(&acc, &acc_want) < 1e-6, "{h}×{w}×{c}: accumulated backward");
        }
    }
}
