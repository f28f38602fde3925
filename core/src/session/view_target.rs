//! What the CPU engine keeps of each view between its visits: the targets
//! computed once from the colour-matched scene `G^c`.
//!
//! The content target is most of it (relu3's 768 channels over the feature
//! grid: 3.1 MB a view at 256 px). With the object focus the masked content
//! loss reads only the covered feature positions, so only their columns are
//! kept ([`ContentTarget::Covered`]); a view whose focus turns to the frame
//! later (a studio slider) computes its whole map again on its next visit.

use std::borrow::Cow;

use crate::style::focus::{feature_mask, gather_positions, scatter_positions};
use crate::style::palette::Palette;
use crate::style::step::FeatureMap;

/// Per-view targets computed once from the colour-matched scene `G^c`.
pub(super) struct ViewTarget {
    pub content: ContentTarget,
    pub inv_depth: Vec<f32>,
    /// Pixels `G^c` covers ([`crate::style::focus::coverage_mask`]): the focus of the losses with `Focus::Object`.
    pub coverage: Vec<bool>,
    /// With λ_out above 0, the pixels `G^c` leaves empty and its render
    /// ([`crate::style::outside`]); `None` otherwise, so no render is kept.
    pub outside: Option<(Vec<bool>, Vec<f32>)>,
    /// The colour-matched render's palette over `coverage` (λ_pal's reference).
    pub palette: Palette,
}

/// A view's content target ([`crate::style::step::content_target`]).
pub(super) enum ContentTarget {
    /// The whole feature map.
    Frame(FeatureMap),
    /// The columns of the covered feature positions only (`channels ×
    /// positions.len()` in `part.data`; `part.height × part.width` is still the
    /// whole grid): what the object focus's content loss reads.
    Covered { part: FeatureMap, positions: Vec<usize> },
}

impl ContentTarget {
    /// Keeps of `full` what a step with this focus reads: with `object`, the
    /// positions the feature mask of `coverage` (an `h × w` pixel mask) covers,
    /// the same mask the step's losses use; the whole map without the object
    /// focus, or where the mask covers no position (the step then drops it).
    pub fn keep(full: FeatureMap, coverage: &[bool], h: usize, w: usize, object: bool) -> Self {
        let (c, fh, fw) = (full.channels, full.height, full.width);
        if !object || coverage.len() != h * w {
            return Self::Frame(full);
        }
        let fmask = feature_mask(coverage, h, w, fh, fw);
        let positions: Vec<usize> = (0..fh * fw).filter(|&k| fmask[k]).collect();
        if positions.is_empty() || positions.len() == fh * fw {
            return Self::Frame(full);
        }
        let data = gather_positions(&full.data, c, fh * fw, &positions);
        Self::Covered { part: FeatureMap { channels: c, height: fh, width: fw, data }, positions }
    }

    /// Whether a step with this focus can use it: the whole map serves both.
    pub fn serves(&self, object: bool) -> bool {
        object || matches!(self, Self::Frame(_))
    }

    /// The whole feature map, zero at the positions not kept (which the
    /// object focus's loss never reads).
    pub fn map(&self) -> Cow<'_, FeatureMap> {
        match self {
            Self::Frame(m) => Cow::Borrowed(m),
            Self::Covered { part, positions } => {
                let (c, n) = (part.channels, part.height * part.width);
                let data = scatter_positions(&part.data, c, n, positions);
                Cow::Owned(FeatureMap { channels: c, height: part.height, width: part.width, data })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::style::content::content_loss_masked;

    /// A 2-channel 2 × 3 feature grid over a 8 × 12 pixel frame.
    fn full() -> FeatureMap {
        FeatureMap { channels: 2, height: 2, width: 3, data: (0..12).map(|v| v as f32 * 0.5 - 1.0).collect() }
    }

    #[test]
    fn the_covered_columns_give_the_masked_loss_of_the_whole_map() {
        let (h, w) = (8, 12);
        // The left half of the frame covered: feature columns 0 and half of 1.
        let coverage: Vec<bool> = (0..h * w).map(|k| k % w < 6).collect();
        let kept = ContentTarget::keep(full(), &coverage, h, w, true);
        let ContentTarget::Covered { part, positions } = &kept else { panic!("expected the covered positions") };
        let fmask = feature_mask(&coverage, h, w, 2, 3);
        assert_eq!(positions, &(0..6).filter(|&k| fmask[k]).collect::<Vec<_>>());
        assert!(positions.len() < 6, "{positions:?}");
        assert_eq!(part.data.len(), 2 * positions.len());
        let rendered: Vec<f32> = (0..12).map(|v| (v as f32).sin()).collect();
        let whole = content_loss_masked(&rendered, &full().data, Some(&fmask));
        let part = content_loss_masked(&rendered, &kept.map().data, Some(&fmask));
        assert_eq!(whole, part);
        assert!(kept.serves(true) && !kept.serves(false));
    }

    #[test]
    fn the_frame_focus_or_an_empty_mask_keeps_the_whole_map() {
        let (h, w) = (8, 12);
        let coverage = vec![true; h * w];
        let none = vec![false; h * w];
        for (mask, object) in [(&coverage, false), (&none, true), (&coverage, true)] {
            let kept = ContentTarget::keep(full(), mask, h, w, object);
            assert!(matches!(kept, ContentTarget::Frame(_)));
            assert_eq!(kept.map().into_owned(), full());
            assert!(kept.serves(false) && kept.serves(true));
        }
    }
}
