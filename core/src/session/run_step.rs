//! One optimisation step of a [`Session`]: render a view, the losses through
//! VGG, the rasterizer's backward and the phase's Adam update, on the CPU or
//! as one submission of the GPU engine.

use super::*;
use crate::style::Phase;
use rayon::prelude::*;

/// Every how many GPU steps the colour watch reads the step's render back
/// (besides each view's first visit).
const GPU_COLOUR_EVERY: u32 = 10;

impl Session {
    /// Runs the next scheduled step; `None` when the schedule is complete or
    /// the GPU engine failed ([`Session::failure`] then says why). The step
    /// runs on the session's engine (the GPU engine when it has one, else
    /// the CPU step below); the report is built here for both.
    pub fn step(&mut self) -> Option<StepReport> {
        if self.failure.is_some() {
            return None;
        }
        let schedule = self.config.schedule();
        let (cycle, phase) = schedule.at(self.step)?;
        let started = Instant::now();
        let view = self.sampler.next();
        // Seconds spent off the clock (the matching audit).
        let (losses, timings, off_clock_s) = if self.engine.is_some() {
            match self.gpu_step(view, phase) {
                Ok((losses, timings)) => (losses, timings, 0.0),
                Err(e) => {
                    self.failure = Some(format!("step {}: {e}", self.step));
                    return None;
                }
            }
        } else {
            self.cpu_step(view, phase)?
        };
        self.elapsed_s += started.elapsed().as_secs_f64() - off_clock_s;
        let report = StepReport {
            iter: self.step,
            total: schedule.total_steps(),
            cycle,
            phase,
            view: view as u32,
            losses,
            timings,
            elapsed_s: self.elapsed_s,
            colour: self.colour_watch.reading(),
        };
        self.step += 1;
        if let Some(live) = &self.live {
            live.publish(u64::from(self.step));
        }
        Some(report)
    }

    /// One step as one submission of the GPU engine, with the colour watch's
    /// read-back on each view's first visit and every few steps.
    fn gpu_step(&mut self, view: usize, phase: Phase) -> Result<(LossTerms, StepTimings), String> {
        let object = self.focus_on_object();
        let Some(engine) = &mut self.engine else { return Err("no GPU engine".into()) };
        engine.set_object_focus(object);
        let cam = &self.cameras[view];
        let losses = engine.step(self.step, view, cam, phase, &self.config, self.extent).map_err(|e| e.to_string())?;
        if self.step.is_multiple_of(GPU_COLOUR_EVERY) || !self.colour_watch.has_reference(view) {
            if let Some(r) = engine.reference_colour(view) {
                self.colour_watch.set_reference(view, r);
            }
            if let Ok(c) = engine.rendered_colour(cam) {
                self.colour_watch.observe(view, c);
            }
        }
        // The session measures the whole step; its device stages are not
        // timed apart, only the host's pairing and its waits on the device.
        let host = engine.host_times();
        Ok((
            losses,
            StepTimings {
                pairing_ms: host.pairing_ms,
                device_wait_ms: host.wait_ms,
                record_ms: host.record_ms,
                submit_ms: host.submit_ms,
                bind_groups: host.bind_groups,
                passes: host.passes,
                ..StepTimings::default()
            },
        ))
    }

    /// One step on the CPU: render, the losses through VGG, the rasterizer's
    /// backward and the phase's Adam update; also the seconds its matching
    /// audit took (off the clock). `None` when the view has no target.
    fn cpu_step(&mut self, view: usize, phase: Phase) -> Option<(LossTerms, StepTimings, f64)> {
        let opts = RenderOptions { background: self.config.background };
        let cam = self.cameras[view].clone();
        let (h, w) = (cam.height as usize, cam.width as usize);
        let mut timings = StepTimings::default();

        self.make_target(view);
        let object = self.focus_on_object();
        let cpu = self.cpu.as_mut()?;

        let t = Instant::now();
        let (img, state) = raster::forward(&cpu.g, &cam, &opts);
        timings.render_ms = ms(t);
        let rgb: Vec<f32> = img.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        self.colour_watch.observe(view, CoveredColour::of(&rgb, &img.alpha));
        let edge = render_edges(&rgb, h, w);
        let target = self.targets[view].as_ref()?;
        let geometry = phase.updates_geometry();
        // With the leak, a colour step also takes the depth map's gradient:
        // it reaches the geometry, whose next step applies it.
        let leaking = self.leak.is_on();
        let depth_grad = geometry || (leaking && phase == Phase::Color);
        // Matches: kept from this view's last visits, or searched (and, when
        // auditing, compared with the exact search off the clock).
        let mc = self.config.matching;
        let kept = self.view_matches[view].take().filter(|(_, uses)| *uses < mc.reuse);
        let uses = kept.as_ref().map_or(0, |k| k.1);
        let audit_now =
            self.audit_every > 0 && self.step.is_multiple_of(self.audit_every) && mc.method != MatchMethod::Exact;
        let (features, index) = (&self.style.targets.features, self.index.as_ref());
        let (mut audited, mut audit_s) = (None, 0.0);
        let mut matcher = |r: [&[f32]; 3], n: usize| match &kept {
            Some((m, _)) => m.clone(),
            None => {
                let m = find_matches(features, index, &mc, r, n);
                if audit_now {
                    let t = Instant::now();
                    audited = Some(agreement(&m, &match_features(features, r, n)));
                    audit_s = t.elapsed().as_secs_f64();
                }
                m
            }
        };
        let loss = step_loss_with(
            &*self.vgg,
            &self.style.targets,
            RenderedMaps { rgb: &rgb, inv_depth: &img.inv_depth, edge: &edge, height: h, width: w },
            Some(&target.content.map()),
            geometry.then_some(target.inv_depth.as_slice()),
            &self.config.weights_for(phase),
            depth_grad,
            LossFocus {
                mask: object.then_some(target.coverage.as_slice()),
                window: self.config.vgg_window,
                outside: (target.outside.as_ref()).filter(|_| object).map(|(mask, rgb)| Outside { mask, rgb }),
                palette: object.then_some(target.palette),
                relief_px: self.config.depth_relief_px as usize,
                assign_block: self.config.assign_block as usize,
            },
            &mut matcher,
        );
        if let Some((b, w)) = audited {
            self.audit = (self.audit.0 + b, self.audit.1 + w, self.audit.2 + 1);
        }
        self.view_matches[view] = Some((loss.matches.clone(), uses + 1));
        timings.features_ms = loss.timings.features_ms;
        timings.matching_ms = loss.timings.matching_ms - (audit_s * 1e3) as f32;
        timings.vgg_backward_ms = loss.timings.backward_ms;
        timings.pairing_ms = loss.timings.pairing_ms;

        // The clamp to [0, 1] passes no gradient outside the range.
        let mut v_rgb = loss.v_rgb;
        for (g, &raw) in v_rgb.iter_mut().zip(&img.rgb) {
            if !(0.0..=1.0).contains(&raw) {
                *g = 0.0;
            }
        }
        let t = Instant::now();
        // The colour steps the DC coefficients only; a geometry step needs them only for the leak.
        let sh = if phase.updates_color() || (leaking && phase == Phase::Geometry) {
            raster::ShGrads::Dc
        } else {
            raster::ShGrads::Skip
        };
        let mut grads = raster::backward_sh(&cpu.g, &cam, &opts, &state, &v_rgb, &loss.v_inv_depth, sh);
        timings.raster_backward_ms = ms(t);

        let t = Instant::now();
        let mut terms = loss.terms;
        let lr = self.config.lr;
        let wts = self.config.weights;
        if phase.updates_color() {
            let k = cpu.g.sh_coeffs() * 3;
            let mut dc = vec![0.0f32; 3 * cpu.g.len()];
            dc.par_chunks_mut(3).zip(cpu.g.sh.par_chunks(k)).with_min_len(PER_TASK).for_each(|(d, sh)| {
                d.copy_from_slice(&sh[..3]);
            });
            // The DC's gradient alone (`ShGrads::Dc`), three values a Gaussian.
            let v_dc = &mut grads.v_sh;
            take_leak(v_dc, &mut self.leak.color);
            cpu.opt.color.step(&mut dc, v_dc, lr.color);
            if self.config.color_floor {
                floor_dc(&mut dc);
            }
            cpu.g.sh.par_chunks_mut(k).zip(dc.par_chunks(3)).with_min_len(PER_TASK).for_each(|(sh, d)| {
                sh[..3].copy_from_slice(d);
            });
        }
        if geometry {
            let reg = |x: &[f32], r: &[f32], components: usize| match self.config.param_regulariser {
                ParamRegulariser::Norm => l2_distance(x, r),
                ParamRegulariser::MeanSquare => mean_square_distance(x, r, components),
            };
            let (l_o, mut v_o) = reg(&cpu.g.opacity_logits, &cpu.g_ref.opacity_logits, 1);
            let (l_s, mut v_s) = reg(flat(&cpu.g.log_scales), flat(&cpu.g_ref.log_scales), 3);
            let (l_q, mut v_q) = reg(flat(&cpu.g.quats), flat(&cpu.g_ref.quats), 4);
            terms.reg_opacity = l_o;
            terms.reg_scale = l_s;
            terms.reg_rotation = l_q;
            terms.total += wts.opacity * l_o + wts.scale * l_s + wts.rotation * l_q;
            add_scaled(&mut v_o, &grads.v_opacity_logits, wts.opacity);
            add_scaled(&mut v_s, flat(&grads.v_log_scales), wts.scale);
            add_scaled(&mut v_q, flat(&grads.v_quats), wts.rotation);
            take_leak(flat_mut(&mut grads.v_means), &mut self.leak.means);
            take_leak(&mut v_s, &mut self.leak.scales);
            take_leak(&mut v_q, &mut self.leak.quats);
            take_leak(&mut v_o, &mut self.leak.opacity);
            cpu.opt.means.step(flat_mut(&mut cpu.g.means), flat(&grads.v_means), lr.means_per_extent * self.extent);
            cpu.opt.scales.step(flat_mut(&mut cpu.g.log_scales), &v_s, lr.scales);
            cpu.opt.quats.step(flat_mut(&mut cpu.g.quats), &v_q, lr.quats);
            cpu.opt.opacity.step(&mut cpu.g.opacity_logits, &v_o, lr.opacity);
        }
        if leaking {
            // What this step's backward left on the other phase's parameters.
            match phase {
                Phase::Color => {
                    add_into(&mut self.leak.means, flat(&grads.v_means));
                    add_into(&mut self.leak.scales, flat(&grads.v_log_scales));
                    add_into(&mut self.leak.quats, flat(&grads.v_quats));
                    add_into(&mut self.leak.opacity, &grads.v_opacity_logits);
                }
                Phase::Geometry => add_into(&mut self.leak.color, &grads.v_sh),
                Phase::Joint => {}
            }
        }
        timings.update_ms = ms(t);
        Some((terms, timings, audit_s))
    }
}

/// Projects DC colour coefficients out of the clamp's dead zone: every
/// channel's base colour `0.5 + C0·f_dc` is raised to at least 0.
fn floor_dc(dc: &mut [f32]) {
    dc.iter_mut().for_each(|v| *v = v.max(crate::style::DC_FLOOR));
}

/// Adds the gradients leaked into `acc` (empty when the leak is off) to
/// `grad` and clears them: the phase's first step after the other phase.
fn take_leak(grad: &mut [f32], acc: &mut [f32]) {
    grad.par_iter_mut().zip(acc.par_iter_mut()).with_min_len(PER_TASK).for_each(|(g, a)| {
        *g += *a;
        *a = 0.0;
    });
}

fn add_into(acc: &mut [f32], grad: &[f32]) {
    acc.par_iter_mut().zip(grad).with_min_len(PER_TASK).for_each(|(a, &g)| *a += g);
}

/// `(x − x^c)/‖x − x^c‖` scaled by λ, plus the loss gradient: `reg ← λ·reg + loss`.
fn add_scaled(reg: &mut [f32], loss_grad: &[f32], lambda: f32) {
    reg.par_iter_mut().zip(loss_grad).with_min_len(PER_TASK).for_each(|(r, &g)| *r = lambda * *r + g);
}

/// Values (or Gaussians) a thread takes at a time in the update's element-wise passes.
const PER_TASK: usize = 1 << 14;

fn flat<const N: usize>(v: &[[f32; N]]) -> &[f32] {
    v.as_flattened()
}

fn flat_mut<const N: usize>(v: &mut [[f32; N]]) -> &mut [f32] {
    v.as_flattened_mut()
}

fn ms(t: Instant) -> f32 {
    t.elapsed().as_secs_f32() * 1e3
}
