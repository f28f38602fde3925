//! Ctrl-C during a long loop (stylize's steps, fit's iterations): the first
//! stops it after the current step, and the command still writes what it
//! has; a second quits at once. Outside such a loop (loading, a download,
//! writing) Ctrl-C quits at once, as everywhere else.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The process's Ctrl-C flags. Installed once per process (a second command
/// in one process, as the tests run them, shares it).
pub struct Interrupt {
    /// A loop is running: Ctrl-C asks it to stop.
    looping: Arc<AtomicBool>,
    /// Ctrl-C was pressed while looping.
    asked: Arc<AtomicBool>,
}

impl Interrupt {
    /// A loop starts: from now on the first Ctrl-C asks it to stop.
    pub fn begin(&self) {
        self.asked.store(false, Ordering::SeqCst);
        self.looping.store(true, Ordering::SeqCst);
    }

    /// Whether Ctrl-C asked the loop to stop.
    pub fn asked(&self) -> bool {
        self.asked.load(Ordering::SeqCst)
    }

    /// The loop is over: Ctrl-C quits at once again.
    pub fn end(&self) {
        self.looping.store(false, Ordering::SeqCst);
    }
}

/// A second SIGINT this soon after the first is the same Ctrl-C delivered
/// twice, not a second press: `timeout -s INT` sends it to the command and
/// then to its process group, and when the two are not merged the command
/// quit at once, writing nothing (a fern run stopped so lost every step).
const ONE_PRESS: Duration = Duration::from_millis(200);

/// The process's [`Interrupt`], its Ctrl-C handler installed on first use.
pub fn interrupt() -> &'static Interrupt {
    static FLAGS: std::sync::OnceLock<Interrupt> = std::sync::OnceLock::new();
    FLAGS.get_or_init(|| {
        let (looping, asked) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let (l, a) = (looping.clone(), asked.clone());
        let mut first: Option<Instant> = None;
        // No handler (another one is installed): Ctrl-C quits as before.
        let _ = ctrlc::set_handler(move || {
            if !l.load(Ordering::SeqCst) {
                std::process::exit(130);
            }
            if !a.swap(true, Ordering::SeqCst) {
                first = Some(Instant::now());
            } else if first.is_none_or(|t| t.elapsed() >= ONE_PRESS) {
                std::process::exit(130);
            }
        });
        Interrupt { looping, asked }
    })
}
