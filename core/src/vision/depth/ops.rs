//! The layers Depth Anything V2 is made of, on the project's gemm kernel.
//!
//! Token states are stored channel-major (`D × N`: one row per channel, one
//! column per token), the same layout as a CHW feature map, so a linear layer
//! is `W · X` with the checkpoint's `out × in` weights as they are, the patch
//! tokens become the reassemble stage's image without a transpose, and the
//! attention products need only the strides [`matmul`] takes.

use rayon::prelude::*;

use crate::vision::conv::{matmul, matmul_serial};
use crate::vision::winograd::{WinogradKernel, winograd_conv};

/// A linear layer, or equally a 1×1 convolution: `y = W x + b` on `in × n` columns.
pub(crate) struct Linear {
    /// `out × in`, row-major.
    pub w: Vec<f32>,
    /// `out` values (zeros for a layer without bias).
    pub b: Vec<f32>,
    /// Input width.
    pub inp: usize,
}

impl Linear {
    /// Output width.
    pub(crate) fn out(&self) -> usize {
        self.b.len()
    }

    /// `W x + b` for `x` of `in × n`; returns `out × n`.
    pub(crate) fn forward(&self, x: &[f32], n: usize) -> Vec<f32> {
        let mut y = vec![0f32; self.out() * n];
        matmul(&mut y, n, (&self.w, self.inp, 1), (x, n), (self.out(), n, self.inp), false);
        add_bias(&mut y, &self.b, n);
        y
    }

    /// `y += W x + b` in place (`y` is `out × n`): a residual branch's last
    /// layer adding onto the stream without an intermediate array.
    pub(crate) fn accumulate(&self, x: &[f32], n: usize, y: &mut [f32]) {
        matmul(y, n, (&self.w, self.inp, 1), (x, n), (self.out(), n, self.inp), true);
        add_bias(y, &self.b, n);
    }

    /// `GELU(W x + b)`, the bias and the activation in one pass over the output.
    pub(crate) fn forward_gelu(&self, x: &[f32], n: usize) -> Vec<f32> {
        let mut y = vec![0f32; self.out() * n];
        matmul(&mut y, n, (&self.w, self.inp, 1), (x, n), (self.out(), n, self.inp), false);
        y.par_chunks_mut(n).zip(&self.b).for_each(|(row, &bc)| row.iter_mut().for_each(|v| *v = gelu(*v + bc)));
        y
    }

    /// The layer followed by a scale per output: `diag(s) (W x + b)`, folded into the weights.
    pub(crate) fn scaled_rows(mut self, s: &[f32]) -> Self {
        let inp = self.inp;
        self.w.chunks_exact_mut(inp).zip(s).for_each(|(row, &sc)| row.iter_mut().for_each(|v| *v *= sc));
        self.b.iter_mut().zip(s).for_each(|(b, &sc)| *b *= sc);
        self
    }

    /// Layers on the same input stacked into one (their outputs concatenated).
    pub(crate) fn stacked(layers: Vec<Linear>) -> Self {
        let inp = layers.first().map_or(0, |l| l.inp);
        let (mut w, mut b) = (Vec::new(), Vec::new());
        for l in layers {
            debug_assert_eq!(l.inp, inp, "Linear::stacked: input widths differ");
            w.extend(l.w);
            b.extend(l.b);
        }
        Self { w, b, inp }
    }
}

/// Adds `b[c]` to every value of row `c` of a `len(b) × n` array.
pub(crate) fn add_bias(y: &mut [f32], b: &[f32], n: usize) {
    y.par_chunks_mut(n).zip(b).for_each(|(row, &bc)| row.iter_mut().for_each(|v| *v += bc));
}

/// Layer normalisation over the channels of each column of a `d × n` array.
pub(crate) struct Norm {
    /// Scale, `d` values.
    pub w: Vec<f32>,
    /// Shift, `d` values.
    pub b: Vec<f32>,
    /// Added to the variance.
    pub eps: f32,
}

impl Norm {
    /// The normalised copy of `x` (`d × n`).
    pub(crate) fn forward(&self, x: &[f32], n: usize) -> Vec<f32> {
        let d = self.w.len();
        let mut mean = vec![0f32; n];
        for row in x.chunks_exact(n) {
            mean.iter_mut().zip(row).for_each(|(m, &v)| *m += v);
        }
        mean.iter_mut().for_each(|m| *m /= d as f32);
        let mut var = vec![0f32; n];
        for row in x.chunks_exact(n) {
            var.iter_mut().zip(row).zip(&mean).for_each(|((s, &v), &m)| *s += (v - m) * (v - m));
        }
        let inv: Vec<f32> = var.iter().map(|s| 1.0 / (s / d as f32 + self.eps).sqrt()).collect();
        let mut y = vec![0f32; d * n];
        y.par_chunks_mut(n).zip(x.par_chunks(n)).enumerate().for_each(|(c, (out, row))| {
            let (g, b) = (self.w[c], self.b[c]);
            for (((o, &v), &m), &s) in out.iter_mut().zip(row).zip(&mean).zip(&inv) {
                *o = (v - m) * s * g + b;
            }
        });
        y
    }
}

/// GELU with the exact error function, as `nn.GELU()` computes it.
#[inline]
fn gelu(v: f32) -> f32 {
    0.5 * v * (1.0 + erf(v * std::f32::consts::FRAC_1_SQRT_2))
}

/// The error function (Abramowitz & Stegun 7.1.26, absolute error below 1.5e-7).
fn erf(x: f32) -> f32 {
    let a = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * a);
    let poly = t * (0.254_829_6 + t * (-0.284_496_74 + t * (1.421_413_8 + t * (-1.453_152_1 + t * 1.061_405_4))));
    let y = 1.0 - poly * exp(-a * a);
    y.copysign(x)
}

/// `eˣ` without branches or library calls, so loops over it vectorise (the
/// softmax and GELU evaluate it ~160 M times per 518² pass): `x = n·ln2 + r`
/// with `n` rounded by the 1.5·2²³ trick, a degree-6 Taylor polynomial for
/// `eʳ` (|r| ≤ ln2/2, relative error ~2e-7), and `2ⁿ` put in the exponent bits.
/// Inputs are clamped to [−87, 88]; below that the result is ~1e-38, not 0.
#[inline]
fn exp(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 · 2²³
    let x = x.clamp(-87.0, 88.0);
    let m = x * std::f32::consts::LOG2_E + MAGIC;
    let n = m - MAGIC;
    let r = (x - n * 0.693_145_75) - n * 1.428_606_8e-6;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    let k = (m.to_bits() as i32).wrapping_sub(0x4B40_0000);
    p * f32::from_bits((k.wrapping_add(127) << 23) as u32)
}

/// Queries per attention block: the block's scores (`n × QUERY_BLOCK`)
/// stay in the L2 cache between the two products and the softmax (at the
/// wave image's 2,887 tokens, 740 KB), where a whole head's `n × n` scores
/// (33 MB) would go through memory three times.
const QUERY_BLOCK: usize = 64;

/// Multi-head self-attention on `q`, `k`, `v` (each `d × n`, channel-major,
/// heads in consecutive row blocks); `q` must already carry the `1/√d_head`
/// scale. Returns the heads' outputs concatenated, `d × n`.
///
/// Each (head, block of queries) is one rayon task on single-threaded
/// products: scores `Kᵀ q` (keys × queries), the softmax's max and
/// exponentials down each column, `V · e`, and the division by the column
/// sums applied to the `d_head × block` output rather than to the scores.
pub(crate) fn attention(q: &[f32], k: &[f32], v: &[f32], d: usize, n: usize, heads: usize) -> Vec<f32> {
    let dh = d / heads;
    let blocks = n.div_ceil(QUERY_BLOCK);
    let parts: Vec<Vec<f32>> = (0..heads * blocks)
        .into_par_iter()
        .map_init(
            || vec![0f32; n * QUERY_BLOCK],
            |s, t| {
                let (h, q0) = (t / blocks, (t % blocks) * QUERY_BLOCK);
                let bq = QUERY_BLOCK.min(n - q0);
                let head = h * dh * n..(h + 1) * dh * n;
                let s = &mut s[..n * bq];
                matmul_serial(s, bq, (&k[head.clone()], 1, n), (&q[head.start + q0..], n), (n, bq, dh), false);
                let inv = exp_columns(s, bq);
                let mut o = vec![0f32; dh * bq];
                matmul_serial(&mut o, bq, (&v[head], n, 1), (s, bq), (dh, bq, n), false);
                o.chunks_exact_mut(bq).for_each(|row| row.iter_mut().zip(&inv).for_each(|(x, &r)| *x *= r));
                o
            },
        )
        .collect();
    let mut out = vec![0f32; d * n];
    for (t, o) in parts.iter().enumerate() {
        let (h, q0) = (t / blocks, (t % blocks) * QUERY_BLOCK);
        let bq = QUERY_BLOCK.min(n - q0);
        for (c, row) in o.chunks_exact(bq).enumerate() {
            out[(h * dh + c) * n + q0..][..bq].copy_from_slice(row);
        }
    }
    out
}

/// The unnormalised softmax down each column of a `rows × w` array: every
/// value becomes `exp(v − max of its column)`. Returns `1 / Σ` per column.
fn exp_columns(s: &mut [f32], w: usize) -> Vec<f32> {
    let mut max = vec![f32::NEG_INFINITY; w];
    for row in s.chunks_exact(w) {
        max.iter_mut().zip(row).for_each(|(m, &v)| *m = m.max(v));
    }
    let mut sum = vec![0f32; w];
    for row in s.chunks_exact_mut(w) {
        for ((v, &m), t) in row.iter_mut().zip(&max).zip(sum.iter_mut()) {
            *v = exp(*v - m);
            *t += *v;
        }
    }
    sum.iter().map(|&t| 1.0 / t).collect()
}

/// A 2-D convolution with square kernel `k`, stride and zero padding.
pub(crate) struct Conv {
    /// OIHW weights, `c_out × c_in·k·k`.
    pub w: Vec<f32>,
    /// `c_out` values (zeros for a convolution without bias).
    pub b: Vec<f32>,
    /// Input channels.
    pub c_in: usize,
    /// Kernel side.
    pub k: usize,
    /// Stride.
    pub stride: usize,
    /// Zero padding on every side.
    pub pad: usize,
    /// The kernel in the Winograd domain, for the 3×3 "same" convolutions.
    wino: Option<WinogradKernel>,
}

impl Conv {
    /// A convolution from OIHW weights (`c_out × c_in·k·k`) and `c_out` biases.
    pub(crate) fn new(w: Vec<f32>, b: Vec<f32>, c_in: usize, k: usize, stride: usize, pad: usize) -> Self {
        let wino = (k == 3 && stride == 1 && pad == 1).then(|| WinogradKernel::forward(&w, b.len(), c_in));
        Self { w, b, c_in, k, stride, pad, wino }
    }

    /// Output channels.
    pub(crate) fn c_out(&self) -> usize {
        self.b.len()
    }

    /// Output size for an `h × w` input.
    pub(crate) fn out_size(&self, h: usize, w: usize) -> (usize, usize) {
        ((h + 2 * self.pad - self.k) / self.stride + 1, (w + 2 * self.pad - self.k) / self.stride + 1)
    }

    /// Convolves `x` (`c_in × h × w`); returns `c_out × oh × ow`.
    pub(crate) fn forward(&self, x: &[f32], h: usize, w: usize) -> Vec<f32> {
        let (oh, ow) = self.out_size(h, w);
        let mut y = vec![0f32; self.c_out() * oh * ow];
        if let Some(kernel) = &self.wino {
            // Winograd F(4×4, 3×3), as VGG runs: a quarter of im2col's multiplies.
            winograd_conv(x, (self.c_in, h, w), kernel, &mut y, &mut Vec::new());
            add_bias(&mut y, &self.b, oh * ow);
            return y;
        }
        let rows = self.c_in * self.k * self.k;
        let mut cols = vec![0f32; rows * oh * ow];
        cols.par_chunks_mut(oh * ow).enumerate().for_each(|(r, out)| {
            let (c, ky, kx) = (r / (self.k * self.k), (r / self.k) % self.k, r % self.k);
            for oy in 0..oh {
                let iy = (oy * self.stride + ky) as isize - self.pad as isize;
                for ox in 0..ow {
                    let ix = (ox * self.stride + kx) as isize - self.pad as isize;
                    let inside = iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < w;
                    out[oy * ow + ox] = if inside { x[(c * h + iy as usize) * w + ix as usize] } else { 0.0 };
                }
            }
        });
        matmul(&mut y, oh * ow, (&self.w, rows, 1), (&cols, oh * ow), (self.c_out(), oh * ow, rows), false);
        add_bias(&mut y, &self.b, oh * ow);
        y
    }
}

/// A transposed convolution whose kernel equals its stride (`f`), so every
/// input pixel paints its own `f × f` block: `ConvTranspose2d(c, c, f, stride=f)`.
pub(crate) struct ConvUp {
    /// Weights as PyTorch stores them, `c_in × c_out × f × f`.
    pub w: Vec<f32>,
    /// `c_out` values.
    pub b: Vec<f32>,
    /// Input channels.
    pub c_in: usize,
    /// Kernel side and stride.
    pub f: usize,
}

impl ConvUp {
    /// Upsamples `x` (`c_in × h × w`) to `c_out × h·f × w·f`.
    pub(crate) fn forward(&self, x: &[f32], h: usize, w: usize) -> Vec<f32> {
        let (c_out, f, hw) = (self.b.len(), self.f, h * w);
        let m = c_out * f * f;
        let mut t = vec![0f32; m * hw];
        matmul(&mut t, hw, (&self.w, 1, m), (x, hw), (m, hw, self.c_in), false);
        let (oh, ow) = (h * f, w * f);
        let mut y = vec![0f32; c_out * oh * ow];
        y.par_chunks_mut(oh * ow).enumerate().for_each(|(o, plane)| {
            for ky in 0..f {
                for kx in 0..f {
                    let src = &t[((o * f + ky) * f + kx) * hw..][..hw];
                    for yy in 0..h {
                        for xx in 0..w {
                            plane[(yy * f + ky) * ow + xx * f + kx] = src[yy * w + xx] + self.b[o];
                        }
                    }
                }
            }
        });
        y
    }
}

/// An HWC resizer: `(src, h, w, c, oh, ow) → dst`, as in [`crate::vision::resize`].
pub(crate) type Resizer = fn(&[f32], usize, usize, usize, usize, usize) -> Vec<f32>;

/// Each channel of a `c × h × w` array resampled to `oh × ow` by `resize`
/// (an HWC resizer called with one channel).
pub(crate) fn resize_planes(
    x: &[f32],
    (c, h, w): (usize, usize, usize),
    (oh, ow): (usize, usize),
    resize: Resizer,
) -> Vec<f32> {
    let mut y = vec![0f32; c * oh * ow];
    y.par_chunks_mut(oh * ow).zip(x.par_chunks(h * w)).for_each(|(out, plane)| {
        out.copy_from_slice(&resize(plane, h, w, 1, oh, ow));
    });
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_exp_matches_std() {
        let mut worst = 0f32;
        for i in -8000..=8000 {
            let x = i as f32 * 0.01;
            worst = worst.max((exp(x) - x.exp()).abs() / x.exp());
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
        assert!(exp(-200.0) < 1e-37 && exp(-200.0) >= 0.0);
    }

    #[test]
    fn erf_matches_known_values() {
        for (x, e) in
            [(0.0f32, 0.0f32), (0.5, 0.520_499_9), (1.0, 0.842_700_8), (-2.0, -0.995_322_3), (3.0, 0.999_977_9)]
        {
            assert!((erf(x) - e).abs() < 3e-7, "erf({x}) = {} (expected {e})", erf(x));
        }
    }

    /// `conv`'s output at `(o, oy, ox)` as the plain sum over its window.
    fn direct(conv: &Conv, x: &[f32], h: usize, w: usize, (o, oy, ox): (usize, usize, usize)) -> f32 {
        let (k, c_in) = (conv.k, conv.c_in);
        let mut s = conv.b[o];
        for c in 0..c_in {
            for ky in 0..k {
                for kx in 0..k {
                    let iy = (oy * conv.stride + ky) as isize - conv.pad as isize;
                    let ix = (ox * conv.stride + kx) as isize - conv.pad as isize;
                    if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < w {
                        s += conv.w[((o * c_in + c) * k + ky) * k + kx] * x[(c * h + iy as usize) * w + ix as usize];
                    }
                }
            }
        }
        s
    }

    #[test]
    fn convolutions_match_a_direct_sum() {
        // Stride 2 (im2col), and stride 1 (Winograd) at a size that is not a
        // multiple of its 4×4 tiles.
        for (stride, h, w, expect) in [(2, 5, 4, (3, 2)), (1, 9, 7, (9, 7))] {
            let c_in = 2;
            let x: Vec<f32> = (0..c_in * h * w).map(|i| ((i * 7) % 11) as f32 - 5.0).collect();
            let conv = Conv::new(
                (0..3 * c_in * 9).map(|i| ((i * 5) % 7) as f32 * 0.1 - 0.3).collect(),
                vec![0.5, -1.0, 0.25],
                c_in,
                3,
                stride,
                1,
            );
            let (oh, ow) = conv.out_size(h, w);
            assert_eq!((oh, ow), expect);
            let y = conv.forward(&x, h, w);
            for o in 0..3 {
                for oy in 0..oh {
                    for ox in 0..ow {
                        let s = direct(&conv, &x, h, w, (o, oy, ox));
                        let got = y[(o * oh + oy) * ow + ox];
                        assert!((got - s).abs() < 1e-4, "stride {stride}: ({o}, {oy}, {ox}) {got} against {s}");
                    }
                }
            }
        }
    }

    #[test]
    fn blocked_attention_matches_the_textbook_one() {
        // Three query blocks, the last one partial; two heads.
        let (d, n, heads) = (8, 2 * QUERY_BLOCK + 19, 2);
        let val = |i: usize, m: usize| ((i * m) % 23) as f32 / 23.0 - 0.5;
        let q: Vec<f32> = (0..d * n).map(|i| val(i, 7)).collect();
        let k: Vec<f32> = (0..d * n).map(|i| val(i, 11)).collect();
        let v: Vec<f32> = (0..d * n).map(|i| val(i, 13)).collect();
        let out = attention(&q, &k, &v, d, n, heads);
        let dh = d / heads;
        let mut worst = 0f32;
        for h in 0..heads {
            for i in 0..n {
                let at = |a: &[f32], c: usize, t: usize| a[(h * dh + c) * n + t];
                let scores: Vec<f64> =
                    (0..n).map(|j| (0..dh).map(|c| f64::from(at(&q, c, i) * at(&k, c, j))).sum()).collect();
                let m = scores.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let e: Vec<f64> = scores.iter().map(|s| (s - m).exp()).collect();
                let z: f64 = e.iter().sum();
                for c in 0..dh {
                    let want: f64 = (0..n).map(|j| e[j] / z * f64::from(at(&v, c, j))).sum();
                    worst = worst.max((out[(h * dh + c) * n + i] - want as f32).abs());
                }
            }
        }
        assert!(worst < 1e-5, "worst difference {worst}");
    }

    #[test]
    fn folded_layers_equal_the_plain_ones() {
        let lin = |seed: usize| Linear {
            w: (0..12).map(|i| ((i * seed) % 7) as f32 - 3.0).collect(),
            b: vec![0.5, -1.0, 2.0],
            inp: 4,
        };
        let n = 5;
        let x: Vec<f32> = (0..4 * n).map(|i| (i % 5) as f32 * 0.3 - 0.6).collect();
        let (plain_a, plain_b) = (lin(3).forward(&x, n), lin(5).forward(&x, n));
        let s = [2.0, 0.5, -1.0];
        let stacked = Linear::stacked(vec![lin(3).scaled_rows(&s), lin(5)]).forward(&x, n);
        for (i, (&a, &b)) in plain_a.iter().zip(&plain_b).enumerate() {
            assert!((stacked[i] - a * s[i / n]).abs() < 1e-5 && (stacked[3 * n + i] - b).abs() < 1e-5);
        }
        let mut y = vec![1f32; 3 * n];
        lin(3).accumulate(&x, n, &mut y);
        let g = lin(3).forward_gelu(&x, n);
        for (i, &a) in plain_a.iter().enumerate() {
            assert!((y[i] - (1.0 + a)).abs() < 1e-5 && (g[i] - gelu(a)).abs() < 1e-6);
        }
    }
}
