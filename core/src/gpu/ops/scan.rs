//! Exclusive prefix sums of `u32` on the GPU (`shaders/scan.wgsl`), without
//! subgroups: the rasterizer turns per-splat tile counts into write offsets
//! with it, and the radix sort turns digit histograms into scatter offsets.
//!
//! The grid is fixed when the workspace is made (at most 256 workgroups, each
//! owning one contiguous range), so three dispatches scan any length and the
//! total lands in a buffer the next kernels read: nothing comes back to the host.

use super::Commands;
use super::{Bind, GpuContext, Kernel};

/// Elements one workgroup scans per block.
const BLOCK: usize = 1024;
/// Most workgroups of the fixed grid (`scan_sums` gives each one thread).
const MAX_GROUPS: usize = 256;

/// The uniform block of `scan.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ScanParams {
    len: u32,
    groups: u32,
    per_group: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<ScanParams>() == 16);

/// The three compiled entry points of `scan.wgsl`.
#[derive(Debug)]
pub struct ScanKernels {
    reduce: Kernel,
    scan_sums: Kernel,
    apply: Kernel,
}

impl ScanKernels {
    /// Compiles `scan.wgsl`.
    pub fn new(ctx: &GpuContext) -> Self {
        let src = include_str!("../../../../shaders/scan.wgsl");
        let binds = [Bind::Uniform, Bind::ReadWrite, Bind::ReadWrite];
        Self {
            reduce: Kernel::new(ctx, "scan.reduce", src, "reduce", &binds),
            scan_sums: Kernel::new(ctx, "scan.scan_sums", src, "scan_sums", &binds),
            apply: Kernel::new(ctx, "scan.apply", src, "apply", &binds),
        }
    }
}

/// A scan of exactly `len` elements: its uniform and its sums buffer.
#[derive(Debug)]
pub struct GpuScan {
    len: usize,
    groups: u32,
    uniform: wgpu::Buffer,
    sums: wgpu::Buffer,
}

impl GpuScan {
    /// A workspace scanning `len` elements.
    pub fn new(ctx: &GpuContext, len: usize) -> Self {
        let blocks = len.div_ceil(BLOCK).max(1);
        let groups = blocks.min(MAX_GROUPS);
        let per_group = blocks.div_ceil(groups) * BLOCK;
        let params = ScanParams { len: len as u32, groups: groups as u32, per_group: per_group as u32, _pad: 0 };
        Self {
            len,
            groups: groups as u32,
            uniform: ctx.uniform("scan.params", &params),
            sums: ctx.zeros("scan.sums", groups + 1),
        }
    }

    /// Elements scanned.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the scan is of nothing.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// After [`GpuScan::record`], word 0 of this buffer holds the sum of all elements.
    pub fn total(&self) -> &wgpu::Buffer {
        &self.sums
    }

    /// Records the in-place exclusive prefix sum of the first `len` words of `data`.
    pub fn record(&self, ctx: &GpuContext, k: &ScanKernels, encoder: &mut dyn Commands, data: &wgpu::Buffer) {
        let bufs = [&self.uniform, data, &self.sums];
        let bind = k.reduce.bind(ctx, &bufs);
        k.reduce.dispatch_bound(encoder, &bind, [self.groups, 1, 1]);
        k.scan_sums.dispatch_bound(encoder, &k.scan_sums.bind(ctx, &bufs), [1, 1, 1]);
        k.apply.dispatch_bound(encoder, &k.apply.bind(ctx, &bufs), [self.groups, 1, 1]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};

    #[test]
    fn matches_a_running_sum() {
        let ctx = ctx();
        let k = ScanKernels::new(ctx);
        for (len, seed) in [(1usize, 1u64), (255, 2), (1024, 3), (5000, 4), (300_001, 5)] {
            let input: Vec<u32> = noise(len, seed).iter().map(|x| ((x + 1.0) * 50.0) as u32).collect();
            let data = ctx.upload("scan.data", &input);
            let scan = GpuScan::new(ctx, len);
            // Stale sums must not leak into the result.
            ctx.write(scan.total(), &vec![7u32; scan.groups as usize + 1]);
            let mut enc = ctx.encoder("scan test");
            scan.record(ctx, &k, &mut enc, &data);
            ctx.submit(enc);
            let got: Vec<u32> = ctx.read(&data).expect("read back");
            let mut run = 0u32;
            let want: Vec<u32> = input
                .iter()
                .map(|&x| {
                    let r = run;
                    run += x;
                    r
                })
                .collect();
            assert_eq!(got, want, "length {len}");
            let total: Vec<u32> = ctx.read_range(scan.total(), 0, 4).expect("read back");
            assert_eq!(total[0], run, "total of length {len}");
        }
    }
}
