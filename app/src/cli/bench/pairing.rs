//! `gast bench pairing`: the assignment terms' host pairing part by part, on
//! the columns a step draws (the render's and the style's VGG relu3 features
//! of real views), the work the GPU engine's step waits for.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use gast_core::style::FeatureNet;
use gast_core::style::assignment::{ASSIGN_BLOCK, ASSIGN_MAX, PairCosts, draw_pairs_seeded};
use gast_core::style::focus::{feature_mask, gather_positions};
use gast_core::style::min_cost::{assign_shortest_paths, assignment_cost};

use super::median;
use crate::views::{Framing, ViewArgs, load_scene, views_for};

/// Arguments of `gast bench pairing`.
#[derive(Args, Debug)]
pub struct PairingArgs {
    #[command(flatten)]
    pub data: super::BenchData,
    /// Working resolution (longer side, pixels, 16 to 4,096): the render VGG sees is half of it.
    #[arg(long, default_value_t = 512, value_parser = crate::views::within(gast_core::style::RESOLUTIONS))]
    pub resolution: u32,
    /// Orbit views, each fitted to the object; one pairing problem drawn per view and repeat (1 to 3,600).
    #[arg(long, default_value_t = 4, value_parser = crate::views::view_count::<usize>())]
    pub views: usize,
    /// Draws per view, at least one (each a fresh set of rendered and style positions).
    #[arg(long, default_value_t = 3, value_parser = crate::views::at_least_one::<usize>)]
    pub draws: usize,
    /// The style's texture scale (its height in pixels, 16 to 4,096, as `gast stylize --texture-scale`).
    #[arg(long, default_value_t = 256, value_parser = crate::views::within(gast_core::style::TEXTURE_SCALES))]
    pub texture_scale: u32,
    /// Pair by squared distance (λ_as alone) instead of by cosine (λ_asc on, the default recipe).
    #[arg(long)]
    pub squared: bool,
    /// Most rows of one least-cost block, as `gast stylize --assign-block` (the pairing is also
    /// timed in one block of every row, the way it was made before 2026-11-30, on the same draws).
    #[arg(long, default_value_t = ASSIGN_BLOCK, value_parser = crate::views::within(16..=ASSIGN_MAX))]
    pub assign_block: usize,
    /// Also write the medians to this JSON file (for `tools/gpu-check`).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Renders the views, computes the features the step pairs (the object's
/// covered positions, as the object focus draws them) and times the pairing's
/// parts on each draw; prints the medians.
pub fn run_pairing(args: PairingArgs) -> anyhow::Result<ExitCode> {
    if let Some(path) = &args.json {
        crate::cli::replaceable_json(path, "--json")?;
    }
    let (scene_path, style_path, weights) = args.data.paths()?;
    let scene = load_scene(&scene_path)?;
    let style = gast_core::session::StyleImage::open(&style_path).map_err(anyhow::Error::msg)?;
    let vgg = super::super::stylize::load_vgg(weights.as_deref())?;
    let views = views_for(
        &scene,
        &ViewArgs {
            cameras: None,
            orbit: false,
            views: args.views,
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
        args.texture_scale as usize,
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
    // Each draw's figures: [cost, assignment, pulls, in all] for the blocks
    // and for one block of every row, and the mean cost of a pair.
    let mut parts = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
    let mut whole = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
    let (mut pair_cost, mut whole_pair_cost, mut drawn_pair_cost) = (Vec::new(), Vec::new(), Vec::new());
    let (mut plain_ms, mut ratios, mut rows_paired, mut blocks, mut same) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), 0usize);
    let (cw, lw) = if args.squared { (0.0, 1.0) } else { (10.0, 0.015) };
    let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
    for (v, cam) in views.iter().enumerate() {
        let render = gast_core::raster::render(&scene, cam, &opts);
        let (h, w) = (render.height as usize, render.width as usize);
        let (half, sh, sw) = gast_core::vision::resize::downscale_half(&render.rgb, h, w, 3);
        let f = FeatureNet::features(&vgg, &half, sh, sw);
        let n = f.height * f.width;
        let object: Vec<bool> = render.alpha.iter().map(|&a| a >= 0.5).collect();
        let cells = feature_mask(&object, h, w, f.height, f.width);
        let covered: Vec<usize> = (0..n).filter(|&i| cells[i]).collect();
        for d in 0..args.draws {
            let (rows, targets) = draw_pairs_seeded((v * 1000 + d) as u64, covered.clone(), m);
            let x = gather_positions(&f.data, channels, n, &rows);
            let s = gather_positions(&style_f.data, channels, m, &targets);
            let r = rows.len();
            // The pairing as a step makes it, then in one block of every row.
            let timed = |block: usize, out: &mut [Vec<f64>; 4]| {
                let t0 = Instant::now();
                let costs = PairCosts::new(&x, &s, channels, !args.squared, block);
                let t1 = Instant::now();
                let sigma = costs.assign();
                let t2 = Instant::now();
                std::hint::black_box(costs.pull(&x, &s, &sigma, cw, lw));
                let t3 = Instant::now();
                for (o, t) in out.iter_mut().zip([ms(t0, t1), ms(t1, t2), ms(t2, t3), ms(t0, t3)]) {
                    o.push(t);
                }
                (costs, sigma)
            };
            let (costs, sigma) = timed(args.assign_block, &mut parts);
            let (one, best) = timed(r.max(1), &mut whole);
            let r_f = r.max(1) as f64;
            pair_cost.push(costs.total(&sigma) / r_f);
            whole_pair_cost.push(one.total(&best) / r_f);
            drawn_pair_cost.push(one.total(&(0..r).collect::<Vec<_>>()) / r_f);
            blocks.push(costs.blocks.len() as f64);
            // The plain shortest augmenting paths on the one block's matrix,
            // after (with the matrix in cache: a bias in their favour).
            let matrix = &one.blocks[0].cost;
            let t4 = Instant::now();
            let plain = assign_shortest_paths(matrix, r, r);
            let t5 = Instant::now();
            let (a, b) = (assignment_cost(matrix, r, &best), assignment_cost(matrix, r, &plain));
            if (a - b).abs() > 1e-9 * b.abs().max(1.0) {
                anyhow::bail!("view {v}, draw {d}: the assignment costs {a}, the plain shortest paths' {b}");
            }
            same += usize::from(best == plain);
            plain_ms.push(ms(t4, t5));
            ratios.push(whole[1].last().copied().unwrap_or(0.0) / ms(t4, t5).max(1e-9));
            rows_paired.push(r as f64);
        }
    }
    let draws = plain_ms.len();
    let med = |v: &Vec<f64>| median(v.clone());
    let json = serde_json::json!({
        "resolution": args.resolution,
        "draws": draws,
        "threads": rayon::current_num_threads(),
        "rows_median": med(&rows_paired),
        "assign_block": args.assign_block,
        "blocks_median": med(&blocks),
        "same_assignment": same,
        "cost_ms": med(&parts[0]),
        "assign_ms": med(&parts[1]),
        "pull_ms": med(&parts[2]),
        "pairing_ms": med(&parts[3]),
        "one_block_cost_ms": med(&whole[0]),
        "one_block_assign_ms": med(&whole[1]),
        "one_block_pull_ms": med(&whole[2]),
        "one_block_pairing_ms": med(&whole[3]),
        "pair_cost": med(&pair_cost),
        "one_block_pair_cost": med(&whole_pair_cost),
        "drawn_pair_cost": med(&drawn_pair_cost),
        "plain_ms": med(&plain_ms),
        "assign_over_plain": med(&ratios),
    });
    println!(
        "rows paired a draw: median {:.0} (at most {ASSIGN_MAX}), in {:.0} blocks of at most {} (median)",
        med(&rows_paired),
        med(&blocks),
        args.assign_block
    );
    println!(
        "one block: the same assignment as the plain shortest paths in {same} of {draws} draws (the same cost in all)"
    );
    let distance = if args.squared { "squared distance" } else { "1 − cos" };
    println!(
        "{:<36} {:>14} {:>12}",
        "part (median of every draw)",
        format!("blocks of {}", args.assign_block),
        "one block"
    );
    for (name, t) in [
        ("cost matrices (product, norms), ms", 0),
        ("least-cost assignment, ms", 1),
        ("both pulls and the gradient, ms", 2),
        ("the pairing in all, ms", 3),
    ] {
        println!("{name:<36} {:>14.2} {:>12.2}", med(&parts[t]), med(&whole[t]));
    }
    println!(
        "{:<36} {:>14.4} {:>12.4}   (the draw's own pairing: {:.4})",
        format!("mean cost of a pair ({distance})"),
        med(&pair_cost),
        med(&whole_pair_cost),
        med(&drawn_pair_cost)
    );
    println!(
        "one block: plain shortest paths (reference) {:.2} ms, Jonker–Volgenant / plain on the same matrix: median ratio {:.3}",
        med(&plain_ms),
        med(&ratios)
    );
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&json)?;
        gast_core::io::write_bytes(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}
