//! The GPU rasterizer's forward pass (`shaders/raster_forward.wgsl`, after
//! `raster_project.wgsl`): project, sort by depth, count and emit (tile,
//! splat) pairs, sort them by tile, find each tile's range, composite. The
//! CPU twin is `raster/forward.rs`; the images agree to rounding.
//!
//! [`GpuRaster`] is the workspace of one scene size and image size: every
//! buffer is made once and reused step after step, and the whole pass is
//! recorded into the caller's encoder with no read-back. The number of
//! (tile, splat) pairs is only known on the GPU, so the pair buffers have a
//! capacity; [`GpuRaster::pairs`] reads the number a pass needed (with the
//! step's scalars, say) so that the caller can grow the workspace.

use super::Commands;
use super::raster_kernels::RasterKernels;
use super::raster_project::{RasterUniform, WORKGROUP};
use super::scan::GpuScan;
use super::sort::{GpuSort, bits_for};
use super::{GpuContext, GpuError, GpuGaussians, Kernel};
use crate::camera::Camera;
use crate::raster::{Render, RenderOptions, ShGrads, TILE};

/// Floats per splat in the `splats` buffer (the CPU `Splat`'s 16 fields, in order).
pub(crate) const SPLAT_FLOATS: usize = 16;

/// Workgroups the backward pass should have in flight: on an H200 (132
/// multiprocessors, eight 256-thread workgroups each) about two full waves.
const BACKWARD_GROUPS: usize = 2048;

/// Slices per tile for the backward pass at `tiles` tiles: 1 from 2,048
/// tiles up (1,024 px square), 8 at 256 px square, at most 16. At low
/// resolution a few hundred tiles each hold a long list, and one workgroup
/// per tile walked it alone (the guitar's backward tiles took 16 ms at 256 px
/// against 4.5 ms at 1,024 on an H200); the slices share the walk.
pub(crate) fn backward_splits(tiles: usize) -> u32 {
    BACKWARD_GROUPS.div_ceil(tiles.max(1)).clamp(1, 16) as u32
}

/// Words of per-pixel state for `npx` pixels and `splits` backward slices:
/// each pixel's final transmittance and contributor count, then five words
/// per slice and pixel only when there is more than one slice (with one, the
/// backward pass starts from the final state and reads no slice record;
/// at 1,024 px square that spares 21 MB).
pub(crate) fn state_words(splits: u32, npx: usize) -> usize {
    if splits > 1 { (2 + 5 * splits as usize) * npx } else { 2 * npx }
}

/// The stages of the forward pass, in order (benchmarks time them one by one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stage {
    /// Per-Gaussian projection to splats and depth keys.
    Project,
    /// Splats sorted by depth.
    DepthSort,
    /// Tile counts, their prefix sums, the (tile, splat) pairs.
    Bin,
    /// Pairs sorted by tile; each tile's range.
    TileSort,
    /// Per-tile compositing.
    Composite,
}

impl Stage {
    /// Every stage in order.
    pub const ALL: [Stage; 5] = [Stage::Project, Stage::DepthSort, Stage::Bin, Stage::TileSort, Stage::Composite];

    /// A name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Project => "raster project",
            Stage::DepthSort => "raster depth sort",
            Stage::Bin => "raster tile binning",
            Stage::TileSort => "raster tile sort",
            Stage::Composite => "raster composite",
        }
    }
}

/// The rasterizer's workspace for `n` Gaussians and one image size.
#[derive(Debug)]
pub struct GpuRaster {
    pub(crate) n: usize,
    pub(crate) width: u32,
    pub(crate) height: u32,
    capacity: usize,
    /// Workgroups per tile in the backward pass ([`backward_splits`]).
    pub(crate) splits: u32,
    pub(crate) uniform: wgpu::Buffer,
    /// 16 floats per Gaussian (by Gaussian index); zeros when culled.
    pub(crate) splats: wgpu::Buffer,
    /// Depth keys, sorted in place (`u32::MAX` for culled Gaussians).
    depth_keys: wgpu::Buffer,
    /// Gaussian indices in depth order.
    pub(crate) order: wgpu::Buffer,
    /// Tile counts per depth rank, then their exclusive prefix sums.
    counts: wgpu::Buffer,
    count_scan: GpuScan,
    depth_sort: GpuSort,
    pair_keys: wgpu::Buffer,
    /// Depth ranks grouped by tile, front to back within each tile.
    pub(crate) pair_values: wgpu::Buffer,
    tile_sort: GpuSort,
    /// Per tile `[first, end)` into `pair_values`.
    pub(crate) ranges: wgpu::Buffer,
    /// Colour, `height × width × 3`.
    pub rgb: wgpu::Buffer,
    /// Inverse depth, `height × width`.
    pub inv_depth: wgpu::Buffer,
    /// Opacity `1 − T_final`, `height × width`.
    pub alpha: wgpu::Buffer,
    /// Per pixel: final transmittance (f32 bits), last composited list
    /// position + 1; then per backward slice and pixel, the transmittance at
    /// the slice's start and its premultiplied colour and inverse depth.
    pub(crate) px_state: wgpu::Buffer,
    /// Screen-space gradients, 10 per Gaussian (the backward pass's accumulator).
    pub(crate) v_splat: wgpu::Buffer,
    /// The SH coefficients whose gradient the backward pass writes (the
    /// [`GpuGrads`](crate::gpu::GpuGrads) it is given must hold them).
    pub(crate) grad_sh: ShGrads,
}

impl GpuRaster {
    /// A workspace for `n` Gaussians rendered at `width × height`, with room
    /// for `capacity` (tile, splat) pairs.
    pub fn new(ctx: &GpuContext, n: usize, width: u32, height: u32, capacity: usize) -> Result<Self, GpuError> {
        let npx = width as usize * height as usize;
        let tiles = (width.div_ceil(TILE) * height.div_ceil(TILE)) as usize;
        let capacity = capacity.max(1);
        let splits = backward_splits(tiles);
        let state = state_words(splits, npx);
        let largest = (n * SPLAT_FLOATS).max(capacity).max(state).max(10 * n) as u64 * 4;
        if largest > ctx.max_binding_bytes() {
            return Err(GpuError::TooLarge(format!(
                "the rasterizer needs a {largest}-byte buffer ({n} Gaussians, {width}×{height}, {capacity} pairs); \
                 the device binds at most {} bytes",
                ctx.max_binding_bytes()
            )));
        }
        Ok(Self {
            n,
            width,
            height,
            capacity,
            splits,
            uniform: ctx.uniform("raster.cam", &<RasterUniform as bytemuck::Zeroable>::zeroed()),
            splats: ctx.zeros("raster.splats", n * SPLAT_FLOATS),
            depth_keys: ctx.zeros("raster.depth_keys", n),
            order: ctx.zeros("raster.order", n),
            counts: ctx.zeros("raster.counts", n),
            count_scan: GpuScan::new(ctx, n),
            depth_sort: GpuSort::new(ctx, n),
            pair_keys: ctx.zeros("raster.pair_keys", capacity),
            pair_values: ctx.zeros("raster.pair_values", capacity),
            tile_sort: GpuSort::new(ctx, capacity),
            ranges: ctx.zeros("raster.ranges", 2 * tiles),
            rgb: ctx.zeros("raster.rgb", 3 * npx),
            inv_depth: ctx.zeros("raster.inv_depth", npx),
            alpha: ctx.zeros("raster.alpha", npx),
            px_state: ctx.zeros("raster.px_state", state),
            v_splat: ctx.zeros("raster.v_splat", 10 * n),
            grad_sh: ShGrads::All,
        })
    }

    /// This workspace with its backward pass writing the gradient of the SH
    /// coefficients `sh` only (a stylization: the DC), for gradients made by
    /// [`GpuGrads::with_sh`](crate::gpu::GpuGrads::with_sh) with the same; takes
    /// effect from the next recorded forward pass.
    pub fn with_grad_sh(mut self, sh: ShGrads) -> Self {
        self.grad_sh = sh;
        self
    }

    /// The (tile, splat) pairs the buffers hold.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// This workspace with `splits` backward slices per tile (tests: one,
    /// and more than the size would pick); record a forward pass before the
    /// next backward.
    #[cfg(test)]
    pub(crate) fn with_splits(mut self, ctx: &GpuContext, splits: u32) -> Self {
        let npx = self.width as usize * self.height as usize;
        self.splits = splits.max(1);
        self.px_state = ctx.zeros("raster.px_state", state_words(self.splits, npx));
        self
    }

    /// Records the forward pass of `g` seen by `cam` (whose size must be the
    /// workspace's). The uniform is written now, so record at most one
    /// forward per workspace in one submission.
    ///
    /// # Panics
    /// When the camera's size or the number of Gaussians differ from the workspace's (a caller bug).
    pub fn forward(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut dyn Commands,
        g: &GpuGaussians,
        cam: &Camera,
        opts: &RenderOptions,
    ) {
        assert!(
            cam.width == self.width && cam.height == self.height && g.len == self.n,
            "GpuRaster::forward: workspace is for {} Gaussians at {}×{}, given {} at {}×{}",
            self.n,
            self.width,
            self.height,
            g.len,
            cam.width,
            cam.height
        );
        let u = RasterUniform::new(cam, opts, self.n, g.sh_degree, self.capacity, self.splits, self.grad_sh);
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&u));
        for stage in Stage::ALL {
            self.record_stage(ctx, k, encoder, g, stage);
        }
    }

    /// Records one stage of the forward pass (the uniform already written).
    pub(crate) fn record_stage(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut dyn Commands,
        g: &GpuGaussians,
        stage: Stage,
    ) {
        let per_gaussian = Kernel::groups_1d(self.n, WORKGROUP);
        let bin = [
            &self.uniform,
            &self.depth_keys,
            &self.order,
            &self.splats,
            &self.counts,
            &self.pair_keys,
            &self.pair_values,
        ];
        let total = self.count_scan.total();
        let (tiles_x, tiles_y) = (self.width.div_ceil(TILE), self.height.div_ceil(TILE));
        match stage {
            Stage::Project => {
                let params = [&self.uniform, &g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh];
                let mut bufs = params.to_vec();
                bufs.extend([&self.splats, &self.depth_keys, &self.order]);
                k.project.project.dispatch(ctx, encoder, &bufs, per_gaussian);
            }
            // Depth keys are positive float bits, or u32::MAX for culled Gaussians.
            Stage::DepthSort => self.depth_sort.record(
                ctx,
                &k.sort,
                encoder,
                self.depth_sort.everything(),
                &self.depth_keys,
                &self.order,
                32,
            ),
            Stage::Bin => {
                k.count_tiles.dispatch(ctx, encoder, &bin, per_gaussian);
                self.count_scan.record(ctx, k.sort.scan(), encoder, &self.counts);
                k.emit.dispatch(ctx, encoder, &bin, per_gaussian);
            }
            Stage::TileSort => {
                let bits = bits_for(tiles_x * tiles_y);
                self.tile_sort.record(ctx, &k.sort, encoder, total, &self.pair_keys, &self.pair_values, bits);
                encoder.encoder().clear_buffer(&self.ranges, 0, None);
                k.ranges.dispatch(
                    ctx,
                    encoder,
                    &[&self.uniform, total, &self.pair_keys, &self.ranges],
                    Kernel::groups_1d(self.capacity, WORKGROUP),
                );
            }
            Stage::Composite => k.composite.dispatch(
                ctx,
                encoder,
                &[
                    &self.uniform,
                    &self.pair_values,
                    &self.order,
                    &self.splats,
                    &self.ranges,
                    &self.rgb,
                    &self.inv_depth,
                    &self.alpha,
                    &self.px_state,
                ],
                [tiles_x, tiles_y, 1],
            ),
        }
    }

    /// The (tile, splat) pairs the last forward pass needed (a read-back:
    /// call it outside the step). More than [`GpuRaster::capacity`] means
    /// that pass dropped pairs and must be redone in a larger workspace.
    pub fn pairs(&self, ctx: &GpuContext) -> Result<usize, GpuError> {
        Ok(ctx.read_range::<u32>(self.pair_count(), 0, 4)?[0] as usize)
    }

    /// The buffer whose first `u32` is the (tile, splat) pairs the last
    /// forward pass needed, for a caller that copies it into its own read-back.
    pub fn pair_count(&self) -> &wgpu::Buffer {
        self.count_scan.total()
    }

    /// Reads the last forward pass's images back.
    pub fn download(&self, ctx: &GpuContext) -> Result<Render, GpuError> {
        Ok(Render {
            width: self.width,
            height: self.height,
            rgb: ctx.read(&self.rgb)?,
            inv_depth: ctx.read(&self.inv_depth)?,
            alpha: ctx.read(&self.alpha)?,
        })
    }

    /// Fills every buffer of the workspace with noise (tests: a kernel that
    /// relies on zeroed or stale memory then fails).
    #[cfg(test)]
    pub(crate) fn fill_noise(&self, ctx: &GpuContext, seed: u64) {
        let bufs = [
            &self.splats,
            &self.depth_keys,
            &self.order,
            &self.counts,
            &self.pair_keys,
            &self.pair_values,
            &self.ranges,
            &self.rgb,
            &self.inv_depth,
            &self.alpha,
            &self.px_state,
            &self.v_splat,
        ];
        for (i, b) in bufs.into_iter().enumerate() {
            ctx.write(b, &super::test_util::noise((b.size() / 4) as usize, seed + i as u64));
        }
    }
}
