//! Typed errors for reading and writing scenes: every message names the file,
//! the element or field, and what was found.

use std::path::PathBuf;

/// Why a scene could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// The file's contents are not what the format requires.
    #[error("{path}: {what}: expected {expected}, found {found}")]
    Format {
        /// The file.
        path: PathBuf,
        /// The element, field or section at fault (e.g. `vertex.scale_0`, `header`).
        what: String,
        /// What the format requires there.
        expected: String,
        /// What the file holds instead.
        found: String,
    },
    /// The file's format is not one the studio reads.
    #[error("{path}: unrecognised scene format: expected {expected}, found {found}")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// The formats that are understood.
        expected: String,
        /// What was seen (extension or magic bytes).
        found: String,
    },
}

impl SceneError {
    /// Shorthand for a [`SceneError::Format`].
    pub fn format(
        path: impl Into<PathBuf>,
        what: impl Into<String>,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> Self {
        Self::Format { path: path.into(), what: what.into(), expected: expected.into(), found: found.into() }
    }

    /// Shorthand for a [`SceneError::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io { path: path.into(), source }
    }
}
