//! Every compiled kernel of the GPU rasterizer ([`RasterKernels`]): the
//! projection's, the forward pass's (`raster_forward.rs` runs them), the
//! sort's, and the backward pass's tile kernel (`raster_backward.rs` runs it),
//! whose source is spliced here for the device's accumulation: native float
//! atomics or a compare-and-swap loop, subgroup sums or one add per pixel.

use super::Bind::{Read, ReadWrite, Uniform};
use super::raster_project::ProjectKernels;
use super::sort::SortKernels;
use super::{GpuContext, Kernel};

/// Every compiled raster kernel, forward and backward, and the sort's.
#[derive(Debug)]
pub struct RasterKernels {
    pub(crate) project: ProjectKernels,
    pub(crate) count_tiles: Kernel,
    pub(crate) emit: Kernel,
    pub(crate) ranges: Kernel,
    pub(crate) composite: Kernel,
    pub(crate) tile_backward: Kernel,
    pub(crate) sort: SortKernels,
}

impl RasterKernels {
    /// Compiles the raster shaders, the backward pass using native float
    /// atomics where the device has them, and subgroup sums where it has
    /// subgroups and is hardware: on lavapipe, whose subgroup operations are
    /// emulated, they made the backward tiles 3× slower (12.3 s against 4.1 s
    /// on the guitar at 256 px), so a software adapter adds per pixel.
    pub fn new(ctx: &GpuContext) -> Self {
        let subgroups = ctx.caps.subgroups && !ctx.is_software();
        Self::with_accumulation(ctx, Accumulation { float_atomics: ctx.caps.float_atomics, subgroups })
    }

    /// As [`RasterKernels::new`] with a chosen accumulation (each feature it
    /// asks for must be on the device; tests force the fallbacks with it).
    pub fn with_accumulation(ctx: &GpuContext, acc: Accumulation) -> Self {
        let src = &super::raster_project::with_camera(include_str!("../../../../shaders/raster_forward.wgsl"));
        let bin = [Uniform, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite];
        Self {
            project: ProjectKernels::new(ctx),
            count_tiles: Kernel::new(ctx, "raster_forward.count_tiles", src, "count_tiles", &bin),
            emit: Kernel::new(ctx, "raster_forward.emit", src, "emit", &bin),
            ranges: Kernel::new(
                ctx,
                "raster_forward.ranges",
                src,
                "ranges_of_tiles",
                &[Uniform, Read, Read, ReadWrite],
            ),
            composite: Kernel::new(
                ctx,
                "raster_forward.composite",
                src,
                "composite",
                &[Uniform, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite],
            ),
            tile_backward: tile_backward_kernel(ctx, acc),
            sort: SortKernels::new(ctx),
        }
    }
}

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
fn tile_backward_source(acc: Accumulation) -> String {
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
fn tile_backward_kernel(ctx: &GpuContext, acc: Accumulation) -> Kernel {
    Kernel::new(
        ctx,
        &format!("raster_backward.tile_backward ({acc:?})"),
        &tile_backward_source(acc),
        "tile_backward",
        &[Uniform, Read, Read, Read, Read, Read, Read, Read, ReadWrite],
    )
}
