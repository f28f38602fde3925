//! The part of each VGG layer that a rectangle of relu3 features depends on.
//!
//! With the losses focused on the object, only the relu3 positions inside
//! the covered box matter. Each layer then needs its output only where the
//! next layer reads it: relu3_3 on the box, relu3_2 one position around it,
//! relu3_1 two, the second pool's output three, and so on back to the input,
//! doubling at each pool. That cone is much smaller than the receptive-field
//! window of `style::window` at the deep layers, where most of the work is.
//!
//! Every convolution runs as usual ("same", zero padded) on its input's
//! region, and its output is cut back by one position on each side that is
//! not the plane's edge: exactly the positions whose 3×3 neighbourhood lay
//! inside the region. So the kept values equal the whole-frame network's,
//! and the backward pass is the same cone in reverse (the cut ring gets a
//! zero gradient). With the box covering the whole grid, every convolution
//! runs on and keeps its whole plane, as the plain pass does.

/// A rectangle `y0..y1 × x0..x1` of a plane.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    /// First row.
    pub y0: usize,
    /// One past the last row.
    pub y1: usize,
    /// First column.
    pub x0: usize,
    /// One past the last column.
    pub x1: usize,
}

impl Region {
    /// The whole `h × w` plane.
    pub fn full(h: usize, w: usize) -> Self {
        Self { y0: 0, y1: h, x0: 0, x1: w }
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.y1 - self.y0
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.x1 - self.x0
    }

    /// Positions.
    pub fn area(&self) -> usize {
        self.height() * self.width()
    }

    /// Grown by `k` on each side, within an `h × w` plane.
    fn grow(self, k: usize, (h, w): (usize, usize)) -> Self {
        Self {
            y0: self.y0.saturating_sub(k),
            y1: (self.y1 + k).min(h),
            x0: self.x0.saturating_sub(k),
            x1: (self.x1 + k).min(w),
        }
    }

    /// The same rectangle one pool earlier (twice the resolution).
    fn double(self) -> Self {
        Self { y0: 2 * self.y0, y1: 2 * self.y1, x0: 2 * self.x0, x1: 2 * self.x1 }
    }

    /// Within the `h × w` plane and not empty.
    fn clamped(self, (h, w): (usize, usize)) -> Self {
        let (y1, x1) = (self.y1.min(h), self.x1.min(w));
        Self { y0: self.y0.min(y1), y1, x0: self.x0.min(x1), x1 }
    }
}

/// For each of the seven convolutions, the region of its input plane it runs
/// on and the region of its output kept, in that layer's own resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct ConePlan {
    pub input: [Region; 7],
    pub output: [Region; 7],
}

impl ConePlan {
    /// The cone of the relu3 positions in `cells` for an `h × w` input.
    pub fn new(cells: Region, (h, w): (usize, usize)) -> Self {
        let d = [(h, w), (h / 2, w / 2), (h / 4, w / 4)];
        let stage = [0, 0, 1, 1, 2, 2, 2];
        if cells.clamped(d[2]) == Region::full(d[2].0, d[2].1) {
            // The whole grid: every layer whole, as the plain pass.
            let full = std::array::from_fn(|l| Region::full(d[stage[l]].0, d[stage[l]].1));
            return Self { input: full, output: full };
        }
        let mut output = [Region::full(0, 0); 7];
        output[6] = cells.clamped(d[2]);
        output[5] = output[6].grow(1, d[2]);
        output[4] = output[6].grow(2, d[2]);
        // conv3_1 reads the second pool's output around its own.
        output[3] = output[6].grow(3, d[2]).double();
        output[2] = output[3].grow(1, d[1]);
        output[1] = output[3].grow(2, d[1]).double();
        output[0] = output[1].grow(1, d[0]);
        let input = std::array::from_fn(|l| output[l].grow(1, d[stage[l]]));
        Self { input, output }
    }
}

/// The share of a whole forward's multiply-adds (at `h × w`, by im2col's
/// count) that the cone of `cells` does: each convolution's channels times
/// the area it runs on.
pub fn work_share(cells: Region, (h, w): (usize, usize)) -> f64 {
    let (cone, full) = (ConePlan::new(cells, (h, w)), ConePlan::new(Region::full(h / 4, w / 4), (h, w)));
    let work = |p: &ConePlan| -> f64 {
        super::weights::CONV_SHAPES.iter().zip(&p.input).map(|(&(co, ci), r)| (co * ci * r.area()) as f64).sum()
    };
    work(&cone) / work(&full).max(1.0)
}

/// The `inner` part of a `c`-plane stack laid out over `outer` (CHW), as its own stack.
pub(crate) fn crop_planes(src: &[f32], c: usize, outer: Region, inner: Region) -> Vec<f32> {
    if inner == outer {
        return src[..c * outer.area()].to_vec();
    }
    let (oy, ox, ow) = (inner.y0 - outer.y0, inner.x0 - outer.x0, outer.width());
    let mut out = Vec::with_capacity(c * inner.area());
    for plane in src.chunks_exact(outer.area()).take(c) {
        for y in 0..inner.height() {
            let row = (oy + y) * ow + ox;
            out.extend_from_slice(&plane[row..row + inner.width()]);
        }
    }
    out
}

/// Adjoint of [`crop_planes`]: the stack over `outer` that is `src` on
/// `inner` and zero elsewhere.
pub(crate) fn embed_planes(src: &[f32], c: usize, outer: Region, inner: Region) -> Vec<f32> {
    if inner == outer {
        return src[..c * outer.area()].to_vec();
    }
    let (oy, ox, ow) = (inner.y0 - outer.y0, inner.x0 - outer.x0, outer.width());
    let mut out = vec![0.0; c * outer.area()];
    for (plane, part) in out.chunks_exact_mut(outer.area()).zip(src.chunks_exact(inner.area().max(1))).take(c) {
        for (y, s) in part.chunks_exact(inner.width().max(1)).enumerate() {
            let row = (oy + y) * ow + ox;
            plane[row..row + inner.width()].copy_from_slice(s);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_whole_grid_runs_every_convolution_on_its_whole_plane() {
        for (h, w) in [(128, 128), (90, 67), (13, 22)] {
            let plan = ConePlan::new(Region::full(h / 4, w / 4), (h, w));
            let d = [(h, w), (h, w), (h / 2, w / 2), (h / 2, w / 2), (h / 4, w / 4), (h / 4, w / 4), (h / 4, w / 4)];
            for (l, &(lh, lw)) in d.iter().enumerate() {
                assert_eq!(plan.input[l], Region::full(lh, lw), "{h}×{w} conv {l}");
                assert_eq!(plan.output[l], plan.input[l], "{h}×{w} conv {l}");
            }
        }
    }

    #[test]
    fn a_box_grows_by_the_receptive_field_layer_by_layer() {
        let plan = ConePlan::new(Region { y0: 10, y1: 12, x0: 20, x1: 21 }, (256, 256));
        assert_eq!(plan.output[6], Region { y0: 10, y1: 12, x0: 20, x1: 21 });
        assert_eq!(plan.input[6], plan.output[5]);
        assert_eq!(plan.input[5], plan.output[4]);
        assert_eq!(plan.input[4], Region { y0: 7, y1: 15, x0: 17, x1: 24 });
        assert_eq!(plan.output[3], Region { y0: 14, y1: 30, x0: 34, x1: 48 });
        assert_eq!(plan.input[3], plan.output[2]);
        assert_eq!(plan.input[2], Region { y0: 12, y1: 32, x0: 32, x1: 50 });
        assert_eq!(plan.output[1], plan.input[2].double());
        assert_eq!(plan.input[1], plan.output[0]);
        // Input rows 22..66 for relu3_3 rows 10..12: 4·10 − 18 and 4·11 + 21 + 1.
        assert_eq!(plan.input[0], Region { y0: 22, y1: 66, x0: 62, x1: 102 });
    }

    #[test]
    fn crop_and_embed_are_adjoint() {
        let outer = Region { y0: 2, y1: 7, x0: 1, x1: 9 };
        let inner = Region { y0: 3, y1: 6, x0: 4, x1: 8 };
        let src: Vec<f32> = (0..2 * outer.area()).map(|i| i as f32 + 1.0).collect();
        let part = crop_planes(&src, 2, outer, inner);
        assert_eq!(part.len(), 2 * inner.area());
        let back = embed_planes(&part, 2, outer, inner);
        for (i, (&a, &b)) in back.iter().zip(&src).enumerate() {
            let (y, x) = ((i % outer.area()) / outer.width() + outer.y0, i % outer.width() + outer.x0);
            let inside = (inner.y0..inner.y1).contains(&y) && (inner.x0..inner.x1).contains(&x);
            assert_eq!(a, if inside { b } else { 0.0 });
        }
    }
}
