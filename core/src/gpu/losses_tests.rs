//! The GPU losses against their CPU twins at odd sizes, with every output and
//! scratch buffer pre-filled with noise.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::style::regularizers::{depth_l1, l2_distance};
use crate::style::tv::tv_loss;

/// Checks a term's value (relative 1e-4) and its accumulated gradient
/// (`before + λ·g`, within 1e-3 of the largest `λ·g`).
fn check(what: &str, value: f32, want: f32, grad: &[f32], before: &[f32], g: &[f32], weight: f32) {
    assert!((value - want).abs() <= 1e-4 * want.abs().max(1e-6), "{what}: value {value} vs CPU {want}");
    let largest = g.iter().fold(0.0f32, |m, v| m.max((weight * v).abs()));
    let mut bad = Vec::new();
    for i in 0..g.len() {
        let w = before[i] + weight * g[i];
        if (grad[i] - w).abs() > 1e-3 * largest {
            bad.push(format!("{i}: {} vs {w}", grad[i]));
        }
    }
    assert!(bad.is_empty(), "{what}: {} gradients differ:\n{}", bad.len(), bad.join("\n"));
}

fn scratch_noise(ctx: &GpuContext, plan: &LossPlan, len: usize) {
    ctx.write(&plan.scratch, &noise(len, 77));
}

#[test]
fn tv_matches_the_cpu_at_odd_sizes() {
    let ctx = ctx();
    let kernels = LossKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    for (s, &(h, w, c)) in
        [(13usize, 17usize, 3usize), (1, 9, 3), (31, 1, 1), (64, 45, 3), (2, 2, 1)].iter().enumerate()
    {
        let seed = 200 + s as u64;
        let img: Vec<f32> = noise(h * w * c, seed).iter().map(|v| 0.5 + 0.5 * v).collect();
        let weight = 0.02;
        let tv = TvLoss::new(ctx, &kernels, &reduce, h, w, c, weight, 3).expect("plan");
        scratch_noise(ctx, &tv.0, 2 * h * w * c);
        let before = noise(h * w * c, seed + 1);
        let grad = ctx.upload("grad", &before);
        let scalars_init = noise(6, seed + 2);
        let scalars = ctx.upload("scalars", &scalars_init);
        let img_buf = ctx.upload("img", &img);
        let mut enc = ctx.encoder("tv test");
        tv.record(ctx, &mut enc, &img_buf, &grad, &scalars);
        ctx.submit(enc);
        let (want, g) = tv_loss(&img, h, w, c);
        let got: Vec<f32> = ctx.read(&scalars).expect("read");
        check(&format!("TV {h}×{w}×{c}"), got[3], want, &ctx.read::<f32>(&grad).expect("read"), &before, &g, weight);
        let others: Vec<usize> = vec![0, 1, 2, 4, 5];
        assert!(others.iter().all(|&i| got[i] == scalars_init[i]), "TV wrote outside its offset");
    }
}

#[test]
fn depth_l1_matches_the_cpu_with_ties() {
    let ctx = ctx();
    let kernels = LossKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    for (s, &n) in [1usize, 37 * 23, 4099].iter().enumerate() {
        let seed = 300 + s as u64;
        let d = noise(n, seed);
        let mut d_ref = noise(n, seed + 1);
        for i in (0..n).step_by(7) {
            d_ref[i] = d[i];
        }
        let weight = 10.0;
        let l1 = RefLoss::depth_l1(ctx, &kernels, &reduce, n, weight, 0).expect("plan");
        scratch_noise(ctx, &l1.plan, n);
        let before = noise(n, seed + 2);
        let grad = ctx.upload("grad", &before);
        let scalars = ctx.upload("scalars", &noise(2, seed + 3));
        let (d_buf, r_buf) = (ctx.upload("d", &d), ctx.upload("d_ref", &d_ref));
        let mut enc = ctx.encoder("depth l1 test");
        l1.record(ctx, &mut enc, &d_buf, &r_buf, &grad, &scalars);
        ctx.submit(enc);
        let (want, g) = depth_l1(&d, &d_ref);
        let got: Vec<f32> = ctx.read(&scalars).expect("read");
        check(&format!("depth L1 n={n}"), got[0], want, &ctx.read::<f32>(&grad).expect("read"), &before, &g, weight);
    }
}

#[test]
fn parameter_regularisers_match_the_cpu_and_vanish_at_zero() {
    let ctx = ctx();
    let kernels = LossKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    let gaussians = 1001;
    let mut scalars_init = noise(4, 9);
    scalars_init[2] = 0.0;
    let scalars = ctx.upload("scalars", &scalars_init);
    let mut enc = ctx.encoder("regulariser test");
    let mut cases = Vec::new();
    // Opacity (1 per Gaussian), log-scales (3), quaternions (4) into offsets 0, 1, 3;
    // a fourth, unmoved array into offset 2 has a zero norm.
    for (k, (per, offset, moved)) in
        [(1usize, 0usize, true), (3, 1, true), (4, 3, true), (3, 2, false)].into_iter().enumerate()
    {
        let len = gaussians * per;
        let x_ref = noise(len, 400 + k as u64);
        let x: Vec<f32> = if moved {
            x_ref.iter().zip(noise(len, 500 + k as u64)).map(|(a, b)| a + 0.01 * b).collect()
        } else {
            x_ref.clone()
        };
        let weight = 1.0 + k as f32;
        let plan = RefLoss::param_l2(ctx, &kernels, &reduce, len, weight, offset).expect("plan");
        scratch_noise(ctx, &plan.plan, len);
        let before = noise(len, 600 + k as u64);
        let grad = ctx.upload("grad", &before);
        let (xb, rb) = (ctx.upload("x", &x), ctx.upload("x_ref", &x_ref));
        plan.record(ctx, &mut enc, &xb, &rb, &grad, &scalars);
        cases.push((plan, x, x_ref, before, grad, offset, weight, xb, rb));
    }
    ctx.submit(enc);
    let got: Vec<f32> = ctx.read(&scalars).expect("read");
    for (_, x, x_ref, before, grad, offset, weight, _, _) in &cases {
        let (want, g) = l2_distance(x, x_ref);
        let what = format!("parameter L2 of {} floats at offset {offset}", x.len());
        check(&what, got[*offset], want, &ctx.read::<f32>(grad).expect("read"), before, &g, *weight);
    }
    assert_eq!(got[2], 0.0, "an unmoved array has a zero norm");
}
