//! Leaving a run's result unexported: closing the window, or opening another
//! scene, while the stylized scene has steps no export holds would drop
//! minutes of optimisation without a word. Both ask first, in a modal:
//! export the stylized scene (then go on once it is written), go on without
//! it, or stay.

use std::path::PathBuf;

use egui::{RichText, Ui};

use super::StudioApp;
use super::viewport::SharedGaussians;

/// What the user asked for that would drop the result.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Leave {
    /// Close the window (quit the studio).
    Quit,
    /// Open this scene in place of the current one.
    OpenScene(PathBuf),
}

/// The guard's state.
#[derive(Default)]
pub(super) struct LeaveGuard {
    /// Asked and waiting for the user's answer (or for the export it chose).
    pub asking: Option<Leave>,
    /// The version of the stylized side last written by an export of the scene.
    pub exported: Option<u64>,
    /// An export of the scene under way: its path, the version it writes, and
    /// whether the pending [`Leave`] goes on once it is written.
    pub exporting: Option<(PathBuf, u64, bool)>,
    /// The user chose to close without exporting (or a script closes): let the close through.
    pub quit_confirmed: bool,
    /// Why the export the question started failed, shown in it.
    pub export_error: Option<String>,
}

impl StudioApp {
    /// The run's step the stylized side shows when no export holds it: what
    /// leaving would lose. `None` without a run's result, or once exported.
    pub(super) fn unexported_step(&self) -> Option<u32> {
        let after = self.after()?;
        let step = match &after.gaussians {
            SharedGaussians::Snapshot(s) => s.step,
            // A blend of a snapshot at a strength below 100%.
            SharedGaussians::Owned(_) => self.snapshot_step()?,
        };
        (step > 0 && self.leave.exported != Some(after.version)).then_some(step)
    }

    fn snapshot_step(&self) -> Option<u32> {
        match &self.snapshot.as_ref()?.gaussians {
            SharedGaussians::Snapshot(s) => Some(s.step),
            SharedGaussians::Owned(_) => None,
        }
    }

    /// Starts exporting the stylized side (or the scene) to `path`, noting
    /// which version it writes; `then_leave` goes on with the pending
    /// [`Leave`] once it is written.
    pub(super) fn export_current_scene(&mut self, path: PathBuf, then_leave: bool) {
        let Some(shown) = self.current_ref() else { return };
        let g = shown.gaussians.clone();
        self.leave.exporting = Some((path.clone(), shown.version, then_leave));
        self.jobs.export_scene(g, path, self.camera_file());
    }

    /// An export of a scene to `path` was written: marks its version as
    /// held, and goes on with the pending [`Leave`] it was for.
    pub(super) fn scene_exported(&mut self, path: &std::path::Path) {
        let Some((p, version, then_leave)) = self.leave.exporting.clone() else { return };
        if p != path {
            return;
        }
        self.leave.exporting = None;
        self.leave.exported = Some(version);
        if then_leave && let Some(leave) = self.leave.asking.take() {
            self.go(leave);
        }
    }

    /// The scene's export failed (`error` says why): the question, if
    /// pending, is asked again with the error in it.
    pub(super) fn scene_export_failed(&mut self, error: &str) {
        if self.leave.exporting.take().is_some_and(|e| e.2) {
            self.leave.export_error = Some(error.to_owned());
        }
    }

    /// Opening a scene, asked first when the result would be lost.
    pub(super) fn open_scene_guarded(&mut self, path: &std::path::Path) {
        if self.unexported_step().is_some() {
            self.leave.asking = Some(Leave::OpenScene(path.to_path_buf()));
        } else {
            self.open_scene(path);
        }
    }

    /// Checks the window's close request: cancelled and asked about while
    /// the result is unexported.
    pub(super) fn guard_close(&mut self, ui: &Ui) {
        if !ui.input(|i| i.viewport().close_requested()) || self.leave.quit_confirmed {
            return;
        }
        if self.unexported_step().is_some() {
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.leave.asking = Some(Leave::Quit);
        }
    }

    /// Closes the window without asking (the user chose so, or a script closes it).
    pub(super) fn close_window(&mut self, ctx: &egui::Context) {
        self.leave.quit_confirmed = true;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    fn go(&mut self, leave: Leave) {
        match leave {
            Leave::Quit => {
                let ctx = self.ctx.clone();
                self.close_window(&ctx);
            }
            Leave::OpenScene(path) => self.open_scene(&path),
        }
    }

    /// The question, while one is pending.
    pub(super) fn leave_modal(&mut self, ui: &Ui) {
        let Some(leave) = self.leave.asking.clone() else { return };
        let step = self.unexported_step();
        let exporting = self.leave.exporting.as_ref().is_some_and(|e| e.2);
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("gast-leave-modal")).show(ui.ctx(), |ui| {
            ui.set_max_width(460.0);
            let what = match &leave {
                Leave::Quit => "Closing the studio".to_owned(),
                Leave::OpenScene(p) => {
                    format!("Opening {}", p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default())
                }
            };
            ui.label(RichText::new("The stylized scene is not exported").strong());
            let run = if self.run.is_live() { ", and stops the run" } else { "" };
            ui.label(match step {
                Some(step) => format!("{what} drops the run's result after {step} steps{run}."),
                None => format!("{what} drops the run's result{run}."),
            });
            if let Some(e) = &self.leave.export_error {
                ui.colored_label(egui::Color32::from_rgb(230, 90, 80), e);
            }
            ui.add_space(8.0);
            if exporting {
                ui.horizontal(|ui| {
                    ui.spinner();
                    ui.label("exporting…");
                });
                return;
            }
            ui.horizontal(|ui| {
                if ui.button("Export .ply…").clicked() {
                    answer = Some(Answer::Export);
                }
                let go = match leave {
                    Leave::Quit => "Close without exporting",
                    Leave::OpenScene(_) => "Open without exporting",
                };
                if ui.button(go).clicked() {
                    answer = Some(Answer::Go);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(Answer::Stay);
                }
            });
        });
        match answer {
            Some(Answer::Export) => {
                if let Some(p) = super::panels::scene_save_dialog() {
                    self.leave.export_error = None;
                    self.export_current_scene(p, true);
                }
            }
            Some(Answer::Go) => {
                self.leave.asking = None;
                self.leave.export_error = None;
                self.go(leave);
            }
            Some(Answer::Stay) => {
                self.leave.asking = None;
                self.leave.export_error = None;
            }
            None => {}
        }
    }
}

/// The modal's buttons.
enum Answer {
    Export,
    Go,
    Stay,
}
