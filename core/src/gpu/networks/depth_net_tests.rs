//! The GPU depth network against the golden file and against the CPU
//! network, with every scratch buffer starting as NaN.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::vision::depth::dpt::Resize;
use crate::vision::depth::ops::{Conv, Linear};
use crate::vision::depth::weights::Checkpoint;
use crate::vision::depth::{BackboneConfig, DepthConfig};
use crate::vision::weights::tests::shared;

/// Largest |a − b| and largest |b|.
fn worst(a: &[f32], b: &[f32]) -> (f32, f32) {
    assert_eq!(a.len(), b.len(), "output lengths differ");
    let err = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    (err, b.iter().fold(0f32, |m, v| m.max(v.abs())))
}

#[test]
fn golden_forward_matches_on_the_gpu() {
    let Some(p) = shared("golden/depth/depth_seed1.safetensors") else { return };
    let net = DepthAnything::load_with_metadata_config(&p).expect("golden network");
    let ck = Checkpoint::read(&p).expect("golden file");
    let x = ck.take("input_pixel_values", &[1, 3, 70, 98]).expect("input");
    let expected = ck.take("out_predicted_depth", &[1, 70, 98]).expect("output");
    let ctx = ctx();
    let mut gpu = GpuDepthNet::new(ctx, net);
    gpu.poison_scratch();
    // 36 tokens: one head at a time, queries in blocks of 27 and 9.
    gpu.limit_score_block(1000);
    let out = gpu.forward(ctx, &x, 70, 98).expect("GPU forward");
    let cpu = gpu.cpu().forward(&x, 70, 98);
    let (err, max_ref) = worst(&out, &expected);
    let (cpu_err, _) = worst(&cpu, &expected);
    println!("golden: GPU error {err:.3e}, CPU error {cpu_err:.3e}, largest |reference| {max_ref:.3e}");
    assert!(out.iter().all(|v| v.is_finite()), "non-finite output");
    assert!(max_ref > 0.0 && err <= 1e-4 * max_ref, "max abs error {err} against max |ref| {max_ref}");
}

/// A network small enough for lavapipe at the full 518-px input, with every
/// kind of layer the published ones have (the four reassemble factors,
/// stages from several layers, the final norm), and the metric head.
fn tiny_config() -> DepthConfig {
    DepthConfig {
        backbone_config: BackboneConfig {
            hidden_size: 32,
            num_hidden_layers: 4,
            num_attention_heads: 2,
            out_indices: Some(vec![1, 2, 3, 4]),
            ..BackboneConfig::default()
        },
        reassemble_hidden_size: 32,
        neck_hidden_sizes: vec![8, 16, 24, 32],
        fusion_hidden_size: 16,
        head_hidden_size: 8,
        // The metric head (sigmoid × max_depth) gives every pixel a value to
        // compare; the golden test covers the relative one (ReLU).
        depth_estimation_type: "metric".into(),
        max_depth: Some(20.0),
        ..DepthConfig::default()
    }
}

/// Scales every weight of a random network (±0.05) to unit gain, so its
/// signals neither vanish nor saturate: the attention is far from uniform
/// and the head's output varies from pixel to pixel (at ±0.05 it is its bias
/// everywhere, clamped to 0 by the final ReLU).
fn unit_gain(net: &mut DepthAnything) {
    let gain = |fan_in: usize| 3f32.sqrt() / (0.05 * (fan_in as f32).sqrt());
    let lin = |l: &mut Linear| {
        let g = gain(l.inp);
        l.w.iter_mut().for_each(|v| *v *= g);
    };
    let conv = |c: &mut Conv| {
        let g = gain(c.c_in * c.k * c.k);
        *c = Conv::new(c.w.iter().map(|v| v * g).collect(), c.b.clone(), c.c_in, c.k, c.stride, c.pad);
    };
    let (vit, dpt) = net.parts_mut();
    lin(&mut vit.patch);
    for l in &mut vit.layers {
        for x in [&mut l.qkv, &mut l.output, &mut l.fc1, &mut l.fc2] {
            lin(x);
        }
    }
    for r in &mut dpt.reassemble {
        lin(&mut r.projection);
        match &mut r.resize {
            Resize::Up(u) => {
                let g = gain(u.c_in);
                u.w.iter_mut().for_each(|v| *v *= g);
            }
            Resize::Same => {}
            Resize::Down(c) => conv(c),
        }
    }
    dpt.convs.iter_mut().for_each(conv);
    for f in &mut dpt.fusion {
        for c in [&mut f.residual1.conv1, &mut f.residual1.conv2, &mut f.residual2.conv1, &mut f.residual2.conv2] {
            conv(c);
        }
        lin(&mut f.projection);
    }
    conv(&mut dpt.head1);
    conv(&mut dpt.head2);
    lin(&mut dpt.head3);
}

#[test]
fn gpu_estimate_equals_the_cpu_one_on_a_non_square_image() {
    // 47 × 61: neither side a multiple of 14; the network sees 406 × 518.
    let (h, w) = (47, 61);
    let rgb: Vec<f32> = noise(h * w * 3, 9).iter().map(|v| 0.5 + 0.45 * v).collect();
    let ctx = ctx();
    let mut net = DepthAnything::random(tiny_config(), 2).expect("random network");
    unit_gain(&mut net);
    let mut gpu = GpuDepthNet::new(ctx, net);
    gpu.poison_scratch();
    let cpu = gpu.cpu().depth_image(&rgb, h, w);
    let got = gpu.depth_image(ctx, &rgb, h, w).expect("GPU depth");
    assert_eq!((got.height, got.width), (406, 518));
    assert_eq!((got.height, got.width), (cpu.height, cpu.width));
    let (err, max_ref) = worst(&got.values, &cpu.values);
    let min = cpu.values.iter().fold(f32::INFINITY, |m, &v| m.min(v));
    println!("406×518: GPU against CPU {err:.3e}, CPU depth in [{min:.3}, {max_ref:.3}]");
    assert!(got.values.iter().all(|v| v.is_finite()), "non-finite output");
    assert!(max_ref - min > 0.1 * max_ref, "the random network's depth is nearly flat: a vacuous comparison");
    assert!(err <= 1e-4 * max_ref, "max abs error {err} against max |CPU| {max_ref}");
}
