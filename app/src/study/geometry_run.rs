//! Runs the geometry study ([`crate::study::geometry`]): the scene (fitted
//! here from the fern photos when none is given) × the styles × the arms, the
//! depth and RGB measures after every cycle on the same evaluation views.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use gast_core::Camera;
use gast_core::eval::depth_structure;
use gast_core::eval::{
    CoveredColour, StabilityThresholds, StyleReference, inverse_depth_change, mean_std_distance, nn_cosine_distance,
};
use gast_core::raster::{self, Render, RenderOptions};
use gast_core::session::{Session, SessionInputs, StyleDepthSource, StyleImage, prepare_style};
use gast_core::vision::Vgg;

use crate::report::sheet;
use crate::study::geometry::{Arm, GeometryCheckpoint, GeometryMeasures, GeometryRecord, GeometryRun, GeometrySizes};
use crate::views::{Framing, ViewArgs, load_scene, views_for};

/// The style's targets for the measures: its relu3 features and its depth map's.
struct StyleRefs {
    rgb: gast_core::vision::Features,
    depth: StyleReference,
}

/// Runs the study into `out` and returns what `results.json` keeps.
/// `fit` fits a scene from a photo set (dataset folder, output `.ply`,
/// iterations at 504 px with every 8th photo held out): the command's `gast
/// fit`, passed in so the study does not reach into the command line.
pub fn run(
    sizes: &GeometrySizes,
    shared: &Path,
    vgg: &Arc<Vgg>,
    out: &Path,
    fit: &dyn Fn(&Path, &Path, u32) -> anyhow::Result<()>,
) -> anyhow::Result<GeometryRun> {
    gast_core::io::create_folder(out).with_context(|| format!("could not create {}", out.display()))?;
    let cameras_path = shared.join(&sizes.cameras);
    let scene_path = match &sizes.scene {
        Some(p) => p.clone(),
        None => fit_scene(sizes, &cameras_path, out, fit)?,
    };
    let scene = Arc::new(load_scene(&scene_path)?);
    let cameras = views_for(
        &scene,
        &ViewArgs {
            cameras: Some(cameras_path.clone()),
            orbit: false,
            views: 0,
            size: sizes.resolution,
            fov: 50.0,
            framing: Framing::Full,
            crop: false,
        },
    )?;
    let eval: Vec<Camera> = sheet::spread(&cameras, sizes.eval_views).cloned().collect();
    let mut plan: Vec<(usize, Arm, u64)> = Vec::new();
    for s in 0..sizes.styles.len() {
        for &arm in &sizes.arms {
            plan.push((s, arm, sizes.noise_seeds.first().copied().unwrap_or(1)));
            if s == 0 && arm == Arm::Decoupled {
                plan.extend(sizes.noise_seeds.iter().skip(1).map(|&seed| (s, arm, seed)));
            }
        }
    }
    let total_steps: u64 = plan
        .iter()
        .map(|&(_, arm, seed)| u64::from(arm.apply(&sizes.base_config(seed)).schedule().total_steps()))
        .sum();
    println!(
        "geometry study: {} ({} Gaussians, {} cameras) × {} styles, {} runs of {} cycles at {} px, texture scale {}",
        scene_path.display(),
        scene.len(),
        cameras.len(),
        sizes.styles.len(),
        plan.len(),
        sizes.cycles,
        sizes.resolution,
        sizes.texture_scale
    );
    let started = Instant::now();
    let bar = crate::progress::bar(total_steps, "steps");
    let mut records = Vec::new();
    let mut prepared_for: Option<(usize, StyleImage, gast_core::session::PreparedStyle, StyleRefs)> = None;
    for &(s, arm, seed) in &plan {
        if prepared_for.as_ref().is_none_or(|p| p.0 != s) {
            let path = shared.join(&sizes.styles[s]);
            let image = StyleImage::open(&path).map_err(anyhow::Error::msg)?;
            let base = sizes.base_config(seed);
            let prepared = prepare_style(
                vgg,
                &image,
                base.texture_scale,
                &StyleDepthSource::Heuristic,
                base.depth_polarity,
                base.depth_relief_px,
            );
            let m = &prepared.maps;
            let refs = StyleRefs {
                rgb: vgg.features(&m.rgb, m.height, m.width),
                depth: depth_structure::style_depth_reference(&**vgg, &m.depth, m.height, m.width)
                    .with_context(|| format!("{}: the style's depth map has no features", path.display()))?,
            };
            prepared_for = Some((s, image, prepared, refs));
        }
        let Some((_, image, prepared, refs)) = &prepared_for else { continue };
        let config = arm.apply(&sizes.base_config(seed));
        let style = style_name(&sizes.styles[s]);
        bar.set_message(format!("{style} {}", arm.label()));
        let base = bar.position();
        let t = Instant::now();
        let inputs = SessionInputs {
            scene: Arc::clone(&scene),
            cameras: cameras.clone(),
            style: image.clone(),
            style_depth: StyleDepthSource::Heuristic,
            vgg: Arc::clone(vgg),
            config: config.clone(),
            gpu: None,
        };
        let mut session = Session::prepare_with_style(inputs, Some(prepared.clone()), &mut |_| {})
            .with_context(|| format!("{style} × {}", arm.label()))?;
        let prepare_s = t.elapsed().as_secs_f64();
        let opts = RenderOptions { background: config.background };
        let colour_matched = session.colour_matched();
        let matched: Vec<Render> = eval.iter().map(|c| raster::render(&colour_matched, c, &opts)).collect();
        drop(colour_matched);
        let mut checkpoints =
            vec![GeometryCheckpoint { step: 0, seconds: prepare_s, measures: measure(vgg, &matched, &matched, refs) }];
        let per_cycle = config.steps_per_cycle.max(1);
        while let Some(r) = session.step() {
            let done = session.steps_done();
            bar.set_position(base + u64::from(done));
            crate::progress::tick(&bar);
            if !r.losses.total.is_finite() {
                break;
            }
            if done % per_cycle == 0 || session.is_done() {
                let g = session.result();
                let now: Vec<Render> = eval.iter().map(|c| raster::render(&g, c, &opts)).collect();
                let measures = measure(vgg, &matched, &now, refs);
                checkpoints.push(GeometryCheckpoint { step: done, seconds: prepare_s + session.elapsed_s(), measures });
            }
        }
        let (first, last) = (checkpoints[0].measures, checkpoints[checkpoints.len() - 1].measures);
        let collapse = gast_core::eval::stability::colour_collapse(
            CoveredColour { luminance: first.luminance, chroma: first.chroma },
            CoveredColour { luminance: last.luminance, chroma: last.chroma },
            &StabilityThresholds::default(),
        )
        .map(|d| format!("{:?} {:.2} > {:.2}", d.kind, d.value, d.threshold));
        let record = GeometryRecord { style: style.clone(), arm, seed, config, checkpoints, collapse };
        let d = record.delta();
        bar.suspend(|| {
            println!(
                "{style:<10} {:<30} seed {seed}  {:>6.1} s  depth NN-cos {:.4} {:+.4}  SW {:+.3}  relief {:.4}  \
                 depth changed {:.1}%  layout {:.3}  RGB NN-cos {:+.4}{}",
                arm.label(),
                record.seconds(),
                first.depth_nn_cos,
                d.depth_nn_cos,
                d.depth_sw,
                d.relief_energy,
                100.0 * d.depth_change,
                d.layout,
                d.rgb_nn_cos,
                record.collapse.as_deref().map_or(String::new(), |c| format!("  COLLAPSE {c}"))
            )
        });
        records.push(record);
    }
    bar.finish_and_clear();
    Ok(GeometryRun {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        scene: scene_path.display().to_string(),
        gaussians: scene.len(),
        sizes: sizes.clone(),
        wall_s: started.elapsed().as_secs_f64(),
        records,
    })
}

/// Fits the study's scene from the dataset's photos (the fern), into `out/fern.ply`.
fn fit_scene(
    sizes: &GeometrySizes,
    dataset: &Path,
    out: &Path,
    fit: &dyn Fn(&Path, &Path, u32) -> anyhow::Result<()>,
) -> anyhow::Result<PathBuf> {
    let path = out.join("fern.ply");
    if path.exists() {
        println!("geometry study: using the scene fitted earlier, {}", path.display());
        return Ok(path);
    }
    println!(
        "geometry study: no --scene given; fitting one from {} ({} iterations at 504 px)",
        dataset.display(),
        sizes.fit_iterations
    );
    fit(dataset, &path, sizes.fit_iterations)
        .with_context(|| format!("fitting the geometry study's scene from {}", dataset.display()))?;
    Ok(path)
}

/// The file stem of a style path.
fn style_name(path: &str) -> String {
    Path::new(path).file_stem().map_or_else(|| path.to_string(), |s| s.to_string_lossy().into_owned())
}

/// The measures of `now` (mean over the views), with `matched` the colour-matched renders of the same views.
fn measure(vgg: &Vgg, matched: &[Render], now: &[Render], refs: &StyleRefs) -> GeometryMeasures {
    let n = now.len().max(1) as f32;
    let mut m = GeometryMeasures::default();
    for (before, after) in matched.iter().zip(now) {
        let (h, w) = (after.height as usize, after.width as usize);
        let rgb: Vec<f32> = after.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        let f = vgg.features(&rgb, h, w);
        let depth = depth_structure::depth_style_distance(vgg, after, &refs.depth);
        let colour = CoveredColour::of(&after.rgb, &after.alpha);
        m.depth_nn_cos += depth.nn_cos / n;
        m.depth_sw += depth.sw / n;
        m.relief_energy += depth_structure::relief_energy(before, after) / n;
        m.layout += depth_structure::layout_correlation(before, after) / n;
        m.depth_change += inverse_depth_change(&before.inv_depth, &after.inv_depth, &before.alpha, &after.alpha) / n;
        m.rgb_nn_cos += nn_cosine_distance(&f.data, &refs.rgb.data, f.c) / n;
        m.rgb_mean_std += mean_std_distance(&f.data, &refs.rgb.data, f.c) / n;
        m.luminance += colour.luminance / n;
        m.chroma += colour.chroma / n;
    }
    m
}
