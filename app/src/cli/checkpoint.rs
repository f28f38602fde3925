//! Checkpoints of long runs (`gast fit`, `gast stylize`): the scene as it
//! stands, written now and then beside the output as an INRIA `.ply`, so that
//! a run killed, crashed or cut off loses at most the interval; removed once
//! the output is written.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Seconds between checkpoints by default: a long fit or stylization (hours
/// on a large capture) loses at most five minutes; a fern fit (about six)
/// writes one.
pub const DEFAULT_CHECKPOINT_S: u64 = 300;

/// The accepted `--checkpoint-every`: none, or up to a day.
pub const CHECKPOINT_SECONDS: std::ops::RangeInclusive<u64> = 0..=86_400;

/// Where a run writing the scene `out` keeps its checkpoint: beside it, the format's
/// suffix replaced by `.checkpoint.ply` (`fern.spz` → `fern.checkpoint.ply`,
/// a SOG folder `out/` → `out.checkpoint.ply`).
pub fn checkpoint_path(out: &Path) -> PathBuf {
    let folder =
        matches!(gast_core::scene::SceneFormat::from_output(out), Ok(gast_core::scene::SceneFormat::SogFolder(_)));
    let (dir, stem) = if folder && out.file_name().is_some_and(|n| n.eq_ignore_ascii_case("meta.json")) {
        let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        (dir.parent().map(Path::to_path_buf), dir.file_name().map(|n| n.to_string_lossy().into_owned()))
    } else {
        (out.parent().map(Path::to_path_buf), out.file_name().map(|n| n.to_string_lossy().into_owned()))
    };
    let mut stem = stem.unwrap_or_else(|| "scene".to_owned());
    if !folder {
        let lower = stem.to_lowercase();
        for suffix in [".compressed.ply", ".ply", ".spz", ".sog"] {
            if lower.ends_with(suffix) {
                stem.truncate(stem.len() - suffix.len());
                break;
            }
        }
    }
    dir.unwrap_or_default().join(format!("{stem}.checkpoint.ply"))
}

/// Writes `scene` to the checkpoint `path` (INRIA .ply, atomically), making
/// its folder first.
pub fn write_scene(path: &Path, scene: &gast_core::Gaussians) -> anyhow::Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        super::output_folder(parent, "--out")?;
    }
    anyhow::Context::with_context(gast_core::scene::save(path, scene, &Default::default()), || {
        format!("could not write the checkpoint {}", path.display())
    })
}

/// When the next checkpoint is due: every `every` seconds (0: never).
pub struct Due {
    every: Option<Duration>,
    last: Instant,
}

impl Due {
    /// From now on, every `seconds` (0: never).
    pub fn every(seconds: u64) -> Self {
        Self { every: (seconds > 0).then(|| Duration::from_secs(seconds)), last: Instant::now() }
    }

    /// Whether the interval has passed since the last [`Self::written`] (or the start).
    pub fn now(&self) -> bool {
        self.every.is_some_and(|e| self.last.elapsed() >= e)
    }

    /// A checkpoint was just written (or tried): the interval starts again.
    pub fn written(&mut self) {
        self.last = Instant::now();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_checkpoint_lies_beside_the_output_as_an_inria_ply() {
        for (out, checkpoint) in [
            ("fern.ply", "fern.checkpoint.ply"),
            ("runs/fern.compressed.ply", "runs/fern.checkpoint.ply"),
            ("runs/Fern.SPZ", "runs/Fern.checkpoint.ply"),
            ("fern.sog", "fern.checkpoint.ply"),
            ("runs/fern/", "runs/fern.checkpoint.ply"),
            ("runs/fern/meta.json", "runs/fern.checkpoint.ply"),
        ] {
            assert_eq!(checkpoint_path(Path::new(out)), Path::new(checkpoint), "{out}");
        }
    }
}
