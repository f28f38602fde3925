//! PlayCanvas's SOG layout: a `meta.json` plus WebP textures, one texel per
//! Gaussian, that a browser can stream and decode with its image decoder.
//!
//! Version 2 (what `splat-transform` writes, and the shared `playbot-sog/`):
//! - `means_l`, `means_u`: low and high bytes of 16-bit unorms per axis in
//!   R, G, B, lerped between `means.mins` and `means.maxs` in a log space
//!   `sign(x)·ln(|x| + 1)`, then mapped back with `sign(v)·(e^|v| − 1)`;
//! - `quats`: R, G, B the three smaller components as `(v/255·2 − 1)/√2`, A
//!   `252 + index` of the largest component in (w, x, y, z), which is
//!   reconstructed as `√(1 − Σ others²)`;
//! - `scales`: R, G, B index the 256-entry `scales.codebook` (natural logs);
//! - `sh0`: R, G, B index `sh0.codebook` (f_dc), A is `sigmoid(opacity)·255`;
//! - `shN_labels`: a 16-bit palette index per Gaussian (R low, G high) into
//!   `shN_centroids`, a texture 64·coeffs wide where palette entry `p` occupies
//!   row `p / 64`, columns `(p mod 64)·coeffs + j` for coefficient `j`, with
//!   R, G, B indexing `shN.codebook`. `shN.bands` (1 to 3) is the SH degree.
//!
//! A `.sog` file is the same set of files in one zip archive (entries stored
//! or deflated), with `meta.json` at its root.
//!
//! Quantisation: positions 1/65535 of the log-space range per axis, quaternion
//! components `2/255/√2`, alpha 1/255, the rest by 256-entry codebooks (and SH
//! additionally by the palette's k-means clustering).

use std::cell::RefCell;
use std::io::{Cursor, Read};
use std::path::{Component, Path, PathBuf};

use serde::Deserialize;

use super::{Gaussians, SceneError, alpha_to_logit, sh_coeffs_for_degree, validate};

#[derive(Deserialize)]
struct Files {
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Means {
    mins: Vec<f64>,
    maxs: Vec<f64>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Coded {
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct ShN {
    count: usize,
    bands: u32,
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Meta {
    version: Option<u32>,
    count: usize,
    means: Means,
    scales: Coded,
    quats: Files,
    sh0: Coded,
    #[serde(rename = "shN")]
    sh_n: Option<ShN>,
}

/// Whether `bytes` are SOG metadata (a `meta.json` this reader takes).
pub(crate) fn is_meta(bytes: &[u8]) -> bool {
    serde_json::from_slice::<Meta>(bytes).is_ok()
}

/// Reads a SOG scene from its `meta.json`.
pub(crate) fn read_sog(meta_path: &Path) -> Result<Gaussians, SceneError> {
    let bytes = std::fs::read(meta_path).map_err(|e| SceneError::io(meta_path, e))?;
    read_sog_meta(meta_path, &bytes)
}

/// Decodes a SOG scene given the bytes of its `meta.json`; the textures are
/// read from beside it.
pub(crate) fn read_sog_meta(path: &Path, bytes: &[u8]) -> Result<Gaussians, SceneError> {
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    decode(path, bytes, &Source::Dir(dir))
}

/// Largest texture or metadata entry read from a bundle (a guard against zip bombs).
const MAX_ENTRY: u64 = 1 << 30;

/// Reads a `.sog` bundle: a zip archive holding `meta.json` and the textures.
pub(crate) fn read_sog_zip(path: &Path, bytes: &[u8]) -> Result<Gaussians, SceneError> {
    let archive = zip::ZipArchive::new(Cursor::new(bytes))
        .map_err(|e| SceneError::format(path, "zip archive", "a readable .sog zip bundle", e.to_string()))?;
    let source = Source::Zip { bundle: path.to_path_buf(), archive: RefCell::new(archive) };
    let (meta_path, meta) = source.read("meta.json")?;
    decode(&meta_path, &meta, &source)
}

/// Where the textures come from.
enum Source<'a> {
    /// Files in a directory.
    Dir(PathBuf),
    /// Entries of a zip bundle.
    Zip { bundle: PathBuf, archive: RefCell<zip::ZipArchive<Cursor<&'a [u8]>>> },
}

impl Source<'_> {
    /// The bytes of `name`, with the path to name in messages.
    fn read(&self, name: &str) -> Result<(PathBuf, Vec<u8>), SceneError> {
        match self {
            Source::Dir(dir) => {
                let file = dir.join(name);
                let bytes = std::fs::read(&file).map_err(|e| SceneError::io(&file, e))?;
                Ok((file, bytes))
            }
            Source::Zip { bundle, archive } => {
                let shown = bundle.join(name);
                let mut archive = archive.borrow_mut();
                let entry = archive.by_name(name).map_err(|e| {
                    SceneError::format(&shown, "zip entry", format!("an entry {name:?}"), e.to_string())
                })?;
                let mut out = Vec::new();
                entry
                    .take(MAX_ENTRY)
                    .read_to_end(&mut out)
                    .map_err(|e| SceneError::format(&shown, "zip entry", "readable data", e.to_string()))?;
                Ok((shown, out))
            }
        }
    }
}

/// An RGBA8 texture, and the file it came from (for messages).
struct Texture {
    file: PathBuf,
    rgba: Vec<u8>,
    width: usize,
    height: usize,
}

impl Texture {
    fn texel(&self, i: usize) -> [u8; 4] {
        let mut t = [0u8; 4];
        if let Some(s) = self.rgba.get(i * 4..i * 4 + 4) {
            t.copy_from_slice(s);
        }
        t
    }
}

fn fmt(path: &Path, what: &str, expected: impl Into<String>, found: impl Into<String>) -> SceneError {
    SceneError::format(path, what, expected, found)
}

/// Loads `name` (relative to the meta file) as RGBA and checks it holds `need` texels.
fn texture(src: &Source<'_>, meta: &Path, field: &str, name: &str, need: usize) -> Result<Texture, SceneError> {
    let rel = Path::new(name);
    if rel.components().any(|c| !matches!(c, Component::Normal(_))) {
        return Err(fmt(meta, field, "a file name beside meta.json", format!("{name:?}")));
    }
    let (file, bytes) = src.read(name)?;
    let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::WebP)
        .map_err(|e| fmt(&file, field, "a WebP image", format!("undecodable data ({e})")))?
        .to_rgba8();
    let (width, height) = (img.width() as usize, img.height() as usize);
    if width * height < need {
        return Err(fmt(
            &file,
            field,
            format!("at least {need} texels"),
            format!("{width}×{height} = {} texels", width * height),
        ));
    }
    Ok(Texture { file, rgba: img.into_raw(), width, height })
}

fn need_files(path: &Path, field: &str, files: &[String], n: usize) -> Result<(), SceneError> {
    if files.len() != n {
        return Err(fmt(path, &format!("{field}.files"), format!("{n} file names"), format!("{:?}", files)));
    }
    Ok(())
}

fn need_codebook(path: &Path, field: &str, codebook: &[f32]) -> Result<(), SceneError> {
    if codebook.len() != 256 {
        return Err(fmt(path, &format!("{field}.codebook"), "256 entries", format!("{} entries", codebook.len())));
    }
    if let Some(j) = codebook.iter().position(|v| !v.is_finite()) {
        return Err(fmt(path, &format!("{field}.codebook[{j}]"), "a finite value", codebook[j].to_string()));
    }
    Ok(())
}

fn inv_log(v: f64) -> f32 {
    let e = v.abs().exp() - 1.0;
    (if v < 0.0 { -e } else { e }) as f32
}

/// Decodes a SOG scene from its `meta.json` bytes and a texture source.
fn decode(path: &Path, bytes: &[u8], src: &Source<'_>) -> Result<Gaussians, SceneError> {
    let meta: Meta = serde_json::from_slice(bytes)
        .map_err(|e| fmt(path, "meta.json", "SOG metadata (count, means, scales, quats, sh0, shN)", e.to_string()))?;
    match meta.version {
        Some(2) => {}
        Some(v) => return Err(fmt(path, "version", "2", v.to_string())),
        None => return Err(fmt(path, "version", "2", "no version (SOG v1, not supported)")),
    }
    let n = meta.count;
    need_files(path, "means", &meta.means.files, 2)?;
    need_files(path, "scales", &meta.scales.files, 1)?;
    need_files(path, "quats", &meta.quats.files, 1)?;
    need_files(path, "sh0", &meta.sh0.files, 1)?;
    need_codebook(path, "scales", &meta.scales.codebook)?;
    need_codebook(path, "sh0", &meta.sh0.codebook)?;
    if meta.means.mins.len() != 3 || meta.means.maxs.len() != 3 {
        return Err(fmt(
            path,
            "means.mins/maxs",
            "three values each",
            format!("{} and {}", meta.means.mins.len(), meta.means.maxs.len()),
        ));
    }
    let degree = match &meta.sh_n {
        None => 0,
        Some(s) => {
            need_files(path, "shN", &s.files, 2)?;
            need_codebook(path, "shN", &s.codebook)?;
            if !(1..=3).contains(&s.bands) {
                return Err(fmt(path, "shN.bands", "1 to 3", s.bands.to_string()));
            }
            if s.count == 0 || s.count > 65536 {
                return Err(fmt(path, "shN.count", "1 to 65536 palette entries", s.count.to_string()));
            }
            s.bands
        }
    };

    let lo = texture(src, path, "means_l", &meta.means.files[0], n)?;
    let hi = texture(src, path, "means_u", &meta.means.files[1], n)?;
    let quats = texture(src, path, "quats", &meta.quats.files[0], n)?;
    let scales = texture(src, path, "scales", &meta.scales.files[0], n)?;
    let sh0 = texture(src, path, "sh0", &meta.sh0.files[0], n)?;
    let k = sh_coeffs_for_degree(degree);
    let palette = match &meta.sh_n {
        Some(s) => {
            let coeffs = k - 1;
            let centroids = texture(src, path, "shN_centroids", &s.files[0], 0)?;
            if centroids.width != 64 * coeffs || centroids.height * 64 < s.count {
                return Err(fmt(
                    &centroids.file,
                    "shN_centroids",
                    format!("{} texels wide, ≥ {} rows for {} entries", 64 * coeffs, s.count.div_ceil(64), s.count),
                    format!("{}×{}", centroids.width, centroids.height),
                ));
            }
            let labels = texture(src, path, "shN_labels", &s.files[1], n)?;
            Some((centroids, labels, s))
        }
        None => None,
    };

    let (mins, maxs) = (&meta.means.mins, &meta.means.maxs);
    let mut g = Gaussians::with_capacity(n, degree);
    g.sh.resize(n * k * 3, 0.0);
    let sc = &meta.scales.codebook;
    let cc = &meta.sh0.codebook;
    for i in 0..n {
        let (l, u) = (lo.texel(i), hi.texel(i));
        let mean = [0, 1, 2].map(|a| {
            let q = l[a] as f64 + 256.0 * u[a] as f64;
            inv_log(mins[a] + (maxs[a] - mins[a]) * q / 65535.0)
        });
        g.means.push(mean);

        let q = quats.texel(i);
        let largest = q[3].checked_sub(252).filter(|&m| m < 4).ok_or_else(|| {
            fmt(
                &quats.file,
                &format!("quats texel {i}"),
                "alpha 252 to 255 (index of the largest component)",
                q[3].to_string(),
            )
        })? as usize;
        let mut rot = [0.0f32; 4];
        let mut others = q[..3].iter();
        let mut sum = 0.0;
        for (c, r) in rot.iter_mut().enumerate() {
            if c != largest {
                let v = (*others.next().unwrap_or(&128) as f32 / 255.0 * 2.0 - 1.0) / std::f32::consts::SQRT_2;
                *r = v;
                sum += v * v;
            }
        }
        rot[largest] = (1.0f32 - sum).max(0.0).sqrt();
        g.quats.push(rot);

        let s = scales.texel(i);
        g.log_scales.push([sc[s[0] as usize], sc[s[1] as usize], sc[s[2] as usize]]);

        let c = sh0.texel(i);
        let out = &mut g.sh[i * k * 3..(i + 1) * k * 3];
        out[..3].copy_from_slice(&[cc[c[0] as usize], cc[c[1] as usize], cc[c[2] as usize]]);
        g.opacity_logits.push(alpha_to_logit(c[3] as f64 / 255.0));

        if let Some((centroids, labels, s)) = &palette {
            let t = labels.texel(i);
            let label = t[0] as usize | (t[1] as usize) << 8;
            if label >= s.count {
                return Err(fmt(
                    &labels.file,
                    &format!("shN_labels texel {i}"),
                    format!("a palette index below {}", s.count),
                    label.to_string(),
                ));
            }
            let coeffs = k - 1;
            for j in 0..coeffs {
                let texel = (label / 64) * centroids.width + (label % 64) * coeffs + j;
                let rgb = centroids.texel(texel);
                for ch in 0..3 {
                    out[(j + 1) * 3 + ch] = s.codebook[rgb[ch] as usize];
                }
            }
        }
    }
    validate(path, &g)?;
    Ok(g)
}
