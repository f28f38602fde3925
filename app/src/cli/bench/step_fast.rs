//! `gast bench step --conv/--matching…`: issue 10's options timed step by step
//! beside the reference (im2col, exact matching) in one process, with FLOP
//! counts per stage against the gemm floor.

use std::process::ExitCode;

use super::memory_mib;
use super::step::{StepArgs, StepInputs, phase_rows, step_inputs};

/// Per-step breakdown of the optimisation for the reference settings and the
/// new ones side by side (steps interleaved, so both see the same machine
/// load), their ratio, FLOP counts per stage against the gemm floor, the
/// whole schedule's time, and memory.
pub(super) fn run_fast_step(args: StepArgs) -> anyhow::Result<ExitCode> {
    use gast_core::session::{Event, Session, SessionInputs, StepReport, StyleDepthSource};
    use gast_core::style::{MatchMethod, Phase, StyleConfig};

    let old_config = StyleConfig {
        resolution: args.resolution,
        focus: args.focus,
        conv: gast_core::vision::ConvAlgo::Im2col,
        vgg_window: false,
        ..StyleConfig::default()
    };
    // The new settings: today's defaults (Winograd, the cone) with the flags applied.
    let mut new_config = StyleConfig { resolution: args.resolution, focus: args.focus, ..StyleConfig::default() };
    args.fast.apply(&mut new_config);
    let new_config = crate::cli::checked(new_config)?;
    // (Checked above, before the scene, the style and VGG are loaded.)
    let StepInputs { scene, views, style, vgg } = step_inputs(&args)?;
    let (cam_h, cam_w) = (views[0].height as usize, views[0].width as usize);
    let mc = new_config.matching;
    let window = |on: bool| if on { "the object's cone" } else { "the whole frame" };
    println!(
        "old: conv im2col, matching exact, VGG on the whole frame | new: conv {}, matching {} (dims {}, candidates {}, reuse {}), VGG on {}",
        new_config.conv,
        mc.method,
        mc.dims,
        mc.candidates,
        mc.reuse,
        window(new_config.vgg_window)
    );
    let inputs = SessionInputs {
        scene,
        cameras: views,
        style,
        style_depth: StyleDepthSource::Heuristic,
        vgg: vgg.clone(),
        config: old_config.clone(),
        gpu: None,
    };
    let print_event = |label: &str, e: Event| match e {
        Event::Stage { name, seconds } => println!("  {label} prepare: {name:<20} {:>8.0} ms", seconds * 1e3),
        Event::Culled { total, kept } => println!("  {label} culling: optimising {kept} of {total} Gaussians"),
        _ => {}
    };
    let mut old = Session::prepare(inputs.clone(), &mut |e| print_event("old", e))?;
    let mut new = Session::prepare_with_style(
        SessionInputs { config: new_config.clone(), ..inputs },
        Some(old.style().clone()),
        &mut |e| print_event("new", e),
    )?;
    new.audit_matches(if mc.method == MatchMethod::Exact { 0 } else { 5 });
    for (label, session) in [("old", &mut old), ("new", &mut new)] {
        let warm = session.warm_view_targets().map_err(anyhow::Error::msg)?;
        println!("  {label} per-view targets (G^c render, content features), once per run: {:.0} ms", warm * 1e3);
    }
    if let Some(share) = new.vgg_work_share() {
        println!(
            "  new VGG work: {:.0}% of a whole-frame pass's multiply-adds on average over the views (focus {})",
            share * 100.0,
            if new.focus_on_object() { "object" } else { "frame" }
        );
    }

    let schedule = old_config.schedule();
    let budget = if args.full { schedule.total_steps() } else { schedule.color_steps + args.geometry_steps };
    let mut reports: [Vec<(StepReport, f64)>; 2] = [Vec::new(), Vec::new()];
    let mut wall_all = [0.0f64; 2];
    for _ in 0..budget {
        for (k, session) in [&mut old, &mut new].into_iter().enumerate() {
            let before = session.elapsed_s();
            let Some(r) = session.step() else { continue };
            let wall = (session.elapsed_s() - before) * 1e3;
            wall_all[k] += wall / 1e3;
            reports[k].push((r, wall));
        }
    }

    println!("\nper-step medians (ms), every view's targets computed before the timed steps");
    println!(
        "{:<16} {:>6} {:>8} {:>10} {:>9} {:>10} {:>10} {:>8} {:>9}",
        "phase", "steps", "render", "vgg fwd×3", "matching", "vgg bwd", "raster bwd", "adam", "step"
    );
    let rows = [phase_rows(&reports[0]), phase_rows(&reports[1])];
    for (label, table) in ["old", "new"].iter().zip(&rows) {
        for (phase, steps, r) in table {
            println!(
                "{:<16} {steps:>6} {:>8.1} {:>10.1} {:>9.1} {:>10.1} {:>10.1} {:>8.1} {:>9.1}",
                format!("{label} {}", format!("{phase:?}").to_lowercase()),
                r[0],
                r[1],
                r[2],
                r[3],
                r[4],
                r[5],
                r[6]
            );
        }
    }
    for ((phase, _, o), (_, _, n)) in rows[0].iter().zip(&rows[1]) {
        let ratio: Vec<String> = o.iter().zip(n).map(|(a, b)| format!("{:.2}", a / b.max(1e-9))).collect();
        println!(
            "{:<16} {:>6} {:>8} {:>10} {:>9} {:>10} {:>10} {:>8} {:>9}",
            format!("old/new {}", format!("{phase:?}").to_lowercase()),
            "",
            ratio[0],
            ratio[1],
            ratio[2],
            ratio[3],
            ratio[4],
            ratio[5],
            ratio[6]
        );
    }
    if let Some((b, w, k)) = new.match_agreement() {
        println!(
            "new matching: {:.1}% of nearest and {:.1}% of farthest matches identical to the exact search ({k} audited steps)",
            b * 100.0,
            w * 100.0
        );
    }

    // FLOPs per stage (geometry step) against the gemm floor.
    let side = (args.resolution / 2) as usize;
    let gemm = gast_core::vision::gemm_gflops(256, 64 * 64, 2304, 3);
    let (sh, sw) = (cam_h / 2, cam_w / 2);
    let fwd_direct = vgg.forward_flops(sh, sw);
    let new_vgg = (*vgg).clone().with_conv(new_config.conv);
    // VGG's work with the focus on the object: the cone of the covered positions.
    let fwd_new = new_vgg.executed_forward_flops(sh, sw) * f64::from(new.vgg_work_share().unwrap_or(1.0));
    // With the focus on the object only the covered positions are matched:
    // the mean covered share of the views stands for their number.
    let share = if old.focus_on_object() { f64::from(old.coverage()) } else { 1.0 };
    let (n, m) = (share * (sh / 4 * (sw / 4)) as f64, old.style().targets.features.positions() as f64);
    let d = 3.0 * gast_core::vision::vgg::FEATURE_CHANNELS as f64;
    let match_old = 2.0 * n * m * d;
    let match_new = match mc.method {
        MatchMethod::Exact => match_old,
        MatchMethod::Pca => {
            let l = f64::from(mc.dims).min(d);
            2.0 * n * d * l + 2.0 * n * m * l + 2.0 * 2.0 * f64::from(mc.candidates).min(m) * n * d
        }
    } / f64::from(mc.reuse.max(1));
    println!(
        "\nFLOPs of a geometry step (GFLOP; floor = at the measured gemm rate, {gemm:.0} GFLOP/s on 256×4096×2304; matching over {:.0}% of the positions, focus {}):",
        share * 100.0,
        if old.focus_on_object() { "object" } else { "frame" }
    );
    println!("{:<14} {:>10} {:>10} {:>10} {:>10}", "stage", "old GFLOP", "floor ms", "new GFLOP", "floor ms");
    for (name, o, nw) in [
        ("vgg fwd ×3", 3.0 * fwd_direct, 3.0 * fwd_new),
        ("matching", match_old, match_new),
        ("vgg bwd ×2", 2.0 * fwd_direct, 2.0 * fwd_new),
    ] {
        println!(
            "{name:<14} {:>10.2} {:>10.0} {:>10.2} {:>10.0}",
            o * 1e-9,
            o / gemm / 1e6,
            nw * 1e-9,
            nw / gemm / 1e6
        );
    }

    // One modality at the VGG input size, each convolution.
    for conv in gast_core::vision::ConvAlgo::ALL {
        let v = (*vgg).clone().with_conv(conv);
        println!("one modality, {conv}: {}", gast_core::vision::vgg::bench(&v, side, side, 3));
    }

    let (peak, rss) = memory_mib();
    for (k, label) in ["old", "new"].iter().enumerate() {
        if args.full {
            println!(
                "{label} whole schedule: {} steps in {:.1} s ({:.1} min)",
                reports[k].len(),
                wall_all[k],
                wall_all[k] / 60.0
            );
        } else {
            let per = |p: Phase| rows[k].iter().find(|r| r.0 == p).map_or(0.0, |r| r.2[6]);
            let est = (f64::from(schedule.cycles * schedule.color_steps) * per(Phase::Color)
                + f64::from(schedule.cycles * schedule.geometry_steps) * per(Phase::Geometry))
                / 1e3;
            println!(
                "{label} whole default schedule ({} colour + {} geometry steps), extrapolated from the medians: {:.0} s ({:.1} min)",
                schedule.cycles * schedule.color_steps,
                schedule.cycles * schedule.geometry_steps,
                est,
                est / 60.0
            );
        }
    }
    println!("memory: peak resident {peak:.0} MiB, now {rss:.0} MiB");
    Ok(ExitCode::SUCCESS)
}
