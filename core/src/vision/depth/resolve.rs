//! Finding a Depth Anything V2 checkpoint on this machine, or fetching the
//! Small one once, the way the VGG weights are found ([`super::super::download`]).
//!
//! Order: a path the user gave (`--depth-model` or `$GAST_DEPTH_MODEL`: a
//! folder with `model.safetensors` and `config.json`, or the weights file);
//! our cache (`$XDG_CACHE_HOME/gast/depth-anything-v2-small/`); the Hugging
//! Face hub cache (`$HF_HOME/hub`, else `~/.cache/huggingface/hub`,
//! `models--depth-anything--Depth-Anything-V2-{Small,Base,Large}-hf/snapshots/*/`),
//! where anyone who has run the model with `transformers` already has it; and
//! only then a download of the Small model's two files into our cache, with
//! progress, resume, the sha256 the hub announces and an atomic rename.

use std::path::{Path, PathBuf};

use super::DepthModelError;
use crate::vision::download::download_verified;
use crate::vision::weights::WeightsError;

/// Where the Small model's files are published.
pub const DEFAULT_BASE_URL: &str = "https://huggingface.co/depth-anything/Depth-Anything-V2-Small-hf/resolve/main";

/// The hub repositories looked for in the Hugging Face cache, smallest first.
const HUB_REPOS: [&str; 3] = [
    "models--depth-anything--Depth-Anything-V2-Small-hf",
    "models--depth-anything--Depth-Anything-V2-Base-hf",
    "models--depth-anything--Depth-Anything-V2-Large-hf",
];

/// Our cache folder's name for the downloaded Small model.
const CACHE_FOLDER: &str = "depth-anything-v2-small";

/// Where to look for the depth network and where to fetch it from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DepthModelLocations {
    /// A folder or file the user named; when set, nothing else is tried.
    pub explicit: Option<PathBuf>,
    /// Our cache folder (`…/gast`); the model goes in a sub-folder.
    pub cache_dir: Option<PathBuf>,
    /// The Hugging Face hub cache (`…/huggingface/hub`), read only.
    pub hub_dir: Option<PathBuf>,
    /// Folder address the two files are downloaded from (`{base}/model.safetensors`, `{base}/config.json`).
    pub base_url: String,
}

impl DepthModelLocations {
    /// The standard locations: `explicit` or `$GAST_DEPTH_MODEL`, the user
    /// cache, the hub cache, and `$GAST_DEPTH_MODEL_URL` or [`DEFAULT_BASE_URL`].
    pub fn from_env(explicit: Option<&Path>) -> Self {
        let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
        let home = var("HOME");
        let cache_home = var("XDG_CACHE_HOME").or_else(|| home.as_ref().map(|h| h.join(".cache")));
        Self {
            explicit: explicit.map(Path::to_path_buf).or_else(|| var("GAST_DEPTH_MODEL")),
            cache_dir: cache_home.as_ref().map(|c| c.join("gast")),
            hub_dir: var("HF_HUB_CACHE")
                .or_else(|| var("HF_HOME").map(|h| h.join("hub")))
                .or_else(|| cache_home.as_ref().map(|c| c.join("huggingface").join("hub"))),
            base_url: std::env::var("GAST_DEPTH_MODEL_URL")
                .ok()
                .filter(|u| !u.is_empty())
                .unwrap_or_else(|| DEFAULT_BASE_URL.into()),
        }
    }

    /// The first checkpoint already on disk (a folder with both files, or
    /// the explicit file), without downloading.
    pub fn find(&self) -> Result<PathBuf, DepthModelError> {
        let complete = |d: &Path| d.join("model.safetensors").is_file() && d.join("config.json").is_file();
        if let Some(p) = &self.explicit {
            return if p.is_file() || (p.is_dir() && complete(p)) {
                Ok(p.clone())
            } else {
                Err(DepthModelError::NotFound { searched: vec![p.clone()] })
            };
        }
        let mut searched = Vec::new();
        if let Some(c) = &self.cache_dir {
            let d = c.join(CACHE_FOLDER);
            if complete(&d) {
                return Ok(d);
            }
            searched.push(d);
        }
        if let Some(hub) = &self.hub_dir {
            for repo in HUB_REPOS {
                let snaps = hub.join(repo).join("snapshots");
                let mut dirs: Vec<PathBuf> = std::fs::read_dir(&snaps)
                    .map(|it| it.filter_map(|e| e.ok().map(|e| e.path())).collect())
                    .unwrap_or_default();
                dirs.sort();
                if let Some(d) = dirs.into_iter().find(|d| complete(d)) {
                    return Ok(d);
                }
                searched.push(snaps.join("*"));
            }
        }
        Err(DepthModelError::NotFound { searched })
    }

    /// [`DepthModelLocations::find`], else download the Small model into the
    /// cache, reporting `(bytes so far, total if known)` of the weights file.
    pub fn resolve(&self, progress: &mut dyn FnMut(u64, Option<u64>)) -> Result<PathBuf, DepthModelError> {
        match self.find() {
            Ok(p) => Ok(p),
            Err(e) if self.explicit.is_some() => Err(e),
            Err(e) => {
                let Some(cache) = &self.cache_dir else { return Err(e) };
                let dir = cache.join(CACHE_FOLDER);
                let base = self.base_url.trim_end_matches('/');
                let fetch = |name: &str, progress: &mut dyn FnMut(u64, Option<u64>)| {
                    download_verified(&format!("{base}/{name}"), &dir, None, progress).map_err(|e| match e {
                        WeightsError::Download { url, detail } => DepthModelError::Download { url, detail },
                        other => other.into(),
                    })
                };
                fetch("config.json", &mut |_, _| {})?;
                fetch("model.safetensors", progress)?;
                Ok(dir)
            }
        }
    }
}

/// Finds the depth network, downloading the Small model once if needed.
pub fn resolve_depth_model(
    explicit: Option<&Path>,
    progress: &mut dyn FnMut(u64, Option<u64>),
) -> Result<PathBuf, DepthModelError> {
    DepthModelLocations::from_env(explicit).resolve(progress)
}

/// The identity of the checkpoint at `path` (a folder or a `.safetensors`
/// file, as [`DepthAnything::load_path`](super::DepthAnything::load_path)
/// takes): the SHA-256 of its weights file and of the `config.json` beside
/// it, if any. Cached results computed with the network are keyed by it.
pub fn checkpoint_digest(path: &Path) -> Result<String, DepthModelError> {
    use sha2::{Digest, Sha256};
    use std::io::Read;
    let weights = if path.is_dir() { path.join("model.safetensors") } else { path.to_path_buf() };
    let mut h = Sha256::new();
    for file in [weights.clone(), weights.with_file_name("config.json")] {
        if file != weights && !file.is_file() {
            continue;
        }
        let io = |source| DepthModelError::Io { path: file.clone(), source };
        let mut f = std::fs::File::open(&file).map_err(io)?;
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = f.read(&mut buf).map_err(io)?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
        h.update(b"\n--\n");
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}
