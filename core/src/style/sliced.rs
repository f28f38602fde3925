//! The sliced Wasserstein term (λ_sw; not in the reference, off by default):
//! the distribution of the rendered RGB relu3 features over the positions the
//! losses average over (the object's with object focus) pulled toward the
//! style's, one 1-D optimal transport per projection direction (Heitz et al.,
//! "A Sliced Wasserstein Loss for Neural Texture Synthesis", CVPR 2021):
//!
//! `(1/P) Σ_p (1/m) Σ_k (r_p,(k) − t_p,k)²`
//!
//! with `r_p,(k)` the k-th smallest projection `θ_p · F(x)` of the `m`
//! rendered positions and `t_p,k` the style's projections' quantile at
//! `(k + ½)/m`. Its gradient moves every feature along each direction toward
//! the style value of its rank.
//!
//! Along a unit direction the squared distance of two quantile functions is
//! the squared difference of their means plus that of the centred ones, and
//! the mean part averages to `|μ − μ^S|²/C` over random directions: the
//! feature-mean term ([`super::feature_mean`]) is this term's first moment.
//! λ_mean pulls every feature by one shift toward the style's average; this
//! term spreads them as the style's are spread, so they can land near actual
//! style features (what GCFM and the nearest-neighbour measure look for).
//!
//! The directions are fixed for a run (seeded, not those of the evaluation's
//! sliced Wasserstein measure), so the style side is projected and sorted
//! once.

use rayon::prelude::*;

use super::focus::gather_positions;
use crate::rng::Rng;
use crate::stats::quantile;
use crate::vision::matmul;

/// Projection directions of the term.
pub const SLICED_PROJECTIONS: usize = 128;
/// Seed of the term's directions (the evaluation's measure draws its own).
const SLICED_LOSS_SEED: u64 = 0x51_1CED_7E57;

/// The style side of the term: the directions and the style's sorted
/// projections on them.
#[derive(Clone, Debug)]
pub struct SlicedTarget {
    channels: usize,
    /// `P × C` unit directions, row-major.
    directions: Vec<f32>,
    /// Per direction, the style's projections in increasing order.
    sorted: Vec<Vec<f32>>,
}

impl SlicedTarget {
    /// The target of the CHW style features `style` (`channels × n`) on
    /// `projections` seeded directions.
    pub fn new(style: &[f32], channels: usize, projections: usize) -> Self {
        let channels = channels.max(1);
        let n = style.len() / channels;
        let mut rng = Rng::new(SLICED_LOSS_SEED);
        let directions: Vec<f32> = (0..projections)
            .flat_map(|_| {
                let v: Vec<f32> = (0..channels).map(|_| rng.normal()).collect();
                let len = v.iter().map(|x| x * x).sum::<f32>().sqrt().max(1e-12);
                v.into_iter().map(move |x| x / len)
            })
            .collect();
        let projected = project(&directions, projections, &style[..n * channels], channels, n);
        let sorted = projected
            .par_chunks(n.max(1))
            .map(|row| {
                let mut r = row.to_vec();
                r.sort_by(f32::total_cmp);
                r
            })
            .collect();
        Self { channels, directions, sorted }
    }

    /// Number of projection directions.
    pub fn projections(&self) -> usize {
        self.sorted.len()
    }

    /// Channels of the features it compares.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The `P × C` unit directions, row-major.
    pub fn directions(&self) -> &[f32] {
        &self.directions
    }

    /// The style's projections on direction `p`, in increasing order.
    pub fn sorted(&self, p: usize) -> &[f32] {
        &self.sorted[p]
    }

    /// Style positions (the length of each direction's sorted projections).
    pub fn style_positions(&self) -> usize {
        self.sorted.first().map_or(0, Vec::len)
    }
}

/// `P × n` projections `Θ X` of the CHW features `x` (`channels × n`).
fn project(directions: &[f32], projections: usize, x: &[f32], channels: usize, n: usize) -> Vec<f32> {
    let mut p = vec![0.0f32; projections * n];
    matmul(&mut p, n, (directions, channels, 1), (x, n), (projections, n, channels), false);
    p
}

/// The term and its gradient w.r.t. `rendered` (`channels × n`, CHW), over
/// the positions in `mask` (all without one); uncovered positions get a zero
/// gradient. A mask that covers nothing, or a target without style
/// positions, gives `(0, zeros)`.
pub fn sliced_loss(rendered: &[f32], channels: usize, target: &SlicedTarget, mask: Option<&[bool]>) -> (f32, Vec<f32>) {
    assert_eq!(channels, target.channels, "sliced_loss: the target's channel count");
    let n = rendered.len() / channels.max(1);
    let mut grad = vec![0.0f32; rendered.len()];
    let covered: Vec<usize> = (0..n).filter(|&i| mask.is_none_or(|m| m[i])).collect();
    let (m, projections) = (covered.len(), target.projections());
    if m == 0 || projections == 0 || target.sorted[0].is_empty() {
        return (0.0, grad);
    }
    // The covered columns, compact (`channels × m`), and their projections.
    let x = gather_positions(rendered, channels, n, &covered);
    let r = project(&target.directions, projections, &x, channels, m);
    // Per direction: each position's residual against the style value of its rank.
    let scale = 2.0 / (m * projections) as f32;
    let (residuals, sums): (Vec<Vec<f32>>, Vec<f64>) = r
        .par_chunks(m)
        .zip(&target.sorted)
        .map(|(row, style)| {
            let mut order: Vec<usize> = (0..m).collect();
            order.sort_by(|&a, &b| row[a].total_cmp(&row[b]));
            let mut e = vec![0.0f32; m];
            let mut sum = 0.0f64;
            for (k, &i) in order.iter().enumerate() {
                let d = row[i] - quantile(style, (k as f32 + 0.5) / m as f32);
                sum += f64::from(d) * f64::from(d);
                e[i] = d * scale;
            }
            (e, sum / m as f64)
        })
        .unzip();
    let value = (sums.iter().sum::<f64>() / projections as f64) as f32;
    // dX = Θᵀ G (`channels × m`), scattered back to the covered positions.
    let g: Vec<f32> = residuals.concat();
    let mut dx = vec![0.0f32; channels * m];
    matmul(&mut dx, m, (&target.directions, 1, channels), (&g, m), (channels, m, projections), false);
    for c in 0..channels {
        for (k, &i) in covered.iter().enumerate() {
            grad[c * n + i] = dx[c * m + k];
        }
    }
    (value, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::style::feature_mean::{channel_means, feature_mean_loss};

    fn sample(c: usize, n: usize, phase: f32) -> Vec<f32> {
        (0..c * n).map(|i| ((i as f32 * 0.37 + phase).sin() + 0.3 * (i as f32 * 1.3).cos()).max(0.0)).collect()
    }

    #[test]
    fn the_gradient_matches_finite_differences_and_is_zero_off_the_mask() {
        let (c, n) = (6, 40);
        let style = sample(c, 55, 2.0);
        let target = SlicedTarget::new(&style, c, 16);
        let f = sample(c, n, 0.4);
        let mask: Vec<bool> = (0..n).map(|i| i % 3 != 0).collect();
        let (l, g) = sliced_loss(&f, c, &target, Some(&mask));
        assert!(l > 0.0);
        let h = 1e-3;
        for k in [0, 5, 41, 77, 130, 199, 238] {
            let (mut up, mut down) = (f.clone(), f.clone());
            up[k] += h;
            down[k] -= h;
            let fd = (sliced_loss(&up, c, &target, Some(&mask)).0 - sliced_loss(&down, c, &target, Some(&mask)).0)
                / (2.0 * h);
            if mask[k % n] {
                assert!((fd - g[k]).abs() < 2e-3 * (1.0 + g[k].abs()), "position {k}: fd {fd} grad {}", g[k]);
            } else {
                assert_eq!(g[k], 0.0, "uncovered position {k}");
                assert!(fd.abs() < 1e-6, "uncovered position {k} moves the loss: {fd}");
            }
        }
    }

    #[test]
    fn the_style_itself_costs_nothing_and_masks_behave() {
        let (c, n) = (5, 33);
        let f = sample(c, n, 1.1);
        let target = SlicedTarget::new(&f, c, 24);
        let (l, g) = sliced_loss(&f, c, &target, None);
        assert!(l < 1e-10, "{l}");
        assert!(g.iter().all(|v| v.abs() < 1e-5));
        // Order of positions does not matter: a distribution, not a layout.
        let rev: Vec<f32> =
            (0..c).flat_map(|ch| (0..n).rev().map(move |i| (ch, i))).map(|(ch, i)| f[ch * n + i]).collect();
        assert!(sliced_loss(&rev, c, &target, None).0 < 1e-10);
        let all = vec![true; n];
        assert_eq!(sliced_loss(&f, c, &target, Some(&all)), sliced_loss(&f, c, &target, None));
        let none = vec![false; n];
        assert_eq!(sliced_loss(&f, c, &target, Some(&none)), (0.0, vec![0.0; c * n]));
        assert_eq!(SlicedTarget::new(&f, c, 24).sorted, target.sorted, "seeded: the same directions");
    }

    #[test]
    fn a_shift_costs_on_average_what_the_feature_mean_term_does() {
        // Shifting every feature by s adds (θ·s)² along θ; over many random
        // unit directions that averages to |s|²/C, the feature-mean term.
        let (c, n) = (8, 30);
        let style = sample(c, n, 0.7);
        let shifted: Vec<f32> = style.iter().enumerate().map(|(k, v)| v + 0.2 + 0.05 * (k / n) as f32).collect();
        let target = SlicedTarget::new(&style, c, 4096);
        let (sw, _) = sliced_loss(&shifted, c, &target, None);
        let (mean, _) = feature_mean_loss(&shifted, c, &channel_means(&style, c), None);
        assert!((sw - mean).abs() < 0.1 * mean, "sliced {sw} against the mean term {mean}");
    }
}
