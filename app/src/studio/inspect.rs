//! CPU work off the UI thread: the inspection maps (RGB, inverse depth, edges)
//! of the current view and the exports. Each job runs on its own thread and
//! reports on a channel; the UI thread only turns results into textures.

use std::path::PathBuf;
use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};
use gast_core::{Camera, Gaussians};

use super::viewport::cpu_reference;

/// The three maps of one view, as 8-bit images ready for textures.
pub struct Maps {
    /// The render.
    pub rgb: egui::ColorImage,
    /// Inverse depth, min-max normalised (near = bright).
    pub depth: egui::ColorImage,
    /// Sobel edges of the render.
    pub edges: egui::ColorImage,
}

/// What a finished job reports.
pub enum JobDone {
    /// Inspection maps are ready.
    Maps(Box<Maps>),
    /// A file was written.
    Exported(PathBuf),
    /// A job failed; the message names the file and the reason.
    Failed(String),
}

/// Starts jobs and collects their results.
pub struct Jobs {
    tx: Sender<JobDone>,
    rx: Receiver<JobDone>,
    waker: Arc<dyn Fn() + Send + Sync>,
    /// Jobs started and not yet reported.
    pub running: usize,
}

fn gray_image(w: u32, h: u32, v: &[f32]) -> egui::ColorImage {
    let (lo, hi) = gast_core::io::finite_range(v);
    let s = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    let px = v.iter().map(|&x| egui::Color32::from_gray(((x - lo) * s * 255.0).clamp(0.0, 255.0) as u8)).collect();
    egui::ColorImage::new([w as usize, h as usize], px)
}

fn rgb_image(w: u32, h: u32, rgb: &[f32]) -> egui::ColorImage {
    let px = rgb.chunks_exact(3).map(|c| {
        let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        egui::Color32::from_rgb(q(c[0]), q(c[1]), q(c[2]))
    });
    egui::ColorImage::new([w as usize, h as usize], px.collect())
}

/// The inspection maps of `g` from `cam`.
pub fn maps(g: &Gaussians, cam: &Camera, background: [f32; 3]) -> Maps {
    let r = cpu_reference::render(g, cam, background);
    let edges = cpu_reference::sobel_edges(r.width, r.height, &r.rgb);
    Maps { rgb: rgb_image(r.width, r.height, &r.rgb), depth: gray_image(r.width, r.height, &r.inv_depth), edges: gray_image(r.width, r.height, &edges) }
}

/// The camera scaled so its longer side is `long_side` pixels.
pub fn scaled(cam: &Camera, long_side: u32) -> Camera {
    let s = long_side as f32 / cam.width.max(cam.height).max(1) as f32;
    let mut c = cam.clone();
    c.width = ((cam.width as f32 * s).round() as u32).max(1);
    c.height = ((cam.height as f32 * s).round() as u32).max(1);
    c.fx *= c.width as f32 / cam.width.max(1) as f32;
    c.fy *= c.height as f32 / cam.height.max(1) as f32;
    c.cx *= c.width as f32 / cam.width.max(1) as f32;
    c.cy *= c.height as f32 / cam.height.max(1) as f32;
    c
}

impl Jobs {
    /// A job runner that calls `waker` when a job finishes.
    pub fn new(waker: Arc<dyn Fn() + Send + Sync>) -> Self {
        let (tx, rx) = crossbeam_channel::unbounded();
        Self { tx, rx, waker, running: 0 }
    }

    fn spawn(&mut self, job: impl FnOnce() -> JobDone + Send + 'static) {
        let tx = self.tx.clone();
        let waker = self.waker.clone();
        self.running += 1;
        std::thread::spawn(move || {
            let _ = tx.send(job());
            waker();
        });
    }

    /// Renders the inspection maps of a view.
    pub fn inspect(&mut self, g: Arc<Gaussians>, cam: Camera, background: [f32; 3]) {
        self.spawn(move || JobDone::Maps(Box::new(maps(&g, &cam, background))));
    }

    /// Renders a view and writes it as PNG.
    pub fn export_png(&mut self, g: Arc<Gaussians>, cam: Camera, background: [f32; 3], path: PathBuf) {
        self.spawn(move || {
            let r = cpu_reference::render(&g, &cam, background);
            match gast_core::io::write_png_rgb(&path, r.width, r.height, &r.rgb) {
                Ok(()) => JobDone::Exported(path),
                Err(e) => JobDone::Failed(format!("exporting the view: {e}")),
            }
        });
    }

    /// Renders a view's inverse depth and writes it as EXR.
    pub fn export_depth(&mut self, g: Arc<Gaussians>, cam: Camera, path: PathBuf) {
        self.spawn(move || {
            let r = cpu_reference::render(&g, &cam, [0.0; 3]);
            match gast_core::io::write_exr_depth(&path, r.width, r.height, &r.inv_depth) {
                Ok(()) => JobDone::Exported(path),
                Err(e) => JobDone::Failed(format!("exporting the depth: {e}")),
            }
        });
    }

    /// Writes Gaussians as `.ply`.
    pub fn export_ply(&mut self, g: Arc<Gaussians>, path: PathBuf) {
        self.spawn(move || match super::scene_io::save_ply(&path, &g) {
            Ok(()) => JobDone::Exported(path),
            Err(e) => JobDone::Failed(format!("{e:#}")),
        });
    }

    /// Results that arrived since the last call.
    pub fn poll(&mut self) -> Vec<JobDone> {
        let done: Vec<JobDone> = self.rx.try_iter().collect();
        self.running = self.running.saturating_sub(done.len());
        done
    }
}
