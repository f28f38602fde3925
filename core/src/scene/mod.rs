//! Gaussian-splat scenes as struct-of-arrays, and the file formats they come in.
//!
//! One layout for every format: the rasterizer, the optimiser and the writers all
//! read the same flat arrays, and each reader converts into it once. SH
//! coefficients are stored band-major per Gaussian, `(N, (deg+1)², 3)`, the layout
//! of the golden files; the INRIA `.ply` stores `f_rest_*` channel-major and the
//! reader/writer transpose.
//!
//! [`load`] recognises a file by its contents, not its name: a PLY header with
//! `packed_*` properties is PlayCanvas's compressed PLY, any other PLY is
//! INRIA's, gzip or `NGSP` bytes are Niantic's `.spz`, and a directory, a
//! `meta.json` or a zip archive is PlayCanvas's SOG. Every reader checks
//! counts against the bytes that are really there before allocating, and
//! every decoded scene is validated (finite values, non-zero quaternions)
//! before it is returned; [`save_ply`] applies the same check, so whatever it
//! writes [`load`] reads back. [`save()`] writes any of these formats, chosen
//! by the output's name (`save.rs`).

pub mod blend;
mod compressed_ply;
mod error;
mod kmeans;
mod ply;
mod ply_header;
mod save;
mod sog;
mod sog_write;
mod spz;
#[cfg(test)]
pub(crate) mod test_util;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_write;

use std::path::Path;

pub use blend::{BlendError, Strength, blend};
pub use error::SceneError;
pub use ply::{LOG_SCALE_INF, LOG_SCALE_NEG_INF, OPACITY_LOGIT_INF, OPACITY_LOGIT_NEG_INF};
pub use save::{
    OUTPUT_NAMES, SOG_PALETTES, SPZ_VERSIONS, SaveOptions, SceneFormat, check_output, save, save_with_progress,
};

/// SH basis constant of band 0: rendered colour is `0.5 + C0 · c_0 + …`.
pub const SH_C0: f32 = 0.282_094_8;

/// The SH degrees a scene may have (the formats' 0 to 3).
pub const SH_DEGREES: std::ops::RangeInclusive<u32> = 0..=3;

/// Number of SH coefficients per colour channel for a degree (1, 4, 9, 16).
pub const fn sh_coeffs_for_degree(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// A set of 3D Gaussians, struct-of-arrays.
///
/// All arrays have `len()` entries except `sh`, which holds
/// `len() · sh_coeffs() · 3` floats laid out `[gaussian][coefficient][channel]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    /// Centres in world space.
    pub means: Vec<[f32; 3]>,
    /// Natural logarithm of the per-axis standard deviations.
    pub log_scales: Vec<[f32; 3]>,
    /// Rotations as quaternions (w, x, y, z); not necessarily normalised.
    pub quats: Vec<[f32; 4]>,
    /// Opacity before the sigmoid.
    pub opacity_logits: Vec<f32>,
    /// SH degree, 0 to 3.
    pub sh_degree: u32,
    /// SH coefficients, `[gaussian][coefficient][channel]`, `(deg+1)²` coefficients.
    pub sh: Vec<f32>,
}

impl Gaussians {
    /// An empty set with room for `n` Gaussians of the given SH degree.
    pub fn with_capacity(n: usize, sh_degree: u32) -> Self {
        Self {
            means: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            quats: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            sh_degree,
            sh: Vec::with_capacity(n * sh_coeffs_for_degree(sh_degree) * 3),
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per channel, `(sh_degree + 1)²`.
    pub fn sh_coeffs(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree)
    }

    /// The SH coefficients of Gaussian `i`, `sh_coeffs() · 3` floats.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let k = self.sh_coeffs() * 3;
        &self.sh[i * k..(i + 1) * k]
    }

    /// Checks that every array has the length the Gaussian count implies.
    pub fn check_consistent(&self) -> Result<(), String> {
        let n = self.len();
        let want_sh = n * self.sh_coeffs() * 3;
        if self.log_scales.len() != n
            || self.quats.len() != n
            || self.opacity_logits.len() != n
            || self.sh.len() != want_sh
            || !SH_DEGREES.contains(&self.sh_degree)
        {
            return Err(format!(
                "inconsistent arrays: {n} means, {} scales, {} quats, {} opacities, {} SH floats (want {want_sh}), degree {}",
                self.log_scales.len(),
                self.quats.len(),
                self.opacity_logits.len(),
                self.sh.len(),
                self.sh_degree
            ));
        }
        Ok(())
    }
}

/// Reads a scene, recognising the format from the contents: INRIA `.ply`
/// (ASCII or binary), PlayCanvas compressed `.ply`, Niantic `.spz` (gzip v2/v3
/// or zstd v4), or a PlayCanvas SOG directory, its `meta.json`, or a `.sog`
/// zip bundle.
/// Warnings (values the reader had to repair) are dropped; use
/// [`load_with_warnings`] to show them.
pub fn load(path: impl AsRef<Path>) -> Result<Gaussians, SceneError> {
    load_with_warnings(path).map(|(g, _)| g)
}

/// [`load`], also returning the readers' warnings: one message per kind of
/// repair, with counts (today: infinite opacity logits or log-scales in an
/// INRIA `.ply`, replaced by finite values that render the same).
pub fn load_with_warnings(path: impl AsRef<Path>) -> Result<(Gaussians, Vec<String>), SceneError> {
    let path = path.as_ref();
    if path.is_dir() {
        let meta = path.join("meta.json");
        if !meta.exists() {
            return Err(SceneError::UnknownFormat {
                path: path.to_path_buf(),
                expected: "a scene file (.ply, .compressed.ply, .spz, .sog) or a SOG folder with its meta.json".into(),
                found: folder_contents(path),
            });
        }
        return sog::read_sog(&meta).map(|g| (g, Vec::new()));
    }
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    load_from_bytes_with_warnings(path, &bytes)
}

/// What a folder that is no SOG scene holds, for the error that refuses it:
/// a posed-photo dataset (which holds no Gaussians: `gast fit` makes a scene
/// from it), an INRIA trainer's model folder (naming its newest
/// `point_cloud.ply`), or else its first few names.
fn folder_contents(dir: &Path) -> String {
    use crate::camera::CameraFileKind;
    let names: Vec<String> = std::fs::read_dir(dir)
        .map(|entries| entries.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    // The cameras a camera load of the folder would find; a `cameras.json`
    // alone is what `gast fit` and the INRIA trainer write beside a scene.
    let photos = match crate::camera::camera_file_in(dir) {
        Some((CameraFileKind::Llff, _)) => Some("LLFF poses_bounds.npy"),
        Some((CameraFileKind::Transforms, _)) => Some("NeRF transforms.json"),
        Some((CameraFileKind::Colmap, _)) => Some("COLMAP sparse/0"),
        Some((CameraFileKind::Inria, _)) | None => None,
    };
    if let Some(kind) = photos {
        return format!(
            "a folder of posed photos ({kind}), which holds no Gaussians: fit a scene from it first \
             (`gast fit {} --out scene.ply`)",
            dir.display()
        );
    }
    let newest = std::fs::read_dir(dir.join("point_cloud"))
        .map(|entries| {
            entries
                .flatten()
                .filter_map(|e| {
                    let n = e.file_name().to_string_lossy().into_owned();
                    let it: u64 = n.strip_prefix("iteration_")?.parse().ok()?;
                    e.path().join("point_cloud.ply").is_file().then_some((it, e.path().join("point_cloud.ply")))
                })
                .max_by_key(|(it, _)| *it)
        })
        .ok()
        .flatten();
    if let Some((_, ply)) = newest {
        return format!("an INRIA model folder without meta.json; its newest scene is {}", ply.display());
    }
    let mut shown: Vec<&String> = names.iter().collect();
    shown.sort();
    match shown.len() {
        0 => "an empty folder".into(),
        n => {
            let first: Vec<&str> = shown.iter().take(5).map(|s| s.as_str()).collect();
            let more = if n > 5 { format!(", … ({n} in all)") } else { String::new() };
            format!("a folder without meta.json holding {}{more}", first.join(", "))
        }
    }
}

/// Decodes a scene file already held in memory, recognising the format as
/// [`load`] does. `path` names the file in errors; for a SOG `meta.json` the
/// textures are read from beside it.
pub fn load_from_bytes(path: impl AsRef<Path>, bytes: &[u8]) -> Result<Gaussians, SceneError> {
    load_from_bytes_with_warnings(path, bytes).map(|(g, _)| g)
}

/// [`load_from_bytes`], also returning the readers' warnings.
pub fn load_from_bytes_with_warnings(
    path: impl AsRef<Path>,
    bytes: &[u8],
) -> Result<(Gaussians, Vec<String>), SceneError> {
    let mut warnings = Vec::new();
    let g = decode(path.as_ref(), bytes, &mut warnings)?;
    Ok((g, warnings))
}

fn decode(path: &Path, bytes: &[u8], warnings: &mut Vec<String>) -> Result<Gaussians, SceneError> {
    if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
        let header = ply_header::parse_header(path, bytes)?;
        let compressed =
            header.element("vertex").is_some_and(|(_, v)| v.props.iter().any(|p| p.name.starts_with("packed_")));
        return if compressed {
            compressed_ply::read_compressed_ply(path, bytes, &header)
        } else {
            ply::read_ply_bytes(path, bytes, &header, warnings)
        };
    }
    if bytes.starts_with(&[0x1f, 0x8b]) || bytes.starts_with(b"NGSP") {
        return spz::read_spz_bytes(path, bytes);
    }
    if bytes.starts_with(b"PK\x03\x04") {
        return sog::read_sog_zip(path, bytes);
    }
    let first = bytes.iter().find(|b| !b.is_ascii_whitespace());
    if first == Some(&b'{') {
        return sog::read_sog_meta(path, bytes);
    }
    let ext = path.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_default();
    let head: Vec<String> = bytes.iter().take(8).map(|b| format!("{b:02x}")).collect();
    Err(SceneError::UnknownFormat {
        path: path.to_path_buf(),
        expected: "INRIA .ply, PlayCanvas compressed .ply, Niantic .spz, or SOG (directory, meta.json or .sog bundle)"
            .into(),
        found: if bytes.is_empty() {
            format!("an empty file (extension {ext:?})")
        } else {
            format!("extension {ext:?}, first bytes [{}]", head.join(" "))
        },
    })
}

/// Writes `g` as an INRIA binary little-endian `.ply` with the original
/// trainer's property names and order. The file is written to a temporary
/// file beside `path` and renamed over it, so an existing file is never left
/// half-overwritten. Reading it back with [`load`] is bit-exact. Scenes with
/// non-finite values or zero quaternions are refused (the error names the
/// Gaussian), since no reader would accept the file.
pub fn save_ply(path: impl AsRef<Path>, g: &Gaussians) -> Result<(), SceneError> {
    ply::save_ply(path.as_ref(), g)
}

/// Checks a decoded scene: every value finite and every quaternion non-zero.
/// The error names the field and the Gaussian's index.
pub(crate) fn validate(path: &Path, g: &Gaussians) -> Result<(), SceneError> {
    g.check_consistent().map_err(|e| SceneError::format(path, "gaussians", "consistent arrays", e))?;
    let bad = |what: String, v: String| SceneError::format(path, what, "a finite value", v);
    let k = g.sh_coeffs() * 3;
    for i in 0..g.len() {
        for (a, v) in g.means[i].iter().enumerate() {
            if !v.is_finite() {
                return Err(bad(format!("vertex {i}: position {}", ["x", "y", "z"][a]), v.to_string()));
            }
        }
        for (a, v) in g.log_scales[i].iter().enumerate() {
            if !v.is_finite() {
                return Err(bad(format!("vertex {i}: scale_{a}"), v.to_string()));
            }
        }
        for (a, v) in g.quats[i].iter().enumerate() {
            if !v.is_finite() {
                return Err(bad(format!("vertex {i}: rot_{a}"), v.to_string()));
            }
        }
        if g.quats[i].iter().all(|&v| v == 0.0) {
            return Err(SceneError::format(
                path,
                format!("vertex {i}: rotation"),
                "a non-zero quaternion",
                "(0, 0, 0, 0)",
            ));
        }
        if !g.opacity_logits[i].is_finite() {
            return Err(bad(format!("vertex {i}: opacity"), g.opacity_logits[i].to_string()));
        }
        for (j, v) in g.sh[i * k..(i + 1) * k].iter().enumerate() {
            if !v.is_finite() {
                let (coeff, ch) = (j / 3, j % 3);
                return Err(bad(format!("vertex {i}: SH coefficient {coeff}, channel {ch}"), v.to_string()));
            }
        }
    }
    Ok(())
}

/// Writes a file through `write` into a temporary file beside `path`, then
/// renames it over `path` ([`crate::io::replace_with`]: a read-only `path` is
/// refused). On any error the temporary file is removed and an existing
/// `path` is untouched.
pub(crate) fn atomic_write(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), SceneError> {
    if path.file_name().is_none() {
        let e = std::io::Error::new(std::io::ErrorKind::InvalidInput, "no file name");
        return Err(SceneError::io(path, e));
    }
    crate::io::replace_with(path, write).map_err(|e| SceneError::io(path, e))
}

/// Index of the component of `q` with the largest magnitude (the first on ties).
pub(crate) fn largest_abs(q: &[f32; 4]) -> usize {
    (1..4).fold(0, |best, c| if q[c].abs() > q[best].abs() { c } else { best })
}

/// `q` scaled to unit length and negated if needed so that its largest
/// component is positive (q and −q are the same rotation), as the
/// smallest-three packings need.
pub(crate) fn normalised_largest_positive(q: [f32; 4]) -> [f32; 4] {
    let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    let s = if q[largest_abs(&q)] < 0.0 { -1.0 / norm } else { 1.0 / norm };
    q.map(|v| v * s)
}

/// Inverse sigmoid of a quantised opacity, clamped to [1e-6, 1 − 1e-6] so
/// that stored alphas of exactly 0 or 1 decode to finite logits (±13.8), as
/// PlayCanvas's readers do.
pub(crate) fn alpha_to_logit(alpha: f64) -> f32 {
    let a = alpha.clamp(1e-6, 1.0 - 1e-6);
    (a / (1.0 - a)).ln() as f32
}
