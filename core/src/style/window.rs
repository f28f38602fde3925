//! VGG on the covered window only: with object focus, the feature positions
//! the losses read are those the scene covers, and each of them depends on a
//! bounded patch of the input (its receptive field), so the three forwards
//! and two backwards of a step need only the covered positions' bounding box
//! grown by that field, not the whole frame.
//!
//! A relu3_3 position `i` (feature grid, a quarter of the VGG input) reads
//! input rows `4i − 18 ..= 4i + 21`: conv1_1/1_2 add 2 on each side, the first
//! pool doubles, conv2_1/2_2 add 2 more at half resolution, the second pool
//! doubles again, conv3_1..3 add 3 at a quarter. So a margin of
//! [`MARGIN_CELLS`] feature cells (20 input pixels) on each side keeps every
//! activation in the covered positions' cones equal to the whole frame's, and
//! the losses and gradients are the same; pixels outside the window get a
//! zero gradient, which is what they get from the whole-frame pass as well.
//!
//! The window's top-left corner sits on a multiple of [`ALIGN_CELLS`] cells
//! (16 input pixels), so the pools and Winograd's 4×4 tiles fall on the same
//! grid at every stage as in the whole frame. The window reaches the frame's
//! bottom or right edge exactly when it includes the last feature row or
//! column, so the floor of the pools and the zero padding there are the
//! frame's own.
//!
//! Inside the window, VGG computes only the cone of the covered box
//! ([`crate::vision::vgg_cone`]), which is smaller still at the deep layers.

use crate::vision::vgg_cone::Region;

/// Feature cells added on each side of the covered bounding box (≥ 18 input pixels).
pub const MARGIN_CELLS: usize = 5;
/// The window's origin is a multiple of this many feature cells.
pub const ALIGN_CELLS: usize = 4;

/// The bounding box of the covered positions of `fmask` (`fh × fw`), or `None`
/// when nothing is covered.
pub fn covered_box(fmask: &[bool], fh: usize, fw: usize) -> Option<Region> {
    assert_eq!(fmask.len(), fh * fw, "covered_box: mask size");
    let (mut y0, mut y1, mut x0, mut x1) = (usize::MAX, 0, usize::MAX, 0);
    for (k, _) in fmask.iter().enumerate().filter(|(_, c)| **c) {
        let (y, x) = (k / fw, k % fw);
        (y0, y1, x0, x1) = (y0.min(y), y1.max(y + 1), x0.min(x), x1.max(x + 1));
    }
    (y1 > 0).then_some(Region { y0, y1, x0, x1 })
}

/// A rectangle of the feature grid, `y0..y1 × x0..x1`, and the frame it lies in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FeatureWindow {
    /// First feature row.
    pub y0: usize,
    /// One past the last feature row.
    pub y1: usize,
    /// First feature column.
    pub x0: usize,
    /// One past the last feature column.
    pub x1: usize,
    /// The whole feature grid's rows.
    pub fh: usize,
    /// The whole feature grid's columns.
    pub fw: usize,
}

impl FeatureWindow {
    /// The window VGG needs for the covered positions of `fmask` (`fh × fw`),
    /// or `None` when nothing is covered or the window is the whole grid.
    pub fn covering(fmask: &[bool], fh: usize, fw: usize) -> Option<Self> {
        covered_box(fmask, fh, fw).and_then(|b| Self::around(b, fh, fw))
    }

    /// The window around the box `cells` of an `fh × fw` grid, or `None` when
    /// it is the whole grid.
    pub fn around(cells: Region, fh: usize, fw: usize) -> Option<Self> {
        let lo = |v: usize| v.saturating_sub(MARGIN_CELLS) / ALIGN_CELLS * ALIGN_CELLS;
        let win = Self {
            y0: lo(cells.y0),
            y1: (cells.y1 + MARGIN_CELLS).min(fh),
            x0: lo(cells.x0),
            x1: (cells.x1 + MARGIN_CELLS).min(fw),
            fh,
            fw,
        };
        (win.cells() < fh * fw).then_some(win)
    }

    /// `cells` (a box of the whole grid inside the window) in the window's own grid.
    pub fn local(&self, cells: Region) -> Region {
        Region { y0: cells.y0 - self.y0, y1: cells.y1 - self.y0, x0: cells.x0 - self.x0, x1: cells.x1 - self.x0 }
    }

    /// Feature positions inside the window.
    pub fn cells(&self) -> usize {
        (self.y1 - self.y0) * (self.x1 - self.x0)
    }

    /// The window's share of the frame's feature positions.
    pub fn share(&self) -> f32 {
        self.cells() as f32 / (self.fh * self.fw).max(1) as f32
    }

    /// Input pixel rows and columns of the window in an `h × w` VGG input
    /// (whose feature grid is `fh × fw`): four per cell, to the frame's edge
    /// where the window reaches the last cell.
    fn pixels(&self, h: usize, w: usize) -> ((usize, usize), (usize, usize)) {
        let end = |c1: usize, f: usize, n: usize| if c1 == f { n } else { 4 * c1 };
        ((4 * self.y0, end(self.y1, self.fh, h)), (4 * self.x0, end(self.x1, self.fw, w)))
    }

    /// The window of an HWC image with `c` channels at `h × w`, and its size.
    pub fn crop_image(&self, img: &[f32], h: usize, w: usize, c: usize) -> (Vec<f32>, usize, usize) {
        assert_eq!(img.len(), h * w * c, "FeatureWindow::crop_image: image size");
        let ((r0, r1), (c0, c1)) = self.pixels(h, w);
        let mut out = Vec::with_capacity((r1 - r0) * (c1 - c0) * c);
        for y in r0..r1 {
            out.extend_from_slice(&img[(y * w + c0) * c..(y * w + c1) * c]);
        }
        (out, r1 - r0, c1 - c0)
    }

    /// Adjoint of [`FeatureWindow::crop_image`]: the `h × w` image that is
    /// `part` inside the window and zero outside.
    pub fn uncrop_image(&self, part: &[f32], h: usize, w: usize, c: usize) -> Vec<f32> {
        let ((r0, r1), (c0, c1)) = self.pixels(h, w);
        let row = (c1 - c0) * c;
        assert_eq!(part.len(), (r1 - r0) * row, "FeatureWindow::uncrop_image: part size");
        let mut out = vec![0.0; h * w * c];
        for (y, src) in (r0..r1).zip(part.chunks_exact(row)) {
            out[(y * w + c0) * c..(y * w + c1) * c].copy_from_slice(src);
        }
        out
    }

    /// The whole grid's `ch × fh × fw` channel-major map that is the window's
    /// map `part` inside and zero outside.
    pub fn embed_features(&self, part: &[f32], ch: usize) -> Vec<f32> {
        let (wh, ww) = (self.y1 - self.y0, self.x1 - self.x0);
        assert_eq!(part.len(), ch * wh * ww, "FeatureWindow::embed_features: part size");
        let mut out = vec![0.0; ch * self.fh * self.fw];
        for (dst, src) in out.chunks_exact_mut(self.fh * self.fw).zip(part.chunks_exact(wh * ww)) {
            for (y, s) in (self.y0..self.y1).zip(src.chunks_exact(ww)) {
                dst[y * self.fw + self.x0..y * self.fw + self.x1].copy_from_slice(s);
            }
        }
        out
    }

    /// The window's part of a whole grid's `ch × fh × fw` map.
    pub fn crop_features(&self, full: &[f32], ch: usize) -> Vec<f32> {
        let n = self.fh * self.fw;
        assert_eq!(full.len(), ch * n, "FeatureWindow::crop_features: map size");
        let mut out = Vec::with_capacity(ch * self.cells());
        for plane in full.chunks_exact(n) {
            for y in self.y0..self.y1 {
                out.extend_from_slice(&plane[y * self.fw + self.x0..y * self.fw + self.x1]);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_covers_the_box_with_its_margin_on_the_aligned_grid() {
        let (fh, fw) = (32, 40);
        let mut m = vec![false; fh * fw];
        for y in 13..17 {
            for x in 21..30 {
                m[y * fw + x] = true;
            }
        }
        let win = FeatureWindow::covering(&m, fh, fw).expect("a window");
        // 13 − 5 = 8 (aligned), 17 + 5 = 22; 21 − 5 = 16, 30 + 5 = 35.
        assert_eq!((win.y0, win.y1, win.x0, win.x1), (8, 22, 16, 35));
        // Near the edges the window is clamped, and a box that needs the whole grid gives none.
        m.iter_mut().for_each(|c| *c = false);
        m[0] = true;
        m[fh * fw - 1] = true;
        assert_eq!(FeatureWindow::covering(&m, fh, fw), None);
        assert_eq!(FeatureWindow::covering(&vec![false; fh * fw], fh, fw), None);
    }

    #[test]
    fn crops_and_embeds_are_adjoint() {
        let win = FeatureWindow { y0: 4, y1: 9, x0: 0, x1: 6, fh: 9, fw: 12 };
        let (h, w, c) = (38, 49, 3);
        let img: Vec<f32> = (0..h * w * c).map(|i| i as f32).collect();
        let (part, ph, pw) = win.crop_image(&img, h, w, c);
        // The window reaches the last row, so it runs to the image's edge (38 − 16 rows).
        assert_eq!((ph, pw), (22, 24));
        let back = win.uncrop_image(&part, h, w, c);
        for y in 0..h {
            for x in 0..w {
                let inside = y >= 16 && x < 24;
                for k in 0..c {
                    let i = (y * w + x) * c + k;
                    assert_eq!(back[i], if inside { img[i] } else { 0.0 });
                }
            }
        }
        let ch = 2;
        let full: Vec<f32> = (0..ch * 9 * 12).map(|i| i as f32 + 1.0).collect();
        let small = win.crop_features(&full, ch);
        assert_eq!(small.len(), ch * win.cells());
        let again = win.embed_features(&small, ch);
        for (i, (&a, &b)) in again.iter().zip(&full).enumerate() {
            let (y, x) = ((i % 108) / 12, i % 12);
            assert_eq!(a, if (4..9).contains(&y) && x < 6 { b } else { 0.0 });
        }
    }
}
