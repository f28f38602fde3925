//! Writing PlayCanvas SOG (version 2), the inverse of `sog.rs`: lossless WebP
//! textures, one texel per Gaussian, and a `meta.json` with the bounds and
//! codebooks.
//!
//! The textures must be lossless (a texel is a set of indices and fixed-point
//! bytes, not a colour), which the `image` crate's WebP encoder is. Positions
//! are 16-bit in the log space the reader expects, quaternions smallest-three
//! in bytes, scales, DC colours and SH coefficients indices into 256-entry
//! k-means codebooks, and the higher SH bands a 16-bit label into a palette
//! of at most 65,536 vectors (exact when the scene has no more distinct SH
//! vectors than that, clustered otherwise: see `kmeans.rs`). Texture sizes
//! follow splat-transform: a width of `⌈√n / 4⌉ · 4` and a height rounded up to
//! a multiple of 4.

use std::io::Write;
use std::path::Path;

use serde_json::json;

use super::kmeans::{codebook, nearest, palette};
use super::{Gaussians, SceneError};

/// Files of a SOG scene: `(name, bytes)`, `meta.json` last.
pub(crate) type SogFiles = Vec<(String, Vec<u8>)>;

/// Entries in each codebook.
const CODEBOOK: usize = 256;

fn lossless_webp(path: &Path, name: &str, rgba: &[u8], width: usize, height: usize) -> Result<Vec<u8>, SceneError> {
    let mut out = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut out)
        .encode(rgba, width as u32, height as u32, image::ExtendedColorType::Rgba8)
        .map_err(|e| SceneError::format(path, name, "a WebP encoding of the texture", e.to_string()))?;
    Ok(out)
}

/// `sign(x) · ln(|x| + 1)`, the space SOG quantises positions in.
fn log_space(x: f32) -> f64 {
    let v = (x.abs() as f64).ln_1p();
    if x < 0.0 { -v } else { v }
}

/// Encodes `g` as SOG files, with a palette of at most `palette_size` entries
/// for the higher SH bands.
pub(crate) fn encode(
    path: &Path,
    g: &Gaussians,
    palette_size: usize,
    progress: &mut dyn FnMut(&str, f32),
) -> Result<SogFiles, SceneError> {
    let n = g.len();
    let width = (((n as f64).sqrt() / 4.0).ceil() as usize * 4).max(4);
    let height = (n.div_ceil(width).div_ceil(4) * 4).max(4);
    let texels = width * height;
    let mut files = Vec::new();
    let mut webp = |name: &str, rgba: &[u8], w: usize, h: usize| -> Result<String, SceneError> {
        let file = format!("{name}.webp");
        files.push((file.clone(), lossless_webp(path, name, rgba, w, h)?));
        Ok(file)
    };

    // Means: 16 bits per axis in log space, low bytes and high bytes.
    let logs: Vec<[f64; 3]> = g.means.iter().map(|m| m.map(log_space)).collect();
    let mut mins = [0.0f64; 3];
    let mut maxs = [0.0f64; 3];
    for a in 0..3 {
        mins[a] = logs.iter().map(|l| l[a]).fold(f64::INFINITY, f64::min);
        maxs[a] = logs.iter().map(|l| l[a]).fold(f64::NEG_INFINITY, f64::max);
        if n == 0 {
            (mins[a], maxs[a]) = (0.0, 0.0);
        }
    }
    let (mut lo, mut hi) = (vec![0u8; texels * 4], vec![0u8; texels * 4]);
    for (i, l) in logs.iter().enumerate() {
        for a in 0..3 {
            let t = if maxs[a] > mins[a] { (l[a] - mins[a]) / (maxs[a] - mins[a]) } else { 0.0 };
            let q = (t * 65535.0).round().clamp(0.0, 65535.0) as u16;
            lo[i * 4 + a] = (q & 0xff) as u8;
            hi[i * 4 + a] = (q >> 8) as u8;
        }
        lo[i * 4 + 3] = 255;
        hi[i * 4 + 3] = 255;
    }
    let means_files = [webp("means_l", &lo, width, height)?, webp("means_u", &hi, width, height)?];

    // Quaternions: three smaller components in bytes, the largest's index in alpha.
    let mut quats = vec![0u8; texels * 4];
    for (i, q) in g.quats.iter().enumerate() {
        let q = super::normalised_largest_positive(*q);
        let largest = super::largest_abs(&q);
        let mut slot = 0;
        for (c, v) in q.iter().enumerate() {
            if c != largest {
                quats[i * 4 + slot] =
                    ((v * std::f32::consts::SQRT_2 + 1.0) * 0.5 * 255.0).round().clamp(0.0, 255.0) as u8;
                slot += 1;
            }
        }
        quats[i * 4 + 3] = 252 + largest as u8;
    }
    let quats_file = webp("quats", &quats, width, height)?;
    progress("codebooks", 0.05);

    // Scales and DC colours through codebooks; opacity in sh0's alpha.
    let scale_book = codebook(g.log_scales.as_flattened(), CODEBOOK);
    let dc: Vec<f32> = (0..n).flat_map(|i| g.sh_of(i)[..3].to_vec()).collect();
    let dc_book = codebook(&dc, CODEBOOK);
    let (mut scales, mut sh0) = (vec![0u8; texels * 4], vec![0u8; texels * 4]);
    for i in 0..n {
        for a in 0..3 {
            scales[i * 4 + a] = nearest(&scale_book, g.log_scales[i][a]) as u8;
            sh0[i * 4 + a] = nearest(&dc_book, dc[i * 3 + a]) as u8;
        }
        scales[i * 4 + 3] = 255;
        let alpha = 1.0 / (1.0 + (-g.opacity_logits[i]).exp());
        sh0[i * 4 + 3] = (alpha * 255.0).round().clamp(0.0, 255.0) as u8;
    }
    let scales_file = webp("scales", &scales, width, height)?;
    let sh0_file = webp("sh0", &sh0, width, height)?;

    let mut meta = json!({
        "version": 2,
        "asset": { "generator": concat!("gast ", env!("CARGO_PKG_VERSION")) },
        "count": n,
        "means": { "mins": mins, "maxs": maxs, "files": means_files },
        "scales": { "codebook": scale_book, "files": [scales_file] },
        "quats": { "files": [quats_file] },
        "sh0": { "codebook": dc_book, "files": [sh0_file] },
    });

    if g.sh_degree > 0 {
        let coeffs = g.sh_coeffs() - 1;
        let dim = coeffs * 3;
        let rest: Vec<f32> = (0..n).flat_map(|i| g.sh_of(i)[3..].to_vec()).collect();
        let (centres, labels) = palette(&rest, dim, palette_size, &mut |f| progress("SH palette", 0.1 + 0.8 * f));
        let count = (centres.len() / dim).max(1);
        let book = codebook(&centres, CODEBOOK);
        let (cw, ch) = (64 * coeffs, count.div_ceil(64));
        let mut cent = vec![0u8; cw * ch * 4];
        for p in 0..centres.len() / dim {
            for j in 0..coeffs {
                let t = (p / 64) * cw + (p % 64) * coeffs + j;
                for c in 0..3 {
                    cent[t * 4 + c] = nearest(&book, centres[p * dim + j * 3 + c]) as u8;
                }
                cent[t * 4 + 3] = 255;
            }
        }
        let mut lab = vec![0u8; texels * 4];
        for (i, &l) in labels.iter().enumerate() {
            lab[i * 4] = (l & 0xff) as u8;
            lab[i * 4 + 1] = (l >> 8) as u8;
            lab[i * 4 + 3] = 255;
        }
        let files = [webp("shN_centroids", &cent, cw, ch)?, webp("shN_labels", &lab, width, height)?];
        meta["shN"] = json!({ "count": count, "bands": g.sh_degree, "codebook": book, "files": files });
    }
    let text = serde_json::to_vec(&meta).map_err(|e| SceneError::format(path, "meta.json", "JSON", e.to_string()))?;
    files.push(("meta.json".into(), text));
    progress("write", 0.95);
    Ok(files)
}

/// The names a SOG folder's files take (`meta.json` and the textures [`encode`] writes).
pub(crate) const FILE_NAMES: [&str; 8] = [
    "meta.json",
    "means_l.webp",
    "means_u.webp",
    "quats.webp",
    "scales.webp",
    "sh0.webp",
    "shN_centroids.webp",
    "shN_labels.webp",
];

/// Refuses an existing folder as a SOG output where writing would replace a
/// file that is not a SOG scene's: a `meta.json` that is not SOG metadata
/// (a folder of other work: `gast convert scene.ply ~/project/` replaced its
/// `meta.json`), or, with no `meta.json`, a file of a texture's name. A
/// folder holding a SOG scene is replaced as a whole, as before.
pub(crate) fn refuse_foreign_folder(dir: &Path) -> Result<(), SceneError> {
    let meta = dir.join("meta.json");
    let choose = "(the SOG output would replace it; choose a new or empty folder)";
    match std::fs::read(&meta) {
        Ok(bytes) if super::sog::is_meta(&bytes) => return Ok(()),
        Ok(_) => {
            return Err(SceneError::format(
                &meta,
                "output folder",
                "a SOG scene's meta.json to replace, or none",
                format!("another file {choose}"),
            ));
        }
        Err(_) => {}
    }
    match FILE_NAMES.iter().map(|n| dir.join(n)).find(|p| p.exists()) {
        Some(path) => Err(SceneError::format(
            &path,
            "output folder",
            "no file of a SOG texture's name where no SOG scene is (the folder has no meta.json)",
            format!("one {choose}"),
        )),
        None => Ok(()),
    }
}

/// Writes the files into `dir`. A new folder is filled under a temporary name
/// and renamed into place; in an existing folder the files are all written
/// before any replaces its old one ([`crate::io::replace_all`]), `meta.json`
/// last, so a failed write keeps the old scene whole and a reader never sees
/// new metadata with old textures. An existing folder whose files are not a SOG scene's is refused
/// ([`refuse_foreign_folder`]).
pub(crate) fn write_folder(dir: &Path, files: &SogFiles) -> Result<(), SceneError> {
    if dir.is_dir() {
        refuse_foreign_folder(dir)?;
        // All or none: a read-only file or a full disk midway would leave old and new textures mixed.
        let files: Vec<_> = files.iter().map(|(name, bytes)| (dir.join(name), bytes.as_slice())).collect();
        return crate::io::replace_all(&files).map_err(|(path, e)| SceneError::io(path, e));
    }
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "sog".into());
    if let Some(parent) = dir.parent() {
        crate::io::refuse_read_only_folder(parent).map_err(|e| SceneError::io(dir, e))?;
        crate::io::remove_stale_temps(if parent.as_os_str().is_empty() { Path::new(".") } else { parent });
    }
    let tmp = dir.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        std::fs::create_dir(&tmp)?;
        for (file, bytes) in files {
            std::fs::write(tmp.join(file), bytes)?;
        }
        std::fs::rename(&tmp, dir)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(SceneError::io(dir, e));
    }
    Ok(())
}

/// The files as one `.sog` zip bundle (textures stored, `meta.json` deflated).
pub(crate) fn zip_bundle(path: &Path, files: &SogFiles) -> Result<Vec<u8>, SceneError> {
    use zip::write::SimpleFileOptions;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let err = |e: zip::result::ZipError| SceneError::format(path, "zip bundle", "a written archive", e.to_string());
    for (name, bytes) in files {
        let method =
            if name.ends_with(".json") { zip::CompressionMethod::Deflated } else { zip::CompressionMethod::Stored };
        zip.start_file(name.as_str(), SimpleFileOptions::default().compression_method(method)).map_err(err)?;
        zip.write_all(bytes).map_err(|e| SceneError::io(path, e))?;
    }
    Ok(zip.finish().map_err(err)?.into_inner())
}
