//! `gast`: GAST Studio, the desktop studio and its command line. With no
//! arguments it opens the studio on the demo scene and style.
//!
//! Every subcommand drives the same `gast-core` code the studio uses; long work
//! shows progress bars, and errors carry the file and what was expected.

mod checkpoint;
mod cli;
mod memory;
mod progress;
mod report;
mod studio;
mod study;
mod turntable;
mod views;

use clap::Parser;

fn main() -> std::process::ExitCode {
    memory::keep_freed();
    give_a_runtime_dir();
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {}", error_text(&err));
            std::process::ExitCode::FAILURE
        }
    }
}

/// Where `XDG_RUNTIME_DIR` is unset or not a folder (a server, a container,
/// CI), Mesa's Vulkan drivers print "error: XDG_RUNTIME_DIR is invalid or not
/// set in the environment." twice while wgpu looks for adapters: not an error
/// of ours, and the first thing a newcomer would read. Points it at a private
/// folder of this user's (`/tmp/gast-runtime-<uid>`, mode 0700) before anything
/// else runs.
#[cfg(unix)]
#[allow(unsafe_code)]
fn give_a_runtime_dir() {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| std::path::Path::new(&d).is_dir()) {
        return;
    }
    let Ok(uid) = std::fs::metadata("/proc/self").map(|m| m.uid()) else { return };
    let dir = std::env::temp_dir().join(format!("gast-runtime-{uid}"));
    let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
    // Only a folder of ours, private, will do (another user may have made the name first).
    let Ok(meta) = std::fs::symlink_metadata(&dir) else { return };
    if !meta.is_dir() || meta.uid() != uid || meta.permissions().mode() & 0o077 != 0 {
        return;
    }
    // SAFETY: called first in `main`, before any thread exists, so nothing
    // reads the environment concurrently.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
}

#[cfg(not(unix))]
fn give_a_runtime_dir() {}

/// An error and its causes on one line, each cause once: the core's errors
/// already quote their source in their own message.
pub fn error_text(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if !out.contains(&text) {
            if !out.is_empty() {
                out.push_str(": ");
            }
            out.push_str(&text);
        }
    }
    out
}
