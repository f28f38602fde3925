//! Measures of a stylization, each with its formula, for reports and benchmarks.
//!
//! - **Mean–std style distance** (as in AdaIN's style loss): for VGG relu3
//!   features `F` of a render and `S` of the style image, both `C × N`,
//!   `d = (1/C) Σ_c |μ_c(F) − μ_c(S)| + |σ_c(F) − σ_c(S)|`. Lower is closer to
//!   the style's feature statistics; it ignores spatial layout.
//! - **Nearest-neighbour feature distance**: `(1/N) Σ_x min_y (1 − cos(F(x), S(y)))`,
//!   how well every rendered feature finds a close style feature.
//! - **Inverse-depth change**: over pixels covered in both renders (alpha ≥ 0.5),
//!   `mean |D_after − D_before| / mean D_before`, a relative change of geometry.

/// `(1/C) Σ_c |μ_c(a) − μ_c(b)| + |σ_c(a) − σ_c(b)|` for CHW feature maps with
/// `channels` channels (any number of positions each).
pub fn mean_std_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    if channels == 0 || a.is_empty() || b.is_empty() {
        return 0.0;
    }
    let (na, nb) = (a.len() / channels, b.len() / channels);
    let stats = |x: &[f32]| {
        let n = x.len() as f64;
        let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
        (mean, var.sqrt())
    };
    let mut d = 0.0f64;
    for c in 0..channels {
        let (ma, sa) = stats(&a[c * na..(c + 1) * na]);
        let (mb, sb) = stats(&b[c * nb..(c + 1) * nb]);
        d += (ma - mb).abs() + (sa - sb).abs();
    }
    (d / channels as f64) as f32
}

/// `(1/N) Σ_x min_y (1 − cos(a(x), b(y)))` for CHW feature maps of `channels`
/// channels. The nearest style feature is found by the same tiled matrix
/// products as the GCFM matching (the other two modalities left empty, so the
/// joint cosine is the cosine of `a` and `b`).
pub fn nn_cosine_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    use crate::style::gcfm::{StyleFeatures, match_features};
    if channels == 0 || a.is_empty() || b.is_empty() {
        return 0.0;
    }
    let (na, nb) = (a.len() / channels, b.len() / channels);
    let style = StyleFeatures::new([b.to_vec(), vec![0.0; b.len()], vec![0.0; b.len()]], channels, 1, nb);
    let zeros = vec![0.0; a.len()];
    let best = match_features(&style, [a, &zeros, &zeros], na).best;
    let norm = |x: &[f32], n: usize, i: usize| (0..channels).map(|c| x[c * n + i].powi(2)).sum::<f32>().sqrt() + 1e-8;
    let total: f64 = best
        .iter()
        .enumerate()
        .map(|(i, &j)| {
            let j = j as usize;
            let dot: f32 = (0..channels).map(|c| a[c * na + i] * b[c * nb + j]).sum();
            f64::from(1.0 - dot / (norm(a, na, i) * norm(b, nb, j)))
        })
        .sum();
    (total / na as f64) as f32
}

/// `mean |after − before| / mean before` over pixels where both alphas are ≥ 0.5
/// (0 when no pixel qualifies).
pub fn inverse_depth_change(before: &[f32], after: &[f32], alpha_before: &[f32], alpha_after: &[f32]) -> f32 {
    let (mut diff, mut base, mut n) = (0.0f64, 0.0f64, 0usize);
    for i in 0..before.len().min(after.len()) {
        if alpha_before[i] >= 0.5 && alpha_after[i] >= 0.5 {
            diff += (after[i] - before[i]).abs() as f64;
            base += before[i].abs() as f64;
            n += 1;
        }
    }
    if n == 0 || base == 0.0 { 0.0 } else { (diff / base) as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_zero_for_identical_maps_and_grow_with_difference() {
        let a: Vec<f32> = (0..2 * 6).map(|i| (i as f32 * 0.37).sin()).collect();
        assert!(mean_std_distance(&a, &a, 2) < 1e-6);
        assert!(nn_cosine_distance(&a, &a, 2) < 1e-5);
        let b: Vec<f32> = a.iter().map(|v| 2.0 * v + 1.0).collect();
        assert!(mean_std_distance(&a, &b, 2) > 0.5);
        let d = [1.0f32, 2.0, 4.0];
        let alpha = [1.0f32, 1.0, 0.0];
        // Third pixel ignored: |1.5-1| + |2-2| over 1 + 2.
        assert!((inverse_depth_change(&d, &[1.5, 2.0, 9.0], &alpha, &alpha) - 0.5 / 3.0).abs() < 1e-6);
    }
}
