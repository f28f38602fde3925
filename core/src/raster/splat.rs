//! A Gaussian on screen: which pixels it can reach and its falloff there.
//!
//! Forward and backward passes both ask these methods, so they visit exactly
//! the same pixels and compute bit-identical α. Every bound here is
//! conservative: `f32` rounding may let a pass visit a pixel where α < 1/255
//! (and skip it there), never miss one where α ≥ 1/255.

use super::TILE;

/// Smallest α that counts.
pub(crate) const ALPHA_MIN: f32 = 1.0 / 255.0;
/// Largest α.
pub(crate) const ALPHA_MAX: f32 = 0.99;
/// Compositing stops before the transmittance would fall below this.
pub(crate) const T_MIN: f32 = 1e-4;

/// Relative and absolute slack on the screen extent, so that `f32` rounding
/// can only make it larger than the exact α ≥ 1/255 region, never smaller.
pub(crate) const EXTENT_REL: f32 = 1e-3;
pub(crate) const EXTENT_ABS: f32 = 1e-2;
/// A pixel with `power < −cut − POWER_SLACK` has α < 1/255 without asking `exp`.
const POWER_SLACK: f32 = 1e-3;

/// Offsets `0, 1, …` of the pixels in a row run, as floats (a zip with this
/// vectorises where an integer-to-float conversion of the index does not).
pub(crate) const LANE: [f32; TILE as usize] =
    [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0];

/// A Gaussian on screen: all that compositing reads (64 bytes).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
pub(crate) struct Splat {
    /// Projected mean in pixels.
    pub xy: [f32; 2],
    /// Inverse 2D covariance `(A, B, C)`: `power = −½(A dx² + C dy²) − B dx dy`.
    pub conic: [f32; 3],
    /// `σ(opacity logit)`.
    pub opacity: f32,
    /// Colour after the `max(0, ·)` clamp.
    pub color: [f32; 3],
    /// `1 / z`.
    pub inv_z: f32,
    /// Camera `z`, the sort key.
    pub depth: f32,
    /// `ln(255·opacity)`: α ≥ 1/255 needs `power ≥ −cut`.
    pub cut: f32,
    /// Half-widths (x, y) of the box around the ellipse `power ≥ −cut`, with slack.
    pub ext: [f32; 2],
    /// `1 / A`, for the row spans.
    pub inv_a: f32,
    /// The determinant `A C − B²` of the conic, for the row spans.
    pub det_conic: f32,
}

const _: () = assert!(std::mem::size_of::<Splat>() == 64);

impl Splat {
    /// The falloff `exp(power)` at the pixel centres `(x_first + k, py)` of
    /// a tile row for `k` in `lo..=hi`, written to `out[k]`, or 0 where the
    /// Gaussian is skipped (`power > 0`, or `power` so low that α < 1/255 for
    /// sure). Other entries of `out` are left unspecified.
    ///
    /// Branch-free: long runs compute the whole fixed-width row, which
    /// vectorises; short runs (most splats are a few pixels wide) compute only
    /// their pixels. Both give bit-identical values (Rust does not contract
    /// to FMA). The caller forms `α = min(0.99, opacity·g)` and applies the
    /// exact `α < 1/255` test.
    #[inline(always)]
    pub fn falloff_row(&self, x_first: f32, py: f32, lo: usize, hi: usize, out: &mut [f32; TILE as usize]) {
        let dy = py - self.xy[1];
        let [a, b, c] = self.conic;
        let (cdy, bdy) = (c * dy * dy, b * dy);
        let floor = -self.cut - POWER_SLACK;
        let dx0 = x_first - self.xy[0];
        let lane = |k: f32| {
            let dx = dx0 + k;
            let power = -0.5 * (a * dx * dx + cdy) - bdy * dx;
            let g = exp_neg(power);
            if power > 0.0 || power < floor { 0.0 } else { g }
        };
        if hi - lo < 8 {
            for (o, &k) in out[lo..=hi].iter_mut().zip(&LANE[lo..=hi]) {
                *o = lane(k);
            }
        } else {
            for (o, &k) in out.iter_mut().zip(&LANE) {
                *o = lane(k);
            }
        }
    }

    /// `α = min(0.99, opacity·g)`, or `None` where it is below 1/255.
    #[inline(always)]
    pub fn alpha(&self, g: f32) -> Option<f32> {
        // Tested before the clamp so that a NaN is skipped, not clamped to 0.99.
        let alpha = self.opacity * g;
        (alpha >= ALPHA_MIN).then(|| alpha.min(ALPHA_MAX))
    }

    /// Inclusive pixel columns and rows `[lo, hi]` whose centres the extent
    /// box covers, clipped to `[x0, x1) × [y0, y1)`; empty when `lo > hi`.
    #[inline(always)]
    pub fn pixel_rect(&self, x0: u32, x1: u32, y0: u32, y1: u32) -> (i64, i64, i64, i64) {
        let (ja, jb) = centre_span(self.xy[0] - self.ext[0], self.xy[0] + self.ext[0], x0, x1);
        let (ia, ib) = centre_span(self.xy[1] - self.ext[1], self.xy[1] + self.ext[1], y0, y1);
        (ja, jb, ia, ib)
    }

    /// The ellipse of pixels that can reach α ≥ 1/255, with slack, as
    /// `A dx² + 2B dx dy + C dy² ≤ reach` (that is `power ≥ −cut − slack`).
    #[inline(always)]
    fn reach(&self) -> f32 {
        2.0 * (self.cut + POWER_SLACK)
    }

    /// Whether the ellipse [`Self::reach`] contains a pixel centre of the
    /// pixel rectangle `[x0, x1) × [y0, y1)`, conservatively: the minimum of
    /// the quadratic form over the rectangle of centres, found on its edges
    /// when the mean lies outside it.
    pub fn touches_rect(&self, x0: u32, x1: u32, y0: u32, y1: u32) -> bool {
        let (xa, xb) = (x0 as f32 + 0.5 - self.xy[0], x1 as f32 - 0.5 - self.xy[0]);
        let (ya, yb) = (y0 as f32 + 0.5 - self.xy[1], y1 as f32 - 0.5 - self.xy[1]);
        if xa <= 0.0 && xb >= 0.0 && ya <= 0.0 && yb >= 0.0 {
            return true;
        }
        let [a, b, c] = self.conic;
        let q = |dx: f32, dy: f32| a * dx * dx + 2.0 * b * dx * dy + c * dy * dy;
        let on_x_edge = |dx: f32| q(dx, (-b * dx / c).clamp(ya, yb));
        let on_y_edge = |dy: f32| q((-b * dy / a).clamp(xa, xb), dy);
        let m = on_x_edge(xa).min(on_x_edge(xb)).min(on_y_edge(ya)).min(on_y_edge(yb));
        m <= self.reach() * (1.0 + EXTENT_REL)
    }

    /// Inclusive pixel columns `[lo, hi]` of row `i` whose centres the
    /// ellipse [`Self::reach`] covers, clipped to `[x0, x1)`.
    #[inline(always)]
    pub fn row_span(&self, i: i64, x0: u32, x1: u32) -> (i64, i64) {
        let [a, b, _] = self.conic;
        let dy = i as f32 + 0.5 - self.xy[1];
        let r = self.reach();
        let disc = a * r - self.det_conic * dy * dy;
        if disc < 0.0 {
            return (1, 0);
        }
        let half = disc.sqrt() * self.inv_a;
        let mid = self.xy[0] - b * dy * self.inv_a;
        let slack = EXTENT_ABS + EXTENT_REL * half;
        centre_span(mid - half - slack, mid + half + slack, x0, x1)
    }
}

/// Pixels `k` in `[lo, hi)` with centre `k + 0.5` in `[a, b]`.
#[inline(always)]
fn centre_span(a: f32, b: f32, lo: u32, hi: u32) -> (i64, i64) {
    // `as` saturates (and maps NaN to 0); a truncation fixed up by one is a
    // ceiling or floor without a libm call.
    let ceil = |x: f32| {
        let t = x as i64;
        if (t as f32) < x { t + 1 } else { t }
    };
    let floor = |x: f32| {
        let t = x as i64;
        if (t as f32) > x { t - 1 } else { t }
    };
    (ceil(a - 0.5).max(i64::from(lo)), floor(b - 0.5).min(i64::from(hi) - 1))
}

/// `exp(x)` for `x ≤ 0` (the Gaussian falloff), about 2e-7 relative error,
/// inlined: `x = n·ln2 + r` with `|r| ≤ ln2/2`, `eʳ` by its degree-6 Taylor
/// polynomial, `2ⁿ` built in the exponent bits. The libm call it replaces was
/// a sixth of the compositing time. Inputs are clamped to `[−87, 0]`.
#[inline(always)]
pub(crate) fn exp_neg(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Adding 1.5·2²³ rounds to an integer held in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 0.0);
    let t = x * std::f32::consts::LOG2_E + ROUND;
    let nf = t - ROUND;
    let r = (x - nf * LN2_HI) - nf * LN2_LO;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    // The low bits of `t` are n (two's complement); 2ⁿ has exponent bits n + 127.
    let two_n = f32::from_bits(t.to_bits().wrapping_sub(0x4b40_0000 - 127) << 23);
    p * two_n
}
