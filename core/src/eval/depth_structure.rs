//! The style's structure in the geometry: how much the rendered inverse depth
//! looks like the style's depth, and how much relief the run added.
//!
//! RGB style distances ([`super::style`]) say nothing of the shape. The
//! geometry half of the method pulls the rendered depth map's VGG features
//! toward the style depth's (GCFM's depth modality), so the measure of its
//! success is the same distance taken on depth:
//!
//! - **Depth style distance**: the render's inverse depth `D`, min-max
//!   normalised over its covered pixels (`alpha ≥ 0.5`, uncovered 0) as the
//!   loss normalises it, downscaled by ½ and replicated to three channels,
//!   through VGG relu3 (768 channels); its nearest-neighbour cosine distance
//!   `mean_x min_y (1 − cos(F_D(x), F_S(y)))` and its sliced-Wasserstein
//!   distance (128 directions) to the features of the style's depth map at
//!   texture scale ([`super::style::StyleReference`]). Lower is closer; a run
//!   lowers it beyond the seed noise when the depth takes the style's shapes.
//! - **Relief energy**: the change `Δ = D_after − D_before` over the pixels
//!   covered in both, in units of `D_before`'s covered range (max − min),
//!   high-passed at the style's pattern scale, `Δ − blur_r(Δ)` with a box blur
//!   of radius `r` = a sixteenth of the render's longer side, and its RMS.
//!   A uniform shift or a change of layout scores 0; bumps, tiles and ridges of
//!   the pattern's size score their height.
//! - **Layout kept**: the Pearson correlation of `D_after` with `D_before`
//!   over the pixels covered in both. Near 1 when the scene keeps its shape
//!   and gains relief on it; it falls when the scene melts (Gaussians drift
//!   toward the cameras, a front layer hides what was behind), which lowers
//!   the depth style distance too, for the wrong reason.

use crate::raster::Render;
use crate::style::FeatureNet;
use crate::vision::Vgg;
use crate::vision::resize::downscale_half;
use crate::vision::style_depth::box_blur;

use super::geometry::COVERED_ALPHA;
use super::style::StyleReference;

/// Sliced-Wasserstein directions of the depth style distance.
pub const DEPTH_PROJECTIONS: usize = 128;

/// The depth map VGG sees: `D` min-max normalised over the covered pixels,
/// uncovered 0, downscaled by ½, three equal channels (HWC); with its size.
pub fn depth_input(render: &Render) -> (Vec<f32>, usize, usize) {
    let (h, w) = (render.height as usize, render.width as usize);
    let covered = |i: usize| render.alpha[i] >= COVERED_ALPHA && render.inv_depth[i].is_finite();
    let (lo, hi) = (0..h * w)
        .filter(|&i| covered(i))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), i| (a.min(render.inv_depth[i]), b.max(render.inv_depth[i])));
    let range = if hi > lo { hi - lo } else { 1.0 };
    let d: Vec<f32> =
        (0..h * w).flat_map(|i| [if covered(i) { (render.inv_depth[i] - lo) / range } else { 0.0 }; 3]).collect();
    downscale_half(&d, h, w, 3)
}

/// The style side: the style depth map (`h × w`, [0, 1]) through VGG (the
/// CPU's or the GPU's), as a reference.
pub fn style_depth_reference<N: FeatureNet>(vgg: &N, depth: &[f32], h: usize, w: usize) -> Option<StyleReference> {
    let d3: Vec<f32> = depth.iter().flat_map(|&v| [v; 3]).collect();
    let f = vgg.features_banded(&d3, h, w);
    StyleReference::new(&f.data, f.channels, DEPTH_PROJECTIONS)
}

/// Nearest-neighbour cosine and sliced-Wasserstein distances of the render's depth to the style's.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DepthStyleDistance {
    /// `mean_x min_y (1 − cos)` of relu3 features.
    pub nn_cos: f32,
    /// Sliced Wasserstein over [`DEPTH_PROJECTIONS`] directions.
    pub sw: f32,
}

/// [`DepthStyleDistance`] of `render`'s inverse depth to the style depth `reference`.
pub fn depth_style_distance(vgg: &Vgg, render: &Render, reference: &StyleReference) -> DepthStyleDistance {
    let (d, h, w) = depth_input(render);
    let f = vgg.features(&d, h, w);
    DepthStyleDistance { nn_cos: reference.nn_cosine(&f.data), sw: reference.sliced_wasserstein(&f.data) }
}

/// The relief energy of the change from `before` to `after` (see the module docs);
/// 0 when no pixel is covered in both or `before`'s depth has no range.
pub fn relief_energy(before: &Render, after: &Render) -> f32 {
    let (h, w) = (before.height as usize, before.width as usize);
    let n = h * w;
    if n == 0 || after.inv_depth.len() != n {
        return 0.0;
    }
    let both = |i: usize| before.alpha[i] >= COVERED_ALPHA && after.alpha[i] >= COVERED_ALPHA;
    let (lo, hi) = (0..n)
        .filter(|&i| both(i) && before.inv_depth[i].is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), i| (a.min(before.inv_depth[i]), b.max(before.inv_depth[i])));
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    let delta: Vec<f32> = (0..n)
        .map(|i| {
            let d = (after.inv_depth[i] - before.inv_depth[i]) / (hi - lo);
            if both(i) && d.is_finite() { d } else { 0.0 }
        })
        .collect();
    let r = (h.max(w) / 16).max(1);
    let smooth = box_blur(&delta, h, w, r);
    let (mut sum, mut count) = (0f64, 0usize);
    for i in (0..n).filter(|&i| both(i)) {
        sum += f64::from(delta[i] - smooth[i]).powi(2);
        count += 1;
    }
    if count == 0 { 0.0 } else { (sum / count as f64).sqrt() as f32 }
}

/// The layout kept from `before` to `after` (see the module docs): the
/// correlation of their inverse depths over the pixels covered in both; 1 when
/// fewer than two such pixels or no variance.
pub fn layout_correlation(before: &Render, after: &Render) -> f32 {
    let n = before.inv_depth.len().min(after.inv_depth.len());
    let pairs: Vec<(f64, f64)> = (0..n)
        .filter(|&i| before.alpha[i] >= COVERED_ALPHA && after.alpha[i] >= COVERED_ALPHA)
        .map(|i| (f64::from(before.inv_depth[i]), f64::from(after.inv_depth[i])))
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .collect();
    if pairs.len() < 2 {
        return 1.0;
    }
    let m = pairs.len() as f64;
    let (ma, mb) = (pairs.iter().map(|p| p.0).sum::<f64>() / m, pairs.iter().map(|p| p.1).sum::<f64>() / m);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (a, b) in &pairs {
        sab += (a - ma) * (b - mb);
        saa += (a - ma).powi(2);
        sbb += (b - mb).powi(2);
    }
    if saa <= 0.0 || sbb <= 0.0 { 1.0 } else { (sab / (saa * sbb).sqrt()) as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(w: u32, h: u32, bump: f32) -> Render {
        let mut r = Render::zeros(w, h);
        for (k, a) in r.alpha.iter_mut().enumerate() {
            *a = 1.0;
            let (x, y) = (k as u32 % w, k as u32 / w);
            let tile = ((x / 4) + (y / 4)) % 2 == 0;
            r.inv_depth[k] = 0.5 + 0.3 * x as f32 / w as f32 + if tile { bump } else { 0.0 };
        }
        r
    }

    #[test]
    fn relief_energy_sees_tiles_not_shifts() {
        let before = plane(64, 64, 0.0);
        assert_eq!(relief_energy(&before, &before), 0.0);
        let mut shifted = before.clone();
        shifted.inv_depth.iter_mut().for_each(|d| *d += 0.05);
        assert!(relief_energy(&before, &shifted) < 1e-4);
        let tiled = plane(64, 64, 0.03);
        let e = relief_energy(&before, &tiled);
        // Tiles of 0.1 of the range: the high-passed change has an RMS near half of it.
        assert!(e > 0.03 && e < 0.07, "{e}");
    }

    #[test]
    fn the_layout_survives_relief_and_not_a_scramble() {
        let before = plane(64, 64, 0.0);
        assert!((layout_correlation(&before, &before) - 1.0).abs() < 1e-6);
        assert!(layout_correlation(&before, &plane(64, 64, 0.03)) > 0.9);
        let mut melted = before.clone();
        melted.inv_depth.reverse();
        melted.inv_depth.iter_mut().enumerate().for_each(|(k, d)| *d = if k % 7 == 0 { 3.0 } else { 0.4 });
        assert!(layout_correlation(&before, &melted).abs() < 0.2, "{}", layout_correlation(&before, &melted));
    }

    #[test]
    fn depth_input_is_normalised_over_covered_pixels() {
        let mut r = plane(8, 6, 0.0);
        r.alpha[0] = 0.0;
        let (d, h, w) = depth_input(&r);
        assert_eq!((h, w, d.len()), (3, 4, 36));
        assert!(d.iter().all(|v| (0.0..=1.0).contains(v)));
    }
}
