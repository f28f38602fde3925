//! Wall time per stage of one depth forward pass, for `gast bench depth`.
//!
//! The network's cost is spread over a dozen kinds of layers (the backbone's
//! products and attention, the neck's convolutions, the resizes), and making
//! it fast needs to know which of them matter. The forward takes a [`Clock`]
//! that is either off (a branch per stage, nothing measured) or records the
//! time since its previous lap under the stage's name, summed over layers.

use std::time::Instant;

/// Seconds spent in each stage of one forward pass, in first-seen order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// `(stage, seconds)`, one entry per stage name, summed over layers.
    pub stages: Vec<(&'static str, f64)>,
}

impl StageTimes {
    /// The sum over stages.
    pub fn total(&self) -> f64 {
        self.stages.iter().map(|(_, s)| s).sum()
    }

    /// The seconds recorded for `stage` (0 when it never ran).
    pub fn get(&self, stage: &str) -> f64 {
        self.stages.iter().find(|(n, _)| *n == stage).map_or(0.0, |(_, s)| *s)
    }

    fn add(&mut self, stage: &'static str, seconds: f64) {
        match self.stages.iter_mut().find(|(n, _)| *n == stage) {
            Some((_, s)) => *s += seconds,
            None => self.stages.push((stage, seconds)),
        }
    }
}

/// A stopwatch threaded through the forward: [`Clock::lap`] charges the time
/// since the previous lap to a stage.
pub(crate) struct Clock<'a> {
    times: Option<&'a mut StageTimes>,
    last: Instant,
}

impl<'a> Clock<'a> {
    /// A clock that records into `times`, or does nothing when `None`.
    pub(crate) fn new(times: Option<&'a mut StageTimes>) -> Self {
        Self { times, last: Instant::now() }
    }

    /// Charges the time since the previous lap (or the start) to `stage`.
    pub(crate) fn lap(&mut self, stage: &'static str) {
        if let Some(t) = self.times.as_deref_mut() {
            let now = Instant::now();
            t.add(stage, (now - self.last).as_secs_f64());
            self.last = now;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laps_sum_by_stage_in_first_seen_order() {
        let mut t = StageTimes::default();
        let mut c = Clock::new(Some(&mut t));
        for _ in 0..3 {
            c.lap("a");
            c.lap("b");
        }
        c.lap("a");
        assert_eq!(t.stages.iter().map(|(n, _)| *n).collect::<Vec<_>>(), ["a", "b"]);
        assert!(t.total() >= 0.0 && t.get("b") >= 0.0 && t.get("c") == 0.0);
        let mut off = Clock::new(None);
        off.lap("a");
    }
}
