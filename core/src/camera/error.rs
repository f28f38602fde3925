//! Typed errors for reading and writing camera files. Users bring camera files
//! from many tools, so every message names the file, the record or field at
//! fault, what was expected and what was found.

use std::path::PathBuf;

/// Why cameras could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// A folder that was asked for does not exist.
    #[error("{path}: expected {expected}, found no such folder")]
    NoFolder {
        /// The folder looked for.
        path: PathBuf,
        /// What it was to hold.
        expected: String,
    },
    /// No file was found where one was looked for: a camera file, an
    /// image a camera names, an images or points file.
    #[error("{path}: expected {expected}, found none")]
    NotFound {
        /// The file or folder given.
        path: PathBuf,
        /// What was looked for.
        expected: String,
    },
    /// A JSON document that does not parse, or whose fields have the wrong shape.
    #[error("{path}: {record}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The record at fault (`document`, `frames[3]`, …).
        record: String,
        /// The parser's message (it names a missing field; one of the wrong
        /// type is named before, by `check_fields`).
        source: serde_json::Error,
    },
    /// A value that is present but not acceptable.
    #[error("{path}: {record}: expected {expected}, found {found}")]
    Format {
        /// The file.
        path: PathBuf,
        /// The record and field at fault (e.g. `image 12 (line 7).qvec`).
        record: String,
        /// What the format requires there.
        expected: String,
        /// What the file holds instead.
        found: String,
    },
    /// A binary file that ends inside a record.
    #[error("{path}: {record}: truncated at byte {offset}: expected {needed} more bytes, found {available}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The record being read.
        record: String,
        /// Byte offset where the read started.
        offset: u64,
        /// Bytes the record needs.
        needed: u64,
        /// Bytes left in the file.
        available: u64,
    },
    /// A COLMAP camera model the studio does not know.
    #[error("{path}: camera {camera_id}: expected a known COLMAP camera model ({known}), found {model}")]
    UnknownModel {
        /// The file.
        path: PathBuf,
        /// The COLMAP camera id.
        camera_id: u64,
        /// The model name or numeric id found.
        model: String,
        /// The models that are understood.
        known: String,
    },
}

impl CameraError {
    /// Shorthand for [`CameraError::Format`].
    pub(crate) fn format(
        path: impl Into<PathBuf>,
        record: impl Into<String>,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> Self {
        Self::Format { path: path.into(), record: record.into(), expected: expected.into(), found: found.into() }
    }

    /// Shorthand for [`CameraError::Io`].
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io { path: path.into(), source }
    }
}
