//! Headless use of the viewport: a device without a window (lavapipe on CI),
//! a synthetic scene of any size, and the frame-time measurement behind
//! `gast viewport-bench`.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context as _;
use gast_core::Gaussians;

use super::{Side, SplatRenderer};
use crate::studio::view::ViewState;

/// A device and queue on the first adapter wgpu finds (no surface), and its description.
pub fn headless_device() -> anyhow::Result<(wgpu::Device, wgpu::Queue, String)> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .context("no GPU adapter (install mesa-vulkan-drivers and libvulkan1 for lavapipe)")?;
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
        .context("requesting a device")?;
    Ok((device, queue, format!("{} ({:?})", info.name, info.backend)))
}

/// A synthetic scene: `n` Gaussians of SH degree 3 in a noisy shell, deterministic.
pub fn synthetic_scene(n: usize) -> Gaussians {
    let mut g = Gaussians::with_capacity(n, 3);
    let mut s = 0x1234_5678_u64;
    let mut f = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    for _ in 0..n {
        let (u, v, r) = (f() * std::f32::consts::TAU, f() * 2.0 - 1.0, 0.8 + 0.4 * f());
        let q = (1.0 - v * v).sqrt();
        g.means.push([r * q * u.cos(), r * v, r * q * u.sin()]);
        g.log_scales.push([-4.5 + f(), -4.5 + f(), -4.5 + f()]);
        g.quats.push([f(), f() - 0.5, f() - 0.5, f() - 0.5]);
        g.opacity_logits.push(2.0 * f() - 0.5);
        for k in 0..48 {
            g.sh.push(if k < 3 { 2.0 * f() - 1.0 } else { 0.1 * (f() - 0.5) });
        }
    }
    g
}

/// Times `frames` viewport frames (sort, upload, projection, draw, wait) at `width × height`,
/// orbiting a little between frames so every frame sorts.
pub fn run(scene: Option<&Path>, count: usize, frames: u32, width: u32, height: u32) -> anyhow::Result<String> {
    let g = match scene {
        Some(p) => gast_core::scene::load(p)?,
        None => synthetic_scene(count),
    };
    let g: super::SharedGaussians = Arc::new(g).into();
    let (device, queue, adapter) = headless_device()?;
    let mut r = SplatRenderer::new(&device);
    let upload = Instant::now();
    if let Some(note) = r.set_scene(&device, Side::Before, 1, &g).map_err(anyhow::Error::msg)? {
        eprintln!("{note}");
    }
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    let upload_ms = upload.elapsed().as_secs_f64() * 1e3;
    let mut view = ViewState::default();
    view.fit(&g);
    let mut times = Vec::new();
    let mut sort = 0.0;
    for k in 0..frames + 1 {
        view.orbit(0.02, 0.0);
        let cam = view.camera(width, height);
        let t = Instant::now();
        r.begin_frame();
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("bench") });
        r.render(&device, &queue, &mut encoder, Side::Before, &cam);
        queue.submit([encoder.finish()]);
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        if k > 0 {
            times.push(t.elapsed().as_secs_f64() * 1e3);
            sort += r.stats.sort_ms as f64;
        }
    }
    let mean = times.iter().sum::<f64>() / times.len().max(1) as f64;
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    Ok(format!(
        "viewport frame time on {adapter}: {} Gaussians (SH {}) at {width}x{height}: mean {mean:.1} ms, best {min:.1} ms over {} frames (CPU sort {:.1} ms/frame, upload once {upload_ms:.0} ms)",
        g.len(),
        g.sh_degree,
        times.len(),
        sort / times.len().max(1) as f64
    ))
}
