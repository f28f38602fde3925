//! The built-in style depth when no learned estimate can be had: a relief that
//! follows the style's own shapes.
//!
//! GCFM matches the rendered inverse depth and its edges against the style's
//! depth and the Canny edges of its JET colouring (ALGORITHM.md, Stage 1). A
//! depth network sees the relief of lit cubes, beads or brush strokes; the
//! earlier built-in guess ([`super::style_depth::HeuristicDepth`], a
//! scene-layout prior of position, contrast and haze) blurred them away, so
//! the depth and edge modalities carried no structure (its Canny edge map is
//! empty on every one of the nine reference styles).
//!
//! [`ReliefDepth`] reads relief the way shading does, under a light from the
//! viewer: a lit face is raised, a dark crease sunk. It is the luminance's
//! detail at the style's pattern scale (the luminance, lightly smoothed, minus
//! its blur over a window of about a sixteenth of the image height), plus a
//! little of the coarse luminance so large regions keep an order, and its
//! range is set by the 1st and 99th percentiles so a few glints do not flatten
//! the rest. Its sharp steps are where the style's outlines are, so the Canny
//! edges of its JET colouring are the style's outlines too. It is still a
//! guess: a dark raised face reads as sunk. A depth image from a real
//! estimator (`--style-depth`) or the learned provider is better where it can
//! be had.

use super::style_depth::{StyleDepthProvider, box_blur};

/// A weight-free relief estimate from luminance detail (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReliefDepth {
    /// Radius of the pattern-scale blur that is subtracted, as a fraction of the height.
    pub pattern_radius: f32,
    /// Radius of the denoising blur, pixels.
    pub detail_radius: usize,
    /// Weight of the coarse luminance (the pattern-scale blur itself) beside the detail.
    pub coarse_weight: f32,
    /// Share of the values clipped at each end before the range is set.
    pub clip: f32,
}

impl Default for ReliefDepth {
    fn default() -> Self {
        Self { pattern_radius: 1.0 / 16.0, detail_radius: 1, coarse_weight: 0.25, clip: 0.01 }
    }
}

impl StyleDepthProvider for ReliefDepth {
    fn estimate(&self, rgb: &[f32], h: usize, w: usize) -> Vec<f32> {
        assert_eq!(rgb.len(), h * w * 3, "ReliefDepth: image size mismatch");
        if h == 0 || w == 0 {
            return Vec::new();
        }
        let lum: Vec<f32> = rgb.chunks_exact(3).map(|p| 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]).collect();
        let fine = if self.detail_radius > 0 { box_blur(&lum, h, w, self.detail_radius) } else { lum };
        let r = ((self.pattern_radius * h as f32).round() as usize).max(2);
        // Two box passes approximate a Gaussian: no square halos around features.
        let coarse = box_blur(&box_blur(&fine, h, w, r), h, w, r);
        let d: Vec<f32> = fine.iter().zip(&coarse).map(|(f, c)| (f - c) + self.coarse_weight * c).collect();
        clip_to_percentiles(&d, self.clip)
    }
}

/// `values` clipped to their `q` and `1 − q` quantiles.
fn clip_to_percentiles(values: &[f32], q: f32) -> Vec<f32> {
    let mut sorted: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if sorted.is_empty() {
        return vec![0.0; values.len()];
    }
    sorted.sort_by(f32::total_cmp);
    let at = |f: f32| sorted[((f * (sorted.len() - 1) as f32).round() as usize).min(sorted.len() - 1)];
    let (lo, hi) = (at(q), at(1.0 - q));
    values.iter().map(|&v| if v.is_finite() { v.clamp(lo, hi) } else { lo }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::canny::style_edges_from_depth;
    use crate::vision::style_depth::{DepthPolarity, style_depth_map};

    /// Lit squares on a dark ground: the squares are raised and outlined.
    #[test]
    fn lit_squares_are_raised_and_have_edges() {
        let (h, w) = (96, 96);
        let mut rgb = vec![0.15f32; h * w * 3];
        for i in 0..h {
            for j in 0..w {
                if (i / 16) % 2 == 0 && (j / 16) % 2 == 0 {
                    rgb[(i * w + j) * 3..(i * w + j) * 3 + 3].copy_from_slice(&[0.8, 0.7, 0.6]);
                }
            }
        }
        let d = style_depth_map(&ReliefDepth::default(), &rgb, h, w, DepthPolarity::NearBright);
        assert!(d.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(d[8 * w + 8] > d[24 * w + 24] + 0.3, "a lit square's centre stands above the ground");
        let edges = style_edges_from_depth(&d, h, w);
        let on: f32 = edges.iter().sum();
        assert!(on > 100.0, "the squares' outlines are edges ({on} edge pixels)");
    }

    #[test]
    fn flat_image_is_flat_and_tiny_images_do_not_panic() {
        let d = ReliefDepth::default().estimate(&[0.5; 4 * 5 * 3], 4, 5);
        assert!(d.iter().all(|v| (v - d[0]).abs() < 1e-6));
        assert_eq!(ReliefDepth::default().estimate(&[0.2, 0.4, 0.6], 1, 1).len(), 1);
    }
}
