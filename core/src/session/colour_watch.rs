//! A live check that the object's colours do not collapse while a run goes on.
//!
//! The collapse study found the decoupled default darkening captured objects
//! (guitar × block2 to under half its luminance within 300 steps) through
//! the geometry steps' moving means. The stability study's detector
//! ([`colour_collapse`]) reads the finished scene; this watch reads the
//! renders the steps make anyway, so a front end can say so while the run is
//! still going: per view, the covered colour of the colour-matched render
//! `G^c` (the reference, once) and of the view's latest render; the reading
//! compares their means over the views that have both.

use crate::eval::stability::{CoveredColour, Degeneration, StabilityThresholds, colour_collapse};

/// The latest reading of a [`ColourWatch`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ColourReading {
    /// Mean covered colour of the colour-matched renders of the views read.
    pub reference: CoveredColour,
    /// Mean covered colour of the same views' latest renders.
    pub now: CoveredColour,
    /// Views read.
    pub views: u32,
}

impl ColourReading {
    /// Luminance now over the colour-matched state's (1: unchanged).
    pub fn luminance_ratio(&self) -> f32 {
        ratio(self.now.luminance, self.reference.luminance)
    }

    /// Chroma now over the colour-matched state's.
    pub fn chroma_ratio(&self) -> f32 {
        ratio(self.now.chroma, self.reference.chroma)
    }

    /// The stability study's colour-collapse detector on this reading.
    pub fn collapse(&self) -> Option<Degeneration> {
        colour_collapse(self.reference, self.now, &StabilityThresholds::default())
    }
}

fn ratio(a: f32, b: f32) -> f32 {
    if b > 1e-6 { a / b } else { 1.0 }
}

/// Per view, the reference and the latest covered colour.
#[derive(Clone, Debug, Default)]
pub struct ColourWatch {
    views: Vec<(Option<CoveredColour>, Option<CoveredColour>)>,
}

impl ColourWatch {
    /// A watch over `views` views, none read yet.
    pub fn new(views: usize) -> Self {
        Self { views: vec![(None, None); views] }
    }

    /// Forgets every reading (new cameras or background).
    pub fn reset(&mut self) {
        self.views.iter_mut().for_each(|v| *v = (None, None));
    }

    /// Whether `view` has its reference.
    pub fn has_reference(&self, view: usize) -> bool {
        self.views.get(view).is_some_and(|v| v.0.is_some())
    }

    /// The colour-matched render's covered colour of `view`.
    pub fn set_reference(&mut self, view: usize, colour: CoveredColour) {
        if let Some(v) = self.views.get_mut(view) {
            v.0 = Some(colour);
        }
    }

    /// The covered colour of `view`'s latest render.
    pub fn observe(&mut self, view: usize, colour: CoveredColour) {
        if let Some(v) = self.views.get_mut(view) {
            v.1 = Some(colour);
        }
    }

    /// The means over the views with both readings; `None` before any.
    pub fn reading(&self) -> Option<ColourReading> {
        let both: Vec<(CoveredColour, CoveredColour)> =
            self.views.iter().filter_map(|&(r, n)| Some((r?, n?))).collect();
        if both.is_empty() {
            return None;
        }
        let n = both.len() as f32;
        let mean = |pick: fn(&(CoveredColour, CoveredColour)) -> CoveredColour| CoveredColour {
            luminance: both.iter().map(|p| pick(p).luminance).sum::<f32>() / n,
            chroma: both.iter().map(|p| pick(p).chroma).sum::<f32>() / n,
        };
        Some(ColourReading { reference: mean(|p| p.0), now: mean(|p| p.1), views: both.len() as u32 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::DegenerationKind;

    fn colour(luminance: f32, chroma: f32) -> CoveredColour {
        CoveredColour { luminance, chroma }
    }

    #[test]
    fn the_reading_averages_the_views_read_and_fires_on_a_collapse() {
        let mut w = ColourWatch::new(3);
        assert_eq!(w.reading(), None, "nothing read yet");
        w.set_reference(0, colour(0.4, 0.2));
        assert_eq!(w.reading(), None, "a reference alone is no reading");
        w.observe(0, colour(0.4, 0.2));
        let r = w.reading().expect("one view");
        assert_eq!((r.views, r.luminance_ratio(), r.chroma_ratio()), (1, 1.0, 1.0));
        assert_eq!(r.collapse(), None);
        // A second view darkened to a tenth: means 0.3 → 0.22.
        w.set_reference(2, colour(0.2, 0.2));
        w.observe(2, colour(0.02, 0.02));
        let r = w.reading().expect("two views");
        assert_eq!(r.views, 2);
        assert!((r.luminance_ratio() - 0.21 / 0.3).abs() < 1e-6, "{r:?}");
        assert_eq!(r.collapse(), None, "0.7 of the luminance is no collapse");
        // Both darkened under half: the detector fires.
        w.observe(0, colour(0.1, 0.05));
        let r = w.reading().expect("two views");
        assert!(r.luminance_ratio() < 0.5, "{r:?}");
        assert_eq!(r.collapse().map(|d| d.kind), Some(DegenerationKind::ColourCollapse));
        // Views out of range are ignored; a reset forgets everything.
        w.observe(7, colour(0.0, 0.0));
        w.reset();
        assert_eq!(w.reading(), None);
        assert!(!w.has_reference(0));
    }
}
