//! Reading a golden file: safetensors whose tensors are all float64, with
//! the errors that name the file, the tensor, what was expected and found.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Why a golden file could not be checked.
#[derive(Debug, thiserror::Error)]
pub enum GoldenError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is not a golden file of a known kind.
    #[error("{path}: {what}: expected {expected}, found {found}")]
    Format {
        /// The file.
        path: PathBuf,
        /// The tensor or section at fault.
        what: String,
        /// What was expected.
        expected: String,
        /// What the file holds.
        found: String,
    },
    /// Running the project's code on the inputs failed.
    #[error("{path}: {message}")]
    Run {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// A float64 tensor read from a golden file.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    /// Dimensions, outermost first.
    pub shape: Vec<usize>,
    /// Values, row-major.
    pub data: Vec<f64>,
}

impl Tensor {
    /// The values converted to f32.
    pub fn to_f32(&self) -> Vec<f32> {
        self.data.iter().map(|&v| v as f32).collect()
    }
}

/// All tensors of one golden file.
#[derive(Clone, Debug)]
pub struct GoldenFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// Tensors by name.
    pub tensors: BTreeMap<String, Tensor>,
}

impl GoldenFile {
    /// Reads a safetensors file whose tensors are all float64.
    pub fn read(path: &Path) -> Result<Self, GoldenError> {
        let bytes = std::fs::read(path).map_err(|source| GoldenError::Io { path: path.to_path_buf(), source })?;
        let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| GoldenError::Format {
            path: path.to_path_buf(),
            what: "header".into(),
            expected: "a safetensors file".into(),
            found: e.to_string(),
        })?;
        let mut tensors = BTreeMap::new();
        for (name, view) in st.tensors() {
            if view.dtype() != safetensors::Dtype::F64 {
                return Err(GoldenError::Format {
                    path: path.to_path_buf(),
                    what: format!("tensor {name}"),
                    expected: "dtype F64".into(),
                    found: format!("{:?}", view.dtype()),
                });
            }
            let data = view
                .data()
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect();
            tensors.insert(name, Tensor { shape: view.shape().to_vec(), data });
        }
        Ok(Self { path: path.to_path_buf(), tensors })
    }

    /// A tensor by name, or an error naming the file and the missing tensor.
    pub fn get(&self, name: &str) -> Result<&Tensor, GoldenError> {
        self.tensors.get(name).ok_or_else(|| GoldenError::Format {
            path: self.path.clone(),
            what: format!("tensor {name}"),
            expected: "present".into(),
            found: "missing".into(),
        })
    }

    /// A tensor by name, checked to have `shape`.
    pub fn get_shaped(&self, name: &str, shape: &[usize]) -> Result<&Tensor, GoldenError> {
        let t = self.get(name)?;
        if t.shape != shape {
            return Err(GoldenError::Format {
                path: self.path.clone(),
                what: format!("tensor {name}"),
                expected: format!("shape {shape:?}"),
                found: format!("shape {:?}", t.shape),
            });
        }
        Ok(t)
    }

    /// The kind of computation the file describes, from its tensor names.
    pub fn kind(&self) -> Option<GoldenKind> {
        let has = |n: &str| self.tensors.contains_key(n);
        if has("out_rgb") && has("means") {
            Some(GoldenKind::Raster)
        } else if has("gcfm_loss") || has("vgg_relu3_of_render_rgb") {
            Some(GoldenKind::Losses)
        } else if has("content_pixels") && has("A") {
            Some(GoldenKind::Color)
        } else if has("out_predicted_depth") && has("input_pixel_values") {
            Some(GoldenKind::Depth)
        } else {
            None
        }
    }
}

/// The kinds of golden file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GoldenKind {
    /// Rasterizer forward and gradients (`raster_*`).
    Raster,
    /// VGG features and the losses (`losses_*`).
    Losses,
    /// Linear colour transfer (`color_*`).
    Color,
    /// A Depth Anything V2 forward pass (`depth/depth_*`).
    Depth,
}
