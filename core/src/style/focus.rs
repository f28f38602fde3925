//! Where the image-space losses look: the whole frame (the paper) or only
//! the pixels and feature positions the scene covers.
//!
//! On a captured object against a black background most of every VGG feature
//! map is background that no Gaussian can change; averaged over the whole
//! frame, GCFM and content are dominated by it and the object's share of the
//! gradient is small. With [`Focus::Object`], GCFM, content and TV are averaged
//! over the covered positions only (alpha of the colour-matched render above
//! [`COVERAGE_ALPHA`], eroded by [`COVERAGE_ERODE_PX`] so the soft rim, where
//! the background bleeds into the features, stays out). The style side keeps
//! all its positions.

use serde::{Deserialize, Serialize};

/// Which positions the image-space losses average over.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Focus {
    /// Every pixel and feature position (the paper's behaviour).
    Frame,
    /// Only what the scene covers ([`coverage_mask`]).
    Object,
    /// `Object` when the scene covers less than [`AUTO_COVERAGE`] of the
    /// optimisation views on average, else `Frame`.
    #[default]
    Auto,
}

/// Below this mean share of covered pixels, [`Focus::Auto`] means [`Focus::Object`].
pub const AUTO_COVERAGE: f32 = 0.5;
/// Alpha above which a pixel counts as covered by the scene.
pub const COVERAGE_ALPHA: f32 = 0.5;
/// Erosion radius of the coverage mask in pixels (a square structuring element).
pub const COVERAGE_ERODE_PX: usize = 2;

impl std::str::FromStr for Focus {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "frame" => Ok(Focus::Frame),
            "object" => Ok(Focus::Object),
            "auto" => Ok(Focus::Auto),
            _ => Err(format!("expected frame, object or auto, found {s:?}")),
        }
    }
}

impl Focus {
    /// All choices, for menus.
    pub const ALL: [Focus; 3] = [Focus::Frame, Focus::Object, Focus::Auto];

    /// Whether the losses are masked, given the scene's mean coverage of the views.
    pub fn is_object(self, mean_coverage: f32) -> bool {
        match self {
            Focus::Frame => false,
            Focus::Object => true,
            Focus::Auto => mean_coverage < AUTO_COVERAGE,
        }
    }
}

/// The covered pixels of an `h × w` alpha map: alpha above [`COVERAGE_ALPHA`],
/// eroded by [`COVERAGE_ERODE_PX`] (a pixel stays covered only when every pixel
/// within that Chebyshev distance, inside the image, is covered).
pub fn coverage_mask(alpha: &[f32], h: usize, w: usize) -> Vec<bool> {
    assert_eq!(alpha.len(), h * w, "coverage_mask: alpha size");
    let r = COVERAGE_ERODE_PX;
    let over: Vec<bool> = alpha.iter().map(|&a| a > COVERAGE_ALPHA).collect();
    // Separable erosion: rows, then columns.
    let erode_1d = |get: &dyn Fn(usize) -> bool, len: usize, out: &mut dyn FnMut(usize, bool)| {
        for k in 0..len {
            let (a, b) = (k.saturating_sub(r), (k + r).min(len - 1));
            out(k, (a..=b).all(get));
        }
    };
    let mut rows = vec![false; h * w];
    for i in 0..h {
        erode_1d(&|j| over[i * w + j], w, &mut |j, v| rows[i * w + j] = v);
    }
    let mut out = vec![false; h * w];
    for j in 0..w {
        erode_1d(&|i| rows[i * w + j], h, &mut |i, v| out[i * w + j] = v);
    }
    out
}

/// The feature positions (`fh × fw`, row-major) whose cell of the `h × w`
/// pixel mask is at least half covered; cell `(i, j)` holds rows
/// `i·h/fh .. (i+1)·h/fh` and the matching columns.
pub fn feature_mask(pixels: &[bool], h: usize, w: usize, fh: usize, fw: usize) -> Vec<bool> {
    assert_eq!(pixels.len(), h * w, "feature_mask: mask size");
    let mut out = vec![false; fh * fw];
    for i in 0..fh {
        let (r0, r1) = (i * h / fh, ((i + 1) * h / fh).max(i * h / fh + 1).min(h));
        for j in 0..fw {
            let (c0, c1) = (j * w / fw, ((j + 1) * w / fw).max(j * w / fw + 1).min(w));
            let covered =
                (r0..r1).flat_map(|y| (c0..c1).map(move |x| (y, x))).filter(|&(y, x)| pixels[y * w + x]).count();
            out[i * fw + j] = 2 * covered >= (r1 - r0) * (c1 - c0);
        }
    }
    out
}

/// The columns `idx` of a `c × n` channel-major map, as a `c × idx.len()` map.
pub fn gather_positions(data: &[f32], c: usize, n: usize, idx: &[usize]) -> Vec<f32> {
    let mut out = Vec::with_capacity(c * idx.len());
    for ch in 0..c {
        let row = &data[ch * n..(ch + 1) * n];
        out.extend(idx.iter().map(|&x| row[x]));
    }
    out
}

/// Adjoint of [`gather_positions`]: a `c × n` map, zero outside `idx`.
pub fn scatter_positions(part: &[f32], c: usize, n: usize, idx: &[usize]) -> Vec<f32> {
    let mut out = vec![0.0; c * n];
    let m = idx.len();
    for ch in 0..c {
        for (k, &x) in idx.iter().enumerate() {
            out[ch * n + x] = part[ch * m + k];
        }
    }
    out
}

/// Share of the pixels of several masks that are covered (0 for none).
pub fn covered_share(masks: &[&[bool]]) -> f32 {
    let total: usize = masks.iter().map(|m| m.len()).sum();
    let on: usize = masks.iter().map(|m| m.iter().filter(|&&v| v).count()).sum();
    if total == 0 { 0.0 } else { on as f32 / total as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erosion_removes_the_rim_and_cells_follow_the_pixels() {
        let (h, w) = (16, 16);
        // A covered square of rows/cols 2..14.
        let alpha: Vec<f32> = (0..h * w)
            .map(|k| if (2..14).contains(&(k / w)) && (2..14).contains(&(k % w)) { 0.9 } else { 0.1 })
            .collect();
        let m = coverage_mask(&alpha, h, w);
        for (k, &covered) in m.iter().enumerate() {
            let inner = (4..12).contains(&(k / w)) && (4..12).contains(&(k % w));
            assert_eq!(covered, inner, "pixel {k}");
        }
        let f = feature_mask(&m, h, w, 4, 4);
        // Cells of 4×4: only the four central ones are fully covered.
        assert_eq!(f.iter().filter(|&&v| v).count(), 4);
        assert!(f[5] && f[6] && f[9] && f[10]);
        let data: Vec<f32> = (0..3 * 16).map(|v| v as f32).collect();
        let idx = [5usize, 6, 9, 10];
        let g = gather_positions(&data, 3, 16, &idx);
        assert_eq!(g[4..8], [21.0, 22.0, 25.0, 26.0]);
        let s = scatter_positions(&g, 3, 16, &idx);
        assert_eq!(s[21], 21.0);
        assert_eq!(s[20], 0.0);
        assert!((covered_share(&[&m]) - 64.0 / 256.0).abs() < 1e-6);
        assert!(Focus::Auto.is_object(0.2) && !Focus::Auto.is_object(0.7) && !Focus::Frame.is_object(0.0));
    }
}
