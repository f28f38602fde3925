//! Running a session on its own thread: commands in, events out, the newest
//! Gaussians in a latest-value slot. The front end is woken through a closure
//! it hands in (e.g. `ctx.request_repaint()`), so the core never depends on a UI.

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TryRecvError};

use super::events::{Command, Event};
use super::moments::OptimiserState;
use super::run::{Session, SessionInputs};
use super::slot::Slot;
use super::{RunStart, Snapshot};
use crate::gpu::LiveGaussians;
use crate::scene::Gaussians;

/// How often at most a snapshot of the whole scene is published.
const SNAPSHOT_INTERVAL: Duration = Duration::from_millis(500);

/// The same while a viewer may draw the GPU engine's buffers directly: the
/// snapshots then serve the CPU-side readers (inspection maps, exports) only.
const LIVE_SNAPSHOT_INTERVAL: Duration = Duration::from_secs(2);

/// The front end's side of a running session.
pub struct SessionHandle {
    /// Commands to the worker.
    pub commands: Sender<Command>,
    /// Events from the worker.
    pub events: Receiver<Event>,
    /// The newest snapshot of the scene.
    pub snapshots: Arc<Slot<Snapshot>>,
    /// The GPU engine's buffers, once the session is prepared on a GPU (for a
    /// viewer on the same device; see [`crate::gpu::LiveGaussians`]).
    pub live: Arc<Slot<LiveGaussians>>,
    /// The run's start, put once when preparation is done.
    pub start: Arc<Slot<RunStart>>,
    thread: Option<JoinHandle<Option<Arc<Snapshot>>>>,
}

impl SessionHandle {
    /// Asks the worker to stop and waits for the result (the scene so far), if any.
    pub fn stop_and_join(mut self) -> Option<Gaussians> {
        let _ = self.commands.send(Command::Stop);
        let last = self.thread.take().and_then(|t| t.join().ok().flatten());
        last.map(|s| Arc::unwrap_or_clone(s).gaussians)
    }

    /// Whether the worker thread has ended.
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }
}

impl Drop for SessionHandle {
    fn drop(&mut self) {
        let _ = self.commands.send(Command::Stop);
    }
}

/// Starts a worker thread that prepares the session and steps it to the end,
/// applying commands between steps.
pub fn spawn(inputs: SessionInputs, waker: Arc<dyn Fn() + Send + Sync>) -> SessionHandle {
    spawn_with(move |_| Ok(inputs), waker)
}

/// Like [`spawn`], but the inputs are gathered on the worker thread by `load`
/// (reading files, resolving or downloading weights), so a front end never
/// waits for them. `load` may report stages through the event callback it is
/// given; an error ends the run with [`Event::Failed`].
pub fn spawn_with<F>(load: F, waker: Arc<dyn Fn() + Send + Sync>) -> SessionHandle
where
    F: FnOnce(&mut dyn FnMut(Event)) -> Result<SessionInputs, String> + Send + 'static,
{
    spawn_run(move |emit| load(emit).map(|inputs| (inputs, RunOptions::default())), waker)
}

/// What a worker does besides stepping a fresh run: go on from an earlier
/// run's state, and keep the run's state now and then, so that a later one
/// can go on from it when this one is killed or crashes.
#[derive(Default)]
pub struct RunOptions {
    /// Go on from this state of a run with the same inputs and settings.
    pub resume: Option<ResumeFrom>,
    /// Keeps the run's state.
    pub keep: Option<Keeper>,
    /// Called on the worker's thread when it ends, after the session and
    /// everything else of the run's is dropped (the studio hands the freed
    /// memory back to the system there).
    pub at_end: Option<Box<dyn FnOnce() + Send>>,
}

/// Calls its function when dropped: declared before the session, it runs
/// after the session is gone, however the worker ends.
struct AtEnd(Option<Box<dyn FnOnce() + Send>>);

impl Drop for AtEnd {
    fn drop(&mut self) {
        if let Some(f) = self.0.take() {
            f();
        }
    }
}

/// An earlier run's state to go on from ([`Session::resume_at`]).
pub struct ResumeFrom {
    /// Its scene after `step` steps (its [`Session::result`], whole).
    pub scene: Gaussians,
    /// Steps it had done.
    pub step: u32,
    /// Its optimiser's state at `step`, where kept; else the moments start afresh.
    pub moments: Option<OptimiserState>,
}

/// Keeps a run's state: `write` is given the session after every `every` of
/// stepping, or longer where a write takes more than [`KEEP_SHARE`] of that
/// ([`Keeper::interval`]), at a pause and at the run's end (whenever it has
/// taken a step since the last write). Each write is reported as a stage
/// with its time; a write's error as a warning, and the run goes on.
pub struct Keeper {
    /// Stepping time between writes, at the least.
    pub every: Duration,
    /// Writes the session's state (its result, optimiser state and step).
    pub write: KeepWrite,
    /// The last write's time.
    last_write: Duration,
}

/// The most of a run's time the keeper's writes take: a scene whose write
/// takes longer than this share of [`Keeper::every`] is written less often
/// (two million Gaussians of SH degree 3: 4.7 s a write, every 4 min rather
/// than every minute).
pub const KEEP_SHARE: f64 = 0.02;

/// A [`Keeper`]'s writer: the session's state to wherever it is kept, with
/// its [`Session::result`] at this step, which the worker has made for the
/// run's snapshot as well (one whole scene, not two).
pub type KeepWrite = Box<dyn FnMut(&Session, &Gaussians) -> Result<(), String> + Send>;

impl Keeper {
    /// A keeper writing with `write` every `every` of stepping, at the least.
    pub fn new(every: Duration, write: KeepWrite) -> Self {
        Self { every, write, last_write: Duration::ZERO }
    }

    /// Stepping time until the next write: `every`, or the last write's time
    /// over [`KEEP_SHARE`] where that is longer.
    pub fn interval(&self) -> Duration {
        self.every.max(self.last_write.div_f64(KEEP_SHARE))
    }

    /// Writes the session's state when it has stepped since `written` (the
    /// step last written), reporting a failure as a warning.
    fn keep(&mut self, session: &Session, result: &Gaussians, written: &mut u32, emit: &dyn Fn(Event)) {
        if session.steps_done() == *written {
            return;
        }
        *written = session.steps_done();
        let t = Instant::now();
        let done = (self.write)(session, result);
        self.last_write = t.elapsed();
        match done {
            Ok(()) => emit(Event::Stage {
                name: format!("kept the run's state at step {written}"),
                seconds: self.last_write.as_secs_f64(),
            }),
            Err(e) => emit(Event::Warning(format!("the run's state could not be kept at step {written}: {e}"))),
        }
    }
}

/// Like [`spawn_with`], with `load` also giving the [`RunOptions`]: a state to
/// go on from (applied once the session is prepared; a state that does not
/// fit the run ends it with [`Event::Failed`]) and a [`Keeper`].
pub fn spawn_run<F>(load: F, waker: Arc<dyn Fn() + Send + Sync>) -> SessionHandle
where
    F: FnOnce(&mut dyn FnMut(Event)) -> Result<(SessionInputs, RunOptions), String> + Send + 'static,
{
    let (cmd_tx, cmd_rx) = crossbeam_channel::unbounded();
    let (ev_tx, ev_rx) = crossbeam_channel::unbounded();
    let slot = Arc::new(Slot::default());
    let start = Arc::new(Slot::default());
    let live = Arc::new(Slot::default());
    let slots = WorkerSlots { snapshots: slot.clone(), start: start.clone(), live: live.clone() };
    let thread = std::thread::Builder::new()
        .name("gast-session".into())
        .spawn(move || worker(load, cmd_rx, ev_tx, slots, waker))
        .ok();
    SessionHandle { commands: cmd_tx, events: ev_rx, snapshots: slot, live, start, thread }
}

/// The slots a worker fills.
struct WorkerSlots {
    snapshots: Arc<Slot<Snapshot>>,
    start: Arc<Slot<RunStart>>,
    live: Arc<Slot<LiveGaussians>>,
}

fn worker<F>(
    load: F,
    commands: Receiver<Command>,
    events: Sender<Event>,
    slots: WorkerSlots,
    waker: Arc<dyn Fn() + Send + Sync>,
) -> Option<Arc<Snapshot>>
where
    F: FnOnce(&mut dyn FnMut(Event)) -> Result<(SessionInputs, RunOptions), String>,
{
    let emit = |e: Event| {
        let _ = events.send(e);
        waker();
    };
    let (inputs, mut options) = match load(&mut |e| emit(e)) {
        Ok(loaded) => loaded,
        Err(e) => {
            emit(Event::Failed(e));
            return None;
        }
    };
    let _at_end = AtEnd(options.at_end.take());
    let mut session = match Session::prepare(inputs, &mut |e| emit(e)) {
        Ok(s) => s,
        Err(e) => {
            emit(Event::Failed(e.to_string()));
            return None;
        }
    };
    if let Some(from) = options.resume {
        let t = Instant::now();
        let with = if from.moments.is_some() { "with" } else { "the moments afresh, without" };
        if let Err(e) = session.resume_at(&from.scene, from.step, from.moments.as_ref()) {
            emit(Event::Failed(format!("could not go on from step {}: {e}", from.step)));
            return None;
        }
        emit(Event::Stage {
            name: format!(
                "went on from step {} of {} ({with} the optimiser's state)",
                from.step,
                session.total_steps()
            ),
            seconds: t.elapsed().as_secs_f64(),
        });
    }
    let slot = &slots.snapshots;
    slots.start.put(RunStart::of(&session));
    if let Some(l) = session.live() {
        slots.live.put(l);
    }
    put_snapshot(slot, &session);
    waker();
    let mut keep = options.keep.map(|k| (k, session.steps_done()));
    run_loop_keeping(&mut session, &commands, &emit, slot, &*waker, keep.as_mut());
    // The result is the slot's last snapshot and the thread's return value at
    // once (one copy, not two), and the session is let go before `Finished`.
    let result = put_snapshot(slot, &session);
    waker();
    if let Some((keeper, written)) = &mut keep {
        keeper.keep(&session, &result.gaussians, written, &emit);
    }
    let (completed, steps, seconds) = (session.is_done(), session.steps_done(), session.elapsed_s());
    drop(session);
    emit(Event::Finished { completed, steps, seconds });
    Some(result)
}

/// Puts the session's [`Session::result`] at this step in `slot` as its
/// newest snapshot; returns it as readers get it.
fn put_snapshot(slot: &Slot<Snapshot>, session: &Session) -> Arc<Snapshot> {
    slot.put(Snapshot { step: session.steps_done(), gaussians: session.result() })
}

/// Steps until the schedule ends or a `Stop` arrives; `Pause` blocks on the
/// command channel (no busy waiting).
pub fn run_loop(
    session: &mut Session,
    commands: &Receiver<Command>,
    emit: &dyn Fn(Event),
    slot: &Slot<Snapshot>,
    waker: &dyn Fn(),
) {
    run_loop_keeping(session, commands, emit, slot, waker, None);
}

/// [`run_loop`], keeping the run's state with `keep` (its keeper and the
/// step it last wrote) every [`Keeper::interval`] of stepping and at a pause.
fn run_loop_keeping(
    session: &mut Session,
    commands: &Receiver<Command>,
    emit: &dyn Fn(Event),
    slot: &Slot<Snapshot>,
    waker: &dyn Fn(),
    mut keep: Option<&mut (Keeper, u32)>,
) {
    let mut paused = false;
    let mut pause_at: Option<u32> = None;
    let mut last_kept = Instant::now();
    let mut last_snapshot = Instant::now();
    let interval = if session.is_shared_live() { LIVE_SNAPSHOT_INTERVAL } else { SNAPSHOT_INTERVAL };
    loop {
        let cmd = if paused {
            match commands.recv() {
                Ok(c) => Some(c),
                Err(_) => return,
            }
        } else {
            match commands.try_recv() {
                Ok(c) => Some(c),
                Err(TryRecvError::Empty) => None,
                Err(TryRecvError::Disconnected) => return,
            }
        };
        let cmd = match cmd {
            None if pause_at.is_some_and(|at| session.steps_done() >= at) => {
                pause_at = None;
                Some(Command::Pause)
            }
            cmd => cmd,
        };
        match cmd {
            Some(Command::Stop) => return,
            Some(Command::Pause) => {
                if !paused {
                    paused = true;
                    let snapshot = put_snapshot(slot, session);
                    if let Some((keeper, written)) = keep.as_deref_mut() {
                        keeper.keep(session, &snapshot.gaussians, written, emit);
                        last_kept = Instant::now();
                    }
                    emit(Event::Paused);
                }
                continue;
            }
            Some(Command::PauseAfter(n)) => {
                pause_at = Some(session.steps_done().saturating_add(n));
                continue;
            }
            Some(Command::Resume) => {
                if paused {
                    paused = false;
                    emit(Event::Resumed);
                }
                continue;
            }
            Some(Command::SetConfig(c)) => {
                match session.set_config(*c) {
                    Ok(()) => emit(Event::ConfigApplied),
                    Err(e) => emit(Event::Warning(format!("parameters not applied: {e}"))),
                }
                continue;
            }
            None => {}
        }
        match session.step() {
            Some(report) => {
                let bad = !report.losses.total.is_finite();
                emit(Event::Step(report));
                if bad {
                    emit(Event::Warning(format!("step {}: the loss is not finite; stopping", report.iter)));
                    return;
                }
                if let Some((keeper, written)) = keep.as_deref_mut()
                    && last_kept.elapsed() >= keeper.interval()
                {
                    // The kept scene is the run's newest snapshot too.
                    let snapshot = put_snapshot(slot, session);
                    keeper.keep(session, &snapshot.gaussians, written, emit);
                    last_kept = Instant::now();
                    last_snapshot = Instant::now();
                    waker();
                }
                if last_snapshot.elapsed() >= interval {
                    put_snapshot(slot, session);
                    last_snapshot = Instant::now();
                    waker();
                }
            }
            None => {
                if let Some(why) = session.failure() {
                    emit(Event::Failed(why.to_owned()));
                }
                return;
            }
        }
        for w in session.take_warnings() {
            emit(Event::Warning(w));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quick write keeps the interval asked; a slow one stretches it so
    /// that writing takes at most KEEP_SHARE of the run.
    #[test]
    fn a_slow_write_is_made_less_often() {
        let mut keeper = Keeper::new(Duration::from_secs(60), Box::new(|_, _| Ok(())));
        assert_eq!(keeper.interval(), Duration::from_secs(60));
        keeper.last_write = Duration::from_millis(30);
        assert_eq!(keeper.interval(), Duration::from_secs(60));
        keeper.last_write = Duration::from_secs_f64(4.68);
        assert!((keeper.interval().as_secs_f64() - 234.0).abs() < 1e-6, "{:?}", keeper.interval());
    }
}
