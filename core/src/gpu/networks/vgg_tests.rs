//! The GPU VGG against the CPU one: features and input gradient, random
//! weights and inputs, odd and even sizes, one or many im2col bands.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::vision::vgg::tests::random_vgg;

/// Largest |a − b| and largest |b|.
fn worst(a: &[f32], b: &[f32]) -> (f32, f32) {
    assert_eq!(a.len(), b.len());
    let err = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    (err, b.iter().fold(0f32, |m, v| m.max(v.abs())))
}

/// Overwrites every scratch and state buffer with noise, so a kernel that
/// relies on zeroed memory fails.
fn poison(ctx: &GpuContext, ws: &GpuVggWorkspace, state: &GpuVggState, seed: u64) {
    let bufs: Vec<&wgpu::Buffer> =
        [&ws.cols, &ws.ping, &ws.pong, &state.features].into_iter().chain(state.acts(ctx).iter()).collect();
    for (i, b) in bufs.into_iter().enumerate() {
        ctx.write(b, &noise((b.size() / 4) as usize, seed + i as u64));
    }
}

#[test]
fn features_and_input_gradient_match_the_cpu_vgg() {
    let ctx = ctx();
    let cpu = random_vgg(3);
    let gpu = GpuVgg::new(ctx, &cpu);
    let mut report = Vec::new();
    let mut failures = Vec::new();
    // (h, w, im2col band limit): the last case forces several bands in every layer.
    for (h, w, band) in [(20, 28, BAND_ELEMS), (32, 32, BAND_ELEMS), (21, 18, 18 * 27 * 7)] {
        let rgb: Vec<f32> = noise(h * w * 3, h as u64).iter().map(|v| 0.5 + 0.45 * v).collect();
        let (f_cpu, s_cpu) = cpu.forward(&rgb, h, w);
        let v = noise(f_cpu.data.len(), 7 + w as u64);
        let g_cpu = cpu.backward(&s_cpu, &v);

        let ws = gpu.workspace_banded(ctx, h, w, band);
        let state = GpuVggState::new(ctx, h, w);
        poison(ctx, &ws, &state, 100);
        let input = ctx.upload("input", &rgb);
        let v_buf = ctx.upload("v", &v);
        let v_input = ctx.upload("v_input", &noise(h * w * 3, 5));
        let mut enc = ctx.encoder("vgg test");
        gpu.forward(ctx, &mut enc, &ws, &input, &state);
        gpu.backward(ctx, &mut enc, &ws, &state, &v_buf, &v_input);
        ctx.submit(enc);
        let f_gpu: Vec<f32> = ctx.read(state.features()).expect("features");
        let g_gpu: Vec<f32> = ctx.read(&v_input).expect("input gradient");
        assert_eq!(state.feature_size(), (f_cpu.h, f_cpu.w));

        let (fe, fmax) = worst(&f_gpu, &f_cpu.data);
        let (ge, gmax) = worst(&g_gpu, &g_cpu);
        let bands = ws.layers[1].bands.len();
        report.push(format!(
            "{h}×{w} ({bands} bands at conv1_2): features err {fe:.2e} (max {fmax:.2}), gradient err {ge:.2e} (max {gmax:.2e})"
        ));
        if fe >= 1e-4 * fmax.max(1.0) {
            failures.push(format!("{h}×{w}: features differ by {fe} (largest {fmax})"));
        }
        if ge >= 1e-3 * gmax {
            failures.push(format!("{h}×{w}: input gradients differ by {ge} (largest {gmax})"));
        }
    }
    println!("{}", report.join("\n"));
    assert!(failures.is_empty(), "{}\n{}", failures.join("\n"), report.join("\n"));
}
