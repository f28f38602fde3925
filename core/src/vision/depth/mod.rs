//! Depth Anything V2, the monocular depth network GAST's reference uses for
//! the style image's geometry cue, run on the project's own CPU kernels.
//!
//! Without it the studio falls back to [`ReliefDepth`](super::relief_depth::ReliefDepth),
//! a relief read from the style's luminance detail: its outlines, not a
//! network's understanding of the scene. The network is read from
//! the published `transformers` checkpoints (`model.safetensors` and
//! `config.json`, found or fetched by [`resolve`]) with every size taken from
//! the config, so Small, Base and Large load through the same code.
//!
//! The pipeline is the reference's: resize keeping the aspect ratio so both
//! sides are multiples of 14 near 518 on the shorter one (bicubic with
//! antialiasing, as Pillow), ImageNet normalisation, the network
//! ([`vit`] then [`dpt`]), and the predicted relative inverse depth resized
//! back (bicubic) to the image. The result is a [`DepthImage`] with near =
//! larger, so it goes through the same min-max normalisation and
//! [`DepthPolarity`](super::style_depth::DepthPolarity) as a user's depth image.

mod config;
pub(crate) mod dpt;
pub(crate) mod ops;
mod profile;
pub mod resolve;
pub(crate) mod vit;
pub(crate) mod weights;

use std::path::{Path, PathBuf};

pub use config::{BackboneConfig, DepthConfig};
pub use profile::StageTimes;
pub use resolve::{DepthModelLocations, checkpoint_digest, resolve_depth_model};

use super::resize::{Unit, resize_bicubic, resize_bicubic_antialias};
use super::style_depth::{DepthImage, StyleDepthProvider};
use super::weights::WeightsError;
use profile::Clock;
use weights::Checkpoint;

/// Why the depth network could not be found, fetched or read.
#[derive(Debug, thiserror::Error)]
pub enum DepthModelError {
    /// Reading a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// `config.json` is unreadable or describes a network this code does not run.
    #[error("{path}: config: {detail}")]
    Config {
        /// The config file (or the checkpoint whose metadata holds it).
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// The weights file is not a safetensors file.
    #[error("{path}: expected {expected}, found {found}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What a valid file has.
        expected: String,
        /// What this file has.
        found: String,
    },
    /// A tensor the network needs is absent.
    #[error("{path}: tensor `{name}` is missing{}", if .nearby.is_empty() { String::new() } else { format!(" (the file has {} nearby)", .nearby.join(", ")) })]
    MissingTensor {
        /// The file.
        path: PathBuf,
        /// The `transformers` parameter name.
        name: String,
        /// Names in the file under the same parent, to spot a misnaming.
        nearby: Vec<String>,
    },
    /// A tensor's shape or element type disagrees with the config.
    #[error("{path}: tensor `{name}`: expected {expected}, found {found}")]
    BadTensor {
        /// The file.
        path: PathBuf,
        /// The `transformers` parameter name.
        name: String,
        /// What the config implies.
        expected: String,
        /// What the file holds.
        found: String,
    },
    /// The file ends before a tensor's data does.
    #[error(
        "{path}: tensor `{name}`: its data ends at byte {needed} but the file has {found} bytes (truncated download?)"
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The tensor whose bytes are missing.
        name: String,
        /// Bytes the tensor needs.
        needed: u64,
        /// Bytes the file has.
        found: u64,
    },
    /// No checkpoint in any of the places looked at.
    #[error("no Depth Anything V2 checkpoint found (looked at: {}); pass --depth-model or set GAST_DEPTH_MODEL to a folder with model.safetensors and config.json", .searched.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "))]
    NotFound {
        /// Every path that was tried.
        searched: Vec<PathBuf>,
    },
    /// Downloading failed (network, HTTP status, or server unreachable).
    #[error(
        "downloading {url} failed: {detail}; to install the depth model by hand, put model.safetensors and config.json of \
         depth-anything/Depth-Anything-V2-Small-hf in ~/.cache/gast/depth-anything-v2-small/ or point GAST_DEPTH_MODEL at them"
    )]
    Download {
        /// The address.
        url: String,
        /// What went wrong.
        detail: String,
    },
    /// No checkpoint anywhere, a damaged download, or a cache that cannot be written.
    #[error("depth model: {0}")]
    Weights(#[from] WeightsError),
}

/// A loaded Depth Anything V2 network.
pub struct DepthAnything {
    config: DepthConfig,
    vit: vit::Vit,
    dpt: dpt::Dpt,
}

/// The shorter side the reference pipeline brings images to.
pub const INPUT_SIZE: usize = 518;

impl DepthAnything {
    /// Loads `model.safetensors` with its `config.json` text (`config_path` is
    /// only for messages).
    pub fn load(weights: &Path, config_json: &str, config_path: &Path) -> Result<Self, DepthModelError> {
        let config = DepthConfig::from_json(config_json)
            .map_err(|detail| DepthModelError::Config { path: config_path.to_path_buf(), detail })?;
        let ck = Checkpoint::read(weights)?;
        Self::from_checkpoint(&ck, config)
    }

    /// Loads a checkpoint folder (`model.safetensors` + `config.json`), or a
    /// `.safetensors` file with `config.json` beside it or in its metadata.
    pub fn load_path(path: &Path) -> Result<Self, DepthModelError> {
        let weights = if path.is_dir() { path.join("model.safetensors") } else { path.to_path_buf() };
        let config_path = weights.with_file_name("config.json");
        if config_path.is_file() {
            let text = std::fs::read_to_string(&config_path)
                .map_err(|source| DepthModelError::Io { path: config_path.clone(), source })?;
            return Self::load(&weights, &text, &config_path);
        }
        Self::load_with_metadata_config(&weights)
    }

    /// Loads a single safetensors file whose metadata entry `config` holds the
    /// config (the golden file's layout).
    pub fn load_with_metadata_config(weights: &Path) -> Result<Self, DepthModelError> {
        let ck = Checkpoint::read(weights)?;
        let Some(text) = ck.metadata.get("config") else {
            return Err(DepthModelError::Config {
                path: weights.to_path_buf(),
                detail: "expected config.json beside the weights or a `config` metadata entry, found neither".into(),
            });
        };
        let config = DepthConfig::from_json(text)
            .map_err(|detail| DepthModelError::Config { path: weights.to_path_buf(), detail })?;
        Self::from_checkpoint(&ck, config)
    }

    /// A network of `config`'s sizes with pseudo-random weights: for timing
    /// the real architecture where the checkpoint is not at hand.
    pub fn random(config: DepthConfig, seed: u64) -> Result<Self, DepthModelError> {
        Self::from_checkpoint(&Checkpoint::random(seed), config)
    }

    fn from_checkpoint(ck: &Checkpoint, config: DepthConfig) -> Result<Self, DepthModelError> {
        let vit = vit::Vit::load(ck, &config)?;
        let dpt = dpt::Dpt::load(ck, &config)?;
        Ok(Self { config, vit, dpt })
    }

    /// The config the network was built from.
    pub fn config(&self) -> &DepthConfig {
        &self.config
    }

    /// The backbone and the neck with head, for the GPU engine to upload.
    pub(crate) fn parts(&self) -> (&vit::Vit, &dpt::Dpt) {
        (&self.vit, &self.dpt)
    }

    /// The backbone and the neck with head, for tests to reshape a random network.
    #[cfg(test)]
    pub(crate) fn parts_mut(&mut self) -> (&mut vit::Vit, &mut dpt::Dpt) {
        (&mut self.vit, &mut self.dpt)
    }

    /// The network on a normalised CHW image (`3 × h × w`, sides multiples of
    /// the patch size): the predicted depth, `h × w`.
    pub fn forward(&self, pixels: &[f32], h: usize, w: usize) -> Vec<f32> {
        self.forward_clocked(pixels, h, w, &mut Clock::new(None))
    }

    /// [`forward`](Self::forward), also returning the wall time of each stage.
    pub fn forward_timed(&self, pixels: &[f32], h: usize, w: usize) -> (Vec<f32>, StageTimes) {
        let mut times = StageTimes::default();
        let depth = self.forward_clocked(pixels, h, w, &mut Clock::new(Some(&mut times)));
        (depth, times)
    }

    fn forward_clocked(&self, pixels: &[f32], h: usize, w: usize, clock: &mut Clock) -> Vec<f32> {
        let p = self.config.patch_size;
        assert!(
            h.is_multiple_of(p) && w.is_multiple_of(p) && pixels.len() == 3 * h * w,
            "DepthAnything::forward: bad input size"
        );
        let stages = self.vit.forward(pixels, h, w, clock);
        self.dpt.forward(&stages, h / p, w / p, clock)
    }

    /// Relative inverse depth of an RGB image (HWC, `f32` in [0, 1] or 8-bit,
    /// [`Unit`], `h × w`) at its own size, through the reference's pre- and
    /// post-processing.
    pub fn estimate_rgb<T: Unit>(&self, rgb: &[T], h: usize, w: usize) -> Vec<f32> {
        let d = self.depth_image(rgb, h, w);
        resize_bicubic(&d.values, d.height, d.width, 1, h, w)
    }

    /// The image resized to `ih × iw` (bicubic with antialiasing) and
    /// ImageNet-normalised, as CHW.
    pub(crate) fn preprocess<T: Unit>(&self, rgb: &[T], h: usize, w: usize, ih: usize, iw: usize) -> Vec<f32> {
        const MEAN: [f32; 3] = [0.485, 0.456, 0.406];
        const STD: [f32; 3] = [0.229, 0.224, 0.225];
        let resized = resize_bicubic_antialias(rgb, h, w, 3, ih, iw);
        let mut chw = vec![0f32; 3 * ih * iw];
        for (i, px) in resized.chunks_exact(3).enumerate() {
            for c in 0..3 {
                chw[c * ih * iw + i] = (px[c] - MEAN[c]) / STD[c];
            }
        }
        chw
    }

    /// The estimate as a depth image (near = larger) at the network's input
    /// size, to compute once per style: [`DepthImage`] resizes it to every
    /// texture scale the style is used at, and polarity applies afterwards.
    pub fn depth_image<T: Unit>(&self, rgb: &[T], h: usize, w: usize) -> DepthImage {
        let (ih, iw) = input_size(h, w, INPUT_SIZE, self.config.patch_size);
        let values = self.forward(&self.preprocess(rgb, h, w, ih, iw), ih, iw);
        DepthImage { values, height: ih, width: iw, near_is_larger: true }
    }
}

impl StyleDepthProvider for DepthAnything {
    fn estimate(&self, rgb: &[f32], h: usize, w: usize) -> Vec<f32> {
        self.estimate_rgb(rgb, h, w)
    }
}

/// The network's input size for an `h × w` image, as `transformers`' DPT
/// image processor computes it (`keep_aspect_ratio`, `ensure_multiple_of`):
/// of the two scales that bring a side to `target`, the one closer to 1 is
/// used for both, and each side is rounded to the nearest multiple of `multiple`.
pub fn input_size(h: usize, w: usize, target: usize, multiple: usize) -> (usize, usize) {
    let (sh, sw) = (target as f64 / h as f64, target as f64 / w as f64);
    let s = if (1.0 - sw).abs() < (1.0 - sh).abs() { sw } else { sh };
    let snap = |v: f64| {
        // Python's round: halves to even.
        let m = ((v / multiple as f64).round_ties_even() as usize) * multiple;
        m.max(multiple)
    };
    (snap(s * h as f64), snap(s * w as f64))
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
