//! Style distances between the VGG relu3 features of a render and those of the
//! style image.
//!
//! Each measure looks at a different property of the feature distribution, so
//! a report shows several: the Gram matrix and the mean–std pair are the
//! second- and first-order statistics classic style losses match, the sliced
//! Wasserstein distance compares the whole distribution, and the
//! nearest-neighbour distance is what the GCFM loss optimises. All take feature
//! maps laid out CHW (`channels × positions`, any number of positions each) and
//! are in the units of the features (VGG activations) unless said otherwise.
//! Lower is closer to the style everywhere; identical maps give 0.

use rayon::prelude::*;

use crate::stats::quantile;
use crate::vision::matmul;

/// The style side of every distance below, computed once: a study measures
/// many renders against one style image, and the style's Gram matrix, its
/// sorted projections and its normalised features are the expensive part.
pub struct StyleReference {
    channels: usize,
    positions: usize,
    /// Per channel `(mean, population std)`.
    moments: Vec<(f64, f64)>,
    /// `G = F Fᵀ / N`, `C × C`.
    gram: Vec<f64>,
    nearest: NearestStyle,
    /// Projection directions, `P × C`, and the sorted projections of the style, one row per direction.
    directions: Vec<f32>,
    sorted: Vec<Vec<f64>>,
}

impl StyleReference {
    /// The statistics of the CHW style features `b` (`channels` channels) with
    /// `projections` sliced-Wasserstein directions; `None` when `b` is empty or `channels` is 0.
    pub fn new(b: &[f32], channels: usize, projections: usize) -> Option<Self> {
        if channels == 0 || b.len() < channels {
            return None;
        }
        let n = b.len() / channels;
        let b = &b[..n * channels];
        let directions = projection_directions(channels, projections);
        let sorted = sorted_projections(&directions, projections, b, channels);
        Some(Self {
            channels,
            positions: n,
            moments: moments(b, channels),
            gram: gram_matrix(b, channels),
            nearest: NearestStyle { channels, positions: n, unit: unit_columns(b, channels) },
            directions,
            sorted,
        })
    }

    fn positions_of(&self, a: &[f32]) -> Option<usize> {
        (a.len() >= self.channels).then_some(a.len() / self.channels)
    }

    /// [`mean_std_distance`] of `a` to the style.
    pub fn mean_std_distance(&self, a: &[f32]) -> f32 {
        if self.positions_of(a).is_none() {
            return 0.0;
        }
        let d: f64 = moments(a, self.channels)
            .iter()
            .zip(&self.moments)
            .map(|((ma, sa), (mb, sb))| (ma - mb).abs() + (sa - sb).abs())
            .sum();
        (d / self.channels as f64) as f32
    }

    /// [`gram_distance`] of `a` to the style.
    pub fn gram_distance(&self, a: &[f32]) -> f32 {
        if self.positions_of(a).is_none() {
            return 0.0;
        }
        let ga = gram_matrix(a, self.channels);
        let sq: f64 = ga.iter().zip(&self.gram).map(|(x, y)| (x - y).powi(2)).sum();
        (sq.sqrt() / self.channels as f64) as f32
    }

    /// [`sliced_wasserstein_distance`] of `a` to the style.
    pub fn sliced_wasserstein(&self, a: &[f32]) -> f32 {
        let Some(na) = self.positions_of(a) else { return 0.0 };
        let projections = self.sorted.len();
        if projections == 0 {
            return 0.0;
        }
        let pa = sorted_projections(&self.directions, projections, &a[..na * self.channels], self.channels);
        let m = na.max(self.positions);
        let total: f64 = pa
            .par_iter()
            .zip(&self.sorted)
            .map(|(pa, pb)| {
                (0..m)
                    .map(|k| {
                        let q = (k as f64 + 0.5) / m as f64;
                        (quantile(pa, q) - quantile(pb, q)).powi(2)
                    })
                    .sum::<f64>()
                    / m as f64
            })
            .sum();
        (total / projections as f64).sqrt() as f32
    }

    /// [`nn_cosine_distance`] of `a` to the style.
    pub fn nn_cosine(&self, a: &[f32]) -> f32 {
        self.nearest.nn_cosine(a)
    }

    /// The nearest-neighbour side alone (its unit style features).
    pub fn nearest(&self) -> &NearestStyle {
        &self.nearest
    }
}

/// Unit-length style features, for nearest-neighbour cosines only (cheap to
/// build for wide joint features, where a Gram matrix would not be).
pub struct NearestStyle {
    channels: usize,
    positions: usize,
    /// Unit-length features, `C × N` (zero columns stay zero).
    unit: Vec<f32>,
}

impl NearestStyle {
    /// The CHW style features `b` of `channels` channels, each position scaled
    /// to unit length; `None` when `b` is empty or `channels` is 0.
    pub fn new(b: &[f32], channels: usize) -> Option<Self> {
        if channels == 0 || b.len() < channels {
            return None;
        }
        let n = b.len() / channels;
        Some(Self { channels, positions: n, unit: unit_columns(&b[..n * channels], channels) })
    }

    /// Channels of a position.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Style positions.
    pub fn positions(&self) -> usize {
        self.positions
    }

    /// The unit-length style features, `C × N` CHW.
    pub fn unit(&self) -> &[f32] {
        &self.unit
    }

    /// [`NearestStyle::nn_cosine`] with the nearest style position of each of
    /// `a`'s positions given (`nearest[x] < positions`, found elsewhere: a
    /// GPU's search); only the cosines of those pairs are computed.
    ///
    /// # Panics
    /// When `nearest` has fewer entries than `a` positions or one is out of range.
    pub fn nn_cosine_at(&self, a: &[f32], nearest: &[u32]) -> f32 {
        if a.len() < self.channels {
            return 0.0;
        }
        let (c, na, nb) = (self.channels, a.len() / self.channels, self.positions);
        let unit_a = unit_columns(&a[..na * c], c);
        let total: f64 = nearest[..na]
            .par_iter()
            .enumerate()
            .map(|(x, &y)| {
                let cos: f32 = (0..c).map(|ch| unit_a[ch * na + x] * self.unit[ch * nb + y as usize]).sum();
                f64::from(1.0 - cos)
            })
            .sum();
        (total / na as f64) as f32
    }

    /// [`nn_cosine_distance`] of `a` to the style.
    pub fn nn_cosine(&self, a: &[f32]) -> f32 {
        if a.len() < self.channels {
            return 0.0;
        }
        let na = a.len() / self.channels;
        let (c, nb) = (self.channels, self.positions);
        // Cosines of every rendered position against every style position:
        // (N_a × C) · (C × N_b) on unit columns, in bands of rows to bound memory.
        let unit_a = unit_columns(&a[..na * c], c);
        let mut at = vec![0.0f32; na * c];
        for ch in 0..c {
            for (p, &v) in unit_a[ch * na..(ch + 1) * na].iter().enumerate() {
                at[p * c + ch] = v;
            }
        }
        let band = (1 << 22) / nb.max(1);
        let band = band.clamp(1, na);
        let mut total = 0.0f64;
        let mut scores = vec![0.0f32; band * nb];
        for r0 in (0..na).step_by(band) {
            let rows = band.min(na - r0);
            matmul(&mut scores[..rows * nb], nb, (&at[r0 * c..], c, 1), (&self.unit, nb), (rows, nb, c), false);
            total += scores[..rows * nb]
                .par_chunks(nb)
                .map(|row| f64::from(1.0 - row.iter().copied().fold(f32::NEG_INFINITY, f32::max)))
                .sum::<f64>();
        }
        (total / na as f64) as f32
    }
}

/// Per-channel mean and population standard deviation of a CHW map.
fn moments(x: &[f32], channels: usize) -> Vec<(f64, f64)> {
    let n = x.len() / channels;
    (0..channels)
        .map(|c| {
            let s = &x[c * n..(c + 1) * n];
            let mean = s.iter().map(|&v| f64::from(v)).sum::<f64>() / n as f64;
            let var = s.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>() / n as f64;
            (mean, var.sqrt())
        })
        .collect()
}

/// The CHW map with every position's feature vector scaled to unit length.
pub(super) fn unit_columns(x: &[f32], channels: usize) -> Vec<f32> {
    let n = x.len() / channels;
    let mut norm = vec![0.0f32; n];
    for c in 0..channels {
        for (acc, &v) in norm.iter_mut().zip(&x[c * n..(c + 1) * n]) {
            *acc += v * v;
        }
    }
    let inv: Vec<f32> = norm.iter().map(|v| if *v > 0.0 { 1.0 / v.sqrt() } else { 0.0 }).collect();
    let mut out = x[..n * channels].to_vec();
    for c in 0..channels {
        for (v, s) in out[c * n..(c + 1) * n].iter_mut().zip(&inv) {
            *v *= s;
        }
    }
    out
}

/// Projections of every position of the CHW map `x` on each of the
/// `projections` directions (`P × C`), one gemm, each row sorted.
pub(super) fn sorted_projections(directions: &[f32], projections: usize, x: &[f32], channels: usize) -> Vec<Vec<f64>> {
    let n = x.len() / channels;
    let mut p = vec![0.0f32; projections * n];
    matmul(&mut p, n, (directions, channels, 1), (x, n), (projections, n, channels), false);
    p.par_chunks(n.max(1))
        .map(|row| {
            let mut r: Vec<f64> = row.iter().map(|&v| f64::from(v)).collect();
            r.sort_by(f64::total_cmp);
            r
        })
        .collect()
}

/// Mean–std distance (as in AdaIN's style loss):
/// `(1/C) Σ_c |μ_c(a) − μ_c(b)| + |σ_c(a) − σ_c(b)|` for CHW feature maps with
/// `channels` channels (population standard deviation). Ignores spatial layout.
/// 0 when either map is empty or `channels` is 0.
pub fn mean_std_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    StyleReference::new(b, channels, 0).map_or(0.0, |r| r.mean_std_distance(a))
}

/// Nearest-neighbour cosine distance `(1/N) Σ_x min_y (1 − cos(a(x), b(y)))`
/// for CHW feature maps of `channels` channels: how well every rendered feature
/// finds a close style feature (unitless, in `[0, 2]`); all cosines by one
/// matrix product of unit-length features. A zero feature vector has cosine 0
/// with everything. 0 when either map is empty.
pub fn nn_cosine_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    NearestStyle::new(b, channels).map_or(0.0, |r| r.nn_cosine(a))
}

/// The normalised Gram matrix `G = F Fᵀ / N` of a CHW feature map (`C × C`,
/// row-major, `f64`, the product itself in `f32` by gemm), `N` the number of
/// positions. Dividing by `N` makes maps of different sizes comparable (a
/// render at 1/4 resolution against a style image of another size). Empty when
/// `channels` is 0 or there are no positions.
pub fn gram_matrix(f: &[f32], channels: usize) -> Vec<f64> {
    if channels == 0 || f.len() < channels {
        return Vec::new();
    }
    let n = f.len() / channels;
    // One f32 matrix product F·Fᵀ (gemm); F transposed to N × C for the right operand.
    let mut ft = vec![0.0f32; n * channels];
    for c in 0..channels {
        for (p, &v) in f[c * n..(c + 1) * n].iter().enumerate() {
            ft[p * channels + c] = v;
        }
    }
    let mut g = vec![0.0f32; channels * channels];
    matmul(&mut g, channels, (f, n, 1), (&ft, channels), (channels, channels, n), false);
    g.into_iter().map(|v| f64::from(v) / n as f64).collect()
}

/// Gram-matrix distance `‖G(a) − G(b)‖_F / C` with `G = F Fᵀ / N` (see
/// [`gram_matrix`]): the root-mean-square difference of the `C²` Gram entries,
/// in squared feature units. 0 when either map is empty.
pub fn gram_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    StyleReference::new(b, channels, 0).map_or(0.0, |r| r.gram_distance(a))
}

/// The seed of the projection directions of [`sliced_wasserstein_distance`]:
/// fixed, so the same inputs always give the same distance.
pub const SLICED_WASSERSTEIN_SEED: u64 = 0x5eed_6a57_0001;

/// Sliced Wasserstein-2 distance between the feature distributions of two CHW
/// maps (each position a point in `R^C`):
/// `SW = sqrt( (1/P) Σ_p (1/M) Σ_k (qa_p(k) − qb_p(k))² )`,
/// over `P = projections` random unit directions `θ_p` (Gaussian, normalised,
/// drawn from the fixed [`SLICED_WASSERSTEIN_SEED`]), where `qa_p(k)` is the
/// `(k + ½)/M` quantile of `{θ_p · a(x)}` (sorted projections, linearly
/// interpolated) and `M = max(N_a, N_b)`. Compares whole distributions, not
/// just their first two moments; in feature units. More projections lower the
/// variance of the estimate (64–256 are usual for 768 channels). 0 when either
/// map is empty or `projections` is 0.
pub fn sliced_wasserstein_distance(a: &[f32], b: &[f32], channels: usize, projections: usize) -> f32 {
    StyleReference::new(b, channels, projections).map_or(0.0, |r| r.sliced_wasserstein(a))
}

/// `projections` unit directions in `R^channels` (`P × C`, row-major):
/// Gaussian draws from the fixed [`SLICED_WASSERSTEIN_SEED`], normalised.
pub(super) fn projection_directions(channels: usize, projections: usize) -> Vec<f32> {
    let mut rng = SplitMix(SLICED_WASSERSTEIN_SEED);
    (0..projections)
        .flat_map(|_| {
            let v: Vec<f64> = (0..channels).map(|_| rng.gaussian()).collect();
            let len = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
            v.into_iter().map(move |x| (x / len) as f32)
        })
        .collect()
}

/// SplitMix64, enough for reproducible projection directions.
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// A standard normal sample (Box–Muller).
    fn gaussian(&mut self) -> f64 {
        let (u, v) = (self.next_f64(), self.next_f64());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(c: usize, n: usize, phase: f32) -> Vec<f32> {
        (0..c * n).map(|i| (i as f32 * 0.37 + phase).sin()).collect()
    }

    #[test]
    fn distances_are_zero_for_identical_maps_and_grow_with_difference() {
        let a = sample(2, 6, 0.0);
        assert!(mean_std_distance(&a, &a, 2) < 1e-6);
        assert!(nn_cosine_distance(&a, &a, 2) < 1e-5);
        assert!(gram_distance(&a, &a, 2) < 1e-9);
        assert!(sliced_wasserstein_distance(&a, &a, 2, 16) < 1e-6);
        let b: Vec<f32> = a.iter().map(|v| 2.0 * v + 1.0).collect();
        assert!(mean_std_distance(&a, &b, 2) > 0.5);
        assert!(gram_distance(&a, &b, 2) > 0.5);
        assert!(sliced_wasserstein_distance(&a, &b, 2, 16) > 0.5);
    }

    #[test]
    fn gram_distance_matches_a_hand_computed_case() {
        // a: channel 0 = [1, 1], channel 1 = [0, 0] → G = [[1, 0], [0, 0]].
        // b: channel 0 = [0, 0], channel 1 = [2, 2] → G = [[0, 0], [0, 4]].
        // ‖G_a − G_b‖_F = sqrt(1 + 16), divided by C = 2.
        let a = [1.0, 1.0, 0.0, 0.0];
        let b = [0.0, 0.0, 2.0, 2.0];
        assert!((gram_distance(&a, &b, 2) - 17f32.sqrt() / 2.0).abs() < 1e-6);
        // The normalisation by N makes a map and its tiling (same distribution, more positions) equal.
        let tiled = [1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
        assert!(gram_distance(&a, &tiled, 2) < 1e-9);
        // Off-diagonal entries: channels [1, 2, 3, 4, 5] and [2, 0, 1, 1, 3] over 5 positions.
        let g = gram_matrix(&[1.0, 2.0, 3.0, 4.0, 5.0, 2.0, 0.0, 1.0, 1.0, 3.0], 2);
        assert_eq!(g, vec![55.0 / 5.0, 24.0 / 5.0, 24.0 / 5.0, 15.0 / 5.0]);
    }

    #[test]
    fn sliced_wasserstein_of_a_shift_is_the_shift_length_projected() {
        // Shifting every point by s moves every 1-D projection by θ·s, so
        // SW² = mean_p (θ_p·s)², which for s along one axis of C = 1 is s².
        let a: Vec<f32> = (0..50).map(|i| i as f32 * 0.1).collect();
        let b: Vec<f32> = a.iter().map(|v| v + 0.75).collect();
        assert!((sliced_wasserstein_distance(&a, &b, 1, 8) - 0.75).abs() < 1e-5);
        // Order of positions does not matter (it compares distributions), and sample counts may differ.
        let rev: Vec<f32> = a.iter().rev().copied().collect();
        assert!(sliced_wasserstein_distance(&a, &rev, 1, 8) < 1e-6);
        let c = sample(3, 40, 0.3);
        let d = sample(3, 25, 1.1);
        let once = sliced_wasserstein_distance(&c, &d, 3, 32);
        assert_eq!(once, sliced_wasserstein_distance(&c, &d, 3, 32), "fixed seed: deterministic");
        assert!(once > 0.0);
    }

    #[test]
    fn nn_cosine_matches_a_brute_force_search() {
        let (c, na, nb) = (5, 37, 23);
        let a = sample(c, na, 0.2);
        let b = sample(c, nb, 2.9);
        let col = |x: &[f32], n: usize, i: usize| (0..c).map(|k| x[k * n + i]).collect::<Vec<f32>>();
        let cos = |u: &[f32], v: &[f32]| {
            let d: f32 = u.iter().zip(v).map(|(x, y)| x * y).sum();
            d / (u.iter().map(|x| x * x).sum::<f32>().sqrt() * v.iter().map(|x| x * x).sum::<f32>().sqrt())
        };
        let brute: f32 = (0..na)
            .map(|i| {
                let best = (0..nb).map(|j| cos(&col(&a, na, i), &col(&b, nb, j))).fold(f32::NEG_INFINITY, f32::max);
                1.0 - best
            })
            .sum::<f32>()
            / na as f32;
        assert!((nn_cosine_distance(&a, &b, c) - brute).abs() < 1e-5, "{} vs {brute}", nn_cosine_distance(&a, &b, c));
        // One reference answers every measure as the free functions do.
        let r = StyleReference::new(&b, c, 16).expect("reference");
        assert_eq!(r.nn_cosine(&a), nn_cosine_distance(&a, &b, c));
        assert_eq!(r.gram_distance(&a), gram_distance(&a, &b, c));
        assert_eq!(r.sliced_wasserstein(&a), sliced_wasserstein_distance(&a, &b, c, 16));
        assert_eq!(r.mean_std_distance(&a), mean_std_distance(&a, &b, c));
    }

    #[test]
    fn degenerate_inputs_give_zero() {
        let a = sample(2, 4, 0.0);
        for f in [mean_std_distance, nn_cosine_distance, gram_distance] {
            assert_eq!(f(&[], &a, 2), 0.0);
            assert_eq!(f(&a, &[], 2), 0.0);
            assert_eq!(f(&a, &a, 0), 0.0);
        }
        assert_eq!(sliced_wasserstein_distance(&a, &a, 2, 0), 0.0);
        assert_eq!(sliced_wasserstein_distance(&[], &a, 2, 4), 0.0);
    }
}
