//! The render's edge map on the GPU (`shaders/canny.wgsl`), the twin of
//! [`crate::vision::canny::render_edges`] replicated to 3 channels: a constant
//! of the step (no gradient), fed to VGG beside the colour and depth maps.
//!
//! Everything after the min-max is integer arithmetic, so the GPU map equals
//! the CPU's exactly. Hysteresis is a connected-component growth, sequential
//! on the CPU (a stack); here it is a bounded number of passes of a tiled
//! kernel that grows edges inside each 64×64 tile until stable (the tile held
//! as bit rows, a row's growth a few word operations) and hands them across
//! tile borders from pass to pass. Each pass writes the next one's
//! indirect dispatch arguments, zero workgroups unless it changed a tile
//! border, so the passes after the map settles cost nothing but their
//! recording; [`EdgeMap::converged`] tells (by a read-back, for tests and
//! diagnostics) whether the bound was enough.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};
use crate::vision::canny::CannyParams;

/// Threads per workgroup of the 1-D entry points of `canny.wgsl`.
const WORKGROUP: u32 = 256;
/// Side of a hysteresis tile (`TILE` in `canny.wgsl`). At 16 px (one pixel
/// a thread) a 512 px map needed a bound of 136 passes, each a dispatch even
/// when empty; at 64 px it is 40.
const TILE: usize = 64;

/// The uniform block of `canny.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct CannyUniform {
    h: u32,
    w: u32,
    n: u32,
    low: i32,
    high: i32,
    iteration: u32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<CannyUniform>() == 32);

/// The compiled entry points of `canny.wgsl`.
#[derive(Debug)]
pub struct CannyKernels {
    nms: Kernel,
    hysteresis: Kernel,
    finish: Kernel,
}

impl CannyKernels {
    /// Compiles `canny.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/canny.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::ReadWrite, Bind::ReadWrite];
        let k = |entry: &str| Kernel::new(ctx, &format!("canny.{entry}"), src, entry, &binds);
        Arc::new(Self { nms: k("nms"), hysteresis: k("hysteresis"), finish: k("finish") })
    }
}

/// The edge map of `h × w` renders: reductions, per-channel state and one
/// uniform per hysteresis pass, allocated once.
#[derive(Debug)]
pub struct EdgeMap {
    kernels: Arc<CannyKernels>,
    h: usize,
    w: usize,
    min: Reduction,
    max: Reduction,
    stats: wgpu::Buffer,
    state: wgpu::Buffer,
    /// Indirect arguments of the passes, in two buffers (pass k reads its
    /// own from `next[k % 2]` and writes pass k + 1's into the other).
    next: [wgpu::Buffer; 2],
    passes: Vec<wgpu::Buffer>,
}

impl EdgeMap {
    /// Plans the edge map of `h × w` renders with the default bound on
    /// hysteresis passes: twice the tiles across plus down, plus 8 (an edge
    /// chain crosses one tile border per pass).
    pub fn new(
        ctx: &GpuContext,
        kernels: &Arc<CannyKernels>,
        reduce: &Arc<ReduceKernels>,
        h: usize,
        w: usize,
    ) -> Result<Self, GpuError> {
        let passes = 2 * (h.div_ceil(TILE) + w.div_ceil(TILE)) + 8;
        Self::with_passes(ctx, kernels, reduce, h, w, passes)
    }

    /// The same with `passes` hysteresis passes (at least one).
    pub fn with_passes(
        ctx: &GpuContext,
        kernels: &Arc<CannyKernels>,
        reduce: &Arc<ReduceKernels>,
        h: usize,
        w: usize,
        passes: usize,
    ) -> Result<Self, GpuError> {
        let n = h * w;
        let params = CannyParams::default();
        let (low, high) = (params.low.min(params.high).floor() as i32, params.low.max(params.high).floor() as i32);
        let uniforms = (0..passes.max(1))
            .map(|k| {
                let u = CannyUniform {
                    h: h as u32,
                    w: w as u32,
                    n: n as u32,
                    low,
                    high,
                    iteration: k as u32,
                    _pad: [0; 2],
                };
                ctx.uniform("canny.params", &u)
            })
            .collect();
        Ok(Self {
            kernels: Arc::clone(kernels),
            h,
            w,
            min: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Min, 3 * n).to(0))?,
            max: Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Max, 3 * n).to(1))?,
            stats: ctx.zeros("canny.stats", 2),
            state: ctx.zeros("canny.state", 3 * n),
            next: std::array::from_fn(|_| {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("canny.next"),
                    size: (3 * 4 * (passes.max(1) + 1)) as u64,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::INDIRECT
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            }),
            passes: uniforms,
        })
    }

    /// Records `edge (h × w × 3) = replicate3(render_edges(rgb))` for a clamped render `rgb` (`h × w × 3`).
    pub fn record(&self, ctx: &GpuContext, encoder: &mut dyn Commands, rgb: &wgpu::Buffer, edge: &wgpu::Buffer) {
        let n = self.h * self.w;
        if n == 0 {
            return;
        }
        // The clears first: between dispatches they would end the encoder's compute pass.
        self.next.iter().for_each(|b| encoder.encoder().clear_buffer(b, 0, None));
        self.min.record(ctx, encoder, rgb, &self.stats);
        self.max.record(ctx, encoder, rgb, &self.stats);
        let first = self.buffers(&self.passes[0], rgb, edge, &self.next[1]);
        self.kernels.nms.dispatch(ctx, encoder, &first, Kernel::groups_1d(3 * n, WORKGROUP));
        let tiles = [self.w.div_ceil(TILE) as u32, self.h.div_ceil(TILE) as u32, 3];
        for (k, u) in self.passes.iter().enumerate() {
            let buffers = self.buffers(u, rgb, edge, &self.next[(k + 1) % 2]);
            if k == 0 {
                self.kernels.hysteresis.dispatch(ctx, encoder, &buffers, tiles);
            } else {
                self.kernels.hysteresis.dispatch_indirect(ctx, encoder, &buffers, &self.next[k % 2], 12 * k as u64);
            }
        }
        self.kernels.finish.dispatch(ctx, encoder, &first, Kernel::groups_1d(n, WORKGROUP));
    }

    /// The bindings of every entry point of `canny.wgsl`, with pass uniform `u`.
    fn buffers<'a>(
        &'a self,
        u: &'a wgpu::Buffer,
        rgb: &'a wgpu::Buffer,
        edge: &'a wgpu::Buffer,
        next: &'a wgpu::Buffer,
    ) -> [&'a wgpu::Buffer; 6] {
        [u, rgb, &self.stats, &self.state, next, edge]
    }

    /// Hysteresis passes that changed a tile border in the last recorded map,
    /// and whether the last pass changed none (the map is then final). A
    /// read-back: for tests and diagnostics, never inside the step.
    pub fn converged(&self, ctx: &GpuContext) -> Result<(usize, bool), GpuError> {
        let next = [ctx.read::<u32>(&self.next[0])?, ctx.read::<u32>(&self.next[1])?];
        let launched: Vec<bool> = (1..=self.passes.len()).map(|k| next[k % 2][3 * k] != 0).collect();
        let busy = launched.iter().filter(|&&l| l).count();
        Ok((busy, launched.last().is_none_or(|&l| !l)))
    }
}

#[cfg(test)]
#[path = "canny_tests.rs"]
mod tests;
