//! Progress bars for long command-line work (hidden when stderr is not a terminal
//! so logs stay readable, but a final line is always printed).

use indicatif::{ProgressBar, ProgressStyle};

/// A bar over `len` items with a message prefix.
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
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
/// way is passed instead, so a run cut short still tells how far it got and
/// how fast.
pub fn advance_to(pb: &ProgressBar, pos: u64) {
    let before = pb.position();
    pb.set_position(pos);
    let len = pb.length().unwrap_or(0);
    if !pb.is_hidden() || len == 0 || before * 10 / len >= pos * 10 / len {
        return;
    }
    let elapsed = pb.elapsed().as_secs_f64();
    let each = elapsed / pos.max(1) as f64;
    eprintln!(
        "{}: {pos}/{len} ({:.0}%), {elapsed:.1} s, {each:.3} s each, about {:.0} s left",
        pb.prefix().trim(),
        100.0 * pos as f64 / len as f64,
        each * len.saturating_sub(pos) as f64
    );
}
