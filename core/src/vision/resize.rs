//! Image resizing with the conventions of the reference's libraries.
//!
//! - Shrinking the style image to height `S` uses OpenCV's `INTER_AREA`
//!   (area-weighted averages; [`resize_area`], [`resize_area_u8`]).
//! - Enlargement and resizing of depth maps use bilinear interpolation with
//!   half-pixel centres, PyTorch `F.interpolate(mode='bilinear',
//!   align_corners=False)` (same as OpenCV `INTER_LINEAR` in floating point).
//! - Rendered maps are downscaled by 0.5 before VGG with
//!   `F.interpolate(scale_factor=0.5, mode='bilinear')`; with the scale factor
//!   given, PyTorch samples at `2·i + 0.5`, i.e. the 2×2 average (odd sizes
//!   drop the last row/column). The loss needs its adjoint,
//!   [`downscale_half_backward`].
//!
//! All images are HWC `f32` (or `u8`) with `c` interleaved channels.

use rayon::prelude::*;

/// Output size of the style image for texture scale `s`: height `s`, width
/// `floor(w · s / h)` (the reference's `int(w * (s / h))`).
pub fn size_for_height(h: usize, w: usize, s: usize) -> (usize, usize) {
    let ratio = s as f64 / h as f64;
    (s, ((w as f64 * ratio) as usize).max(1))
}

/// OpenCV's area-interpolation table along one axis: for each output index the
/// list of `(source index, weight)`, weights summing to one.
fn area_table(src: usize, dst: usize) -> Vec<Vec<(usize, f64)>> {
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|d| {
            let fsx1 = d as f64 * scale;
            let fsx2 = fsx1 + scale;
            let mut sx1 = fsx1.ceil() as usize;
            let sx2 = (fsx2.floor() as usize).min(src - 1);
            sx1 = sx1.min(sx2);
            let cell = scale.min(src as f64 - fsx1);
            let mut taps = Vec::new();
            if sx1 as f64 - fsx1 > 1e-3 {
                taps.push((sx1 - 1, (sx1 as f64 - fsx1) / cell));
            }
            for s in sx1..sx2 {
                taps.push((s, 1.0 / cell));
            }
            if fsx2 - sx2 as f64 > 1e-3 {
                taps.push((sx2, (fsx2 - sx2 as f64).min(1.0).min(cell) / cell));
            }
            taps
        })
        .collect()
}

/// Area resize (OpenCV `INTER_AREA`) of an `f32` image to `oh × ow`. Meant for
/// shrinking; when either side grows it falls back to [`resize_bilinear`]
/// (OpenCV's area mode is then close to, not exactly, bilinear).
pub fn resize_area(src: &[f32], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<f32> {
    assert_eq!(src.len(), h * w * c, "resize_area: image size mismatch");
    if oh > h || ow > w {
        return resize_bilinear(src, h, w, c, oh, ow);
    }
    shrink_area(src, h, w, c, oh, ow)
}

/// [`resize_area`]'s shrinking, from `f32` or 8-bit values alike: an 8-bit
/// image is read as it is, not copied to `f32` first (a 12,000 × 12,000
/// style took 1.6 GiB for that copy).
fn shrink_area<T: Copy + Into<f64>>(src: &[T], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<f32> {
    let ty = area_table(h, oh);
    let tx = area_table(w, ow);
    // Horizontal pass (h × ow), then vertical, accumulated in f64.
    let mut tmp = vec![0f64; h * ow * c];
    for i in 0..h {
        for (j, taps) in tx.iter().enumerate() {
            for &(s, wt) in taps {
                for k in 0..c {
                    tmp[(i * ow + j) * c + k] += wt * src[(i * w + s) * c + k].into();
                }
            }
        }
    }
    let mut out = vec![0f32; oh * ow * c];
    for (i, taps) in ty.iter().enumerate() {
        for j in 0..ow {
            for k in 0..c {
                let v: f64 = taps.iter().map(|&(s, wt)| wt * tmp[(s * ow + j) * c + k]).sum();
                out[(i * ow + j) * c + k] = v as f32;
            }
        }
    }
    out
}

/// Area resize of an 8-bit image as `cv2.resize(.., INTER_AREA)`: integer
/// factors average blocks with round-half-up (OpenCV's fast path), other
/// factors use the area weights and round half to even.
pub fn resize_area_u8(src: &[u8], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<u8> {
    assert_eq!(src.len(), h * w * c, "resize_area_u8: image size mismatch");
    let integer = oh > 0 && ow > 0 && h.is_multiple_of(oh) && w.is_multiple_of(ow) && oh <= h && ow <= w;
    if integer {
        let (fy, fx) = (h / oh, w / ow);
        let area = (fy * fx) as u32;
        let mut out = vec![0u8; oh * ow * c];
        for i in 0..oh {
            for j in 0..ow {
                for k in 0..c {
                    let mut s = 0u32;
                    for a in 0..fy {
                        for b in 0..fx {
                            s += u32::from(src[((i * fy + a) * w + j * fx + b) * c + k]);
                        }
                    }
                    out[(i * ow + j) * c + k] = ((s + area / 2) / area) as u8;
                }
            }
        }
        return out;
    }
    let out = if oh > h || ow > w {
        let f: Vec<f32> = src.iter().map(|&v| f32::from(v)).collect();
        resize_bilinear(&f, h, w, c, oh, ow)
    } else {
        shrink_area(src, h, w, c, oh, ow)
    };
    out.into_iter().map(|v| v.round_ties_even().clamp(0.0, 255.0) as u8).collect()
}

/// Source taps of PyTorch's bilinear (`align_corners=False`) along one axis,
/// with `scale` source pixels per output pixel: `(i0, i1, w0, w1)`.
pub(crate) fn bilinear_taps(src: usize, dst: usize, scale: f64) -> Vec<(usize, usize, f32, f32)> {
    (0..dst)
        .map(|d| {
            let x = ((d as f64 + 0.5) * scale - 0.5).max(0.0);
            let i0 = (x.floor() as usize).min(src - 1);
            let i1 = if i0 < src - 1 { i0 + 1 } else { i0 };
            let l1 = (x - i0 as f64).clamp(0.0, 1.0) as f32;
            (i0, i1, 1.0 - l1, l1)
        })
        .collect()
}

/// Bilinear resize to `oh × ow` as `F.interpolate(size=(oh, ow),
/// mode='bilinear', align_corners=False)` (no antialiasing).
pub fn resize_bilinear(src: &[f32], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<f32> {
    resize_bilinear_scaled(src, h, w, c, oh, ow, h as f64 / oh as f64, w as f64 / ow as f64)
}

/// Bilinear resize with explicit source-pixels-per-output-pixel scales (what
/// PyTorch uses when `scale_factor` is given: `1 / scale_factor`).
#[allow(clippy::too_many_arguments)]
pub fn resize_bilinear_scaled(
    src: &[f32],
    h: usize,
    w: usize,
    c: usize,
    oh: usize,
    ow: usize,
    scale_h: f64,
    scale_w: f64,
) -> Vec<f32> {
    assert_eq!(src.len(), h * w * c, "resize_bilinear: image size mismatch");
    let ty = bilinear_taps(h, oh, scale_h);
    let tx = bilinear_taps(w, ow, scale_w);
    let mut out = vec![0f32; oh * ow * c];
    for (i, &(y0, y1, wy0, wy1)) in ty.iter().enumerate() {
        for (j, &(x0, x1, wx0, wx1)) in tx.iter().enumerate() {
            for k in 0..c {
                let p = |y: usize, x: usize| src[(y * w + x) * c + k];
                out[(i * ow + j) * c + k] =
                    wy0 * (wx0 * p(y0, x0) + wx1 * p(y0, x1)) + wy1 * (wx0 * p(y1, x0) + wx1 * p(y1, x1));
            }
        }
    }
    out
}

/// Adjoint of [`resize_bilinear_scaled`]: scatters `v_out` (`oh × ow × c`) back
/// to the `h × w × c` input.
#[allow(clippy::too_many_arguments)]
pub fn resize_bilinear_scaled_backward(
    v_out: &[f32],
    h: usize,
    w: usize,
    c: usize,
    oh: usize,
    ow: usize,
    scale_h: f64,
    scale_w: f64,
) -> Vec<f32> {
    assert_eq!(v_out.len(), oh * ow * c, "resize_bilinear_backward: size mismatch");
    let ty = bilinear_taps(h, oh, scale_h);
    let tx = bilinear_taps(w, ow, scale_w);
    let mut v = vec![0f32; h * w * c];
    for (i, &(y0, y1, wy0, wy1)) in ty.iter().enumerate() {
        for (j, &(x0, x1, wx0, wx1)) in tx.iter().enumerate() {
            for k in 0..c {
                let g = v_out[(i * ow + j) * c + k];
                v[(y0 * w + x0) * c + k] += wy0 * wx0 * g;
                v[(y0 * w + x1) * c + k] += wy0 * wx1 * g;
                v[(y1 * w + x0) * c + k] += wy1 * wx0 * g;
                v[(y1 * w + x1) * c + k] += wy1 * wx1 * g;
            }
        }
    }
    v
}

/// The 0.5× bilinear downscale of `F.interpolate(scale_factor=0.5,
/// mode='bilinear', align_corners=False)`. Returns the image and its size
/// `(floor(h/2), floor(w/2))`.
pub fn downscale_half(src: &[f32], h: usize, w: usize, c: usize) -> (Vec<f32>, usize, usize) {
    let (oh, ow) = (h / 2, w / 2);
    (resize_bilinear_scaled(src, h, w, c, oh, ow, 2.0, 2.0), oh, ow)
}

/// Adjoint of [`downscale_half`]: `v_out` is `floor(h/2) × floor(w/2) × c`.
pub fn downscale_half_backward(v_out: &[f32], h: usize, w: usize, c: usize) -> Vec<f32> {
    resize_bilinear_scaled_backward(v_out, h, w, c, h / 2, w / 2, 2.0, 2.0)
}

/// Source taps of one output sample along one axis: `(source index, weight)`.
pub(crate) type Taps = Vec<Vec<(usize, f32)>>;

/// A channel value an image holds, read as `f32` in [0, 1]: an `f32` as it
/// is, an 8-bit value over 255 (as `StyleImage::to_f32` divides), so an
/// 8-bit style is read in place rather than copied to `f32` first (a
/// 12,000 × 12,000 style took 1.6 GiB for that copy).
pub trait Unit: Copy + Send + Sync {
    /// The value in [0, 1].
    fn unit(self) -> f32;
}

impl Unit for f32 {
    fn unit(self) -> f32 {
        self
    }
}

impl Unit for u8 {
    fn unit(self) -> f32 {
        f32::from(self) / 255.0
    }
}

/// Applies per-axis taps to an HWC image: columns first, then rows, each
/// pass parallel over output rows (a style photo brought to the depth
/// network's size is millions of pixels with a dozen taps each).
fn resample_separable<T: Unit>(src: &[T], (h, w, c): (usize, usize, usize), ty: &Taps, tx: &Taps) -> Vec<f32> {
    assert_eq!(src.len(), h * w * c, "resample: image size mismatch");
    let ow = tx.len();
    if h == 0 || w == 0 || ow == 0 || c == 0 {
        return vec![0f32; ty.len() * ow * c];
    }
    let mut mid = vec![0f32; h * ow * c];
    mid.par_chunks_mut(ow * c).zip(src.par_chunks(w * c)).for_each(|(mid_row, src_row)| {
        for (out, taps) in mid_row.chunks_exact_mut(c).zip(tx) {
            for &(x, wt) in taps {
                out.iter_mut().zip(&src_row[x * c..(x + 1) * c]).for_each(|(o, &v)| *o += wt * v.unit());
            }
        }
    });
    let mut out = vec![0f32; ty.len() * ow * c];
    out.par_chunks_mut(ow * c).zip(ty).for_each(|(row, taps)| {
        for &(y, wt) in taps {
            row.iter_mut().zip(&mid[y * ow * c..(y + 1) * ow * c]).for_each(|(o, &m)| *o += wt * m);
        }
    });
    out
}

/// PyTorch's cubic convolution taps (`A = −0.75`, half-pixel centres, no
/// antialiasing, borders clamped) with `scale` source pixels per output pixel.
fn torch_cubic_taps(src: usize, dst: usize) -> Taps {
    const A: f64 = -0.75;
    let near = |x: f64| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let far = |x: f64| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|d| {
            let real = scale * (d as f64 + 0.5) - 0.5;
            let i = real.floor();
            let t = real - i;
            let wts = [far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)];
            (0..4).map(|k| ((i as isize + k as isize - 1).clamp(0, src as isize - 1) as usize, wts[k] as f32)).collect()
        })
        .collect()
}

/// Bicubic resize as `F.interpolate(size=(oh, ow), mode='bicubic',
/// align_corners=False)`: DINOv2's position-embedding interpolation and the
/// `transformers` depth post-processing.
pub fn resize_bicubic(src: &[f32], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<f32> {
    resample_separable(src, (h, w, c), &torch_cubic_taps(h, oh), &torch_cubic_taps(w, ow))
}

/// Pillow's bicubic taps (`a = −0.5`), widened by the scale when shrinking
/// (antialiasing) and normalised to sum to one.
fn pil_cubic_taps(src: usize, dst: usize) -> Taps {
    let cubic = |x: f64| {
        let (a, x) = (-0.5, x.abs());
        if x < 1.0 {
            ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0
        } else if x < 2.0 {
            (((x - 5.0) * x + 8.0) * x - 4.0) * a
        } else {
            0.0
        }
    };
    let scale = src as f64 / dst as f64;
    let fscale = scale.max(1.0);
    let support = 2.0 * fscale;
    (0..dst)
        .map(|d| {
            let center = (d as f64 + 0.5) * scale;
            let lo = ((center - support + 0.5).floor().max(0.0)) as usize;
            let hi = ((center + support + 0.5).floor() as usize).min(src);
            let raw: Vec<(usize, f64)> = (lo..hi).map(|x| (x, cubic((x as f64 - center + 0.5) / fscale))).collect();
            let sum: f64 = raw.iter().map(|t| t.1).sum();
            let sum = if sum == 0.0 { 1.0 } else { sum };
            raw.into_iter().map(|(x, v)| (x, (v / sum) as f32)).collect()
        })
        .collect()
}

/// Bicubic resize with antialiasing as Pillow's `Image.resize(BICUBIC)` (and
/// torchvision's `antialias=True`) computes it, in floating point: what the
/// `transformers` image processors use to bring an image to the network's size.
pub fn resize_bicubic_antialias<T: Unit>(src: &[T], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<f32> {
    resample_separable(src, (h, w, c), &pil_cubic_taps(h, oh), &pil_cubic_taps(w, ow))
}

/// Bilinear taps with the corners aligned: output `d` samples source `d·(src−1)/(dst−1)`.
pub(crate) fn aligned_linear_taps(src: usize, dst: usize) -> Taps {
    let scale = if dst > 1 { (src as f64 - 1.0) / (dst as f64 - 1.0) } else { 0.0 };
    (0..dst)
        .map(|d| {
            let x = d as f64 * scale;
            let i0 = (x.floor() as usize).min(src - 1);
            let i1 = (i0 + 1).min(src - 1);
            let l = (x - i0 as f64) as f32;
            vec![(i0, 1.0 - l), (i1, l)]
        })
        .collect()
}

/// Bilinear resize as `F.interpolate(size=(oh, ow), mode='bilinear',
/// align_corners=True)` (the DPT fusion and head upsampling).
pub fn resize_bilinear_align_corners(src: &[f32], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Vec<f32> {
    resample_separable(src, (h, w, c), &aligned_linear_taps(h, oh), &aligned_linear_taps(w, ow))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(h: usize, w: usize, c: usize) -> Vec<f32> {
        (0..h * w * c).map(|i| ((i * 37) % 101) as f32 / 100.0).collect()
    }

    #[test]
    fn an_8bit_shrink_reads_the_bytes_as_its_f32_copy_did() {
        let (h, w) = (37, 53);
        let img: Vec<u8> = (0..h * w * 3).map(|i| (i * 31 % 256) as u8).collect();
        let f: Vec<f32> = img.iter().map(|&v| f32::from(v)).collect();
        for (oh, ow) in [(16, 22), (5, 7), (37, 53)] {
            let want: Vec<u8> = (resize_area(&f, h, w, 3, oh, ow).into_iter())
                .map(|v| v.round_ties_even().clamp(0.0, 255.0) as u8)
                .collect();
            assert_eq!(resize_area_u8(&img, h, w, 3, oh, ow), want, "{oh}x{ow}");
        }
    }

    #[test]
    fn half_downscale_is_two_by_two_average() {
        let (h, w, c) = (6, 8, 3);
        let img = ramp(h, w, c);
        let (out, oh, ow) = downscale_half(&img, h, w, c);
        assert_eq!((oh, ow), (3, 4));
        for i in 0..oh {
            for j in 0..ow {
                for k in 0..c {
                    let p = |y: usize, x: usize| img[(y * w + x) * c + k];
                    let avg =
                        (p(2 * i, 2 * j) + p(2 * i + 1, 2 * j) + p(2 * i, 2 * j + 1) + p(2 * i + 1, 2 * j + 1)) / 4.0;
                    assert!((out[(i * ow + j) * c + k] - avg).abs() < 1e-6);
                }
            }
        }
    }

    #[test]
    fn backward_is_the_adjoint() {
        for &(h, w, oh, ow) in &[(7usize, 9usize, 3usize, 4usize), (5, 6, 11, 13), (8, 8, 4, 4)] {
            let c = 2;
            let x = ramp(h, w, c);
            let y: Vec<f32> = (0..oh * ow * c).map(|i| ((i * 13) % 17) as f32 / 7.0 - 1.0).collect();
            let (sh, sw) = (h as f64 / oh as f64, w as f64 / ow as f64);
            let ax = resize_bilinear_scaled(&x, h, w, c, oh, ow, sh, sw);
            let aty = resize_bilinear_scaled_backward(&y, h, w, c, oh, ow, sh, sw);
            let lhs: f64 = ax.iter().zip(&y).map(|(a, b)| f64::from(a * b)).sum();
            let rhs: f64 = x.iter().zip(&aty).map(|(a, b)| f64::from(a * b)).sum();
            assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
        }
    }

    #[test]
    fn area_resize_integer_and_fractional() {
        // Integer factor: block means.
        let img: Vec<f32> = (0..16).map(|v| v as f32).collect();
        let out = resize_area(&img, 4, 4, 1, 2, 2);
        assert_eq!(out, vec![2.5, 4.5, 10.5, 12.5]);
        // 3 -> 2: weights 2/3, 1/3 and 1/3, 2/3.
        let row = vec![0.0, 3.0, 6.0];
        let out = resize_area(&row, 1, 3, 1, 1, 2);
        assert!((out[0] - 1.0).abs() < 1e-6 && (out[1] - 5.0).abs() < 1e-6, "{out:?}");
        // Constant images stay constant.
        let cst = vec![0.7f32; 7 * 11 * 3];
        assert!(resize_area(&cst, 7, 11, 3, 3, 5).iter().all(|v| (v - 0.7).abs() < 1e-6));
        let u = resize_area_u8(&[10, 20, 30, 41], 2, 2, 1, 1, 1);
        assert_eq!(u, vec![25]);
    }

    #[test]
    fn style_size_follows_the_reference() {
        assert_eq!(size_for_height(1000, 1500, 256), (256, 384));
        assert_eq!(size_for_height(300, 401, 256), (256, 342));
    }

    #[test]
    fn cubic_resizers_keep_constants_and_identity() {
        let cst = vec![0.3f32; 9 * 7 * 2];
        for f in [resize_bicubic, resize_bicubic_antialias, resize_bilinear_align_corners] {
            assert!(f(&cst, 9, 7, 2, 4, 13).iter().all(|v| (v - 0.3).abs() < 1e-5));
            let img = ramp(6, 5, 3);
            let same = f(&img, 6, 5, 3, 6, 5);
            assert!(img.iter().zip(&same).all(|(a, b)| (a - b).abs() < 1e-6));
        }
    }

    #[test]
    fn antialias_reads_8_bit_values_as_their_f32_copy() {
        // The depth network's resize reads a style's bytes in place: the same
        // bits as the resize of the copy `StyleImage::to_f32` made before.
        let (h, w) = (37, 53);
        let bytes: Vec<u8> = (0..h * w * 3).map(|i| (i * 97 % 251) as u8).collect();
        let copy: Vec<f32> = bytes.iter().map(|&v| f32::from(v) / 255.0).collect();
        for (oh, ow) in [(12, 17), (37, 53), (50, 80)] {
            let from_bytes = resize_bicubic_antialias(&bytes, h, w, 3, oh, ow);
            assert_eq!(from_bytes, resize_bicubic_antialias(&copy, h, w, 3, oh, ow), "{oh}x{ow}");
        }
    }

    #[test]
    fn torch_bicubic_known_values() {
        // F.interpolate(torch.tensor([[[[0., 1., 4., 9.]]]]), size=(1, 2), mode='bicubic', align_corners=False)
        // samples x = 0.5 and 2.5: 0.3125·0 … computed by hand from the A = −0.75 kernel.
        let out = resize_bicubic(&[0.0, 1.0, 4.0, 9.0], 1, 4, 1, 1, 2);
        // Taps at t = 0.5: (−0.09375, 0.59375, 0.59375, −0.09375), indices clamped at the border.
        let e0 = -0.09375 * 0.0 + 0.59375 * 0.0 + 0.59375 * 1.0 - 0.09375 * 4.0;
        let e1 = -0.09375 * 1.0 + 0.59375 * 4.0 + 0.59375 * 9.0 - 0.09375 * 9.0;
        assert!((out[0] - e0).abs() < 1e-6 && (out[1] - e1).abs() < 1e-6, "{out:?}");
        // Aligned corners keep both ends.
        let al = resize_bilinear_align_corners(&[0.0, 3.0], 1, 2, 1, 1, 4);
        assert_eq!(al, vec![0.0, 1.0, 2.0, 3.0]);
    }
}
