//! `gast bench viewport-live`: what the viewport pays per optimiser update to
//! show a GPU run, measured side by side in one process on a real session —
//! the snapshot path (the worker reads the optimised Gaussians back and
//! scatters them into the whole scene, the viewport packs and uploads it)
//! against the engine-buffer path ([`super::splat_from_engine`]: one copy on
//! the device).

use std::sync::Arc;
use std::time::Instant;

use anyhow::Context as _;
use gast_core::Gaussians;
use gast_core::gpu::{AdapterPolicy, GpuContext};
use gast_core::session::{Session, SessionInputs, StyleDepthSource, StyleImage};
use gast_core::style::{Focus, Mode, StyleConfig};
use gast_core::vision::Vgg;

use super::{SharedGaussians, Side, SplatRenderer};

/// Mean and best of a list of milliseconds.
fn summary(ms: &[f64]) -> (f64, f64) {
    let mean = ms.iter().sum::<f64>() / ms.len().max(1) as f64;
    (mean, ms.iter().copied().fold(f64::INFINITY, f64::min))
}

/// Prepares a GPU session on `scene` (any adapter, lavapipe included) at a
/// small working resolution, then `reps` times: one real step (not timed),
/// the snapshot path, the engine-buffer path. Returns the report's lines.
pub fn run(scene: Gaussians, style: StyleImage, vgg: Arc<Vgg>, reps: u32) -> anyhow::Result<String> {
    let ctx = GpuContext::headless(AdapterPolicy::AnyAdapter).context("the benchmark needs a wgpu adapter")?;
    let opts = gast_core::camera::OrbitOptions { count: 6, width: 64, height: 64, ..Default::default() };
    let cameras = gast_core::camera::orbit_cameras(&scene.means, &opts);
    let config = StyleConfig {
        cycles: 1,
        steps_per_cycle: reps + 1,
        resolution: 64,
        texture_scale: 64,
        mode: Mode::Joint,
        focus: Focus::Frame,
        ..Default::default()
    };
    let style_depth = StyleDepthSource::Heuristic;
    let inputs = SessionInputs { scene, cameras, style, style_depth, vgg, config, gpu: Some(ctx.clone()) };
    let mut session = Session::prepare(inputs, &mut |_| {}).map_err(|e| anyhow::anyhow!("{e}"))?;
    let live = session.live().context("the session did not start on the GPU")?;
    let device = &ctx.device;
    let mut r = SplatRenderer::new(device);
    r.use_gpu_sort(ctx.clone());
    let t = Instant::now();
    r.set_live_scene(device, Side::After, 1, &live).map_err(anyhow::Error::msg)?;
    ctx.wait()?;
    let setup_ms = t.elapsed().as_secs_f64() * 1e3;
    let (mut readback, mut upload, mut snapshot, mut engine) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for rep in 0..reps {
        session.step().with_context(|| format!("GPU step failed: {:?}", session.failure()))?;
        // The snapshot path: what the worker and the UI do for one snapshot.
        let t = Instant::now();
        let g: SharedGaussians = Arc::new(session.result()).into();
        let read = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        r.set_scene(device, Side::Before, u64::from(rep) + 2, &g).map_err(anyhow::Error::msg)?;
        ctx.wait()?;
        let up = t.elapsed().as_secs_f64() * 1e3;
        readback.push(read);
        upload.push(up);
        snapshot.push(read + up);
        // The engine-buffer path: the copy on the device, waited for.
        let t = Instant::now();
        let mut enc = ctx.encoder("bench.viewport_live");
        anyhow::ensure!(r.sync_live(&mut enc, Side::After), "no copy after a step");
        ctx.submit(enc);
        ctx.wait()?;
        engine.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let (s_mean, s_best) = summary(&snapshot);
    let (e_mean, e_best) = summary(&engine);
    let base = live.base();
    Ok(format!(
        "viewport update per optimiser step on {} ({} Gaussians, {} optimised, SH degree {}), {reps} updates:\n\
         snapshot path     mean {s_mean:.1} ms, best {s_best:.1} ms (read back + scatter {:.1} ms, pack + upload {:.1} ms)\n\
         engine-buffer path mean {e_mean:.2} ms, best {e_best:.2} ms (one-time setup {setup_ms:.0} ms)\n\
         ratio snapshot / engine-buffer: {:.0}x (means), {:.0}x (best)",
        ctx.describe(),
        base.len(),
        live.keep().len(),
        base.sh_degree,
        summary(&readback).0,
        summary(&upload).0,
        s_mean / e_mean.max(1e-9),
        s_best / e_best.max(1e-9),
    ))
}
