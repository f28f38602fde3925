//! The layers Depth Anything V2 is made of, on the project's gemm kernel.
//!
//! Token states are stored channel-major (`D × N`: one row per channel, one
//! column per token), the same layout as a CHW feature map, so a linear layer
//! is `W · X` with the checkpoint's `out × in` weights as they are, the patch
//! tokens become the reassemble stage's image without a transpose, and the
//! attention products need only the strides [`matmul`] takes.

use rayon::prelude::*;

use crate::vision::conv::{conv_affine, matmul};

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
pub(crate) fn gelu_in_place(x: &mut [f32]) {
    x.par_chunks_mut(1 << 14)
        .for_each(|c| c.iter_mut().for_each(|v| *v = 0.5 * *v * (1.0 + erf(*v * std::f32::consts::FRAC_1_SQRT_2))));
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
    p * f32::from_bits(((k + 127) << 23) as u32)
}

/// Multi-head self-attention on `q`, `k`, `v` (each `d × n`, channel-major,
/// heads in consecutive row blocks); `q` must already carry the `1/√d_head`
/// scale. Returns the heads' outputs concatenated, `d × n`.
pub(crate) fn attention(q: &[f32], k: &[f32], v: &[f32], d: usize, n: usize, heads: usize) -> Vec<f32> {
    let dh = d / heads;
    let mut out = vec![0f32; d * n];
    // Scores are kept transposed (keys × queries) so both products read
    // their operands at the strides the kernel takes.
    let mut s = vec![0f32; n * n];
    for h in 0..heads {
        let rows = h * dh * n..(h + 1) * dh * n;
        matmul(&mut s, n, (&k[rows.clone()], 1, n), (&q[rows.clone()], n), (n, n, dh), false);
        softmax_columns(&mut s, n);
        matmul(&mut out[rows.clone()], n, (&v[rows], n, 1), (&s, n), (dh, n, n), false);
    }
    out
}

/// Softmax down each column of an `n × n` array (over keys, for each query).
fn softmax_columns(s: &mut [f32], n: usize) {
    let combine = |f: fn(f32, f32) -> f32| {
        move |mut acc: Vec<f32>, row: &[f32]| {
            acc.iter_mut().zip(row).for_each(|(a, &v)| *a = f(*a, v));
            acc
        }
    };
    let merge = |f: fn(f32, f32) -> f32| {
        move |mut a: Vec<f32>, b: Vec<f32>| {
            a.iter_mut().zip(&b).for_each(|(x, &y)| *x = f(*x, y));
            a
        }
    };
    let max = s
        .par_chunks(n)
        .fold(|| vec![f32::NEG_INFINITY; n], combine(f32::max))
        .reduce(|| vec![f32::NEG_INFINITY; n], merge(f32::max));
    s.par_chunks_mut(n).for_each(|row| row.iter_mut().zip(&max).for_each(|(v, &m)| *v = exp(*v - m)));
    let add = |a: f32, b: f32| a + b;
    let sum = s.par_chunks(n).fold(|| vec![0f32; n], combine(add)).reduce(|| vec![0f32; n], merge(add));
    let inv: Vec<f32> = sum.iter().map(|&t| 1.0 / t).collect();
    s.par_chunks_mut(n).for_each(|row| row.iter_mut().zip(&inv).for_each(|(v, &r)| *v *= r));
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
}

impl Conv {
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
        if self.k == 3 && self.stride == 1 && self.pad == 1 {
            // The banded im2col kernel VGG runs on.
            conv_affine(x, (self.c_in, h, w), &self.w, &self.b, &mut y, &mut Vec::new());
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

    #[test]
    fn strided_conv_matches_a_direct_sum() {
        let (c_in, h, w) = (2, 5, 4);
        let x: Vec<f32> = (0..c_in * h * w).map(|i| ((i * 7) % 11) as f32 - 5.0).collect();
        let conv = Conv {
            w: (0..3 * c_in * 9).map(|i| ((i * 5) % 7) as f32 * 0.1 - 0.3).collect(),
            b: vec![0.5, -1.0, 0.25],
            c_in,
            k: 3,
            stride: 2,
            pad: 1,
        };
        let (oh, ow) = conv.out_size(h, w);
        assert_eq!((oh, ow), (3, 2));
        let y = conv.forward(&x, h, w);
        for (o, &bias) in conv.b.iter().enumerate() {
            for oy in 0..oh {
                for ox in 0..ow {
                    let mut s = bias;
                    for c in 0..c_in {
                        for ky in 0..3 {
                            for kx in 0..3 {
                                let (iy, ix) = ((oy * 2 + ky) as isize - 1, (ox * 2 + kx) as isize - 1);
                                if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < w {
                                    s += conv.w[((o * c_in + c) * 3 + ky) * 3 + kx]
                                        * x[(c * h + iy as usize) * w + ix as usize];
                                }
                            }
                        }
                    }
                    assert!((y[(o * oh + oy) * ow + ox] - s).abs() < 1e-4);
                }
            }
        }
    }
}
