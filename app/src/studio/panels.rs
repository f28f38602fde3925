//! The studio's panels around the viewport: menu bar, status and errors, the
//! side panel (style strip, run buttons and chart, parameters, view), and the
//! inspection strip.

use std::sync::Arc;

use egui::{Color32, RichText, Ui};
use gast_core::session::Command;
use gast_core::style::StyleConfig;

use super::inspect::{self, SheetJob};
use super::session_link::{RunStatus, StartRequest};
use super::view::{UpAxis, ViewState};
use super::viewport::SharedGaussians;
use super::{StudioApp, controls};
use crate::report::sheet;
use crate::turntable::TurntableOptions;

/// The file dialog that names an exported scene; the name's ending picks
/// the format (NAME.compressed.ply for PlayCanvas's).
pub(super) fn scene_save_dialog() -> Option<std::path::PathBuf> {
    rfd::FileDialog::new()
        .add_filter("INRIA PLY or PlayCanvas NAME.compressed.ply", &["ply"])
        .add_filter("Niantic SPZ", &["spz"])
        .add_filter("PlayCanvas SOG bundle", &["sog"])
        .set_file_name("stylized.ply")
        .save_file()
}

impl StudioApp {
    pub(super) fn menu_bar(&mut self, ui: &mut Ui) {
        ui.horizontal(|ui| {
            ui.label(RichText::new("GAST Studio").strong());
            ui.separator();
            if ui.button("Open scene…").clicked()
                && let Some(p) = rfd::FileDialog::new().add_filter("Gaussian splats", &["ply"]).pick_file()
            {
                self.open_scene_guarded(&p);
            }
            if ui.button("Open style…").clicked()
                && let Some(p) =
                    rfd::FileDialog::new().add_filter("Images", &["png", "jpg", "jpeg", "webp"]).pick_file()
            {
                self.open_style(&p);
            }
            ui.menu_button("Export", |ui| self.export_menu(ui));
            ui.separator();
            ui.weak("drop scenes, style images or presets onto the window");
        });
    }

    pub(super) fn export_menu(&mut self, ui: &mut Ui) {
        let current = self.current();
        let cam = self.viewport_camera();
        ui.add_enabled_ui(current.is_some(), |ui| {
            let Some(g) = current else { return };
            if ui.button("Current Gaussians as .ply, .compressed.ply, .spz or .sog…").clicked()
                && let Some(p) = scene_save_dialog()
            {
                self.export_current_scene(p, false);
            }
            let have_run = self.run.start().is_some() && self.snapshot.is_some();
            if ui
                .add_enabled(have_run, egui::Button::new("Contact sheet of the run (PNG)…"))
                .on_hover_text("the style and four views before / colour-matched / after, in RGB and depth")
                .on_disabled_hover_text("start a run first")
                .clicked()
                && let Some(p) =
                    rfd::FileDialog::new().add_filter("PNG", &["png"]).set_file_name("sheet.png").save_file()
            {
                self.export_sheet(p);
            }
            if ui.button("Current view as PNG…").clicked()
                && let Some(p) =
                    rfd::FileDialog::new().add_filter("PNG", &["png"]).set_file_name("view.png").save_file()
            {
                self.jobs.export_png(g.clone(), cam.clone(), self.background, p);
            }
            if ui.button("Current view's inverse depth as EXR…").clicked()
                && let Some(p) =
                    rfd::FileDialog::new().add_filter("OpenEXR", &["exr"]).set_file_name("depth.exr").save_file()
            {
                self.jobs.export_depth(g.clone(), cam.clone(), p);
            }
            ui.separator();
            let compare = self.snapshot.is_some();
            let label = if compare { "Turntable, before | after…" } else { "Turntable…" };
            if ui
                .button(label)
                .on_hover_text(
                    "36 frames around the scene (through its own cameras for a forward-facing capture) as PNG \
                     and an animated GIF, into a folder",
                )
                .clicked()
                && let Some(dir) = rfd::FileDialog::new().set_title("Folder for the turntable").pick_folder()
            {
                self.export_turntable(dir, TurntableOptions::default());
            }
        });
    }

    /// Starts writing a turntable into `dir` in the background: the loaded
    /// scene, beside the newest snapshot of a run when there is one (the GIF's
    /// path appears in the status line when it is done).
    pub(super) fn export_turntable(&mut self, dir: std::path::PathBuf, opts: TurntableOptions) {
        let Some(scene) = &self.scene else { return };
        let before = scene.scene.gaussians.clone();
        let after = self.after().map(|s| s.gaussians.clone());
        // The scene's own cameras, when it has them: a forward-facing capture loops through them.
        let training = if self.camera_source.is_some() { self.cameras.clone() } else { Vec::new() };
        let opts =
            TurntableOptions { up: self.view.up.vector().to_array(), background: self.background, training, ..opts };
        self.notice = format!("writing a turntable into {}…", dir.display());
        self.jobs.export_turntable(before, after, opts, dir);
    }

    /// Starts writing the contact sheet of the current run (the loaded scene,
    /// the run's colour-matched start and its newest snapshot) to `path` in the
    /// background; the path appears in the status line when it is written, an
    /// error in the bottom panel.
    pub(super) fn export_sheet(&mut self, path: std::path::PathBuf) {
        let (Some(scene), Some(start), Some(snapshot)) = (&self.scene, self.run.start(), &self.snapshot) else {
            self.report(anyhow::anyhow!("{}: no contact sheet without a run; start one first", path.display()));
            return;
        };
        let step = match &snapshot.gaussians {
            SharedGaussians::Snapshot(s) => s.step,
            SharedGaussians::Owned(_) => 0,
        };
        let style = self
            .style
            .and_then(|k| self.styles.get(k))
            .and_then(|s| s.path.file_name())
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let job = SheetJob {
            input: scene.scene.gaussians.clone(),
            result: snapshot.gaussians.clone(),
            title: format!("{} x {style}", scene.name),
            settings: sheet::settings_line(
                &start.config,
                (0, step),
                self.run.elapsed_s(),
                start.focus_on_object,
                start.coverage,
            ),
            start,
        };
        self.notice = format!("writing the contact sheet {}…", path.display());
        self.jobs.export_sheet(job, path);
    }

    pub(super) fn status_panel(&mut self, ui: &mut Ui) {
        let stats = self.stats.lock().map(|s| *s).unwrap_or_default();
        ui.horizontal(|ui| {
            match &self.scene {
                Some(s) => ui.label(format!("{}: {} Gaussians", s.name, s.scene.gaussians.len())),
                None => ui.label("no scene"),
            };
            ui.separator();
            let kept = if stats.kept > 0 { " (kept from the last frame)" } else { "" };
            ui.label(format!(
                "drawn {}{kept}  sort {:.1} ms  prepare {:.1} ms",
                stats.drawn, stats.sort_ms, stats.prepare_ms
            ));
            if self.software_viewport && matches!(self.run.status, RunStatus::Running) {
                ui.label(format!(
                    "software renderer: the view takes the run's newest state every {} s",
                    super::SOFTWARE_VIEW_INTERVAL.as_secs()
                ));
            }
            if let Some(step) = stats.live_step {
                ui.label(format!("after: step {step} from the optimiser's GPU buffers"));
            }
            if self.jobs.running > 0 {
                ui.separator();
                ui.spinner();
                ui.label(format!("{} background job(s)", self.jobs.running));
            }
            if !self.notice.is_empty() {
                ui.separator();
                ui.weak(&self.notice);
            }
        });
        if !self.errors.is_empty() {
            ui.horizontal(|ui| {
                ui.label(
                    RichText::new(format!("{} error(s)", self.errors.len()))
                        .color(Color32::from_rgb(255, 110, 90))
                        .strong(),
                );
                if ui.small_button("clear").clicked() {
                    self.errors.clear();
                }
            });
            egui::ScrollArea::vertical().stick_to_bottom(true).show(ui, |ui| {
                for e in &self.errors {
                    ui.label(RichText::new(e).color(Color32::from_rgb(255, 130, 110)));
                }
            });
        }
        for line in self.run.log.iter().rev().take(3) {
            ui.weak(line);
        }
    }

    pub(super) fn side_panel(&mut self, ui: &mut Ui) {
        ui.heading("Style");
        ui.horizontal_wrapped(|ui| {
            let mut pick = None;
            for (k, s) in self.styles.iter().enumerate() {
                let selected = self.style == Some(k);
                let img = egui::Image::new(&s.texture)
                    .fit_to_exact_size(egui::vec2(64.0, 64.0 * s.size[1] as f32 / s.size[0].max(1) as f32));
                let r = ui.add(egui::Button::image(img).selected(selected)).on_hover_text(s.path.display().to_string());
                if r.clicked() {
                    pick = Some(k);
                }
            }
            if let Some(k) = pick {
                self.select_style(k);
            }
        });
        if let Some(s) = self.style.and_then(|k| self.styles.get(k)) {
            ui.weak(format!("{} ({}×{})", s.path.display(), s.size[0], s.size[1]));
            let path = s.path.clone();
            self.style_depth_row(ui, &path);
        }

        ui.separator();
        ui.heading("Run");
        self.run_buttons(ui);
        self.kept_run_offer(ui);
        controls::loss_chart(ui, &self.run.steps);
        if let Some((p, eta)) = self.run.progress(self.progress_total()) {
            ui.add(egui::ProgressBar::new(p).text(format!("{:.0}%  ETA {}", p * 100.0, time_left(eta))));
        }
        if let Some(c) = self.run.steps.last().and_then(|s| s.colour) {
            let object = self.run.start().is_some_and(|s| s.focus_on_object);
            colour_line(ui, &c, object);
        }
        if let Some(g) = self.current() {
            ui.weak(format!("current: {} Gaussians", g.len()));
        }

        ui.separator();
        ui.heading("Parameters");
        let coverage = self.run.start().map(|s| s.coverage);
        let style = self.style.and_then(|k| self.styles.get(k)).map(|s| s.size);
        let gaussians = self.scene.as_ref().map(|s| s.scene.gaussians.len());
        if controls::config_editor(ui, &mut self.config, coverage, style, gaussians) && self.run.is_live() {
            self.run.send(Command::SetConfig(Box::new(self.config.clone())));
        }
        ui.horizontal(|ui| {
            if ui.button("Save preset…").clicked()
                && let Some(p) =
                    rfd::FileDialog::new().add_filter("Preset", &["json"]).set_file_name("preset.json").save_file()
            {
                self.save_preset(&p);
            }
            if ui.button("Load preset…").clicked()
                && let Some(p) = rfd::FileDialog::new().add_filter("Preset", &["json"]).pick_file()
            {
                self.load_preset(&p);
            }
            if ui.button("Defaults").clicked() {
                self.config = StyleConfig::default();
            }
        });
        for p in self.config.problems() {
            ui.colored_label(Color32::from_rgb(255, 130, 110), p);
        }

        ui.separator();
        ui.heading("View");
        self.view_controls(ui);
    }

    pub(super) fn run_buttons(&mut self, ui: &mut Ui) {
        let live = self.run.is_live();
        let paused = self.run.status == RunStatus::Paused;
        ui.horizontal(|ui| {
            let can_start = self.starter.is_some() && !live && self.scene.is_some() && self.style.is_some();
            let why = if self.starter.is_none() {
                "no session runner is connected to this build yet"
            } else if live {
                "a run is in progress"
            } else {
                "open a scene and a style first"
            };
            if ui.add_enabled(can_start, egui::Button::new("Start")).on_disabled_hover_text(why).clicked() {
                self.start_run();
            }
            let not_live = "no run in progress";
            if ui.add_enabled(live && !paused, egui::Button::new("Pause")).on_disabled_hover_text(not_live).clicked() {
                self.run.send(Command::Pause);
            }
            if ui.add_enabled(live && paused, egui::Button::new("Resume")).on_disabled_hover_text(not_live).clicked() {
                self.run.send(Command::Resume);
            }
            if ui.add_enabled(live, egui::Button::new("Stop")).on_disabled_hover_text(not_live).clicked() {
                self.run.send(Command::Stop);
            }
        });
        self.device_selector(ui, live);
        // The budget is the CPU's: a run on the GPU keeps the resolution and cycles set.
        let on_gpu = self.device.pick(self.gpu.as_ref()).is_some();
        ui.add_enabled(
            !live && !on_gpu,
            egui::Checkbox::new(&mut self.fit_budget, "fit the run to about 10 min on the CPU"),
        )
        .on_hover_text(
            "on the CPU, lower the working resolution and the cycles so that the whole run takes about ten \
             minutes, as `gast stylize` does; off: the resolution and cycles set below",
        )
        .on_disabled_hover_text(if on_gpu {
            "the run steps on the GPU: it keeps the resolution and cycles set below"
        } else {
            "a run is in progress"
        });
        let status = match &self.run.status {
            RunStatus::Idle => "idle".to_string(),
            RunStatus::Running => "running".into(),
            RunStatus::Paused => "paused".into(),
            RunStatus::Finished { completed: true } => "finished".into(),
            RunStatus::Finished { completed: false } => "stopped".into(),
            RunStatus::Failed(m) => format!("failed: {m}"),
        };
        ui.weak(format!("status: {status}"));
    }

    /// Where the next run computes: auto, CPU or GPU, and what that means on this machine.
    fn device_selector(&mut self, ui: &mut Ui, live: bool) {
        use gast_core::gpu::DeviceChoice;
        ui.horizontal(|ui| {
            ui.add_enabled_ui(!live, |ui| {
                egui::ComboBox::new("device", "device").selected_text(self.device.name()).show_ui(ui, |ui| {
                    for choice in DeviceChoice::ALL {
                        ui.selectable_value(&mut self.device, choice, choice.name());
                    }
                });
            });
            let runs_on = match self.device.pick(self.gpu.as_ref()) {
                Some(g) => format!("GPU: {}", g.describe()),
                None if self.device == DeviceChoice::Gpu => "no GPU device: the run will use the CPU".into(),
                None => "CPU".into(),
            };
            ui.weak(runs_on);
        });
    }

    /// The depth provider next to the style, the style's depth-image slot, and
    /// the warning when the chosen depth fell back to the heuristic.
    fn style_depth_row(&mut self, ui: &mut Ui, style: &std::path::Path) {
        use gast_core::vision::style_depth::DepthProvider;
        ui.horizontal(|ui| {
            ui.label("depth");
            egui::ComboBox::from_id_salt("depth provider")
                .selected_text(self.config.depth_provider.name())
                .show_ui(ui, |ui| {
                    for p in DepthProvider::ALL {
                        ui.selectable_value(&mut self.config.depth_provider, p, p.name());
                    }
                })
                .response
                .on_hover_text("learned: Depth Anything V2 (fetched once) · image: a depth image for this style · heuristic: built in");
            if ui.button("Depth image…").on_hover_text("a depth image for this style (PNG or EXR)").clicked()
                && let Some(p) = rfd::FileDialog::new().add_filter("Depth images", &["png", "exr"]).pick_file()
            {
                self.style_depth_images.insert(style.to_path_buf(), p);
                self.config.depth_provider = DepthProvider::Image;
            }
        });
        if let Some(p) = self.style_depth_images.get(style) {
            ui.weak(format!("depth image: {}", p.display()));
        }
        if let Some(w) = &self.style_depth_warning {
            short_warning(ui, "style depth warning", w);
        }
    }

    pub(super) fn start_run(&mut self) {
        self.start_run_from(None);
    }

    /// Starts a run, going on from the kept run `resume` when given (its
    /// settings are the editor's by then); its state is kept against a crash.
    pub(super) fn start_run_from(&mut self, resume: Option<super::recovery::Offer>) {
        let (Some(_), Some(scene), Some((style, image))) = (
            &self.starter,
            &self.scene,
            self.style.and_then(|k| self.styles.get(k)).and_then(|s| Some((s, s.image.clone()?))),
        ) else {
            return;
        };
        let problems = self.config.problems();
        if !problems.is_empty() {
            self.report(anyhow::anyhow!("cannot start: {}", problems.join("; ")));
            return;
        }
        let ctx = self.ctx.clone();
        let scene = scene.scene.gaussians.to_arc();
        let style_path = style.path.clone();
        let style_depth_image = match &resume {
            Some(offer) => offer.record.style_depth_image.clone(),
            None => self.style_depth_images.get(&style.path).cloned(),
        };
        if resume.is_none()
            && let Some(kept) = self.recovery.offer.take()
        {
            // Start begins afresh, as the offer says: the kept run goes now, not at the new run's first write.
            kept.discard();
        }
        let keep = self.new_slot(&style_path, [image.width, image.height], style_depth_image.clone());
        let request = StartRequest {
            scene,
            style: image,
            style_path,
            style_depth_image,
            config: self.config.clone(),
            cameras: self.cameras.clone(),
            // Every step's report wakes the window (progress, loss chart); a
            // software renderer, whose frames take the run's CPU, redraws
            // for them at most once a second.
            waker: if self.software_viewport {
                Arc::new(move || ctx.request_repaint_after(std::time::Duration::from_secs(1)))
            } else {
                Arc::new(move || ctx.request_repaint())
            },
            gpu: self.device.pick(self.gpu.as_ref()),
            fit_budget: self.fit_budget && resume.is_none(),
            keep,
            resume,
        };
        let Some(starter) = &self.starter else { return };
        match starter(request) {
            Ok(link) => self.run.attach(link),
            Err(e) => self.report(e.context("starting the run")),
        }
    }

    pub(super) fn view_controls(&mut self, ui: &mut Ui) {
        ui.horizontal(|ui| {
            if ui
                .button("Fit")
                .on_hover_text("frame the scene's robust bounds, or a forward-facing capture from its first camera (F)")
                .clicked()
            {
                self.frame_scene();
            }
            if ui.button("Reset").clicked() {
                let up = self.view.up;
                self.view = ViewState { up, ..ViewState::default() };
                self.frame_scene();
            }
            egui::ComboBox::new("up", "up axis").selected_text(format!("{:?}", self.view.up)).show_ui(ui, |ui| {
                for up in [UpAxis::NegY, UpAxis::PosY, UpAxis::PosZ] {
                    ui.selectable_value(&mut self.view.up, up, format!("{up:?}"));
                }
            });
        });
        let mut fov = self.view.fov_y.to_degrees();
        if ui.add(egui::Slider::new(&mut fov, 10.0..=120.0).text("vertical fov°")).changed() {
            self.view.fov_y = fov.to_radians();
        }
        ui.horizontal(|ui| {
            ui.checkbox(&mut self.compare, "")
                .on_hover_text("compare before | after in the viewport (B); off: the after side alone");
            ui.add_enabled(self.compare, egui::Slider::new(&mut self.split, 0.0..=1.0).text("before | after"))
                .on_hover_text("left of the line: the scene as loaded; or drag the line's handle in the viewport");
        });
        let strength_hover = "how much of the stylization the after side shows and exports: 0% is the run's \
                              colour-matched scene, 100% the stylized one; no new optimisation";
        for (k, what) in [(0, "colour strength"), (1, "shape strength")] {
            let mut pct = self.strength[k] * 100.0;
            let slider = egui::Slider::new(&mut pct, 0.0..=100.0).suffix("%").text(what);
            if ui.add_enabled(self.run.start().is_some(), slider).on_hover_text(strength_hover).changed() {
                self.strength[k] = (pct / 100.0).clamp(0.0, 1.0);
            }
        }
        let mut bg = self.background;
        ui.horizontal(|ui| {
            ui.label("background");
            if ui.color_edit_button_rgb(&mut bg).changed() {
                self.background = bg;
            }
        });
        egui::CollapsingHeader::new(format!("Cameras ({}, {})", self.cameras.len(), self.camera_source_name())).show(
            ui,
            |ui| {
                let mut snap = None;
                for (k, c) in self.cameras.iter().enumerate() {
                    if ui.selectable_label(false, &c.name).clicked() {
                        snap = Some(k);
                    }
                }
                if let Some(k) = snap {
                    let focus =
                        self.current().and_then(|g| gast_core::camera::robust_bounds(&g.means)).map(|b| b.center);
                    let cam = self.cameras[k].clone();
                    self.view.snap_to(&cam, focus);
                }
            },
        );
        ui.weak("left drag: orbit · right/middle drag: pan · wheel: zoom · hold right + WASD/QE: fly");
    }

    pub(super) fn inspect_panel(&mut self, ui: &mut Ui) {
        ui.horizontal(|ui| {
            ui.label(RichText::new("Inspect").strong());
            ui.checkbox(&mut self.auto_inspect, "follow the view");
            if ui.button("Refresh").clicked() {
                self.inspected_view = None;
                self.request_inspection(true);
            }
            ui.weak("RGB · inverse depth, grey and JET · edges: the current view (CPU rasterizer) | the style at texture scale");
        });
        // One height for all eight maps, so that they fit the strip side by side.
        let aspect = |maps: &inspect::MapTextures| maps.aspects().iter().sum::<f32>();
        let total = self.maps.as_ref().map_or(0.0, aspect) + self.style_maps.as_ref().map_or(0.0, |(_, m)| aspect(m));
        let room = ui.available_width() - 9.0 * ui.spacing().item_spacing.x - 8.0;
        let h = if total > 0.0 { (room / total).clamp(40.0, 150.0) } else { 150.0 };
        let px = (h * ui.ctx().pixels_per_point()).round() as usize;
        for maps in self.maps.iter_mut().chain(self.style_maps.iter_mut().map(|(_, m)| m)) {
            maps.fit(px);
        }
        let show = |ui: &mut Ui, maps: &inspect::MapTextures, what: &str| {
            for (i, name) in inspect::MAP_NAMES.iter().enumerate() {
                let size = egui::vec2(h * maps.aspects()[i], h);
                ui.add(egui::Image::new(&maps.shown()[i]).fit_to_exact_size(size)).on_hover_ui(|ui| {
                    ui.label(format!("{what}: {name}"));
                    let t = &maps.full()[i];
                    let [w, th] = t.size();
                    let ppp = ui.ctx().pixels_per_point();
                    ui.add(egui::Image::new(t).fit_to_exact_size(egui::vec2(w as f32, th as f32) / ppp));
                });
            }
        };
        ui.horizontal(|ui| {
            match &self.maps {
                Some(maps) => show(ui, maps, "view"),
                None => {
                    ui.weak("no maps yet");
                }
            }
            ui.separator();
            if let Some((_, maps)) = &self.style_maps {
                show(ui, maps, "style");
            }
        });
    }

    /// Starts the inspection maps of the current view once it has been still for
    /// a moment (or at once when `force`); while waiting, asks egui to look again.
    pub(super) fn request_inspection(&mut self, force: bool) {
        let Some(g) = self.current() else { return };
        let scene_v = self.scene.as_ref().map(|s| s.scene.version).unwrap_or(0);
        let snap_v = self.after().map(|s| s.version).unwrap_or(0);
        let key = (self.view.clone(), self.viewport_px, scene_v, snap_v);
        if !force && self.inspected_view.as_ref() == Some(&key) {
            return;
        }
        let now = std::time::Instant::now();
        let still_since = match &self.inspect_pending {
            Some((k, t)) if *k == key => *t,
            _ => {
                self.inspect_pending = Some((key.clone(), now));
                now
            }
        };
        let settle = std::time::Duration::from_millis(150);
        if self.jobs.running > 0 || (!force && now.duration_since(still_since) < settle) {
            self.ctx.request_repaint_after(settle);
            return;
        }
        self.inspected_view = Some(key);
        self.inspect_pending = None;
        let cam = self.viewport_camera().with_longer_side(240);
        self.jobs.inspect(g, cam, self.background);
    }
}

/// A warning as one line (its first sentence) with the whole text behind a
/// click, so that a long one does not push the panel's controls down.
pub(super) fn short_warning(ui: &mut Ui, id: &str, text: &str) {
    let color = ui.visuals().warn_fg_color;
    let (head, rest) = first_sentence(text, 72);
    if rest.is_empty() {
        ui.colored_label(color, format!("warning: {head}"));
        return;
    }
    egui::CollapsingHeader::new(RichText::new(format!("warning: {head}…")).color(color)).id_salt(id).show(ui, |ui| {
        ui.label(RichText::new(text).color(color).small());
    });
}

/// The first sentence of `text`, cut at a word to at most `max` characters,
/// and whether anything is left after it.
pub(super) fn first_sentence(text: &str, max: usize) -> (String, &str) {
    let end = [text.find(". "), text.find(": ")].into_iter().flatten().min().map_or(text.len(), |i| i + 1);
    let head: &str = &text[..end];
    let head = if head.chars().count() <= max {
        head.trim_end_matches(['.', ':']).to_string()
    } else {
        let cut: String = head.chars().take(max).collect();
        match cut.rfind(' ') {
            Some(i) if i > max / 2 => cut[..i].to_string(),
            _ => cut,
        }
    };
    let shown = head.len();
    (head, if shown >= text.trim_end_matches('.').len() { "" } else { &text[shown..] })
}

/// The colour watch's reading under the progress bar: the object's luminance
/// and chroma against the colour-matched state's, and a warning in red with
/// what to change when the colours collapse (`object`: whether the run's
/// losses focus on the object already).
fn colour_line(ui: &mut Ui, c: &gast_core::session::ColourReading, object: bool) {
    let text = format!(
        "object colour: luminance {:.2}×, chroma {:.2}× the colour-matched ({} views)",
        c.luminance_ratio(),
        c.chroma_ratio(),
        c.views
    );
    match c.collapse() {
        None => {
            ui.weak(text);
        }
        Some(d) => {
            ui.colored_label(Color32::from_rgb(255, 130, 110), text);
            let focus = if object { "" } else { "set Focus to object, or " };
            ui.colored_label(
                Color32::from_rgb(255, 130, 110),
                format!(
                    "Colour collapse: {:.0}% of the colour is lost. The geometry steps' moving means bring dark \
                     Gaussians in front: {focus}lower the learning rate 'means / extent' to 1e-5, or raise \
                     λ_cont to 0.1 (it holds the colour-matched look, but the style's marks fade too).",
                    d.value * 100.0
                ),
            );
        }
    }
}

/// Seconds left as a person reads them: "45 s", "12 min 05 s".
fn time_left(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    if s < 90 { format!("{s} s") } else { format!("{} min {:02} s", s / 60, s % 60) }
}

#[cfg(test)]
mod tests {
    #[test]
    fn time_left_reads_in_seconds_then_minutes() {
        assert_eq!(super::time_left(44.6), "45 s");
        assert_eq!(super::time_left(-3.0), "0 s");
        assert_eq!(super::time_left(89.0), "89 s");
        assert_eq!(super::time_left(725.0), "12 min 05 s");
    }
}
