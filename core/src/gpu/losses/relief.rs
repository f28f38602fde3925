//! The depth map's relief on the GPU (`shaders/depth_relief.wgsl`), when
//! [`StyleConfig::depth_relief_px`](crate::style::StyleConfig::depth_relief_px)
//! is above 0: the min-max normalised depth minus its masked blur, centred on
//! 0.5, goes to VGG instead of the depth itself, and its adjoint takes the
//! gradient back to the normalised depth.
//!
//! The CPU twin is [`crate::style::relief`] (`relief`, `centred` and their
//! backwards): the blur is two box passes of radius `r`, each a sum over the
//! row then the column, normalised by the mask's own box sum; the centring
//! divides by the peak |relief| over the mask, whose gradient flows back to
//! the pixels at the peak, shared among ties. The box sums run directly (2r +
//! 1 reads a pixel and direction, in f32) where the CPU uses f64 prefix sums.
//! The peak and the backward's two sums are [`Reduction`]s into a small stats
//! buffer; nothing is read back. It works in place on the depth map's
//! `h × w × 3` buffers: [`DepthRelief::forward`] replaces the normalised map
//! with its centred relief, [`DepthRelief::backward`] the centred map's
//! gradient with the normalised map's (in channel 0, the others 0, which the
//! min-max backward's channel sum reads as it is).

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};

/// Threads per workgroup in `depth_relief.wgsl`.
const WORKGROUP: u32 = 256;
/// Floats in the stats buffer: max |relief|, Σ relief·g, #(covered pixels at the peak).
const STATS: usize = 3;

/// The uniform block of `depth_relief.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ReliefParams {
    h: u32,
    w: u32,
    r: u32,
    stride: u32,
}
const _: () = assert!(std::mem::size_of::<ReliefParams>() == 16);

/// The compiled entry points of `depth_relief.wgsl`.
#[derive(Debug)]
pub struct DepthReliefKernels {
    rows: Kernel,
    cols: Kernel,
    count_inverse: Kernel,
    relief: Kernel,
    centre: Kernel,
    centre_terms: Kernel,
    centre_back: Kernel,
    relief_back: Kernel,
}

impl DepthReliefKernels {
    /// Compiles `depth_relief.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/depth_relief.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::Read, Bind::Read];
        let k = |entry: &str| Kernel::new(ctx, &format!("depth_relief.{entry}"), src, entry, &binds);
        Arc::new(Self {
            rows: k("rows"),
            cols: k("cols"),
            count_inverse: k("count_inverse"),
            relief: k("relief"),
            centre: k("centre"),
            centre_terms: k("centre_terms"),
            centre_back: k("centre_back"),
            relief_back: k("relief_back"),
        })
    }
}

/// The relief of `h × w` depth maps at one radius: its reductions, stats and
/// scratch (about ten floats a pixel), allocated once.
#[derive(Debug)]
pub struct DepthRelief {
    kernels: Arc<DepthReliefKernels>,
    n: usize,
    radius: usize,
    peak: Reduction,
    sums: Reduction,
    stats: wgpu::Buffer,
    /// `1 / (K m)` of the last forward's mask.
    inv_count: wgpu::Buffer,
    /// The rows' box sums, before the columns'.
    rows: wgpu::Buffer,
    /// One blur pass's result (the forward), or one adjoint pass's (the backward).
    pass: [wgpu::Buffer; 2],
    /// The relief and its magnitude (`2n`), kept from the forward for the backward.
    relief: wgpu::Buffer,
    /// The backward's two planes of terms (`2n`).
    terms: wgpu::Buffer,
    /// The gradient w.r.t. the relief (`m·v`).
    v_relief: wgpu::Buffer,
    unit: wgpu::Buffer,
    strided: wgpu::Buffer,
}

impl DepthRelief {
    /// Plans the relief of `h × w` maps at `radius` pixels.
    pub fn new(
        ctx: &GpuContext,
        kernels: &Arc<DepthReliefKernels>,
        reduce: &Arc<ReduceKernels>,
        h: usize,
        w: usize,
        radius: usize,
    ) -> Result<Self, GpuError> {
        let n = h * w;
        let params = |stride| ReliefParams { h: h as u32, w: w as u32, r: radius as u32, stride };
        Ok(Self {
            kernels: Arc::clone(kernels),
            n,
            radius,
            peak: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Max, n).from(n).to(0))?,
            sums: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, n).lanes(2).to(1))?,
            stats: ctx.zeros("depth_relief.stats", STATS),
            inv_count: ctx.zeros("depth_relief.inv_count", n),
            rows: ctx.zeros("depth_relief.rows", n),
            pass: std::array::from_fn(|_| ctx.zeros("depth_relief.pass", n)),
            relief: ctx.zeros("depth_relief.relief", 2 * n),
            terms: ctx.zeros("depth_relief.terms", 2 * n),
            v_relief: ctx.zeros("depth_relief.v_relief", n),
            unit: ctx.uniform("depth_relief.params", &params(1)),
            strided: ctx.uniform("depth_relief.params.strided", &params(3)),
        })
    }

    /// The radius this plan blurs at, pixels.
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// Records `map (h × w × 3) ← replicate3(0.5 + rel / 2M)`, `rel = m·(d̃ −
    /// B d̃)` the relief of the normalised map `d̃` (channel 0 of `map`, as
    /// [`super::DepthMap::forward`] leaves it) inside `mask` (`h × w`, 1 or
    /// 0), `M` its peak magnitude.
    pub fn forward(&self, ctx: &GpuContext, enc: &mut dyn Commands, mask: &wgpu::Buffer, map: &wgpu::Buffer) {
        let (k, groups, s) = (&self.kernels, Kernel::groups_1d(self.n, WORKGROUP), &self.stats);
        let u = &self.unit;
        // n = K m, inverted (m·m = m for a 0/1 mask).
        k.rows.dispatch(ctx, enc, &[u, mask, mask, &self.rows, mask, s], groups);
        k.count_inverse.dispatch(ctx, enc, &[u, &self.rows, mask, &self.inv_count, mask, s], groups);
        // Two passes x ← (1/n)·K(m·x), the first reading channel 0 of the map.
        k.rows.dispatch(ctx, enc, &[&self.strided, map, mask, &self.rows, mask, s], groups);
        k.cols.dispatch(ctx, enc, &[u, &self.rows, &self.inv_count, &self.pass[0], mask, s], groups);
        k.rows.dispatch(ctx, enc, &[u, &self.pass[0], mask, &self.rows, mask, s], groups);
        k.cols.dispatch(ctx, enc, &[u, &self.rows, &self.inv_count, &self.pass[1], mask, s], groups);
        k.relief.dispatch(ctx, enc, &[u, &self.pass[1], mask, &self.relief, map, s], groups);
        self.peak.record(ctx, enc, &self.relief, &self.stats);
        k.centre.dispatch(ctx, enc, &[u, &self.relief, mask, map, mask, s], groups);
    }

    /// Records the adjoint in place: `v_map` (`h × w × 3`), the gradient
    /// w.r.t. the centred map, becomes the gradient w.r.t. the normalised
    /// map, in channel 0 (the others 0). Uses the relief of the last
    /// [`DepthRelief::forward`], which must have been recorded with the same `mask`.
    pub fn backward(&self, ctx: &GpuContext, enc: &mut dyn Commands, mask: &wgpu::Buffer, v_map: &wgpu::Buffer) {
        let (k, groups, s) = (&self.kernels, Kernel::groups_1d(self.n, WORKGROUP), &self.stats);
        let u = &self.unit;
        k.centre_terms.dispatch(ctx, enc, &[u, &self.relief, mask, &self.terms, v_map, s], groups);
        self.sums.record(ctx, enc, &self.terms, &self.stats);
        k.centre_back.dispatch(ctx, enc, &[u, &self.relief, mask, &self.v_relief, v_map, s], groups);
        // Bᵀ u = m·K((1/n)·m·K((1/n)·u)): two passes x ← m·K((1/n)·x).
        k.rows.dispatch(ctx, enc, &[u, &self.v_relief, &self.inv_count, &self.rows, mask, s], groups);
        k.cols.dispatch(ctx, enc, &[u, &self.rows, mask, &self.pass[0], mask, s], groups);
        k.rows.dispatch(ctx, enc, &[u, &self.pass[0], &self.inv_count, &self.rows, mask, s], groups);
        k.cols.dispatch(ctx, enc, &[u, &self.rows, mask, &self.pass[1], mask, s], groups);
        k.relief_back.dispatch(ctx, enc, &[u, &self.pass[1], mask, v_map, &self.v_relief, s], groups);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::gpu::{DepthMap, DepthMapKernels};
    use crate::style::relief::{centred, centred_backward, relief, relief_backward};
    use crate::style::step::{min_max_backward, replicate3};

    /// The relief after the depth map, forward and backward, against the
    /// CPU's chain on maps with and without a mask, at radii below and
    /// above the map's size.
    #[test]
    fn the_relief_and_its_adjoint_match_the_cpu() {
        let ctx = ctx();
        let (kernels, depth) = (DepthReliefKernels::new(ctx), DepthMapKernels::new(ctx));
        let reduce = ReduceKernels::new(ctx);
        let cases = [(23usize, 31usize, 3usize, false), (23, 31, 3, true), (40, 17, 1, true), (9, 12, 20, false)];
        for (s, &(h, w, r, masked)) in cases.iter().enumerate() {
            let n = h * w;
            let seed = 70 + 10 * s as u64;
            // A smooth slope with bumps, so the relief is not the map itself.
            let bumps = noise(n, seed);
            let d: Vec<f32> = (0..n).map(|k| 0.2 + 0.01 * (k / w) as f32 + 0.05 * bumps[k]).collect();
            let inside: Vec<bool> = noise(n, seed + 5).iter().map(|&v| !masked || v > -0.4).collect();
            let mask: Vec<f32> = inside.iter().map(|&v| f32::from(u8::from(v))).collect();
            let cpu_mask = masked.then_some(inside.as_slice());

            let map = DepthMap::new(ctx, &depth, &reduce, h, w).expect("depth map plan");
            let rel_plan = DepthRelief::new(ctx, &kernels, &reduce, h, w, r).expect("relief plan");
            let d_buf = ctx.upload("d", &d);
            let m_buf = ctx.upload("mask", &mask);
            let out = ctx.upload("map", &noise(3 * n, seed + 1));
            let v_map = noise(3 * n, seed + 2);
            let v_map_buf = ctx.upload("v_map", &v_map);
            let v_depth = ctx.upload("v_depth", &noise(n, seed + 3));
            let mut enc = ctx.encoder("depth relief test");
            map.forward(ctx, &mut enc, &d_buf, &m_buf, &out);
            rel_plan.forward(ctx, &mut enc, &m_buf, &out);
            rel_plan.backward(ctx, &mut enc, &m_buf, &v_map_buf);
            map.backward(ctx, &mut enc, &d_buf, &m_buf, &v_map_buf, &v_depth, false);
            ctx.submit(enc);

            // The CPU's chain (step_loss): normalise, relief, centre; and back.
            let (lo, hi) = d
                .iter()
                .zip(&inside)
                .filter(|(_, m)| **m)
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), (&x, _)| (a.min(x), b.max(x)));
            let normed: Vec<f32> =
                d.iter().zip(&inside).map(|(&x, &m)| if m { (x - lo) / (hi - lo + 1e-8) } else { 0.0 }).collect();
            let rel = relief(&normed, h, w, cpu_mask, r);
            let want = replicate3(&centred(&rel, cpu_mask));
            let got = ctx.read::<f32>(&out).expect("read");
            let err = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
            assert!(err < 1e-4, "{h}×{w} r {r} masked {masked}: forward max abs error {err}");
            assert!(want.iter().any(|v| (v - 0.5).abs() > 0.1), "{h}×{w}: the relief is not flat");

            let v_n: Vec<f32> = v_map.chunks_exact(3).map(|p| p[0] + p[1] + p[2]).collect();
            let v_rel = relief_backward(&centred_backward(&rel, &v_n, cpu_mask), h, w, cpu_mask, r);
            let v_want = min_max_backward(&d, &v_rel, cpu_mask);
            let largest = v_want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let v_got = ctx.read::<f32>(&v_depth).expect("read");
            for i in 0..n {
                assert!(
                    (v_got[i] - v_want[i]).abs() <= 1e-3 * largest,
                    "{h}×{w} r {r} masked {masked} pixel {i}: {} vs {}",
                    v_got[i],
                    v_want[i]
                );
            }
        }
    }
}
