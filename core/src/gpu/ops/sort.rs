//! A stable GPU radix sort of `u32` keys with `u32` values
//! (`shaders/sort.wgsl`), needing no subgroups: workgroup-memory prefix sums
//! rank each block's elements, [`GpuScan`] turns digit histograms into
//! offsets. 4 bits a pass, only as many passes as the key bits in use.
//!
//! The rasterizer sorts splats by depth with it, then their (tile, splat)
//! pairs by tile, relying on stability to keep each tile's list in depth
//! order; the studio's viewport can sort its splats by depth the same way.
//! The element count is read from a GPU buffer, so a kernel recorded before
//! the sort can decide it without a read-back; the workspace is sized for a
//! capacity fixed when it is made.

use super::Commands;
use super::scan::{GpuScan, ScanKernels};
use super::{Bind, GpuContext, Kernel};

/// Elements per workgroup block in `sort.wgsl`.
const BLOCK: usize = 1024;
/// Most workgroups of the fixed grid.
const MAX_GROUPS: usize = 1024;
/// Digits per pass.
const RADIX_BITS: u32 = 4;
/// Passes for a full 32-bit key.
const MAX_PASSES: usize = 8;

/// The uniform block of `sort.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct SortParams {
    shift: u32,
    groups: u32,
    capacity: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<SortParams>() == 16);

/// The compiled entry points of `sort.wgsl` and `scan.wgsl`.
#[derive(Debug)]
pub struct SortKernels {
    histogram: Kernel,
    scatter: Kernel,
    scan: ScanKernels,
}

impl SortKernels {
    /// Compiles `sort.wgsl` (and `scan.wgsl`, which it uses).
    pub fn new(ctx: &GpuContext) -> Self {
        let src = include_str!("../../../../shaders/sort.wgsl");
        let binds =
            [Bind::Uniform, Bind::Read, Bind::Read, Bind::Read, Bind::ReadWrite, Bind::ReadWrite, Bind::ReadWrite];
        Self {
            histogram: Kernel::new(ctx, "sort.histogram", src, "histogram", &binds),
            scatter: Kernel::new(ctx, "sort.scatter", src, "scatter", &binds),
            scan: ScanKernels::new(ctx),
        }
    }

    /// The scan kernels, for callers that also need prefix sums.
    pub fn scan(&self) -> &ScanKernels {
        &self.scan
    }
}

/// A sort workspace for up to `capacity` elements: the ping-pong buffers,
/// the digit histograms and one uniform per pass, allocated once.
#[derive(Debug)]
pub struct GpuSort {
    capacity: usize,
    groups: u32,
    uniforms: Vec<wgpu::Buffer>,
    hist: wgpu::Buffer,
    hist_scan: GpuScan,
    keys_alt: wgpu::Buffer,
    values_alt: wgpu::Buffer,
    everything: wgpu::Buffer,
}

impl GpuSort {
    /// A workspace sorting at most `capacity` elements.
    pub fn new(ctx: &GpuContext, capacity: usize) -> Self {
        let groups = capacity.div_ceil(BLOCK).clamp(1, MAX_GROUPS);
        let uniforms = (0..MAX_PASSES)
            .map(|p| {
                let params = SortParams {
                    shift: p as u32 * RADIX_BITS,
                    groups: groups as u32,
                    capacity: capacity as u32,
                    _pad: 0,
                };
                ctx.uniform("sort.params", &params)
            })
            .collect();
        Self {
            capacity,
            groups: groups as u32,
            uniforms,
            hist: ctx.zeros("sort.hist", 16 * groups),
            hist_scan: GpuScan::new(ctx, 16 * groups),
            keys_alt: ctx.zeros("sort.keys_alt", capacity),
            values_alt: ctx.zeros("sort.values_alt", capacity),
            everything: ctx.upload("sort.everything", &[capacity as u32]),
        }
    }

    /// The most elements one sort handles.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// A count buffer holding the capacity, for sorting every element.
    pub fn everything(&self) -> &wgpu::Buffer {
        &self.everything
    }

    /// Records a stable sort of the first `n` elements of `keys` and `values`
    /// by the low `key_bits` bits of the keys (higher bits must be zero), with
    /// `n = min(count[0], capacity)` read on the GPU. Both buffers hold at
    /// least `capacity` words.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        k: &SortKernels,
        encoder: &mut dyn Commands,
        count: &wgpu::Buffer,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        key_bits: u32,
    ) {
        let passes = key_bits.div_ceil(RADIX_BITS).min(MAX_PASSES as u32) as usize;
        let groups = [self.groups, 1, 1];
        for p in 0..passes {
            let (src, dst) = if p % 2 == 0 {
                ((keys, values), (&self.keys_alt, &self.values_alt))
            } else {
                ((&self.keys_alt, &self.values_alt), (keys, values))
            };
            let bufs = [&self.uniforms[p], count, src.0, src.1, &self.hist, dst.0, dst.1];
            k.histogram.dispatch(ctx, encoder, &bufs, groups);
            self.hist_scan.record(ctx, &k.scan, encoder, &self.hist);
            k.scatter.dispatch(ctx, encoder, &bufs, groups);
        }
        if passes % 2 == 1 {
            let bytes = (self.capacity.max(1) * 4) as u64;
            encoder.encoder().copy_buffer_to_buffer(&self.keys_alt, 0, keys, 0, bytes);
            encoder.encoder().copy_buffer_to_buffer(&self.values_alt, 0, values, 0, bytes);
        }
    }
}

/// The number of bits needed to hold every value below `n` (at least 1).
pub fn bits_for(n: u32) -> u32 {
    (32 - n.saturating_sub(1).leading_zeros()).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};

    fn check(n: usize, capacity: usize, key_bits: u32, seed: u64) {
        let ctx = ctx();
        let k = SortKernels::new(ctx);
        let mask = if key_bits >= 32 { u32::MAX } else { (1u32 << key_bits) - 1 };
        // Few distinct keys at small widths: many duplicates, whose values must keep their order.
        let keys: Vec<u32> = noise(n, seed).iter().map(|x| (x.to_bits().wrapping_mul(2_654_435_761)) & mask).collect();
        let values: Vec<u32> = (0..n as u32).collect();
        let mut kbuf = keys.clone();
        let mut vbuf = values.clone();
        // Past n: noise that must stay where it is.
        let tail: Vec<u32> = noise(capacity - n, seed + 1).iter().map(|x| x.to_bits()).collect();
        kbuf.extend(&tail);
        vbuf.extend(&tail);
        let kb = ctx.upload("keys", &kbuf);
        let vb = ctx.upload("values", &vbuf);
        let count = ctx.upload("count", &[n as u32]);
        let sort = GpuSort::new(ctx, capacity);
        let mut enc = ctx.encoder("sort test");
        sort.record(ctx, &k, &mut enc, &count, &kb, &vb, key_bits);
        ctx.submit(enc);
        let got_k: Vec<u32> = ctx.read(&kb).expect("read back");
        let got_v: Vec<u32> = ctx.read(&vb).expect("read back");
        let mut want: Vec<(u32, u32)> = keys.iter().copied().zip(values).collect();
        want.sort_by_key(|&(k, _)| k); // stable
        let (want_k, want_v): (Vec<u32>, Vec<u32>) = want.into_iter().unzip();
        assert_eq!(got_k[..n], want_k[..], "keys, n {n}, bits {key_bits}");
        assert_eq!(got_v[..n], want_v[..], "values (stability), n {n}, bits {key_bits}");
        if key_bits.div_ceil(4).is_multiple_of(2) {
            assert_eq!(got_k[n..], tail[..], "elements past n moved");
        }
    }

    #[test]
    fn matches_a_stable_cpu_sort() {
        check(1, 1, 32, 1);
        check(1000, 1500, 5, 2);
        check(4097, 4097, 32, 3);
        check(70_001, 80_000, 12, 4);
        check(3000, 5000, 31, 5);
        check(2_500_000 / 10, 300_000, 8, 6);
        // More blocks than the grid has workgroups: each owns several.
        check(2_200_000, 2_500_000, 20, 8);
        check(1_200_000, 1_300_000, 5, 9);
    }

    #[test]
    fn a_count_of_zero_sorts_nothing() {
        check(0, 100, 16, 7);
    }

    #[test]
    fn bits_cover_the_range() {
        assert_eq!(bits_for(0), 1);
        assert_eq!(bits_for(1), 1);
        assert_eq!(bits_for(2), 1);
        assert_eq!(bits_for(3), 2);
        assert_eq!(bits_for(256), 8);
        assert_eq!(bits_for(257), 9);
    }
}
