//! Content loss: keeps the stylised render's VGG features close to those of
//! the colour-matched scene from the same view, so objects stay recognisable.
//!
//! `L = mean((φ − φ_c)²)` over all channels and positions, `∂L/∂φ = 2(φ − φ_c)/n`.

/// Mean squared difference of two feature maps (any layout, same length) and
/// its gradient with respect to `features`.
pub fn content_loss(features: &[f32], content_features: &[f32]) -> (f32, Vec<f32>) {
    content_loss_masked(features, content_features, None)
}

/// [`content_loss`] averaged over the positions in `mask` only: the maps are
/// channel-major (`c × mask.len()`), the mean runs over every channel of the
/// covered positions, and uncovered positions get a zero gradient.
pub fn content_loss_masked(features: &[f32], content_features: &[f32], mask: Option<&[bool]>) -> (f32, Vec<f32>) {
    assert_eq!(features.len(), content_features.len(), "content_loss: feature sizes differ");
    let positions = mask.map_or(1, <[bool]>::len).max(1);
    let inside = |k: usize| mask.is_none_or(|m| m[k % positions]);
    let count = match mask {
        None => features.len(),
        Some(m) => m.iter().filter(|&&v| v).count() * (features.len() / positions),
    };
    let n = count.max(1) as f64;
    let mut sum = 0f64;
    let scale = (2.0 / n) as f32;
    let grad = features
        .iter()
        .zip(content_features)
        .enumerate()
        .map(|(k, (&f, &c))| {
            if !inside(k) {
                return 0.0;
            }
            let d = f - c;
            sum += f64::from(d) * f64::from(d);
            scale * d
        })
        .collect();
    ((sum / n) as f32, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_and_finite_difference() {
        let f = vec![0.5f32, -1.0, 2.0, 0.25];
        let c = vec![0.0f32, 1.0, 1.5, 0.25];
        let (l, g) = content_loss(&f, &c);
        assert!((l - (0.25 + 4.0 + 0.25) / 4.0).abs() < 1e-6);
        for i in 0..f.len() {
            let mut p = f.clone();
            p[i] += 1e-3;
            let mut m = f.clone();
            m[i] -= 1e-3;
            let fd = (content_loss(&p, &c).0 - content_loss(&m, &c).0) / 2e-3;
            assert!((fd - g[i]).abs() < 1e-3, "{i}: {fd} vs {}", g[i]);
        }
    }
}
