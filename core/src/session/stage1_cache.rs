//! The on-disk cache of Stage-1 results that take seconds to compute and
//! depend only on their inputs: today, the style's learned depth.
//!
//! Depth Anything V2 costs seconds per style on a CPU, and the same style is
//! stylized again and again (other scenes, other settings, the studio and the
//! CLI), so its depth is computed once and kept in one folder,
//! `$XDG_CACHE_HOME/gast/stage1/` (else `~/.cache/gast/stage1/`), one file
//! per entry named by the hash of everything the value depends on. A file is
//! written to a temporary name and renamed, so a reader never sees half of
//! one; one that is damaged anyway (a full disk, an edit) fails its checksum
//! and is recomputed with a warning.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::style_image::StyleImage;
use crate::vision::style_depth::DepthImage;

/// The first bytes of a cached depth file (format version 1).
const DEPTH_MAGIC: &[u8; 8] = b"GASTDEP1";
/// Magic, height, width, polarity flag with 3 bytes of padding.
const DEPTH_HEADER: usize = 8 + 4 + 4 + 4;
/// The SHA-256 of everything before it closes the file.
const DIGEST: usize = 32;

/// A folder of cached Stage-1 results.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stage1Cache {
    dir: PathBuf,
}

/// How a cached lookup was answered.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CacheOutcome {
    /// Read from this file.
    Hit(PathBuf),
    /// Computed (and written, unless a warning says otherwise).
    Computed,
}

impl Stage1Cache {
    /// A cache in `dir` (created when first written).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The user's cache: `$XDG_CACHE_HOME/gast/stage1`, else `$HOME/.cache/gast/stage1`;
    /// `None` when neither variable is set.
    pub fn from_env() -> Option<Self> {
        let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
        let base = var("XDG_CACHE_HOME").or_else(|| var("HOME").map(|h| h.join(".cache")))?;
        Some(Self::new(base.join("gast").join("stage1")))
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The file of the depth entry `key`.
    pub fn depth_path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("depth-{key}.bin"))
    }

    /// The cached depth under `key`: `Ok(None)` when there is none, `Err`
    /// (saying what is wrong with which file) when the file is unreadable or damaged.
    pub fn read_depth(&self, key: &str) -> Result<Option<DepthImage>, String> {
        let path = self.depth_path(key);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        };
        decode_depth(&bytes).map(Some).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Writes `depth` under `key` (temporary file, then rename); returns the file.
    pub fn write_depth(&self, key: &str, depth: &DepthImage) -> Result<PathBuf, String> {
        let path = self.depth_path(key);
        let fail = |e: std::io::Error| format!("{}: {e}", path.display());
        std::fs::create_dir_all(&self.dir).map_err(|e| format!("{}: {e}", self.dir.display()))?;
        let tmp = self.dir.join(format!(".depth-{key}.{}.tmp", std::process::id()));
        std::fs::write(&tmp, encode_depth(depth)).map_err(fail)?;
        std::fs::rename(&tmp, &path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            fail(e)
        })?;
        Ok(path)
    }

    /// The depth under `key` if the cache has a sound copy, else `compute`'s,
    /// which is then written. A damaged file or a failed write is not an
    /// error: the value is computed (or just not kept) and `warnings` says so.
    pub fn depth_or_compute<E>(
        &self,
        key: &str,
        compute: impl FnOnce() -> Result<DepthImage, E>,
        warnings: &mut Vec<String>,
    ) -> Result<(DepthImage, CacheOutcome), E> {
        match self.read_depth(key) {
            Ok(Some(depth)) => return Ok((depth, CacheOutcome::Hit(self.depth_path(key)))),
            Ok(None) => {}
            Err(e) => warnings.push(format!("ignoring the cached style depth ({e}); computing it again")),
        }
        let depth = compute()?;
        if let Err(e) = self.write_depth(key, &depth) {
            warnings.push(format!("could not cache the style depth ({e})"));
        }
        Ok((depth, CacheOutcome::Computed))
    }
}

/// The key of a style's learned depth: a hash of the style's pixels and
/// size, the network's identity (e.g. its checkpoint's digest) and the side
/// the network's input is resized to (which, with the checkpoint's patch
/// size, fixes the input size).
pub fn depth_key(style: &StyleImage, model_id: &str, input_side: usize) -> String {
    let mut h = Sha256::new();
    h.update(b"gast stage1 learned depth v1\n");
    h.update((style.width as u64).to_le_bytes());
    h.update((style.height as u64).to_le_bytes());
    h.update(&style.rgb);
    h.update((model_id.len() as u64).to_le_bytes());
    h.update(model_id.as_bytes());
    h.update((input_side as u64).to_le_bytes());
    hex(&h.finalize())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn encode_depth(d: &DepthImage) -> Vec<u8> {
    let mut out = Vec::with_capacity(DEPTH_HEADER + 4 * d.values.len() + DIGEST);
    out.extend_from_slice(DEPTH_MAGIC);
    out.extend_from_slice(&(d.height as u32).to_le_bytes());
    out.extend_from_slice(&(d.width as u32).to_le_bytes());
    out.extend_from_slice(&[u8::from(d.near_is_larger), 0, 0, 0]);
    for v in &d.values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let digest = Sha256::digest(&out);
    out.extend_from_slice(&digest);
    out
}

fn decode_depth(bytes: &[u8]) -> Result<DepthImage, String> {
    if bytes.len() < DEPTH_HEADER + DIGEST || &bytes[..8] != DEPTH_MAGIC {
        return Err(format!(
            "expected a gast depth cache file (starting with {:?}, at least {} bytes), found {} bytes starting with {:?}",
            String::from_utf8_lossy(DEPTH_MAGIC),
            DEPTH_HEADER + DIGEST,
            bytes.len(),
            String::from_utf8_lossy(&bytes[..bytes.len().min(8)])
        ));
    }
    let u32_at = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]) as usize;
    let (height, width) = (u32_at(8), u32_at(12));
    let expected =
        height.checked_mul(width).and_then(|n| n.checked_mul(4)).and_then(|n| n.checked_add(DEPTH_HEADER + DIGEST));
    if expected != Some(bytes.len()) || height == 0 || width == 0 {
        return Err(format!(
            "expected {} bytes for a {width}×{height} depth map, found {} (truncated?)",
            expected.map_or_else(|| "an impossible number of".to_string(), |n| n.to_string()),
            bytes.len()
        ));
    }
    let (body, digest) = bytes.split_at(bytes.len() - DIGEST);
    if Sha256::digest(body).as_slice() != digest {
        return Err("checksum mismatch: expected the SHA-256 stored at its end, found other bytes".into());
    }
    let values: Vec<f32> =
        body[DEPTH_HEADER..].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    Ok(DepthImage { values, height, width, near_is_larger: bytes[16] != 0 })
}

#[cfg(test)]
#[path = "stage1_cache_tests.rs"]
mod tests;
