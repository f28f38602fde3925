//! Detectors of degenerate optimisation, run on the Gaussians before and after
//! a stylization (and on its loss curve and consistency measures).
//!
//! A run that diverges rarely fails loudly: it leaves NaNs, a few Gaussians
//! grown over the whole scene, a cloud of invisible Gaussians, points flung out
//! of the scene, splats smeared over the background, or views that no longer
//! agree. Benchmarks and long batch runs need to flag those automatically
//! instead of by eye, so every detector reports the value it measured beside
//! the threshold it compared against.
//! Thresholds live in one serde struct so a preset file or the CLI can tune them.

use serde::{Deserialize, Serialize};

use crate::Gaussians;
use crate::camera::robust_bounds;
use crate::stats::median;

/// Thresholds of the detectors; the defaults are documented per field.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct StabilityThresholds {
    /// Exploding scale: some `exp(log_scale)` after exceeds this many scene
    /// extents (the diagonal of the input's robust bounds) and the largest scale
    /// of the input. Default 1.0.
    pub max_scale_extents: f32,
    /// Exploding scales: the median over Gaussians of the largest axis scale
    /// grows by more than this factor. Default 3.0.
    pub max_median_scale_growth: f32,
    /// Opacity collapse: of the Gaussians visible in the input (`σ(o) ≥ 1/255`),
    /// the fraction that are invisible after exceeds this. Default 0.5.
    pub max_vanished_fraction: f32,
    /// Leaving the scene: the input's robust bounds are enlarged on every side
    /// by this fraction of their size on that axis. Default 0.5.
    pub bounds_margin: f32,
    /// Leaving the scene: the fraction of means outside the enlarged bounds
    /// (non-finite means count as outside) may rise by at most this much over
    /// the input's. Default 0.05.
    pub max_outside_rise: f32,
    /// Consistency collapse: the multi-view RMSE after may be at most this
    /// factor times the input's (the input's floored at 0.01). Default 2.0.
    pub max_consistency_growth: f32,
    /// Coverage blow-up: the fraction of the evaluation views' pixels that the
    /// scene covers may grow by at most this factor. Splats that swelled or
    /// turned opaque smear over the background long before any single one is
    /// larger than the scene. Default 1.5.
    pub max_coverage_growth: f32,
    /// Colour collapse: the mean luminance, or the mean chroma, of the pixels
    /// the scene covers in the evaluation views may fall by at most this
    /// fraction of the colour-matched state's. A colour DC driven below the
    /// clamp at 0 gets no gradient again, so such a run renders ever darker
    /// while its depth keeps the shape. Default 0.5.
    pub max_colour_loss: f32,
}

impl Default for StabilityThresholds {
    fn default() -> Self {
        Self {
            max_scale_extents: 1.0,
            max_median_scale_growth: 3.0,
            max_vanished_fraction: 0.5,
            bounds_margin: 0.5,
            max_outside_rise: 0.05,
            max_consistency_growth: 2.0,
            max_coverage_growth: 1.5,
            max_colour_loss: 0.5,
        }
    }
}

/// What went wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum DegenerationKind {
    /// A NaN or infinity in a Gaussian parameter (value: how many).
    NonFiniteParameter,
    /// A NaN or infinity in the loss curve (value: how many).
    NonFiniteLoss,
    /// A Gaussian larger than the scene (value: largest scale / scene extent).
    ExplodingScale,
    /// Scales grew overall (value: median after / median before).
    MedianScaleGrowth,
    /// Visible Gaussians became transparent (value: fraction that vanished).
    OpacityCollapse,
    /// Gaussians left the scene (value: rise of the fraction outside the bounds).
    LeftBounds,
    /// Views no longer agree (value: RMSE after / RMSE before).
    ConsistencyCollapse,
    /// The scene smears over the frame (value: coverage after / coverage before).
    CoverageGrowth,
    /// The covered pixels went dark or grey (value: the larger fractional loss
    /// of mean luminance or mean chroma against the colour-matched state).
    ColourCollapse,
}

/// One detected degeneration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Degeneration {
    /// Which detector fired.
    pub kind: DegenerationKind,
    /// What it measured (units per [`DegenerationKind`]).
    pub value: f32,
    /// What it compared against; the detector fires when `value > threshold`.
    pub threshold: f32,
}

/// Every degeneration found; empty when the run looks healthy.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StabilityReport {
    /// The detectors that fired, in the order of [`DegenerationKind`].
    pub issues: Vec<Degeneration>,
}

impl StabilityReport {
    /// True when no detector fired.
    pub fn is_healthy(&self) -> bool {
        self.issues.is_empty()
    }

    /// True when a detector of `kind` fired.
    pub fn has(&self, kind: DegenerationKind) -> bool {
        self.issues.iter().any(|d| d.kind == kind)
    }
}

/// Runs every detector: parameters of `after` against `before`, the `losses`
/// of the run, and the multi-view RMSE, the covered fraction of the views and
/// the colour of the covered pixels `(before, after)` when measured.
pub fn assess_stability(
    before: &Gaussians,
    after: &Gaussians,
    losses: &[f32],
    consistency_rmse: Option<(f32, f32)>,
    coverage: Option<(f32, f32)>,
    colour: Option<(CoveredColour, CoveredColour)>,
    th: &StabilityThresholds,
) -> StabilityReport {
    let issues = [
        non_finite_parameters(after),
        non_finite_losses(losses),
        exploding_scale(before, after, th),
        median_scale_growth(before, after, th),
        opacity_collapse(before, after, th),
        left_bounds(before, after, th),
        consistency_rmse.and_then(|(b, a)| consistency_collapse(b, a, th)),
        coverage.and_then(|(b, a)| coverage_growth(b, a, th)),
        colour.and_then(|(b, a)| colour_collapse(b, a, th)),
    ];
    StabilityReport { issues: issues.into_iter().flatten().collect() }
}

fn fired(kind: DegenerationKind, value: f32, threshold: f32) -> Option<Degeneration> {
    // A NaN measurement fires too.
    (value > threshold || value.is_nan()).then_some(Degeneration { kind, value, threshold })
}

/// NaN or infinite values in any parameter of `g`.
pub fn non_finite_parameters(g: &Gaussians) -> Option<Degeneration> {
    let bad = |x: &f32| !x.is_finite();
    let n = g.means.iter().flatten().filter(|x| bad(x)).count()
        + g.log_scales.iter().flatten().filter(|x| bad(x)).count()
        + g.quats.iter().flatten().filter(|x| bad(x)).count()
        + g.opacity_logits.iter().filter(|x| bad(x)).count()
        + g.sh.iter().filter(|x| bad(x)).count();
    fired(DegenerationKind::NonFiniteParameter, n as f32, 0.0)
}

/// NaN or infinite values in a loss curve.
pub fn non_finite_losses(losses: &[f32]) -> Option<Degeneration> {
    fired(DegenerationKind::NonFiniteLoss, losses.iter().filter(|x| !x.is_finite()).count() as f32, 0.0)
}

/// The scene extent: the diagonal of the robust bounds of the means (1 when
/// there are none or they are a point).
pub fn scene_size(g: &Gaussians) -> f32 {
    robust_bounds(&g.means).map(|b| (b.max - b.min).length()).filter(|s| s.is_finite() && *s > 1e-6).unwrap_or(1.0)
}

/// The largest axis scale of each Gaussian, `max_k exp(log_scale_k)`.
fn max_scales(g: &Gaussians) -> Vec<f32> {
    g.log_scales.iter().map(|s| s.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v)).exp()).collect()
}

/// A Gaussian grown beyond `max_scale_extents` scene extents (of `before`) that
/// is also larger than any Gaussian of the input.
pub fn exploding_scale(before: &Gaussians, after: &Gaussians, th: &StabilityThresholds) -> Option<Degeneration> {
    let extent = scene_size(before);
    let largest = |g: &Gaussians| max_scales(g).into_iter().filter(|v| v.is_finite()).fold(0.0f32, f32::max);
    let (b, a) = (largest(before) / extent, largest(after) / extent);
    fired(DegenerationKind::ExplodingScale, a, th.max_scale_extents.max(b))
}

/// The median largest-axis scale growing by more than `max_median_scale_growth`.
pub fn median_scale_growth(before: &Gaussians, after: &Gaussians, th: &StabilityThresholds) -> Option<Degeneration> {
    let (b, a) = (median(max_scales(before))?, median(max_scales(after))?);
    fired(DegenerationKind::MedianScaleGrowth, a / b.max(1e-12), th.max_median_scale_growth)
}

/// Visible input Gaussians (`σ(o) ≥ 1/255`) that became invisible, as a
/// fraction of the visible ones (index-aligned; extra Gaussians are ignored).
pub fn opacity_collapse(before: &Gaussians, after: &Gaussians, th: &StabilityThresholds) -> Option<Degeneration> {
    let visible = |logit: f32| 1.0 / (1.0 + (-logit).exp()) >= 1.0 / 255.0;
    let (mut was, mut vanished) = (0usize, 0usize);
    for (&b, &a) in before.opacity_logits.iter().zip(&after.opacity_logits) {
        if visible(b) {
            was += 1;
            vanished += usize::from(!visible(a));
        }
    }
    if was == 0 {
        return None;
    }
    fired(DegenerationKind::OpacityCollapse, vanished as f32 / was as f32, th.max_vanished_fraction)
}

/// The fraction of `after`'s means outside the input's robust bounds enlarged
/// by `bounds_margin`, rising by more than `max_outside_rise` over the input's.
pub fn left_bounds(before: &Gaussians, after: &Gaussians, th: &StabilityThresholds) -> Option<Degeneration> {
    let b = robust_bounds(&before.means)?;
    let pad = (b.max - b.min) * th.bounds_margin.max(0.0);
    let (lo, hi) = (b.min - pad, b.max + pad);
    let outside = |g: &Gaussians| {
        if g.means.is_empty() {
            return 0.0;
        }
        let n = g.means.iter().filter(|m| !(0..3).all(|k| m[k].is_finite() && m[k] >= lo[k] && m[k] <= hi[k])).count();
        n as f32 / g.means.len() as f32
    };
    fired(DegenerationKind::LeftBounds, outside(after) - outside(before), th.max_outside_rise)
}

/// The multi-view RMSE after exceeding `max_consistency_growth` times the
/// input's (floored at 0.01, so a perfectly consistent input does not make
/// every change fire).
pub fn consistency_collapse(before_rmse: f32, after_rmse: f32, th: &StabilityThresholds) -> Option<Degeneration> {
    let base = if before_rmse.is_finite() { before_rmse.max(0.01) } else { 0.01 };
    fired(DegenerationKind::ConsistencyCollapse, after_rmse / base, th.max_consistency_growth)
}

/// The covered fraction of the views after exceeding `max_coverage_growth`
/// times the input's (floored at 1 %, so an almost empty view does not fire on noise).
pub fn coverage_growth(before: f32, after: f32, th: &StabilityThresholds) -> Option<Degeneration> {
    let base = if before.is_finite() { before.max(0.01) } else { 0.01 };
    fired(DegenerationKind::CoverageGrowth, after / base, th.max_coverage_growth)
}

/// Mean colour of the pixels a scene covers in some views.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CoveredColour {
    /// Mean Rec. 709 luminance `0.2126 R + 0.7152 G + 0.0722 B`, in [0, 1].
    pub luminance: f32,
    /// Mean chroma `max(R, G, B) − min(R, G, B)`, in [0, 1].
    pub chroma: f32,
}

impl CoveredColour {
    /// The mean over the pixels of `rgb` (HWC, clamped to [0, 1]) whose
    /// `alpha ≥ 0.5`; zeros when none is covered.
    pub fn of(rgb: &[f32], alpha: &[f32]) -> Self {
        let (mut l, mut c, mut n) = (0f64, 0f64, 0usize);
        for (p, &a) in rgb.chunks_exact(3).zip(alpha) {
            if a >= 0.5 {
                let [r, g, b] = [p[0], p[1], p[2]].map(|v| f64::from(v.clamp(0.0, 1.0)));
                l += 0.2126 * r + 0.7152 * g + 0.0722 * b;
                c += r.max(g).max(b) - r.min(g).min(b);
                n += 1;
            }
        }
        let n = n.max(1) as f64;
        Self { luminance: (l / n) as f32, chroma: (c / n) as f32 }
    }
}

/// Chroma below which the colour-matched state counts as grey, so that a
/// grey style's noise cannot fire the chroma half of [`colour_collapse`].
const GREY_CHROMA: f32 = 0.05;

/// The covered pixels' mean luminance, or their mean chroma (when the
/// colour-matched state has some), falling by more than `max_colour_loss` of
/// the colour-matched state's.
pub fn colour_collapse(before: CoveredColour, after: CoveredColour, th: &StabilityThresholds) -> Option<Degeneration> {
    let loss = |b: f32, a: f32| if b > 1e-6 { 1.0 - a / b } else { 0.0 };
    let lum = loss(before.luminance, after.luminance);
    let chroma = if before.chroma >= GREY_CHROMA { loss(before.chroma, after.chroma) } else { 0.0 };
    fired(DegenerationKind::ColourCollapse, lum.max(chroma), th.max_colour_loss)
}

#[cfg(test)]
mod tests {
    use super::*;
    use DegenerationKind::*;

    /// A 10×10×10 grid of Gaussians in [0, 9]³, scales 0.2 to 0.4, opaque.
    fn scene() -> Gaussians {
        let mut g = Gaussians::with_capacity(1000, 0);
        for i in 0..1000 {
            g.means.push([(i % 10) as f32, (i / 10 % 10) as f32, (i / 100) as f32]);
            let s = (0.2 + 0.2 * (i % 7) as f32 / 6.0).ln();
            g.log_scales.push([s, s, s]);
            g.quats.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity_logits.push(2.0);
            g.sh.extend([0.1, 0.2, 0.3]);
        }
        g
    }

    fn only(report: &StabilityReport, kind: DegenerationKind) {
        assert!(report.has(kind) && report.issues.len() == 1, "expected only {kind:?}: {report:?}");
        let d = report.issues[0];
        assert!(d.value > d.threshold || d.value.is_nan(), "{d:?}");
    }

    fn assess(after: &Gaussians) -> StabilityReport {
        assess_stability(
            &scene(),
            after,
            &[1.0, 0.5],
            Some((0.05, 0.06)),
            Some((0.2, 0.21)),
            Some((CoveredColour { luminance: 0.4, chroma: 0.2 }, CoveredColour { luminance: 0.37, chroma: 0.22 })),
            &StabilityThresholds::default(),
        )
    }

    #[test]
    fn a_healthy_run_passes_every_detector() {
        let mut after = scene();
        // Small, ordinary changes: moved a little, scales up 20 %, a few Gaussians faded.
        after.means.iter_mut().for_each(|m| m[0] += 0.3);
        after.log_scales.iter_mut().flatten().for_each(|s| *s += 0.2f32.ln_1p());
        after.opacity_logits.iter_mut().take(50).for_each(|o| *o = -8.0);
        assert!(assess(&after).is_healthy(), "{:?}", assess(&after));
        assert!(assess(&scene()).is_healthy());
        let empty = Gaussians::default();
        let th = StabilityThresholds::default();
        assert!(assess_stability(&empty, &empty, &[], None, None, None, &th).is_healthy());
    }

    #[test]
    fn non_finite_parameters_and_losses_are_found() {
        let mut after = scene();
        after.sh[7] = f32::NAN;
        after.quats[3][1] = f32::INFINITY;
        let r = assess(&after);
        only(&r, NonFiniteParameter);
        assert_eq!(r.issues[0].value, 2.0);
        let th = StabilityThresholds::default();
        let r = assess_stability(&scene(), &scene(), &[1.0, f32::NAN, 0.5], None, None, None, &th);
        only(&r, NonFiniteLoss);
    }

    #[test]
    fn one_exploding_gaussian_is_found() {
        let mut after = scene();
        // The extent is the grid diagonal ≈ 8.8·√3 ≈ 15.2 (2 %–98 % bounds); one σ of 40 exceeds it.
        after.log_scales[10] = [40f32.ln(), 0.0, 0.0];
        only(&assess(&after), ExplodingScale);
    }

    #[test]
    fn median_scale_growth_is_found() {
        let mut after = scene();
        after.log_scales.iter_mut().flatten().for_each(|s| *s += 5f32.ln());
        only(&assess(&after), MedianScaleGrowth);
    }

    #[test]
    fn opacity_collapse_is_found() {
        let mut after = scene();
        after.opacity_logits.iter_mut().take(600).for_each(|o| *o = -10.0);
        let r = assess(&after);
        only(&r, OpacityCollapse);
        assert!((r.issues[0].value - 0.6).abs() < 1e-6);
    }

    #[test]
    fn gaussians_leaving_the_scene_are_found() {
        let mut after = scene();
        // 10 % of the means flung 100 units away (far beyond the bounds plus margin).
        after.means.iter_mut().step_by(10).for_each(|m| m[1] += 100.0);
        let r = assess(&after);
        only(&r, LeftBounds);
        assert!((r.issues[0].value - 0.1).abs() < 1e-6);
    }

    #[test]
    fn consistency_collapse_is_found() {
        let th = StabilityThresholds::default();
        let r = assess_stability(&scene(), &scene(), &[], Some((0.05, 0.2)), None, None, &th);
        only(&r, ConsistencyCollapse);
        assert!((r.issues[0].value - 4.0).abs() < 1e-5);
        // A perfect input is floored at 0.01: 0.015 is fine, NaN is not.
        assert!(consistency_collapse(0.0, 0.015, &th).is_none());
        assert!(consistency_collapse(0.05, f32::NAN, &th).is_some());
    }

    #[test]
    fn coverage_growth_is_found() {
        let th = StabilityThresholds::default();
        // The geometry-only lr×100 run of the stress study: 8.9 % of the frame covered before, 33 % after.
        let r = assess_stability(&scene(), &scene(), &[], None, Some((0.089, 0.330)), None, &th);
        only(&r, CoverageGrowth);
        assert!((r.issues[0].value - 0.330 / 0.089).abs() < 1e-4);
        assert!(coverage_growth(0.089, 0.094, &th).is_none(), "a few per cent more is healthy");
        assert!(coverage_growth(0.0, 0.012, &th).is_none(), "floored at 1 %");
    }

    #[test]
    fn colour_collapse_is_found() {
        // The guitar after 3,000 frame-focus steps: the covered pixels' colour DC
        // driven below the clamp for most Gaussians. Constructed here: render a
        // small scene, clamp 60 % of its Gaussians' DC to the dead zone, render again.
        use crate::camera::{OrbitOptions, orbit_cameras};
        use crate::raster::{RenderOptions, render};
        let mut before = scene();
        before.sh.chunks_exact_mut(3).for_each(|c| c.copy_from_slice(&[0.8, 0.0, -0.8]));
        let mut after = before.clone();
        let k = after.sh_coeffs() * 3;
        for i in (0..after.len()).filter(|i| i % 5 < 3) {
            after.sh[i * k..i * k + 3].copy_from_slice(&[-2.0; 3]);
        }
        let cams =
            orbit_cameras(&before.means, &OrbitOptions { count: 2, width: 48, height: 48, ..Default::default() });
        let measure = |g: &Gaussians| {
            let r = render(g, &cams[0], &RenderOptions::default());
            CoveredColour::of(&r.rgb, &r.alpha)
        };
        let (b, a) = (measure(&before), measure(&after));
        assert!(b.luminance > 0.3 && b.chroma > 0.2, "{b:?}");
        let th = StabilityThresholds::default();
        let r = assess_stability(&before, &after, &[], None, None, Some((b, a)), &th);
        only(&r, ColourCollapse);
        assert!(r.issues[0].value > 0.5, "{:?}", r.issues[0]);
        // A healthy recolouring (10 % darker) and a grey input whose chroma wobbles do not fire.
        let darker = CoveredColour { luminance: 0.9 * b.luminance, chroma: 0.95 * b.chroma };
        assert!(colour_collapse(b, darker, &th).is_none());
        let grey = CoveredColour { luminance: 0.5, chroma: 0.01 };
        assert!(colour_collapse(grey, CoveredColour { luminance: 0.5, chroma: 0.001 }, &th).is_none());
        // Chroma alone collapsing fires.
        assert!(colour_collapse(b, CoveredColour { luminance: b.luminance, chroma: 0.2 * b.chroma }, &th).is_some());
    }

    #[test]
    fn thresholds_round_trip_and_fill_defaults() {
        let th: StabilityThresholds = serde_json::from_str(r#"{"max_vanished_fraction": 0.25}"#).expect("parse");
        assert_eq!(th, StabilityThresholds { max_vanished_fraction: 0.25, ..Default::default() });
        let text = serde_json::to_string(&th).expect("serialise");
        assert_eq!(serde_json::from_str::<StabilityThresholds>(&text).expect("parse"), th);
    }
}
