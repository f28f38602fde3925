//! CPU work off the UI thread: the inspection maps (RGB, inverse depth, edges)
//! of the current view and the exports. Each job runs on its own thread and
//! reports on a channel; the UI thread only turns results into textures.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};
use gast_core::session::StyleDepthSource;
use gast_core::session::StyleImage;
use gast_core::style::stage1;
use gast_core::vision::relief_depth::ReliefDepth;
use gast_core::vision::style_depth::{DepthPolarity, DepthProvider};
use gast_core::{Camera, Gaussians};

use super::viewport::SharedGaussians;
use crate::report::sheet::{RunViews, SheetContent, maps_tiles, write_sheet};
use gast_core::session::RunStart;

use gast_core::raster::{RenderOptions, render};

/// The three maps of one view, as 8-bit images ready for textures.
pub struct Maps {
    /// The render.
    pub rgb: egui::ColorImage,
    /// Inverse depth, min-max normalised (near = bright).
    pub depth: egui::ColorImage,
    /// The same in the JET colour map, as the reference draws its depth
    /// figures: a relief of a tenth of the range shows as a change of hue.
    pub depth_jet: egui::ColorImage,
    /// Edges: Canny (25, 200) per channel of the render, averaged, as the
    /// optimisation computes them (for the style: Canny of its JET-coloured depth).
    pub edges: egui::ColorImage,
}

/// The names of the four maps, in [`Maps`]' order.
pub const MAP_NAMES: [&str; 4] = ["RGB", "inverse depth", "inverse depth (JET)", "edges"];

impl Maps {
    fn into_array(self) -> [egui::ColorImage; 4] {
        [self.rgb, self.depth, self.depth_jet, self.edges]
    }
}

/// One set of maps on the inspect strip, as textures: each map at its full
/// size (shown on hover) and as drawn in the strip, filtered down to the
/// strip's height. egui_wgpu samples textures without mipmaps, so a map drawn
/// at a quarter of its size picks one texel in four: a style's one-pixel edge
/// lines came out as speckle noise.
pub struct MapTextures {
    maps: [egui::ColorImage; 4],
    full: [egui::TextureHandle; 4],
    shown: [egui::TextureHandle; 4],
    /// The height in pixels `shown` was filtered to.
    shown_height: usize,
}

impl MapTextures {
    pub fn new(ctx: &egui::Context, name: &str, maps: Maps) -> Self {
        let maps = maps.into_array();
        let opts = egui::TextureOptions::LINEAR;
        // Two textures a map (a handle's clone would share its texture).
        let load =
            |i: usize, what: &str| ctx.load_texture(format!("{name} {} {what}", MAP_NAMES[i]), maps[i].clone(), opts);
        let full = std::array::from_fn(|i| load(i, "full"));
        let shown = std::array::from_fn(|i| load(i, "strip"));
        let shown_height = maps[0].height();
        Self { maps, full, shown, shown_height }
    }

    /// Width over height of each map.
    pub fn aspects(&self) -> [f32; 4] {
        std::array::from_fn(|i| self.maps[i].width() as f32 / self.maps[i].height().max(1) as f32)
    }

    /// Refilters the strip's textures for drawing `height` pixels tall (not
    /// above the maps' own size); nothing when they already are.
    pub fn fit(&mut self, height: usize) {
        let height = height.clamp(1, self.maps[0].height().max(1));
        if height == self.shown_height {
            return;
        }
        for (t, m) in self.shown.iter_mut().zip(&self.maps) {
            t.set(downscale(m, height), egui::TextureOptions::LINEAR);
        }
        self.shown_height = height;
    }

    /// The textures drawn in the strip.
    pub fn shown(&self) -> &[egui::TextureHandle; 4] {
        &self.shown
    }

    /// The textures at the maps' own size.
    pub fn full(&self) -> &[egui::TextureHandle; 4] {
        &self.full
    }
}

/// `img` resized to `height` rows (its aspect kept) by area averaging
/// ([`gast_core::vision::resize::resize_area_u8`]), so that every source
/// pixel counts: a thin line turns grey rather than vanishing or aliasing.
pub fn downscale(img: &egui::ColorImage, height: usize) -> egui::ColorImage {
    let (w, h) = (img.width(), img.height());
    if height >= h || w == 0 || h == 0 {
        return img.clone();
    }
    let width = ((w * height) as f32 / h as f32).round().max(1.0) as usize;
    let out = gast_core::vision::resize::resize_area_u8(img.as_raw(), h, w, 4, height, width);
    egui::ColorImage::from_rgba_premultiplied([width, height], &out)
}

/// A scene file as read: its Gaussians and the training cameras found beside it.
pub struct SceneFile {
    /// The Gaussians.
    pub gaussians: Gaussians,
    /// Cameras from the scene's folder (COLMAP, LLFF `poses_bounds.npy`, `cameras.json`,
    /// `transforms.json`) or its INRIA model folder, and that folder
    /// ([`gast_core::camera::beside_scene`]).
    pub cameras: Option<(gast_core::camera::CameraSet, PathBuf)>,
    /// What the reader had to repair (e.g. infinite opacities), one line per kind.
    pub warnings: Vec<String>,
}

/// Reads a scene and looks for training cameras beside it.
pub fn read_scene_file(path: &std::path::Path) -> anyhow::Result<SceneFile> {
    let (gaussians, mut warnings) = gast_core::scene::load_with_warnings(path)?;
    let cameras = match gast_core::camera::beside_scene(path) {
        Some(Ok((set, dir))) => match gast_core::session::plan::foreign_cameras(&gaussians, &set.cameras) {
            Some(why) => {
                warnings.push(format!("the cameras beside the scene in {} are not used: {why}", dir.display()));
                None
            }
            None => Some((set, dir)),
        },
        Some(Err(e)) => {
            warnings.push(format!("the cameras beside the scene are not used: {e}"));
            None
        }
        None => None,
    };
    Ok(SceneFile { gaussians, cameras, warnings })
}

/// A style image as the studio keeps it: what a run takes, and its thumbnail
/// for the strip of recent styles.
pub struct StyleFile {
    /// The whole image, handed to the worker when a run starts.
    pub image: Arc<StyleImage>,
    /// 96 px wide.
    pub thumb: egui::ColorImage,
    /// The file's bytes ([`crate::checkpoint::file_fingerprint`]), which a
    /// kept run's record names; `None` for a style made in memory.
    pub file: Option<String>,
}

/// A decoded style image made ready for the strip; one the runs cannot use
/// (smaller than 4×4, or too long and narrow) is an error naming `path`.
pub fn style_file(path: &Path, img: image::RgbImage) -> Result<StyleFile, String> {
    let thumb = image::imageops::thumbnail(&img, 96, (96 * img.height() / img.width().max(1)).max(1));
    let image = Arc::new(StyleImage::from_rgb(path, img)?);
    let thumb = egui::ColorImage::from_rgb([thumb.width() as usize, thumb.height() as usize], thumb.as_raw());
    Ok(StyleFile { image, thumb, file: None })
}

/// Reads a style image file ([`style_file`]): off the UI thread once the
/// window runs, where the decoding held the window still for as long as it
/// took (wave.jpg, 4,200 × 2,000, decodes in about 0.17 s with PIL on a
/// 2-core machine; a 12,000-px image takes seconds).
pub fn read_style_file(path: &Path) -> Result<StyleFile, String> {
    let img = gast_core::io::open_image(path)
        .map_err(|e| format!("{}: not a style image this build can read (PNG, JPEG, WebP): {e}", path.display()))?;
    let file = crate::checkpoint::file_fingerprint(path);
    Ok(StyleFile { file, ..style_file(path, img.into_rgb8())? })
}

/// How the message of a failed scene export starts.
pub const SCENE_EXPORT_FAILED: &str = "exporting the scene";

/// What a finished job reports.
pub enum JobDone {
    /// A scene file was read (or not).
    Scene(PathBuf, anyhow::Result<SceneFile>),
    /// A style image was read (or not).
    Style(PathBuf, Result<StyleFile, String>),
    /// Inspection maps are ready.
    Maps(Box<Maps>),
    /// The style's maps for a [`StyleMapsKey`] are ready, with the depth's fallback warning.
    StyleMaps(StyleMapsKey, Box<Maps>, Option<String>),
    /// A file was written, with what to tell beside it (cameras written with a scene).
    Exported(PathBuf, Vec<String>),
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

/// An 8-bit RGB buffer as an image.
fn jet_image(w: u32, h: u32, rgb: &[u8]) -> egui::ColorImage {
    egui::ColorImage::from_rgb([w as usize, h as usize], rgb)
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
    let clamped: Vec<f32> = r.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
    let edges = gast_core::vision::canny::render_edges(&clamped, r.height as usize, r.width as usize);
    // Inverse depth is Σ wᵢ/zᵢ: divide by the opacity to get the covered pixels' own depth.
    let depth: Vec<f32> = r.inv_depth.iter().zip(&r.alpha).map(|(d, a)| if *a > 0.05 { d / a } else { 0.0 }).collect();
    Maps {
        rgb: rgb_image(r.width, r.height, &r.rgb),
        depth: gray_image(r.width, r.height, &depth, |i| r.alpha[i] > 0.05),
        depth_jet: jet_image(r.width, r.height, &gast_core::vision::colormap::depth_to_jet(&r.inv_depth, &r.alpha)),
        edges: gray_image(r.width, r.height, &edges, |_| true),
    }
}

/// What the style maps were computed for: the style file, texture scale, depth
/// polarity, depth provider and the style's depth image (if one was given).
pub type StyleMapsKey = (PathBuf, u32, DepthPolarity, DepthProvider, Option<PathBuf>);

/// The style's RGB, depth and edge maps at texture scale, as the optimisation
/// sees them (the run resolves its depth through the same cache), and the
/// warning when the chosen depth fell back to the heuristic.
pub fn style_maps(style: &StyleImage, key: &StyleMapsKey) -> (Maps, Option<String>) {
    let (path, scale, polarity, provider, image) = key;
    let (source, warning) = super::style_depth::source_for(path, style, *provider, image.as_deref(), None);
    let m = match &source {
        StyleDepthSource::Image(img) => {
            stage1::style_maps(&style.rgb, style.height, style.width, *scale as usize, img, *polarity)
        }
        StyleDepthSource::Heuristic => {
            let relief = ReliefDepth::default();
            stage1::style_maps(&style.rgb, style.height, style.width, *scale as usize, &relief, *polarity)
        }
    };
    let (w, h) = (m.width as u32, m.height as u32);
    let maps = Maps {
        rgb: rgb_image(w, h, &m.rgb),
        depth: gray_image(w, h, &m.depth, |_| true),
        depth_jet: jet_image(w, h, &gast_core::vision::colormap::depth_to_jet(&m.depth, &vec![1.0; m.depth.len()])),
        edges: gray_image(w, h, &m.edge, |_| true),
    };
    (maps, warning)
}

/// Views on a contact sheet exported from the studio (as `gast stylize` writes by default).
const SHEET_VIEWS: usize = 4;

/// What a contact sheet of a run is drawn from.
pub struct SheetJob {
    /// The scene as loaded.
    pub input: SharedGaussians,
    /// The newest snapshot of the run.
    pub result: SharedGaussians,
    /// The run's start: colour-matched scene, cameras, style maps, parameters.
    pub start: Arc<RunStart>,
    /// The sheet's first line.
    pub title: String,
    /// The sheet's second line.
    pub settings: String,
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

    /// Computes the style's maps.
    pub fn style_maps(&mut self, key: StyleMapsKey, style: Arc<StyleImage>) {
        self.spawn(move || {
            let (maps, warning) = style_maps(&style, &key);
            JobDone::StyleMaps(key, Box::new(maps), warning)
        });
    }

    /// Reads a scene file.
    pub fn load_scene(&mut self, path: PathBuf) {
        self.spawn(move || {
            let result = read_scene_file(&path);
            JobDone::Scene(path, result)
        });
    }

    /// Reads a style image file.
    pub fn load_style(&mut self, path: PathBuf) {
        self.spawn(move || {
            let result = read_style_file(&path);
            JobDone::Style(path, result)
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
                Ok(()) => JobDone::Exported(path, Vec::new()),
                Err(e) => JobDone::Failed(format!("exporting the view: {e}")),
            }
        });
    }

    /// Renders a view's inverse depth and writes it as EXR.
    pub fn export_depth(&mut self, g: SharedGaussians, cam: Camera, path: PathBuf) {
        self.spawn(move || {
            let r = render(&g, &cam, &RenderOptions::default());
            match gast_core::io::write_exr_depth(&path, r.width, r.height, &r.inv_depth) {
                Ok(()) => JobDone::Exported(path, Vec::new()),
                Err(e) => JobDone::Failed(format!("exporting the depth: {e}")),
            }
        });
    }

    /// Writes a turntable of `g` (beside `after` when given) into `dir`; reports the GIF.
    pub fn export_turntable(
        &mut self,
        g: SharedGaussians,
        after: Option<SharedGaussians>,
        opts: crate::turntable::TurntableOptions,
        dir: PathBuf,
    ) {
        self.spawn(move || match crate::turntable::write(&dir, &g, after.as_deref(), &opts, &mut |_, _| {}) {
            Ok(made) => JobDone::Exported(made.gif, Vec::new()),
            Err(e) => JobDone::Failed(format!("exporting the turntable: {}", crate::error_text(&e))),
        });
    }

    /// Renders the before / colour-matched / after views of a run and writes
    /// its contact sheet ([`crate::report::sheet`]) as PNG, atomically.
    pub fn export_sheet(&mut self, sheet: SheetJob, path: PathBuf) {
        self.spawn(move || {
            let views = RunViews {
                input: &sheet.input,
                colour_matched: &sheet.start.colour_matched,
                result: &sheet.result,
                cameras: &sheet.start.cameras,
                background: sheet.start.config.background,
            }
            .render(SHEET_VIEWS);
            let content = SheetContent {
                title: sheet.title,
                settings: sheet.settings,
                style: maps_tiles(&sheet.start.style_maps),
                views,
            };
            match write_sheet(&path, &content) {
                Ok(()) => JobDone::Exported(path, Vec::new()),
                Err(e) => JobDone::Failed(crate::error_text(&e)),
            }
        });
    }

    /// Writes Gaussians in the format the file's name asks for (`.ply`,
    /// `.compressed.ply`, `.spz`, `.sog`; see `gast_core::scene::save`).
    /// With `cameras` (the training cameras and the file they came from),
    /// writes them beside it as `cameras.json`, so the export reopens on them.
    /// A failure's message starts with [`SCENE_EXPORT_FAILED`].
    pub fn export_scene(&mut self, g: SharedGaussians, path: PathBuf, cameras: Option<(Vec<Camera>, PathBuf)>) {
        self.spawn(move || {
            if let Err(e) = gast_core::scene::save(&path, &g, &Default::default()) {
                return JobDone::Failed(format!("{SCENE_EXPORT_FAILED}: {e}"));
            }
            let Some((cameras, source)) = cameras else { return JobDone::Exported(path, Vec::new()) };
            match crate::views::write_cameras_beside(&path, &source, &cameras) {
                Ok(said) => JobDone::Exported(path, said),
                Err(e) => JobDone::Failed(format!("{SCENE_EXPORT_FAILED}'s cameras: {}", crate::error_text(&e))),
            }
        });
    }

    /// Results that arrived since the last call.
    pub fn poll(&mut self) -> Vec<JobDone> {
        let done: Vec<JobDone> = self.rx.try_iter().collect();
        self.running = self.running.saturating_sub(done.len());
        done
    }
}

#[cfg(test)]
mod tests {
    use super::{MapTextures, Maps, downscale};

    #[test]
    fn the_strip_draws_filtered_textures_and_keeps_the_full_ones() {
        let ctx = egui::Context::default();
        let img = |c| egui::ColorImage::filled([240, 120], c);
        let maps = Maps {
            rgb: img(egui::Color32::RED),
            depth: img(egui::Color32::GRAY),
            depth_jet: img(egui::Color32::BLUE),
            edges: img(egui::Color32::WHITE),
        };
        let mut t = MapTextures::new(&ctx, "test", maps);
        assert_eq!(t.aspects(), [2.0; 4]);
        t.fit(60);
        for i in 0..4 {
            assert_eq!(t.shown()[i].size(), [120, 60]);
            assert_eq!(t.full()[i].size(), [240, 120]);
        }
        // Never above the maps' own size.
        t.fit(500);
        assert_eq!(t.shown()[0].size(), [240, 120]);
    }

    #[test]
    fn downscale_keeps_thin_lines_as_grey() {
        // One-pixel white columns every fourth pixel on black, as an edge map's
        // lines: sampled one texel in four they would come out all white or all
        // black; filtered to a quarter, every column is the same grey.
        let (w, h) = (64, 32);
        let px = (0..w * h).map(|i| if i % w % 4 == 1 { egui::Color32::WHITE } else { egui::Color32::BLACK }).collect();
        let img = egui::ColorImage::new([w, h], px);
        let small = downscale(&img, 8);
        assert_eq!(small.size, [16, 8]);
        let greys: Vec<u8> = small.pixels.iter().map(|c| c.r()).collect();
        let (lo, hi) = greys.iter().fold((u8::MAX, 0), |(lo, hi), &g| (lo.min(g), hi.max(g)));
        assert!(hi - lo <= 16 && (40..=90).contains(&lo), "greys {lo}..{hi}");
        // Not enlarged, and kept as it is at its own size.
        assert_eq!(downscale(&img, 32).pixels, img.pixels);
        assert_eq!(downscale(&img, 64).size, [64, 32]);
    }
}
