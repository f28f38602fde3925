//! VGG convolution weights up to conv3_3, from the files people actually have.
//!
//! The style losses need only `features.0` … `features.14` of torchvision's
//! VGG (conv1_1 … conv3_3, 1.7 M parameters), so that is all this loads, and
//! from two kinds of file: safetensors with torchvision names (what the
//! project's test data is), and PyTorch `.pth` checkpoints (what torchvision
//! downloads into the hub cache, so a user who has run torchvision already has
//! one). VGG16 and VGG19 share their layer indices up to relu3_3, so either
//! network's file works.

use std::path::Path;

use safetensors::{Dtype, SafeTensors};

use super::pth;
pub(crate) use super::weights_file::RawTensor;
pub use super::weights_file::{HOW_TO_GET, WeightsError};

/// torchvision `features` indices of the seven convolutions conv1_1 … conv3_3.
pub const CONV_INDICES: [usize; 7] = [0, 2, 5, 7, 10, 12, 14];

/// `(out_channels, in_channels)` of the seven convolutions, all 3×3.
pub const CONV_SHAPES: [(usize, usize); 7] =
    [(64, 3), (64, 64), (128, 64), (128, 128), (256, 128), (256, 256), (256, 256)];

/// One 3×3 convolution: `weight` is OIHW (`c_out × c_in × 3 × 3`), `bias` is `c_out`.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvWeights {
    /// Output channels.
    pub c_out: usize,
    /// Input channels.
    pub c_in: usize,
    /// `c_out · c_in · 9` values, OIHW.
    pub weight: Vec<f32>,
    /// `c_out` values.
    pub bias: Vec<f32>,
}

/// The seven convolutions conv1_1 … conv3_3 of torchvision's VGG16/VGG19.
#[derive(Clone, Debug, PartialEq)]
pub struct VggWeights {
    /// In network order, `features.{0,2,5,7,10,12,14}`.
    pub convs: Vec<ConvWeights>,
}

/// The parameter names this module reads, in network order: weight then bias.
pub(crate) fn needed_names() -> Vec<String> {
    CONV_INDICES.iter().flat_map(|i| [format!("features.{i}.weight"), format!("features.{i}.bias")]).collect()
}

impl VggWeights {
    /// Loads from a `.safetensors` or PyTorch `.pth` file (zip or legacy format),
    /// recognised by content, not by name.
    pub fn load(path: &Path) -> Result<Self, WeightsError> {
        let mut magic = [0u8; 8];
        {
            use std::io::Read;
            let mut f = std::fs::File::open(path).map_err(|e| WeightsError::io(path, e))?;
            let n = f.read(&mut magic).map_err(|e| WeightsError::io(path, e))?;
            if n < 8 {
                return Err(WeightsError::format(path, "a weights file", format!("{n} bytes")));
            }
        }
        let tensors = if magic.starts_with(b"PK\x03\x04") || magic[0] == 0x80 {
            pth::read_tensors(path, &needed_names())?
        } else {
            read_safetensors(path)?
        };
        Self::from_raw(path, tensors)
    }

    /// Checks names, shapes and types and assembles the network.
    pub(crate) fn from_raw(
        path: &Path,
        mut tensors: std::collections::HashMap<String, RawTensor>,
    ) -> Result<Self, WeightsError> {
        let mut convs = Vec::with_capacity(CONV_INDICES.len());
        for (&idx, &(c_out, c_in)) in CONV_INDICES.iter().zip(&CONV_SHAPES) {
            let mut take = |suffix: &str, shape: Vec<usize>| -> Result<Vec<f32>, WeightsError> {
                let name = format!("features.{idx}.{suffix}");
                let t = tensors
                    .remove(&name)
                    .ok_or_else(|| WeightsError::MissingTensor { path: path.to_path_buf(), name: name.clone() })?;
                let bad = |found: String| WeightsError::BadTensor {
                    path: path.to_path_buf(),
                    name: name.clone(),
                    expected: format!("float32 of shape {shape:?}"),
                    found,
                };
                if t.shape != shape {
                    return Err(bad(format!("shape {:?}", t.shape)));
                }
                t.data.ok_or_else(|| bad(format!("element type {}", t.dtype)))
            };
            let weight = take("weight", vec![c_out, c_in, 3, 3])?;
            let bias = take("bias", vec![c_out])?;
            convs.push(ConvWeights { c_out, c_in, weight, bias });
        }
        Ok(Self { convs })
    }

    /// Number of parameters (1,735,488 for conv1_1 … conv3_3).
    pub fn parameter_count(&self) -> usize {
        self.convs.iter().map(|c| c.weight.len() + c.bias.len()).sum()
    }
}

fn read_safetensors(path: &Path) -> Result<std::collections::HashMap<String, RawTensor>, WeightsError> {
    let bytes = std::fs::read(path).map_err(|e| WeightsError::io(path, e))?;
    let st = SafeTensors::deserialize(&bytes)
        .map_err(|e| WeightsError::format(path, "a safetensors or PyTorch .pth file", format!("neither ({e})")))?;
    let mut out = std::collections::HashMap::new();
    for name in needed_names() {
        let Ok(view) = st.tensor(&name) else { continue };
        let data = match view.dtype() {
            Dtype::F32 => {
                Some(view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
            }
            _ => None,
        };
        out.insert(name, RawTensor { shape: view.shape().to_vec(), dtype: format!("{:?}", view.dtype()), data });
    }
    Ok(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use std::path::PathBuf;

    use super::*;

    /// A file under `$GAST_SHARED` (else `../shared` beside the workspace), or
    /// `None` after a loud message when it is absent.
    pub(crate) fn shared(rel: &str) -> Option<PathBuf> {
        let base = std::env::var_os("GAST_SHARED")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
        let p = base.join(rel);
        if p.exists() {
            Some(p)
        } else {
            eprintln!("\n!!!!!!!! SKIPPED: shared data file {} is absent !!!!!!!!\n", p.display());
            None
        }
    }

    #[test]
    fn loads_shared_safetensors() -> Result<(), WeightsError> {
        let Some(p) = shared("data/weights/vgg19-conv3.safetensors") else { return Ok(()) };
        let w = VggWeights::load(&p)?;
        assert_eq!(w.convs.len(), 7);
        assert_eq!(w.parameter_count(), 1_735_488);
        Ok(())
    }

    #[test]
    fn garbage_is_a_format_error_naming_the_file() {
        let dir = std::env::temp_dir().join(format!("gast-weights-garbage-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let p = dir.join("junk.bin");
        let _ = std::fs::write(&p, b"this is not a weights file at all");
        let err = VggWeights::load(&p).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains("junk.bin") && err.contains("expected"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
