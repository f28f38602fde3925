//! Shared helpers for the workspace-level integration tests: where the shared
//! data lives, loading golden files, and a scene file with no Gaussians.
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

/// Writes an INRIA `.ply` header that declares no Gaussians (every property
/// of an SH-degree-0 scene, 0 vertices): a well-formed scene with nothing to
/// draw or stylize.
pub fn write_empty_ply(path: &std::path::Path) {
    let props: String = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2"]
        .into_iter()
        .chain(["rot_0", "rot_1", "rot_2", "rot_3"])
        .map(|p| format!("property float {p}\n"))
        .collect();
    let header = format!("ply\nformat binary_little_endian 1.0\nelement vertex 0\n{props}end_header\n");
    std::fs::write(path, header).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}
