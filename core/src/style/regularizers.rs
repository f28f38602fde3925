//! Geometry-phase regularisers: keep the stylised Gaussians near the
//! colour-matched ones (`G^c`) so that geometry changes stay local.
//!
//! - Parameter terms: the plain L2 norm `‖x − x^c‖₂` over all Gaussians (not
//!   squared), gradient `(x − x^c)/‖x − x^c‖`, taken as 0 where the norm is 0
//!   (the first steps, when nothing has moved yet).
//!   [`ParamRegulariser::MeanSquare`](super::config::ParamRegulariser) uses
//!   `mean_i ‖x_i − x_i^c‖²` instead, gradient `2(x − x^c)/n` (not in the paper).
//! - Depth term: `mean|D − D^c|` over the inverse-depth maps, subgradient
//!   `sign(D − D^c)/n` (0 where they are equal).

use rayon::prelude::*;

/// `‖x − x_ref‖₂` over a flat parameter array and its gradient w.r.t. `x`.
pub fn l2_distance(x: &[f32], x_ref: &[f32]) -> (f32, Vec<f32>) {
    assert_eq!(x.len(), x_ref.len(), "l2_distance: sizes differ");
    let norm = squared_distance(x, x_ref).sqrt();
    if norm == 0.0 {
        return (0.0, vec![0.0; x.len()]);
    }
    let inv = (1.0 / norm) as f32;
    (norm as f32, scaled_difference(x, x_ref, inv))
}

/// `(1/n)·Σ_i ‖x_i − x_ref,i‖²` over `n` Gaussians of `components` values each
/// (the mean over Gaussians of the squared deviation) and its gradient
/// `2(x − x_ref)/n`.
pub fn mean_square_distance(x: &[f32], x_ref: &[f32], components: usize) -> (f32, Vec<f32>) {
    assert_eq!(x.len(), x_ref.len(), "mean_square_distance: sizes differ");
    let n = (x.len() / components.max(1)).max(1) as f64;
    let sq = squared_distance(x, x_ref);
    let k = (2.0 / n) as f32;
    ((sq / n) as f32, scaled_difference(x, x_ref, k))
}

/// Values summed per task, in order, then the tasks' sums in order: the
/// same total whatever the number of threads.
const CHUNK: usize = 1 << 15;

/// `Σ (x − x_ref)²` in f64, over fixed chunks in parallel (a 2M-Gaussian
/// scene's 8M geometry values a step).
fn squared_distance(x: &[f32], x_ref: &[f32]) -> f64 {
    let parts: Vec<f64> = x
        .par_chunks(CHUNK)
        .zip(x_ref.par_chunks(CHUNK))
        .map(|(x, r)| x.iter().zip(r).map(|(&a, &b)| f64::from(a - b) * f64::from(a - b)).sum::<f64>())
        .collect();
    parts.iter().sum()
}

/// `k·(x − x_ref)`, element by element in parallel.
fn scaled_difference(x: &[f32], x_ref: &[f32], k: f32) -> Vec<f32> {
    let mut out = Vec::new();
    x.par_iter().zip(x_ref).with_min_len(CHUNK).map(|(&a, &b)| (a - b) * k).collect_into_vec(&mut out);
    out
}

/// `mean|d − d_ref|` and its subgradient w.r.t. `d`.
pub fn depth_l1(d: &[f32], d_ref: &[f32]) -> (f32, Vec<f32>) {
    assert_eq!(d.len(), d_ref.len(), "depth_l1: sizes differ");
    let n = d.len().max(1) as f64;
    let sum: f64 = d.iter().zip(d_ref).map(|(&a, &b)| f64::from((a - b).abs())).sum();
    let k = (1.0 / n) as f32;
    let grad = d
        .iter()
        .zip(d_ref)
        .map(|(&a, &b)| {
            if a > b {
                k
            } else if a < b {
                -k
            } else {
                0.0
            }
        })
        .collect();
    ((sum / n) as f32, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn l2_value_gradient_and_zero() {
        let (l, g) = l2_distance(&[3.0, 4.0], &[0.0, 0.0]);
        assert!((l - 5.0).abs() < 1e-6);
        assert!((g[0] - 0.6).abs() < 1e-6 && (g[1] - 0.8).abs() < 1e-6);
        let (l0, g0) = l2_distance(&[1.0, 2.0], &[1.0, 2.0]);
        assert_eq!(l0, 0.0);
        assert!(g0.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn mean_square_value_and_gradient() {
        // Two Gaussians of two components: deviations (3, 4) and (0, 0).
        let (l, g) = mean_square_distance(&[3.0, 4.0, 1.0, 1.0], &[0.0, 0.0, 1.0, 1.0], 2);
        assert!((l - 12.5).abs() < 1e-6);
        assert_eq!(g, vec![3.0, 4.0, 0.0, 0.0]);
    }

    #[test]
    fn depth_l1_subgradient() {
        let (l, g) = depth_l1(&[1.0, 0.0, 0.5, 0.2], &[0.0, 1.0, 0.5, 0.1]);
        assert!((l - (1.0 + 1.0 + 0.0 + 0.1) / 4.0).abs() < 1e-6);
        assert_eq!(g, vec![0.25, -0.25, 0.0, 0.25]);
    }
}
