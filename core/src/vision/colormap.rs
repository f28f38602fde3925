//! OpenCV's `COLORMAP_JET`, bit-exact, and depth maps drawn in it.
//!
//! The reference colours the style depth with `cv2.applyColorMap(.., JET)` and
//! runs Canny on the result, so the style edges depend on the exact 8-bit
//! colours. OpenCV builds the table from 256 piecewise-linear float samples,
//! re-interpolates them in `f32` and converts with round-half-to-even; this
//! module repeats that arithmetic instead of using an analytic jet.

use std::path::Path;
use std::sync::OnceLock;

use crate::io::{OutputError, covered_unit_depth, to_u8, write_png_rgb8};

/// The 256 float samples of one channel of OpenCV's jet base map, as piecewise
/// linear functions of the index `k` (OpenCV lists them as literals; these are
/// the same numbers).
fn jet_base(channel: usize, k: usize) -> f32 {
    let k = k as f64;
    let v = match channel {
        // red
        0 => match k as usize {
            0..=95 => 0.0,
            96..=159 => (1.5 + 4.0 * (k - 96.0)) / 255.0,
            160..=223 => 1.0,
            _ => (251.5 - 4.0 * (k - 224.0)) / 255.0,
        },
        // green
        1 => match k as usize {
            0..=31 => 0.0,
            32..=95 => (0.5 + 4.0 * (k - 32.0)) / 255.0,
            96..=159 => 1.0,
            160..=223 => (252.5 - 4.0 * (k - 160.0)) / 255.0,
            _ => 0.0,
        },
        // blue
        _ => match k as usize {
            0..=31 => (127.5 + 4.0 * k) / 255.0,
            32..=95 => 1.0,
            96..=159 => (253.5 - 4.0 * (k - 96.0)) / 255.0,
            _ => 0.0,
        },
    };
    v as f32
}

/// OpenCV's `linspace(0, 1, 256)` in `f32`.
fn linspace256() -> [f32; 256] {
    let step = 1.0f32 / 255.0f32;
    let mut x = [0.0f32; 256];
    for (i, xi) in x.iter_mut().enumerate() {
        *xi = 0.0 + (i as f32) * step;
    }
    x
}

/// The lookup table `[grey] -> [r, g, b]`, computed once.
pub fn jet_lut() -> &'static [[u8; 3]; 256] {
    static LUT: OnceLock<[[u8; 3]; 256]> = OnceLock::new();
    LUT.get_or_init(|| {
        let x = linspace256();
        let mut lut = [[0u8; 3]; 256];
        for ch in 0..3 {
            let y: Vec<f32> = (0..256).map(|k| jet_base(ch, k)).collect();
            for (i, entry) in lut.iter_mut().enumerate() {
                // OpenCV's interp1 at the breakpoints themselves: the binary search
                // ends with high = i, low = i - 1 (low = 0, high = 1 for i = 0).
                let (lo, hi) = if i == 0 { (0, 1) } else { (i - 1, i) };
                let v = y[lo] + (x[i] - x[lo]) * (y[hi] - y[lo]) / (x[hi] - x[lo]);
                let s = (v * 255.0f32).round_ties_even();
                entry[ch] = s.clamp(0.0, 255.0) as u8;
            }
        }
        lut
    })
}

/// Applies JET to an 8-bit grey image; returns RGB (OpenCV returns BGR: same
/// colours, channels reversed).
pub fn apply_jet(grey: &[u8]) -> Vec<u8> {
    let lut = jet_lut();
    let mut out = Vec::with_capacity(grey.len() * 3);
    for &g in grey {
        out.extend_from_slice(&lut[g as usize]);
    }
    out
}

/// Converts a map in `[0, 1]` to 8-bit the way the reference does before
/// colouring: min-max again (`(d − min)/(max − min + 1e-8)`), times 255,
/// truncated (`astype(uint8)`).
pub fn to_u8_truncating(map: &[f32]) -> Vec<u8> {
    let (lo, hi) = map.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let range = hi - lo + 1e-8;
    map.iter().map(|&v| (((v - lo) / range) * 255.0).clamp(0.0, 255.0) as u8).collect()
}

/// An inverse-depth map in the JET colour map, the way the reference draws its
/// depth figures (z-score, then per-frame min-max, then JET: the z-score is
/// affine, so this is min-max over the covered pixels, `alpha ≥ 0.5`);
/// uncovered pixels black. A relief of a tenth of the range shows as a change
/// of hue, where the grey of [`crate::io::depth_to_gray`] barely changes. RGB, 8-bit.
pub fn depth_to_jet(inv_depth: &[f32], alpha: &[f32]) -> Vec<u8> {
    let lut = jet_lut();
    covered_unit_depth(inv_depth, alpha).flat_map(|t| t.map_or([0; 3], |t| lut[to_u8(t) as usize])).collect()
}

/// Writes an inverse-depth map as a JET-coloured PNG ([`depth_to_jet`]).
pub fn write_depth_jet_png(
    path: &Path,
    width: u32,
    height: u32,
    inv_depth: &[f32],
    alpha: &[f32],
) -> Result<(), OutputError> {
    write_png_rgb8(path, width, height, &depth_to_jet(inv_depth, alpha))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jet_end_points_match_opencv() {
        let lut = jet_lut();
        // Well-known OpenCV values: 0 -> dark blue, 255 -> dark red, 0.5·255 -> 0.5 after rounding.
        assert_eq!(lut[0], [0, 0, 128]);
        assert_eq!(lut[255], [128, 0, 0]);
        // Plateaus.
        assert_eq!(lut[64][2], 255);
        assert_eq!(lut[64][0], 0);
        assert_eq!(lut[128][1], 255);
        assert_eq!(lut[192][0], 255);
        assert_eq!(lut[192][2], 0);
    }

    #[test]
    fn jet_channels_are_monotone_pieces() {
        let lut = jet_lut();
        for k in 96..159 {
            assert!(lut[k + 1][0] > lut[k][0]);
        }
        for k in 32..95 {
            assert!(lut[k + 1][1] > lut[k][1]);
        }
    }

    #[test]
    fn truncating_conversion() {
        let v = to_u8_truncating(&[0.0, 0.5, 1.0]);
        assert_eq!(v, vec![0, 127, 255]);
    }
}
