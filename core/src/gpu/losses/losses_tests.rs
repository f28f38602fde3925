//! The GPU losses against their CPU twins at odd sizes, with every output and
//! scratch buffer pre-filled with noise.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::style::outside::{Outside, outside_loss};
use crate::style::regularizers::{depth_l1, l2_distance, mean_square_distance};
use crate::style::tv::tv_loss_masked;

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

/// The focus of an `h × w` pixel mask, its counts computed here (the cells are unused).
fn focus_of(ctx: &GpuContext, h: usize, w: usize, mask: &[bool]) -> crate::gpu::GpuFocus {
    let f = crate::gpu::GpuFocus::frame(ctx, h, w, 1, 1);
    let pairs_h = (0..h * w).filter(|&p| p % w + 1 < w && mask[p] && mask[p + 1]).count();
    let pairs_v = (0..h * w).filter(|&p| p / w + 1 < h && mask[p] && mask[p + w]).count();
    let on: Vec<f32> = mask.iter().map(|&v| f32::from(u8::from(v))).collect();
    ctx.write(f.pixels(), &on);
    ctx.write(f.counts(), &[1.0, pairs_h as f32, pairs_v as f32, 0.0]);
    f
}

#[test]
fn tv_matches_the_cpu_at_odd_sizes() {
    let ctx = ctx();
    let kernels = LossKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    let cases = [(13usize, 17usize, 3usize, false), (1, 9, 3, false), (31, 1, 1, false), (64, 45, 3, false)];
    let masked = [(2, 2, 1, false), (13, 17, 3, true), (64, 45, 3, true), (1, 9, 3, true)];
    for (s, &(h, w, c, masked)) in cases.iter().chain(&masked).enumerate() {
        let seed = 200 + s as u64;
        let mask: Vec<bool> = noise(h * w, seed + 3).iter().map(|&v| !masked || v > -0.5).collect();
        let focus = focus_of(ctx, h, w, &mask);
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
        tv.record(ctx, &mut enc, &img_buf, &focus, &grad, &scalars);
        ctx.submit(enc);
        let (want, g) = tv_loss_masked(&img, h, w, c, masked.then_some(mask.as_slice()));
        let got: Vec<f32> = ctx.read(&scalars).expect("read");
        let v = ctx.read::<f32>(&grad).expect("read");
        check(&format!("TV {h}×{w}×{c} masked {masked}"), got[3], want, &v, &before, &g, weight);
        for (e, (&a, &b)) in v.iter().zip(&before).enumerate() {
            assert!(mask[e / c] || a == b, "TV {h}×{w}×{c}: element {e} is outside the mask");
        }
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

#[test]
fn the_parameter_mean_square_matches_the_cpu() {
    let ctx = ctx();
    let kernels = LossKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    let gaussians = 1000;
    let scalars = ctx.upload("scalars", &[0.0f32; 4]);
    let mut enc = ctx.encoder("param mean square");
    let mut cases = Vec::new();
    for (k, (per, offset)) in [(1usize, 0usize), (3, 1), (4, 3)].into_iter().enumerate() {
        let len = gaussians * per;
        let x_ref = noise(len, 700 + k as u64);
        let x: Vec<f32> = x_ref.iter().zip(noise(len, 800 + k as u64)).map(|(a, b)| a + 0.1 * b).collect();
        let weight = 1.0 + k as f32;
        let plan = RefLoss::param_mean_square(ctx, &kernels, &reduce, len, gaussians, weight, offset).expect("plan");
        scratch_noise(ctx, &plan.plan, len);
        let before = noise(len, 900 + k as u64);
        let grad = ctx.upload("grad", &before);
        let (xb, rb) = (ctx.upload("x", &x), ctx.upload("x_ref", &x_ref));
        plan.record(ctx, &mut enc, &xb, &rb, &grad, &scalars);
        cases.push((plan, x, x_ref, before, grad, offset, weight, per, xb, rb));
    }
    ctx.submit(enc);
    let got: Vec<f32> = ctx.read(&scalars).expect("read");
    for (_, x, x_ref, before, grad, offset, weight, per, _, _) in &cases {
        let (want, g) = mean_square_distance(x, x_ref, *per);
        let what = format!("parameter mean square of {} floats at offset {offset}", x.len());
        check(&what, got[*offset], want, &ctx.read::<f32>(grad).expect("read"), before, &g, *weight);
    }
}

#[test]
fn the_background_hold_matches_the_cpu() {
    let ctx = ctx();
    let kernels = LossKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    for (s, (h, w, share)) in
        [(1usize, 1usize, 1.0f32), (13, 17, 0.4), (64, 45, 0.9), (5, 7, -1.0)].into_iter().enumerate()
    {
        let seed = 400 + s as u64;
        let n = h * w;
        let held: Vec<bool> = noise(n, seed).iter().map(|&v| v < 2.0 * share - 1.0).collect();
        let img: Vec<f32> = noise(3 * n, seed + 1).iter().map(|v| 0.5 + 0.5 * v).collect();
        let target: Vec<f32> = noise(3 * n, seed + 2).iter().map(|v| 0.5 + 0.5 * v).collect();
        let weight = 30.0;
        let hold = RefLoss::hold(ctx, &kernels, &reduce, n, weight, 2).expect("plan");
        scratch_noise(ctx, &hold.plan, 3 * n);
        let before = noise(3 * n, seed + 3);
        let grad = ctx.upload("grad", &before);
        let scalars = ctx.upload("scalars", &noise(6, seed + 4));
        let (img_buf, reference) =
            (ctx.upload("img", &img), ctx.upload("ref", &RefLoss::hold_reference(&target, &held)));
        let mut enc = ctx.encoder("hold test");
        hold.record(ctx, &mut enc, &img_buf, &reference, &grad, &scalars);
        ctx.submit(enc);
        let (want, g) = outside_loss(&img, Outside { mask: &held, rgb: &target });
        let value = ctx.read::<f32>(&scalars).expect("scalars")[2];
        let got = ctx.read::<f32>(&grad).expect("grad");
        check(&format!("hold {h}×{w}"), value, want, &got, &before, &g, weight);
    }
}
