//! Shared helpers for the workspace-level integration tests: where the shared
//! data lives, and loading golden files.
//!
//! The data stays in `../shared` beside the checkout (never copied into the
//! repo); `GAST_SHARED` overrides the location. A test whose file is truly
//! absent skips with a loud message; CI always has the data.

use std::path::PathBuf;

/// The shared folder: `$GAST_SHARED`, else `../shared` beside the workspace.
pub fn shared_dir() -> PathBuf {
    match std::env::var_os("GAST_SHARED") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"),
    }
}

/// A file under the shared folder, or `None` after a loud message when it is absent.
pub fn shared_file(rel: &str) -> Option<PathBuf> {
    let p = shared_dir().join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "\n!!!!!!!! SKIPPED: shared data file {} is absent (set GAST_SHARED to the folder holding data/ and golden/) !!!!!!!!\n",
            p.display()
        );
        None
    }
}
