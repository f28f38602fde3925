//! Where a stylized scene's darkening comes from: which Gaussians the views
//! show before and after, what colour the newly shown ones have, how far
//! each group moved, and the covered luminance of renders that undo one kind
//! of change at a time (the means put back, the other geometry put back, the
//! newly shown Gaussians hidden).
//!
//! The collapse study found the object's covered luminance falling to a
//! fraction of the colour-matched state's over long runs, with frozen means
//! keeping it (frozen opacity, scales or rotations not). The renders tell the
//! possible causes apart: colours turned dark (putting the colours back gives
//! the brightness back), Gaussians that were hidden brought forward (hiding
//! the newly shown ones does), a porous object (alpha on its footprint falls),
//! or the means reordering Gaussians that were shown all along (only putting
//! the means back does; the case on guitar × block2, README).
//!
//! Usage: `cargo run --release -p gast-core --example collapse_probe -- SCENE STYLE STYLIZED [WEIGHTS]`
//! (STYLIZED: `stylized.ply` of `gast stylize` on SCENE × STYLE; the weights
//! default to `$GAST_SHARED/data/weights/vgg19-conv3.safetensors`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use gast_core::camera::{OrbitOptions, orbit_cameras};
use gast_core::eval::CoveredColour;
use gast_core::raster::{self, RenderOptions};
use gast_core::scene::{Gaussians, SH_C0};
use gast_core::session::{Session, SessionInputs, StyleDepthSource, StyleImage};
use gast_core::style::StyleConfig;
use gast_core::vision::Vgg;
use gast_core::vision::weights::VggWeights;

/// Rec. 709 luminance of Gaussian `i`'s base (DC) colour, clamped as rendered.
fn dc_luminance(g: &Gaussians, i: usize) -> f32 {
    let sh = &g.sh[i * g.sh_coeffs() * 3..];
    let c = |ch: usize| (0.5 + SH_C0 * sh[ch]).clamp(0.0, 1.0);
    0.2126 * c(0) + 0.7152 * c(1) + 0.0722 * c(2)
}

fn mean(v: impl Iterator<Item = f32>) -> f32 {
    let (s, n) = v.fold((0.0f64, 0usize), |(s, n), x| (s + f64::from(x), n + 1));
    if n == 0 { f32::NAN } else { (s / n as f64) as f32 }
}

fn quantile(mut v: Vec<f32>, q: f32) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    v.sort_by(f32::total_cmp);
    v[((v.len() - 1) as f32 * q).round() as usize]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, style, stylized, rest @ ..] = args.as_slice() else {
        return Err("usage: collapse_probe SCENE STYLE STYLIZED [WEIGHTS]".into());
    };
    let weights = match rest.first() {
        Some(w) => PathBuf::from(w),
        None => PathBuf::from(std::env::var("GAST_SHARED").unwrap_or_else(|_| "../shared".into()))
            .join("data/weights/vgg19-conv3.safetensors"),
    };
    let vgg = Arc::new(Vgg::from_weights(VggWeights::load(&weights)?));
    let g0 = gast_core::scene::load(Path::new(scene))?;
    let after = gast_core::scene::load(Path::new(stylized))?;
    if after.len() != g0.len() {
        return Err(format!("{stylized}: {} Gaussians, the scene has {}", after.len(), g0.len()).into());
    }
    let cameras = orbit_cameras(
        &g0.means,
        &OrbitOptions { count: 36, width: 256, height: 256, fov_y_degrees: 50.0, ..OrbitOptions::default() },
    );
    let inputs = SessionInputs {
        scene: std::sync::Arc::new(g0.clone()),
        cameras: cameras.clone(),
        style: StyleImage::open(Path::new(style))?,
        style_depth: StyleDepthSource::Heuristic,
        vgg,
        config: StyleConfig { resolution: 256, ..StyleConfig::default() },
        gpu: None,
    };
    let session = Session::prepare_with_style(inputs, None, &mut |_| {})?;
    let before = session.colour_matched();
    let opts = RenderOptions::default();
    let n = before.len();

    // Which Gaussians some view shows, before and after.
    let shown = |g: &Gaussians| {
        let mut any = vec![false; n];
        for cam in &cameras {
            for (a, s) in any.iter_mut().zip(raster::contributing(g, cam, &opts)) {
                *a |= s;
            }
        }
        any
    };
    let (was, is) = (shown(&before), shown(&after));
    let extent = {
        let c: [f32; 3] = std::array::from_fn(|k| mean(before.means.iter().map(|m| m[k])));
        quantile(before.means.iter().map(|m| (0..3).map(|k| (m[k] - c[k]).powi(2)).sum::<f32>().sqrt()).collect(), 0.9)
    };
    let moved =
        |i: usize| (0..3).map(|k| (after.means[i][k] - before.means[i][k]).powi(2)).sum::<f32>().sqrt() / extent;
    let groups: [(&str, Vec<usize>); 4] = [
        ("shown before and after", (0..n).filter(|&i| was[i] && is[i]).collect()),
        ("shown after only (surfaced)", (0..n).filter(|&i| !was[i] && is[i]).collect()),
        ("shown before only (hidden)", (0..n).filter(|&i| was[i] && !is[i]).collect()),
        ("never shown", (0..n).filter(|&i| !was[i] && !is[i]).collect()),
    ];
    println!("{stylized}: {n} Gaussians, 36 orbit views at 256 px, extent (90% radius) {extent:.4}");
    println!("| group | count | DC luminance before | after | moved / extent: median | 90% | opacity before | after |");
    println!("|---|---|---|---|---|---|---|---|");
    let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
    for (name, idx) in &groups {
        let moves: Vec<f32> = idx.iter().map(|&i| moved(i)).collect();
        println!(
            "| {name} | {} | {:.3} | {:.3} | {:.4} | {:.4} | {:.3} | {:.3} |",
            idx.len(),
            mean(idx.iter().map(|&i| dc_luminance(&before, i))),
            mean(idx.iter().map(|&i| dc_luminance(&after, i))),
            quantile(moves.clone(), 0.5),
            quantile(moves, 0.9),
            mean(idx.iter().map(|&i| sigmoid(before.opacity_logits[i]))),
            mean(idx.iter().map(|&i| sigmoid(after.opacity_logits[i]))),
        );
    }

    // Do dark Gaussians move out and bright ones in? The shown ones split at
    // their median base luminance in `G^c`; displacement along the direction
    // from the scene's centre (outward positive), over the extent.
    let centre: [f32; 3] = std::array::from_fn(|k| mean(before.means.iter().map(|m| m[k])));
    let outward = |i: usize| {
        let d: [f32; 3] = std::array::from_fn(|k| before.means[i][k] - centre[k]);
        let len = d.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
        (0..3).map(|k| (after.means[i][k] - before.means[i][k]) * d[k] / len).sum::<f32>() / extent
    };
    let shown_both = &groups[0].1;
    let median_lum = quantile(shown_both.iter().map(|&i| dc_luminance(&before, i)).collect(), 0.5);
    println!();
    println!("| shown before and after | count | DC luminance | outward move / extent: mean | median |");
    println!("|---|---|---|---|---|");
    for (name, dark) in [("darker half", true), ("brighter half", false)] {
        let idx: Vec<usize> =
            shown_both.iter().copied().filter(|&i| (dc_luminance(&before, i) < median_lum) == dark).collect();
        let out: Vec<f32> = idx.iter().map(|&i| outward(i)).collect();
        println!(
            "| {name} | {} | {:.3} | {:+.5} | {:+.5} |",
            idx.len(),
            mean(idx.iter().map(|&i| dc_luminance(&before, i))),
            mean(out.iter().copied()),
            quantile(out, 0.5),
        );
    }

    // Covered luminance of renders that undo one kind of change at a time,
    // and their mean alpha over the pixels the colour-matched render covers
    // (alpha ≥ 0.5): below 1 where the object turned porous.
    let reference: Vec<raster::Render> = cameras.iter().map(|cam| raster::render(&before, cam, &opts)).collect();
    let footprint: Vec<Vec<bool>> = reference.iter().map(|r| r.alpha.iter().map(|&a| a >= 0.5).collect()).collect();
    let measure_renders = |renders: &[raster::Render]| {
        let (mut l, mut a) = (Vec::new(), Vec::new());
        for (r, on) in renders.iter().zip(&footprint) {
            l.push(CoveredColour::of(&r.rgb, &r.alpha).luminance);
            a.push(mean(r.alpha.iter().zip(on).filter(|(_, on)| **on).map(|(&a, _)| a)));
        }
        (mean(l.into_iter()), mean(a.into_iter()))
    };
    let measure = |g: &Gaussians| {
        let renders: Vec<raster::Render> = cameras.iter().map(|cam| raster::render(g, cam, &opts)).collect();
        measure_renders(&renders)
    };
    let mut means_back = after.clone();
    means_back.means.clone_from(&before.means);
    let mut shape_back = before.clone();
    shape_back.means.clone_from(&after.means);
    shape_back.sh.clone_from(&after.sh);
    let mut colours_back = after.clone();
    colours_back.sh.clone_from(&before.sh);
    let mut surfaced_hidden = after.clone();
    for &i in &groups[1].1 {
        surfaced_hidden.opacity_logits[i] = -30.0;
    }
    let (base, base_alpha) = measure_renders(&reference);
    println!();
    println!("| render | covered luminance | / colour-matched | alpha on the colour-matched footprint |");
    println!("|---|---|---|---|");
    println!("| colour-matched | {base:.4} | 1.000 | {base_alpha:.3} |");
    for (name, g) in [
        ("stylized", &after),
        ("stylized, means put back", &means_back),
        ("stylized, opacity, scales and rotations put back", &shape_back),
        ("stylized, colours put back", &colours_back),
        ("stylized, surfaced Gaussians hidden", &surfaced_hidden),
    ] {
        let (l, a) = measure(g);
        println!("| {name} | {l:.4} | {:.3} | {a:.3} |", l / base);
    }
    Ok(())
}
