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

/// Median and best of a list of milliseconds.
fn summary(ms: &[f64]) -> (f64, f64) {
    let mut v = ms.to_vec();
    v.sort_by(f64::total_cmp);
    let median = v.get(v.len() / 2).copied().unwrap_or(f64::NAN);
    (median, v.first().copied().unwrap_or(f64::NAN))
}

/// Milliseconds with one decimal, comma-separated.
fn list(ms: &[f64]) -> String {
    ms.iter().map(|v| format!("{v:.1}")).collect::<Vec<_>>().join(", ")
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
    let inputs =
        SessionInputs { scene: Arc::new(scene), cameras, style, style_depth, vgg, config, gpu: Some(ctx.clone()) };
    let mut session = Session::prepare(inputs, &mut |_| {}).map_err(|e| anyhow::anyhow!("{e}"))?;
    let live = session.live().context("the session did not start on the GPU")?;
    let device = &ctx.device;
    let mut r = SplatRenderer::new(device);
    r.use_gpu_sort(ctx.clone());
    let t = Instant::now();
    r.set_live_scene(device, Side::After, 1, &live).map_err(anyhow::Error::msg)?;
    // The first copy (step 0) compiles the kernels on drivers that do so lazily.
    let mut enc = ctx.encoder("bench.viewport_live");
    r.sync_live(&mut enc, Side::After);
    ctx.submit(enc);
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
    let (s_med, s_best) = summary(&snapshot);
    let (e_med, e_best) = summary(&engine);
    let base = live.base();
    Ok(format!(
        "viewport update per optimiser step on {} ({} Gaussians, {} optimised, SH degree {}), {reps} updates:\n\
         snapshot path      median {s_med:.1} ms, best {s_best:.1} ms (median read back + scatter {:.1} ms, pack + upload {:.1} ms) [{}]\n\
         engine-buffer path median {e_med:.2} ms, best {e_best:.2} ms (one-time setup and first copy {setup_ms:.0} ms) [{}]\n\
         ratio snapshot / engine-buffer: {:.1}x (medians), {:.1}x (best)",
        ctx.describe(),
        base.len(),
        live.keep().len(),
        base.sh_degree,
        summary(&readback).0,
        summary(&upload).0,
        list(&snapshot),
        list(&engine),
        s_med / e_med.max(1e-9),
        s_best / e_best.max(1e-9),
    ))
}
