//! The step's image and parameter losses on the GPU (`shaders/losses.wgsl`):
//! TV on the rendered colour, the depth L1 against the colour-matched scene's
//! inverse depth, and the three parameter regularisers.
//!
//! Each term adds its λ-weighted gradient to a buffer the caller owns (`+=`,
//! so the step sums several terms into one image gradient) and writes its
//! **unweighted** value into the caller's scalars buffer at the offset given
//! when it was planned, as the CPU step reports terms (`LossTerms`) and
//! weights them in the total. Values are sums in a deterministic tree
//! ([`Reduction`]); the CPU twins ([`crate::style::tv::tv_loss`],
//! [`crate::style::regularizers::depth_l1`],
//! [`crate::style::regularizers::l2_distance`]) sum in f64, so values agree to
//! f32 rounding, not bit for bit.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, GpuFocus, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};

/// Threads per workgroup in `losses.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `losses.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct LossParams {
    h: u32,
    w: u32,
    c: u32,
    n: u32,
    weight: f32,
    kh: f32,
    kv: f32,
    norm_index: u32,
}
const _: () = assert!(std::mem::size_of::<LossParams>() == 32);

/// The compiled entry points of `losses.wgsl`.
#[derive(Debug)]
pub struct LossKernels {
    tv: Kernel,
    depth_l1: Kernel,
    param_diff: Kernel,
    param_grad: Kernel,
    param_sq_grad: Kernel,
    hold: Kernel,
}

impl LossKernels {
    /// Compiles `losses.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/losses.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::ReadWrite, Bind::Read];
        let k = |entry: &str| Kernel::new(ctx, &format!("losses.{entry}"), src, entry, &binds);
        Arc::new(Self {
            tv: k("tv"),
            depth_l1: k("depth_l1"),
            param_diff: k("param_diff"),
            param_grad: k("param_grad"),
            param_sq_grad: k("param_sq_grad"),
            hold: k("hold"),
        })
    }
}

/// What every term keeps: its uniform, its per-element scratch and the reduction of it.
#[derive(Debug)]
struct LossPlan {
    kernels: Arc<LossKernels>,
    params: LossParams,
    uniform: wgpu::Buffer,
    scratch: wgpu::Buffer,
    reduction: Reduction,
}

impl LossPlan {
    fn new(
        ctx: &GpuContext,
        kernels: &Arc<LossKernels>,
        reduce: &Arc<ReduceKernels>,
        params: LossParams,
        scratch_len: usize,
        spec: ReduceSpec,
    ) -> Result<Self, GpuError> {
        Ok(Self {
            kernels: Arc::clone(kernels),
            params,
            uniform: ctx.uniform("losses.params", &params),
            scratch: ctx.zeros("losses.scratch", scratch_len),
            reduction: Reduction::new(ctx, reduce, spec)?,
        })
    }

    fn set_weight(&mut self, ctx: &GpuContext, weight: f32) {
        self.params.weight = weight;
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&self.params));
    }

    #[allow(clippy::too_many_arguments)]
    fn dispatch(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        kernel: &Kernel,
        x: &wgpu::Buffer,
        x_ref: &wgpu::Buffer,
        grad: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let groups = Kernel::groups_1d(self.params.n as usize, WORKGROUP);
        kernel.dispatch(ctx, encoder, &[&self.uniform, x, x_ref, grad, &self.scratch, scalars], groups);
    }
}

fn inverse(count: usize) -> f32 {
    if count > 0 { (1.0 / count as f64) as f32 } else { 0.0 }
}

/// TV `(mean(Δ_h I)² + mean(Δ_v I)²)/2` of an `h × w × c` image (the paper's
/// formula, as [`crate::style::tv::tv_loss_masked`]), over the differences
/// whose two pixels a [`GpuFocus`] covers (all of them for the frame).
#[derive(Debug)]
pub struct TvLoss(LossPlan);

impl TvLoss {
    /// Plans TV of `h × w × c` images with weight `weight`, its value going to `scalars[loss_offset]`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &GpuContext,
        kernels: &Arc<LossKernels>,
        reduce: &Arc<ReduceKernels>,
        h: usize,
        w: usize,
        c: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let n = h * w * c;
        let params =
            LossParams { h: h as u32, w: w as u32, c: c as u32, n: n as u32, weight, kh: 0.0, kv: 0.0, norm_index: 0 };
        let spec = ReduceSpec::new(ReduceOp::Sum, 2 * n).to(loss_offset);
        Ok(Self(LossPlan::new(ctx, kernels, reduce, params, 2 * n, spec)?))
    }

    /// Changes λ (from the next submission on).
    pub fn set_weight(&mut self, ctx: &GpuContext, weight: f32) {
        self.0.set_weight(ctx, weight);
    }

    /// Records `v_img += λ ∂TV/∂img` and `scalars[loss_offset] = TV(img)`,
    /// over the pixels `focus` covers.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        img: &wgpu::Buffer,
        focus: &GpuFocus,
        v_img: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        // The mask takes x_ref's binding and the counts the scalars'.
        self.0.dispatch(ctx, encoder, &self.0.kernels.tv, img, focus.pixels(), v_img, focus.counts());
        self.0.reduction.record(ctx, encoder, &self.0.scratch, scalars);
    }
}

/// Which term a [`RefLoss`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RefKind {
    DepthL1,
    ParamL2,
    ParamMeanSquare,
    Hold,
}

/// A term comparing a buffer with its reference from the colour-matched scene
/// `G^c`: the depth regulariser `mean|D − D^c|` over the inverse-depth map
/// ([`crate::style::regularizers::depth_l1`]), or a parameter regulariser
/// `‖x − x^c‖₂` over a flat array of opacity logits, log-scales or
/// quaternions ([`crate::style::regularizers::l2_distance`]), or the
/// background hold over an RGB render ([`crate::style::outside`]).
#[derive(Debug)]
pub struct RefLoss {
    kind: RefKind,
    plan: LossPlan,
}

impl RefLoss {
    /// Plans the depth L1 of `n`-pixel maps with weight `weight`, its value going to `scalars[loss_offset]`.
    pub fn depth_l1(
        ctx: &GpuContext,
        kernels: &Arc<LossKernels>,
        reduce: &Arc<ReduceKernels>,
        n: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let k = inverse(n);
        let params = LossParams { h: 1, w: n as u32, c: 1, n: n as u32, weight, kh: k, kv: 0.0, norm_index: 0 };
        let spec = ReduceSpec::new(ReduceOp::Sum, n).to(loss_offset).scaled(k);
        Ok(Self { kind: RefKind::DepthL1, plan: LossPlan::new(ctx, kernels, reduce, params, n, spec)? })
    }

    /// Plans the L2 norm of `len`-float arrays with weight `weight`, its value going to `scalars[loss_offset]`.
    pub fn param_l2(
        ctx: &GpuContext,
        kernels: &Arc<LossKernels>,
        reduce: &Arc<ReduceKernels>,
        len: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let n = len as u32;
        let params = LossParams { h: 1, w: n, c: 1, n, weight, kh: 0.0, kv: 0.0, norm_index: loss_offset as u32 };
        let spec = ReduceSpec::new(ReduceOp::SumSquares, len).to(loss_offset).sqrt();
        Ok(Self { kind: RefKind::ParamL2, plan: LossPlan::new(ctx, kernels, reduce, params, len, spec)? })
    }

    /// Plans the per-Gaussian mean square of `len`-float arrays holding
    /// `gaussians` Gaussians, `(1/gaussians)·Σ(x − x^c)²`
    /// ([`crate::style::regularizers::mean_square_distance`]), with weight
    /// `weight`, its value going to `scalars[loss_offset]`.
    pub fn param_mean_square(
        ctx: &GpuContext,
        kernels: &Arc<LossKernels>,
        reduce: &Arc<ReduceKernels>,
        len: usize,
        gaussians: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let n = len as u32;
        let k = inverse(gaussians);
        let params = LossParams { h: 1, w: n, c: 1, n, weight, kh: 2.0 * k, kv: 0.0, norm_index: loss_offset as u32 };
        let spec = ReduceSpec::new(ReduceOp::SumSquares, len).to(loss_offset).scaled(k);
        Ok(Self { kind: RefKind::ParamMeanSquare, plan: LossPlan::new(ctx, kernels, reduce, params, len, spec)? })
    }

    /// Plans the background hold of `pixels`-pixel RGB renders with weight
    /// `weight`, its value going to `scalars[loss_offset]`; its reference is
    /// [`RefLoss::hold_reference`].
    pub fn hold(
        ctx: &GpuContext,
        kernels: &Arc<LossKernels>,
        reduce: &Arc<ReduceKernels>,
        pixels: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let n = 3 * pixels;
        let params = LossParams { h: 1, w: n as u32, c: 3, n: n as u32, weight, kh: 0.0, kv: 0.0, norm_index: 0 };
        let spec = ReduceSpec::new(ReduceOp::Sum, n).to(loss_offset);
        Ok(Self { kind: RefKind::Hold, plan: LossPlan::new(ctx, kernels, reduce, params, n, spec)? })
    }

    /// The hold's reference from the colour-matched render (`rgb` HWC,
    /// clamped) and the pixels to hold: per pixel `[r, g, b, k]` with
    /// `k = 1/(3·held)` where held, 0 elsewhere.
    pub fn hold_reference(rgb: &[f32], held: &[bool]) -> Vec<f32> {
        let count = held.iter().filter(|&&m| m).count();
        let k = inverse(3 * count);
        held.iter()
            .enumerate()
            .flat_map(|(p, &m)| [rgb[3 * p], rgb[3 * p + 1], rgb[3 * p + 2], if m { k } else { 0.0 }])
            .collect()
    }

    /// Changes λ (from the next submission on).
    pub fn set_weight(&mut self, ctx: &GpuContext, weight: f32) {
        self.plan.set_weight(ctx, weight);
    }

    /// Records the term of `x` against `x_ref` into `scalars[loss_offset]` and
    /// its weighted gradient into `v_x`: for the depth L1 `v_x += λ sign(x −
    /// x_ref)/n`; for a parameter norm `v_x += λ (x − x_ref)/‖x − x_ref‖`
    /// (nothing where the norm is 0); for the hold `v_x += λ·2k(x − x^c)`.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        x: &wgpu::Buffer,
        x_ref: &wgpu::Buffer,
        v_x: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let (p, k) = (&self.plan, &self.plan.kernels);
        match self.kind {
            RefKind::DepthL1 | RefKind::Hold => {
                let kernel = if self.kind == RefKind::Hold { &k.hold } else { &k.depth_l1 };
                p.dispatch(ctx, encoder, kernel, x, x_ref, v_x, scalars);
                p.reduction.record(ctx, encoder, &p.scratch, scalars);
            }
            RefKind::ParamL2 => {
                p.dispatch(ctx, encoder, &k.param_diff, x, x_ref, v_x, scalars);
                p.reduction.record(ctx, encoder, &p.scratch, scalars);
                p.dispatch(ctx, encoder, &k.param_grad, x, x_ref, v_x, scalars);
            }
            RefKind::ParamMeanSquare => {
                p.dispatch(ctx, encoder, &k.param_diff, x, x_ref, v_x, scalars);
                p.reduction.record(ctx, encoder, &p.scratch, scalars);
                p.dispatch(ctx, encoder, &k.param_sq_grad, x, x_ref, v_x, scalars);
            }
        }
    }
}

#[cfg(test)]
#[path = "losses_tests.rs"]
mod tests;
