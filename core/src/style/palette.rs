//! The palette hold (λ_pal; not in the reference, off by default): with
//! object focus, the covered pixels' per-channel mean and standard deviation
//! stay at the colour-matched render's,
//! `Σ_c (μ_c − μ^c_c)² + (σ_c − σ^c_c)²` over the view's covered pixels.
//!
//! Stage 1 gives the object the style's palette (on guitar × stone the
//! colour-matched object's covered luminance and chroma, 0.183 and 0.168,
//! are the painting's 0.17 and 0.16). The feature losses then ask each patch
//! to look like some style patch, and a dark one (stone's crevices) serves
//! as well as any: the geometry steps' moving means darken the object below
//! the palette it started with (docs/studies/defaults.md, "What darkens
//! guitar × stone"). These six numbers leave the arrangement of the colours
//! free and hold their overall statistics.

/// Per channel the mean, then the standard deviation, of a render's pixels.
pub type Palette = [f32; 6];

/// The palette of `rgb` (HWC) over the pixels in `mask` (`h × w`); zeros
/// when the mask is empty.
pub fn palette_of(rgb: &[f32], mask: &[bool]) -> Palette {
    palette_and_count(rgb, mask).0
}

/// [`palette_of`] and the number of pixels in the mask.
fn palette_and_count(rgb: &[f32], mask: &[bool]) -> (Palette, usize) {
    assert_eq!(rgb.len(), mask.len() * 3, "palette_of: mask size");
    let (mut s, mut n) = ([0f64; 6], 0usize);
    for (p, _) in rgb.chunks_exact(3).zip(mask).filter(|(_, m)| **m) {
        for c in 0..3 {
            let v = f64::from(p[c]);
            s[c] += v;
            s[3 + c] += v * v;
        }
        n += 1;
    }
    let mut out = [0f32; 6];
    if n == 0 {
        return (out, 0);
    }
    let count = n as f64;
    for c in 0..3 {
        let m = s[c] / count;
        out[c] = m as f32;
        out[3 + c] = (s[3 + c] / count - m * m).max(0.0).sqrt() as f32;
    }
    (out, n)
}

/// The term and its gradient w.r.t. `rgb` (HWC): zero off the mask, and
/// `(0, zeros)` for an empty mask.
pub fn palette_loss(rgb: &[f32], mask: &[bool], reference: &Palette) -> (f32, Vec<f32>) {
    let (now, n) = palette_and_count(rgb, mask);
    let mut grad = vec![0f32; rgb.len()];
    if n == 0 {
        return (0.0, grad);
    }
    let n = n as f32;
    let (mut loss, mut a, mut b) = (0f32, [0f32; 3], [0f32; 3]);
    for c in 0..3 {
        let (dm, ds) = (now[c] - reference[c], now[3 + c] - reference[3 + c]);
        loss += dm * dm + ds * ds;
        // ∂μ/∂x = 1/n; ∂σ/∂x = (x − μ)/(n σ), taken as 0 for a flat channel.
        a[c] = 2.0 * dm / n;
        b[c] = if now[3 + c] > 1e-6 { 2.0 * ds / (n * now[3 + c]) } else { 0.0 };
    }
    for ((g, p), _) in grad.chunks_exact_mut(3).zip(rgb.chunks_exact(3)).zip(mask).filter(|(_, m)| **m) {
        for c in 0..3 {
            g[c] = a[c] + b[c] * (p[c] - now[c]);
        }
    }
    (loss, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(h: usize, w: usize, k: usize) -> Vec<f32> {
        (0..h * w * 3).map(|i| ((i * k + 5) % 23) as f32 / 23.0).collect()
    }

    #[test]
    fn the_palette_is_the_masked_mean_and_deviation() {
        // Two covered pixels (0.2, 0.4, 0.6) and (0.6, 0.4, 0.2); the third is off the mask.
        let rgb = [0.2, 0.4, 0.6, 0.6, 0.4, 0.2, 1.0, 1.0, 1.0];
        let p = palette_of(&rgb, &[true, true, false]);
        let want = [0.4, 0.4, 0.4, 0.2, 0.0, 0.2];
        for (a, b) in p.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{p:?}");
        }
        assert_eq!(palette_of(&rgb, &[false; 3]), [0.0; 6]);
    }

    #[test]
    fn the_gradient_is_the_finite_difference_and_zero_off_the_mask() {
        let (h, w) = (4, 5);
        let rgb = image(h, w, 13);
        let mask: Vec<bool> = (0..h * w).map(|i| i % 3 != 0).collect();
        let reference = palette_of(&image(h, w, 7), &mask);
        let (l, g) = palette_loss(&rgb, &mask, &reference);
        assert!(l > 1e-4, "the two palettes differ: {l}");
        let eps = 1e-3;
        for i in 0..rgb.len() {
            let (mut up, mut down) = (rgb.clone(), rgb.clone());
            up[i] += eps;
            down[i] -= eps;
            let fd = (palette_loss(&up, &mask, &reference).0 - palette_loss(&down, &mask, &reference).0) / (2.0 * eps);
            assert!((fd - g[i]).abs() < 2e-3, "pixel {} channel {}: {fd} against {}", i / 3, i % 3, g[i]);
            if !mask[i / 3] {
                assert_eq!(g[i], 0.0);
            }
        }
    }

    #[test]
    fn the_colour_matched_render_holds_nothing() {
        let (h, w) = (3, 3);
        let rgb = image(h, w, 11);
        let mask = vec![true; h * w];
        let (l, g) = palette_loss(&rgb, &mask, &palette_of(&rgb, &mask));
        assert!(l < 1e-10 && g.iter().all(|v| v.abs() < 1e-6), "{l}");
        // A darker render is pulled up: every covered channel's gradient is negative.
        let dark: Vec<f32> = rgb.iter().map(|v| v * 0.5).collect();
        let (l, g) = palette_loss(&dark, &mask, &palette_of(&rgb, &mask));
        assert!(l > 0.0 && g.iter().sum::<f32>() < 0.0);
        assert_eq!(palette_loss(&rgb, &[false; 9], &palette_of(&rgb, &mask)), (0.0, vec![0.0; 27]));
    }
}
