//! One fixed set of measures of a scene, so that runs with different settings
//! (mode, budget, working resolution, weights) are compared on the same views.
//!
//! The views are a ring of [`RING_VIEWS`] cameras around the input scene, 2.5°
//! apart, at [`EvalOptions::elevation_degrees`] and rendered at
//! [`EvalOptions::resolution`] whatever the run's working resolution. Four of
//! them, a quarter turn apart ([`STYLE_VIEWS`]), carry the style, content and
//! geometry measures (each the mean over the four); two pairs per baseline
//! carry consistency: a short baseline of 5° ([`SHORT_PAIRS`]) and a long one of
//! 37.5° ([`LONG_PAIRS`]). The ring is not the optimisation's camera set, so
//! the measures also see the scene between training views.
//!
//! Small objects leave most of a view to the background, which the whole-view
//! measures average in; the `_object` measures read only the pixels (or
//! feature positions) the colour-matched scene covers in each view
//! ([`coverage_mask`]), so a study of object focus compares on the object.

use std::sync::Arc;

use super::consistency::{DEFAULT_DEPTH_TOLERANCE, warp_consistency, warp_consistency_masked};
use super::content::{content_distance, content_distance_masked};
use super::geometry::{inverse_depth_change, normal_change};
use super::sliced::SlicedBreakdown;
use super::stability::CoveredColour;
use super::style::{NearestStyle, StyleReference};
use crate::camera::{Camera, OrbitLayout, OrbitOptions, fit_view, framing_subject, orbit_cameras};
use crate::raster::{self, Render, RenderOptions};
use crate::scene::Gaussians;
use crate::style::StyleFeatures;
use crate::style::focus::{coverage_mask, feature_mask, gather_positions};
use crate::style::outside::outside_mask;
use crate::style::step::{FeatureMap, content_target, replicate3};
use crate::vision::Vgg;
use crate::vision::canny::render_edges;

/// Cameras on the evaluation ring (2.5° apart).
pub const RING_VIEWS: usize = 144;
/// Ring indices of the views that carry the style, content and geometry measures (0°, 90°, 180°, 270°).
pub const STYLE_VIEWS: [usize; 4] = [0, 36, 72, 108];
/// Short-baseline pairs (5° apart).
pub const SHORT_PAIRS: [(usize, usize); 2] = [(0, 2), (72, 74)];
/// Long-baseline pairs (37.5° apart).
pub const LONG_PAIRS: [(usize, usize); 2] = [(0, 15), (72, 87)];
/// Random projections of the sliced Wasserstein distance.
pub const SW_PROJECTIONS: usize = 64;

/// Where the evaluation views are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvalOptions {
    /// Longer side of the evaluation renders in pixels (square views). Default 192.
    pub resolution: u32,
    /// Elevation of the ring above the horizontal plane, degrees. Default 15.
    pub elevation_degrees: f32,
    /// Vertical field of view, degrees. Default 50 (as the optimisation orbit).
    pub fov_y_degrees: f32,
    /// Background colour of the renders.
    pub background: [f32; 3],
    /// Fit every ring view to the object ([`crate::camera::fit_view`]) so the
    /// measures rest on its pixels; the plain ring otherwise. Default false.
    pub fit_to_object: bool,
    /// Render the ring over the style image's mean colour instead of the
    /// run's background ([`super::run_trial`]), so that the object's rim is
    /// not measured against black: over black, the rim's features are long
    /// and darkening the object shortens them. Default false.
    pub over_style_colour: bool,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            resolution: 192,
            elevation_degrees: 15.0,
            fov_y_degrees: 50.0,
            background: [0.0; 3],
            fit_to_object: false,
            over_style_colour: false,
        }
    }
}

/// The measures of one scene; lower is "more" of what the name says except
/// where noted. Every value is a mean over the views or pairs named in the module doc.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Measures {
    /// Gram distance to the style ([`super::gram_distance`]), squared feature units; lower is closer.
    pub gram: f32,
    /// Mean–std distance to the style ([`super::mean_std_distance`]), feature units.
    pub mean_std: f32,
    /// Sliced Wasserstein distance to the style ([`super::sliced_wasserstein_distance`], 64 projections), feature units.
    pub sliced_wasserstein: f32,
    /// Nearest-neighbour cosine distance to the style ([`super::nn_cosine_distance`]), in `[0, 2]`.
    pub nn_cosine: f32,
    /// The same between the rendered depth map (inverse depth min-max normalised
    /// per view, as GCFM sees it) and the style's depth map: structure, not colour.
    pub nn_cosine_depth: f32,
    /// The same between the render's Canny edge map and the style's edge map.
    pub nn_cosine_edge: f32,
    /// GCFM's own matching criterion on these views: the cosine distance of each
    /// joint vector `[F_rgb; F_depth; F_edge]` (2304 channels) to its nearest
    /// style joint vector, in `[0, 2]`.
    pub nn_cosine_joint: f32,
    /// Content distance to the colour-matched scene, relative ([`content_distance`]); unitless.
    pub content: f32,
    /// Multi-view RMSE at the 5° baseline, RGB in `[0, 1]`.
    pub consistency_short: f32,
    /// Multi-view RMSE at the 37.5° baseline, RGB in `[0, 1]`.
    pub consistency_long: f32,
    /// Inverse-depth change against the colour-matched scene ([`inverse_depth_change`]), relative.
    pub depth_change: f32,
    /// Mean angle between depth normals before and after ([`normal_change`]), degrees.
    pub normal_change_degrees: f32,
    /// Fraction of pixels covered (alpha ≥ 0.5) in the style views; shows holes and blow-ups.
    pub coverage: f32,
    /// Mean luminance and chroma of the covered pixels of the style views (the
    /// colour-collapse detector's input), flattened into `luminance` and
    /// `chroma` so every measure in `results.json` stays a number.
    #[serde(flatten)]
    pub colour: CoveredColour,
    /// [`Measures::sliced_wasserstein`] over the feature positions the
    /// colour-matched scene covers ([`crate::style::focus::coverage_mask`]):
    /// the style distance on the object, not the background.
    #[serde(default)]
    pub sliced_wasserstein_object: f32,
    /// [`Measures::nn_cosine`] over the covered feature positions.
    #[serde(default)]
    pub nn_cosine_object: f32,
    /// [`Measures::content`] over the covered feature positions
    /// ([`super::content::content_distance_masked`]); unitless.
    #[serde(default)]
    pub content_object: f32,
    /// [`Measures::consistency_short`] over the pixels the colour-matched
    /// scene covers in both views ([`warp_consistency_masked`]), RGB in `[0, 1]`.
    #[serde(default)]
    pub consistency_short_object: f32,
    /// [`Measures::consistency_long`] over the covered pixels, RGB in `[0, 1]`.
    #[serde(default)]
    pub consistency_long_object: f32,
    /// The part of [`Measures::sliced_wasserstein_object`] that is a shift of
    /// the mean ([`super::sliced`]), feature units.
    #[serde(default)]
    pub sliced_wasserstein_object_mean: f32,
    /// The part that is the centred distribution's shape (`mean² + shape² = SW²`), feature units.
    #[serde(default)]
    pub sliced_wasserstein_object_shape: f32,
    /// The sliced Wasserstein distance between unit-length features on the
    /// object (directions only, as NN-cos and GCFM see them); unitless.
    #[serde(default)]
    pub sliced_wasserstein_object_unit: f32,
    /// Mean relu3 feature length on the object over the style's mean feature length.
    #[serde(default)]
    pub feature_norm_object: f32,
    /// Haze: the mean absolute RGB change against the colour-matched render
    /// over the pixels it leaves empty ([`crate::style::outside::outside_mask`])
    /// in the style views, RGB in `[0, 1]`.
    #[serde(default)]
    pub outside_change: f32,
}

/// The fixed views, the colour-matched renders and the style's features that
/// every scene of a study is measured against.
pub struct Evaluator {
    net: Arc<Vgg>,
    /// Statistics of the style's RGB features (see [`StyleFeatures`]).
    style: Option<StyleReference>,
    /// The same features for splitting the object's SW into its parts.
    breakdown: Option<SlicedBreakdown>,
    /// The style's depth, edge and joint features, for nearest neighbours.
    nearest: [Option<NearestStyle>; 3],
    cameras: Vec<(usize, Camera)>,
    opts: RenderOptions,
    /// Colour-matched renders, one per entry of `cameras`.
    reference: Vec<Render>,
    /// Features (RGB, depth, edge) of the colour-matched renders of the style views.
    reference_features: Vec<[FeatureMap; 3]>,
    /// Per style view, the feature positions the colour-matched scene covers.
    covered_positions: Vec<Vec<usize>>,
    /// The same as flags, one per feature position.
    covered_cells: Vec<Vec<bool>>,
    /// Per entry of `cameras`, the pixels the colour-matched render covers ([`coverage_mask`]).
    covered_pixels: Vec<Vec<bool>>,
}

impl Evaluator {
    /// Builds the ring around `reference` (the colour-matched input `G^c`, whose
    /// robust bounds place the ring) and renders it once. `style` holds the VGG
    /// relu3 features of the style's RGB, depth and edge maps (as the
    /// optimisation uses them).
    pub fn new(net: Arc<Vgg>, style: &StyleFeatures, reference: &Gaussians, options: &EvalOptions) -> Self {
        let ring = orbit_cameras(
            &reference.means,
            &OrbitOptions {
                count: RING_VIEWS,
                width: options.resolution.max(16),
                height: options.resolution.max(16),
                fov_y_degrees: options.fov_y_degrees,
                layout: OrbitLayout::Ring { elevation_degrees: options.elevation_degrees },
                ..OrbitOptions::default()
            },
        );
        let mut used: Vec<usize> = STYLE_VIEWS.to_vec();
        used.extend(SHORT_PAIRS.iter().chain(&LONG_PAIRS).flat_map(|&(a, b)| [a, b]));
        used.sort_unstable();
        used.dedup();
        let subject = if options.fit_to_object { framing_subject(reference) } else { Vec::new() };
        let long = options.resolution.max(16);
        let cameras: Vec<(usize, Camera)> = used
            .into_iter()
            .map(|i| (i, if options.fit_to_object { fit_view(&ring[i], &subject, long) } else { ring[i].clone() }))
            .collect();
        let opts = RenderOptions { background: options.background };
        let reference: Vec<Render> = cameras.iter().map(|(_, c)| raster::render(reference, c, &opts)).collect();
        let c = style.channels;
        let joint: Vec<f32> = (0..3).flat_map(|m| style.modality(m).iter().copied()).collect();
        let nearest = [
            NearestStyle::new(style.modality(1), c),
            NearestStyle::new(style.modality(2), c),
            NearestStyle::new(&joint, 3 * c),
        ];
        let breakdown = SlicedBreakdown::new(style.modality(0), c, SW_PROJECTIONS);
        let style = StyleReference::new(style.modality(0), c, SW_PROJECTIONS);
        let mut out = Self {
            net,
            style,
            breakdown,
            nearest,
            cameras,
            opts,
            reference,
            reference_features: Vec::new(),
            covered_positions: Vec::new(),
            covered_cells: Vec::new(),
            covered_pixels: Vec::new(),
        };
        out.covered_pixels =
            out.reference.iter().map(|r| coverage_mask(&r.alpha, r.height as usize, r.width as usize)).collect();
        out.reference_features = STYLE_VIEWS.iter().map(|&v| out.features(&out.reference[out.slot(v)])).collect();
        out.covered_cells = STYLE_VIEWS
            .iter()
            .zip(&out.reference_features)
            .map(|(&v, f)| {
                let r = &out.reference[out.slot(v)];
                let (h, w) = (r.height as usize, r.width as usize);
                feature_mask(&out.covered_pixels[out.slot(v)], h, w, f[0].height, f[0].width)
            })
            .collect();
        out.covered_positions =
            out.covered_cells.iter().map(|cells| (0..cells.len()).filter(|&x| cells[x]).collect()).collect();
        out
    }

    /// The evaluation cameras of the style views (for sample renders).
    pub fn style_cameras(&self) -> Vec<Camera> {
        STYLE_VIEWS.iter().map(|&v| self.cameras[self.slot(v)].1.clone()).collect()
    }

    /// The measures of the colour-matched scene itself (no second render).
    pub fn measure_reference(&self) -> Measures {
        self.measure_renders(&self.reference, &self.reference_features)
    }

    /// Renders `g` from the evaluation views and measures it.
    pub fn measure(&self, g: &Gaussians) -> Measures {
        let renders: Vec<Render> = self.cameras.iter().map(|(_, c)| raster::render(g, c, &self.opts)).collect();
        let feats: Vec<[FeatureMap; 3]> = STYLE_VIEWS.iter().map(|&v| self.features(&renders[self.slot(v)])).collect();
        self.measure_renders(&renders, &feats)
    }

    /// A sample sheet of style view `k` (0..4): the colour-matched input, `g`,
    /// then the inverse depth of each (grey, near = bright, one range for both),
    /// side by side. Returns `(width, height, rgb)`, RGB in `[0, 1]` row-major.
    pub fn sample_sheet(&self, g: &Gaussians, k: usize) -> (u32, u32, Vec<f32>) {
        let slot = self.slot(STYLE_VIEWS[k.min(STYLE_VIEWS.len() - 1)]);
        let before = &self.reference[slot];
        let after = raster::render(g, &self.cameras[slot].1, &self.opts);
        let (w, h) = (before.width as usize, before.height as usize);
        let covered = |r: &Render| -> Vec<f32> {
            r.inv_depth.iter().zip(&r.alpha).filter(|(_, a)| **a >= 0.5).map(|(d, _)| *d).collect()
        };
        let all: Vec<f32> = covered(before).into_iter().chain(covered(&after)).filter(|v| v.is_finite()).collect();
        let lo = all.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = all.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let grey = |r: &Render, i: usize| {
            if r.alpha[i] < 0.5 || hi <= lo { 0.0 } else { ((r.inv_depth[i] - lo) / (hi - lo)).clamp(0.0, 1.0) }
        };
        let mut out = vec![0.0f32; 4 * w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let panels = [
                    [before.rgb[3 * i], before.rgb[3 * i + 1], before.rgb[3 * i + 2]],
                    [after.rgb[3 * i], after.rgb[3 * i + 1], after.rgb[3 * i + 2]],
                    [grey(before, i); 3],
                    [grey(&after, i); 3],
                ];
                for (p, rgb) in panels.iter().enumerate() {
                    let o = 3 * (y * 4 * w + p * w + x);
                    for c in 0..3 {
                        out[o + c] = rgb[c].clamp(0.0, 1.0);
                    }
                }
            }
        }
        (4 * w as u32, h as u32, out)
    }

    fn slot(&self, ring_index: usize) -> usize {
        self.cameras.iter().position(|(i, _)| *i == ring_index).unwrap_or(0)
    }

    /// Features of the three maps GCFM compares: RGB (clamped), the inverse
    /// depth min-max normalised per view, and the Canny edges of the RGB.
    fn features(&self, r: &Render) -> [FeatureMap; 3] {
        let (h, w) = (r.height as usize, r.width as usize);
        let rgb: Vec<f32> = r.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        let (lo, hi) = r.inv_depth.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        let depth: Vec<f32> = r.inv_depth.iter().map(|&x| (x - lo) / (hi - lo + 1e-8)).collect();
        let edge = render_edges(&rgb, h, w);
        let net = &*self.net;
        [
            content_target(net, &rgb, h, w),
            content_target(net, &replicate3(&depth), h, w),
            content_target(net, &replicate3(&edge), h, w),
        ]
    }

    fn measure_renders(&self, renders: &[Render], feats: &[[FeatureMap; 3]]) -> Measures {
        let n = STYLE_VIEWS.len() as f32;
        let mut m = Measures::default();
        for (k, &v) in STYLE_VIEWS.iter().enumerate() {
            let f = &feats[k][0].data;
            if let Some(s) = &self.style {
                m.gram += s.gram_distance(f) / n;
                m.mean_std += s.mean_std_distance(f) / n;
                m.sliced_wasserstein += s.sliced_wasserstein(f) / n;
                m.nn_cosine += s.nn_cosine(f) / n;
                let fm = &feats[k][0];
                let idx = &self.covered_positions[k];
                if !idx.is_empty() {
                    let on = gather_positions(f, fm.channels, fm.height * fm.width, idx);
                    m.sliced_wasserstein_object += s.sliced_wasserstein(&on) / n;
                    m.nn_cosine_object += s.nn_cosine(&on) / n;
                    if let Some(b) = &self.breakdown {
                        let p = b.parts(&on);
                        m.sliced_wasserstein_object_mean += p.mean / n;
                        m.sliced_wasserstein_object_shape += p.shape / n;
                        m.sliced_wasserstein_object_unit += p.unit / n;
                        m.feature_norm_object += p.norm_ratio / n;
                    }
                }
            }
            let [depth, edge, joint] = &self.nearest;
            if let Some(s) = depth {
                m.nn_cosine_depth += s.nn_cosine(&feats[k][1].data) / n;
            }
            if let Some(s) = edge {
                m.nn_cosine_edge += s.nn_cosine(&feats[k][2].data) / n;
            }
            if let Some(s) = joint {
                let v: Vec<f32> = feats[k].iter().flat_map(|f| f.data.iter().copied()).collect();
                m.nn_cosine_joint += s.nn_cosine(&v) / n;
            }
            let reference = &self.reference_features[k][0];
            m.content += content_distance(f, &reference.data).map_or(0.0, |d| d.relative) / n;
            m.content_object += content_distance_masked(f, &reference.data, reference.channels, &self.covered_cells[k])
                .map_or(0.0, |d| d.relative)
                / n;
            let (before, after) = (&self.reference[self.slot(v)], &renders[self.slot(v)]);
            let cam = &self.cameras[self.slot(v)].1;
            m.depth_change +=
                inverse_depth_change(&before.inv_depth, &after.inv_depth, &before.alpha, &after.alpha) / n;
            m.normal_change_degrees += normal_change(before, after, cam).mean_degrees / n;
            let covered = after.alpha.iter().filter(|&&a| a >= 0.5).count() as f32;
            m.coverage += covered / after.alpha.len().max(1) as f32 / n;
            let colour = CoveredColour::of(&after.rgb, &after.alpha);
            m.colour.luminance += colour.luminance / n;
            m.colour.chroma += colour.chroma / n;
            m.outside_change += outside_change(before, after) / n;
        }
        let pair_rmse = |pairs: &[(usize, usize)], on_object: bool| {
            pairs
                .iter()
                .map(|&(a, b)| {
                    let (ia, ib) = (self.slot(a), self.slot(b));
                    let (ra, ca, rb, cb) = (&renders[ia], &self.cameras[ia].1, &renders[ib], &self.cameras[ib].1);
                    let masks = (self.covered_pixels[ia].as_slice(), self.covered_pixels[ib].as_slice());
                    let c = if on_object {
                        warp_consistency_masked(ra, ca, rb, cb, DEFAULT_DEPTH_TOLERANCE, masks)
                    } else {
                        warp_consistency(ra, ca, rb, cb, DEFAULT_DEPTH_TOLERANCE)
                    };
                    c.rmse
                })
                .sum::<f32>()
                / pairs.len() as f32
        };
        m.consistency_short = pair_rmse(&SHORT_PAIRS, false);
        m.consistency_long = pair_rmse(&LONG_PAIRS, false);
        m.consistency_short_object = pair_rmse(&SHORT_PAIRS, true);
        m.consistency_long_object = pair_rmse(&LONG_PAIRS, true);
        m
    }
}

/// The mean absolute RGB difference between `after` and `before` over the
/// pixels `before` leaves empty (0 when it covers every pixel).
fn outside_change(before: &Render, after: &Render) -> f32 {
    let (mut sum, mut count) = (0f64, 0usize);
    for (p, _) in outside_mask(&before.alpha).into_iter().enumerate().filter(|(_, empty)| *empty) {
        for c in 3 * p..3 * p + 3 {
            let clamp = |v: f32| v.clamp(0.0, 1.0);
            sum += f64::from((clamp(after.rgb[c]) - clamp(before.rgb[c])).abs());
        }
        count += 3;
    }
    if count == 0 { 0.0 } else { (sum / count as f64) as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_outside_change_reads_only_the_empty_pixels() {
        let render =
            |alpha: Vec<f32>, rgb: Vec<f32>| Render { rgb, alpha, inv_depth: vec![0.0; 4], width: 2, height: 2 };
        let before = render(vec![1.0, 0.0, 0.0, 0.5], vec![0.5; 12]);
        let mut rgb = vec![0.5; 12];
        rgb[0..3].copy_from_slice(&[1.0; 3]); // covered: not counted
        rgb[3..6].copy_from_slice(&[0.7; 3]); // empty: 0.2
        rgb[6..9].copy_from_slice(&[2.0; 3]); // empty, clamped: 0.5
        let after = render(vec![1.0; 4], rgb);
        assert!((outside_change(&before, &after) - 0.35).abs() < 1e-6);
        assert_eq!(outside_change(&after, &before), 0.0, "a render that covers everything has no outside");
    }

    #[test]
    fn the_ring_indices_give_the_documented_baselines() {
        let step = 360.0 / RING_VIEWS as f32;
        for (a, b) in SHORT_PAIRS {
            assert!(((b - a) as f32 * step - 5.0).abs() < 1e-4);
        }
        for (a, b) in LONG_PAIRS {
            assert!(((b - a) as f32 * step - 37.5).abs() < 1e-4);
        }
        for (k, v) in STYLE_VIEWS.iter().enumerate() {
            assert!((*v as f32 * step - 90.0 * k as f32).abs() < 1e-4);
        }
    }
}
