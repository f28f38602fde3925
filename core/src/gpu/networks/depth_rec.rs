//! What the depth network's two halves ([`super::depth_net`], the backbone,
//! and [`super::depth_dpt`], the neck and head) record with: its linear
//! layers on the device and one forward's recorder (encoder, GEMM plans,
//! scratch, elementwise launches).

use super::gemm::{Gemm, GemmSpec, Strided};
use super::{Encoder, GpuContext, Kernel};
use crate::vision::depth::ops::Linear;

/// Threads per workgroup of the elementwise kernels.
const WORKGROUP: u32 = 256;

/// A linear layer (or 1×1 convolution) on the device: `out × in` weights, `out` biases.
#[derive(Debug)]
pub(super) struct GpuLinear {
    pub w: wgpu::Buffer,
    pub b: wgpu::Buffer,
    pub out: usize,
    pub inp: usize,
}

impl GpuLinear {
    pub fn new(ctx: &GpuContext, l: &Linear) -> Self {
        Self { w: ctx.upload("depth.w", &l.w), b: ctx.upload("depth.b", &l.b), out: l.out(), inp: l.inp }
    }
}

/// One forward's command encoder, the buffers it made (kept alive until
/// the submission), and whether scratch starts as NaN (tests).
pub(super) struct Rec<'a> {
    pub ctx: &'a GpuContext,
    pub enc: Encoder,
    pub gemm: &'a Gemm,
    poison: bool,
    /// The im2col scratch every convolution shares (launches run in order).
    cols: Option<wgpu::Buffer>,
}

impl<'a> Rec<'a> {
    /// A recorder for one forward on a fresh encoder; scratch starts as NaN
    /// when `poison` (tests).
    pub fn new(ctx: &'a GpuContext, label: &str, gemm: &'a Gemm, poison: bool) -> Self {
        Self { ctx, enc: ctx.encoder(label), gemm, poison, cols: None }
    }

    /// The shared column scratch, at least `len` f32s (grown when needed).
    pub fn cols(&mut self, len: usize) -> wgpu::Buffer {
        match &self.cols {
            Some(b) if b.size() >= (len * 4) as u64 => b.clone(),
            _ => {
                let b = self.scratch("depth.cols", len);
                self.cols = Some(b.clone());
                b
            }
        }
    }

    /// A scratch buffer of `len` f32s; its contents are not to be relied on
    /// (NaN when poisoned, so a kernel reading unwritten memory shows).
    pub fn scratch(&self, label: &str, len: usize) -> wgpu::Buffer {
        if self.poison { self.ctx.upload(label, &vec![f32::NAN; len.max(1)]) } else { self.ctx.zeros(label, len) }
    }

    /// Records one GEMM (plan made on the spot: a forward runs once per style).
    pub fn gemm(
        &mut self,
        spec: &GemmSpec,
        a: &wgpu::Buffer,
        b: &wgpu::Buffer,
        bias: Option<&wgpu::Buffer>,
        c: &wgpu::Buffer,
    ) {
        let plan = self.gemm.plan(self.ctx, spec);
        self.gemm.record(self.ctx, &mut self.enc, &plan, a, b, bias, c);
    }

    /// `y (= or +=) W x + b` for `x` of `in × n` at column offset `x_off`
    /// with row stride `x_rs`, into `y` (`out × n`) at `y_off`, row stride `y_rs`.
    #[allow(clippy::too_many_arguments)]
    pub fn linear(
        &mut self,
        l: &GpuLinear,
        x: &wgpu::Buffer,
        (x_off, x_rs): (usize, usize),
        n: usize,
        y: &wgpu::Buffer,
        (y_off, y_rs): (usize, usize),
        accumulate: bool,
    ) {
        let spec = GemmSpec {
            a: Strided::rows(0, l.inp),
            b: Strided::rows(x_off, x_rs),
            c: Strided::rows(y_off, y_rs),
            accumulate,
            bias: Some(0),
            ..GemmSpec::plain(l.out, n, l.inp)
        };
        self.gemm(&spec, &l.w, x, Some(&l.b), y);
    }

    /// Records one elementwise launch of `kernel` over `len` threads with bindings (src, aux, dst).
    pub fn launch<T: bytemuck::Pod>(
        &mut self,
        kernel: &Kernel,
        params: &T,
        len: usize,
        (src, aux, dst): (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer),
    ) {
        let uniform = self.ctx.uniform("depth.params", params);
        kernel.dispatch(self.ctx, &mut self.enc, &[&uniform, src, aux, dst], Kernel::groups_1d(len, WORKGROUP));
    }
}
