//! The step's depth map on the GPU (`shaders/depth_map.wgsl`): the rendered
//! inverse depth min-max normalised per image and replicated to 3 channels,
//! and its adjoint.
//!
//! The CPU twin is the start of [`crate::style::step::step_loss`] and its
//! `min_max_backward`: the min and max are part of the function, so their
//! gradients (`∂/∂max = −Σg·d̃/r`, `∂/∂min = (Σg·d̃ − Σg)/r`) flow back to the
//! pixels that hold them, shared equally among ties as autodiff does. The
//! min, max and the backward's sums are [`Reduction`]s into a small stats
//! buffer this workspace owns; nothing is read back. A pixel mask (the object
//! focus, [`super::GpuFocus`]; all ones for the whole frame) restricts the
//! range to the covered pixels and zeroes the map and its gradient elsewhere.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};

/// Threads per workgroup in `depth_map.wgsl`.
const WORKGROUP: u32 = 256;
/// Floats in the stats buffer: min, max, Σg, Σg·d̃, #min, #max.
const STATS: usize = 6;

/// The uniform block of `depth_map.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct DepthParams {
    n: u32,
    accumulate: u32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<DepthParams>() == 16);

/// The compiled entry points of `depth_map.wgsl`.
#[derive(Debug)]
pub struct DepthMapKernels {
    bounds: Kernel,
    normalize: Kernel,
    terms: Kernel,
    backward: Kernel,
}

impl DepthMapKernels {
    /// Compiles `depth_map.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/depth_map.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::Read, Bind::Read];
        Arc::new(Self {
            bounds: Kernel::new(ctx, "depth_map.bounds", src, "bounds", &binds),
            normalize: Kernel::new(ctx, "depth_map.normalize", src, "normalize", &binds),
            terms: Kernel::new(ctx, "depth_map.backward_terms", src, "backward_terms", &binds),
            backward: Kernel::new(ctx, "depth_map.backward", src, "backward", &binds),
        })
    }
}

/// The depth map of `h × w` renders: its reductions, stats and scratch, allocated once.
#[derive(Debug)]
pub struct DepthMap {
    kernels: Arc<DepthMapKernels>,
    n: usize,
    min: Reduction,
    max: Reduction,
    sums: Reduction,
    stats: wgpu::Buffer,
    scratch: wgpu::Buffer,
    overwrite: wgpu::Buffer,
    accumulate: wgpu::Buffer,
}

impl DepthMap {
    /// Plans the depth map of `h × w` inverse-depth renders.
    pub fn new(
        ctx: &GpuContext,
        kernels: &Arc<DepthMapKernels>,
        reduce: &Arc<ReduceKernels>,
        h: usize,
        w: usize,
    ) -> Result<Self, GpuError> {
        let n = h * w;
        let params = |accumulate| DepthParams { n: n as u32, accumulate, _pad: [0; 2] };
        Ok(Self {
            kernels: Arc::clone(kernels),
            n,
            min: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Min, n).to(0))?,
            max: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Max, n).from(n).to(1))?,
            sums: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, n).lanes(4).to(2))?,
            stats: ctx.zeros("depth_map.stats", STATS),
            scratch: ctx.zeros("depth_map.scratch", 4 * n),
            overwrite: ctx.uniform("depth_map.params", &params(0)),
            accumulate: ctx.uniform("depth_map.params.acc", &params(1)),
        })
    }

    /// The stats buffer `[min, max, Σg, Σg·d̃, #min, #max]` (the first two
    /// after [`DepthMap::forward`], the rest after [`DepthMap::backward`]).
    pub fn stats(&self) -> &wgpu::Buffer {
        &self.stats
    }

    /// Records `map (h × w × 3) = replicate3((d − min)/(max − min + 1e-8))`
    /// with the min and max over the pixels in `mask` (`h × w`, 1 or 0) and
    /// 0 outside it.
    pub fn forward(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        inv_depth: &wgpu::Buffer,
        mask: &wgpu::Buffer,
        map: &wgpu::Buffer,
    ) {
        let groups = Kernel::groups_1d(self.n, WORKGROUP);
        let k = &self.kernels;
        k.bounds.dispatch(ctx, encoder, &[&self.overwrite, inv_depth, &self.stats, &self.scratch, mask, mask], groups);
        self.min.record(ctx, encoder, &self.scratch, &self.stats);
        self.max.record(ctx, encoder, &self.scratch, &self.stats);
        k.normalize.dispatch(ctx, encoder, &[&self.overwrite, inv_depth, &self.stats, map, mask, mask], groups);
    }

    /// Records the adjoint: `v_inv_depth (=|+=) ∂/∂d` of the map's gradient
    /// `v_map` (`h × w × 3`), 0 outside `mask`. Uses the min and max of the last
    /// [`DepthMap::forward`], which must have been recorded on the same
    /// `inv_depth` and `mask`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        inv_depth: &wgpu::Buffer,
        mask: &wgpu::Buffer,
        v_map: &wgpu::Buffer,
        v_inv_depth: &wgpu::Buffer,
        accumulate: bool,
    ) {
        let groups = Kernel::groups_1d(self.n, WORKGROUP);
        self.kernels.terms.dispatch(
            ctx,
            encoder,
            &[&self.overwrite, inv_depth, &self.stats, &self.scratch, v_map, mask],
            groups,
        );
        self.sums.record(ctx, encoder, &self.scratch, &self.stats);
        let uniform = if accumulate { &self.accumulate } else { &self.overwrite };
        self.kernels.backward.dispatch(
            ctx,
            encoder,
            &[uniform, inv_depth, &self.stats, v_inv_depth, v_map, mask],
            groups,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::step::{min_max_backward, replicate3};

    #[test]
    fn forward_and_backward_match_the_cpu_with_ties_at_both_ends() {
        let ctx = ctx();
        let kernels = DepthMapKernels::new(ctx);
        let reduce = ReduceKernels::new(ctx);
        let cases = [(23usize, 31usize, false), (64, 47, false), (1, 5, false), (23, 31, true), (64, 47, true)];
        for (s, &(h, w, masked)) in cases.iter().enumerate() {
            let n = h * w;
            let seed = 40 + 10 * s as u64;
            let mut d: Vec<f32> = noise(n, seed).iter().map(|v| 0.3 + 0.25 * v).collect();
            // With a mask: about 70% covered, and the frame's extremes outside it.
            let inside: Vec<bool> = noise(n, seed + 5).iter().map(|&v| !masked || v > -0.4).collect();
            // Ties: the min three times, the max twice (when there is room), all covered.
            if n > 10 {
                for i in [3, 8, n - 1] {
                    d[i] = 0.01;
                }
                for i in [0, n / 2] {
                    d[i] = 0.9;
                }
            }
            let mut inside = inside;
            if masked {
                for i in [3, 8, n - 1, 0, n / 2] {
                    inside[i] = true;
                }
                (d[5], d[6], inside[5], inside[6]) = (2.0, -1.0, false, false);
            }
            let mask: Vec<f32> = inside.iter().map(|&v| f32::from(u8::from(v))).collect();
            let map = DepthMap::new(ctx, &kernels, &reduce, h, w).expect("plan");
            ctx.write(&map.stats, &noise(STATS, 1));
            ctx.write(&map.scratch, &noise(4 * n, 2));
            let d_buf = ctx.upload("d", &d);
            let m_buf = ctx.upload("mask", &mask);
            let out = ctx.upload("map", &noise(3 * n, seed + 1));
            let v_map = noise(3 * n, seed + 2);
            let v_map_buf = ctx.upload("v_map", &v_map);
            let before = noise(n, seed + 3);
            let v_over = ctx.upload("v_over", &before);
            let v_acc = ctx.upload("v_acc", &before);
            let mut enc = ctx.encoder("depth map test");
            map.forward(ctx, &mut enc, &d_buf, &m_buf, &out);
            map.backward(ctx, &mut enc, &d_buf, &m_buf, &v_map_buf, &v_over, false);
            map.backward(ctx, &mut enc, &d_buf, &m_buf, &v_map_buf, &v_acc, true);
            ctx.submit(enc);

            let (lo, hi) = d
                .iter()
                .zip(&inside)
                .filter(|(_, m)| **m)
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), (&x, _)| (a.min(x), b.max(x)));
            let r = hi - lo + 1e-8;
            let normed: Vec<f32> = d.iter().zip(&inside).map(|(&x, &m)| if m { (x - lo) / r } else { 0.0 }).collect();
            let want = replicate3(&normed);
            let got = ctx.read::<f32>(&out).expect("read");
            let err = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
            assert!(err < 1e-4, "{h}×{w} masked {masked}: forward max abs error {err}");

            let v_n: Vec<f32> = v_map.chunks_exact(3).map(|p| p[0] + p[1] + p[2]).collect();
            let v_want = min_max_backward(&d, &v_n, masked.then_some(inside.as_slice()));
            let largest = v_want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let over = ctx.read::<f32>(&v_over).expect("read");
            let acc = ctx.read::<f32>(&v_acc).expect("read");
            for i in 0..n {
                assert!(
                    (over[i] - v_want[i]).abs() <= 1e-3 * largest,
                    "{h}×{w} masked {masked} pixel {i}: {} vs {}",
                    over[i],
                    v_want[i]
                );
                if !inside[i] {
                    assert_eq!(over[i], 0.0, "{h}×{w} pixel {i} is outside the mask");
                }
                let a = before[i] + v_want[i];
                assert!((acc[i] - a).abs() <= 1e-3 * largest, "{h}×{w} pixel {i} accumulated: {} vs {a}", acc[i]);
            }
        }
    }
}
