//! The feature-mean term (λ_mean; not in the reference, off by default): the
//! mean of the rendered RGB relu3 features over the positions the losses
//! average over (the object's with object focus) pulled toward the mean of
//! the style's, `(1/C) Σ_c (μ_c − μ^S_c)²`.
//!
//! GCFM's nearest-neighbour pull leaves the object's feature mean where the
//! colour matching put it; the paper's whole-frame losses move it toward the
//! style's by darkening the object. This term moves the mean directly,
//! without the background (README, the focus study's λ_mean rows).

use serde::{Deserialize, Serialize};

use super::schedule::Phase;

/// Which steps λ_mean acts on.
///
/// On the geometry steps the term competes with GCFM's nearest-neighbour
/// pull; left to the colour steps it gives that pull back, but the colour
/// steps (10 of 100, DC only) move the mean little: on biker × fire,
/// particle and starry at 200 steps, `colour` kept NN-cos ahead of the frame
/// arm on all three and lost SW on two, `every` the reverse (README, the
/// focus study's row on λ_mean's steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeanSteps {
    /// The steps that update colour (the colour phase, and every `joint` step).
    Colour,
    /// Every step, colour and geometry.
    #[default]
    Every,
}

impl MeanSteps {
    /// All choices, for menus.
    pub const ALL: [MeanSteps; 2] = [MeanSteps::Colour, MeanSteps::Every];

    /// Whether the term acts on a step of `phase`.
    pub fn acts_in(self, phase: Phase) -> bool {
        match self {
            MeanSteps::Colour => phase.updates_color(),
            MeanSteps::Every => true,
        }
    }
}

impl std::str::FromStr for MeanSteps {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "colour" | "color" => Ok(MeanSteps::Colour),
            "every" => Ok(MeanSteps::Every),
            _ => Err(format!("expected colour or every, found {s:?}")),
        }
    }
}

/// Per channel, the mean of a `channels × n` (CHW) feature map over its positions.
pub fn channel_means(features: &[f32], channels: usize) -> Vec<f32> {
    let n = features.len() / channels.max(1);
    (0..channels)
        .map(|c| {
            let row = &features[c * n..(c + 1) * n];
            (row.iter().map(|&v| f64::from(v)).sum::<f64>() / n.max(1) as f64) as f32
        })
        .collect()
}

/// The term and its gradient w.r.t. `rendered` (`channels × n`, CHW), over
/// the positions in `mask` (all without one); uncovered positions get a zero
/// gradient. A mask that covers nothing gives `(0, zeros)`.
pub fn feature_mean_loss(
    rendered: &[f32],
    channels: usize,
    style_mean: &[f32],
    mask: Option<&[bool]>,
) -> (f32, Vec<f32>) {
    assert_eq!(style_mean.len(), channels, "feature_mean_loss: one style mean per channel");
    let n = rendered.len() / channels.max(1);
    let inside: Vec<usize> = (0..n).filter(|&x| mask.is_none_or(|m| m[x])).collect();
    let mut grad = vec![0f32; rendered.len()];
    if inside.is_empty() || channels == 0 {
        return (0.0, grad);
    }
    let mut loss = 0f64;
    for c in 0..channels {
        let row = &rendered[c * n..(c + 1) * n];
        let mu = inside.iter().map(|&x| f64::from(row[x])).sum::<f64>() / inside.len() as f64;
        let d = mu - f64::from(style_mean[c]);
        loss += d * d;
        let g = (2.0 * d / (channels as f64 * inside.len() as f64)) as f32;
        for &x in &inside {
            grad[c * n + x] = g;
        }
    }
    ((loss / channels as f64) as f32, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(c: usize, n: usize) -> Vec<f32> {
        (0..c * n).map(|i| ((i * 37 % 101) as f32 / 50.0 - 1.0).abs()).collect()
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (c, n) = (5, 12);
        let f = features(c, n);
        let target: Vec<f32> = (0..c).map(|k| 0.1 * k as f32).collect();
        let mask: Vec<bool> = (0..n).map(|x| x % 3 != 0).collect();
        let (_, g) = feature_mean_loss(&f, c, &target, Some(&mask));
        let h = 1e-3;
        for i in 0..c * n {
            let (mut up, mut down) = (f.clone(), f.clone());
            up[i] += h;
            down[i] -= h;
            let fd = (feature_mean_loss(&up, c, &target, Some(&mask)).0
                - feature_mean_loss(&down, c, &target, Some(&mask)).0)
                / (2.0 * h);
            assert!((fd - g[i]).abs() < 1e-3, "element {i}: {fd} against {}", g[i]);
        }
    }

    #[test]
    fn an_all_ones_mask_equals_none_and_uncovered_positions_get_nothing() {
        let (c, n) = (4, 10);
        let f = features(c, n);
        let target = vec![0.3; c];
        let all = vec![true; n];
        assert_eq!(feature_mean_loss(&f, c, &target, Some(&all)), feature_mean_loss(&f, c, &target, None));
        let mask: Vec<bool> = (0..n).map(|x| x < 4).collect();
        let (l, g) = feature_mean_loss(&f, c, &target, Some(&mask));
        assert!(l > 0.0);
        for ch in 0..c {
            assert!(g[ch * n + 4..(ch + 1) * n].iter().all(|&v| v == 0.0), "channel {ch}");
            assert!(g[ch * n..ch * n + 4].iter().all(|&v| v != 0.0), "channel {ch}");
        }
        // Changing an uncovered position changes nothing.
        let mut moved = f.clone();
        moved[n - 1] += 5.0;
        assert_eq!(feature_mean_loss(&moved, c, &target, Some(&mask)).0, l);
        let none = vec![false; n];
        assert_eq!(feature_mean_loss(&f, c, &target, Some(&none)), (0.0, vec![0.0; c * n]));
    }

    #[test]
    fn matching_means_cost_nothing() {
        let (c, n) = (3, 8);
        let f = features(c, n);
        let (l, g) = feature_mean_loss(&f, c, &channel_means(&f, c), None);
        assert!(l < 1e-12 && g.iter().all(|v| v.abs() < 1e-6));
    }
}
