//! CPU work off the UI thread: the inspection maps (RGB, inverse depth, edges)
//! of the current view and the exports. Each job runs on its own thread and
//! reports on a channel; the UI thread only turns results into textures.

use std::path::PathBuf;
use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};
use gast_core::{Camera, Gaussians};

use super::viewport::SharedGaussians;

use gast_core::raster::{RenderOptions, render};

/// The three maps of one view, as 8-bit images ready for textures.
pub struct Maps {
    /// The render.
    pub rgb: egui::ColorImage,
    /// Inverse depth, min-max normalised (near = bright).
    pub depth: egui::ColorImage,
    /// Sobel edges of the render (until `gast_core::vision` Canny is merged in).
    pub edges: egui::ColorImage,
}

/// A scene file as read: its Gaussians and the training cameras found beside it.
pub struct SceneFile {
    /// The Gaussians.
    pub gaussians: Gaussians,
    /// Cameras from the scene's folder (COLMAP, `cameras.json`, `transforms.json`) and that folder.
    pub cameras: Option<(gast_core::camera::CameraSet, PathBuf)>,
}

/// Reads a scene and looks for training cameras beside it.
pub fn read_scene_file(path: &std::path::Path) -> anyhow::Result<SceneFile> {
    let gaussians = gast_core::scene::load(path)?;
    let cameras = path.parent().filter(|d| !d.as_os_str().is_empty()).and_then(|dir| {
        gast_core::camera::load(dir).ok().filter(|set| !set.cameras.is_empty()).map(|set| (set, dir.to_path_buf()))
    });
    Ok(SceneFile { gaussians, cameras })
}

/// What a finished job reports.
pub enum JobDone {
    /// A scene file was read (or not).
    Scene(PathBuf, anyhow::Result<SceneFile>),
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

/// A grey image of `v`, min-max normalised over the pixels where `mask` is set
/// (the rest black), so that empty background does not flatten the contrast.
fn gray_image(w: u32, h: u32, v: &[f32], mask: impl Fn(usize) -> bool) -> egui::ColorImage {
    let inside: Vec<f32> = v.iter().enumerate().filter(|(i, _)| mask(*i)).map(|(_, &x)| x).collect();
    let (lo, hi) = gast_core::io::finite_range(&inside);
    let s = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    let px = v
        .iter()
        .enumerate()
        .map(|(i, &x)| {
            if mask(i) {
                egui::Color32::from_gray((16.0 + (x - lo) * s * 239.0).clamp(0.0, 255.0) as u8)
            } else {
                egui::Color32::BLACK
            }
        })
        .collect();
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
    let r = render(g, cam, &RenderOptions { background });
    let edges = sobel_edges(r.width, r.height, &r.rgb);
    // Inverse depth is Σ wᵢ/zᵢ: divide by the opacity to get the covered pixels' own depth.
    let depth: Vec<f32> = r.inv_depth.iter().zip(&r.alpha).map(|(d, a)| if *a > 0.05 { d / a } else { 0.0 }).collect();
    Maps {
        rgb: rgb_image(r.width, r.height, &r.rgb),
        depth: gray_image(r.width, r.height, &depth, |i| r.alpha[i] > 0.05),
        edges: gray_image(r.width, r.height, &edges, |_| true),
    }
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

    /// Reads a scene file.
    pub fn load_scene(&mut self, path: PathBuf) {
        self.spawn(move || {
            let result = read_scene_file(&path);
            JobDone::Scene(path, result)
        });
    }

    /// Renders the inspection maps of a view.
    pub fn inspect(&mut self, g: SharedGaussians, cam: Camera, background: [f32; 3]) {
        self.spawn(move || JobDone::Maps(Box::new(maps(&g, &cam, background))));
    }

    /// Renders a view and writes it as PNG.
    pub fn export_png(&mut self, g: SharedGaussians, cam: Camera, background: [f32; 3], path: PathBuf) {
        self.spawn(move || {
            let r = render(&g, &cam, &RenderOptions { background });
            match gast_core::io::write_png_rgb(&path, r.width, r.height, &r.rgb) {
                Ok(()) => JobDone::Exported(path),
                Err(e) => JobDone::Failed(format!("exporting the view: {e}")),
            }
        });
    }

    /// Renders a view's inverse depth and writes it as EXR.
    pub fn export_depth(&mut self, g: SharedGaussians, cam: Camera, path: PathBuf) {
        self.spawn(move || {
            let r = render(&g, &cam, &RenderOptions::default());
            match gast_core::io::write_exr_depth(&path, r.width, r.height, &r.inv_depth) {
                Ok(()) => JobDone::Exported(path),
                Err(e) => JobDone::Failed(format!("exporting the depth: {e}")),
            }
        });
    }

    /// Writes Gaussians as `.ply`.
    pub fn export_ply(&mut self, g: SharedGaussians, path: PathBuf) {
        self.spawn(move || match gast_core::scene::save_ply(&path, &g) {
            Ok(()) => JobDone::Exported(path),
            Err(e) => JobDone::Failed(format!("exporting the scene: {e}")),
        });
    }

    /// Results that arrived since the last call.
    pub fn poll(&mut self) -> Vec<JobDone> {
        let done: Vec<JobDone> = self.rx.try_iter().collect();
        self.running = self.running.saturating_sub(done.len());
        done
    }
}

/// Gradient magnitude (Sobel) of the luminance of an RGB image, normalised to [0, 1].
pub fn sobel_edges(width: u32, height: u32, rgb: &[f32]) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    let lum: Vec<f32> = rgb.chunks_exact(3).map(|c| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]).collect();
    let at = |x: isize, y: isize| lum[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize];
    let mut out = vec![0.0f32; w * h];
    let mut max = 0.0f32;
    for y in 0..h as isize {
        for x in 0..w as isize {
            let gx = at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x - 1, y)
                - at(x - 1, y + 1);
            let gy = at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x, y - 1)
                - at(x + 1, y - 1);
            let m = (gx * gx + gy * gy).sqrt();
            max = max.max(m);
            out[y as usize * w + x as usize] = m;
        }
    }
    if max > 0.0 {
        out.iter_mut().for_each(|v| *v /= max);
    }
    out
}
