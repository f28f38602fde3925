//! Axis ranges and their tick values: "nice" 1-2-5 steps on linear axes,
//! decades (or 1-2-5 multiples within a decade or two) on log axes, and labels
//! as short as the step allows. Kept apart from the drawing so the choices can
//! be tested as plain numbers.

/// One axis's range in the drawn coordinate: the value, or its log10 on a log axis.
#[derive(Clone, Copy, Debug)]
pub(super) struct Scale {
    lo: f64,
    hi: f64,
    log: bool,
}

impl Scale {
    /// Whether `v` can be drawn on this kind of axis.
    pub(super) fn accepts(log: bool, v: f64) -> bool {
        v.is_finite() && (!log || v > 0.0)
    }

    /// The range of the (accepted) `values` with a 5% margin; a default range
    /// without values and a padded one around a single value.
    pub(super) fn fit(values: &[f64], log: bool) -> Self {
        let (lo, hi) = values
            .iter()
            .map(|&v| if log { v.log10() } else { v })
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| (lo.min(t), hi.max(t)));
        let (lo, hi) = if lo > hi {
            (0.0, 1.0)
        } else if hi - lo <= 1e-9 * lo.abs().max(1.0) {
            let pad = if log { 0.5 } else { (lo.abs() * 0.1).max(0.5) };
            (lo - pad, hi + pad)
        } else {
            let pad = 0.05 * (hi - lo);
            (lo - pad, hi + pad)
        };
        Self { lo, hi, log }
    }

    /// Where `v` falls between the low (0) and high (1) end.
    pub(super) fn frac(&self, v: f64) -> f64 {
        let t = if self.log { v.log10() } else { v };
        (t - self.lo) / (self.hi - self.lo)
    }

    /// About `target` labelled tick values inside the range.
    pub(super) fn ticks(&self, target: usize) -> Vec<(f64, String)> {
        if self.log { log_ticks(self.lo, self.hi, target) } else { linear_ticks(self.lo, self.hi, target) }
    }

    /// Unlabelled grid values between the decade ticks of a log axis spanning few decades.
    pub(super) fn minor(&self, major: &[(f64, String)]) -> Vec<f64> {
        if !self.log || self.hi - self.lo > 6.0 {
            return Vec::new();
        }
        decade_multiples(self.lo, self.hi, &[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
            .into_iter()
            .filter(|v| major.iter().all(|(m, _)| (m - v).abs() > 1e-9 * v))
            .collect()
    }
}

/// The 1, 2 or 5 times a power of ten nearest to `raw` (on a log scale).
fn nice_step(raw: f64) -> f64 {
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let nice = if norm < 2f64.sqrt() {
        1.0
    } else if norm < 10f64.sqrt() {
        2.0
    } else if norm < 50f64.sqrt() {
        5.0
    } else {
        10.0
    };
    nice * mag
}

/// Multiples of a 1-2-5 step inside `[lo, hi]`, about `target` of them, with labels.
fn linear_ticks(lo: f64, hi: f64, target: usize) -> Vec<(f64, String)> {
    let step = nice_step((hi - lo) / target.max(1) as f64);
    let (first, last) = ((lo / step - 1e-9).ceil(), (hi / step + 1e-9).floor());
    // Also rejects NaN from a degenerate step.
    if !(step.is_finite() && step > 0.0 && last - first < 1000.0) {
        return Vec::new();
    }
    (first as i64..=last as i64)
        .map(|i| {
            let v = i as f64 * step;
            (v, linear_label(v, step))
        })
        .collect()
}

/// A tick label with as many decimals as the step needs; scientific for very
/// large values or very small steps.
fn linear_label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let step_exp = step.log10().floor();
    // Fixed decimals while they stay short ("0.19995"); exponents only for huge or tiny values.
    if v.abs() >= 1e6 || (step < 1e-4 && v.abs() < 1e-2) {
        let digits = (v.abs().log10().floor() - step_exp).clamp(0.0, 6.0) as usize;
        format!("{v:.digits$e}")
    } else {
        let decimals = (-step_exp).clamp(0.0, 10.0) as usize;
        format!("{v:.decimals$}")
    }
}

/// The value `m·10^k` labelled compactly: "0.02", "500", "1e6".
fn log_label(v: f64) -> String {
    if (1e-4..1e6).contains(&v) {
        let decimals = (-(v.log10() + 1e-9).floor()).max(0.0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:e}")
    }
}

/// The values `m·10^k` for the given multipliers whose log10 lies in `[lo, hi]`.
fn decade_multiples(lo: f64, hi: f64, mults: &[f64]) -> Vec<f64> {
    let (k0, k1) = (lo.floor(), hi.floor());
    if !(k1 - k0).is_finite() || k1 - k0 >= 400.0 {
        return Vec::new();
    }
    (k0 as i32..=k1 as i32)
        .flat_map(|k| mults.iter().map(move |m| m * 10f64.powi(k)))
        .filter(|v| (lo - 1e-9..=hi + 1e-9).contains(&v.log10()))
        .collect()
}

/// Ticks of a log axis whose drawn range is `[lo, hi]` (log10 of the values):
/// decades (every n-th when there are many), else 1-2-5 or 1…9 multiples within
/// a decade or two, else plain linear ticks when the range is narrower still.
fn log_ticks(lo: f64, hi: f64, target: usize) -> Vec<(f64, String)> {
    let target = target.max(2);
    let decades = decade_multiples(lo, hi, &[1.0]);
    let values = if decades.len() >= 3 {
        // Every n-th decade, on exponents that are multiples of n where that leaves two.
        let every = decades.len().div_ceil(target) as i32;
        let aligned: Vec<f64> =
            decades.iter().copied().filter(|v| (v.log10().round() as i32).rem_euclid(every) == 0).collect();
        if aligned.len() >= 2 { aligned } else { decades.into_iter().step_by(every as usize).collect() }
    } else {
        let fine = decade_multiples(lo, hi, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        let mid = decade_multiples(lo, hi, &[1.0, 2.0, 5.0]);
        if (2..=target).contains(&fine.len()) {
            fine
        } else if (2..=target).contains(&mid.len()) {
            mid
        } else if decades.len() == 2 {
            decades
        } else {
            let linear = linear_ticks(10f64.powf(lo), 10f64.powf(hi), target);
            return linear.into_iter().filter(|(v, _)| *v > 0.0).collect();
        }
    };
    values.into_iter().map(|v| (v, log_label(v))).collect()
}

/// The densest ticks up to `target` whose labels, `extent` pixels long along an
/// axis of `len` pixels, keep at least 10 pixels apart.
pub(super) fn fit_ticks(scale: &Scale, len: f64, target: usize, extent: impl Fn(&str) -> f64) -> Vec<(f64, String)> {
    let mut target = target.max(2);
    loop {
        let ticks = scale.ticks(target);
        let fits = ticks.windows(2).all(|t| {
            let gap = (scale.frac(t[1].0) - scale.frac(t[0].0)).abs() * len;
            gap >= (extent(&t[0].1) + extent(&t[1].1)) / 2.0 + 10.0
        });
        if fits || target == 2 {
            return ticks;
        }
        target -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(ticks: &[(f64, String)]) -> Vec<&str> {
        ticks.iter().map(|t| t.1.as_str()).collect()
    }

    #[test]
    fn linear_ticks_are_nice() {
        assert_eq!(labels(&linear_ticks(0.0, 1.0, 5)), ["0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        assert_eq!(labels(&linear_ticks(-0.3, 97.0, 5)), ["0", "20", "40", "60", "80"]);
        assert_eq!(labels(&linear_ticks(-3.2, 7.9, 6)), ["-2", "0", "2", "4", "6"]);
        assert_eq!(labels(&linear_ticks(0.9995, 1.0005, 4)), ["0.9996", "0.9998", "1.0000", "1.0002", "1.0004"]);
        assert_eq!(labels(&linear_ticks(1e6, 5e6, 4)), ["1e6", "2e6", "3e6", "4e6", "5e6"]);
        assert!(linear_ticks(0.0, f64::INFINITY, 5).is_empty());
        assert!(linear_ticks(1.0, 1.0, 5).is_empty() || linear_ticks(1.0, 1.0, 5).len() == 1);
    }

    #[test]
    fn log_ticks_use_decades_then_multiples() {
        assert_eq!(labels(&log_ticks(-0.1, 3.1, 8)), ["1", "10", "100", "1000"]);
        assert_eq!(labels(&log_ticks(-6.0, 6.0, 4)), ["0.0001", "1", "10000"]);
        assert_eq!(labels(&log_ticks(-0.1, 2.1, 8)), ["1", "10", "100"]);
        assert_eq!(labels(&log_ticks(0.1, 1.9, 8)), ["2", "5", "10", "20", "50"]);
        assert_eq!(labels(&log_ticks(3f64.log10(), 8f64.log10(), 8)), ["3", "4", "5", "6", "7", "8"]);
        assert_eq!(labels(&log_ticks(-2.4, -1.1, 8)), ["0.005", "0.01", "0.02", "0.05"]);
        let narrow = log_ticks(3.1f64.log10(), 3.4f64.log10(), 4);
        assert_eq!(labels(&narrow), ["3.1", "3.2", "3.3", "3.4"]);
        let scale = Scale::fit(&[1.0, 1000.0], true);
        assert_eq!(scale.minor(&scale.ticks(8)).len(), 8 * 3 + 2, "2…9 in three decades, 0.8 and 0.9 in the margin");
    }

    #[test]
    fn scales_pad_single_values_and_default_when_empty() {
        let one = Scale::fit(&[5.0], false);
        assert!(one.lo < 5.0 && one.hi > 5.0);
        let zero = Scale::fit(&[0.0, 0.0], false);
        assert!(zero.lo < 0.0 && zero.hi > 0.0);
        let log = Scale::fit(&[3.0], true);
        assert!(log.frac(3.0) > 0.0 && log.frac(3.0) < 1.0);
        let empty = Scale::fit(&[], false);
        assert_eq!((empty.lo, empty.hi), (0.0, 1.0));
    }
}
