//! The studio's test switches (see the module docs of `studio`): a scripted
//! run that presses Start, pauses after N steps and exports, and the frame
//! count, screenshot and close that the GUI tests drive it with.

use super::*;

impl StudioApp {
    /// Drives the `GAST_STUDIO_RUN_STEPS` switch; true once it is done (or absent).
    pub(super) fn scripted_run(&mut self, ctx: &egui::Context) -> bool {
        let Some(script) = &mut self.script else { return true };
        if script.done {
            return true;
        }
        // The run's events wake the window at every step (on a software
        // renderer at most once a second); this only polls the loading and
        // the pause, as a user's window would not redraw on its own (an
        // immediate repaint here drew frames without end, and a poll every
        // 250 ms drew four frames a second, which on a software renderer took
        // the CPU from the run it scripts).
        let poll = if self.software_viewport { 1000 } else { 250 };
        ctx.request_repaint_after(std::time::Duration::from_millis(poll));
        if !script.started {
            let ready = self.scene.is_some() && self.style.is_some() && self.starter.is_some();
            if ready {
                script.started = true;
                // The worker pauses itself after the scripted steps: exactly
                // there, however late this window is woken (on a software
                // renderer once a second, when a short run had ended).
                let steps = u32::try_from(script.steps).unwrap_or(u32::MAX);
                if !script.go_on {
                    self.start_run();
                } else if self.recovery.offer.is_some() {
                    self.go_on_from_kept_run();
                } else {
                    self.report(anyhow::anyhow!(
                        "GAST_STUDIO_GO_ON: no kept run of this scene and style to go on from"
                    ));
                }
                // The worker puts the paused state's snapshot in the slot
                // before it reports Paused, so the export below is exactly
                // what the run holds.
                self.run.send(Command::PauseAfter(steps));
            }
            // A scene or style that failed to load, or a run refused at its
            // start, ends the script (it waited for ever) with what the window shows.
            if (ready && self.run.link.is_none()) || (!ready && self.jobs.running == 0 && self.frames > 2) {
                if let Some(script) = &mut self.script {
                    (script.done, script.failed) = (true, true);
                }
                let why = self.errors.last().map_or("no scene, style or run to start", String::as_str);
                eprintln!("studio: the scripted run could not start: {why}");
                if let Some(n) = self.exit_after {
                    self.exit_after = Some(self.frames + n);
                }
                return true;
            }
            return false;
        }
        let finished = matches!(self.run.status, RunStatus::Finished { .. } | RunStatus::Failed(_));
        let paused = self.run.status == RunStatus::Paused;
        if paused || finished {
            script.done = true;
            let export = script.export.clone();
            let pace = self.run.steps.last().map_or(String::new(), |s| {
                format!(", {:.1} s optimising, {:.3} s a step", s.elapsed_s, s.elapsed_s / f64::from(s.iter + 1))
            });
            eprintln!("studio: scripted run paused after {} steps ({:?}{pace})", self.run.steps.len(), self.run.status);
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

    pub(super) fn test_switches(&mut self, ctx: &egui::Context) {
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
            self.close_window(ctx);
        }
        if self.frames >= n + 600 {
            eprintln!("studio: the screenshot never arrived; closing");
            self.close_window(ctx);
        }
    }
}
