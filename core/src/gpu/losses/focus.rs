//! The object focus on the GPU (`shaders/focus.wgsl`): the masks that make
//! GCFM, content, TV and the depth map's normalisation look only at what the
//! scene covers, as [`crate::style::focus`] does on the CPU.
//!
//! A [`GpuFocus`] is made once per view from the alpha of the colour-matched
//! render (the pixel mask: alpha above [`COVERAGE_ALPHA`], eroded by
//! [`COVERAGE_ERODE_PX`]), with the feature-position mask at relu3 resolution
//! and the counts the masked means divide by, all on the device. The loss
//! kernels multiply by the masks and read the counts from the device, so the
//! whole frame is the same code with an all-ones mask ([`GpuFocus::frame`])
//! and a step reads nothing back.

use std::sync::Arc;

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel, ReduceKernels, ReduceOp, ReduceSpec, Reduction};
use crate::style::focus::{COVERAGE_ALPHA, COVERAGE_ERODE_PX};

/// Threads per workgroup in `focus.wgsl`.
const WORKGROUP: u32 = 256;

/// Where each count lives in [`GpuFocus::counts`] (in `f32`s).
pub mod count {
    /// Covered feature positions.
    pub const CELLS: usize = 0;
    /// Horizontal pixel pairs with both pixels covered (TV's horizontal differences per channel).
    pub const PAIRS_H: usize = 1;
    /// Vertical pixel pairs with both pixels covered.
    pub const PAIRS_V: usize = 2;
    /// Floats in the counts buffer.
    pub const LEN: usize = 4;
}

/// The uniform block of `focus.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct FocusParams {
    h: u32,
    w: u32,
    fh: u32,
    fw: u32,
    radius: u32,
    threshold: f32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<FocusParams>() == 32);
// The pairs reduction writes its two lanes next to each other.
const _: () = assert!(count::PAIRS_V == count::PAIRS_H + 1);

/// The compiled entry points of `focus.wgsl`.
#[derive(Debug)]
pub struct FocusKernels {
    coverage: Kernel,
    cells: Kernel,
    pairs: Kernel,
}

impl FocusKernels {
    /// Compiles `focus.wgsl`.
    pub fn new(ctx: &GpuContext) -> Arc<Self> {
        let src = include_str!("../../../../shaders/focus.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::ReadWrite];
        let k = |entry: &str| Kernel::new(ctx, &format!("focus.{entry}"), src, entry, &binds);
        Arc::new(Self { coverage: k("coverage"), cells: k("cells"), pairs: k("pairs") })
    }
}

/// The pixels and feature positions one view's losses average over, and their counts.
#[derive(Debug)]
pub struct GpuFocus {
    /// `h × w` pixel mask (1 covered, 0 not).
    pixels: wgpu::Buffer,
    /// `fh × fw` feature-position mask.
    cells: wgpu::Buffer,
    /// The counts ([`count`]), as `f32`s.
    counts: wgpu::Buffer,
}

impl GpuFocus {
    /// The whole frame of `h × w` renders with `fh × fw` features: all-ones
    /// masks (the paper's losses).
    pub fn frame(ctx: &GpuContext, h: usize, w: usize, fh: usize, fw: usize) -> Self {
        let counts = [(fh * fw) as f32, (h * w.saturating_sub(1)) as f32, (h.saturating_sub(1) * w) as f32, 0.0];
        Self {
            pixels: ctx.upload("focus.frame.pixels", &vec![1.0f32; (h * w).max(1)]),
            cells: ctx.upload("focus.frame.cells", &vec![1.0f32; (fh * fw).max(1)]),
            counts: ctx.upload("focus.frame.counts", &counts),
        }
    }

    /// Records the focus of an `h × w` render with alpha `alpha` and `fh × fw`
    /// features: the pixel mask, the cell mask and their counts.
    #[allow(clippy::too_many_arguments)]
    pub fn from_alpha(
        ctx: &GpuContext,
        k: &FocusKernels,
        reduce: &Arc<ReduceKernels>,
        enc: &mut dyn Commands,
        alpha: &wgpu::Buffer,
        (h, w): (usize, usize),
        (fh, fw): (usize, usize),
    ) -> Result<Self, GpuError> {
        let (n, cells_n) = (h * w, fh * fw);
        let params = FocusParams {
            h: h as u32,
            w: w as u32,
            fh: fh as u32,
            fw: fw as u32,
            radius: COVERAGE_ERODE_PX as u32,
            threshold: COVERAGE_ALPHA,
            _pad: [0; 2],
        };
        let focus = Self {
            pixels: ctx.zeros("focus.pixels", n.max(1)),
            cells: ctx.zeros("focus.cells", cells_n.max(1)),
            counts: ctx.zeros("focus.counts", count::LEN),
        };
        let uniform = ctx.uniform("focus.params", &params);
        let pairs = ctx.zeros("focus.pairs", 2 * n.max(1));
        let sum_cells = Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, cells_n).to(count::CELLS))?;
        let sum_pairs = Reduction::new(ctx, reduce, ReduceSpec::new(ReduceOp::Sum, n).lanes(2).to(count::PAIRS_H))?;
        k.coverage.dispatch(ctx, enc, &[&uniform, alpha, &focus.pixels], Kernel::groups_1d(n, WORKGROUP));
        k.cells.dispatch(ctx, enc, &[&uniform, &focus.pixels, &focus.cells], Kernel::groups_1d(cells_n, WORKGROUP));
        k.pairs.dispatch(ctx, enc, &[&uniform, &focus.pixels, &pairs], Kernel::groups_1d(n, WORKGROUP));
        sum_cells.record(ctx, enc, &focus.cells, &focus.counts);
        sum_pairs.record(ctx, enc, &pairs, &focus.counts);
        Ok(focus)
    }

    /// The pixel mask (`h × w`, 1 or 0).
    pub fn pixels(&self) -> &wgpu::Buffer {
        &self.pixels
    }

    /// The feature-position mask (`fh × fw`, 1 or 0).
    pub fn cells(&self) -> &wgpu::Buffer {
        &self.cells
    }

    /// The counts ([`count`]).
    pub fn counts(&self) -> &wgpu::Buffer {
        &self.counts
    }

    /// Reads back the feature-position mask ([`GpuFocus::cells`]) as flags.
    pub fn covered_mask(&self, ctx: &GpuContext) -> Result<Vec<bool>, GpuError> {
        let cells: Vec<f32> = ctx.read(&self.cells)?;
        Ok(cells.iter().map(|&c| c != 0.0).collect())
    }

    /// Reads back how many feature positions are covered (once per view,
    /// after the submission that made the focus): with none, the CPU falls
    /// back to the whole frame, and so does the engine.
    pub fn covered_cells(&self, ctx: &GpuContext) -> Result<usize, GpuError> {
        let c: Vec<f32> = ctx.read(&self.counts)?;
        Ok(c[count::CELLS] as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::focus::{coverage_mask, feature_mask};

    #[test]
    fn masks_and_counts_match_the_cpu() {
        let ctx = ctx();
        let (k, reduce) = (FocusKernels::new(ctx), ReduceKernels::new(ctx));
        for (s, &(h, w, fh, fw)) in
            [(23usize, 31usize, 5usize, 7usize), (64, 48, 8, 6), (12, 9, 2, 1), (40, 40, 5, 5)].iter().enumerate()
        {
            // A soft blob plus noise: covered, rim and background, with ragged edges.
            let wobble = noise(h * w, 60 + s as u64);
            let alpha: Vec<f32> = (0..h * w)
                .map(|p| {
                    let (y, x) = ((p / w) as f32 / h as f32 - 0.5, (p % w) as f32 / w as f32 - 0.45);
                    (1.6 - 3.0 * (x * x + y * y).sqrt() + 0.3 * wobble[p]).clamp(0.0, 1.0)
                })
                .collect();
            let a = ctx.upload("alpha", &alpha);
            let mut enc = ctx.encoder("focus test");
            let f = GpuFocus::from_alpha(ctx, &k, &reduce, &mut enc, &a, (h, w), (fh, fw)).expect("focus");
            // Noise in the outputs: written before the submission, so before the kernels run.
            ctx.write(&f.pixels, &noise(h * w, 4));
            ctx.write(&f.cells, &noise(fh * fw, 5));
            ctx.write(&f.counts, &noise(count::LEN, 6));
            ctx.submit(enc);
            let want = coverage_mask(&alpha, h, w);
            let want_cells = feature_mask(&want, h, w, fh, fw);
            let got: Vec<f32> = ctx.read(&f.pixels).expect("pixels");
            let got_cells: Vec<f32> = ctx.read(&f.cells).expect("cells");
            let counts: Vec<f32> = ctx.read(&f.counts).expect("counts");
            let on = want.iter().filter(|&&v| v).count();
            assert!(on > 0 && on < h * w, "{h}×{w}: the test alpha covers part of the frame ({on})");
            for p in 0..h * w {
                assert_eq!(got[p], f32::from(u8::from(want[p])), "{h}×{w} pixel {p}");
            }
            for c in 0..fh * fw {
                assert_eq!(got_cells[c], f32::from(u8::from(want_cells[c])), "{h}×{w} cell {c}");
            }
            let pairs_h = (0..h * w).filter(|&p| p % w + 1 < w && want[p] && want[p + 1]).count();
            let pairs_v = (0..h * w).filter(|&p| p / w + 1 < h && want[p] && want[p + w]).count();
            let cells = want_cells.iter().filter(|&&v| v).count();
            assert_eq!(counts[..3], [cells as f32, pairs_h as f32, pairs_v as f32], "{h}×{w} counts");
            assert_eq!(f.covered_cells(ctx).expect("read"), cells);
        }
    }

    #[test]
    fn the_frame_covers_everything() {
        let ctx = ctx();
        let f = GpuFocus::frame(ctx, 6, 5, 3, 2);
        let counts: Vec<f32> = ctx.read(&f.counts).expect("counts");
        assert_eq!(counts, [6.0, 24.0, 25.0, 0.0]);
        assert!(ctx.read::<f32>(&f.pixels).expect("pixels").iter().all(|&v| v == 1.0));
        assert_eq!(f.covered_cells(ctx).expect("read"), 6);
    }
}
