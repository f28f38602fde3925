//! Running a session on its own thread: commands in, events out, the newest
//! Gaussians in a latest-value slot. The front end is woken through a closure
//! it hands in (e.g. `ctx.request_repaint()`), so the core never depends on a UI.

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TryRecvError};

use super::events::{Command, Event};
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
    thread: Option<JoinHandle<Option<Gaussians>>>,
}

impl SessionHandle {
    /// Asks the worker to stop and waits for the result (the scene so far), if any.
    pub fn stop_and_join(mut self) -> Option<Gaussians> {
        let _ = self.commands.send(Command::Stop);
        self.thread.take().and_then(|t| t.join().ok().flatten())
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
) -> Option<Gaussians>
where
    F: FnOnce(&mut dyn FnMut(Event)) -> Result<SessionInputs, String>,
{
    let emit = |e: Event| {
        let _ = events.send(e);
        waker();
    };
    let inputs = match load(&mut |e| emit(e)) {
        Ok(inputs) => inputs,
        Err(e) => {
            emit(Event::Failed(e));
            return None;
        }
    };
    let mut session = match Session::prepare(inputs, &mut |e| emit(e)) {
        Ok(s) => s,
        Err(e) => {
            emit(Event::Failed(e.to_string()));
            return None;
        }
    };
    let slot = &slots.snapshots;
    slots.start.put(RunStart::of(&session));
    if let Some(l) = session.live() {
        slots.live.put(l);
    }
    slot.put(Snapshot { step: 0, gaussians: session.result() });
    waker();
    run_loop(&mut session, &commands, &emit, slot, &*waker);
    let result = session.result();
    slot.put(Snapshot { step: session.steps_done(), gaussians: result.clone() });
    emit(Event::Finished { completed: session.is_done(), steps: session.steps_done(), seconds: session.elapsed_s() });
    Some(result)
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
    let mut paused = false;
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
        match cmd {
            Some(Command::Stop) => return,
            Some(Command::Pause) => {
                if !paused {
                    paused = true;
                    slot.put(Snapshot { step: session.steps_done(), gaussians: session.result() });
                    emit(Event::Paused);
                }
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
                if last_snapshot.elapsed() >= interval {
                    slot.put(Snapshot { step: session.steps_done(), gaussians: session.result() });
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
