//! Order statistics the losses, the measures, the studies and the benchmarks
//! share: one quantile convention and the median it gives.
//!
//! The quantile interpolates linearly between samples placed at `(i + ½)/n`
//! (Hazen's plotting positions), so the median of an even count is the mean
//! of the two middle values. It is computed in the samples' own type: the
//! sliced loss's `f32` quantiles are bit for bit what they were.

use std::ops::{Add, Mul, Sub};

/// `f32` or `f64`: what [`quantile`] and [`median`] compute in.
pub trait Real: Copy + PartialOrd + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> {
    /// `n` in this type (exact below 2²⁴ for `f32`).
    fn of_count(n: usize) -> Self;
    /// `x`, rounded in this type.
    fn of(x: f64) -> Self;
    /// The largest whole value not above this one.
    fn floor(self) -> Self;
    /// The index of a non-negative whole value.
    fn index(self) -> usize;
    /// Neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// The IEEE total order (NaN after every number).
    fn total_cmp(&self, other: &Self) -> std::cmp::Ordering;
}

macro_rules! real {
    ($t:ty) => {
        impl Real for $t {
            fn of_count(n: usize) -> Self {
                n as $t
            }
            fn of(x: f64) -> Self {
                x as $t
            }
            fn floor(self) -> Self {
                <$t>::floor(self)
            }
            fn index(self) -> usize {
                self as usize
            }
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            fn total_cmp(&self, other: &Self) -> std::cmp::Ordering {
                <$t>::total_cmp(self, other)
            }
        }
    };
}
real!(f32);
real!(f64);

/// The `q` quantile of sorted, non-empty `s`, linearly interpolated between
/// sample `i` at position `(i + ½)/n`; below the first position the first
/// sample, past the last the last.
pub fn quantile<T: Real>(s: &[T], q: T) -> T {
    let last = T::of_count(s.len() - 1);
    let x = q * T::of_count(s.len()) - T::of(0.5);
    let x = if x < T::of(0.0) {
        T::of(0.0)
    } else if x > last {
        last
    } else {
        x
    };
    let i = x.floor().index();
    let j = (i + 1).min(s.len() - 1);
    let t = x - T::of_count(i);
    s[i] * (T::of(1.0) - t) + s[j] * t
}

/// The median of the finite values of `v` (the mean of the middle two for an
/// even count, [`quantile`]'s `0.5`); `None` when none is finite. A selection,
/// not a sort: linear in a scene's Gaussians.
pub fn median<T: Real>(mut v: Vec<T>) -> Option<T> {
    v.retain(|x| x.is_finite());
    let n = v.len();
    if n == 0 {
        return None;
    }
    let (below, mid, _) = v.select_nth_unstable_by(n / 2, T::total_cmp);
    let mid = *mid;
    if n % 2 == 1 {
        return Some(mid);
    }
    let lower = below.iter().copied().max_by(T::total_cmp)?;
    let half = T::of(0.5);
    Some(lower * half + mid * half)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_the_samples_midpoints() {
        let s = [1.0f64, 2.0, 4.0, 8.0];
        // Positions 1/8, 3/8, 5/8, 7/8.
        assert_eq!(quantile(&s, 0.125), 1.0);
        assert_eq!(quantile(&s, 0.25), 1.5);
        assert_eq!(quantile(&s, 0.5), 3.0);
        assert_eq!(quantile(&s, 0.875), 8.0);
        assert_eq!(quantile(&s, 0.0), 1.0);
        assert_eq!(quantile(&s, 1.0), 8.0);
        assert_eq!(quantile(&[5.0f32], 0.3), 5.0);
    }

    /// The `f32` quantile is the arithmetic the sliced loss had, to the bit.
    #[test]
    fn the_f32_quantile_computes_in_f32() {
        let mut s: Vec<f32> = (0..37).map(|i| (i as f32 * 0.731).sin()).collect();
        s.sort_by(f32::total_cmp);
        for k in 0..50 {
            let q = (k as f32 + 0.5) / 50.0;
            let x = (q * s.len() as f32 - 0.5).clamp(0.0, (s.len() - 1) as f32);
            let i = x.floor() as usize;
            let j = (i + 1).min(s.len() - 1);
            let t = x - i as f32;
            assert_eq!(quantile(&s, q).to_bits(), (s[i] * (1.0 - t) + s[j] * t).to_bits(), "q = {q}");
        }
    }

    #[test]
    fn the_median_skips_what_is_not_finite() {
        assert_eq!(median(vec![3.0f32, f32::NAN, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0f64, 1.0, f64::INFINITY, 3.0, 2.0]), Some(2.5));
        assert_eq!(median(vec![f32::NAN]), None);
        assert_eq!(median(Vec::<f64>::new()), None);
        // The selection gives the sorted quantile's value.
        for n in 1..40 {
            let v: Vec<f64> = (0..n).map(|i| ((i * 7919) % 101) as f64 * 0.37).collect();
            let mut s = v.clone();
            s.sort_by(f64::total_cmp);
            assert_eq!(median(v), Some(quantile(&s, 0.5)), "n = {n}");
        }
    }
}
