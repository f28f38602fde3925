//! The whole GPU step loss against the CPU's ([`crate::style::step::step_loss_masked`])
//! with the object focus, and an all-ones focus against the whole frame, on
//! a random VGG and noise maps.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::style::focus::coverage_mask;
use crate::style::step::{content_target, step_loss_masked};
use crate::vision::vgg::tests::random_vgg;

/// The maps, style, content image, reference depth and alpha of one test view.
struct Inputs {
    vgg: Vgg,
    style: StyleTargets,
    rgb: Vec<f32>,
    inv_depth: Vec<f32>,
    edge: Vec<f32>,
    content: Vec<f32>,
    depth_ref: Vec<f32>,
    alpha: Vec<f32>,
    h: usize,
    w: usize,
}

fn inputs() -> Inputs {
    let (h, w) = (48, 40);
    let vgg = random_vgg(5);
    let unit = |len: usize, seed: u64| -> Vec<f32> { noise(len, seed).iter().map(|v| 0.5 + 0.45 * v).collect() };
    let (sh, sw) = (32, 28);
    let edge_of = |len: usize, seed: u64| -> Vec<f32> {
        noise(len, seed).iter().map(|&v| f32::from(u8::from(v > 0.6))).collect()
    };
    let style = StyleTargets::new(&vgg, &unit(sh * sw * 3, 1), &unit(sh * sw, 2), &edge_of(sh * sw, 3), sh, sw);
    // A soft blob off the centre with a ragged rim: about a third of the frame covered.
    let wobble = noise(h * w, 9);
    let alpha = (0..h * w)
        .map(|p| {
            let (y, x) = ((p / w) as f32 / h as f32 - 0.45, (p % w) as f32 / w as f32 - 0.55);
            (1.6 - 3.5 * (x * x + y * y).sqrt() + 0.2 * wobble[p]).clamp(0.0, 1.0)
        })
        .collect();
    Inputs {
        style,
        rgb: unit(h * w * 3, 4),
        inv_depth: noise(h * w, 5).iter().map(|v| 0.4 + 0.2 * v).collect(),
        edge: edge_of(h * w, 6),
        content: unit(h * w * 3, 7),
        depth_ref: noise(h * w, 8).iter().map(|v| 0.4 + 0.2 * v).collect(),
        alpha,
        vgg,
        h,
        w,
    }
}

/// Differences between two losses: values (relative `tol`), gradients (`tol`
/// of the largest) and the matches, each as a line.
fn differences(what: &str, a: &StepLoss, b: &StepLoss, tol: f32) -> Vec<String> {
    let mut off = Vec::new();
    for (name, x, y) in [
        ("gcfm", a.terms.gcfm, b.terms.gcfm),
        ("content", a.terms.content, b.terms.content),
        ("tv", a.terms.tv, b.terms.tv),
        ("depth", a.terms.depth, b.terms.depth),
        ("sliced", a.terms.sliced, b.terms.sliced),
        ("sliced depth", a.terms.sliced_depth, b.terms.sliced_depth),
        ("total", a.terms.total, b.terms.total),
    ] {
        if (x - y).abs() > tol * x.abs().max(1e-6) {
            off.push(format!("{what} {name}: {x} vs {y}"));
        }
    }
    for (name, x, y) in [("v_rgb", &a.v_rgb, &b.v_rgb), ("v_inv_depth", &a.v_inv_depth, &b.v_inv_depth)] {
        let largest = x.iter().fold(0f32, |m, v| m.max(v.abs()));
        let err = x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0f32, f32::max);
        if err > tol * largest {
            off.push(format!("{what} {name}: off by {err}, largest {largest}"));
        }
    }
    if a.matches != b.matches {
        off.push(format!("{what}: the matches differ"));
    }
    off
}

#[test]
fn the_object_focus_gives_the_cpu_masked_loss_and_all_ones_the_frame() {
    let ctx = ctx();
    let t = inputs();
    let k = StepLossKernels::new(ctx, &t.vgg);
    let (h, w) = (t.h, t.w);
    let maps = RenderedMaps { rgb: &t.rgb, inv_depth: &t.inv_depth, edge: &t.edge, height: h, width: w };
    // The paper's terms and both sliced terms (λ_swd where the depth's gradient is taken).
    let weights = LossWeights { sliced: 10.0, sliced_depth: 10.0, ..Default::default() };
    let target = content_target(&t.vgg, &t.content, h, w);
    let mask = coverage_mask(&t.alpha, h, w);
    let on = mask.iter().filter(|&&v| v).count();
    assert!(on > h * w / 8 && on < h * w / 2, "the test blob covers {on} of {} pixels", h * w);
    let mut failures = Vec::new();
    for depth_grad in [true, false] {
        let dref = depth_grad.then_some(t.depth_ref.as_slice());
        let cpu = step_loss_masked(&t.vgg, &t.style, maps, Some(&target), dref, &weights, depth_grad, Some(&mask));
        let gpu = step_loss_gpu(ctx, &k, &t.style, maps, Some(&t.content), dref, &weights, depth_grad, Some(&t.alpha))
            .expect("GPU loss");
        assert!(cpu.terms.sliced > 0.0 && (cpu.terms.sliced_depth > 0.0) == depth_grad, "{:?}", cpu.terms);
        failures.extend(differences(&format!("object focus, depth grad {depth_grad}:"), &cpu, &gpu, 1e-3));
        // Every position matched on the GPU lies in the focus, as on the CPU.
        assert!(gpu.matches.best.contains(&u32::MAX) && gpu.matches.best.iter().any(|&m| m != u32::MAX));

        // An all-ones focus is the whole frame, on both devices.
        let ones = vec![1.0f32; h * w];
        let frame =
            step_loss_gpu(ctx, &k, &t.style, maps, Some(&t.content), dref, &weights, depth_grad, None).expect("GPU");
        let all = step_loss_gpu(ctx, &k, &t.style, maps, Some(&t.content), dref, &weights, depth_grad, Some(&ones))
            .expect("GPU");
        failures.extend(differences(&format!("GPU all-ones vs frame, depth grad {depth_grad}:"), &frame, &all, 0.0));
        let cpu_frame = step_loss_masked(&t.vgg, &t.style, maps, Some(&target), dref, &weights, depth_grad, None);
        failures.extend(differences(&format!("frame CPU vs GPU, depth grad {depth_grad}:"), &cpu_frame, &frame, 1e-3));
        // The focus changes the loss (the test would pass vacuously otherwise).
        assert!(
            (cpu_frame.terms.gcfm - cpu.terms.gcfm).abs() > 1e-3 * cpu.terms.gcfm.abs(),
            "focus and frame give the same GCFM"
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// VGG on the object's window gives the whole frame's loss, gradients and
/// matches (and the CPU's, which windows too), on a frame where the window
/// is about half of it.
#[test]
fn the_vgg_window_gives_the_whole_frames_loss() {
    let ctx = ctx();
    let t = inputs();
    let (h, w) = (192, 160);
    let unit = |len: usize, seed: u64| -> Vec<f32> { noise(len, seed).iter().map(|v| 0.5 + 0.45 * v).collect() };
    let (rgb, content) = (unit(h * w * 3, 14), unit(h * w * 3, 17));
    let inv_depth: Vec<f32> = noise(h * w, 15).iter().map(|v| 0.4 + 0.2 * v).collect();
    let depth_ref: Vec<f32> = noise(h * w, 18).iter().map(|v| 0.4 + 0.2 * v).collect();
    let edge: Vec<f32> = noise(h * w, 16).iter().map(|&v| f32::from(u8::from(v > 0.6))).collect();
    // A small blob off the centre: a tenth of the frame.
    let alpha: Vec<f32> = (0..h * w)
        .map(|p| {
            let (y, x) = ((p / w) as f32 / h as f32 - 0.4, (p % w) as f32 / w as f32 - 0.6);
            (1.8 - 10.0 * (x * x + y * y).sqrt()).clamp(0.0, 1.0)
        })
        .collect();
    let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
    let weights = LossWeights { sliced: 10.0, sliced_depth: 10.0, ..Default::default() };
    let k = StepLossKernels::new(ctx, &t.vgg);

    // The plan's window: about half the frame's feature cells.
    let mut gstyle = GpuStyle::new(ctx, &t.style.features);
    gstyle.upload_sliced(ctx, &t.style.features, &weights);
    let mut plan = StepLossPlan::new(ctx, &k, &gstyle, h, w, &weights).expect("plan");
    let mut enc = ctx.encoder("test.focus");
    let focus = plan.record_focus(ctx, &k, &mut enc, &ctx.upload("alpha", &alpha)).expect("focus");
    ctx.submit(enc);
    let covered = focus.covered_mask(ctx).expect("cells");
    let (fh, fw) = plan.feature_size();
    let b = crate::style::window::covered_box(&covered, fh, fw).expect("a covered box");
    plan.fit_window(ctx, &k, b);
    let size = plan.window_size().expect("a window");
    let share = size.share(fh, fw);
    assert!(share > 0.2 && share < 0.7, "the window is {size:?} of {fh}×{fw}");

    let target = content_target(&t.vgg, &content, h, w);
    let mask = coverage_mask(&alpha, h, w);
    let mut failures = Vec::new();
    for depth_grad in [true, false] {
        let dref = depth_grad.then_some(depth_ref.as_slice());
        let run = |window| {
            step_loss_gpu_windowed(
                ctx,
                &k,
                &t.style,
                maps,
                Some(&content),
                dref,
                &weights,
                depth_grad,
                Some(&alpha),
                window,
            )
            .expect("GPU loss")
        };
        let (windowed, whole) = (run(true), run(false));
        // With the window, the whole frame's VGG ran only for the content
        // target (on the edge map's state, its scratch): the RGB and depth
        // maps' whole-frame activations were never made.
        assert_eq!(windowed.1.whole_frame_activations(), [false, false, true]);
        assert_eq!(whole.1.whole_frame_activations(), [true, true, true]);
        let (windowed, whole) = (windowed.0, whole.0);
        failures.extend(differences(&format!("window vs frame, depth grad {depth_grad}:"), &whole, &windowed, 1e-5));
        let cpu = step_loss_masked(&t.vgg, &t.style, maps, Some(&target), dref, &weights, depth_grad, Some(&mask));
        failures.extend(differences(&format!("window vs CPU, depth grad {depth_grad}:"), &cpu, &windowed, 1e-3));
        // Pixels far outside the window get no gradient either way.
        assert!(windowed.v_rgb[..3 * w].iter().all(|&g| g == 0.0), "the top row has a gradient");
        assert!(windowed.v_rgb.iter().any(|&g| g != 0.0), "no gradient at all");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
