//! The sliced Wasserstein term on the GPU (`shaders/sliced.wgsl`): λ_sw's
//! and λ_swd's twin of [`crate::style::sliced::sliced_loss`], over the
//! feature positions a [`GpuFocus`] covers, whose count the kernels read from
//! the device.
//!
//! A GEMM projects the features on the term's directions, two stable radix
//! sorts ([`GpuSort`]: by value, then by direction) rank every direction's
//! projections at once, a kernel pulls each toward the style's quantile of
//! its rank, and a second GEMM takes the gradient back to the features. The
//! style side ([`GpuSlicedTarget`]) is the CPU's [`SlicedTarget`], uploaded.

use std::sync::Arc;

use super::Commands;
use super::{
    Bind, Gemm, GemmPlan, GemmSpec, GpuContext, GpuError, GpuFocus, GpuSort, Kernel, ReduceKernels, ReduceOp,
    ReduceSpec, Reduction, SortKernels, Strided, bits_for,
};
use crate::style::sliced::SlicedTarget;

/// Threads per workgroup in `sliced.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `sliced.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct SlicedParams {
    positions: u32,
    projections: u32,
    style_positions: u32,
    weight: f32,
}
const _: () = assert!(std::mem::size_of::<SlicedParams>() == 16);

/// The style side on the device: the directions (`P × C`, row-major) and,
/// per direction, the style's sorted projections (`P × M`).
#[derive(Debug)]
pub struct GpuSlicedTarget {
    channels: usize,
    projections: usize,
    style_positions: usize,
    directions: wgpu::Buffer,
    sorted: wgpu::Buffer,
}

impl GpuSlicedTarget {
    /// Uploads `target`.
    pub fn new(ctx: &GpuContext, target: &SlicedTarget) -> Self {
        let projections = target.projections();
        let style_positions = target.style_positions();
        let sorted: Vec<f32> = (0..projections).flat_map(|p| target.sorted(p).iter().copied()).collect();
        Self {
            channels: target.channels(),
            projections,
            style_positions,
            directions: ctx.upload("sliced.directions", target.directions()),
            sorted: ctx.upload("sliced.sorted", if sorted.is_empty() { &[0.0] } else { &sorted }),
        }
    }
}

/// The compiled kernels of the term (with the GEMM and the sort they use).
#[derive(Debug)]
pub struct SlicedKernels {
    keys: Kernel,
    direction_keys: Kernel,
    residual: Kernel,
    gemm: Gemm,
    sort: SortKernels,
}

impl SlicedKernels {
    /// Compiles `sliced.wgsl`, `gemm.wgsl` and `sort.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/sliced.wgsl");
        let binds = [
            Bind::Uniform,
            Bind::Read,
            Bind::Read,
            Bind::Read,
            Bind::Read,
            Bind::ReadWrite,
            Bind::ReadWrite,
            Bind::ReadWrite,
            Bind::ReadWrite,
        ];
        Arc::new(Self {
            keys: Kernel::new(ctx, "sliced.make_keys", src, "make_keys", &binds),
            direction_keys: Kernel::new(ctx, "sliced.direction_keys", src, "direction_keys", &binds),
            residual: Kernel::new(ctx, "sliced.residual", src, "residual", &binds),
            gemm: Gemm::new(ctx),
            sort: SortKernels::new(ctx),
        })
    }
}

/// The term over `channels × positions` feature maps against one target:
/// its planned GEMMs, sort workspace and scratch.
#[derive(Debug)]
pub struct SlicedLoss {
    kernels: Arc<SlicedKernels>,
    positions: usize,
    projections: usize,
    style_positions: usize,
    uniform: wgpu::Buffer,
    project: GemmPlan,
    back: GemmPlan,
    sort: GpuSort,
    /// `P × n` projections of the rendered features.
    proj: wgpu::Buffer,
    keys: wgpu::Buffer,
    slots: wgpu::Buffer,
    /// `P × n` gradient w.r.t. the projections (λ included).
    grad: wgpu::Buffer,
    /// Per sorted slot, `(r − t)² / (m P)`, for the reduction.
    sq: wgpu::Buffer,
    reduction: Reduction,
}

impl SlicedLoss {
    /// Plans the term over `positions` feature positions against `target`
    /// with weight `weight`, its unweighted value going to `scalars[loss_offset]`.
    pub fn new(
        ctx: &GpuContext,
        kernels: &Arc<SlicedKernels>,
        reduce: &Arc<ReduceKernels>,
        target: &GpuSlicedTarget,
        positions: usize,
        weight: f32,
        loss_offset: usize,
    ) -> Result<Self, GpuError> {
        let (c, n, p) = (target.channels.max(1), positions.max(1), target.projections.max(1));
        let len = n * p;
        // R (P × n) = Θ (P × C) · F (C × n).
        let project = kernels.gemm.plan(ctx, &GemmSpec::plain(p, n, c));
        // v_F (C × n) += Θᵀ (C × P) · G (P × n).
        let back = kernels
            .gemm
            .plan(ctx, &GemmSpec { a: Strided::transposed(0, c), accumulate: true, ..GemmSpec::plain(c, n, p) });
        Ok(Self {
            kernels: Arc::clone(kernels),
            positions: n,
            projections: p,
            style_positions: target.style_positions,
            uniform: ctx.uniform("sliced.params", &Self::params(n, p, target.style_positions, weight)),
            project,
            back,
            sort: GpuSort::new(ctx, len),
            proj: ctx.zeros("sliced.proj", len),
            keys: ctx.zeros("sliced.keys", len),
            slots: ctx.zeros("sliced.slots", len),
            grad: ctx.zeros("sliced.grad", len),
            sq: ctx.zeros("sliced.sq", len),
            reduction: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, len).to(loss_offset))?,
        })
    }

    fn params(positions: usize, projections: usize, style_positions: usize, weight: f32) -> SlicedParams {
        SlicedParams {
            positions: positions as u32,
            projections: projections as u32,
            style_positions: style_positions as u32,
            weight,
        }
    }

    /// Changes λ (from the next submission on).
    pub fn set_weight(&self, ctx: &GpuContext, weight: f32) {
        let p = Self::params(self.positions, self.projections, self.style_positions, weight);
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&p));
    }

    /// Records, over the positions `focus` covers, `v_features += λ·∂L/∂F`
    /// and `scalars[loss_offset] = L`, for the features `features`
    /// (`channels × positions`, channel-major) against `target`.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        target: &GpuSlicedTarget,
        features: &wgpu::Buffer,
        focus: &GpuFocus,
        v_features: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
    ) {
        let k = &self.kernels;
        k.gemm.record(ctx, encoder, &self.project, &target.directions, features, None, &self.proj);
        let b = [
            &self.uniform,
            &self.proj,
            focus.cells(),
            focus.counts(),
            &target.sorted,
            &self.keys,
            &self.slots,
            &self.grad,
            &self.sq,
        ];
        let groups = Kernel::groups_1d(self.positions * self.projections, WORKGROUP);
        let all = self.sort.everything();
        k.keys.dispatch(ctx, encoder, &b, groups);
        self.sort.record(ctx, &k.sort, encoder, all, &self.keys, &self.slots, 32);
        k.direction_keys.dispatch(ctx, encoder, &b, groups);
        self.sort.record(ctx, &k.sort, encoder, all, &self.keys, &self.slots, bits_for(self.projections as u32));
        k.residual.dispatch(ctx, encoder, &b, groups);
        k.gemm.record(ctx, encoder, &self.back, &target.directions, &self.grad, None, v_features);
        self.reduction.record(ctx, encoder, &self.sq, scalars);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{check_masked_term, ctx, noise};
    use crate::style::sliced::sliced_loss;

    #[test]
    fn matches_the_cpu_sliced_term_and_accumulates() {
        let ctx = ctx();
        let (kernels, reduce) = (SlicedKernels::new(ctx), ReduceKernels::new(ctx));
        for (c, positions, style_positions, projections, cover) in [
            (3usize, 1usize, 1usize, 2usize, 1.0f32),
            (16, 200, 150, 128, 1.0),
            (16, 200, 333, 128, 0.4),
            (24, 3_000, 900, 64, 0.7),
            (8, 50, 40, 16, 0.0),
        ] {
            // ReLU features, as VGG's: many exact zeros, so many ties.
            let f: Vec<f32> = noise(c * positions, 1).iter().map(|v| v.max(0.0)).collect();
            let style: Vec<f32> = noise(c * style_positions, 2).iter().map(|v| (v + 0.2).max(0.0)).collect();
            let target = SlicedTarget::new(&style, c, projections);
            let cells: Vec<bool> = noise(positions, 4).iter().map(|&v| v.abs() < cover).collect();
            let gtarget = GpuSlicedTarget::new(ctx, &target);
            let loss = SlicedLoss::new(ctx, &kernels, &reduce, &gtarget, positions, 0.5, 3).expect("plan");
            let cpu = sliced_loss(&f, c, &target, Some(&cells));
            let label = format!("{c} × {positions} against {style_positions}, {projections} directions, cover {cover}");
            check_masked_term(ctx, &label, &f, &cells, cpu, 1e-4, |enc, fb, focus, gb, scalars| {
                loss.record(ctx, enc, &gtarget, fb, focus, gb, scalars)
            });
        }
    }
}
