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
//! With `GAST_STUDIO_GO_ON=1` the scripted run goes on from the kept run
//! offered ([`recovery`]) instead of pressing Start.
//! `GAST_STUDIO_STRENGTH=C[,S]` sets the strength sliders (percent);
//! `GAST_STUDIO_WINDOW=WxH` opens the window at that size (1280×800 without),
//! so a screenshot can show the whole side panel. `gast studio --headless`
//! runs the same app with no window ([`headless`]).

pub mod assets;
pub mod controls;
mod headless;
pub mod inspect;
mod leave;
mod open;
mod panels;
pub mod recovery;
mod scripted;
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

pub use headless::run as run_headless;
use session_link::{RunMonitor, RunStatus, SessionStarter};
use view::ViewState;
use viewport::{FrameStats, LiveRef, SceneRef, SharedGaussians, ViewportCallback, ViewportNotes, ViewportResources};

/// What `gast studio` was asked to open.
#[derive(Clone, Debug, Default)]
pub struct StudioArgs {
    /// A scene file; the demo scene when absent.
    pub scene: Option<PathBuf>,
    /// Style images, opened in order (the last one selected); the first
    /// demo style when none is given.
    pub styles: Vec<PathBuf>,
    /// Where runs compute at first (the device selector changes it).
    pub device: gast_core::gpu::DeviceChoice,
}

/// A loaded scene.
struct LoadedScene {
    name: String,
    /// The file it came from (`None`: generated).
    path: Option<PathBuf>,
    scene: SceneRef,
}

/// A style image and its thumbnail.
struct LoadedStyle {
    path: PathBuf,
    /// The whole image, which a run and the style's maps take: kept while the
    /// style is selected, and always for a generated one; a file's is let go
    /// when another style is picked and read again when it is picked back
    /// (eight recent styles at full size held 432 MB each at 12,000 px).
    image: Option<Arc<gast_core::session::StyleImage>>,
    /// Read from a file, which can be read again.
    from_file: bool,
    /// That file's bytes when it was read ([`inspect::StyleFile::file`]).
    file: Option<String>,
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
    /// Asking before a close or an open drops an unexported result.
    leave: leave::LeaveGuard,
    /// Runs kept against a crash: this studio's, and one offered to go on from.
    recovery: recovery::Recovery,
    /// A newer snapshot than `snapshot`, waiting for [`SOFTWARE_VIEW_INTERVAL`]
    /// on a software renderer, and when `snapshot` was taken up.
    newer_snapshot: Option<Arc<gast_core::session::Snapshot>>,
    snapshot_taken_at: Option<std::time::Instant>,
    /// The viewport draws on a software renderer (lavapipe): the CPU the run needs.
    software_viewport: bool,
    /// How much of the stylization is shown and exported (colour, shape; 1 = all).
    strength: [f32; 2],
    /// The snapshot blended toward the run's colour-matched scene by
    /// `strength` ([`gast_core::scene::blend()`]), with the snapshot version and
    /// strength it was made for; the snapshot itself at full strength.
    shown: Option<(u64, [f32; 2], SceneRef)>,
    /// The running optimisation's GPU buffers, drawn instead of the snapshot when the viewport can.
    live: Option<LiveRef>,
    next_version: u64,
    styles: Vec<LoadedStyle>,
    style: Option<usize>,
    /// The run's parameters, edited by the side panel.
    pub config: StyleConfig,
    view: ViewState,
    cameras: Vec<Camera>,
    /// The file or folder the training cameras came from; `None`: the orbit.
    camera_source: Option<PathBuf>,
    /// Where the before | after line sits (0: all after, 1: all before).
    split: f32,
    /// Whether the viewport compares before | after (off: the after side alone).
    compare: bool,
    /// The split line is being dragged (a primary drag that started on it).
    dragging_split: bool,
    /// Runs on the CPU fit about ten minutes ([`session_link::StartRequest::fit_budget`]).
    fit_budget: bool,
    /// The run start whose planned settings the editor has taken ([`Self::adopt_plan`]).
    adopted: Option<std::sync::Weak<gast_core::session::RunStart>>,
    /// The cycles the editor held before the plan's replaced them: the most
    /// a re-plan gives ([`Self::replan_after_first_cycle`]).
    asked_cycles: u32,
    /// The run start whose cycles were re-planned, or found to need none.
    replanned: Option<std::sync::Weak<gast_core::session::RunStart>>,
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
    maps: Option<inspect::MapTextures>,
    /// The selected style's maps at texture scale, and what they were made for.
    style_maps: Option<(inspect::StyleMapsKey, inspect::MapTextures)>,
    style_maps_requested: Option<inspect::StyleMapsKey>,
    /// A depth image per style (by style path), for the `image` depth provider.
    style_depth_images: std::collections::HashMap<PathBuf, PathBuf>,
    /// Why the selected style's depth fell back to the heuristic, if it did.
    style_depth_warning: Option<String>,
    auto_inspect: bool,
    inspected_view: Option<InspectKey>,
    inspect_pending: Option<(InspectKey, std::time::Instant)>,
    viewport_px: [u32; 2],
    /// Where the viewport was laid out last frame (in points).
    viewport_rect: egui::Rect,
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
    /// `GAST_STUDIO_GO_ON`: go on from the kept run offered instead of pressing Start.
    go_on: bool,
    export: Option<PathBuf>,
    started: bool,
    done: bool,
    /// The run could not start (no scene or style loaded, or refused).
    failed: bool,
}

/// Opens the studio window with `starter` connected to the Start button.
pub fn run_with(args: StudioArgs, starter: Option<SessionStarter>) -> anyhow::Result<()> {
    let icon = assets::icon();
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("GAST Studio")
            .with_inner_size(window_size(std::env::var("GAST_STUDIO_WINDOW").ok().as_deref()))
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
            Ok(Box::new(StudioApp::on_device(cc.egui_ctx.clone(), args, rs, starter)))
        }),
    )
    .map_err(|e| anyhow::anyhow!("the studio window failed: {e}"))
}

/// Storage buffers the viewport's kernels bind in one shader stage (its
/// projection pass; `shaders/splat_project.wgsl`).
const VIEWPORT_STORAGE_BUFFERS: u32 = 4;

/// How often a running optimisation's newest snapshot is drawn when the
/// viewport renders in software ([`StudioApp::take_newer_snapshot`]).
const SOFTWARE_VIEW_INTERVAL: std::time::Duration = std::time::Duration::from_secs(4);

/// Whether the window's device can run the viewport's compute passes: a GL
/// fallback without compute storage buffers cannot (wgpu would refuse the
/// pipelines), and the studio then says so instead of stopping.
fn viewport_support(limits: &wgpu::Limits, adapter: &str) -> Result<(), String> {
    let found = limits.max_storage_buffers_per_shader_stage;
    if found >= VIEWPORT_STORAGE_BUFFERS {
        return Ok(());
    }
    Err(format!(
        "the viewport cannot draw on this graphics driver: it needs {VIEWPORT_STORAGE_BUFFERS} storage buffers per \
         shader stage and \"{adapter}\" offers {found} (a GL fallback); install a Vulkan driver (Debian: \
         mesa-vulkan-drivers) and restart. Runs on the CPU and exports still work."
    ))
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

    fn on_exit(&mut self) {
        self.shut_down();
    }
}

/// The window's size from `WxH` (1280×800 without one, or when it does not read as two sizes of 200 to 8192).
fn window_size(switch: Option<&str>) -> [f32; 2] {
    switch
        .and_then(|s| s.split_once(['x', '×']))
        .and_then(|(w, h)| Some([w.trim().parse::<f32>().ok()?, h.trim().parse::<f32>().ok()?]))
        .filter(|s| s.iter().all(|v| (200.0..=8192.0).contains(v)))
        .unwrap_or([1280.0, 800.0])
}

/// The `GAST_STUDIO_STRENGTH=C[,S]` test switch: the colour and shape
/// strengths in percent (one value for both); full strength without it.
fn env_strength() -> [f32; 2] {
    let Ok(text) = std::env::var("GAST_STUDIO_STRENGTH") else { return [1.0, 1.0] };
    let v: Vec<f32> =
        text.split(',').filter_map(|t| t.trim().parse::<f32>().ok()).map(|p| (p / 100.0).clamp(0.0, 1.0)).collect();
    match v.as_slice() {
        [c] => [*c, *c],
        [c, s] => [*c, *s],
        _ => [1.0, 1.0],
    }
}

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.trim().parse().ok())
}

impl StudioApp {
    /// The studio on the renderer's device `rs` (the window's, or the
    /// headless one's): the device becomes the GPU engine's context and the
    /// viewport's, when it can run the viewport's compute passes, and
    /// `starter` is connected to the Start button.
    fn on_device(
        ctx: egui::Context,
        args: StudioArgs,
        rs: &egui_wgpu::RenderState,
        starter: Option<SessionStarter>,
    ) -> Self {
        let mut app = StudioApp::new(ctx, args);
        let info = rs.adapter.get_info();
        app.software_viewport = info.device_type == wgpu::DeviceType::Cpu;
        match viewport_support(&rs.device.limits(), &info.name) {
            Ok(()) => {
                let gpu = gast_core::gpu::GpuContext::from_device(rs.device.clone(), rs.queue.clone(), info);
                let mut resources = ViewportResources::new(&rs.device, rs.target_format);
                resources.use_gpu_sort(gpu.clone());
                rs.renderer.write().callback_resources.insert(resources);
                app.set_gpu(gpu);
            }
            // The window still opens (menus, export, CPU runs); the viewport stays empty.
            Err(why) => app.report(anyhow::anyhow!(why)),
        }
        if let Some(starter) = starter {
            app.set_session_starter(starter);
        }
        app
    }

    /// The studio with `args` opened (the demo scene and style when absent).
    pub fn new(ctx: egui::Context, args: StudioArgs) -> Self {
        let waker_ctx = ctx.clone();
        let waker: Arc<dyn Fn() + Send + Sync> = Arc::new(move || waker_ctx.request_repaint());
        let mut app = Self {
            scene: None,
            snapshot: None,
            leave: leave::LeaveGuard::default(),
            recovery: recovery::Recovery::in_folder(recovery::folder()),
            newer_snapshot: None,
            snapshot_taken_at: None,
            software_viewport: false,
            strength: env_strength(),
            shown: None,
            live: None,
            next_version: 1,
            styles: Vec::new(),
            style: None,
            config: StyleConfig::default(),
            view: ViewState::default(),
            cameras: Vec::new(),
            camera_source: None,
            split: 0.5,
            compare: true,
            dragging_split: false,
            fit_budget: true,
            adopted: None,
            asked_cycles: StyleConfig::default().cycles,
            replanned: None,
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
            viewport_rect: egui::Rect::NOTHING,
            load_in_background: false,
            ctx,
            frames: 0,
            exit_after: env_u64("GAST_STUDIO_EXIT_AFTER_FRAMES"),
            screenshot_path: std::env::var_os("GAST_STUDIO_SCREENSHOT").map(PathBuf::from),
            screenshot: ScreenshotState::default(),
            script: env_u64("GAST_STUDIO_RUN_STEPS").map(|n| ScriptedRun {
                steps: n as usize,
                go_on: std::env::var_os("GAST_STUDIO_GO_ON").is_some_and(|v| v == "1"),
                export: std::env::var_os("GAST_STUDIO_EXPORT").map(PathBuf::from),
                started: false,
                done: false,
                failed: false,
            }),
        };
        if let Some(p) = std::env::var_os("GAST_STUDIO_PRESET") {
            app.load_preset(Path::new(&p));
        }
        match &args.scene {
            Some(p) => app.open_scene(p),
            None => app.open_demo_scene(),
        }
        let demo = assets::source_assets_dir().join(assets::DEMO_STYLES[0]);
        if !args.styles.is_empty() {
            args.styles.iter().for_each(|p| app.open_style(p));
        } else if demo.exists() {
            app.open_style(&demo);
        } else {
            app.open_generated_styles();
        }
        app.load_in_background = true;
        app
    }

    /// The device runs may use: eframe's own, so the optimiser and the viewport share it.
    pub fn set_gpu(&mut self, gpu: gast_core::gpu::GpuContext) {
        self.gpu = Some(gpu);
    }

    /// Connects the code that spawns session workers; until then Start is disabled.
    /// Ends the studio's run and removes the state it kept: the studio
    /// closes (after asking about an unexported result). The slots go first,
    /// so the run's end writes no state only to have it removed.
    pub(super) fn shut_down(&mut self) {
        self.recovery.discard_all();
        self.run.shut_down();
    }

    pub fn set_session_starter(&mut self, starter: SessionStarter) {
        self.starter = Some(starter);
    }

    /// Shows an error in the bottom panel (and keeps everything else as it was).
    pub fn report(&mut self, err: anyhow::Error) {
        self.errors.push(crate::error_text(&err));
        if self.errors.len() > 20 {
            self.errors.remove(0);
        }
    }

    /// The Gaussians shown as "current": the newest snapshot at the chosen
    /// strength, else the scene.
    fn current(&self) -> Option<SharedGaussians> {
        self.current_ref().map(|s| s.gaussians.clone())
    }

    /// [`Self::current`] with its version.
    fn current_ref(&self) -> Option<&SceneRef> {
        self.after().or(self.scene.as_ref().map(|s| &s.scene))
    }

    /// The stylized side as shown and exported: the newest snapshot, blended
    /// toward the colour-matched scene when a strength is below 100%.
    fn after(&self) -> Option<&SceneRef> {
        match &self.shown {
            Some((_, _, blended)) if self.strength != [1.0, 1.0] => Some(blended),
            _ => self.snapshot.as_ref(),
        }
    }

    /// Makes [`StudioApp::after`] follow a new snapshot or strength (a blend
    /// of every Gaussian on the UI thread, done once per snapshot or slider
    /// change: about 60 million floats for a million Gaussians at SH degree 3).
    fn refresh_strength(&mut self) {
        let (Some(snap), Some(start)) = (&self.snapshot, self.run.start()) else {
            self.shown = None;
            return;
        };
        if self.strength == [1.0, 1.0]
            || self.shown.as_ref().is_some_and(|(v, s, _)| *v == snap.version && *s == self.strength)
        {
            return;
        }
        let strength = gast_core::scene::Strength { colour: self.strength[0], shape: self.strength[1] };
        match gast_core::scene::blend(&start.colour_matched, &snap.gaussians, strength) {
            Ok(g) => {
                let blended = SceneRef { version: self.next_version, gaussians: SharedGaussians::Owned(Arc::new(g)) };
                self.next_version += 1;
                self.shown = Some((snap.version, self.strength, blended));
            }
            Err(e) => {
                self.strength = [1.0, 1.0];
                self.errors.push(format!("strength: {e}"));
            }
        }
    }

    fn viewport_camera(&self) -> Camera {
        self.view.camera(self.viewport_px[0], self.viewport_px[1])
    }

    /// Takes into the editor what the run's plan set (`worker::plan_for_cpu`:
    /// the working resolution, the cycles, the texture scale) once per run
    /// start, so that a slider moved during the run sends them back rather
    /// than the settings the plan replaced (it sent the unplanned 30 cycles
    /// and the run outgrew its ten minutes). The other settings stay as the
    /// user has them.
    fn adopt_plan(&mut self) {
        let Some(start) = self.run.start() else { return };
        if is_start(&self.adopted, &start) {
            return;
        }
        let planned = &start.config;
        self.asked_cycles = self.config.cycles;
        (self.config.resolution, self.config.cycles, self.config.texture_scale) =
            (planned.resolution, planned.cycles, planned.texture_scale);
        self.adopted = Some(Arc::downgrade(&start));
    }

    /// A planned CPU run's cycles rest on one machine's step times
    /// (`worker::plan_for_cpu`): at the end of the first cycle with a steady
    /// pace (every view visited, then revisits), the run takes the cycles
    /// that pace fits in the plan's ten minutes, up to those the editor
    /// asked for, as `gast stylize` does
    /// ([`gast_core::session::plan::replan_cycles`]); once per run, and not
    /// when the cycles were moved during the run.
    fn replan_after_first_cycle(&mut self) {
        use gast_core::session::plan::{AUTO_RUN_BUDGET_S, replan_cycles};
        let Some((start, planned_s)) = self.replan_due() else { return };
        let Some(pace) = self.run.pace_at_cycle_end() else { return };
        let Some(steady) = pace.steady_s else { return };
        self.replanned = Some(Arc::downgrade(&start));
        if self.config.cycles != start.config.cycles {
            return;
        }
        let per_cycle = start.config.schedule().steps_per_cycle();
        let fits = replan_cycles(pace, per_cycle, AUTO_RUN_BUDGET_S, self.asked_cycles);
        let Some(cycles) = fits.filter(|&c| c != self.config.cycles) else { return };
        self.config.cycles = cycles;
        self.run.send(Command::SetConfig(Box::new(self.config.clone())));
        let after = pace.cycles_said(per_cycle);
        self.run.log.push(format!(
            "re-planned after {after}: {cycles} cycles (its steps took {steady:.2} s after each view's first visit, \
             the plan's model {planned_s:.2} s)"
        ));
    }

    /// The live planned run (its start and the plan's seconds a step) whose
    /// re-plan ([`Self::replan_after_first_cycle`]) has not been made yet.
    fn replan_due(&self) -> Option<(Arc<gast_core::session::RunStart>, f64)> {
        let (start, planned_s) = (self.run.start()?, self.run.planned_step_s?);
        let due = !is_start(&self.replanned, &start) && is_start(&self.adopted, &start) && self.run.is_live();
        due.then_some((start, planned_s))
    }

    /// The steps the progress bar counts to: while a planned run's re-plan
    /// is due ([`Self::replan_due`]) and its cycles are the plan's, the
    /// cycles its pace so far fits in the plan's ten minutes
    /// ([`session_link::RunMonitor::replanned_total`]); `None`, the run's own
    /// steps, otherwise.
    pub(crate) fn progress_total(&self) -> Option<u32> {
        use gast_core::session::plan::AUTO_RUN_BUDGET_S;
        let (start, _) = self.replan_due().filter(|(start, _)| self.config.cycles == start.config.cycles)?;
        let per_cycle = start.config.schedule().steps_per_cycle();
        self.run.replanned_total(per_cycle, AUTO_RUN_BUDGET_S, self.asked_cycles)
    }

    /// Takes up the run's newest snapshot: at once on a GPU, at most every
    /// [`SOFTWARE_VIEW_INTERVAL`] while a run goes on with a software
    /// renderer, where drawing a whole-frame scene takes about half a second
    /// of a 2-core machine (fern at 1,104×690 on lavapipe) and every
    /// snapshot's draw would take that from the run. A paused or ended run's is taken at once.
    fn take_newer_snapshot(&mut self) {
        if self.newer_snapshot.is_none() {
            return;
        }
        let since = self.snapshot_taken_at.map(|t| t.elapsed());
        if self.software_viewport
            && matches!(self.run.status, RunStatus::Running)
            && let Some(since) = since.filter(|&s| s < SOFTWARE_VIEW_INTERVAL)
        {
            self.ctx.request_repaint_after(SOFTWARE_VIEW_INTERVAL - since);
            return;
        }
        if let Some(snap) = self.newer_snapshot.take() {
            self.snapshot = Some(SceneRef { version: self.next_version, gaussians: SharedGaussians::Snapshot(snap) });
            self.next_version += 1;
            self.snapshot_taken_at = Some(std::time::Instant::now());
        }
    }

    fn poll_workers(&mut self) {
        if let Ok(mut notes) = self.viewport_notes.lock() {
            self.errors.append(&mut notes.errors);
            self.run.log.append(&mut notes.warnings);
        }
        if let Some(snap) = self.run.poll() {
            self.newer_snapshot = Some(snap);
        }
        self.take_newer_snapshot();
        self.adopt_plan();
        self.replan_after_first_cycle();
        self.look_for_kept_run();
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
                inspect::JobDone::Maps(m) => self.maps = Some(inspect::MapTextures::new(&self.ctx, "inspect", *m)),
                inspect::JobDone::StyleMaps(key, m, warning) => {
                    self.style_depth_warning = warning;
                    self.style_maps = Some((key, inspect::MapTextures::new(&self.ctx, "style", *m)));
                }
                inspect::JobDone::Scene(path, result) => self.finish_open_scene(&path, result),
                inspect::JobDone::Style(path, result) => {
                    let opened = result.is_ok().then(|| format!("opened {}", path.display()));
                    self.finish_open_style(path, result);
                    if let Some(notice) = opened {
                        self.notice = notice;
                    }
                }
                inspect::JobDone::Exported(p, said) => {
                    self.notice = format!("wrote {}", p.display());
                    if said.iter().any(|l| l.starts_with("wrote")) {
                        self.notice += " and its cameras.json";
                    }
                    self.run.log.extend(said);
                    self.scene_exported(&p);
                }
                inspect::JobDone::Failed(e) => {
                    if e.starts_with(inspect::SCENE_EXPORT_FAILED) {
                        self.scene_export_failed(&e);
                    }
                    self.errors.push(e);
                }
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
        self.refresh_strength();
        self.handle_drops(ui);
        self.guard_close(ui);
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
        self.leave_modal(ui);
        self.test_switches(ui.ctx());
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
        let Some(image) = style.image.clone() else { return };
        self.style_maps_requested = Some(key.clone());
        self.jobs.style_maps(key, image);
    }

    fn viewport(&mut self, ui: &mut Ui) {
        let size = ui.available_size();
        let (rect, response) = ui.allocate_exact_size(size, egui::Sense::click_and_drag());
        let ppp = ui.ctx().pixels_per_point();
        self.viewport_rect = rect;
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
            after: self.after().cloned(),
            // The engine's buffers hold the run at full strength.
            live: self.live.clone().filter(|_| self.strength == [1.0, 1.0]),
            split: self.shown_split(),
            rect,
            background: self.background,
            stats: self.stats.clone(),
            notes: self.viewport_notes.clone(),
        };
        ui.painter().add(egui_wgpu::Callback::new_paint_callback(rect, callback));
        if self.snapshot.is_some() && self.compare && self.split > 0.0 && self.split < 1.0 {
            let x = rect.left() + rect.width() * self.split;
            // The handle: drag it to move the line (B hides the comparison).
            let handle = egui::pos2(x, rect.center().y);
            let hot = self.dragging_split || response.hover_pos().is_some_and(|p| (p.x - x).abs() <= SPLIT_GRAB_PX);
            ui.painter().circle(
                handle,
                if hot { 9.0 } else { 7.0 },
                Color32::from_rgb(250, 210, 60),
                egui::Stroke::new(1.5, Color32::BLACK),
            );
            // White on a dark pill, legible over a bright wall as over black.
            for (dx, align, label) in
                [(-6.0, egui::Align2::RIGHT_TOP, "before"), (6.0, egui::Align2::LEFT_TOP, "after")]
            {
                let galley =
                    ui.painter().layout_no_wrap(label.into(), egui::FontId::proportional(13.0), Color32::WHITE);
                let at = align.anchor_size(egui::pos2(x + dx, rect.top() + 6.0), galley.size());
                ui.painter().rect_filled(at.expand(3.0), 4.0, Color32::from_black_alpha(160));
                ui.painter().galley(at.min, galley, Color32::WHITE);
            }
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

    /// The split the viewport draws: the slider's, or 0 (after alone) with the comparison hidden.
    fn shown_split(&self) -> f32 {
        if self.compare { self.split } else { 0.0 }
    }

    /// A primary drag that starts on the before | after line moves the line
    /// instead of orbiting; true while it does.
    fn drag_split(&mut self, ui: &Ui, response: &egui::Response, rect: egui::Rect) -> bool {
        let on_line = |x: f32| (x - (rect.left() + rect.width() * self.split)).abs() <= SPLIT_GRAB_PX;
        let comparing = self.snapshot.is_some() && self.compare;
        if comparing
            && response.drag_started_by(egui::PointerButton::Primary)
            && ui.input(|i| i.pointer.press_origin()).is_some_and(|p| on_line(p.x))
        {
            self.dragging_split = true;
        }
        if !self.dragging_split {
            return false;
        }
        if response.dragged_by(egui::PointerButton::Primary)
            && let Some(p) = response.interact_pointer_pos()
        {
            // Never all the way to an edge: the handle stays where it can be grabbed.
            self.split = ((p.x - rect.left()) / rect.width().max(1.0)).clamp(0.02, 0.98);
        }
        if !response.dragged() {
            self.dragging_split = false;
        }
        true
    }

    /// Applies the mouse and keyboard to the view; true while the view is being moved.
    fn handle_view_input(&mut self, ui: &Ui, response: &egui::Response, rect: egui::Rect) -> bool {
        if response.hovered() && ui.input(|i| i.key_pressed(egui::Key::B)) {
            self.compare = !self.compare;
        }
        if self.drag_split(ui, response, rect) {
            return false;
        }
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
            if ui.input(|i| i.key_pressed(egui::Key::F)) {
                self.frame_scene();
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

/// How near the before | after line (in points) a drag grabs it.
const SPLIT_GRAB_PX: f32 = 10.0;

/// Whether `seen` is the run start `start` (a run the editor has already
/// handled, by [`StudioApp::adopt_plan`] or its re-plan).
fn is_start(
    seen: &Option<std::sync::Weak<gast_core::session::RunStart>>,
    start: &Arc<gast_core::session::RunStart>,
) -> bool {
    seen.as_ref().is_some_and(|a| std::ptr::eq(a.as_ptr(), Arc::as_ptr(start)))
}

#[cfg(test)]
mod tests;
