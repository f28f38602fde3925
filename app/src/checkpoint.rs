//! Checkpoints of long runs (`gast fit`, `gast stylize`, a studio run): the
//! scene as it stands, written now and then as an INRIA `.ply` with a record
//! (`.json`) of the run's settings and progress, and the optimiser's state
//! where the run keeps one, so that a run killed, crashed or cut off loses at
//! most the interval and goes on from it (`--resume`, the studio's "Go on");
//! removed once the output is written. The command line keeps its checkpoint
//! beside the output, the studio in the user's cache (`studio::recovery`).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;

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
fn write_scene(path: &Path, scene: &gast_core::Gaussians) -> anyhow::Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        gast_core::io::create_folder(parent)
            .with_context(|| format!("could not create the checkpoint's folder {}", parent.display()))?;
    }
    gast_core::scene::save(path, scene, &Default::default())
        .with_context(|| format!("could not write the checkpoint {}", path.display()))
}

/// The record beside a checkpoint's scene (`fern.checkpoint.json`).
pub fn record_path(checkpoint: &Path) -> PathBuf {
    checkpoint.with_extension("json")
}

/// The optimiser's state beside a checkpoint's scene
/// (`stylized.checkpoint.adam.safetensors`), where the run keeps one.
pub fn moments_path(checkpoint: &Path) -> PathBuf {
    checkpoint.with_extension("adam.safetensors")
}

/// What writes a run's optimiser state (a safetensors file) into a file.
pub type StateWrite<'a> = &'a dyn Fn(&mut dyn std::io::Write) -> std::io::Result<()>;

/// Writes the checkpoint `path`: the scene, the optimiser's state
/// (`moments` writes it, straight into its file) where given, then its `record`
/// (last: a record always names a scene and state written whole; older ones
/// are removed first, so that they do not pair with the new scene if this
/// write stops half-way).
pub fn write_with_record(
    path: &Path,
    scene: &gast_core::Gaussians,
    moments: Option<StateWrite<'_>>,
    record: &impl serde::Serialize,
) -> anyhow::Result<()> {
    let record_path = record_path(path);
    for old in [&record_path, &moments_path(path)] {
        if old.is_file() {
            std::fs::remove_file(old).with_context(|| format!("could not replace {}", old.display()))?;
        }
    }
    write_scene(path, scene)?;
    if let Some(write) = moments {
        let at = moments_path(path);
        gast_core::io::atomic_write(&at, |w| write(w))
            .with_context(|| format!("could not write the optimiser's state {}", at.display()))?;
    }
    let json = serde_json::to_string_pretty(record)?;
    gast_core::io::write_bytes(&record_path, json.as_bytes())
        .with_context(|| format!("could not write the checkpoint's record {}", record_path.display()))
}

/// Writes the checkpoint `path` of a stylization's `session` with its
/// `record`: the scene it holds (`result`, its [`gast_core::session::Session::result`]
/// now) and its optimiser's state. `Ok(Some(why))`: written without the
/// state, which could not be read.
pub fn write_session(
    path: &Path,
    session: &gast_core::session::Session,
    result: &gast_core::Gaussians,
    record: &impl serde::Serialize,
) -> anyhow::Result<Option<String>> {
    let moments = session.optimiser_state();
    let write = moments.as_ref().ok().map(|m| move |w: &mut dyn std::io::Write| m.write_to(w));
    write_with_record(path, result, write.as_ref().map(|f| f as StateWrite<'_>), record)?;
    Ok(moments.err())
}

/// The optimiser's state beside the checkpoint `path` at `step`, and what
/// to say of it: kept, or why the moments start afresh (none written, or
/// unreadable: a resume still goes on, as from a checkpoint without one).
pub fn read_moments(path: &Path, step: u32) -> (Option<gast_core::session::OptimiserState>, String) {
    let at = moments_path(path);
    let read = std::fs::read(&at)
        .map_err(|e| e.to_string())
        .and_then(|b| gast_core::session::OptimiserState::from_safetensors(&b));
    match read {
        Ok(m) if m.step == step => (Some(m), "with the optimiser's moments".into()),
        Ok(m) => (None, format!("the optimiser's moments start afresh: {} holds step {}'s", at.display(), m.step)),
        Err(_) if !at.exists() => (None, format!("the optimiser's moments start afresh: no {}", at.display())),
        Err(e) => (None, format!("the optimiser's moments start afresh: {} is unreadable ({e})", at.display())),
    }
}

/// Removes the checkpoint `path`, its record and its optimiser's state,
/// where they are (a warning for what cannot be removed).
pub fn remove(path: &Path) {
    for path in [&record_path(path), &moments_path(path), path] {
        if path.is_file()
            && let Err(e) = std::fs::remove_file(path)
        {
            eprintln!("warning: could not remove the checkpoint {}: {e}", path.display());
        }
    }
}

/// Reads the record of the checkpoint `path`, which `--resume` asked for on
/// behalf of the output `out` (`what`: "fit", "stylization"); an error that
/// says what is missing or unreadable.
pub fn read_record<R: serde::de::DeserializeOwned>(out: &Path, path: &Path, what: &str) -> anyhow::Result<R> {
    let record_path = record_path(path);
    anyhow::ensure!(
        path.is_file() && record_path.is_file(),
        "{}: expected the checkpoint of an earlier {what} to --resume from ({} with its record {}, written every \
         --checkpoint-every seconds and at Ctrl-C), found {}",
        out.display(),
        path.display(),
        record_path.display(),
        if path.is_file() { "the scene without its record" } else { "none" }
    );
    let text =
        std::fs::read_to_string(&record_path).with_context(|| format!("could not read {}", record_path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: expected a {what} checkpoint's record (JSON)", record_path.display()))
}

/// Refuses to go on from the checkpoint `path` whose record `was` differs
/// from this run's `now`, naming each setting that differs.
pub fn refuse_other_settings<R: serde::Serialize + PartialEq>(path: &Path, was: &R, now: &R) -> anyhow::Result<()> {
    if was == now {
        return Ok(());
    }
    let (was, is) = (serde_json::to_value(was)?, serde_json::to_value(now)?);
    anyhow::bail!(
        "{}: the checkpoint was made with other settings ({}); give the same flags to --resume, or leave --resume \
         out to start afresh (the new run replaces the checkpoint)",
        path.display(),
        differing_keys(&was, &is, "").join(", ")
    )
}

/// `key: was → is` for every leaf where two JSON objects differ.
fn differing_keys(was: &serde_json::Value, is: &serde_json::Value, prefix: &str) -> Vec<String> {
    match (was, is) {
        (serde_json::Value::Object(a), serde_json::Value::Object(b)) => a
            .iter()
            .flat_map(|(k, v)| {
                let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                differing_keys(v, b.get(k).unwrap_or(&serde_json::Value::Null), &key)
            })
            .collect(),
        _ if was == is => Vec::new(),
        _ => vec![format!("{prefix}: {was} then, {is} now")],
    }
}

/// Says so when a checkpoint of an earlier run (`what`) lies at `path`: this
/// run replaces it at its first checkpoint, and `--resume` would go on from it.
pub fn warn_of_a_checkpoint(path: &Path, what: &str) {
    if path.is_file() {
        eprintln!(
            "warning: {} holds a checkpoint of an earlier {what}; this {what} replaces it at its first checkpoint \
             and removes it when done (the same command with --resume goes on from it instead)",
            path.display()
        );
    }
}

/// `N views, <hash>`: FNV-1a over the cameras' every field, which a record
/// keeps so that a run goes on only over the views it was made with.
pub fn cameras_fingerprint(cameras: &[gast_core::Camera]) -> String {
    let text = format!("{cameras:?}");
    format!("{} views, {:016x}", cameras.len(), fnv1a(text.bytes().map(u64::from)))
}

/// `N bytes, <hash>`: FNV-1a over a file's bytes (a style image's, read
/// where the run or the studio reads the image), which a record keeps so
/// that a run goes on only with the image it was made with, not another
/// written over it under the same name; `None` when the file cannot be read
/// (the run's own read says why).
pub fn file_fingerprint(path: &Path) -> Option<String> {
    let bytes = std::fs::read(path).ok()?;
    Some(format!("{} bytes, {:016x}", bytes.len(), fnv1a(bytes.iter().map(|&b| u64::from(b)))))
}

/// FNV-1a over `words` (over bytes, each a word below 256, it is the usual
/// byte-wise FNV-1a): the hashes a record keeps of views, scenes and styles.
pub fn fnv1a(words: impl Iterator<Item = u64>) -> u64 {
    words.fold(0xcbf2_9ce4_8422_2325u64, |h, w| (h ^ w).wrapping_mul(0x0100_0000_01b3))
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

    #[test]
    fn the_fingerprint_tells_other_views_apart() {
        let cams = gast_core::camera::orbit_cameras(
            &[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]],
            &gast_core::camera::OrbitOptions { count: 4, width: 64, height: 48, ..Default::default() },
        );
        let a = cameras_fingerprint(&cams);
        assert!(a.starts_with("4 views, "), "{a}");
        assert_eq!(a, cameras_fingerprint(&cams.clone()));
        let wider: Vec<_> = cams.iter().map(|c| c.with_longer_side(128)).collect();
        assert_ne!(a, cameras_fingerprint(&wider));
        assert_ne!(a, cameras_fingerprint(&cams[..3]));
    }
}
