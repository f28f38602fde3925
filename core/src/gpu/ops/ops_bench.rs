//! Timings of the step's image operations and losses on the GPU, for `gast
//! bench step` to print beside the other parts of a step.
//!
//! Each operation is recorded `repeats` times into one encoder and submitted
//! once, after a warm-up run; the figure is the wall time to completion
//! divided by `repeats`, so it includes dispatch overhead, as a step pays it.

use std::time::Instant;

use super::Commands;
use super::{
    CannyKernels, Clamp01, DepthMap, DepthMapKernels, Downscale, EdgeMap, GpuContext, GpuError, LossKernels,
    ReduceKernels, RefLoss, ResizeKernels, TvLoss,
};

/// Records one call of an operation.
type Record<'a> = &'a dyn Fn(&mut dyn Commands);

/// Milliseconds per call of each image operation and loss at `side × side`
/// renders (one row per operation and size, labelled `"tv 256²"`), plus the
/// three parameter regularisers at `gaussians` Gaussians (500k is playbot's size).
pub fn bench_image_ops(
    ctx: &GpuContext,
    sides: &[usize],
    gaussians: usize,
    repeats: usize,
) -> Result<Vec<(String, f64)>, GpuError> {
    let repeats = repeats.max(1);
    let reduce = ReduceKernels::new(ctx);
    let resize = ResizeKernels::new(ctx);
    let depth_k = DepthMapKernels::new(ctx);
    let canny_k = CannyKernels::new(ctx);
    let loss_k = LossKernels::new(ctx);
    let time = |record: Record<'_>| -> Result<f64, GpuError> {
        let mut enc = ctx.encoder("bench warm-up");
        record(&mut enc);
        ctx.submit(enc);
        ctx.wait()?;
        let t = Instant::now();
        let mut enc = ctx.encoder("bench");
        for _ in 0..repeats {
            record(&mut enc);
        }
        ctx.submit(enc);
        ctx.wait()?;
        Ok(t.elapsed().as_secs_f64() * 1e3 / repeats as f64)
    };
    let mut rows = Vec::new();
    for &side in sides {
        let (h, w) = (side, side);
        let n = h * w;
        let ramp = |len: usize| -> Vec<f32> { (0..len).map(|i| ((i * 7919) % 1013) as f32 / 1013.0).collect() };
        let rgb = ctx.upload("bench.rgb", &ramp(3 * n));
        let depth = ctx.upload("bench.depth", &ramp(n));
        let depth_ref = ctx.upload("bench.depth_ref", &ramp(n).iter().rev().copied().collect::<Vec<_>>());
        let full3 = ctx.zeros("bench.full3", 3 * n);
        let v_full3 = ctx.upload("bench.v_full3", &ramp(3 * n));
        let small3 = ctx.zeros("bench.small3", 3 * (h / 2) * (w / 2));
        let v_small3 = ctx.upload("bench.v_small3", &ramp(3 * (h / 2) * (w / 2)));
        let v_depth = ctx.zeros("bench.v_depth", n);
        let scalars = ctx.zeros("bench.scalars", 8);

        let clamp = Clamp01::new(ctx, &resize, 3 * n);
        let down = Downscale::new(ctx, &resize, h, w, 3);
        let map = DepthMap::new(ctx, &depth_k, &reduce, h, w)?;
        let edges = EdgeMap::new(ctx, &canny_k, &reduce, h, w)?;
        let tv = TvLoss::new(ctx, &loss_k, &reduce, h, w, 3, 0.02, 0)?;
        let l1 = RefLoss::depth_l1(ctx, &loss_k, &reduce, n, 10.0, 1)?;
        let frame = crate::gpu::GpuFocus::frame(ctx, h, w, 1, 1);
        let ones = frame.pixels();
        let ops: [(&str, Record<'_>); 8] = [
            ("clamp fwd+bwd", &|e| {
                clamp.forward(ctx, e, &v_full3, &full3);
                clamp.backward(ctx, e, &rgb, &full3);
            }),
            ("downscale rgb fwd", &|e| down.forward(ctx, e, &rgb, &small3)),
            ("downscale rgb bwd", &|e| down.backward(ctx, e, &v_small3, &full3, false)),
            ("depth map fwd", &|e| map.forward(ctx, e, &depth, ones, &full3)),
            ("depth map bwd", &|e| map.backward(ctx, e, &depth, ones, &v_full3, &v_depth, false)),
            ("edge map", &|e| edges.record(ctx, e, &rgb, &full3)),
            ("tv", &|e| tv.record(ctx, e, &rgb, &frame, &full3, &scalars)),
            ("depth l1", &|e| l1.record(ctx, e, &depth, &depth_ref, &v_depth, &scalars)),
        ];
        for (name, record) in ops {
            rows.push((format!("{name} {side}²"), time(record)?));
        }
    }
    let len = gaussians.max(1);
    let x = ctx.upload("bench.x", &(0..4 * len).map(|i| (i % 97) as f32 * 0.01).collect::<Vec<_>>());
    let x_ref = ctx.zeros("bench.x_ref", 4 * len);
    let v_x = ctx.zeros("bench.v_x", 4 * len);
    let scalars = ctx.zeros("bench.scalars", 4);
    let regs = [1, 3, 4]
        .iter()
        .enumerate()
        .map(|(k, &per)| RefLoss::param_l2(ctx, &loss_k, &reduce, per * len, 1.0, k))
        .collect::<Result<Vec<_>, _>>()?;
    let ms = time(&|e| regs.iter().for_each(|r| r.record(ctx, e, &x, &x_ref, &v_x, &scalars)))?;
    rows.push((format!("param l2 ×3 {len} gaussians"), ms));
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::ctx;

    #[test]
    fn bench_reports_every_operation() {
        let rows = bench_image_ops(ctx(), &[24], 1000, 1).expect("bench");
        assert_eq!(rows.len(), 9);
        assert!(rows.iter().all(|(name, ms)| ms.is_finite() && *ms >= 0.0 && !name.is_empty()), "{rows:?}");
        assert!(rows[5].0 == "edge map 24²", "{rows:?}");
    }
}
