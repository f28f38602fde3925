//! GAST Studio: the desktop window around a stylization run.
//!
//! A central wgpu splat viewport (orbit, pan, zoom, fly), a side panel with the
//! run's parameters, presets and buttons, an inspection strip (RGB, inverse
//! depth, edges of the current view, computed on the CPU off the UI thread) and
//! a bottom panel where every error is shown. Files arrive by drag and drop or
//! through dialogs; a bad file explains itself and the previous scene stays.
//!
//! Test switches: `GAST_STUDIO_EXIT_AFTER_FRAMES=N` closes the window after N
//! frames, `GAST_STUDIO_SCREENSHOT=path` saves a screenshot of the window first.
//! `GAST_STUDIO_PRESET=path` loads a preset at start; `GAST_STUDIO_RUN_STEPS=N`
//! presses Start once the scene and style are open, pauses after N steps and
//! saves the current Gaussians to `GAST_STUDIO_EXPORT` (the frame count of the
//! exit switch then starts from there), as a user would with the Export menu.

pub mod assets;
pub mod controls;
pub mod inspect;
mod panels;
pub mod session_link;
pub mod style_depth;
pub mod view;
pub mod viewport;
pub mod worker;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use anyhow::Context as _;
use egui::{Color32, Ui};
use gast_core::session::Command;
use gast_core::style::StyleConfig;
use gast_core::{Camera, Gaussians};

use session_link::{RunMonitor, RunStatus, SessionStarter};
use view::ViewState;
use viewport::{FrameStats, LiveRef, SceneRef, SharedGaussians, ViewportCallback, ViewportNotes, ViewportResources};

/// What `gast studio` was asked to open.
#[derive(Clone, Debug, Default)]
pub struct StudioArgs {
    /// A scene file; the demo scene when absent.
    pub scene: Option<PathBuf>,
    /// A style image; the first demo style when absent.
    pub style: Option<PathBuf>,
    /// Where runs compute at first (the device selector changes it).
    pub device: gast_core::gpu::DeviceChoice,
}

/// A loaded scene.
struct LoadedScene {
    name: String,
    scene: SceneRef,
}

/// A style image and its thumbnail.
struct LoadedStyle {
    path: PathBuf,
    /// The whole image, handed to the worker when a run starts.
    image: Arc<gast_core::session::StyleImage>,
    thumb: egui::ColorImage,
    texture: egui::TextureHandle,
    size: [usize; 2],
}

/// What the inspection maps were computed for: view, viewport size, scene and snapshot versions.
type InspectKey = (ViewState, [u32; 2], u64, u64);

/// Where the previous frame's screenshot request stands.
#[derive(Default)]
struct ScreenshotState {
    requested: bool,
    done: Arc<AtomicBool>,
}

/// The studio's state. One struct, updated only on the UI thread; workers talk
/// to it through channels and the snapshot slot.
pub struct StudioApp {
    scene: Option<LoadedScene>,
    snapshot: Option<SceneRef>,
    /// The running optimisation's GPU buffers, drawn instead of the snapshot when the viewport can.
    live: Option<LiveRef>,
    next_version: u64,
    styles: Vec<LoadedStyle>,
    style: Option<usize>,
    /// The run's parameters, edited by the side panel.
    pub config: StyleConfig,
    view: ViewState,
    cameras: Vec<Camera>,
    camera_source: String,
    split: f32,
    background: [f32; 3],
    /// Messages shown in the bottom panel, newest last.
    pub errors: Vec<String>,
    notice: String,
    run: RunMonitor,
    starter: Option<SessionStarter>,
    /// eframe's device as the GPU engine's context (none in headless tests).
    gpu: Option<gast_core::gpu::GpuContext>,
    /// Where runs compute (the device selector).
    device: gast_core::gpu::DeviceChoice,
    stats: Arc<Mutex<FrameStats>>,
    viewport_notes: Arc<Mutex<ViewportNotes>>,
    jobs: inspect::Jobs,
    maps: Option<[egui::TextureHandle; 3]>,
    /// The selected style's maps at texture scale, and what they were made for.
    style_maps: Option<(inspect::StyleMapsKey, [egui::TextureHandle; 3])>,
    style_maps_requested: Option<inspect::StyleMapsKey>,
    /// A depth image per style (by style path), for the `image` depth provider.
    style_depth_images: std::collections::HashMap<PathBuf, PathBuf>,
    /// Why the selected style's depth fell back to the heuristic, if it did.
    style_depth_warning: Option<String>,
    auto_inspect: bool,
    inspected_view: Option<InspectKey>,
    inspect_pending: Option<(InspectKey, std::time::Instant)>,
    viewport_px: [u32; 2],
    /// Scene files load on a worker thread (off while the command line's files open).
    load_in_background: bool,
    ctx: egui::Context,
    frames: u64,
    exit_after: Option<u64>,
    screenshot_path: Option<PathBuf>,
    screenshot: ScreenshotState,
    script: Option<ScriptedRun>,
}

/// The `GAST_STUDIO_RUN_STEPS` test switch's progress.
struct ScriptedRun {
    steps: usize,
    export: Option<PathBuf>,
    started: bool,
    /// Pause was sent; the export waits for the paused state's snapshot.
    pausing: bool,
    done: bool,
}

/// Opens the studio window with `starter` connected to the Start button.
pub fn run_with(args: StudioArgs, starter: Option<SessionStarter>) -> anyhow::Result<()> {
    let icon = assets::icon();
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("GAST Studio")
            .with_inner_size([1280.0, 800.0])
            .with_drag_and_drop(true)
            .with_icon(egui::IconData { width: icon.width(), height: icon.height(), rgba: icon.into_raw() }),
        wgpu_options: wgpu_options(),
        ..Default::default()
    };
    eframe::run_native(
        "GAST Studio",
        options,
        Box::new(move |cc| {
            let Some(rs) = cc.wgpu_render_state.as_ref() else {
                return Err("the studio needs the wgpu renderer, which did not start".into());
            };
            let gpu =
                gast_core::gpu::GpuContext::from_device(rs.device.clone(), rs.queue.clone(), rs.adapter.get_info());
            let mut resources = ViewportResources::new(&rs.device, rs.target_format);
            resources.use_gpu_sort(gpu.clone());
            rs.renderer.write().callback_resources.insert(resources);
            let mut app = StudioApp::new(cc.egui_ctx.clone(), args);
            app.set_gpu(gpu);
            if let Some(starter) = starter {
                app.set_session_starter(starter);
            }
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| anyhow::anyhow!("the studio window failed: {e}"))
}

/// eframe's device, created with the adapter's limits and the optional
/// features the GPU engine's kernels use, so the optimiser and the viewport
/// share one device (and the optimiser's buffers can be drawn without a copy).
fn wgpu_options() -> egui_wgpu::WgpuConfiguration {
    let setup = egui_wgpu::WgpuSetupCreateNew {
        device_descriptor: Arc::new(gast_core::gpu::device_descriptor),
        ..egui_wgpu::WgpuSetupCreateNew::without_display_handle()
    };
    egui_wgpu::WgpuConfiguration { wgpu_setup: egui_wgpu::WgpuSetup::CreateNew(setup), ..Default::default() }
}

impl eframe::App for StudioApp {
    fn ui(&mut self, ui: &mut Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }
}

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.trim().parse().ok())
}

impl StudioApp {
    /// The studio with `args` opened (the demo scene and style when absent).
    pub fn new(ctx: egui::Context, args: StudioArgs) -> Self {
        let waker_ctx = ctx.clone();
        let waker: Arc<dyn Fn() + Send + Sync> = Arc::new(move || waker_ctx.request_repaint());
        let mut app = Self {
            scene: None,
            snapshot: None,
            live: None,
            next_version: 1,
            styles: Vec::new(),
            style: None,
            config: StyleConfig::default(),
            view: ViewState::default(),
            cameras: Vec::new(),
            camera_source: String::new(),
            split: 0.5,
            background: [0.0; 3],
            errors: Vec::new(),
            notice: String::new(),
            run: RunMonitor::default(),
            starter: None,
            gpu: None,
            device: args.device,
            stats: Arc::default(),
            viewport_notes: Arc::default(),
            jobs: inspect::Jobs::new(waker),
            maps: None,
            style_maps: None,
            style_maps_requested: None,
            style_depth_images: std::collections::HashMap::new(),
            style_depth_warning: None,
            auto_inspect: true,
            inspected_view: None,
            inspect_pending: None,
            viewport_px: [640, 480],
            load_in_background: false,
            ctx,
            frames: 0,
            exit_after: env_u64("GAST_STUDIO_EXIT_AFTER_FRAMES"),
            screenshot_path: std::env::var_os("GAST_STUDIO_SCREENSHOT").map(PathBuf::from),
            screenshot: ScreenshotState::default(),
            script: env_u64("GAST_STUDIO_RUN_STEPS").map(|n| ScriptedRun {
                steps: n as usize,
                export: std::env::var_os("GAST_STUDIO_EXPORT").map(PathBuf::from),
                started: false,
                pausing: false,
                done: false,
            }),
        };
        if let Some(p) = std::env::var_os("GAST_STUDIO_PRESET") {
            app.load_preset(Path::new(&p));
        }
        match &args.scene {
            Some(p) => app.open_scene(p),
            None => app.open_demo_scene(),
        }
        let style = args.style.clone().or_else(|| {
            let p = assets::source_assets_dir().join(assets::DEMO_STYLES[0]);
            p.exists().then_some(p)
        });
        match style {
            Some(p) => app.open_style(&p),
            None => app.open_generated_styles(),
        }
        app.load_in_background = true;
        app
    }

    /// The device runs may use: eframe's own, so the optimiser and the viewport share it.
    pub fn set_gpu(&mut self, gpu: gast_core::gpu::GpuContext) {
        self.gpu = Some(gpu);
    }

    /// Connects the code that spawns session workers; until then Start is disabled.
    pub fn set_session_starter(&mut self, starter: SessionStarter) {
        self.starter = Some(starter);
    }

    /// Shows an error in the bottom panel (and keeps everything else as it was).
    pub fn report(&mut self, err: anyhow::Error) {
        self.errors.push(format!("{err:#}"));
        if self.errors.len() > 20 {
            self.errors.remove(0);
        }
    }

    /// The Gaussians shown as "current": the newest snapshot, else the scene.
    fn current(&self) -> Option<SharedGaussians> {
        self.snapshot.as_ref().or(self.scene.as_ref().map(|s| &s.scene)).map(|s| s.gaussians.clone())
    }

    fn set_scene(&mut self, name: String, g: Gaussians) {
        let g = Arc::new(g);
        self.view.fit(&g);
        self.cameras = view::orbit_ring(&g, self.view.up, 12, 800, 600);
        self.camera_source = "orbit".into();
        self.scene = Some(LoadedScene { name, scene: SceneRef { version: self.next_version, gaussians: g.into() } });
        self.next_version += 1;
        self.snapshot = None;
        self.maps = None;
        self.inspected_view = None;
    }

    /// Loads a scene file (on a worker thread once the window runs); on failure
    /// the error is shown and the previous scene stays.
    pub fn open_scene(&mut self, path: &Path) {
        if self.load_in_background {
            self.notice = format!("loading {}…", path.display());
            self.jobs.load_scene(path.to_path_buf());
        } else {
            let result = inspect::read_scene_file(path);
            self.finish_open_scene(path, result);
        }
    }

    fn finish_open_scene(&mut self, path: &Path, result: anyhow::Result<inspect::SceneFile>) {
        match result {
            Ok(f) if f.gaussians.is_empty() => {
                let keep = self.keeping_scene();
                self.report(anyhow::anyhow!("{}: the scene holds no Gaussians; {keep}", path.display()))
            }
            Ok(f) => {
                let g = f.gaussians;
                let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                self.notice = format!("opened {} ({} Gaussians, SH degree {})", path.display(), g.len(), g.sh_degree);
                self.set_scene(name, g);
                self.run.log.extend(f.warnings.iter().map(|w| format!("scene: {w}")));
                if let Some((set, dir)) = f.cameras {
                    self.set_cameras(set, &dir);
                }
            }
            Err(e) => {
                let keep = self.keeping_scene();
                self.report(anyhow::anyhow!("{e:#}; {keep}"))
            }
        }
    }

    /// What a failed open leaves on screen, for the end of its message.
    fn keeping_scene(&self) -> &'static str {
        if self.scene.is_some() { "keeping the previous scene" } else { "no scene is open" }
    }

    fn open_demo_scene(&mut self) {
        let path = assets::source_assets_dir().join(assets::DEMO_SCENE);
        if path.exists() {
            self.open_scene(&path);
        } else {
            self.set_scene("demo scene (generated)".into(), assets::demo_scene());
        }
    }

    fn add_style(&mut self, path: PathBuf, img: image::RgbImage) {
        let thumb = image::imageops::thumbnail(&img, 96, (96 * img.height() / img.width().max(1)).max(1));
        let color = egui::ColorImage::from_rgb([thumb.width() as usize, thumb.height() as usize], thumb.as_raw());
        let texture =
            self.ctx.load_texture(format!("style {}", path.display()), color.clone(), egui::TextureOptions::LINEAR);
        let size = [img.width() as usize, img.height() as usize];
        let image = Arc::new(gast_core::session::StyleImage { width: size[0], height: size[1], rgb: img.into_raw() });
        self.styles.retain(|s| s.path != path);
        self.styles.insert(0, LoadedStyle { path, image, thumb: color, texture, size });
        self.styles.truncate(8);
        self.style = Some(0);
    }

    /// Loads a style image; on failure the error is shown and the previous style stays.
    pub fn open_style(&mut self, path: &Path) {
        match image::open(path) {
            Ok(img) => self.add_style(path.to_path_buf(), img.to_rgb8()),
            Err(e) => {
                let keep = if self.styles.is_empty() { "no style is open" } else { "keeping the previous style" };
                self.report(anyhow::anyhow!(
                    "{}: not a style image this build can read (PNG, JPEG, WebP): {e}; {keep}",
                    path.display()
                ))
            }
        }
    }

    fn open_generated_styles(&mut self) {
        for (name, img) in assets::demo_styles().into_iter().rev() {
            self.add_style(PathBuf::from(name), img);
        }
    }

    fn set_cameras(&mut self, set: gast_core::camera::CameraSet, from: &Path) {
        self.cameras = set.cameras;
        self.camera_source = from.display().to_string();
        for w in set.warnings {
            self.run.log.push(format!("cameras: {w}"));
        }
    }

    /// Loads optimisation cameras (COLMAP, `cameras.json`, `transforms.json`) for the snap list.
    pub fn open_cameras(&mut self, path: &Path) {
        match gast_core::camera::load(path) {
            Ok(set) if set.cameras.is_empty() => {
                self.report(anyhow::anyhow!("{}: no cameras in the file", path.display()))
            }
            Ok(set) => {
                self.notice = format!("{} cameras from {}", set.cameras.len(), path.display());
                self.set_cameras(set, path);
            }
            Err(e) => self.report(anyhow::anyhow!("{e}; keeping the current camera list")),
        }
    }

    /// Opens a file by what it is: a style image, a preset, cameras or a scene.
    pub fn open_any(&mut self, path: &Path) {
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        match ext.as_str() {
            "png" | "jpg" | "jpeg" | "webp" => self.open_style(path),
            "bin" | "txt" => self.open_cameras(path),
            "json" => {
                // cameras.json is a list, transforms.json has frames, SOG's meta.json has means; the rest are presets.
                let text = std::fs::read_to_string(path).unwrap_or_default();
                let value: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
                if value.is_array() || value.get("frames").is_some() {
                    self.open_cameras(path);
                } else if value.get("means").is_some() {
                    self.open_scene(path);
                } else {
                    self.load_preset(path);
                }
            }
            _ if path.is_dir() && !path.join("meta.json").exists() => self.open_cameras(path),
            _ => self.open_scene(path),
        }
    }

    /// Loads a preset file into the configuration.
    pub fn load_preset(&mut self, path: &Path) {
        let result = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the preset", path.display()))
            .and_then(|t| {
                StyleConfig::from_json(&t).with_context(|| format!("{}: not a style preset", path.display()))
            });
        match result {
            Ok(c) => {
                let problems = c.problems();
                if problems.is_empty() {
                    self.config = c;
                    self.notice = format!("preset {} loaded", path.display());
                } else {
                    self.report(anyhow::anyhow!(
                        "{}: {}; keeping the current parameters",
                        path.display(),
                        problems.join("; ")
                    ));
                }
            }
            Err(e) => self.report(e),
        }
    }

    /// Saves the configuration as a preset (atomically).
    pub fn save_preset(&mut self, path: &Path) {
        let json = self.config.to_json();
        match gast_core::io::write_bytes(path, json.as_bytes()) {
            Ok(()) => self.notice = format!("preset saved to {}", path.display()),
            Err(e) => self.report(anyhow::Error::new(e).context("saving the preset")),
        }
    }

    fn viewport_camera(&self) -> Camera {
        self.view.camera(self.viewport_px[0], self.viewport_px[1])
    }

    fn poll_workers(&mut self) {
        if let Ok(mut notes) = self.viewport_notes.lock() {
            self.errors.append(&mut notes.errors);
            self.run.log.append(&mut notes.warnings);
        }
        if let Some(snap) = self.run.poll() {
            self.snapshot = Some(SceneRef { version: self.next_version, gaussians: SharedGaussians::Snapshot(snap) });
            self.next_version += 1;
        }
        // While the run is live its GPU buffers are drawn; once it ends, its final snapshot.
        match self.run.live() {
            Some(l) if self.live.as_ref().is_some_and(|r| r.live.same_run(&l)) => {}
            Some(l) => {
                self.live = Some(LiveRef { version: self.next_version, live: l });
                self.next_version += 1;
            }
            None => self.live = None,
        }
        if let RunStatus::Failed(msg) = &self.run.status {
            let msg = format!("the run failed: {msg}");
            if self.errors.last() != Some(&msg) {
                self.errors.push(msg);
            }
        }
        for done in self.jobs.poll() {
            match done {
                inspect::JobDone::Maps(m) => {
                    let opts = egui::TextureOptions::LINEAR;
                    self.maps = Some([
                        self.ctx.load_texture("inspect rgb", m.rgb, opts),
                        self.ctx.load_texture("inspect depth", m.depth, opts),
                        self.ctx.load_texture("inspect edges", m.edges, opts),
                    ]);
                }
                inspect::JobDone::StyleMaps(key, m, warning) => {
                    self.style_depth_warning = warning;
                    let opts = egui::TextureOptions::LINEAR;
                    self.style_maps = Some((
                        key,
                        [
                            self.ctx.load_texture("style rgb", m.rgb, opts),
                            self.ctx.load_texture("style depth", m.depth, opts),
                            self.ctx.load_texture("style edges", m.edges, opts),
                        ],
                    ));
                }
                inspect::JobDone::Scene(path, result) => self.finish_open_scene(&path, result),
                inspect::JobDone::Exported(p) => self.notice = format!("wrote {}", p.display()),
                inspect::JobDone::Failed(e) => self.errors.push(e),
            }
        }
    }

    fn handle_drops(&mut self, ui: &Ui) {
        let dropped: Vec<PathBuf> = ui.input(|i| {
            i.raw.dropped_files.iter().map(|f| f.path().to_path_buf()).filter(|p| !p.as_os_str().is_empty()).collect()
        });
        for p in dropped {
            self.open_any(&p);
        }
    }

    /// Adopts the context the window draws with (a test harness brings its own)
    /// and moves the style thumbnails onto it.
    fn adopt_context(&mut self, ctx: &egui::Context) {
        self.ctx = ctx.clone();
        for s in &mut self.styles {
            s.texture =
                ctx.load_texture(format!("style {}", s.path.display()), s.thumb.clone(), egui::TextureOptions::LINEAR);
        }
    }

    /// The whole window.
    pub fn show(&mut self, ui: &mut Ui) {
        if self.frames == 0 {
            self.adopt_context(ui.ctx());
        }
        self.frames += 1;
        self.poll_workers();
        self.handle_drops(ui);
        egui::Panel::top("menu").show(ui, |ui| self.menu_bar(ui));
        egui::Panel::bottom("status").resizable(true).default_size(90.0).show(ui, |ui| self.status_panel(ui));
        egui::Panel::right("controls").resizable(true).default_size(330.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.side_panel(ui));
        });
        egui::Panel::bottom("inspect").resizable(false).exact_size(190.0).show(ui, |ui| self.inspect_panel(ui));
        egui::CentralPanel::default().show(ui, |ui| self.viewport(ui));
        // After the viewport took this frame's input, so the maps follow the newest view.
        if self.auto_inspect {
            self.request_inspection(false);
        }
        self.request_style_maps();
        self.test_switches(ui.ctx());
    }

    /// Drives the `GAST_STUDIO_RUN_STEPS` switch; true once it is done (or absent).
    fn scripted_run(&mut self, ctx: &egui::Context) -> bool {
        let Some(script) = &mut self.script else { return true };
        if script.done {
            return true;
        }
        ctx.request_repaint();
        if !script.started {
            if self.scene.is_some() && self.style.is_some() && self.starter.is_some() {
                script.started = true;
                self.start_run();
            }
            return false;
        }
        let finished = matches!(self.run.status, RunStatus::Finished { .. } | RunStatus::Failed(_));
        let have_snapshot = self.snapshot.as_ref().is_some_and(|s| !s.gaussians.is_empty());
        if !script.pausing && self.run.steps.len() >= script.steps && have_snapshot {
            // The worker puts the paused state's snapshot in the slot before it
            // reports Paused, so the export below is exactly what the run holds.
            script.pausing = true;
            self.run.send(Command::Pause);
        }
        let paused = script.pausing && self.run.status == RunStatus::Paused;
        if paused || finished {
            script.done = true;
            let export = script.export.clone();
            eprintln!("studio: scripted run paused after {} steps ({:?})", self.run.steps.len(), self.run.status);
            if let (Some(path), Some(g)) = (export, self.current()) {
                match gast_core::scene::save(&path, &g, &Default::default()) {
                    Ok(()) => eprintln!("studio: exported {} Gaussians to {}", g.len(), path.display()),
                    Err(e) => self.report(anyhow::Error::new(e).context("exporting the scripted run")),
                }
            }
            if let Some(n) = self.exit_after {
                self.exit_after = Some(self.frames + n);
            }
            return true;
        }
        false
    }

    /// Starts the selected style's maps when the style, texture scale or depth
    /// polarity changed since they were last made or asked for.
    fn request_style_maps(&mut self) {
        let Some(style) = self.style.and_then(|k| self.styles.get(k)) else { return };
        let depth_image = self.style_depth_images.get(&style.path).cloned();
        let key = (
            style.path.clone(),
            self.config.texture_scale,
            self.config.depth_polarity,
            self.config.depth_provider,
            depth_image,
        );
        let have = self.style_maps.as_ref().is_some_and(|(k, _)| *k == key);
        if have || self.style_maps_requested.as_ref() == Some(&key) {
            return;
        }
        self.style_maps_requested = Some(key.clone());
        let image = style.image.clone();
        self.jobs.style_maps(key, image);
    }

    fn test_switches(&mut self, ctx: &egui::Context) {
        if !self.scripted_run(ctx) {
            return;
        }
        let Some(n) = self.exit_after else { return };
        ctx.request_repaint();
        if let Some(path) = self.screenshot_path.clone()
            && !self.screenshot.requested
            && self.frames + 2 >= n
        {
            self.screenshot.requested = true;
            let done = self.screenshot.done.clone();
            ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(egui::ScreenshotCallback::new(move |img| {
                let rgb: Vec<f32> =
                    img.pixels.iter().flat_map(|c| [c.r(), c.g(), c.b()].map(|v| v as f32 / 255.0)).collect();
                match gast_core::io::write_png_rgb(&path, img.size[0] as u32, img.size[1] as u32, &rgb) {
                    Ok(()) => eprintln!("studio: screenshot saved to {}", path.display()),
                    Err(e) => eprintln!("studio: screenshot failed: {e}"),
                }
                done.store(true, Ordering::SeqCst);
            })));
        }
        let shot_pending = self.screenshot.requested && !self.screenshot.done.load(Ordering::SeqCst);
        if self.frames >= n && !shot_pending {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
        if self.frames >= n + 600 {
            eprintln!("studio: the screenshot never arrived; closing");
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }

    fn viewport(&mut self, ui: &mut Ui) {
        let size = ui.available_size();
        let (rect, response) = ui.allocate_exact_size(size, egui::Sense::click_and_drag());
        let ppp = ui.ctx().pixels_per_point();
        self.viewport_px =
            [(rect.width() * ppp).round().max(1.0) as u32, (rect.height() * ppp).round().max(1.0) as u32];
        let interacting = self.handle_view_input(ui, &response, rect);
        let full = self.viewport_camera();
        // Half resolution while the view moves keeps big scenes responsive on software GPUs.
        let camera = if interacting && self.scene.as_ref().is_some_and(|s| s.scene.gaussians.len() > 200_000) {
            full.with_longer_side(full.width.max(full.height) / 2)
        } else {
            full
        };
        let callback = ViewportCallback {
            camera,
            before: self.scene.as_ref().map(|s| s.scene.clone()),
            after: self.snapshot.clone(),
            live: self.live.clone(),
            split: self.split,
            background: self.background,
            stats: self.stats.clone(),
            notes: self.viewport_notes.clone(),
        };
        ui.painter().add(egui_wgpu::Callback::new_paint_callback(rect, callback));
        if self.snapshot.is_some() && self.split > 0.0 && self.split < 1.0 {
            let x = rect.left() + rect.width() * self.split;
            ui.painter().text(
                egui::pos2(x - 6.0, rect.top() + 6.0),
                egui::Align2::RIGHT_TOP,
                "before",
                egui::FontId::proportional(13.0),
                Color32::WHITE,
            );
            ui.painter().text(
                egui::pos2(x + 6.0, rect.top() + 6.0),
                egui::Align2::LEFT_TOP,
                "after",
                egui::FontId::proportional(13.0),
                Color32::WHITE,
            );
        }
        if self.scene.is_none() {
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "drop a scene (.ply) here",
                egui::FontId::proportional(18.0),
                Color32::GRAY,
            );
        }
    }

    /// Applies the mouse and keyboard to the view; true while the view is being moved.
    fn handle_view_input(&mut self, ui: &Ui, response: &egui::Response, rect: egui::Rect) -> bool {
        let delta = response.drag_delta();
        if response.dragged_by(egui::PointerButton::Primary) {
            self.view.orbit(delta.x * 0.006, -delta.y * 0.006);
        }
        if response.dragged_by(egui::PointerButton::Secondary) || response.dragged_by(egui::PointerButton::Middle) {
            self.view.pan(delta.x, delta.y, rect.height());
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.view.zoom(scroll);
            }
            if ui.input(|i| i.key_pressed(egui::Key::F))
                && let Some(g) = self.current()
            {
                self.view.fit(&g);
            }
        }
        let flying = ui.input(|i| i.pointer.secondary_down()) && (response.hovered() || response.dragged());
        if flying {
            let (dt, keys) = ui.input(|i| {
                let k = |key| if i.key_down(key) { 1.0f32 } else { 0.0 };
                (
                    i.stable_dt.min(0.1),
                    [
                        k(egui::Key::D) - k(egui::Key::A),
                        k(egui::Key::E) - k(egui::Key::Q),
                        k(egui::Key::W) - k(egui::Key::S),
                    ],
                )
            });
            if keys != [0.0; 3] {
                self.view.fly(keys[0], keys[1], keys[2], dt);
                ui.ctx().request_repaint();
            }
        }
        response.dragged() || flying
    }
}

#[cfg(test)]
mod tests;
