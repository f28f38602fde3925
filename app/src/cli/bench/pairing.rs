//! `gast bench pairing`: the assignment terms' host pairing part by part, on
//! the columns a step draws (the render's and the style's VGG relu3 features
//! of real views), the work the GPU engine's step waits for.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use gast_core::style::FeatureNet;
use gast_core::style::assignment::{ASSIGN_MAX, PairCosts, draw_pairs_seeded};
use gast_core::style::focus::{feature_mask, gather_positions};
use gast_core::style::min_cost::{assign_min_cost, assign_shortest_paths, assignment_cost};

use super::median;
use crate::views::{Framing, ViewArgs, load_scene, views_for};

/// Arguments of `gast bench pairing`.
#[derive(Args, Debug)]
pub struct PairingArgs {
    #[command(flatten)]
    pub data: super::BenchData,
    /// Working resolution (longer side, pixels): the render VGG sees is half of it.
    #[arg(long, default_value_t = 512)]
    pub resolution: u32,
    /// Orbit views, each fitted to the object; one pairing problem drawn per view and repeat.
    #[arg(long, default_value_t = 4)]
    pub views: usize,
    /// Draws per view (each a fresh set of rendered and style positions).
    #[arg(long, default_value_t = 3)]
    pub draws: usize,
    /// The style's texture scale (its height in pixels, as `gast stylize --texture-scale`).
    #[arg(long, default_value_t = 256)]
    pub texture_scale: u32,
    /// Pair by squared distance (λ_as alone) instead of by cosine (λ_asc on, the default recipe).
    #[arg(long)]
    pub squared: bool,
    /// Also write the medians to this JSON file (for `tools/gpu-check`).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Renders the views, computes the features the step pairs (the object's
/// covered positions, as the object focus draws them) and times the pairing's
/// parts on each draw; prints the medians.
pub fn run_pairing(args: PairingArgs) -> anyhow::Result<ExitCode> {
    let (scene_path, style_path, weights) = args.data.paths();
    let scene = load_scene(&scene_path)?;
    let style = gast_core::session::StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    let vgg = super::super::stylize::load_vgg(weights.as_deref())?;
    let views = views_for(
        &scene,
        &ViewArgs {
            cameras: None,
            views: args.views.max(1),
            size: args.resolution,
            fov: 50.0,
            framing: Framing::Object,
            crop: false,
        },
    )?;
    let maps = gast_core::style::style_maps(
        &style.rgb,
        style.height,
        style.width,
        args.texture_scale.max(16) as usize,
        &gast_core::vision::relief_depth::ReliefDepth::default(),
        Default::default(),
    );
    let style_f = FeatureNet::features(&vgg, &maps.rgb, maps.height, maps.width);
    let (channels, m) = (style_f.channels, style_f.height * style_f.width);
    println!(
        "pairing benchmark: {} against {} (texture scale {}, {m} style positions), {} views at {} px, \
         {} draws each, {} channels, by {}, {} threads",
        scene_path.display(),
        style_path.display(),
        args.texture_scale,
        views.len(),
        args.resolution,
        args.draws,
        channels,
        if args.squared { "squared distance" } else { "cosine distance" },
        rayon::current_num_threads()
    );

    let opts = gast_core::raster::RenderOptions::default();
    let (mut cost_ms, mut assign_ms, mut pull_ms, mut total_ms) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut plain_ms, mut ratios, mut rows_paired, mut same) = (Vec::new(), Vec::new(), Vec::new(), 0usize);
    for (v, cam) in views.iter().enumerate() {
        let render = gast_core::raster::render(&scene, cam, &opts);
        let (h, w) = (render.height as usize, render.width as usize);
        let (half, sh, sw) = gast_core::vision::resize::downscale_half(&render.rgb, h, w, 3);
        let f = FeatureNet::features(&vgg, &half, sh, sw);
        let n = f.height * f.width;
        let object: Vec<bool> = render.alpha.iter().map(|&a| a >= 0.5).collect();
        let cells = feature_mask(&object, h, w, f.height, f.width);
        let covered: Vec<usize> = (0..n).filter(|&i| cells[i]).collect();
        for d in 0..args.draws.max(1) {
            let (rows, targets) = draw_pairs_seeded((v * 1000 + d) as u64, covered.clone(), m);
            let x = gather_positions(&f.data, channels, n, &rows);
            let s = gather_positions(&style_f.data, channels, m, &targets);
            let t0 = Instant::now();
            let costs = PairCosts::new(&x, &s, channels, !args.squared);
            let t1 = Instant::now();
            let sigma = assign_min_cost(&costs.cost, costs.r, costs.r);
            let t2 = Instant::now();
            let pulled = if args.squared {
                costs.pull(&x, &s, &sigma, 0.0, 1.0)
            } else {
                costs.pull(&x, &s, &sigma, 10.0, 0.015)
            };
            let t3 = Instant::now();
            std::hint::black_box(pulled);
            // The plain shortest augmenting paths on the same matrix, after
            // (with the matrix in cache: a bias in their favour).
            let t4 = Instant::now();
            let plain = assign_shortest_paths(&costs.cost, costs.r, costs.r);
            let t5 = Instant::now();
            let total = |s: &[usize]| assignment_cost(&costs.cost, costs.r, s);
            let (a, b) = (total(&sigma), total(&plain));
            if (a - b).abs() > 1e-9 * b.abs().max(1.0) {
                anyhow::bail!("view {v}, draw {d}: the assignment costs {a}, the plain shortest paths' {b}");
            }
            same += usize::from(sigma == plain);
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            cost_ms.push(ms(t0, t1));
            assign_ms.push(ms(t1, t2));
            pull_ms.push(ms(t2, t3));
            total_ms.push(ms(t0, t3));
            plain_ms.push(ms(t4, t5));
            ratios.push(ms(t1, t2) / ms(t4, t5).max(1e-9));
            rows_paired.push(costs.r as f64);
        }
    }
    let draws = total_ms.len();
    let json = serde_json::json!({
        "resolution": args.resolution,
        "draws": draws,
        "threads": rayon::current_num_threads(),
        "rows_median": median(rows_paired.clone()),
        "same_assignment": same,
        "cost_ms": median(cost_ms.clone()),
        "assign_ms": median(assign_ms.clone()),
        "pull_ms": median(pull_ms.clone()),
        "pairing_ms": median(total_ms.clone()),
        "plain_ms": median(plain_ms.clone()),
        "assign_over_plain": median(ratios.clone()),
    });
    println!("rows paired a draw: median {:.0} (at most {ASSIGN_MAX})", median(rows_paired));
    println!("the same assignment as the plain shortest paths in {same} of {draws} draws (the same cost in all)");
    println!("{:<34} {:>10}", "part (median of every draw)", "ms");
    for (name, v) in [
        ("cost matrix (product, norms)", cost_ms),
        ("least-cost assignment", assign_ms),
        ("both pulls and the gradient", pull_ms),
        ("the pairing in all", total_ms),
        ("plain shortest paths (reference)", plain_ms),
    ] {
        println!("{name:<34} {:>10.2}", median(v));
    }
    println!("assignment / plain shortest paths, same matrix: median ratio {:.3}", median(ratios));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&json)?;
        gast_core::io::write_bytes(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}
