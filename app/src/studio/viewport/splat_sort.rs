//! The viewport's back-to-front order on the GPU (`shaders/splat_sort.wgsl`
//! and the engine's radix sort, `gast_core::gpu::GpuSort`): depth keys from
//! the projection pass, sorted on the device, so no per-frame sort of every
//! Gaussian runs on the UI thread (35–60 ms at 500k on the CPU). The CPU sort
//! ([`super::sort`]) stays for renderers without a [`GpuContext`] and as the
//! reference in tests.

use gast_core::gpu::{Bind, GpuContext, GpuSort, Kernel, SortKernels};

/// Threads per workgroup of `depth_keys`.
const WORKGROUP: u32 = 256;

/// The uniform block of `splat_sort.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct KeyParams {
    n: u32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<KeyParams>() == 16);

/// The kernels, compiled once per renderer.
pub struct DepthSortKernels {
    ctx: GpuContext,
    keys: Kernel,
    sort: SortKernels,
}

impl DepthSortKernels {
    /// Compiles the key kernel and the radix sort on `ctx`'s device.
    pub fn new(ctx: GpuContext) -> Self {
        let keys = Kernel::new(
            &ctx,
            "splat_sort.depth_keys",
            include_str!("../../../../shaders/splat_sort.wgsl"),
            "depth_keys",
            &[Bind::Uniform, Bind::Read, Bind::ReadWrite, Bind::ReadWrite],
        );
        let sort = SortKernels::new(&ctx);
        Self { ctx, keys, sort }
    }

    /// A workspace for a scene of `n` Gaussians.
    pub fn scene(&self, n: usize) -> SceneSort {
        SceneSort {
            n,
            uniform: self.ctx.uniform("splat_sort.params", &KeyParams { n: n as u32, _pad: [0; 3] }),
            keys: self.ctx.zeros("splat_sort.keys", n),
            sort: GpuSort::new(&self.ctx, n.max(1)),
        }
    }

    /// Records the keys of `projected` and the sort of `order` by them:
    /// afterwards `order` lists every Gaussian, farthest first, culled ones last.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        s: &SceneSort,
        projected: &wgpu::Buffer,
        order: &wgpu::Buffer,
    ) {
        let groups = Kernel::groups_1d(s.n, WORKGROUP);
        self.keys.dispatch(&self.ctx, encoder, &[&s.uniform, projected, &s.keys, order], groups);
        s.sort.record(&self.ctx, &self.sort, encoder, s.sort.everything(), &s.keys, order, 32);
    }
}

/// One scene's keys and sort workspace.
pub struct SceneSort {
    n: usize,
    uniform: wgpu::Buffer,
    keys: wgpu::Buffer,
    sort: GpuSort,
}
