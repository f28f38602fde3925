//! The background hold (λ_out; not in the reference, off by default): with
//! object focus, the pixels the colour-matched scene leaves empty keep their
//! colour-matched render, `(1/3N) Σ_{p outside} Σ_c (I_p,c − I^c_p,c)²`.
//!
//! The masked losses see only the object ([`super::focus`]), so nothing stops
//! a geometry step from spreading a rim Gaussian into the empty frame or a
//! colour step from lighting a floater there; with λ_mean the renders show
//! haze and streaks around the silhouette (README, the focus study's λ_mean
//! rows). This term gives those pixels a gradient back toward `G^c`'s.
//! Pixels between the covered mask and the empty one (the soft rim) stay free.

/// Below this alpha of the colour-matched render a pixel counts as empty.
pub const OUTSIDE_ALPHA: f32 = 0.05;

/// The pixels the colour-matched render leaves empty (`alpha < OUTSIDE_ALPHA`).
pub fn outside_mask(alpha: &[f32]) -> Vec<bool> {
    alpha.iter().map(|&a| a < OUTSIDE_ALPHA).collect()
}

/// What the hold compares with: the empty pixels (`h × w`) and the
/// colour-matched render (HWC, clamped to [0, 1]).
#[derive(Clone, Copy, Debug)]
pub struct Outside<'a> {
    /// The pixels to hold.
    pub mask: &'a [bool],
    /// The colour-matched render of the same view.
    pub rgb: &'a [f32],
}

/// The term and its gradient w.r.t. `rgb` (HWC): the mean squared difference
/// over the held pixels' channels; pixels outside the mask get a zero
/// gradient, and a mask that holds nothing gives `(0, zeros)`.
pub fn outside_loss(rgb: &[f32], held: Outside<'_>) -> (f32, Vec<f32>) {
    assert_eq!(rgb.len(), held.rgb.len(), "outside_loss: render and target size");
    assert_eq!(rgb.len(), held.mask.len() * 3, "outside_loss: mask size");
    let count = held.mask.iter().filter(|&&m| m).count();
    let mut grad = vec![0f32; rgb.len()];
    if count == 0 {
        return (0.0, grad);
    }
    let n = 3.0 * count as f64;
    let mut loss = 0f64;
    for (p, _) in held.mask.iter().enumerate().filter(|(_, m)| **m) {
        for c in 3 * p..3 * p + 3 {
            let d = f64::from(rgb[c] - held.rgb[c]);
            loss += d * d;
            grad[c] = (2.0 * d / n) as f32;
        }
    }
    ((loss / n) as f32, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gradient_is_the_finite_difference_and_zero_off_the_mask() {
        let (h, w) = (4, 5);
        let rgb: Vec<f32> = (0..h * w * 3).map(|i| (i * 13 % 17) as f32 / 17.0).collect();
        let target: Vec<f32> = (0..h * w * 3).map(|i| (i * 7 % 11) as f32 / 11.0).collect();
        let mask: Vec<bool> = (0..h * w).map(|p| p % 3 != 0).collect();
        let held = Outside { mask: &mask, rgb: &target };
        let (l, g) = outside_loss(&rgb, held);
        assert!(l > 0.0);
        for i in 0..rgb.len() {
            let eps = 1e-3;
            let mut up = rgb.clone();
            up[i] += eps;
            let mut down = rgb.clone();
            down[i] -= eps;
            let fd = (outside_loss(&up, held).0 - outside_loss(&down, held).0) / (2.0 * eps);
            assert!((fd - g[i]).abs() < 1e-3, "channel {i}: finite difference {fd}, gradient {}", g[i]);
            if !mask[i / 3] {
                assert_eq!(g[i], 0.0, "channel {i} is off the mask");
            }
        }
    }

    #[test]
    fn an_empty_mask_or_an_equal_render_costs_nothing() {
        let rgb = vec![0.3f32; 12];
        let none = vec![false; 4];
        assert_eq!(outside_loss(&rgb, Outside { mask: &none, rgb: &[0.0; 12] }), (0.0, vec![0.0; 12]));
        let all = vec![true; 4];
        assert_eq!(outside_loss(&rgb, Outside { mask: &all, rgb: &rgb }), (0.0, vec![0.0; 12]));
        assert_eq!(outside_mask(&[0.0, 0.049, 0.05, 1.0]), vec![true, true, false, false]);
    }
}
