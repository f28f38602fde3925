//! Writing a scene in any format the studio reads, chosen by the output's name.
//!
//! Artists share splats in the compressed formats (SuperSplat and PlayCanvas
//! want `.compressed.ply` or SOG, Niantic's viewers `.spz`), so every reader has
//! a writer beside it and [`save`] picks one from the name the user typed:
//! `*.compressed.ply`, `*.ply`, `*.spz`, `*.sog`, or a SOG folder (`…/meta.json`,
//! an existing folder, or a name ending in `/`). An unknown name is an error
//! that lists these. Every writer goes through a temporary sibling and a rename
//! (a SOG folder through a temporary folder), so a failed write leaves nothing
//! half-written, and the output's folder must already exist: a typo in the
//! folder is reported, not silently created.

use std::path::{Path, PathBuf};

use super::{Gaussians, SceneError, compressed_ply, ply, sog_write, spz, validate};

/// The formats [`save`] writes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// INRIA binary `.ply` (lossless).
    Ply,
    /// PlayCanvas compressed `.ply` (16 bytes a Gaussian plus 8-bit SH).
    CompressedPly,
    /// Niantic `.spz`: version 3 is one gzip stream, version 4 a header and zstd streams.
    Spz,
    /// PlayCanvas SOG as a folder (`meta.json` plus WebP textures); the path is the folder.
    SogFolder(PathBuf),
    /// PlayCanvas SOG as one zip bundle (`.sog`).
    SogBundle,
}

/// What the accepted output names are, for error messages and help texts.
pub const OUTPUT_NAMES: &str = "a name ending in .ply (INRIA), .compressed.ply (PlayCanvas), .spz (Niantic), \
     .sog (SOG bundle), or a SOG folder (…/meta.json, an existing folder, or a name ending in /)";

/// The format `path` asks for, checked before any long work: an existing
/// folder as a SOG output must hold a SOG scene or none of its files
/// (`sog_write::refuse_foreign_folder`).
pub fn check_output(path: &Path) -> Result<SceneFormat, SceneError> {
    let format = SceneFormat::from_output(path)?;
    if let SceneFormat::SogFolder(dir) = &format
        && dir.is_dir()
    {
        super::sog_write::refuse_foreign_folder(dir)?;
    }
    Ok(format)
}

impl SceneFormat {
    /// The format an output name asks for (see the module docs). An existing
    /// folder whose name ends as a file format's (`scene.ply/`) is an error
    /// unless the name ends in `/`: `gast convert a.spz out.ply` with a
    /// folder `out.ply` wrote a SOG scene into it.
    pub fn from_output(path: &Path) -> Result<Self, SceneError> {
        let name = path.file_name().map(|n| n.to_string_lossy().to_lowercase()).unwrap_or_default();
        let text = path.to_string_lossy();
        let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase());
        let by_name = if name.ends_with(".compressed.ply") {
            Some(Self::CompressedPly)
        } else {
            match ext.as_deref() {
                Some("ply") => Some(Self::Ply),
                Some("spz") => Some(Self::Spz),
                Some("sog") => Some(Self::SogBundle),
                _ => None,
            }
        };
        let trailing = text.ends_with('/') || text.ends_with(std::path::MAIN_SEPARATOR);
        let folder = path.is_dir();
        if !trailing && by_name.is_some() && folder {
            let expected = format!(
                "a file, as the name's .{} asks (to write a SOG scene into that folder, end the name with /)",
                ext.unwrap_or_default()
            );
            return Err(SceneError::format(path, "output", expected, "an existing folder of that name"));
        }
        if trailing || folder {
            return Ok(Self::SogFolder(path.to_path_buf()));
        }
        if name == "meta.json" {
            let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            return Ok(Self::SogFolder(dir.to_path_buf()));
        }
        by_name.ok_or_else(|| SceneError::UnknownFormat {
            path: path.to_path_buf(),
            expected: OUTPUT_NAMES.into(),
            found: match ext {
                Some(e) => format!("the extension .{e}"),
                None => "a name without an extension".into(),
            },
        })
    }
}

/// The `.spz` versions written: 3 (gzip) and 4 (zstd streams, the current one).
pub const SPZ_VERSIONS: std::ops::RangeInclusive<u32> = 3..=4;

/// The sizes a SOG palette of the higher SH bands may take, in entries.
pub const SOG_PALETTES: std::ops::RangeInclusive<usize> = 1..=65_536;

/// Choices of the lossy writers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SaveOptions {
    /// `.spz` version, one of [`SPZ_VERSIONS`].
    pub spz_version: u32,
    /// Largest SOG palette for the higher SH bands, in [`SOG_PALETTES`].
    pub sog_palette: usize,
}

impl Default for SaveOptions {
    fn default() -> Self {
        Self { spz_version: *SPZ_VERSIONS.end(), sog_palette: *SOG_PALETTES.end() }
    }
}

/// Writes `g` in the format its name asks for ([`SceneFormat::from_output`]).
pub fn save(path: impl AsRef<Path>, g: &Gaussians, opts: &SaveOptions) -> Result<(), SceneError> {
    save_with_progress(path, g, opts, &mut |_, _| {})
}

/// [`save`], reporting progress as `(stage, fraction done)` through `progress`
/// (the SOG palette's clustering is the only slow part).
pub fn save_with_progress(
    path: impl AsRef<Path>,
    g: &Gaussians,
    opts: &SaveOptions,
    progress: &mut dyn FnMut(&str, f32),
) -> Result<(), SceneError> {
    let path = path.as_ref();
    let format = SceneFormat::from_output(path)?;
    validate(path, g)?;
    if !SPZ_VERSIONS.contains(&opts.spz_version) {
        return Err(SceneError::format(path, "spz version", "3 or 4", opts.spz_version.to_string()));
    }
    if !SOG_PALETTES.contains(&opts.sog_palette) {
        return Err(SceneError::format(path, "SOG palette size", "1 to 65536 entries", opts.sog_palette.to_string()));
    }
    let target = match &format {
        SceneFormat::SogFolder(dir) => dir.as_path(),
        _ => path,
    };
    check_parent(path, target)?;
    progress("encode", 0.0);
    match format {
        SceneFormat::Ply => ply::save_ply(path, g)?,
        SceneFormat::CompressedPly => super::atomic_write(path, |w| compressed_ply::write_compressed_ply(w, g))?,
        SceneFormat::Spz => {
            let bytes = spz::encode(path, g, opts.spz_version)?;
            super::atomic_write(path, |w| std::io::Write::write_all(w, &bytes))?;
        }
        SceneFormat::SogFolder(dir) => {
            let files = sog_write::encode(path, g, opts.sog_palette, progress)?;
            sog_write::write_folder(&dir, &files)?;
        }
        SceneFormat::SogBundle => {
            let files = sog_write::encode(path, g, opts.sog_palette, progress)?;
            let bytes = sog_write::zip_bundle(path, &files)?;
            super::atomic_write(path, |w| std::io::Write::write_all(w, &bytes))?;
        }
    }
    progress("done", 1.0);
    Ok(())
}

/// The folder that will hold `target` must exist and be a folder; otherwise
/// say so before any work is done.
fn check_parent(path: &Path, target: &Path) -> Result<(), SceneError> {
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => return Ok(()),
    };
    match std::fs::metadata(parent) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(SceneError::format(
            path,
            "output folder",
            format!("{} to be a folder", parent.display()),
            "a file (cannot write inside it)",
        )),
        Err(e) => {
            Err(SceneError::format(path, "output folder", format!("{} to exist", parent.display()), e.to_string()))
        }
    }
}
