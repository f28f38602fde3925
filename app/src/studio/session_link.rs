//! The studio's side of a stylization run: the three channels a session worker
//! hands back (commands in, small events out, snapshots in a latest-value slot)
//! and what the studio learns from the events. The studio never drives the
//! optimisation; it only sends [`Command`]s and reads.
//!
//! Wiring a worker: call [`super::run_with`] (or
//! [`super::StudioApp::set_session_starter`]) with a [`SessionStarter`] that
//! spawns the session thread for a [`StartRequest`] and returns its
//! [`SessionLink`]; the worker calls `request.waker` after every event or
//! snapshot so the window repaints.

use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};
use gast_core::Gaussians;
use gast_core::session::{Command, Event, RunStart, Slot, Snapshot, StepReport};
use gast_core::style::StyleConfig;

/// The channels of one running session.
pub struct SessionLink {
    /// Commands to the worker (applied between steps).
    pub commands: Sender<Command>,
    /// Events from the worker.
    pub events: Receiver<Event>,
    /// The newest Gaussians.
    pub snapshots: Arc<Slot<Snapshot>>,
    /// The GPU engine's buffers, when the run steps on the GPU (the viewport
    /// draws from them when it shares the device).
    pub live: Arc<Slot<gast_core::gpu::LiveGaussians>>,
    /// The run's start (colour-matched scene, cameras, style maps), once prepared.
    pub start: Arc<Slot<RunStart>>,
    /// The worker thread, told to stop when the link is dropped, and stopped
    /// and waited for by [`Self::stop_and_join`] (`None` in tests that play
    /// the worker's part themselves).
    pub worker: Option<gast_core::session::SessionHandle>,
}

/// How long a close waits for the run's thread to end.
const JOIN_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

impl SessionLink {
    /// The link to a running session worker: its channels and its thread.
    pub fn of(handle: gast_core::session::SessionHandle) -> Self {
        Self {
            commands: handle.commands.clone(),
            events: handle.events.clone(),
            snapshots: handle.snapshots.clone(),
            live: handle.live.clone(),
            start: handle.start.clone(),
            worker: Some(handle),
        }
    }

    /// Stops the worker and waits for its thread to end (a step, mostly), so
    /// that no thread is still inside the graphics driver when the studio's
    /// device is dropped and the process exits: on an H200 the headless
    /// studio, closing with its paused run's thread alive, ended in a
    /// segmentation fault after its screenshot was saved. A worker still
    /// loading (a weights download answers no command) is left after
    /// [`JOIN_WAIT`], as before, so a close never hangs on it.
    pub fn stop_and_join(&mut self) {
        let Some(worker) = self.worker.take() else { return };
        let _ = self.commands.send(Command::Stop);
        let t = std::time::Instant::now();
        while !worker.is_finished() && t.elapsed() < JOIN_WAIT {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        if worker.is_finished() {
            worker.stop_and_join();
        }
    }
}

/// Everything a worker needs to start a run.
pub struct StartRequest {
    /// The scene as loaded.
    pub scene: Arc<Gaussians>,
    /// The style image.
    pub style: Arc<gast_core::session::StyleImage>,
    /// Where the style image came from (the key of its cached depth).
    pub style_path: std::path::PathBuf,
    /// The user's depth image for this style, for the `image` depth provider.
    pub style_depth_image: Option<std::path::PathBuf>,
    /// The run's parameters.
    pub config: StyleConfig,
    /// Optimisation cameras (the scene's training cameras); orbit views around
    /// the scene when empty.
    pub cameras: Vec<gast_core::Camera>,
    /// Wakes the UI; call after sending an event or putting a snapshot.
    pub waker: Arc<dyn Fn() + Send + Sync>,
    /// The GPU the steps run on (the studio's own device, shared with the
    /// viewport); `None` runs them on the CPU.
    pub gpu: Option<gast_core::gpu::GpuContext>,
    /// On the CPU, fit the working resolution and the cycles to about ten
    /// minutes (`gast_core::session::plan::auto_plan`), as `gast stylize` does.
    pub fit_budget: bool,
    /// Where the run's state is kept against a crash ([`super::recovery`]).
    pub keep: Option<super::recovery::Slot>,
    /// A kept run to go on from (its settings are `config`; no plan is made).
    pub resume: Option<super::recovery::Offer>,
}

/// Starts a session worker (provided by whoever links the session runner in).
pub type SessionStarter = Box<dyn Fn(StartRequest) -> anyhow::Result<SessionLink>>;

/// Where a run stands, as far as the events tell.
#[derive(Clone, Debug, PartialEq)]
pub enum RunStatus {
    /// No run.
    Idle,
    /// Steps are being taken.
    Running,
    /// Paused by the user.
    Paused,
    /// Ended (all steps or stopped).
    Finished {
        /// Whether every scheduled step ran.
        completed: bool,
    },
    /// Ended with an error.
    Failed(String),
}

/// The studio's record of a run, built only from events.
pub struct RunMonitor {
    /// The channels, while connected.
    pub link: Option<SessionLink>,
    /// Status.
    pub status: RunStatus,
    /// Every step report so far (small; the loss chart reads them).
    pub steps: Vec<StepReport>,
    /// Stage and warning lines for the status panel.
    pub log: Vec<String>,
    /// Version of the newest snapshot taken from the slot.
    pub snapshot_version: u64,
    /// The seconds a step the run's plan expects, when it was planned.
    pub planned_step_s: Option<f64>,
}

impl Default for RunMonitor {
    fn default() -> Self {
        Self {
            link: None,
            status: RunStatus::Idle,
            steps: Vec::new(),
            log: Vec::new(),
            snapshot_version: 0,
            planned_step_s: None,
        }
    }
}

impl RunMonitor {
    /// Starts following a new run.
    pub fn attach(&mut self, link: SessionLink) {
        *self = Self { link: Some(link), status: RunStatus::Running, ..Self::default() };
    }

    /// Stops the connected worker, if any, and waits for it (the studio's close).
    pub fn shut_down(&mut self) {
        if let Some(link) = &mut self.link {
            link.stop_and_join();
        }
    }

    /// Whether a worker is connected and has not ended.
    pub fn is_live(&self) -> bool {
        self.link.is_some() && matches!(self.status, RunStatus::Running | RunStatus::Paused)
    }

    /// The run's start, once the worker has prepared it.
    pub fn start(&self) -> Option<Arc<RunStart>> {
        self.link.as_ref().and_then(|l| l.start.latest())
    }

    /// Seconds of optimisation so far, from the last step report.
    pub fn elapsed_s(&self) -> f64 {
        self.steps.last().map_or(0.0, |s| s.elapsed_s)
    }

    /// The pace of the steps up to the end of the last cycle that has ended
    /// (a later cycle's step reported), as a re-plan reads it.
    pub fn pace_at_cycle_end(&self) -> Option<gast_core::session::plan::Pace> {
        let ended = self.steps.last()?.cycle.checked_sub(1)?;
        let end = self.steps.iter().rposition(|r| r.cycle == ended)?;
        gast_core::session::plan::Pace::read(self.steps[..=end].iter().map(|r| (r.view, r.elapsed_s)))
    }

    /// Sends a command; false when no run is connected.
    pub fn send(&self, command: Command) -> bool {
        self.link.as_ref().is_some_and(|l| l.commands.send(command).is_ok())
    }

    /// The running optimisation's GPU buffers, while the run is live and steps on the GPU.
    pub fn live(&self) -> Option<gast_core::gpu::LiveGaussians> {
        let link = self.link.as_ref().filter(|_| self.is_live())?;
        link.live.latest().map(|l| (*l).clone())
    }

    /// Drains pending events; returns a newer snapshot when the slot holds one.
    pub fn poll(&mut self) -> Option<Arc<Snapshot>> {
        let Some(link) = &self.link else { return None };
        let events: Vec<Event> = link.events.try_iter().collect();
        let fresh = link.snapshots.newer_than(self.snapshot_version).map(|(v, s)| {
            self.snapshot_version = v;
            s
        });
        for e in events {
            self.apply(e);
        }
        fresh
    }

    /// Updates the record with one event.
    pub fn apply(&mut self, event: Event) {
        match event {
            Event::Step(r) => self.steps.push(r),
            Event::Planned { seconds_per_step } => self.planned_step_s = Some(seconds_per_step),
            Event::Stage { name, seconds } => self.log.push(format!("{name}: {seconds:.2} s")),
            Event::Culled { total, kept } => {
                self.log.push(format!("optimising {kept} of {total} Gaussians (the rest are seen by no camera)"))
            }
            Event::Warning(w) => self.log.push(format!("warning: {w}")),
            Event::Paused => self.status = RunStatus::Paused,
            Event::Resumed => self.status = RunStatus::Running,
            Event::ConfigApplied => self.log.push("new parameters applied".into()),
            Event::Finished { completed, steps, seconds } => {
                self.status = RunStatus::Finished { completed };
                self.log.push(format!(
                    "finished: {steps} steps in {seconds:.1} s{}",
                    if completed { "" } else { " (stopped early)" }
                ));
            }
            Event::Failed(msg) => self.status = RunStatus::Failed(msg),
        }
    }

    /// Progress in [0, 1] and the estimated seconds left: the steps left at
    /// the pace of the last whole cycle (its colour and geometry steps in
    /// their proportion), so the estimate follows a machine whose load
    /// changes; before a cycle has ended, at the pace since every view's
    /// first visit. A view's first step also makes its targets (the render
    /// of `G^c` and its features); read into the pace, they raised the
    /// first cycle's estimate (guitar × wave on the 2-core CPU, after 32
    /// steps: 13 min 17 s against 12 min 20 s). While every step so far has
    /// been a first visit, a planned run's expected pace stands in (fern's
    /// 20 views: 25 min after 13 steps of a run planned to 10).
    ///
    /// A run that went on from a kept one reports from its step on, its
    /// times from its own start. The steps counted to are `total` where
    /// given (those a due re-plan will leave, [`Self::replanned_total`]),
    /// else the run's own.
    pub fn progress(&self, total: Option<u32>) -> Option<(f32, f64)> {
        let (first, last) = (self.steps.first()?, self.steps.last()?);
        let done = (last.iter + 1) as f64;
        let total = total.unwrap_or(last.total).max(1) as f64;
        let per_step = (self.last_cycle_pace().or_else(|| self.pace_after_first_visits()))
            .or(self.planned_step_s)
            .unwrap_or(last.elapsed_s / f64::from(last.iter + 1 - first.iter));
        Some(((done / total) as f32, (per_step * (total - done)).max(0.0)))
    }

    /// The steps of `steps_per_cycle` a planned run's re-plan would give it
    /// now ([`gast_core::session::plan::replan_cycles`] over every step so
    /// far, within `budget_s` and at most `most` cycles); `None` until a
    /// steady pace is read (a few revisits of a view). Before the re-plan at
    /// the first cycle's end, the progress counts to these: fern's planned
    /// 2,000 steps at the studio's 0.47 s a step read "ETA 16 min" 41 steps
    /// into a run the re-plan then cut to about ten minutes.
    pub fn replanned_total(&self, steps_per_cycle: u32, budget_s: f64, most: u32) -> Option<u32> {
        use gast_core::session::plan::{Pace, replan_cycles};
        let pace = Pace::read(self.steps.iter().map(|r| (r.view, r.elapsed_s)))?;
        pace.steady_s?;
        replan_cycles(pace, steps_per_cycle, budget_s, most).map(|c| c * steps_per_cycle)
    }

    /// Seconds a step over the last cycle that has ended, from the elapsed
    /// times at its two ends; for the first cycle, from its last first visit
    /// of a view on.
    fn last_cycle_pace(&self) -> Option<f64> {
        let current = self.steps.last()?.cycle;
        let ended = current.checked_sub(1)?;
        // The last step of the ended cycle and the last one before it (if any).
        let end = self.steps.iter().rposition(|r| r.cycle == ended)?;
        let start = self.steps[..end]
            .iter()
            .rposition(|r| r.cycle < ended)
            .or_else(|| self.last_first_visit().filter(|&k| k < end));
        let before_first = i64::from(self.steps[0].iter) - 1;
        let (s0, i0) = start.map_or((0.0, before_first), |k| (self.steps[k].elapsed_s, self.steps[k].iter as i64));
        let steps = self.steps[end].iter as i64 - i0;
        (steps > 0).then(|| (self.steps[end].elapsed_s - s0) / steps as f64)
    }

    /// Seconds a step since the last first visit of a view; `None` until a
    /// view has been visited twice.
    fn pace_after_first_visits(&self) -> Option<f64> {
        let (first, last) = (&self.steps[self.last_first_visit()?], self.steps.last()?);
        let steps = last.iter.checked_sub(first.iter).filter(|&n| n > 0)?;
        Some((last.elapsed_s - first.elapsed_s) / f64::from(steps))
    }

    /// Index in `steps` of the step before the first that revisits a view
    /// (the session visits every view once before any twice); `None` while
    /// every step has been a first visit.
    fn last_first_visit(&self) -> Option<usize> {
        gast_core::session::plan::last_first_visit(self.steps.iter().map(|r| r.view))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gast_core::session::LossTerms;
    use gast_core::style::Phase;

    #[test]
    fn monitor_follows_events_and_snapshots() {
        let (ctx, crx) = crossbeam_channel::unbounded();
        let (etx, erx) = crossbeam_channel::unbounded();
        let slot = Arc::new(Slot::default());
        let mut m = RunMonitor::default();
        m.attach(SessionLink {
            commands: ctx,
            events: erx,
            snapshots: slot.clone(),
            live: Arc::default(),
            start: Arc::default(),
            worker: None,
        });
        assert!(m.send(Command::Pause));
        assert_eq!(crx.try_recv().ok(), Some(Command::Pause));
        let step = |iter: u32| {
            let losses = LossTerms { total: 1.0 / (iter + 1) as f32, ..LossTerms::default() };
            Event::Step(StepReport { losses, ..report(iter, 10, 0, Phase::Color, f64::from(iter + 1)) })
        };
        etx.send(step(0)).expect("send");
        etx.send(step(1)).expect("send");
        etx.send(Event::Paused).expect("send");
        slot.put(Snapshot { step: 2, gaussians: Gaussians::default() });
        let snap = m.poll().expect("snapshot");
        assert_eq!(snap.step, 2);
        assert!(m.poll().is_none(), "the same snapshot twice");
        assert_eq!(m.steps.len(), 2);
        assert_eq!(m.status, RunStatus::Paused);
        let (p, eta) = m.progress(None).expect("progress");
        assert!((p - 0.2).abs() < 1e-6 && (eta - 8.0).abs() < 1e-9);
        etx.send(Event::Finished { completed: false, steps: 2, seconds: 2.0 }).expect("send");
        m.poll();
        assert!(!m.is_live());
    }

    /// A step's report of view 0 with zero losses and timings.
    fn report(iter: u32, total: u32, cycle: u32, phase: Phase, elapsed_s: f64) -> StepReport {
        StepReport {
            iter,
            total,
            cycle,
            phase,
            view: 0,
            losses: LossTerms::default(),
            timings: Default::default(),
            elapsed_s,
            colour: None,
        }
    }

    /// The estimate follows the pace of the last whole cycle: a machine that
    /// slowed down after the first cycle is not read at the first cycle's pace.
    #[test]
    fn the_eta_takes_the_pace_of_the_last_whole_cycle() {
        let mut m = RunMonitor::default();
        // Cycles of 4 steps (2 colour, 2 geometry); 1 s a step in cycle 0, 3 s in cycle 1.
        let mut elapsed = 0.0;
        for iter in 0..10u32 {
            let cycle = iter / 4;
            elapsed += if cycle == 0 { 1.0 } else { 3.0 };
            m.steps.push(report(iter, 20, cycle, if iter % 4 < 2 { Phase::Color } else { Phase::Geometry }, elapsed));
            let (p, eta) = m.progress(None).expect("progress");
            assert!((p - (iter + 1) as f32 / 20.0).abs() < 1e-6);
            let left = f64::from(20 - (iter + 1));
            // In cycle 0 no cycle has ended: the pace since the start; in cycle 1,
            // cycle 0's 1 s; in cycle 2, cycle 1's 3 s (not the mean since the start).
            let pace = match cycle {
                0 => elapsed / f64::from(iter + 1),
                1 => 1.0,
                _ => 3.0,
            };
            assert!((eta - pace * left).abs() < 1e-9, "step {iter}: ETA {eta} against {}", pace * left);
        }
    }

    /// A run that went on from step 10 of 20 reports from there, its times
    /// from its own start: its pace is its own steps' (2 s), not its time
    /// over all the steps before it.
    #[test]
    fn a_run_gone_on_from_a_kept_one_takes_its_own_pace() {
        let mut m = RunMonitor::default();
        for (k, iter) in (10..13u32).enumerate() {
            m.steps.push(report(iter, 20, 2, Phase::Color, 2.0 * (k + 1) as f64));
            let (p, eta) = m.progress(None).expect("progress");
            assert!((p - (iter + 1) as f32 / 20.0).abs() < 1e-6);
            assert!((eta - 2.0 * f64::from(20 - (iter + 1))).abs() < 1e-9, "step {iter}: ETA {eta}");
        }
        // A cycle that ended within this run: its pace from the run's first step.
        m.steps.push(report(13, 20, 3, Phase::Color, 8.0));
        let (_, eta) = m.progress(None).expect("progress");
        assert!((eta - 2.0 * 6.0).abs() < 1e-9, "ETA {eta} after the first cycle ended");
    }

    /// The first visits' targets are not read into the pace: views 0–3 each
    /// cost 6 s on their first step and 1 s on every other; before any view
    /// is seen twice the estimate is the mean since the start.
    #[test]
    fn the_eta_leaves_out_each_views_first_visit() {
        let mut m = RunMonitor::default();
        // Cycles of 10 steps (6 colour, 4 geometry) over 4 views.
        let mut elapsed = 0.0;
        for iter in 0..14u32 {
            elapsed += if iter < 4 { 6.0 } else { 1.0 };
            let phase = if iter % 10 < 6 { Phase::Color } else { Phase::Geometry };
            m.steps.push(StepReport { view: iter % 4, ..report(iter, 40, iter / 10, phase, elapsed) });
            let (_, eta) = m.progress(None).expect("progress");
            let pace = if iter < 4 { elapsed / f64::from(iter + 1) } else { 1.0 };
            let want = pace * f64::from(40 - (iter + 1));
            assert!((eta - want).abs() < 1e-9, "step {iter}: ETA {eta} against {want}");
        }
    }

    /// A planned run's expected pace stands in while every step has been a
    /// first visit (their targets made them slow), then the steps' own.
    #[test]
    fn a_planned_run_starts_its_eta_at_the_planned_pace() {
        let mut m = RunMonitor::default();
        m.apply(Event::Planned { seconds_per_step: 0.5 });
        let mut elapsed = 0.0;
        for iter in 0..6u32 {
            elapsed += if iter < 4 { 6.0 } else { 1.0 };
            m.steps.push(StepReport { view: iter % 4, ..report(iter, 40, 0, Phase::Color, elapsed) });
            let (_, eta) = m.progress(None).expect("progress");
            let pace = if iter < 4 { 0.5 } else { 1.0 };
            let want = pace * f64::from(40 - (iter + 1));
            assert!((eta - want).abs() < 1e-9, "step {iter}: ETA {eta} against {want}");
        }
        // A new run forgets the plan of the last.
        m.attach(SessionLink::of(gast_core::session::spawn_with(|_| Err("none".into()), Arc::new(|| {}))));
        assert_eq!(m.planned_step_s, None);
    }

    /// A planned run of 20 cycles of 100 steps over 20 views (fern's plan)
    /// whose steps take 0.47 s (1 s on each view's first visit) against the
    /// plan's 0.30: once the pace is steady, the progress counts to the 12
    /// cycles a re-plan fits in ten minutes, not to the 20 planned.
    #[test]
    fn a_due_replan_sets_the_steps_the_progress_counts_to() {
        let mut m = RunMonitor::default();
        let mut elapsed = 0.0;
        for iter in 0..41u32 {
            elapsed += if iter < 20 { 1.0 } else { 0.47 };
            m.steps.push(StepReport { view: iter % 20, ..report(iter, 2000, 0, Phase::Color, elapsed) });
            let total = m.replanned_total(100, 600.0, 30);
            // Five revisits make a steady pace (plan::STEADY_STEPS).
            assert_eq!(total.is_some(), iter >= 24, "step {iter}: {total:?}");
        }
        // 41 + (600 − 29.87) / 0.47 = 1,254 steps fit: 12 whole cycles.
        assert_eq!(m.replanned_total(100, 600.0, 30), Some(1200));
        assert_eq!(m.replanned_total(100, 600.0, 8), Some(800), "at most the cycles asked for");
        let (p, eta) = m.progress(Some(1200)).expect("progress");
        assert!((p - 41.0 / 1200.0).abs() < 1e-6);
        assert!((eta - 0.47 * 1159.0).abs() < 1e-6, "ETA {eta}");
        let (_, planned) = m.progress(None).expect("progress");
        assert!((planned - 0.47 * 1959.0).abs() < 1e-6, "ETA {planned} over the planned steps");
    }

    /// A close joins a worker that answers its Stop, and leaves one still
    /// loading after [`JOIN_WAIT`] rather than hang.
    #[test]
    fn a_close_joins_the_worker_or_leaves_one_that_is_still_loading() {
        use gast_core::session::spawn_with;
        let link = SessionLink::of;
        // A load that fails at once: its thread ends and the close joins it.
        let mut m = RunMonitor::default();
        m.attach(link(spawn_with(|_| Err("no inputs".into()), Arc::new(|| {}))));
        let t = std::time::Instant::now();
        m.shut_down();
        assert!(t.elapsed() < JOIN_WAIT, "the close waited {:?} for a thread that had ended", t.elapsed());
        assert!(m.link.as_ref().is_some_and(|l| l.worker.is_none()), "the worker was not taken and joined");
        // A load that waits (as a weights download does): the close returns after the wait.
        let (hold, release) = crossbeam_channel::bounded::<()>(0);
        let mut slow = link(spawn_with(
            move |_| {
                let _ = release.recv();
                Err("released".into())
            },
            Arc::new(|| {}),
        ));
        let t = std::time::Instant::now();
        slow.stop_and_join();
        let waited = t.elapsed();
        assert!(slow.worker.is_none());
        assert!(waited >= JOIN_WAIT && waited < JOIN_WAIT * 3, "waited {waited:?}");
        drop(hold); // the load returns and its thread ends
    }
}
