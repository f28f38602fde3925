//! The GPU rasterizer's backward pass (`shaders/raster_backward.wgsl`, then
//! `raster_project.wgsl`'s `project_backward`): reverse compositing per tile
//! to each Gaussian's screen-space gradient, accumulated with atomic adds,
//! then the per-Gaussian chain to the parameter gradients. The CPU twin is
//! `raster/backward.rs`; float atomics make the sum order vary, so the two
//! agree to rounding, not bit for bit.
//!
//! `raster_forward.rs` holds every raster kernel (this file's
//! `tile_backward` among them, compiled for the device's accumulation) and
//! this file runs them through its types: one rasterizer, split by direction.

use super::raster_forward::{GpuRaster, RasterKernels};
use super::raster_project::WORKGROUP;
use super::{Bind, GpuContext, GpuGaussians, GpuGrads, Kernel};
use crate::raster::TILE;

/// The fallback accumulator in `raster_backward.wgsl`, between these markers.
const CAS_BEGIN: &str = "// BEGIN add_grad";
const CAS_END: &str = "// END add_grad";
/// What replaces it where the device has `SHADER_FLOAT32_ATOMIC`.
const NATIVE_ADD: &str = "@group(0) @binding(8) var<storage, read_write> v_splat: array<atomic<f32>>;

fn add_grad(i: u32, v: f32) {
    atomicAdd(&v_splat[i], v);
}
";

/// The per-thread flush in `raster_backward.wgsl`, between these markers.
const FLUSH_BEGIN: &str = "// BEGIN flush";
const FLUSH_END: &str = "// END flush";
/// What replaces it where the device has subgroups: one add per subgroup,
/// and no sums at all in a subgroup none of whose pixels the splat touched
/// (at low resolution most splats cover a few pixels of a 256-pixel tile,
/// and the ten sums per splat were most of the pass's work).
/// (naga 30 has no `subgroupElect`: the first invocation is the one with nothing before it.)
const SUBGROUP_FLUSH: &str = "fn flush(base: u32, gv: array<f32, 10>) {
    var touched = false;
    for (var c = 0u; c < 10u; c = c + 1u) {
        touched = touched || gv[c] != 0.0;
    }
    if !subgroupAny(touched) {
        return;
    }
    let first = subgroupExclusiveAdd(1u) == 0u;
    for (var c = 0u; c < 10u; c = c + 1u) {
        let s = subgroupAdd(gv[c]);
        if first && s != 0.0 {
            add_grad(base + c, s);
        }
    }
}
";

/// How the backward pass accumulates gradients: the device features it uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Accumulation {
    /// Native `atomic<f32>` adds (`SHADER_FLOAT32_ATOMIC`), else a compare-and-swap loop.
    pub float_atomics: bool,
    /// A subgroup sum before each add (`SUBGROUP`), else one add per pixel.
    pub subgroups: bool,
}

/// `src` with the text between `begin` and `end` replaced by `with`.
fn splice(src: &str, begin: &str, end: &str, with: &str) -> String {
    let (head, rest) = src.split_once(begin).expect("raster_backward.wgsl has its markers");
    let (_, tail) = rest.split_once(end).expect("raster_backward.wgsl has its markers");
    format!("{head}{with}{tail}")
}

/// The `raster_backward.wgsl` source for an accumulation mode.
pub(crate) fn tile_backward_source(acc: Accumulation) -> String {
    let mut src = super::raster_project::with_camera(include_str!("../../../../shaders/raster_backward.wgsl"));
    if acc.float_atomics {
        src = splice(&src, CAS_BEGIN, CAS_END, NATIVE_ADD);
    }
    if acc.subgroups {
        src = splice(&src, FLUSH_BEGIN, FLUSH_END, SUBGROUP_FLUSH);
    }
    src
}

/// Compiles `tile_backward` for an accumulation mode.
pub(crate) fn tile_backward_kernel(ctx: &GpuContext, acc: Accumulation) -> Kernel {
    use Bind::{Read, ReadWrite, Uniform};
    Kernel::new(
        ctx,
        &format!("raster_backward.tile_backward ({acc:?})"),
        &tile_backward_source(acc),
        "tile_backward",
        &[Uniform, Read, Read, Read, Read, Read, Read, Read, ReadWrite],
    )
}

impl GpuRaster {
    /// Records the backward pass of the last recorded [`GpuRaster::forward`]
    /// (same Gaussians, camera and options) given `v_rgb = ∂L/∂rgb` (H·W·3)
    /// and `v_inv_depth = ∂L/∂inv_depth` (H·W). Every entry of `grads` is
    /// written: zero for Gaussians that no pixel composited.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        v_rgb: &wgpu::Buffer,
        v_inv_depth: &wgpu::Buffer,
        grads: &GpuGrads,
    ) {
        self.backward_tiles(ctx, k, encoder, v_rgb, v_inv_depth);
        self.backward_gaussians(ctx, k, encoder, g, grads);
    }

    /// The first half of [`GpuRaster::backward`]: reverse compositing to the splats' gradients.
    pub(crate) fn backward_tiles(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut wgpu::CommandEncoder,
        v_rgb: &wgpu::Buffer,
        v_inv_depth: &wgpu::Buffer,
    ) {
        encoder.clear_buffer(&self.v_splat, 0, None);
        k.tile_backward.dispatch(
            ctx,
            encoder,
            &[
                &self.uniform,
                &self.pair_values,
                &self.order,
                &self.splats,
                &self.ranges,
                &self.px_state,
                v_rgb,
                v_inv_depth,
                &self.v_splat,
            ],
            [self.width.div_ceil(TILE), self.height.div_ceil(TILE), 1],
        );
    }

    /// The second half of [`GpuRaster::backward`]: splat gradients to parameter gradients.
    pub(crate) fn backward_gaussians(
        &self,
        ctx: &GpuContext,
        k: &RasterKernels,
        encoder: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        grads: &GpuGrads,
    ) {
        k.project.backward.dispatch(
            ctx,
            encoder,
            &[
                &self.uniform,
                &g.means,
                &g.log_scales,
                &g.quats,
                &g.opacity_logits,
                &g.sh,
                &self.v_splat,
                &grads.v_means,
                &grads.v_log_scales,
                &grads.v_quats,
                &grads.v_opacity_logits,
                &grads.v_sh,
            ],
            Kernel::groups_1d(self.n, WORKGROUP),
        );
    }
}
