//! VGG on the object's window of the frame: the GPU twin of
//! [`crate::style::window`]. With the object focus every feature-space loss
//! reads the covered positions only, and a relu3 position depends on a
//! bounded patch of the input, so the three forwards and two backwards of a
//! step need only the covered positions' bounding box grown by
//! [`MARGIN_CELLS`] cells, not the whole frame: the same losses and
//! gradients, for the window's share of the work.
//!
//! A plan holds one window size (the largest any of its views has needed so
//! far, [`WindowSize::grown`]); each view's window of that size is placed
//! over its own covered box ([`VggWindow::place`]). The window's image is cut
//! out of the downscaled map, VGG runs on it, and its features are put back
//! into the frame's feature grid (zero outside); backwards, the features'
//! gradient is cut out and the image gradient put back (zero outside, as the
//! whole frame's is there). The window's origin is a whole feature cell (four
//! input pixels), so the pools fall as in the frame; the GEMM sums every
//! output over the same taps in the same order either way. Frames whose VGG
//! input is not four whole pixels a cell (an odd half) run the whole frame.

use std::sync::atomic::{AtomicU64, Ordering};

use super::Commands;
use super::{Bind, GpuContext, GpuVgg, GpuVggState, GpuVggWorkspace, Kernel};
use crate::style::window::MARGIN_CELLS;
use crate::vision::vgg::FEATURE_CHANNELS;
use crate::vision::vgg_cone::Region;

/// Threads per workgroup of `window.wgsl`.
const WORKGROUP: u32 = 256;

/// Above this share of the frame's feature positions a window saves too
/// little to be worth its copies: the plan runs the whole frame.
pub const MAX_SHARE: f64 = 0.8;

/// The uniform block of `window.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct RectParams {
    planes: u32,
    rows: u32,
    cols: u32,
    src_w: u32,
    src_plane: u32,
    src_off: u32,
    dst_w: u32,
    dst_plane: u32,
    dst_off: u32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<RectParams>() == 48);

impl RectParams {
    fn items(&self) -> usize {
        (self.planes * self.rows * self.cols) as usize
    }
}

/// The copy kernel of `window.wgsl`, compiled once per context.
#[derive(Debug)]
pub struct WindowKernel(Kernel);

impl WindowKernel {
    /// Compiles `window.wgsl`.
    pub fn new(ctx: &GpuContext) -> Self {
        let src = include_str!("../../../../shaders/window.wgsl");
        Self(Kernel::new(ctx, "window.copy_rect", src, "copy_rect", &[Bind::Uniform, Bind::Read, Bind::ReadWrite]))
    }
}

/// The rows `lo..hi` of an `n`-cell dimension a window must hold for the
/// covered cells `c0..c1`: the covered span and its margin, within the frame.
fn span(c0: usize, c1: usize, n: usize) -> (usize, usize) {
    (c0.saturating_sub(MARGIN_CELLS), (c1 + MARGIN_CELLS).min(n))
}

/// A window's size in feature cells, rows × columns, in an `fh × fw` grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WindowSize {
    /// Rows of cells.
    pub rows: usize,
    /// Columns of cells.
    pub cols: usize,
}

impl WindowSize {
    /// The smallest size (rounded up to four cells, so that a few views do
    /// not each grow it by a cell) at least `self` (when given) that holds
    /// the covered box `b` of an `fh × fw` grid with its margin.
    pub fn grown(this: Option<Self>, b: Region, fh: usize, fw: usize) -> Self {
        let need = |(lo, hi): (usize, usize), n: usize| (hi - lo).div_ceil(4).saturating_mul(4).min(n);
        let rows = need(span(b.y0, b.y1, fh), fh);
        let cols = need(span(b.x0, b.x1, fw), fw);
        match this {
            Some(s) => Self { rows: s.rows.max(rows), cols: s.cols.max(cols) },
            None => Self { rows, cols },
        }
    }

    /// The window's share of the frame's feature positions.
    pub fn share(&self, fh: usize, fw: usize) -> f64 {
        (self.rows * self.cols) as f64 / (fh * fw).max(1) as f64
    }
}

/// VGG's buffers at one window size of one frame size, and the copies
/// between the window and the frame.
#[derive(Debug)]
pub struct VggWindow {
    /// The frame's feature grid, rows × columns (its VGG input is four
    /// pixels a cell).
    grid: (usize, usize),
    size: WindowSize,
    ws: GpuVggWorkspace,
    /// The RGB, depth and edge maps' states at the window's size.
    states: [GpuVggState; 3],
    /// The three maps' windows (HWC, `4·rows × 4·cols × 3`).
    small: [wgpu::Buffer; 3],
    /// The RGB and depth features' gradients in the window.
    v_feat: [wgpu::Buffer; 2],
    /// The RGB and depth maps' gradients in the window.
    v_small: [wgpu::Buffer; 2],
    /// The copies' uniforms: image cut out, features put back, features'
    /// gradient cut out, image gradient put back.
    params: [wgpu::Buffer; 4],
    /// Their work items.
    items: [usize; 4],
    /// The origin the uniforms hold, rows in the high half (made at (0, 0)).
    placed: AtomicU64,
}

impl VggWindow {
    /// The buffers of a `size` window of an `fh × fw` feature grid.
    pub fn new(ctx: &GpuContext, vgg: &GpuVgg, (fh, fw): (usize, usize), size: WindowSize) -> Self {
        let (ih, iw) = (4 * size.rows, 4 * size.cols);
        let first = Self::copies((fh, fw), size, (0, 0));
        Self {
            grid: (fh, fw),
            size,
            ws: vgg.workspace(ctx, ih, iw),
            states: std::array::from_fn(|_| GpuVggState::new(ctx, ih, iw)),
            small: std::array::from_fn(|_| ctx.zeros("window.small", ih * iw * 3)),
            v_feat: std::array::from_fn(|_| ctx.zeros("window.v_feat", FEATURE_CHANNELS * size.rows * size.cols)),
            v_small: std::array::from_fn(|_| ctx.zeros("window.v_small", ih * iw * 3)),
            params: first.map(|p| ctx.uniform("window.params", &p)),
            items: first.map(|p| p.items()),
            placed: AtomicU64::new(0),
        }
    }

    /// The window's size in cells.
    pub fn size(&self) -> WindowSize {
        self.size
    }

    /// The four copies of a window at cell `(oy, ox)`.
    fn copies((fh, fw): (usize, usize), size: WindowSize, (oy, ox): (usize, usize)) -> [RectParams; 4] {
        let u = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        let (rows, cols) = (size.rows, size.cols);
        // Images: one plane of HWC rows, 4 pixels × 3 values a cell across.
        let (frame_row, win_row) = (12 * fw, 12 * cols);
        let image_off = 4 * oy * frame_row + 12 * ox;
        let image = |src_w, src_off, dst_w, dst_off| RectParams {
            planes: 1,
            rows: u(4 * rows),
            cols: u(win_row),
            src_w: u(src_w),
            src_plane: 0,
            src_off: u(src_off),
            dst_w: u(dst_w),
            dst_plane: 0,
            dst_off: u(dst_off),
            _pad: [0; 3],
        };
        // Features: one plane per channel.
        let (frame_plane, win_plane, feat_off) = (fh * fw, rows * cols, oy * fw + ox);
        let features = |src_w, src_plane, src_off, dst_w, dst_plane, dst_off| RectParams {
            planes: u(FEATURE_CHANNELS),
            rows: u(rows),
            cols: u(cols),
            src_w: u(src_w),
            src_plane: u(src_plane),
            src_off: u(src_off),
            dst_w: u(dst_w),
            dst_plane: u(dst_plane),
            dst_off: u(dst_off),
            _pad: [0; 3],
        };
        [
            image(frame_row, image_off, win_row, 0),
            features(cols, win_plane, 0, fw, frame_plane, feat_off),
            features(fw, frame_plane, feat_off, cols, win_plane, 0),
            image(win_row, 0, frame_row, image_off),
        ]
    }

    /// The origin (first cell row and column) of this size's window over the
    /// covered box `b`: at the box's margin, moved back inside the frame.
    pub fn origin(&self, b: Region) -> (usize, usize) {
        let (fh, fw) = self.grid;
        (span(b.y0, b.y1, fh).0.min(fh - self.size.rows), span(b.x0, b.x1, fw).0.min(fw - self.size.cols))
    }

    /// Whether the covered box `b` and its margin fit a window of this size.
    pub fn holds(&self, b: Region) -> bool {
        let (fh, fw) = self.grid;
        let ((y0, y1), (x0, x1)) = (span(b.y0, b.y1, fh), span(b.x0, b.x1, fw));
        y1 - y0 <= self.size.rows && x1 - x0 <= self.size.cols
    }

    /// Places the window over the covered box `b` for the commands submitted
    /// next (the copies' uniforms are written through the queue).
    pub fn place(&self, ctx: &GpuContext, b: Region) {
        let origin = self.origin(b);
        let key = ((origin.0 as u64) << 32) | origin.1 as u64;
        if self.placed.swap(key, Ordering::Relaxed) == key {
            return;
        }
        let copies = Self::copies(self.grid, self.size, origin);
        for (buffer, p) in self.params.iter().zip(&copies) {
            ctx.write(buffer, std::slice::from_ref(p));
        }
    }

    fn copy(
        &self,
        ctx: &GpuContext,
        k: &WindowKernel,
        enc: &mut dyn Commands,
        which: usize,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
    ) {
        let groups = Kernel::groups_1d(self.items[which], WORKGROUP);
        k.0.dispatch(ctx, enc, &[&self.params[which], src, dst], groups);
    }

    /// Records VGG's forward pass of map `m` (0 RGB, 1 depth, 2 edge) on the
    /// window of `small` (the frame's downscaled map, HWC), its features put
    /// into `features` (the frame's grid, CHW; zero outside the window).
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        ctx: &GpuContext,
        k: &WindowKernel,
        vgg: &GpuVgg,
        enc: &mut dyn Commands,
        m: usize,
        small: &wgpu::Buffer,
        features: &wgpu::Buffer,
    ) {
        self.copy(ctx, k, enc, 0, small, &self.small[m]);
        vgg.forward(ctx, enc, &self.ws, &self.small[m], &self.states[m]);
        enc.encoder().clear_buffer(features, 0, None);
        self.copy(ctx, k, enc, 1, self.states[m].features(), features);
    }

    /// Records VGG's backward pass of map `m` (0 RGB, 1 depth) on the window:
    /// the window's part of `v_features` (the frame's grid) back to `v_small`
    /// (the frame's downscaled map, zero outside the window).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        ctx: &GpuContext,
        k: &WindowKernel,
        vgg: &GpuVgg,
        enc: &mut dyn Commands,
        m: usize,
        v_features: &wgpu::Buffer,
        v_small: &wgpu::Buffer,
    ) {
        self.copy(ctx, k, enc, 2, v_features, &self.v_feat[m]);
        vgg.backward(ctx, enc, &self.ws, &self.states[m], &self.v_feat[m], &self.v_small[m]);
        enc.encoder().clear_buffer(v_small, 0, None);
        self.copy(ctx, k, enc, 3, &self.v_small[m], v_small);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_holds_each_box_with_its_margin_inside_the_frame() {
        let b = |y0, y1, x0, x1| Region { y0, y1, x0, x1 };
        let (fh, fw) = (64, 48);
        // A box in the middle: its span and margin, rounded up to four cells.
        let s = WindowSize::grown(None, b(20, 30, 10, 17), fh, fw);
        assert_eq!(s, WindowSize { rows: 20, cols: 20 });
        // Another view's larger box grows it; a smaller one does not shrink it.
        let s = WindowSize::grown(Some(s), b(0, 3, 0, 30), fh, fw);
        assert_eq!(s, WindowSize { rows: 20, cols: 36 });
        assert_eq!(WindowSize::grown(Some(s), b(30, 31, 5, 6), fh, fw), s);
        // Never past the frame.
        assert_eq!(WindowSize::grown(None, b(0, 64, 0, 48), fh, fw), WindowSize { rows: 64, cols: 48 });
        assert!((s.share(fh, fw) - 720.0 / 3072.0).abs() < 1e-12);
    }
}
