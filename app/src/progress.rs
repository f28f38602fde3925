//! Progress bars for long command-line work (hidden when stderr is not a terminal
//! so logs stay readable, but a final line is always printed).

use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};

/// The longest a hidden bar goes without a line, seconds: a slow run (a scene
/// of millions of Gaussians takes seconds a step) says how far it got at
/// least once a minute, not only at each tenth of the way.
pub const LINE_EVERY_S: f64 = 60.0;

/// Each hidden bar's (prefix, elapsed seconds at its last line).
static LAST_LINE: Mutex<Vec<(String, f64)>> = Mutex::new(Vec::new());

/// The elapsed seconds at the last line of the bar `prefix` (0 before one).
fn last_line(prefix: &str) -> f64 {
    let lines = LAST_LINE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    lines.iter().find(|(p, _)| p == prefix).map_or(0.0, |(_, at)| *at)
}

/// Notes that the bar `prefix` printed a line at `elapsed` (0: a new bar).
fn note_line(prefix: &str, elapsed: f64) {
    let mut lines = LAST_LINE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    match lines.iter_mut().find(|(p, _)| p == prefix) {
        Some((_, at)) => *at = elapsed,
        None => lines.push((prefix.to_string(), elapsed)),
    }
}

/// Whether a hidden bar over `len` prints a line on moving from `before` to
/// `pos`, `elapsed` seconds in, its last line at `last`: when a tenth of the
/// way is passed, or [`LINE_EVERY_S`] has gone by since the last line.
fn line_due(before: u64, pos: u64, len: u64, elapsed: f64, last: f64) -> bool {
    len > 0 && pos > before && (before * 10 / len < pos * 10 / len || elapsed - last >= LINE_EVERY_S)
}

/// A bar over `len` items with a message prefix.
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
    note_line(what, 0.0);
    pb
}

/// A bar over bytes (downloads); its length is set once known.
pub fn bytes_bar(what: &str) -> ProgressBar {
    let pb = ProgressBar::new(0);
    pb.set_style(
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {bytes}/{total_bytes} {bytes_per_sec} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
    pb
}

/// Advances `pb` by one; see [`advance_to`].
pub fn tick(pb: &ProgressBar) {
    advance_to(pb, pb.position() + 1);
}

/// Moves `pb` to `pos`; when the bar is hidden (stderr is not a terminal: a
/// log, a CI job, a remote machine) it prints a line each time a tenth of the
/// way is passed instead, and at least once a minute ([`LINE_EVERY_S`]), so
/// a run cut short still tells how far it got and how fast.
pub fn advance_to(pb: &ProgressBar, pos: u64) {
    let before = pb.position();
    pb.set_position(pos);
    let len = pb.length().unwrap_or(0);
    if !pb.is_hidden() || len == 0 {
        return;
    }
    let elapsed = pb.elapsed().as_secs_f64();
    let prefix = pb.prefix();
    if !line_due(before, pos, len, elapsed, last_line(&prefix)) {
        return;
    }
    note_line(&prefix, elapsed);
    let each = elapsed / pos.max(1) as f64;
    eprintln!(
        "{}: {pos}/{len} ({:.0}%), {elapsed:.1} s, {each:.3} s each, about {:.0} s left",
        pb.prefix().trim(),
        100.0 * pos as f64 / len as f64,
        each * len.saturating_sub(pos) as f64
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hidden_bar_prints_each_tenth_and_once_a_minute() {
        // Each tenth of 100 steps, however quick.
        assert!(line_due(9, 10, 100, 1.0, 0.5));
        assert!(!line_due(10, 11, 100, 1.0, 0.9));
        // Between tenths, once a minute has gone by since the last line.
        assert!(!line_due(11, 12, 2000, 59.0, 0.0));
        assert!(line_due(11, 12, 2000, 61.0, 0.0));
        assert!(!line_due(12, 13, 2000, 62.0, 61.0));
        // Nothing without a length or a move.
        assert!(!line_due(0, 1, 0, 100.0, 0.0));
        assert!(!line_due(5, 5, 100, 100.0, 0.0));
        // A bar's last line is its own; a new bar of the prefix starts at 0.
        assert_eq!(last_line("test-a"), 0.0);
        note_line("test-a", 61.0);
        note_line("test-b", 5.0);
        assert_eq!((last_line("test-a"), last_line("test-b")), (61.0, 5.0));
        note_line("test-a", 0.0);
        assert_eq!(last_line("test-a"), 0.0);
    }
}
