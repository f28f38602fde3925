//! What the weights readers share: the tensors a file yields before they are
//! checked ([`RawTensor`]) and why finding, fetching or reading a weights
//! file fails ([`WeightsError`]). `weights.rs` (safetensors and the VGG
//! checks), `pth.rs` (PyTorch checkpoints), `download.rs` and the depth
//! network's loader all use them; `weights.rs` re-exports them.

use std::path::{Path, PathBuf};

/// Where the network torchvision publishes can be downloaded from (see [`super::download`]).
pub const HOW_TO_GET: &str = "download https://download.pytorch.org/models/vgg16-397923af.pth \
(torchvision's VGG16) into ~/.cache/gast/ or torch's hub cache ~/.cache/torch/hub/checkpoints/, \
or point GAST_WEIGHTS at a .pth or .safetensors file holding features.0 … features.14";

/// Why weights could not be found, fetched or read.
#[derive(Debug, thiserror::Error)]
pub enum WeightsError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// No weights file anywhere we looked.
    #[error("no VGG weights found (looked at: {}); to get them, {HOW_TO_GET}", .searched.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "))]
    NotFound {
        /// Every path that was tried.
        searched: Vec<PathBuf>,
    },
    /// The file is not a format we read, or is damaged.
    #[error("{path}: expected {expected}, found {found}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What a valid file has here.
        expected: String,
        /// What this file has.
        found: String,
    },
    /// A tensor the network needs is absent.
    #[error(
        "{path}: tensor `{name}` is missing (expected a torchvision VGG state dict with features.0 … features.14); to get a good file, {HOW_TO_GET}"
    )]
    MissingTensor {
        /// The file.
        path: PathBuf,
        /// The torchvision parameter name.
        name: String,
    },
    /// A tensor has the wrong shape or element type.
    #[error("{path}: tensor `{name}`: expected {expected}, found {found}")]
    BadTensor {
        /// The file.
        path: PathBuf,
        /// The torchvision parameter name.
        name: String,
        /// What the network needs.
        expected: String,
        /// What the file holds.
        found: String,
    },
    /// Downloading failed (network, HTTP status, or server unreachable).
    #[error("downloading {url} failed: {detail}; to install the weights by hand, {HOW_TO_GET}")]
    Download {
        /// The address.
        url: String,
        /// What went wrong.
        detail: String,
    },
    /// A downloaded file does not have the sha256 its name promises.
    #[error("{url}: sha256 expected to start with {expected}, found {found}; the partial file was removed, try again")]
    Checksum {
        /// The address.
        url: String,
        /// The hash prefix from the file name.
        expected: String,
        /// The full hash of what arrived.
        found: String,
    },
}

impl WeightsError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io { path: path.to_path_buf(), source }
    }

    pub(crate) fn format(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Self {
        Self::Format { path: path.to_path_buf(), expected: expected.into(), found: found.into() }
    }
}

/// A tensor as found in a file, before it is checked against what the network needs.
pub(crate) struct RawTensor {
    pub shape: Vec<usize>,
    /// Element type as the file names it (`"F32"`, `"FloatStorage"`, …), for messages.
    pub dtype: String,
    /// Row-major f32 values, or `None` when the element type is not f32.
    pub data: Option<Vec<f32>>,
}
