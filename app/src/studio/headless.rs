//! The studio with no window (`gast studio --headless`): the same app, its
//! frames drawn offscreen by egui-wgpu on a device of its own and read back,
//! with no display or window system at all. It serves a machine whose GPU no
//! X server can show (a lent GPU machine, where Xvfb has no GLX for the
//! NVIDIA driver), so a scripted run (`GAST_STUDIO_RUN_STEPS`) and a
//! screenshot (`GAST_STUDIO_SCREENSHOT`) take the same paths as in a window:
//! the app's own frame count asks for the screenshot and the close, and this
//! loop answers them.

use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use super::{SessionStarter, StudioApp, StudioArgs, wgpu_options, window_size};

/// Frames drawn when `GAST_STUDIO_EXIT_AFTER_FRAMES` is not set.
const DEFAULT_FRAMES: u64 = 30;

/// Runs the studio offscreen until it closes itself: after
/// `GAST_STUDIO_EXIT_AFTER_FRAMES` frames (30 without), counted from the end
/// of a scripted run when there is one, with the screenshot before it.
pub fn run(args: StudioArgs, starter: Option<SessionStarter>) -> anyhow::Result<()> {
    let config = wgpu_options();
    let instance = pollster::block_on(config.wgpu_setup.new_instance());
    let rs = pollster::block_on(egui_wgpu::RenderState::create(
        &config,
        &instance,
        None,
        egui_wgpu::RendererOptions::default(),
    ))
    .map_err(|e| anyhow::anyhow!("no graphics adapter for the headless studio: {e}"))?;
    let info = rs.adapter.get_info();
    eprintln!("studio: headless on {} ({:?}, {:?})", info.name, info.backend, info.device_type);
    let ctx = egui::Context::default();
    let wake = Wake::default();
    {
        let wake = wake.clone();
        ctx.set_request_repaint_callback(move |info| {
            if info.viewport_id == egui::ViewportId::ROOT {
                wake.ask(info.delay);
            }
        });
    }
    let mut app = StudioApp::on_device(ctx.clone(), args, &rs, starter);
    if app.exit_after.is_none() {
        app.exit_after = Some(DEFAULT_FRAMES);
    }
    let size = window_size(std::env::var("GAST_STUDIO_WINDOW").ok().as_deref());
    let screen = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(size[0], size[1]));
    let start = Instant::now();
    loop {
        let input = egui::RawInput {
            screen_rect: Some(screen),
            time: Some(start.elapsed().as_secs_f64()),
            max_texture_side: Some(rs.device.limits().max_texture_dimension_2d as usize),
            ..Default::default()
        };
        let mut output = ctx.run_ui(input, |ui| app.show(ui));
        let mut close = false;
        let mut shots = Vec::new();
        for vp in output.viewport_output.values_mut() {
            for command in vp.commands.drain(..) {
                match command {
                    egui::ViewportCommand::Close => close = true,
                    egui::ViewportCommand::Screenshot(cb) => shots.push(cb),
                    _ => {}
                }
            }
        }
        let delay = output.viewport_output.get(&egui::ViewportId::ROOT).map_or(Duration::ZERO, |v| v.repaint_delay);
        wake.ask(delay);
        if let Some(image) = draw(&rs, &ctx, output, !shots.is_empty())? {
            for cb in shots {
                cb.complete(image.clone());
            }
        }
        if close {
            // What the window would have shown in its panels, for the log.
            for line in &app.run.log {
                eprintln!("studio: the run's log: {line}");
            }
            for e in &app.errors {
                eprintln!("studio: shown in the window: {e}");
            }
            // The run's thread ends before the device and the process do.
            app.shut_down();
            if app.script.as_ref().is_some_and(|s| s.failed) {
                anyhow::bail!("the scripted run (GAST_STUDIO_RUN_STEPS) could not start");
            }
            return Ok(());
        }
        // A window draws when something asks for it (an input, a worker's
        // wake-up, a delayed repaint), and so does this loop: it sleeps until
        // the earliest repaint asked for, leaving the time between frames to
        // the workers (the run, the maps). Before, it drew a frame every
        // 100 ms whether asked or not: on a software renderer, with the
        // script's polls, lavapipe took 37 % of the process's CPU, and the
        // run's steps 1.2–1.5× the time (docs/figures.md).
        wake.wait(Duration::from_millis(10), IDLE_FRAME);
    }
}

/// The longest the loop waits with no repaint asked for before it draws
/// anyway, so that a missed wake-up costs a second, not a hang.
const IDLE_FRAME: Duration = Duration::from_secs(1);

/// The earliest repaint asked for, from the pass (its repaint delay) or
/// from any thread (egui's repaint callback: a worker's wake-up).
#[derive(Clone, Default)]
struct Wake(Arc<(Mutex<Option<Instant>>, Condvar)>);

impl Wake {
    /// A repaint `delay` from now (`Duration::MAX`: none).
    fn ask(&self, delay: Duration) {
        let Some(at) = Instant::now().checked_add(delay) else { return };
        let (due, bell) = &*self.0;
        let mut due = due.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if due.is_none_or(|d| at < d) {
            *due = Some(at);
            bell.notify_one();
        }
    }

    /// Sleeps at least `least`, then until the earliest repaint asked for
    /// is due (and takes it) or `most` has passed since the call (a repaint
    /// asked for later stays asked for).
    fn wait(&self, least: Duration, most: Duration) {
        let deadline = Instant::now() + most;
        std::thread::sleep(least);
        let (due, bell) = &*self.0;
        let mut due = due.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        loop {
            let now = Instant::now();
            if due.is_some_and(|d| d <= now) {
                *due = None;
                return;
            }
            if now >= deadline {
                return;
            }
            let until = due.map_or(deadline, |d| d.min(deadline));
            due = bell.wait_timeout(due, until - now).unwrap_or_else(std::sync::PoisonError::into_inner).0;
        }
    }
}

/// Draws one frame's output into a texture of the screen's size and waits
/// for it; reads it back when `read_back` (a screenshot asked for it).
fn draw(
    rs: &egui_wgpu::RenderState,
    ctx: &egui::Context,
    mut output: egui::FullOutput,
    read_back: bool,
) -> anyhow::Result<Option<Arc<egui::ColorImage>>> {
    let (device, queue) = (&rs.device, &rs.queue);
    let ppp = output.pixels_per_point;
    let size = ctx.content_rect().size() * ppp;
    let (w, h) = ((size.x.round() as u32).max(1), (size.y.round() as u32).max(1));
    let screen = egui_wgpu::ScreenDescriptor { size_in_pixels: [w, h], pixels_per_point: ppp };
    let mut textures = std::mem::take(&mut output.textures_delta);
    let mut renderer = rs.renderer.write();
    #[expect(clippy::iter_over_hash_type, reason = "each texture's deltas are applied in their order; textures apart")]
    for (id, deltas) in textures.set.drain() {
        for delta in &deltas {
            renderer.update_texture(device, queue, id, delta);
        }
    }
    let jobs = ctx.tessellate(output.shapes, ppp);
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("headless") });
    let extra = renderer.update_buffers(device, queue, &mut encoder, &jobs, &screen);
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("headless.frame"),
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: rs.target_format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    {
        let mut pass = encoder
            .begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("headless.egui"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                    depth_slice: None,
                })],
                ..Default::default()
            })
            .forget_lifetime();
        renderer.render(&mut pass, &jobs, &screen);
    }
    queue.submit(extra.into_iter().chain(std::iter::once(encoder.finish())));
    for id in std::mem::take(&mut textures.free) {
        renderer.free_texture(&id);
    }
    drop(renderer);
    if !read_back {
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        return Ok(None);
    }
    let rows = super::viewport::read_texture_rows(device, queue, &texture, 4)
        .ok_or_else(|| anyhow::anyhow!("the headless frame could not be read back"))?;
    let bgra = matches!(rs.target_format, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb);
    let pixels = rows
        .iter()
        .flat_map(|line| line.chunks_exact(4))
        .map(|p| {
            let (r, b) = if bgra { (p[2], p[0]) } else { (p[0], p[2]) };
            egui::Color32::from_rgba_premultiplied(r, p[1], b, p[3])
        })
        .collect();
    Ok(Some(Arc::new(egui::ColorImage::new([w as usize, h as usize], pixels))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loop_sleeps_until_a_repaint_is_asked_for() {
        let ms = Duration::from_millis;
        // Asked for at once (a worker's wake-up from another thread, while the loop sleeps).
        let wake = Wake::default();
        let bell = wake.clone();
        let t = Instant::now();
        let waker = std::thread::spawn(move || {
            std::thread::sleep(ms(50));
            bell.ask(Duration::ZERO);
        });
        wake.wait(ms(1), ms(5_000));
        let woke = t.elapsed();
        waker.join().expect("the waker thread");
        assert!(woke >= ms(50) && woke < ms(2_000), "woke after {woke:?}");
        // Nothing asked for: the idle frame's bound.
        let t = Instant::now();
        wake.wait(ms(1), ms(100));
        assert!(t.elapsed() >= ms(100), "woke after {:?} with nothing asked for", t.elapsed());
        // A repaint asked for later than the bound stays asked for, and comes.
        wake.ask(ms(150));
        let t = Instant::now();
        wake.wait(ms(1), ms(50));
        assert!(t.elapsed() < ms(140), "the bound held the loop {:?}", t.elapsed());
        wake.wait(ms(1), ms(5_000));
        let came = t.elapsed();
        assert!(came >= ms(140) && came < ms(2_000), "the later repaint came after {came:?}");
        // The earlier of two requests wins.
        wake.ask(ms(5_000));
        wake.ask(ms(20));
        let t = Instant::now();
        wake.wait(ms(1), ms(10_000));
        assert!(t.elapsed() < ms(2_000), "the earlier request was lost: {:?}", t.elapsed());
    }
}
