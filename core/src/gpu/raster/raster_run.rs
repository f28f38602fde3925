//! The GPU rasterizer driven from the host, outside any optimisation loop:
//! one render or one render-and-gradients with read-back (`gast check golden
//! --device gpu`, tests), a workspace sized by a first pass, and the
//! benchmark the lead's `gast bench step` calls.

use std::time::Instant;

use super::Commands;
use super::raster_forward::Stage;
use super::{GpuContext, GpuError, GpuGaussians, GpuGrads, GpuRaster, RasterKernels};
use crate::camera::Camera;
use crate::raster::{Grads, Render, RenderOptions};
use crate::scene::Gaussians;

impl GpuRaster {
    /// A workspace for `g` seen by `cam` with room for the pairs this view
    /// needs (plus a quarter): one forward pass in a guessed workspace tells
    /// how many, and a larger one is made when the guess was short. Leaves
    /// the forward pass of this view recorded and done.
    pub fn fitted(
        ctx: &GpuContext,
        k: &RasterKernels,
        g: &GpuGaussians,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> Result<Self, GpuError> {
        let guess = (8 * g.len).max(4096);
        let mut raster = Self::new(ctx, g.len, cam.width, cam.height, guess)?;
        loop {
            let mut enc = ctx.encoder("raster.fitted");
            raster.forward(ctx, k, &mut enc, g, cam, opts);
            ctx.submit(enc);
            let pairs = raster.pairs(ctx)?;
            if pairs <= raster.capacity() {
                return Ok(raster);
            }
            raster = Self::new(ctx, g.len, cam.width, cam.height, pairs + pairs / 4)?;
        }
    }
}

/// Renders `g` from `cam` on the GPU and reads the image back.
pub fn render_gpu(ctx: &GpuContext, g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Result<Render, GpuError> {
    let k = RasterKernels::new(ctx);
    let gg = GpuGaussians::upload(ctx, g);
    GpuRaster::fitted(ctx, &k, &gg, cam, opts)?.download(ctx)
}

/// Renders `g` from `cam` on the GPU and back-propagates the cotangents
/// `v_rgb` (H·W·3) and `v_inv_depth` (H·W): the GPU twin of
/// [`crate::raster::forward`] then [`crate::raster::backward`].
pub fn render_and_backward_gpu(
    ctx: &GpuContext,
    k: &RasterKernels,
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    v_rgb: &[f32],
    v_inv_depth: &[f32],
) -> Result<(Render, Grads), GpuError> {
    let gg = GpuGaussians::upload(ctx, g);
    let raster = GpuRaster::fitted(ctx, k, &gg, cam, opts)?;
    let grads = GpuGrads::new(ctx, &gg);
    let (vr, vd) = (ctx.upload("v_rgb", v_rgb), ctx.upload("v_inv_depth", v_inv_depth));
    let mut enc = ctx.encoder("raster.backward");
    raster.backward(ctx, k, &mut enc, &gg, &vr, &vd, &grads);
    ctx.submit(enc);
    Ok((raster.download(ctx)?, grads.download(ctx)?))
}

/// Milliseconds of the rasterizer on `g` seen by `cam`: each forward stage,
/// the two halves of the backward pass, and the whole forward and backward,
/// each the median of several runs after a warm-up, timed by waiting for the
/// queue (so each includes one submission). Names start with "raster".
pub fn bench_raster(ctx: &GpuContext, g: &Gaussians, cam: &Camera) -> Result<Vec<(String, f64)>, GpuError> {
    const RUNS: usize = 5;
    let opts = RenderOptions::default();
    let k = RasterKernels::new(ctx);
    let gg = GpuGaussians::upload(ctx, g);
    let raster = GpuRaster::fitted(ctx, &k, &gg, cam, &opts)?;
    let grads = GpuGrads::new(ctx, &gg);
    let npx = cam.width as usize * cam.height as usize;
    let vr = ctx.upload("v_rgb", &vec![1.0f32; 3 * npx]);
    let vd = ctx.upload("v_inv_depth", &vec![0.1f32; npx]);
    let time = |record: &dyn Fn(&mut dyn Commands)| -> Result<f64, GpuError> {
        let mut ms = Vec::with_capacity(RUNS);
        for run in 0..=RUNS {
            let mut enc = ctx.encoder("bench.raster");
            let t0 = Instant::now();
            record(&mut enc);
            ctx.submit(enc);
            ctx.wait()?;
            if run > 0 {
                ms.push(t0.elapsed().as_secs_f64() * 1e3);
            }
        }
        ms.sort_by(f64::total_cmp);
        Ok(ms[RUNS / 2])
    };
    let mut out = Vec::new();
    // `fitted` left this view's uniform written; each stage reads what the previous left.
    for stage in Stage::ALL {
        out.push((stage.name().to_owned(), time(&|enc| raster.record_stage(ctx, &k, enc, &gg, stage))?));
    }
    out.push(("raster backward tiles".into(), time(&|enc| raster.backward_tiles(ctx, &k, enc, &vr, &vd))?));
    out.push(("raster backward gaussians".into(), time(&|enc| raster.backward_gaussians(ctx, &k, enc, &gg, &grads))?));
    out.push(("raster forward".into(), time(&|enc| raster.forward(ctx, &k, enc, &gg, cam, &opts))?));
    out.push(("raster backward".into(), time(&|enc| raster.backward(ctx, &k, enc, &gg, &vr, &vd, &grads))?));
    Ok(out)
}
