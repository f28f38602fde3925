//! The preview views a `gast stylize` run writes and measures: before /
//! colour-matched / after renders with their depth, the style distances of
//! each against the style (RGB on the whole view and on the object, depth),
//! the covered colour, and their mean, `report.json`'s `preview` and
//! `summary`.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use gast_core::Camera;
use gast_core::eval::depth_structure::{self, DepthStyleDistance};
use gast_core::eval::{CoveredColour, Degeneration, StyleReference, inverse_depth_change};
use gast_core::gpu::GpuNearest;
use gast_core::io::{write_depth_png, write_exr_depth, write_png_gray_normalized, write_png_rgb};
use gast_core::raster::{self, RenderOptions};
use gast_core::style::{FeatureNet, StyleMaps};
use gast_core::vision::colormap::write_depth_jet_png;
use serde::Serialize;

use super::STYLE_NAMES;
use crate::report::sheet;

/// One preview view's measures (`report.json`'s `preview`).
#[derive(Serialize, Clone, Copy)]
pub(super) struct PreviewMetrics {
    pub(super) view: usize,
    #[serde(flatten)]
    pub(super) measures: Measures,
}

/// The style distances, depth change and covered colour of a view's renders
/// (input, colour-matched, after), or their mean over the preview views.
#[derive(Serialize, Clone, Copy, Default)]
pub(super) struct Measures {
    /// Over the whole views.
    #[serde(flatten)]
    pub(super) rgb: RgbDistances,
    pub(super) inverse_depth_change: f32,
    /// The depth style distance (`gast_core::eval::depth_structure`) of the
    /// colour-matched and after renders' inverse depth to the style's depth.
    pub(super) depth_style_matched: DepthStyleDistance,
    pub(super) depth_style_after: DepthStyleDistance,
    /// RMS of the inverse-depth change at the style's pattern scale, in units of the depth range.
    pub(super) relief_energy: f32,
    /// Mean colour of the covered pixels (alpha ≥ 0.5) of the colour-matched and after renders.
    pub(super) colour_matched: CoveredColour,
    pub(super) colour_after: CoveredColour,
    /// The RGB style distances on the object, for a run whose losses are on
    /// the object (absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) on_object: Option<RgbDistances>,
}

/// The RGB style distances (mean-std and nearest-neighbour cosine of VGG
/// relu3 against the style's) of a view's input, colour-matched and after
/// renders, or their mean over views.
#[derive(Serialize, Clone, Copy, Default)]
pub(super) struct RgbDistances {
    pub(super) mean_std_before: f32,
    /// The colour-matched render's, the state the optimisation starts from.
    pub(super) mean_std_matched: f32,
    pub(super) mean_std_after: f32,
    pub(super) nn_distance_before: f32,
    pub(super) nn_distance_matched: f32,
    pub(super) nn_distance_after: f32,
}

impl RgbDistances {
    /// The distances of the (input, colour-matched, after) features `[b, m,
    /// a]` (channel-major, the style's channels) to `style`, the
    /// nearest-neighbour ones by `nn`.
    fn measure(
        style: &StyleReference,
        [b, m, a]: [&[f32]; 3],
        nn: impl Fn(&[f32]) -> anyhow::Result<f32>,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            mean_std_before: style.mean_std_distance(b),
            mean_std_matched: style.mean_std_distance(m),
            mean_std_after: style.mean_std_distance(a),
            nn_distance_before: nn(b)?,
            nn_distance_matched: nn(m)?,
            nn_distance_after: nn(a)?,
        })
    }

    /// The mean of each distance over `all`; `None` when empty.
    fn mean(all: &[RgbDistances]) -> Option<Self> {
        let n = all.len() as f32;
        let mut m = Self::default();
        for p in all {
            m.mean_std_before += p.mean_std_before / n;
            m.mean_std_matched += p.mean_std_matched / n;
            m.mean_std_after += p.mean_std_after / n;
            m.nn_distance_before += p.nn_distance_before / n;
            m.nn_distance_matched += p.nn_distance_matched / n;
            m.nn_distance_after += p.nn_distance_after / n;
        }
        (!all.is_empty()).then_some(m)
    }
}

impl Measures {
    /// The mean of each measure over `all` (zeros when empty).
    pub(super) fn mean<'a>(all: impl ExactSizeIterator<Item = &'a Measures>) -> Self {
        let n = all.len().max(1) as f32;
        let mut m = Self::default();
        let (mut rgb, mut on_object) = (Vec::new(), Vec::new());
        for p in all {
            rgb.push(p.rgb);
            on_object.extend(p.on_object);
            m.inverse_depth_change += p.inverse_depth_change / n;
            m.depth_style_matched.nn_cos += p.depth_style_matched.nn_cos / n;
            m.depth_style_matched.sw += p.depth_style_matched.sw / n;
            m.depth_style_after.nn_cos += p.depth_style_after.nn_cos / n;
            m.depth_style_after.sw += p.depth_style_after.sw / n;
            m.relief_energy += p.relief_energy / n;
            m.colour_matched.luminance += p.colour_matched.luminance / n;
            m.colour_matched.chroma += p.colour_matched.chroma / n;
            m.colour_after.luminance += p.colour_after.luminance / n;
            m.colour_after.chroma += p.colour_after.chroma / n;
        }
        m.rgb = RgbDistances::mean(&rgb).unwrap_or_default();
        // On the object: the mean over the views that show it.
        m.on_object = RgbDistances::mean(&on_object);
        m
    }
}

/// The preview views' mean measures and the colour-collapse detector on them
/// (`report.json`'s `summary`).
#[derive(Serialize)]
pub(super) struct Summary {
    #[serde(flatten)]
    pub(super) measures: Measures,
    /// What the detector fired on, from the covered luminance and chroma
    /// (colour-matched against after); null: nothing.
    pub(super) colour_collapse: Option<Degeneration>,
}

/// The three renders of a preview view and the four files of each:
/// `view{k}_{tag}{suffix}`.
pub(super) const PREVIEW_TAGS: [&str; 3] = ["before", "colour_matched", "after"];
pub(super) const PREVIEW_SUFFIXES: [&str; 4] = [".png", "_depth.png", "_depth.exr", "_depth_jet.png"];

/// Removes the preview files of views `kept` and above from `out`, which an
/// earlier run with more preview views left there: beside this run's files
/// they showed another run's scene and style under the same names.
pub(super) fn remove_stale_previews(out: &Path, kept: usize) -> anyhow::Result<usize> {
    let names: Vec<String> =
        PREVIEW_TAGS.iter().flat_map(|tag| PREVIEW_SUFFIXES.iter().map(move |s| format!("_{tag}{s}"))).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    gast_core::io::remove_series_tail(out, "view", &names, kept)
        .map_err(|(path, e)| anyhow::anyhow!("{}: removing an earlier run's preview file: {e}", path.display()))
}

/// The preview views' renders (before, colour-matched, after, per view, for
/// the contact sheet too), their measures, and the time each kind of work took.
pub(super) struct Previews {
    pub(super) metrics: Vec<PreviewMetrics>,
    pub(super) renders: Vec<[raster::Render; 3]>,
    /// Seconds spent rendering, in VGG forwards, on the distances, writing files.
    pub(super) parts: [(&'static str, f64); 4],
}

/// Renders a few views before (input scene) and after, with depth, and
/// measures them with `net` (the CPU's VGG, or the GPU's when the run has a
/// hardware one: at 1,008×756 the twenty forwards are most of the time) and
/// the nearest-neighbour searches on `nearest`'s device when given (the rest
/// of the distances on the CPU).
#[allow(clippy::too_many_arguments)]
pub(super) fn write_previews<N: FeatureNet>(
    out: &Path,
    input: &gast_core::Gaussians,
    colour_matched: &gast_core::Gaussians,
    result: &gast_core::Gaussians,
    cameras: &[Camera],
    style: &StyleMaps,
    background: [f32; 3],
    net: &N,
    nearest: Option<&GpuNearest>,
    count: usize,
    on_object: bool,
) -> anyhow::Result<Previews> {
    let mut parts = [
        ("preview views rendered", 0.0),
        ("preview VGG features", 0.0),
        ("preview style distances", 0.0),
        ("preview files written", 0.0),
    ];
    let mut clock = Instant::now();
    let mut lap = |part: usize, parts: &mut [(&'static str, f64); 4]| {
        parts[part].1 += clock.elapsed().as_secs_f64();
        clock = Instant::now();
    };
    let opts = RenderOptions { background };
    let nn = |r: &StyleReference, a: &[f32]| -> anyhow::Result<f32> {
        Ok(match nearest {
            Some(gpu) => gpu.nn_cosine(r.nearest(), a)?,
            None => r.nn_cosine(a),
        })
    };
    // The style side of each distance once (its features, statistics and unit
    // features), not once per render.
    let style_feats = net.features_banded(&style.rgb, style.height, style.width);
    let rgb_ref =
        StyleReference::new(&style_feats.data, style_feats.channels, 0).context("the style image has no features")?;
    let depth_ref = depth_structure::style_depth_reference(net, &style.depth, style.height, style.width)
        .context("the style's depth map has no features")?;
    lap(1, &mut parts);
    let mut metrics = Vec::new();
    let mut renders = Vec::new();
    write_png_rgb(&out.join(STYLE_NAMES[0]), style.width as u32, style.height as u32, &style.rgb)?;
    write_png_gray_normalized(&out.join(STYLE_NAMES[1]), style.width as u32, style.height as u32, &style.depth)?;
    write_png_gray_normalized(&out.join(STYLE_NAMES[2]), style.width as u32, style.height as u32, &style.edge)?;
    lap(3, &mut parts);
    let views: Vec<&Camera> = sheet::spread(cameras, count).collect();
    for (k, cam) in views.iter().copied().enumerate() {
        eprintln!("  preview view {} of {}: rendering and measuring", k + 1, views.len());
        let (w, h) = (cam.width, cam.height);
        let before = raster::render(input, cam, &opts);
        let matched = raster::render(colour_matched, cam, &opts);
        let after = raster::render(result, cam, &opts);
        lap(0, &mut parts);
        for (tag, img) in PREVIEW_TAGS.into_iter().zip([&before, &matched, &after]) {
            let name = |suffix: &str| out.join(format!("view{k}_{tag}{suffix}"));
            let [rgb, depth, exr, jet] = PREVIEW_SUFFIXES;
            write_png_rgb(&name(rgb), w, h, &img.rgb)?;
            write_depth_png(&name(depth), w, h, &img.inv_depth, &img.alpha)?;
            write_exr_depth(&name(exr), w, h, &img.inv_depth)?;
            write_depth_jet_png(&name(jet), w, h, &img.inv_depth, &img.alpha)?;
        }
        lap(3, &mut parts);
        let feats = |img: &raster::Render| {
            let rgb: Vec<f32> = img.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
            net.features(&rgb, h as usize, w as usize)
        };
        let depth_feats = |img: &raster::Render| {
            let (d, h, w) = depth_structure::depth_input(img);
            net.features(&d, h, w)
        };
        let (fb, fm, fa) = (feats(&before), feats(&matched), feats(&after));
        let (dm, da) = (depth_feats(&matched), depth_feats(&after));
        lap(1, &mut parts);
        let object =
            if on_object { object_distances(&rgb_ref, &matched, [&fb, &fm, &fa], |a| nn(&rgb_ref, a))? } else { None };
        let measures = Measures {
            rgb: RgbDistances::measure(&rgb_ref, [&fb.data, &fm.data, &fa.data], |a| nn(&rgb_ref, a))?,
            inverse_depth_change: inverse_depth_change(
                &matched.inv_depth,
                &after.inv_depth,
                &matched.alpha,
                &after.alpha,
            ),
            depth_style_matched: DepthStyleDistance {
                nn_cos: nn(&depth_ref, &dm.data)?,
                sw: depth_ref.sliced_wasserstein(&dm.data),
            },
            depth_style_after: DepthStyleDistance {
                nn_cos: nn(&depth_ref, &da.data)?,
                sw: depth_ref.sliced_wasserstein(&da.data),
            },
            relief_energy: depth_structure::relief_energy(&matched, &after),
            // As the detector of `gast bench quality` reads them: each render's own covered pixels.
            colour_matched: CoveredColour::of(&matched.rgb, &matched.alpha),
            colour_after: CoveredColour::of(&after.rgb, &after.alpha),
            on_object: object,
        };
        lap(2, &mut parts);
        metrics.push(PreviewMetrics { view: k, measures });
        renders.push([before, matched, after]);
    }
    Ok(Previews { metrics, renders, parts })
}

/// The RGB style distances of a view's (input, colour-matched, after)
/// features over the feature positions `matched` covers
/// (`gast_core::style::focus::{coverage_mask, feature_mask}`: the positions
/// an object run's losses read, as `gast bench quality`'s `_object`
/// measures); `None` where it covers none. An object run leaves the
/// background, the same in every render, which the whole-view distances
/// average in.
pub(super) fn object_distances(
    style: &StyleReference,
    matched: &raster::Render,
    feats: [&gast_core::style::step::FeatureMap; 3],
    nn: impl Fn(&[f32]) -> anyhow::Result<f32>,
) -> anyhow::Result<Option<RgbDistances>> {
    use gast_core::style::focus::{coverage_mask, feature_mask, gather_positions};
    let (h, w) = (matched.height as usize, matched.width as usize);
    let f = feats[1];
    let cells = feature_mask(&coverage_mask(&matched.alpha, h, w), h, w, f.height, f.width);
    let idx: Vec<usize> = (0..cells.len()).filter(|&x| cells[x]).collect();
    if idx.is_empty() {
        return Ok(None);
    }
    let on = |f: &gast_core::style::step::FeatureMap| gather_positions(&f.data, f.channels, f.height * f.width, &idx);
    let [b, m, a] = feats.map(on);
    RgbDistances::measure(style, [&b, &m, &a], nn).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use gast_core::gpu::{GpuContext, GpuFeatureNet};

    /// The summary is the preview views' mean, and report.json keeps its
    /// flat keys (`summary.nn_distance_after`, `preview[0].view`) that the
    /// studies and the device check's report read.
    #[test]
    fn the_summary_is_the_views_mean_with_flat_keys() {
        let view = |v: f32| Measures {
            rgb: RgbDistances { nn_distance_after: v, ..RgbDistances::default() },
            depth_style_after: DepthStyleDistance { nn_cos: v, sw: 2.0 * v },
            colour_after: CoveredColour { luminance: v, chroma: 0.5 },
            ..Measures::default()
        };
        let preview =
            [PreviewMetrics { view: 0, measures: view(0.2) }, PreviewMetrics { view: 1, measures: view(0.4) }];
        let m = Measures::mean(preview.iter().map(|p| &p.measures));
        assert!((m.rgb.nn_distance_after - 0.3).abs() < 1e-6 && (m.depth_style_after.sw - 0.6).abs() < 1e-6);
        assert!((m.colour_after.chroma - 0.5).abs() < 1e-6);
        assert_eq!(Measures::mean([].iter()).rgb.nn_distance_after, 0.0);
        let json = serde_json::to_value(Summary { measures: m, colour_collapse: None }).expect("serialises");
        assert!(json["nn_distance_after"].as_f64().is_some_and(|v| (v - 0.3).abs() < 1e-6), "{json}");
        assert!(json["depth_style_after"]["sw"].is_number() && json["colour_collapse"].is_null(), "{json}");
        let first = serde_json::to_value(preview[0]).expect("serialises");
        assert_eq!(first["view"], 0);
        assert!(first["mean_std_after"].is_number() && first.get("measures").is_none(), "{first}");
        assert!(first.get("on_object").is_none(), "a run on the whole frame has no object distances: {first}");
        // An object run's distances on the object: the mean of the views that show it.
        let on = |v: f32| Some(RgbDistances { nn_distance_after: v, ..RgbDistances::default() });
        let views = [
            Measures { on_object: on(0.1), ..view(0.2) },
            Measures { on_object: None, ..view(0.4) },
            Measures { on_object: on(0.3), ..view(0.4) },
        ];
        let o = Measures::mean(views.iter()).on_object.expect("two views show the object");
        assert!((o.nn_distance_after - 0.2).abs() < 1e-6);
        let json = serde_json::to_value(Measures::mean(views.iter())).expect("serialises");
        assert!(json["on_object"]["nn_distance_after"].is_number(), "{json}");
    }

    /// The preview measures with the GPU's VGG and nearest-neighbour search
    /// (lavapipe here) are the CPU's: `gast stylize` takes the GPU's after a
    /// run on a hardware adapter.
    #[test]
    fn the_preview_measures_on_the_gpu_are_the_cpus() {
        use gast_core::camera::{OrbitOptions, orbit_cameras};
        use gast_core::gpu::AdapterPolicy;
        use gast_core::vision::style_depth::{DepthPolarity, HeuristicDepth};
        let in_ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
        let weights = gast_tests::shared_dir().join("data/weights/vgg19-conv3.safetensors");
        let ctx = match GpuContext::headless(AdapterPolicy::AnyAdapter) {
            Ok(ctx) if weights.is_file() => ctx,
            found => {
                let why = found.err().map_or("no shared VGG weights".to_string(), |e| e.to_string());
                assert!(!in_ci, "{why} (CI=true, so this is a failure)");
                eprintln!("SKIPPED the_preview_measures_on_the_gpu_are_the_cpus: {why}");
                return;
            }
        };
        let vgg = super::super::load_vgg(Some(&weights)).expect("the shared VGG weights");
        let before = crate::studio::assets::demo_scene();
        // The colour-matched and "after" scenes: recoloured, then moved, so every measure has something to see.
        let mut matched = before.clone();
        matched.sh.iter_mut().step_by(3).for_each(|v| *v += 0.2);
        let mut after = matched.clone();
        after.means.iter_mut().enumerate().for_each(|(i, m)| m[2] += 0.02 * ((i % 7) as f32 - 3.0));
        let opts = OrbitOptions { count: 2, width: 80, height: 60, ..Default::default() };
        let cameras = orbit_cameras(&before.means, &opts);
        let (_, image) = &crate::studio::assets::demo_styles()[0];
        let (w, h) = (image.width() as usize, image.height() as usize);
        let maps = gast_core::style::style_maps(
            image.as_raw(),
            h,
            w,
            48,
            &HeuristicDepth::default(),
            DepthPolarity::NearBright,
        );
        let dir = std::env::temp_dir().join(format!("gast-previews-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        let measures = |p: Previews| numbers(&serde_json::to_value(&p.metrics).expect("serialises"));
        let (scenes, bg) = ([&before, &matched, &after], [0.0; 3]);
        // As for a run whose losses are on the object: its distances there too.
        let cpu = write_previews(&dir, scenes[0], scenes[1], scenes[2], &cameras, &maps, bg, &vgg, None, 2, true)
            .expect("CPU");
        let (net, nearest) = (GpuFeatureNet::new(ctx.clone(), &vgg), GpuNearest::new(ctx));
        let nearest = Some(&nearest);
        let gpu = write_previews(&dir, scenes[0], scenes[1], scenes[2], &cameras, &maps, bg, &net, nearest, 2, true)
            .expect("GPU");
        let (cpu, gpu) = (measures(cpu), measures(gpu));
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(cpu.len(), gpu.len());
        assert!(cpu.len() >= 2 * (16 + 6), "{} measures", cpu.len());
        assert_eq!(cpu.iter().filter(|(n, _)| n.contains("on_object.nn_distance")).count(), 2 * 3, "{cpu:?}");
        for ((name, c), (_, g)) in cpu.iter().zip(&gpu) {
            assert!((c - g).abs() <= 1e-3 * c.abs().max(1e-2), "{name}: CPU {c}, GPU {g}");
        }
        let changed = |key: &str| cpu.iter().filter(|(n, v)| n.ends_with(key) && *v > 0.0).count();
        assert_eq!(changed("inverse_depth_change"), 2, "the moved scene's depth changed in both views");
    }

    /// Every number of a JSON value with its path, in order.
    fn numbers(v: &serde_json::Value) -> Vec<(String, f64)> {
        fn walk(v: &serde_json::Value, path: String, out: &mut Vec<(String, f64)>) {
            match v {
                serde_json::Value::Number(n) => out.push((path, n.as_f64().unwrap_or(f64::NAN))),
                serde_json::Value::Array(a) => {
                    a.iter().enumerate().for_each(|(i, x)| walk(x, format!("{path}[{i}]"), out))
                }
                serde_json::Value::Object(o) => o.iter().for_each(|(k, x)| walk(x, format!("{path}.{k}"), out)),
                _ => {}
            }
        }
        let mut out = Vec::new();
        walk(v, String::new(), &mut out);
        out
    }
}
