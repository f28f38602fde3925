//! Why a sliced Wasserstein distance moved: a shift of the whole feature
//! distribution, a change of its shape, or only the features' lengths.
//!
//! The focus study saw object focus lower the nearest-neighbour cosine
//! distance on the object more than the whole-frame losses do, while it
//! lowered the sliced Wasserstein distance (SW) less. The two read different
//! things: NN-cos, like the GCFM loss, looks only at the *directions* of the
//! relu3 feature vectors; SW compares the vectors themselves, so how long they
//! are (how bright and contrasted the render is) and where their mean lies
//! count as much as the patterns. This module splits SW so a report can say
//! which part moved:
//! - per projection, the squared distance between two quantile functions
//!   splits exactly into the squared difference of their means (a shift of
//!   the whole distribution) and the distance between the centred quantiles
//!   (its shape), so `SW² = SW_mean² + SW_shape²`, on the very directions and
//!   quantiles of [`super::StyleReference::sliced_wasserstein`];
//! - SW between unit-length features, which ignores every vector's length as
//!   NN-cos and GCFM do;
//! - the mean feature length of the render over the style's.

use rayon::prelude::*;

use super::style::{projection_directions, sorted_projections, unit_columns};
use crate::stats::quantile;

/// The parts of one sliced Wasserstein distance (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SlicedParts {
    /// The shift of the means along the projections, feature units.
    pub mean: f32,
    /// The centred distributions' distance, feature units (`mean² + shape² = SW²`).
    pub shape: f32,
    /// SW between unit-length features (directions only), unitless.
    pub unit: f32,
    /// Mean feature length of the render over the style's mean feature length.
    pub norm_ratio: f32,
}

/// The style side of [`SlicedParts`], computed once per style.
pub struct SlicedBreakdown {
    channels: usize,
    /// `P × C` unit directions, those of [`super::StyleReference`] for the same `P`.
    directions: Vec<f32>,
    /// Sorted projections of the style's features and of its unit-length features, one row per direction.
    sorted: Vec<Vec<f64>>,
    sorted_unit: Vec<Vec<f64>>,
    /// Mean length of the style's feature vectors.
    mean_norm: f64,
}

impl SlicedBreakdown {
    /// The CHW style features `b` (`channels` channels) on `projections`
    /// directions; `None` when `b` is empty, `channels` is 0 or `projections` is 0.
    pub fn new(b: &[f32], channels: usize, projections: usize) -> Option<Self> {
        if channels == 0 || projections == 0 || b.len() < channels {
            return None;
        }
        let n = b.len() / channels;
        let b = &b[..n * channels];
        let directions = projection_directions(channels, projections);
        let unit = unit_columns(b, channels);
        Some(Self {
            channels,
            sorted: sorted_projections(&directions, projections, b, channels),
            sorted_unit: sorted_projections(&directions, projections, &unit, channels),
            directions,
            mean_norm: mean_norm(b, channels),
        })
    }

    /// The parts of the distance from the CHW features `a` to the style
    /// (all 0 when `a` has no position).
    pub fn parts(&self, a: &[f32]) -> SlicedParts {
        let c = self.channels;
        if a.len() < c {
            return SlicedParts::default();
        }
        let a = &a[..a.len() / c * c];
        let p = self.sorted.len();
        let (mean, shape) = split(&sorted_projections(&self.directions, p, a, c), &self.sorted);
        let (um, us) = split(&sorted_projections(&self.directions, p, &unit_columns(a, c), c), &self.sorted_unit);
        SlicedParts {
            mean: mean as f32,
            shape: shape as f32,
            unit: (um * um + us * us).sqrt() as f32,
            norm_ratio: (mean_norm(a, c) / self.mean_norm.max(1e-12)) as f32,
        }
    }
}

/// `(SW_mean, SW_shape)` of sorted projections `pa` against `pb` (one row per
/// direction), on the quantiles `(k + ½)/M`, `M = max(N_a, N_b)`.
fn split(pa: &[Vec<f64>], pb: &[Vec<f64>]) -> (f64, f64) {
    let (mean, shape) = pa
        .par_iter()
        .zip(pb)
        .map(|(pa, pb)| {
            let m = pa.len().max(pb.len());
            let d: Vec<f64> = (0..m)
                .map(|k| {
                    let q = (k as f64 + 0.5) / m as f64;
                    quantile(pa, q) - quantile(pb, q)
                })
                .collect();
            let dm = d.iter().sum::<f64>() / m as f64;
            (dm * dm, d.iter().map(|x| (x - dm).powi(2)).sum::<f64>() / m as f64)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let n = pa.len().max(1) as f64;
    ((mean / n).sqrt(), (shape / n).sqrt())
}

/// Mean Euclidean length of the feature vectors of a CHW map.
fn mean_norm(x: &[f32], channels: usize) -> f64 {
    let n = x.len() / channels;
    let mut sq = vec![0f64; n];
    for ch in 0..channels {
        for (acc, &v) in sq.iter_mut().zip(&x[ch * n..(ch + 1) * n]) {
            *acc += f64::from(v) * f64::from(v);
        }
    }
    sq.iter().map(|v| v.sqrt()).sum::<f64>() / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::style::StyleReference;

    fn sample(c: usize, n: usize, phase: f32) -> Vec<f32> {
        (0..c * n).map(|i| (i as f32 * 0.37 + phase).sin() + 0.2 * (i as f32 * 1.3).cos()).collect()
    }

    #[test]
    fn the_mean_and_shape_parts_add_up_to_the_reported_distance() {
        let (c, p) = (4, 32);
        let style = sample(c, 50, 0.0);
        let render = sample(c, 23, 1.7);
        let sw = StyleReference::new(&style, c, p).expect("style").sliced_wasserstein(&render);
        let parts = SlicedBreakdown::new(&style, c, p).expect("style").parts(&render);
        let sum = (parts.mean.powi(2) + parts.shape.powi(2)).sqrt();
        assert!((sum - sw).abs() < 1e-5 * sw.max(1.0), "mean {} shape {} sw {sw}", parts.mean, parts.shape);
        assert!(parts.mean > 0.0 && parts.shape > 0.0);
    }

    #[test]
    fn a_shift_is_all_mean_and_a_scaling_leaves_the_unit_distance_at_zero() {
        let (c, p) = (3, 16);
        let style = sample(c, 40, 0.4);
        let b = SlicedBreakdown::new(&style, c, p).expect("style");
        let same = b.parts(&style);
        assert!(same.mean < 1e-6 && same.shape < 1e-6 && same.unit < 1e-6, "{same:?}");
        assert!((same.norm_ratio - 1.0).abs() < 1e-6);
        // Every position moved by the same vector: the shape is unchanged.
        let shifted: Vec<f32> = style.iter().enumerate().map(|(i, v)| v + if i < 40 { 0.5 } else { -0.25 }).collect();
        let s = b.parts(&shifted);
        assert!(s.shape < 1e-5 && s.mean > 0.05, "{s:?}");
        // Every vector twice as long: the directions, and so the unit distance, are unchanged.
        let doubled: Vec<f32> = style.iter().map(|v| 2.0 * v).collect();
        let d = b.parts(&doubled);
        assert!(d.unit < 1e-6 && d.mean + d.shape > 0.1, "{d:?}");
        assert!((d.norm_ratio - 2.0).abs() < 1e-5);
        assert_eq!(b.parts(&[]), SlicedParts::default());
        assert!(SlicedBreakdown::new(&style, c, 0).is_none() && SlicedBreakdown::new(&[], c, p).is_none());
    }
}
