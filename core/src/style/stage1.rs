//! Stage 1: everything on the style side, computed once per style image and
//! texture scale.
//!
//! As the reference does it: the style image shrunk to height `S` with area
//! interpolation on 8-bit values, its depth min-max normalised and oriented,
//! the edges of the JET-coloured depth, and the VGG features of the three maps
//! at that size (no downscale). The maps are kept for display.

use super::step::{FeatureNet, StyleTargets};
use crate::vision::canny::style_edges_from_depth;
use crate::vision::resize::{resize_area_u8, size_for_height};
use crate::vision::style_depth::{DepthPolarity, StyleDepthProvider, style_depth_map};

/// The style maps at their final size, `height × width`.
#[derive(Clone, Debug)]
pub struct StyleMaps {
    /// Rows (`S`).
    pub height: usize,
    /// Columns (`floor(w · S / h)`).
    pub width: usize,
    /// RGB in [0, 1], HWC.
    pub rgb: Vec<f32>,
    /// Depth in [0, 1], oriented by the chosen polarity.
    pub depth: Vec<f32>,
    /// Edges in {0, 1}.
    pub edge: Vec<f32>,
}

/// Builds the style maps from an 8-bit RGB style image (`h × w × 3`) at
/// texture scale `s` (the output height).
pub fn style_maps(
    rgb_u8: &[u8],
    h: usize,
    w: usize,
    s: usize,
    depth: &dyn StyleDepthProvider,
    polarity: DepthPolarity,
) -> StyleMaps {
    assert_eq!(rgb_u8.len(), h * w * 3, "style_maps: image size mismatch");
    let (sh, sw) = size_for_height(h, w, s);
    let small = resize_area_u8(rgb_u8, h, w, 3, sh, sw);
    let rgb: Vec<f32> = small.iter().map(|&v| f32::from(v) / 255.0).collect();
    let d = style_depth_map(depth, &rgb, sh, sw, polarity);
    let edge = style_edges_from_depth(&d, sh, sw);
    StyleMaps { height: sh, width: sw, rgb, depth: d, edge }
}

impl StyleMaps {
    /// The VGG features of the three maps, ready for the per-step loss.
    pub fn targets<N: FeatureNet>(&self, net: &N) -> StyleTargets {
        StyleTargets::new(net, &self.rgb, &self.depth, &self.edge, self.height, self.width)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::style_depth::HeuristicDepth;

    #[test]
    fn maps_have_the_target_size_and_ranges() {
        let (h, w) = (90, 120);
        let img: Vec<u8> = (0..h * w * 3).map(|i| ((i / 3 % w) * 2 + (i / 3 / w)) as u8).collect();
        let m = style_maps(&img, h, w, 48, &HeuristicDepth::default(), DepthPolarity::NearBright);
        assert_eq!((m.height, m.width), (48, 64));
        assert_eq!(m.rgb.len(), 48 * 64 * 3);
        assert!(m.depth.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(m.edge.iter().all(|&v| v == 0.0 || v == 1.0));
    }
}
