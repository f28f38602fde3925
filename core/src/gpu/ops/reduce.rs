//! Reductions on the GPU (`shaders/reduce.wgsl`): sum, min, max and sum of
//! squares over a buffer, the building block of every scalar the step needs
//! (the depth map's and the edge map's min-max, the losses' sums, the
//! regularisers' norms).
//!
//! Two levels and no atomics, so the order of additions depends only on the
//! sizes: a run is bit-for-bit reproducible, and no device feature is needed.
//! A [`Reduction`] is planned once per size (its uniform and its partials are
//! allocated then) and recorded every step; it can reduce several equal-length
//! "lanes" of one buffer at once (lane `l` reads `input[l·len..(l+1)·len]` and
//! writes `out[out_offset + l]`).

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel};

/// Threads per workgroup in `reduce.wgsl`.
const WORKGROUP: usize = 256;
/// Most first-level workgroups per lane (the second level folds them in one workgroup).
const MAX_GROUPS: usize = 256;
/// Elements a thread folds, at least, before workgroups are added.
const PER_THREAD: usize = 8;

/// What a [`Reduction`] computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReduceOp {
    /// `Σ x`.
    Sum,
    /// `min x`.
    Min,
    /// `max x`.
    Max,
    /// `Σ x²`.
    SumSquares,
}

impl ReduceOp {
    fn code(self) -> u32 {
        match self {
            ReduceOp::Sum => 0,
            ReduceOp::Min => 1,
            ReduceOp::Max => 2,
            ReduceOp::SumSquares => 3,
        }
    }
}

/// The uniform block of `reduce.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ReduceParams {
    len: u32,
    op: u32,
    groups: u32,
    out_offset: u32,
    sqrt_result: u32,
    scale: f32,
    in_offset: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<ReduceParams>() == 32);

/// The two compiled entry points, shared by every [`Reduction`] of a context.
#[derive(Debug)]
pub struct ReduceKernels {
    partial: Kernel,
    finish: Kernel,
}

impl ReduceKernels {
    /// Compiles `reduce.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/reduce.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::ReadWrite, Bind::ReadWrite];
        Arc::new(Self {
            partial: Kernel::new(ctx, "reduce.partial", src, "partial", &binds),
            finish: Kernel::new(ctx, "reduce.finish", src, "finish", &binds),
        })
    }
}

/// What to reduce and where the result goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReduceSpec {
    /// The operation.
    pub op: ReduceOp,
    /// Elements per lane.
    pub len: usize,
    /// Lanes (consecutive runs of `len` elements), each with its own result.
    pub lanes: usize,
    /// Index in the output buffer of lane 0's result.
    pub out_offset: usize,
    /// Take the square root of the result (with [`ReduceOp::SumSquares`]: an L2 norm).
    pub sqrt: bool,
    /// Multiply the result by this (after the square root): `1/n` makes a mean.
    pub scale: f32,
    /// Index in the input buffer of lane 0's first element.
    pub in_offset: usize,
}

impl ReduceSpec {
    /// `op` over `len` elements into `out[0]`, unscaled.
    pub fn new(op: ReduceOp, len: usize) -> Self {
        Self { op, len, lanes: 1, out_offset: 0, sqrt: false, scale: 1.0, in_offset: 0 }
    }

    /// The same with `lanes` lanes.
    pub fn lanes(self, lanes: usize) -> Self {
        Self { lanes, ..self }
    }

    /// The same writing to `out[offset..]`.
    pub fn to(self, offset: usize) -> Self {
        Self { out_offset: offset, ..self }
    }

    /// The same reading its lanes from `input[offset..]`.
    pub fn from(self, offset: usize) -> Self {
        Self { in_offset: offset, ..self }
    }

    /// The same with the square root taken.
    pub fn sqrt(self) -> Self {
        Self { sqrt: true, ..self }
    }

    /// The same multiplied by `scale`.
    pub fn scaled(self, scale: f32) -> Self {
        Self { scale, ..self }
    }
}

/// A planned reduction: its uniform and partials, allocated once.
#[derive(Debug)]
pub struct Reduction {
    kernels: Arc<ReduceKernels>,
    spec: ReduceSpec,
    groups: usize,
    uniform: wgpu::Buffer,
    partials: wgpu::Buffer,
}

impl Reduction {
    /// Plans `spec`; fails when the input would exceed one storage binding.
    pub fn new(ctx: &GpuContext, kernels: &Arc<ReduceKernels>, spec: ReduceSpec) -> Result<Self, GpuError> {
        let bytes = (spec.in_offset as u64 + (spec.len as u64) * (spec.lanes as u64)) * 4;
        if bytes > ctx.max_binding_bytes() || spec.len > u32::MAX as usize {
            return Err(GpuError::TooLarge(format!(
                "a reduction over {} × {} floats ({bytes} bytes) exceeds the device's storage binding of {} bytes",
                spec.lanes,
                spec.len,
                ctx.max_binding_bytes()
            )));
        }
        let groups = spec.len.div_ceil(WORKGROUP * PER_THREAD).clamp(1, MAX_GROUPS);
        let params = ReduceParams {
            len: spec.len as u32,
            op: spec.op.code(),
            groups: groups as u32,
            out_offset: spec.out_offset as u32,
            sqrt_result: u32::from(spec.sqrt),
            scale: spec.scale,
            in_offset: spec.in_offset as u32,
            _pad: 0,
        };
        Ok(Self {
            kernels: Arc::clone(kernels),
            spec,
            groups,
            uniform: ctx.uniform("reduce.params", &params),
            partials: ctx.zeros("reduce.partials", groups * spec.lanes.max(1)),
        })
    }

    /// What this reduction computes.
    pub fn spec(&self) -> &ReduceSpec {
        &self.spec
    }

    /// Records the reduction of `input` into `out[out_offset..out_offset + lanes]`.
    pub fn record(&self, ctx: &GpuContext, encoder: &mut dyn Commands, input: &wgpu::Buffer, out: &wgpu::Buffer) {
        let buffers = [&self.uniform, input, &self.partials, out];
        let lanes = self.spec.lanes as u32;
        self.kernels.partial.dispatch(ctx, encoder, &buffers, [self.groups as u32, lanes, 1]);
        self.kernels.finish.dispatch(ctx, encoder, &buffers, [1, lanes, 1]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};

    fn cpu(op: ReduceOp, x: &[f32]) -> f64 {
        match op {
            ReduceOp::Sum => x.iter().map(|&v| f64::from(v)).sum(),
            ReduceOp::SumSquares => x.iter().map(|&v| f64::from(v) * f64::from(v)).sum(),
            ReduceOp::Min => f64::from(x.iter().copied().fold(f32::INFINITY, f32::min)),
            ReduceOp::Max => f64::from(x.iter().copied().fold(f32::NEG_INFINITY, f32::max)),
        }
    }

    #[test]
    fn every_op_matches_the_cpu_at_odd_sizes_with_lanes() {
        let ctx = ctx();
        let kernels = ReduceKernels::new(ctx);
        let ops = [ReduceOp::Sum, ReduceOp::Min, ReduceOp::Max, ReduceOp::SumSquares];
        for (s, &len) in [1usize, 7, 255, 257, 2049, 65_537, 700_001].iter().enumerate() {
            let lanes = if len < 100_000 { 3 } else { 1 };
            let x = noise(len * lanes, 100 + s as u64);
            let input = ctx.upload("x", &x);
            for (o, &op) in ops.iter().enumerate() {
                let spec = ReduceSpec::new(op, len).lanes(lanes).to(2).scaled(0.5);
                let red = Reduction::new(ctx, &kernels, spec).expect("plan");
                ctx.write(&red.partials, &noise(red.groups * lanes, 7));
                let out_init = noise(lanes + 4, 9 + o as u64);
                let out = ctx.upload("out", &out_init);
                let mut enc = ctx.encoder("reduce test");
                red.record(ctx, &mut enc, &input, &out);
                ctx.submit(enc);
                let got: Vec<f32> = ctx.read(&out).expect("read");
                for l in 0..lanes {
                    let lane = &x[l * len..(l + 1) * len];
                    let want = 0.5 * cpu(op, lane);
                    let mag: f64 = 0.5 * lane.iter().map(|&v| f64::from(v.abs()).max(f64::from(v * v))).sum::<f64>();
                    let err = (f64::from(got[2 + l]) - want).abs();
                    let tol = if matches!(op, ReduceOp::Min | ReduceOp::Max) { 0.0 } else { 1e-6 * mag.max(1.0) };
                    assert!(err <= tol, "{op:?} len {len} lane {l}: gpu {} cpu {want}", got[2 + l]);
                }
                // Untouched around the results.
                assert_eq!(&got[..2], &out_init[..2]);
                assert_eq!(&got[2 + lanes..], &out_init[2 + lanes..]);
            }
        }
    }

    #[test]
    fn norm_is_reproducible_bit_for_bit() {
        let ctx = ctx();
        let kernels = ReduceKernels::new(ctx);
        let x = noise(100_003, 3);
        let input = ctx.upload("x", &x);
        let red = Reduction::new(ctx, &kernels, ReduceSpec::new(ReduceOp::SumSquares, x.len()).sqrt()).expect("plan");
        let out = ctx.zeros("out", 1);
        let mut runs = Vec::new();
        for _ in 0..2 {
            let mut enc = ctx.encoder("reduce test");
            red.record(ctx, &mut enc, &input, &out);
            ctx.submit(enc);
            runs.push(ctx.read::<f32>(&out).expect("read")[0]);
        }
        assert_eq!(runs[0].to_bits(), runs[1].to_bits());
        let want = cpu(ReduceOp::SumSquares, &x).sqrt();
        assert!((f64::from(runs[0]) - want).abs() < 1e-5 * want, "{} vs {want}", runs[0]);
    }
}
