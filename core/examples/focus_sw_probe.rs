//! What the focus study's object measures reward, without any optimisation:
//! the colour-matched scene `G^c` of a scene × style pair is measured on the
//! fitted evaluation ring as it is, darkened (every colour scaled by k) and
//! with its colours pulled towards their mean (less contrast), and the sliced
//! Wasserstein distance, its parts ([`gast_core::eval::sliced`]) and the
//! nearest-neighbour cosine distance on the object are printed for each.
//!
//! The study found frame focus lowering SW on the object more than object
//! focus while object focus lowered NN-cos more, and frame focus darkening
//! the object. If darkening alone lowers SW by as much as a frame run does,
//! and leaves NN-cos where it was, SW is reading brightness, not style.
//!
//! The renders' background is black, as in the study; with
//! `GAST_PROBE_BACKGROUND=style` (the style image's mean colour) or `=R,G,B`
//! the ring is rendered over that colour instead, to see how much of what SW
//! reads comes from the object's rim against black.
//!
//! Usage: `cargo run --release -p gast-core --example focus_sw_probe -- SCENE STYLE [WEIGHTS]`
//! (the weights default to `$GAST_SHARED/data/weights/vgg19-conv3.safetensors`).

use std::path::PathBuf;
use std::sync::Arc;

use gast_core::camera::{OrbitOptions, orbit_cameras};
use gast_core::eval::{EvalOptions, Evaluator, Measures};
use gast_core::scene::{Gaussians, SH_C0};
use gast_core::session::{Session, SessionInputs, StyleDepthSource, StyleImage};
use gast_core::style::{Focus, StyleConfig};
use gast_core::vision::Vgg;
use gast_core::vision::weights::VggWeights;

/// Every rendered colour `c` becomes `mean + k·(c − mean)` per channel, `mean`
/// the DC colours' mean over the scene (`k < 1`: less contrast), then is scaled
/// by `dim` (`dim < 1`: darker). Higher SH bands scale with both.
fn recolour(g: &Gaussians, dim: f32, k: f32) -> Gaussians {
    let mut out = g.clone();
    let stride = g.sh_coeffs() * 3;
    let n = g.len().max(1) as f32;
    let mean: [f32; 3] =
        std::array::from_fn(|ch| (0..g.len()).map(|i| SH_C0 * g.sh[i * stride + ch] + 0.5).sum::<f32>() / n);
    for i in 0..g.len() {
        let sh = &mut out.sh[i * stride..(i + 1) * stride];
        for ch in 0..3 {
            let c = SH_C0 * sh[ch] + 0.5;
            sh[ch] = (dim * (mean[ch] + k * (c - mean[ch])) - 0.5) / SH_C0;
        }
        sh[3..].iter_mut().for_each(|v| *v *= dim * k);
    }
    out
}

/// The background `GAST_PROBE_BACKGROUND` asks for: unset, black; `style`,
/// the style image's mean colour; else `R,G,B` in 0–1.
fn background(style: &StyleImage) -> Result<[f32; 3], Box<dyn std::error::Error>> {
    match std::env::var("GAST_PROBE_BACKGROUND").ok().as_deref() {
        None | Some("") => Ok([0.0; 3]),
        Some("style") => {
            let n = (style.rgb.len() / 3).max(1) as f32;
            Ok(std::array::from_fn(|ch| {
                style.rgb.iter().skip(ch).step_by(3).map(|&v| v as f32).sum::<f32>() / n / 255.0
            }))
        }
        Some(s) => {
            let v: Vec<f32> = s.split(',').map(|t| t.trim().parse::<f32>()).collect::<Result<_, _>>()?;
            let [r, g, b] = v.as_slice() else {
                return Err(format!("GAST_PROBE_BACKGROUND: expected `style` or R,G,B, found {s:?}").into());
            };
            Ok([*r, *g, *b])
        }
    }
}

fn line(label: &str, m: &Measures, base: &Measures) -> String {
    format!(
        "{label:<24} SW {:.4} (Δ {:+.4})  mean {:.4}  shape {:.4}  unit {:.4}  NN {:.4} (Δ {:+.4})  length {:.3}  luminance {:.3}",
        m.sliced_wasserstein_object,
        base.sliced_wasserstein_object - m.sliced_wasserstein_object,
        m.sliced_wasserstein_object_mean,
        m.sliced_wasserstein_object_shape,
        m.sliced_wasserstein_object_unit,
        m.nn_cosine_object,
        base.nn_cosine_object - m.nn_cosine_object,
        m.feature_norm_object,
        m.colour.luminance,
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, style, rest @ ..] = args.as_slice() else {
        return Err("usage: focus_sw_probe SCENE STYLE [WEIGHTS]".into());
    };
    let weights = match rest.first() {
        Some(w) => PathBuf::from(w),
        None => PathBuf::from(std::env::var("GAST_SHARED").unwrap_or_else(|_| "../shared".into()))
            .join("data/weights/vgg19-conv3.safetensors"),
    };
    let vgg = Arc::new(Vgg::from_weights(VggWeights::load(&weights)?));
    let (g, _) = gast_core::scene::load_with_warnings(std::path::Path::new(scene))?;
    // The focus study's frame arm: 36 orbit views at 128 px.
    let config = StyleConfig { resolution: 128, focus: Focus::Frame, ..StyleConfig::default() };
    let cameras = orbit_cameras(
        &g.means,
        &OrbitOptions { count: 36, width: 128, height: 128, fov_y_degrees: 50.0, ..OrbitOptions::default() },
    );
    let style_image = StyleImage::open(std::path::Path::new(style))?;
    let background = background(&style_image)?;
    let inputs = SessionInputs {
        scene: std::sync::Arc::new(g),
        cameras,
        style: style_image,
        style_depth: StyleDepthSource::Heuristic,
        vgg: Arc::clone(&vgg),
        config,
        gpu: None,
    };
    let session = Session::prepare_with_style(inputs, None, &mut |_| {})?;
    let gc = &session.colour_matched();
    let eval = Evaluator::new(
        vgg,
        &session.style().targets.features,
        gc,
        &EvalOptions { fit_to_object: true, background, ..EvalOptions::default() },
    );
    let base = eval.measure_reference();
    println!("{scene} × {style}, fitted ring at 192 px over {background:.3?}, object positions");
    println!("{}", line("colour-matched", &base, &base));
    for dim in [0.9f32, 0.8, 0.7] {
        println!("{}", line(&format!("darkened ×{dim}"), &eval.measure(&recolour(gc, dim, 1.0)), &base));
    }
    for k in [0.8f32, 0.6] {
        println!("{}", line(&format!("contrast ×{k}"), &eval.measure(&recolour(gc, 1.0, k)), &base));
    }
    Ok(())
}
