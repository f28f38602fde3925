//! A studio run's state kept against a crash: while a run steps, its scene,
//! its optimiser's moments and a record of its inputs and settings are
//! written to the user's cache (`$XDG_CACHE_HOME/gast/studio-runs/`) every
//! [`KEEP_EVERY`] of stepping, at a pause and at its end. A studio killed or
//! crashed (or a machine that went down) leaves them there, and the next
//! studio that opens the same scene with the same style offers to go on from
//! the step they hold, as `gast stylize --resume` does, or to discard them. A
//! studio that leaves its runs itself (its window closed, another scene
//! opened: the close asked about an unexported result first) removes them.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gast_core::Gaussians;
use gast_core::session::{Keeper, ResumeFrom};
use gast_core::style::StyleConfig;
use serde::{Deserialize, Serialize};

use super::StudioApp;
use crate::checkpoint;

/// Stepping time between two writes of a run's state: a crash loses at
/// most a minute of a run (a fern-sized scene's write took 17–34 ms), or
/// more where a write takes longer than `gast_core::session::KEEP_SHARE`
/// of it (two million Gaussians of degree 3: 4.7 s, every 4 min).
pub const KEEP_EVERY: Duration = Duration::from_secs(60);

/// What is kept beside a run's scene: enough to offer it for the scene and
/// style it was made with, and to go on with its settings.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Record {
    /// Steps done when the state was written, of the schedule's `total`.
    pub step: u32,
    pub total: u32,
    /// The scene's name, file (where it came from one) and [`scene_key`], and its Gaussians.
    pub scene_name: String,
    #[serde(default)]
    pub scene_path: Option<PathBuf>,
    pub scene_key: String,
    pub gaussians: usize,
    /// The style image (its absolute path where it resolves), its size and
    /// its bytes ([`checkpoint::file_fingerprint`]; `None` where unread).
    pub style: PathBuf,
    pub style_size: [usize; 2],
    #[serde(default)]
    pub style_file: Option<String>,
    /// The user's depth image for the style, where one was given.
    pub style_depth_image: Option<PathBuf>,
    /// The optimisation views ([`checkpoint::cameras_fingerprint`]) and the
    /// file they came from (`None`: the orbit around the scene).
    pub cameras: String,
    pub camera_source: Option<PathBuf>,
    /// The run's settings as they stood (sliders moved during the run included).
    pub config: StyleConfig,
    /// When it was written (seconds since 1970).
    pub written_unix_s: u64,
}

/// The folder of kept runs: `GAST_STUDIO_RUNS`, else
/// `$XDG_CACHE_HOME/gast/studio-runs`, else `$HOME/.cache/gast/studio-runs`;
/// `None` when none of them is set (no run is kept then).
pub fn folder() -> Option<PathBuf> {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    var("GAST_STUDIO_RUNS").or_else(|| {
        let cache = var("XDG_CACHE_HOME").or_else(|| var("HOME").map(|h| h.join(".cache")))?;
        Some(cache.join("gast").join("studio-runs"))
    })
}

/// What tells a scene as loaded from another: its count, SH degree, and a
/// hash of its means and opacities (a few milliseconds at 500,000 Gaussians).
pub fn scene_key(g: &Gaussians) -> String {
    let words = g.means.iter().flatten().chain(&g.opacity_logits).map(|v| u64::from(v.to_bits()));
    format!("{} Gaussians, degree {}, {:016x}", g.len(), g.sh_degree, checkpoint::fnv1a(words))
}

/// A style's path as recorded: absolute where it resolves.
fn absolute(p: &Path) -> PathBuf {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf())
}

/// Where the state of a run of the scene `scene_key` with the style at
/// `style` is kept in `folder`: one slot per scene and style.
pub fn slot_path(folder: &Path, scene_key: &str, style: &Path) -> PathBuf {
    let text = format!("{scene_key}\n{}", absolute(style).display());
    folder.join(format!("{:016x}.checkpoint.ply", checkpoint::fnv1a(text.bytes().map(u64::from))))
}

/// A run's slot: where its state is written, and what its record says of
/// its inputs. Turned off when the studio discards it, so that a worker that
/// outlives the studio's wait writes no more.
#[derive(Clone, Debug)]
pub struct Slot {
    pub path: PathBuf,
    pub record: Record,
    off: Arc<AtomicBool>,
}

impl Slot {
    /// The slot in `folder` of a run with these inputs (its step, total and
    /// settings are filled in at each write).
    pub fn new(folder: &Path, record: Record) -> Self {
        let record = Record { style: absolute(&record.style), ..record };
        Self { path: slot_path(folder, &record.scene_key, &record.style), record, off: Arc::default() }
    }

    /// The worker's keeper: writes the session's scene, optimiser state and
    /// record every [`KEEP_EVERY`] of stepping (or longer, for a scene whose
    /// write is slow), at a pause and at the end.
    pub fn keeper(&self) -> Keeper {
        let slot = self.clone();
        Keeper::new(KEEP_EVERY, Box::new(move |session, result| slot.write(session, result)))
    }

    fn write(&self, session: &gast_core::session::Session, result: &gast_core::Gaussians) -> Result<(), String> {
        if self.off.load(Ordering::SeqCst) {
            return Ok(());
        }
        let written_unix_s =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let record = Record {
            step: session.steps_done(),
            total: session.total_steps(),
            config: session.config().clone(),
            written_unix_s,
            ..self.record.clone()
        };
        let without = checkpoint::write_session(&self.path, session, result, &record).map_err(|e| format!("{e:#}"))?;
        // Discarded while it wrote (a close that gave up waiting for the run): gone all the same.
        if self.off.load(Ordering::SeqCst) {
            checkpoint::remove(&self.path);
            return Ok(());
        }
        without.map_or(Ok(()), |e| Err(format!("{}: kept without the optimiser's state ({e})", self.path.display())))
    }

    /// Removes what the slot holds and writes no more to it.
    pub fn discard(&self) {
        self.off.store(true, Ordering::SeqCst);
        checkpoint::remove(&self.path);
    }
}

/// A kept run the studio can go on from.
#[derive(Clone, Debug, PartialEq)]
pub struct Offer {
    pub path: PathBuf,
    pub record: Record,
    /// Why its files cannot be opened to go on from it (read with the list
    /// of kept runs): a file gone, or another image written over its style.
    pub unusable: Option<String>,
}

impl Offer {
    /// The kept run of the scene `scene_key` with the style at `style`, if
    /// the cache holds one whose record reads and matches; `Err` says why a
    /// slot that is there cannot be offered (unreadable, or of another
    /// style's size or bytes: an image written over the style's file, whose
    /// bytes as read are `style_file`).
    pub fn find(
        folder: &Path,
        scene_key: &str,
        style: &Path,
        style_size: [usize; 2],
        style_file: Option<&str>,
    ) -> Result<Option<Self>, String> {
        let path = slot_path(folder, scene_key, style);
        if !checkpoint::record_path(&path).is_file() {
            return Ok(None);
        }
        let record: Record = checkpoint::read_record(&path, &path, "studio run").map_err(|e| format!("{e:#}"))?;
        if record.scene_key != scene_key || record.style != absolute(style) {
            return Ok(None);
        }
        if record.style_size != style_size {
            return Err(format!(
                "{}: a run of this scene and style was kept, with a style of {}×{} px; the style is {}×{} px now \
                 (changed since)",
                path.display(),
                record.style_size[0],
                record.style_size[1],
                style_size[0],
                style_size[1]
            ));
        }
        if let (Some(was), Some(now)) = (record.style_file.as_deref(), style_file)
            && was != now
        {
            return Err(format!(
                "{}: a run of this scene and style was kept, with a style file of {was}; the file is {now} now \
                 (another image written over it since)",
                path.display()
            ));
        }
        Ok(Some(Self { path, record, unusable: None }))
    }

    /// The kept state to go on from (read on the worker thread) and what to
    /// say of its optimiser's state.
    pub fn load(&self) -> Result<(ResumeFrom, String), String> {
        let scene = gast_core::scene::load(&self.path)
            .map_err(|e| format!("could not read the kept run {}: {e}", self.path.display()))?;
        let (moments, said) = checkpoint::read_moments(&self.path, self.record.step);
        Ok((ResumeFrom { scene, step: self.record.step, moments }, said))
    }

    /// Every kept run in `folder` whose record reads, newest first, each
    /// with why its files cannot be opened to go on from it, if they cannot.
    pub fn list(folder: &Path) -> Vec<Self> {
        let Ok(entries) = std::fs::read_dir(folder) else { return Vec::new() };
        let mut found: Vec<Self> = entries
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.to_string_lossy().ends_with(".checkpoint.json"))
            .filter_map(|record| {
                let path = record.with_extension("ply");
                let record: Record = checkpoint::read_record(&path, &path, "studio run").ok()?;
                let unusable = why_unusable(&record);
                Some(Self { path, record, unusable })
            })
            .collect();
        found.sort_by(|a, b| b.record.written_unix_s.cmp(&a.record.written_unix_s).then(a.path.cmp(&b.path)));
        found
    }

    /// Removes the kept run.
    pub fn discard(&self) {
        checkpoint::remove(&self.path);
    }

    /// `fern.ply with block2.jpg`.
    pub fn inputs(&self) -> String {
        let style = self
            .record
            .style
            .file_name()
            .map_or_else(|| self.record.style.display().to_string(), |n| n.to_string_lossy().into_owned());
        format!("{} with {style}", self.record.scene_name)
    }

    /// `step 744 of 1510, kept 3 min ago`.
    pub fn summary(&self, now_unix_s: u64) -> String {
        let ago = now_unix_s.saturating_sub(self.record.written_unix_s);
        let ago = match ago {
            0..60 => "less than a minute ago".to_owned(),
            60..7200 => format!("{} min ago", ago / 60),
            7200..172_800 => format!("{} h ago", ago / 3600),
            _ => format!("{} days ago", ago / 86_400),
        };
        format!("step {} of {}, kept {ago}", self.record.step, self.record.total)
    }
}

/// Why a kept run's files cannot be opened to go on from it: its scene or
/// style file gone, or its style's bytes not those it was made with (only
/// Discard helps then; opening them would refuse the run, as
/// [`Offer::find`] does). The style is read once, when the list is.
fn why_unusable(record: &Record) -> Option<String> {
    if !record.scene_path.as_ref().is_some_and(|p| p.is_file()) || !record.style.is_file() {
        return Some("its scene or style file is no longer where it was".into());
    }
    let was = record.style_file.as_deref()?;
    let now = checkpoint::file_fingerprint(&record.style)?;
    (was != now).then(|| format!("another image was written over {} since it was kept", record.style.display()))
}

/// The studio's side: where runs are kept, what it offers, and the slots of its own runs.
#[derive(Default)]
pub struct Recovery {
    /// The folder of kept runs ([`folder`], read when the studio opens; `None`: none are kept).
    pub folder: Option<PathBuf>,
    /// The scene version and style last looked for.
    looked: Option<(u64, PathBuf)>,
    /// The open scene's version and [`scene_key`].
    scene_key: Option<(u64, String)>,
    /// A kept run of the open scene and selected style, offered to go on from.
    pub offer: Option<Offer>,
    /// The kept runs of other scenes or styles, newest first (`None`: to be read).
    others: Option<Vec<Offer>>,
    /// The slots of the runs this studio started, removed when it leaves them.
    slots: Vec<Slot>,
}

impl Recovery {
    /// Runs kept in `folder` ([`folder`] where the studio opens).
    pub fn in_folder(folder: Option<PathBuf>) -> Self {
        Self { folder, ..Self::default() }
    }

    /// Removes the state of every run this studio started: it leaves them
    /// (closing, or opening another scene), after asking about an unexported result.
    pub fn discard_all(&mut self) {
        for slot in self.slots.drain(..) {
            slot.discard();
        }
    }
}

fn now_unix_s() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs())
}

impl StudioApp {
    /// The open scene's key (hashed once per scene).
    fn scene_key(&mut self) -> Option<String> {
        let scene = self.scene.as_ref()?;
        let version = scene.scene.version;
        if self.recovery.scene_key.as_ref().is_none_or(|(v, _)| *v != version) {
            self.recovery.scene_key = Some((version, scene_key(&scene.scene.gaussians)));
        }
        self.recovery.scene_key.as_ref().map(|(_, k)| k.clone())
    }

    /// Looks in the cache for a kept run of the open scene and selected
    /// style when either changed and no run is live; one of this studio's
    /// own runs is not offered.
    pub(super) fn look_for_kept_run(&mut self) {
        let Some(folder) = self.recovery.folder.clone() else { return };
        if self.recovery.others.is_none() {
            self.recovery.others = Some(Offer::list(&folder));
        }
        let (Some(version), Some((style, size, file))) = (
            self.scene.as_ref().map(|s| s.scene.version),
            self.style.and_then(|k| self.styles.get(k)).map(|s| (s.path.clone(), s.size, s.file.clone())),
        ) else {
            self.recovery.offer = None;
            return;
        };
        let looking = Some((version, style.clone()));
        if self.recovery.looked == looking || self.run.is_live() {
            return;
        }
        self.recovery.looked = looking;
        let Some(key) = self.scene_key() else { return };
        self.recovery.offer = match Offer::find(&folder, &key, &style, size, file.as_deref()) {
            Ok(offer) => offer.filter(|o| self.recovery.slots.iter().all(|s| s.path != o.path)),
            Err(e) => {
                self.report(anyhow::anyhow!("{e}"));
                None
            }
        };
    }

    /// The slot of a run about to start on the open scene and selected
    /// style, noted as this studio's (`None` without a cache folder).
    pub(super) fn new_slot(
        &mut self,
        style: &Path,
        style_size: [usize; 2],
        style_depth_image: Option<PathBuf>,
    ) -> Option<Slot> {
        let folder = self.recovery.folder.clone()?;
        let scene_key = self.scene_key()?;
        let scene = self.scene.as_ref()?;
        let record = Record {
            step: 0,
            total: 0,
            scene_name: scene.name.clone(),
            scene_path: scene.path.as_deref().map(absolute),
            scene_key,
            gaussians: scene.scene.gaussians.len(),
            style: style.to_path_buf(),
            style_size,
            // The bytes as the studio read them, the image the run takes.
            style_file: self.styles.iter().find(|s| s.path == style).and_then(|s| s.file.clone()),
            style_depth_image,
            cameras: checkpoint::cameras_fingerprint(&self.cameras),
            camera_source: self.camera_source.as_deref().map(absolute),
            config: self.config.clone(),
            written_unix_s: 0,
        };
        let slot = Slot::new(&folder, record);
        self.recovery.offer = None;
        if self.recovery.slots.iter().all(|s| s.path != slot.path) {
            self.recovery.slots.push(slot.clone());
        }
        Some(slot)
    }

    /// Goes on from the offered run: its settings, over the same views.
    pub(super) fn go_on_from_kept_run(&mut self) {
        let Some(offer) = self.recovery.offer.clone() else { return };
        let now = checkpoint::cameras_fingerprint(&self.cameras);
        if offer.record.cameras != now {
            let from = offer
                .record
                .camera_source
                .as_ref()
                .map_or_else(|| "the orbit around the scene".to_owned(), |p| format!("the cameras of {}", p.display()));
            self.report(anyhow::anyhow!(
                "{}: the kept run used other views ({}, {from}) than those open now ({now}); open the cameras it \
                 used to go on from it",
                offer.path.display(),
                offer.record.cameras
            ));
            return;
        }
        self.config = offer.record.config.clone();
        self.start_run_from(Some(offer));
    }

    /// The offer in the Run panel, while there is one and no run is live;
    /// else the runs kept of other scenes or styles.
    pub(super) fn kept_run_offer(&mut self, ui: &mut egui::Ui) {
        if self.run.is_live() {
            return;
        }
        let Some(offer) = self.recovery.offer.clone() else {
            self.kept_elsewhere(ui);
            return;
        };
        ui.group(|ui| {
            ui.label(egui::RichText::new("A run left unfinished").strong());
            ui.label(format!(
                "A studio ended without closing (a crash, a kill, the machine gone down) during a run of this scene \
                 with this style: {}.",
                offer.summary(now_unix_s())
            ));
            ui.horizontal(|ui| {
                if ui
                    .button("Go on from it")
                    .on_hover_text("go on from the kept step with the run's settings as they stood, as `gast stylize --resume` does")
                    .clicked()
                {
                    self.go_on_from_kept_run();
                }
                if ui.button("Discard").on_hover_text("remove the kept run").clicked() {
                    offer.discard();
                    self.recovery.offer = None;
                    self.recovery.others = None;
                }
            });
            ui.weak("Start begins afresh and removes it.");
        });
    }

    /// The runs kept of other scenes or styles than those open (three at
    /// most, newest first): the files they used can be opened, which offers
    /// the run, or the run discarded. What a studio restarted on its own
    /// (no scene or style given) shows after a crash.
    fn kept_elsewhere(&mut self, ui: &mut egui::Ui) {
        let own: Vec<&Path> = self.recovery.slots.iter().map(|s| s.path.as_path()).collect();
        let list: Vec<Offer> = self
            .recovery
            .others
            .iter()
            .flatten()
            .filter(|o| !own.contains(&o.path.as_path()))
            .take(3)
            .cloned()
            .collect();
        if list.is_empty() {
            return;
        }
        let (mut open, mut discard) = (None, None);
        ui.group(|ui| {
            ui.label(egui::RichText::new("Runs left unfinished").strong());
            let now = now_unix_s();
            for offer in &list {
                ui.label(format!("{}: {}", offer.inputs(), offer.summary(now)));
                if let Some(why) = &offer.unusable {
                    ui.weak(format!("Cannot go on: {why}."));
                }
                ui.horizontal(|ui| {
                    let button = ui
                        .add_enabled(offer.unusable.is_none(), egui::Button::new("Open"))
                        .on_hover_text("open its scene and style; the run is then offered to go on from")
                        .on_disabled_hover_text(offer.unusable.clone().unwrap_or_default());
                    if button.clicked() {
                        open = offer.record.scene_path.clone().zip(Some(offer.record.style.clone()));
                    }
                    if ui.button("Discard").on_hover_text("remove the kept run").clicked() {
                        discard = Some(offer.clone());
                    }
                });
            }
        });
        if let Some((scene, style)) = open {
            self.open_style(&style);
            self.open_scene_guarded(&scene);
        }
        if let Some(offer) = discard {
            offer.discard();
            self.recovery.others = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(n: usize, shift: f32) -> Gaussians {
        Gaussians {
            means: (0..n).map(|i| [i as f32 + shift, 0.0, 0.0]).collect(),
            log_scales: vec![[-2.0; 3]; n],
            quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacity_logits: vec![0.0; n],
            sh_degree: 0,
            sh: vec![0.5; 3 * n],
        }
    }

    fn record(key: &str, style: &Path) -> Record {
        Record {
            step: 0,
            total: 0,
            scene_name: "s.ply".into(),
            scene_path: None,
            scene_key: key.into(),
            gaussians: 3,
            style: style.to_path_buf(),
            style_size: [64, 48],
            style_file: checkpoint::file_fingerprint(style),
            style_depth_image: None,
            cameras: "1 views, 0".into(),
            camera_source: None,
            config: StyleConfig::default(),
            written_unix_s: 100,
        }
    }

    #[test]
    fn a_scene_key_tells_scenes_apart() {
        let (a, b) = (scene(3, 0.0), scene(3, 1e-6));
        assert_eq!(scene_key(&a), scene_key(&a.clone()));
        assert_ne!(scene_key(&a), scene_key(&b));
        assert_ne!(scene_key(&a), scene_key(&scene(4, 0.0)));
        assert!(scene_key(&a).starts_with("3 Gaussians, degree 0, "));
    }

    /// A slot written is offered for its scene and style only, says why it
    /// cannot be offered when the style's size or bytes changed, and is gone once discarded.
    #[test]
    fn a_kept_run_is_offered_for_its_scene_and_style() {
        let dir = std::env::temp_dir().join(format!("gast-recovery-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a folder");
        let style = dir.join("style.png");
        std::fs::write(&style, b"x").expect("a style file");
        // The style's bytes as the studio reads them with the image.
        let now = |p: &Path| checkpoint::file_fingerprint(p);
        let key = scene_key(&scene(3, 0.0));
        let slot = Slot::new(&dir, record(&key, &style));
        let kept = Record { step: 7, total: 20, ..slot.record.clone() };
        checkpoint::write_with_record(&slot.path, &scene(3, 0.5), None, &kept).expect("written");
        let offer =
            Offer::find(&dir, &key, &style, [64, 48], now(&style).as_deref()).expect("readable").expect("offered");
        assert_eq!(offer.record, kept);
        assert_eq!(offer.summary(100 + 180), "step 7 of 20, kept 3 min ago");
        let (from, said) = offer.load().expect("loads");
        assert_eq!((from.step, from.scene.means[0][0], from.moments.is_none()), (7, 0.5, true));
        assert!(said.contains("start afresh"), "{said}");
        let other = scene_key(&scene(3, 1.0));
        assert_eq!(Offer::find(&dir, &other, &style, [64, 48], now(&style).as_deref()).expect("readable"), None);
        assert_eq!(Offer::find(&dir, &key, &dir.join("other.png"), [64, 48], None).expect("readable"), None);
        let e = Offer::find(&dir, &key, &style, [32, 48], now(&style).as_deref()).expect_err("another size");
        assert!(e.contains("with a style of 64×48 px; the style is 32×48 px now"), "{e}");
        // Another image of the same size written over the style's file.
        std::fs::write(&style, b"yz").expect("another style file");
        let e = Offer::find(&dir, &key, &style, [64, 48], now(&style).as_deref()).expect_err("another image");
        assert!(e.contains("with a style file of 1 bytes, ") && e.contains("the file is 2 bytes, "), "{e}");
        std::fs::write(&style, b"x").expect("the style file again");
        std::fs::write(checkpoint::record_path(&slot.path), b"{").expect("damaged");
        let e = Offer::find(&dir, &key, &style, [64, 48], now(&style).as_deref()).expect_err("unreadable");
        assert!(e.contains("expected a studio run checkpoint's record"), "{e}");
        slot.discard();
        assert!(!slot.path.exists() && !checkpoint::record_path(&slot.path).exists());
        assert_eq!(Offer::find(&dir, &key, &style, [64, 48], now(&style).as_deref()).expect("readable"), None);
        std::fs::remove_dir_all(&dir).ok();
    }
}
