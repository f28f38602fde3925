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

/// Mean–std distance (as in AdaIN's style loss):
/// `(1/C) Σ_c |μ_c(a) − μ_c(b)| + |σ_c(a) − σ_c(b)|` for CHW feature maps with
/// `channels` channels (population standard deviation). Ignores spatial layout.
/// 0 when either map is empty or `channels` is 0.
pub fn mean_std_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    if channels == 0 || a.len() < channels || b.len() < channels {
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

/// Nearest-neighbour cosine distance `(1/N) Σ_x min_y (1 − cos(a(x), b(y)))`
/// for CHW feature maps of `channels` channels: how well every rendered feature
/// finds a close style feature (unitless, in `[0, 2]`). The nearest style
/// feature is found by the same tiled matrix products as the GCFM matching
/// (the other two modalities left empty, so the joint cosine is the cosine of
/// `a` and `b`). 0 when either map is empty.
pub fn nn_cosine_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    use crate::style::gcfm::{StyleFeatures, match_features};
    if channels == 0 || a.len() < channels || b.len() < channels {
        return 0.0;
    }
    let (na, nb) = (a.len() / channels, b.len() / channels);
    let (a, b) = (&a[..na * channels], &b[..nb * channels]);
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

/// The normalised Gram matrix `G = F Fᵀ / N` of a CHW feature map (`C × C`,
/// row-major, `f64`), `N` the number of positions. Dividing by `N` makes maps
/// of different sizes comparable (a render at 1/4 resolution against a style
/// image of another size). Empty when `channels` is 0 or there are no positions.
pub fn gram_matrix(f: &[f32], channels: usize) -> Vec<f64> {
    if channels == 0 || f.len() < channels {
        return Vec::new();
    }
    let n = f.len() / channels;
    // Upper triangle only (G is symmetric), four partial sums for throughput.
    let rows: Vec<Vec<f64>> = (0..channels)
        .into_par_iter()
        .map(|i| {
            let fi = &f[i * n..(i + 1) * n];
            (i..channels).map(|j| dot(fi, &f[j * n..(j + 1) * n]) / n as f64).collect()
        })
        .collect();
    let mut g = vec![0.0f64; channels * channels];
    for (i, row) in rows.iter().enumerate() {
        for (k, &v) in row.iter().enumerate() {
            g[i * channels + i + k] = v;
            g[(i + k) * channels + i] = v;
        }
    }
    g
}

/// `Σ x·y` in `f64`.
fn dot(x: &[f32], y: &[f32]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (xc, yc) = (x.chunks_exact(4), y.chunks_exact(4));
    let tail: f64 = xc.remainder().iter().zip(yc.remainder()).map(|(&a, &b)| f64::from(a) * f64::from(b)).sum();
    for (a, b) in xc.zip(yc) {
        for k in 0..4 {
            acc[k] += f64::from(a[k]) * f64::from(b[k]);
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// Gram-matrix distance `‖G(a) − G(b)‖_F / C` with `G = F Fᵀ / N` (see
/// [`gram_matrix`]): the root-mean-square difference of the `C²` Gram entries,
/// in squared feature units. 0 when either map is empty.
pub fn gram_distance(a: &[f32], b: &[f32], channels: usize) -> f32 {
    let (ga, gb) = (gram_matrix(a, channels), gram_matrix(b, channels));
    if ga.is_empty() || gb.is_empty() {
        return 0.0;
    }
    let sq: f64 = ga.iter().zip(&gb).map(|(x, y)| (x - y).powi(2)).sum();
    (sq.sqrt() / channels as f64) as f32
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
    if channels == 0 || projections == 0 || a.len() < channels || b.len() < channels {
        return 0.0;
    }
    let (na, nb) = (a.len() / channels, b.len() / channels);
    let m = na.max(nb);
    let mut rng = SplitMix(SLICED_WASSERSTEIN_SEED);
    let dirs: Vec<Vec<f64>> = (0..projections)
        .map(|_| {
            let v: Vec<f64> = (0..channels).map(|_| rng.gaussian()).collect();
            let len = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
            v.into_iter().map(|x| x / len).collect()
        })
        .collect();
    let project = |f: &[f32], n: usize, dir: &[f64]| {
        let mut p = vec![0.0f64; n];
        for (c, &w) in dir.iter().enumerate() {
            for (acc, &x) in p.iter_mut().zip(&f[c * n..(c + 1) * n]) {
                *acc += w * f64::from(x);
            }
        }
        p.sort_by(f64::total_cmp);
        p
    };
    let total: f64 = dirs
        .par_iter()
        .map(|dir| {
            let (pa, pb) = (project(a, na, dir), project(b, nb, dir));
            (0..m)
                .map(|k| {
                    (quantile(&pa, (k as f64 + 0.5) / m as f64) - quantile(&pb, (k as f64 + 0.5) / m as f64)).powi(2)
                })
                .sum::<f64>()
                / m as f64
        })
        .sum();
    (total / projections as f64).sqrt() as f32
}

/// The `q` quantile of sorted, non-empty `s`, linearly interpolated between
/// sample `i` at position `(i + ½)/n`.
fn quantile(s: &[f64], q: f64) -> f64 {
    let x = (q * s.len() as f64 - 0.5).clamp(0.0, (s.len() - 1) as f64);
    let i = x.floor() as usize;
    let j = (i + 1).min(s.len() - 1);
    let t = x - i as f64;
    s[i] * (1.0 - t) + s[j] * t
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
