//! The image operations chained as one step chains them (`session/run.rs` and
//! `style/step.rs` on the CPU), with stand-ins for VGG's input gradients: the
//! three downscaled maps, the image-space gradients and the loss scalars of
//! the GPU chain against the CPU's, in one encoder with nothing read back
//! until the end.

use super::{
    CannyKernels, Clamp01, DepthMap, DepthMapKernels, Downscale, EdgeMap, LossKernels, ReduceKernels, RefLoss,
    ResizeKernels, TvLoss,
};
use crate::gpu::test_util::{ctx, noise};
use crate::style::regularizers::depth_l1;
use crate::style::step::{min_max_backward, replicate3};
use crate::style::tv::tv_loss;
use crate::vision::canny::render_edges;
use crate::vision::resize::{downscale_half, downscale_half_backward};

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn the_maps_and_image_gradients_of_a_step_match_the_cpu() {
    let ctx = ctx();
    let (h, w) = (37usize, 51usize);
    let (n, sn) = (h * w, (h / 2) * (w / 2));
    let (lambda_tv, lambda_depth) = (0.02f32, 10.0f32);
    // A render a little outside [0, 1] (the clamp acts), its inverse depth and the reference's.
    let raw: Vec<f32> = noise(3 * n, 1).iter().map(|v| 0.5 + 0.7 * v).collect();
    let inv_depth: Vec<f32> = noise(n, 2).iter().map(|v| 0.4 + 0.3 * v).collect();
    let depth_ref: Vec<f32> = noise(n, 3).iter().map(|v| 0.4 + 0.3 * v).collect();
    // Stand-ins for VGG's input gradients of the RGB and depth maps.
    let v_small_rgb = noise(3 * sn, 4);
    let v_small_depth = noise(3 * sn, 5);

    // CPU, as run.rs and step_loss do it.
    let rgb: Vec<f32> = raw.iter().map(|v| v.clamp(0.0, 1.0)).collect();
    let edge = render_edges(&rgb, h, w);
    let (lo, hi) = inv_depth.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let depth_n: Vec<f32> = inv_depth.iter().map(|&x| (x - lo) / (hi - lo + 1e-8)).collect();
    let cpu_small: Vec<Vec<f32>> =
        [rgb.clone(), replicate3(&depth_n), replicate3(&edge)].iter().map(|m| downscale_half(m, h, w, 3).0).collect();
    let mut v_rgb = downscale_half_backward(&v_small_rgb, h, w, 3);
    let (tv, v_tv) = tv_loss(&rgb, h, w, 3);
    v_rgb.iter_mut().zip(&v_tv).for_each(|(a, b)| *a += lambda_tv * b);
    v_rgb.iter_mut().zip(&raw).filter(|(_, r)| !(0.0..=1.0).contains(*r)).for_each(|(g, _)| *g = 0.0);
    let v_depth3 = downscale_half_backward(&v_small_depth, h, w, 3);
    let v_n: Vec<f32> = v_depth3.chunks_exact(3).map(|p| p[0] + p[1] + p[2]).collect();
    let mut v_inv = min_max_backward(&inv_depth, &v_n, None);
    let (dl1, v_dl1) = depth_l1(&inv_depth, &depth_ref);
    v_inv.iter_mut().zip(&v_dl1).for_each(|(a, b)| *a += lambda_depth * b);

    // GPU: the same chain in one encoder, every output pre-filled with noise.
    let reduce = ReduceKernels::new(ctx);
    let resize = ResizeKernels::new(ctx);
    let losses = LossKernels::new(ctx);
    let clamp = Clamp01::new(ctx, &resize, 3 * n);
    let down = Downscale::new(ctx, &resize, h, w, 3);
    let depth_map = DepthMap::new(ctx, &DepthMapKernels::new(ctx), &reduce, h, w).expect("plan");
    let edges = EdgeMap::new(ctx, &CannyKernels::new(ctx), &reduce, h, w).expect("plan");
    let tv_term = TvLoss::new(ctx, &losses, &reduce, h, w, 3, lambda_tv, 0).expect("plan");
    let depth_term = RefLoss::depth_l1(ctx, &losses, &reduce, n, lambda_depth, 1).expect("plan");
    let buf = |label: &str, len: usize, seed: u64| ctx.upload(label, &noise(len, seed));
    let (raw_b, inv_b, ref_b) =
        (ctx.upload("raw", &raw), ctx.upload("inv_depth", &inv_depth), ctx.upload("depth_ref", &depth_ref));
    let (rgb_b, depth3_b, edge3_b) = (buf("rgb", 3 * n, 10), buf("depth3", 3 * n, 11), buf("edge3", 3 * n, 12));
    let small: Vec<wgpu::Buffer> = (0..3).map(|k| buf("small", 3 * sn, 20 + k)).collect();
    let (vs_rgb, vs_depth) = (ctx.upload("v_small_rgb", &v_small_rgb), ctx.upload("v_small_depth", &v_small_depth));
    let (v_rgb_b, v_depth3_b, v_inv_b) = (buf("v_rgb", 3 * n, 30), buf("v_depth3", 3 * n, 31), buf("v_inv", n, 32));
    let scalars = buf("scalars", 2, 33);
    let frame = crate::gpu::GpuFocus::frame(ctx, h, w, 1, 1);

    let mut enc = ctx.encoder("step chain");
    clamp.forward(ctx, &mut enc, &raw_b, &rgb_b);
    edges.record(ctx, &mut enc, &rgb_b, &edge3_b);
    depth_map.forward(ctx, &mut enc, &inv_b, frame.pixels(), &depth3_b);
    for (map, out) in [&rgb_b, &depth3_b, &edge3_b].into_iter().zip(&small) {
        down.forward(ctx, &mut enc, map, out);
    }
    down.backward(ctx, &mut enc, &vs_rgb, &v_rgb_b, false);
    tv_term.record(ctx, &mut enc, &rgb_b, &frame, &v_rgb_b, &scalars);
    clamp.backward(ctx, &mut enc, &raw_b, &v_rgb_b);
    down.backward(ctx, &mut enc, &vs_depth, &v_depth3_b, false);
    depth_map.backward(ctx, &mut enc, &inv_b, frame.pixels(), &v_depth3_b, &v_inv_b, false);
    depth_term.record(ctx, &mut enc, &inv_b, &ref_b, &v_inv_b, &scalars);
    ctx.submit(enc);

    for (k, name) in ["rgb", "depth", "edge"].iter().enumerate() {
        let got: Vec<f32> = ctx.read(&small[k]).expect("read");
        let err = max_abs(&got, &cpu_small[k]);
        assert!(err < 1e-4, "downscaled {name} map: max abs error {err}");
    }
    let got: Vec<f32> = ctx.read(&edge3_b).expect("read");
    assert_eq!(got, replicate3(&edge), "edge map");
    for (name, buf, want) in [("v_rgb", &v_rgb_b, &v_rgb), ("v_inv_depth", &v_inv_b, &v_inv)] {
        let got: Vec<f32> = ctx.read(buf).expect("read");
        let largest = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let err = max_abs(&got, want);
        assert!(err <= 1e-3 * largest, "{name}: max abs error {err}, largest {largest}");
    }
    let s: Vec<f32> = ctx.read(&scalars).expect("read");
    assert!((s[0] - tv).abs() <= 1e-4 * tv, "TV {} vs {tv}", s[0]);
    assert!((s[1] - dl1).abs() <= 1e-4 * dl1, "depth L1 {} vs {dl1}", s[1]);
}
