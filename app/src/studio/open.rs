//! What the studio opens: scenes, styles, camera sets and presets, from
//! dialogs, drops and the command line. Loading runs off the UI thread once
//! the window exists; a bad file is reported in the error panel and what was
//! open before stays.

use super::*;

impl StudioApp {
    pub(super) fn set_scene(&mut self, name: String, path: Option<PathBuf>, g: Gaussians) {
        // A run of the previous scene ends with it: its snapshots would come
        // in as this scene's result (the question of `leave` came first).
        if self.run.link.is_some() {
            self.recovery.discard_all();
            self.run.shut_down();
            self.run = session_link::RunMonitor::default();
            self.live = None;
            self.shown = None;
        }
        let g = Arc::new(g);
        self.view.fit(&g);
        self.cameras = view::orbit_ring(&g, self.view.up, 12, 800, 600);
        self.camera_source = None;
        let scene = SceneRef { version: self.next_version, gaussians: g.into() };
        self.scene = Some(LoadedScene { name, path, scene });
        self.next_version += 1;
        self.snapshot = None;
        self.newer_snapshot = None;
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

    pub(super) fn finish_open_scene(&mut self, path: &Path, result: anyhow::Result<inspect::SceneFile>) {
        match result {
            Ok(f) if f.gaussians.is_empty() => {
                let keep = self.keeping_scene();
                self.report(anyhow::anyhow!("{}: the scene holds no Gaussians; {keep}", path.display()))
            }
            Ok(f) => {
                let g = f.gaussians;
                let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                self.notice = format!("opened {} ({} Gaussians, SH degree {})", path.display(), g.len(), g.sh_degree);
                self.set_scene(name, Some(path.to_path_buf()), g);
                self.run.log.extend(f.warnings.iter().map(|w| format!("scene: {w}")));
                if let Some((set, dir)) = f.cameras {
                    self.set_cameras(set, &dir);
                }
            }
            Err(e) => {
                let keep = self.keeping_scene();
                self.report(anyhow::anyhow!("{}; {keep}", crate::error_text(&e)))
            }
        }
    }

    /// What a failed open leaves on screen, for the end of its message.
    pub(super) fn keeping_scene(&self) -> &'static str {
        if self.scene.is_some() { "keeping the previous scene" } else { "no scene is open" }
    }

    pub(super) fn open_demo_scene(&mut self) {
        let path = assets::source_assets_dir().join(assets::DEMO_SCENE);
        if path.exists() {
            self.open_scene(&path);
        } else {
            self.set_scene("demo scene (generated)".into(), None, assets::demo_scene());
        }
    }

    /// Adds a decoded style image (a generated one) and selects it, as
    /// [`StudioApp::finish_open_style`] does a file's.
    pub(super) fn add_style(&mut self, path: PathBuf, img: image::RgbImage) {
        let file = inspect::style_file(&path, img);
        self.finish_open_style(path, file);
        if let Some(s) = self.styles.first_mut() {
            s.from_file = false;
        }
    }

    /// Selects the `k`-th recent style: at once when its image is held, else
    /// once its file is read again (then at the head of the strip).
    pub(super) fn select_style(&mut self, k: usize) {
        let Some(s) = self.styles.get(k) else { return };
        if s.image.is_some() {
            self.style = Some(k);
            self.release_unselected_styles();
        } else {
            let path = s.path.clone();
            self.open_style(&path);
        }
    }

    /// Lets go of the images of the styles read from files and not selected.
    fn release_unselected_styles(&mut self) {
        for (k, s) in self.styles.iter_mut().enumerate() {
            if Some(k) != self.style && s.from_file {
                s.image = None;
            }
        }
    }

    /// Loads a style image (on a worker thread once the window runs).
    pub fn open_style(&mut self, path: &Path) {
        if self.load_in_background {
            self.notice = format!("loading {}…", path.display());
            self.jobs.load_style(path.to_path_buf());
        } else {
            let result = inspect::read_style_file(path);
            self.finish_open_style(path.to_path_buf(), result);
        }
    }

    /// Puts a read style at the head of the recent strip and selects it; on
    /// failure (a file this build cannot read, an image the runs cannot use)
    /// the error is shown and the previous style stays.
    pub(super) fn finish_open_style(&mut self, path: PathBuf, result: Result<inspect::StyleFile, String>) {
        let file = match result {
            Ok(file) => file,
            Err(e) => {
                let keep = if self.styles.is_empty() { "no style is open" } else { "keeping the previous style" };
                return self.report(anyhow::anyhow!("{e}; {keep}"));
            }
        };
        let inspect::StyleFile { image, thumb, file } = file;
        let texture =
            self.ctx.load_texture(format!("style {}", path.display()), thumb.clone(), egui::TextureOptions::LINEAR);
        let size = [image.width, image.height];
        self.styles.retain(|s| s.path != path);
        self.styles.insert(0, LoadedStyle { path, image: Some(image), from_file: true, file, thumb, texture, size });
        self.styles.truncate(8);
        self.style = Some(0);
        self.release_unselected_styles();
    }

    pub(super) fn open_generated_styles(&mut self) {
        for (name, img) in assets::demo_styles().into_iter().rev() {
            self.add_style(PathBuf::from(name), img);
        }
    }

    /// The training cameras and where they came from, for an export to
    /// carry; `None` with the orbit, which is made again from any scene.
    pub(super) fn camera_file(&self) -> Option<(Vec<Camera>, PathBuf)> {
        self.camera_source.clone().map(|from| (self.cameras.clone(), from))
    }

    /// Where the cameras came from, for the cameras panel.
    pub(super) fn camera_source_name(&self) -> String {
        self.camera_source.as_ref().map_or_else(|| "orbit".to_owned(), |p| p.display().to_string())
    }

    pub(super) fn set_cameras(&mut self, set: gast_core::camera::CameraSet, from: &Path) {
        self.cameras = set.cameras;
        self.camera_source = Some(from.to_path_buf());
        // The view starts at the first training camera: a forward-facing
        // capture (fern) seen from the orbit around it shows its blurred back.
        self.snap_to_first_camera();
        for w in set.warnings {
            self.run.log.push(format!("cameras: {w}"));
        }
    }

    /// Puts the view at the first training camera, looking at the scene's centre.
    fn snap_to_first_camera(&mut self) {
        if let Some(cam) = self.cameras.first().cloned() {
            let focus = self.current().and_then(|g| gast_core::camera::robust_bounds(&g.means)).map(|b| b.center);
            self.view.snap_to(&cam, focus);
        }
    }

    /// Frames the scene (F, Fit, Reset): from a three-quarter view of its
    /// bounds, or, for a forward-facing capture's own cameras (fern), from its
    /// first camera, as it opened: its bounds seen from aside show what no
    /// photo saw.
    pub(super) fn frame_scene(&mut self) {
        if self.camera_source.is_some() && gast_core::camera::forward_facing(&self.cameras).is_some() {
            self.snap_to_first_camera();
        } else if let Some(g) = self.current() {
            self.view.fit(&g);
        }
    }

    /// Loads optimisation cameras (COLMAP, LLFF `poses_bounds.npy`, `cameras.json`,
    /// `transforms.json`) for the snap list.
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
            "bin" | "txt" | "npy" => self.open_cameras(path),
            "json" => {
                // cameras.json is a list, transforms.json has frames, SOG's meta.json has means; the rest are presets.
                let text = std::fs::read_to_string(path).unwrap_or_default();
                let value: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
                if value.is_array() || value.get("frames").is_some() {
                    self.open_cameras(path);
                } else if value.get("means").is_some() {
                    self.open_scene_guarded(path);
                } else {
                    self.load_preset(path);
                }
            }
            _ if path.is_dir() && !path.join("meta.json").exists() => self.open_cameras(path),
            _ => self.open_scene_guarded(path),
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
}
