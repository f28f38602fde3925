//! Writing outputs safely: every file goes to a temporary sibling first and is
//! renamed into place, so an existing file is never half-overwritten, and
//! files that belong together are replaced all or none ([`replace_all`]);
//! plus the image formats the studio exports (PNG for colour, EXR for depth),
//! and reading images within the decoder's memory limit ([`open_image`]).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Why an output could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Creating, writing or renaming the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The destination.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The encoder refused the data.
    #[error("{path}: could not encode {format}: {message}")]
    Encode {
        /// The destination.
        path: PathBuf,
        /// The format being written.
        format: &'static str,
        /// The encoder's message.
        message: String,
    },
    /// The data does not have the size the image dimensions imply.
    #[error("{path}: expected {expected} values for the image, found {found}")]
    Size {
        /// The destination.
        path: PathBuf,
        /// Values expected.
        expected: usize,
        /// Values given.
        found: usize,
    },
}

/// The temporary sibling a file is written to before the rename:
/// `.<name>.tmp-<pid>`, the one scheme of every writer here (scenes and SOG
/// folders too), so that [`remove_stale_temps`] can find what a killed
/// process left.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Removes the temporary files and folders ([`temp_path`]) in `dir` that a
/// process which no longer runs left behind (a write killed midway), so they
/// do not pile up beside their targets; returns how many. Others' live writes
/// and this process's own are left alone. Linux only (it asks `/proc` whether
/// a process runs); elsewhere it removes nothing.
pub fn remove_stale_temps(dir: &Path) -> usize {
    if !cfg!(target_os = "linux") || !Path::new("/proc/self").exists() {
        return 0;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let own = std::process::id();
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = stale_pid(&name) else { continue };
        if pid == own || Path::new(&format!("/proc/{pid}")).exists() {
            continue;
        }
        let path = e.path();
        let gone = if e.file_type().is_ok_and(|t| t.is_dir()) {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed += usize::from(gone.is_ok());
    }
    removed
}

/// Removes from `dir` the files named `{prefix}{k}{suffix}`, `k` a decimal
/// number (any padding) from `kept` up and `suffix` one of `suffixes`: what
/// an earlier, longer series of views or frames left under the names this
/// one writes, which beside the new series read as part of it. Only those
/// exact names are touched. Returns how many were removed.
pub fn remove_series_tail(
    dir: &Path,
    prefix: &str,
    suffixes: &[&str],
    kept: usize,
) -> Result<usize, (PathBuf, std::io::Error)> {
    let in_tail = |name: &str| -> bool {
        let Some(rest) = name.strip_prefix(prefix) else { return false };
        let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
        let (number, suffix) = rest.split_at(digits);
        number.parse::<usize>().is_ok_and(|k| k >= kept) && suffixes.contains(&suffix)
    };
    let entries = std::fs::read_dir(dir).map_err(|e| (dir.to_path_buf(), e))?;
    let mut removed = 0;
    for e in entries.flatten() {
        if e.file_type().is_ok_and(|t| t.is_file()) && e.file_name().to_str().is_some_and(in_tail) {
            let path = e.path();
            std::fs::remove_file(&path).map_err(|err| (path, err))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// The process id in a [`temp_path`] name (`.<name>.tmp-<pid>`), if it is one.
fn stale_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('.')?;
    let (stem, pid) = rest.rsplit_once(".tmp-")?;
    if stem.is_empty() || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Writes a file atomically: `write` fills a buffered temporary sibling, which is
/// flushed, synced and renamed over `path`. On any error the temporary file is
/// removed and `path` is untouched. Parent folders are created.
pub fn atomic_write<F>(path: &Path, write: F) -> Result<(), OutputError>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    let io_err = |source| OutputError::Io { path: path.to_path_buf(), source };
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        create_folder(parent).map_err(io_err)?;
    }
    replace_with(path, write).map_err(io_err)
}

/// An error when `path` is a file whose permissions make it read-only, or
/// its folder is read-only ([`refuse_read_only_folder`]; see [`replace_with`]).
pub fn refuse_read_only(path: &Path) -> std::io::Result<()> {
    if std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.permissions().readonly()) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::PermissionDenied,
            "expected a file that may be replaced, found a read-only one (left as it is: make it writable or choose another name)",
        ));
    }
    refuse_read_only_folder(path.parent().unwrap_or(Path::new("")))
}

/// An error when the folder `dir`, or the nearest folder above it that
/// exists, is read-only by its permissions (no write bit for anyone): the one
/// a file would be added to or a folder made in. Root passes over such
/// permissions, and a read-only folder usually holds someone's originals (a
/// dataset, shared data), so no writer here adds to one, as root or not.
pub fn refuse_read_only_folder(dir: &Path) -> std::io::Result<()> {
    let mut at = dir;
    loop {
        let here = if at.as_os_str().is_empty() { Path::new(".") } else { at };
        match std::fs::metadata(here) {
            Ok(m) if m.is_dir() && m.permissions().readonly() => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::PermissionDenied,
                    format!(
                        "expected a folder that may be written in, found a read-only one, {} (left as it is: make it \
                         writable or choose another folder)",
                        here.display()
                    ),
                ));
            }
            Ok(_) => return Ok(()),
            Err(_) => match at.parent() {
                Some(up) if !at.as_os_str().is_empty() => at = up,
                _ => return Ok(()),
            },
        }
    }
}

/// Makes the output folder `dir` with its parents, refusing one inside a
/// read-only folder ([`refuse_read_only_folder`]): every output folder of the
/// commands, the studies and the demo is made here.
pub fn create_folder(dir: impl AsRef<Path>) -> std::io::Result<()> {
    let dir = dir.as_ref();
    refuse_read_only_folder(dir)?;
    std::fs::create_dir_all(dir)
}

/// The one way every writer here replaces a file: `write` fills a buffered
/// [`temp_path`] sibling, which is flushed, synced and renamed over `path`; on
/// any error the temporary file is removed and `path` is untouched. A `path`
/// whose permissions make it read-only is refused, not replaced: the rename
/// would pass over the protection an in-place write meets (as root, or in a
/// writable folder), and a protected file is usually someone's original.
/// The folder's stale temporaries ([`remove_stale_temps`]) are swept only
/// once the write is allowed.
pub(crate) fn replace_with<F>(path: &Path, write: F) -> std::io::Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    refuse_read_only(path)?;
    remove_stale_temps(folder_of(path));
    let tmp = write_temp(path, write)?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

/// Replaces files that only make sense together (a SOG scene's textures and
/// its `meta.json`, a COLMAP model's cameras and images) all or none, as
/// [`replace_with`] does one: every file is written to its [`temp_path`] and
/// synced, and only when all are written are they renamed into place. A write
/// that fails (a full disk, a read-only file) removes the temporaries and
/// leaves every existing file as it was; before, the files replaced until then
/// stayed, beside the old others. The renames need no space; only a crash
/// between them could still mix the two sets. The error names the file.
pub fn replace_all(files: &[(PathBuf, &[u8])]) -> Result<(), (PathBuf, std::io::Error)> {
    for (path, _) in files {
        refuse_read_only(path).map_err(|e| (path.clone(), e))?;
    }
    let mut swept: Vec<&Path> = Vec::new();
    for (path, _) in files {
        let folder = folder_of(path);
        if !swept.contains(&folder) {
            remove_stale_temps(folder);
            swept.push(folder);
        }
    }
    let mut temps: Vec<PathBuf> = Vec::with_capacity(files.len());
    let remove = |temps: &[PathBuf]| temps.iter().for_each(|t| drop(std::fs::remove_file(t)));
    for (path, bytes) in files {
        match write_temp(path, |w| w.write_all(bytes)) {
            Ok(tmp) => temps.push(tmp),
            Err(e) => {
                remove(&temps);
                return Err((path.clone(), e));
            }
        }
    }
    for (k, ((path, _), tmp)) in files.iter().zip(&temps).enumerate() {
        if let Err(e) = std::fs::rename(tmp, path) {
            remove(&temps[k..]);
            return Err((path.clone(), e));
        }
    }
    Ok(())
}

/// The folder `path` is in (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Writes `path`'s [`temp_path`] through `write`, flushed and synced, and
/// returns it; on an error the temporary file is removed.
fn write_temp<F>(path: &Path, write: F) -> std::io::Result<PathBuf>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    let tmp = temp_path(path);
    let result = (|| {
        let mut w = BufWriter::new(File::create(&tmp)?);
        write(&mut w)?;
        w.flush()?;
        w.get_ref().sync_all()
    })();
    match result {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// The most one decoded image may take: the `image` crate's default limit
/// (512 MiB), which [`open_image`] keeps. An RGB JPEG of 13,000 × 13,000
/// pixels fits; a run uses a style at its texture scale (at most 4,096 px
/// high), so a larger file only costs memory.
pub const IMAGE_DECODE_LIMIT: u64 = 512 << 20;

/// Decodes an image file (PNG, JPEG, WebP) within [`IMAGE_DECODE_LIMIT`]. One
/// past it is said with its size and what it would take decoded (`image`
/// itself only says "Memory limit exceeded"); other errors are the decoder's.
pub fn open_image(path: &Path) -> Result<image::DynamicImage, String> {
    if path.is_dir() {
        // `image` says only "The image format could not be determined".
        return Err("a folder".into());
    }
    image::open(path).map_err(|e| match (&e, decoded_size(path)) {
        (image::ImageError::Limits(_), Some((w, h, bytes))) if bytes > IMAGE_DECODE_LIMIT => format!(
            "a {w}x{h} image, which takes {:.2} GiB decoded, more than the {} MiB one image may take here; \
             downscale it (to about 8,000 px on its longer side)",
            bytes as f64 / f64::from(1u32 << 30),
            IMAGE_DECODE_LIMIT >> 20
        ),
        _ => e.to_string(),
    })
}

/// An image file's width, height and decoded size in bytes, from its header.
fn decoded_size(path: &Path) -> Option<(u32, u32, u64)> {
    use image::ImageDecoder;
    let mut reader = image::ImageReader::open(path).ok()?.with_guessed_format().ok()?;
    reader.no_limits();
    let decoder = reader.into_decoder().ok()?;
    let (w, h) = decoder.dimensions();
    Some((w, h, decoder.total_bytes()))
}

/// Writes `bytes` as the whole file, atomically ([`atomic_write`]).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    atomic_write(path, |w| w.write_all(bytes))
}

/// Writes an RGB image (`width·height·3` floats in [0, 1], row-major) as 8-bit PNG.
pub fn write_png_rgb(path: &Path, width: u32, height: u32, rgb: &[f32]) -> Result<(), OutputError> {
    let bytes: Vec<u8> = rgb.iter().map(|&v| to_u8(v)).collect();
    write_png_rgb8(path, width, height, &bytes)
}

/// Writes an 8-bit RGB image (`width·height·3` bytes, row-major) as PNG.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), OutputError> {
    write_png(path, width, height, image::ColorType::Rgb8, rgb)
}

/// Writes a single-channel map (`width·height` floats) as 8-bit grey PNG after
/// min-max normalisation (a constant map is written black).
pub fn write_png_gray_normalized(path: &Path, width: u32, height: u32, values: &[f32]) -> Result<(), OutputError> {
    let (lo, hi) = finite_range(values);
    let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    let bytes: Vec<u8> = values.iter().map(|&v| to_u8(if v.is_finite() { (v - lo) * scale } else { 0.0 })).collect();
    write_png(path, width, height, image::ColorType::L8, &bytes)
}

/// Writes an inverse-depth map as 8-bit grey PNG, min-max normalised over the
/// pixels the scene covers (`alpha ≥ 0.5`, near = bright); uncovered pixels are black.
pub fn write_depth_png(
    path: &Path,
    width: u32,
    height: u32,
    inv_depth: &[f32],
    alpha: &[f32],
) -> Result<(), OutputError> {
    write_png(path, width, height, image::ColorType::L8, &depth_to_gray(inv_depth, alpha))
}

/// An inverse-depth map as 8-bit grey, as [`write_depth_png`] draws it:
/// min-max over the covered pixels (`alpha ≥ 0.5`), near bright, uncovered black.
pub fn depth_to_gray(inv_depth: &[f32], alpha: &[f32]) -> Vec<u8> {
    covered_unit_depth(inv_depth, alpha).map(|t| t.map_or(0, |t| to_u8(0.1 + 0.9 * t))).collect()
}

/// Each pixel's inverse depth min-max normalised over the covered pixels
/// (`alpha ≥ 0.5`) to [0, 1], `None` where it is uncovered or not finite.
pub fn covered_unit_depth<'a>(inv_depth: &'a [f32], alpha: &'a [f32]) -> impl Iterator<Item = Option<f32>> + 'a {
    let covered: Vec<f32> = inv_depth.iter().zip(alpha).filter(|(_, a)| **a >= 0.5).map(|(d, _)| *d).collect();
    let (lo, hi) = finite_range(&covered);
    let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    inv_depth.iter().zip(alpha).map(move |(&d, &a)| (a >= 0.5 && d.is_finite()).then_some((d - lo) * scale))
}

fn write_png(path: &Path, width: u32, height: u32, color: image::ColorType, bytes: &[u8]) -> Result<(), OutputError> {
    let expected = width as usize * height as usize * color.channel_count() as usize;
    if bytes.len() != expected {
        return Err(OutputError::Size { path: path.to_path_buf(), expected, found: bytes.len() });
    }
    let mut encoded = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut encoded),
        bytes,
        width,
        height,
        color.into(),
    )
    .map_err(|e| OutputError::Encode { path: path.to_path_buf(), format: "PNG", message: e.to_string() })?;
    write_bytes(path, &encoded)
}

/// Writes a single-channel float map (`width·height`, row-major) as a 32-bit
/// float OpenEXR file with one channel named `Z`.
pub fn write_exr_depth(path: &Path, width: u32, height: u32, values: &[f32]) -> Result<(), OutputError> {
    use exr::prelude::*;
    let (w, h) = (width as usize, height as usize);
    if values.len() != w * h {
        return Err(OutputError::Size { path: path.to_path_buf(), expected: w * h, found: values.len() });
    }
    let channel = AnyChannel::new("Z", FlatSamples::F32(values.to_vec()));
    let layer = Layer::new(
        (w, h),
        LayerAttributes::named("depth"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let image = Image::from_layer(layer);
    let mut encoded = std::io::Cursor::new(Vec::new());
    image.write().non_parallel().to_buffered(&mut encoded).map_err(|e| OutputError::Encode {
        path: path.to_path_buf(),
        format: "EXR",
        message: e.to_string(),
    })?;
    atomic_write(path, |w| w.write_all(encoded.get_ref()))
}

/// A value in [0, 1] as 8 bits, rounded (clamped outside).
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// The smallest and largest finite value (0, 0 when there is none).
pub fn finite_range(values: &[f32]) -> (f32, f32) {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo <= hi { (lo, hi) } else { (0.0, 0.0) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Makes `path` (a file or a folder) read-only, or writable again.
    fn set_readonly(path: &Path, on: bool) {
        let mut perms = std::fs::metadata(path).expect("stat").permissions();
        #[allow(clippy::permissions_set_readonly_false)]
        perms.set_readonly(on);
        std::fs::set_permissions(path, perms).expect("chmod");
    }

    /// An empty scratch folder of this test process, `gast-io-NAME-PID`.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("gast-io-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a scratch folder");
        dir
    }

    #[test]
    fn stale_temporaries_of_dead_processes_are_removed_and_live_ones_kept() {
        let dir = scratch("stale");
        // Beyond Linux's largest pid (2^22): no such process can run.
        let dead_file = dir.join(".scene.ply.tmp-99999999");
        let dead_dir = dir.join(".out-sog.tmp-99999998");
        let live = dir.join(".scene.ply.tmp-1"); // pid 1 always runs
        let own = temp_path(&dir.join("mine.ply"));
        let user = dir.join("notes.tmp-99999999"); // not hidden: not ours
        for f in [&dead_file, &live, &own, &user] {
            std::fs::write(f, b"x").expect("a temporary file");
        }
        std::fs::create_dir(&dead_dir).expect("a temporary file");
        std::fs::write(dead_dir.join("meta.json"), b"{}").expect("a temporary file");
        write_bytes(&dir.join("target.bin"), b"new").expect("a temporary file");
        assert!(!dead_file.exists() && !dead_dir.exists(), "stale temporaries remain");
        assert!(live.exists() && own.exists() && user.exists(), "a live, own or foreign file was removed");
        assert_eq!(std::fs::read(dir.join("target.bin")).expect("a temporary file"), b"new");
        assert_eq!(stale_pid(".a.ply.tmp-12"), Some(12));
        assert_eq!((stale_pid(".a.ply.tmp-"), stale_pid("a.ply.tmp-12"), stale_pid(".tmp-12")), (None, None, None));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn atomic_write_keeps_old_file_on_error() {
        let dir = scratch("keep");
        let path = dir.join("keep.txt");
        std::fs::write(&path, b"old contents").expect("seed file");
        let err = atomic_write(&path, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("simulated failure"))
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read(&path).expect("read back"), b"old contents");
        let leftovers: Vec<_> =
            std::fs::read_dir(&dir).expect("list").filter_map(|e| e.ok()).map(|e| e.file_name()).collect();
        assert_eq!(leftovers.len(), 1, "temporary file left behind: {leftovers:?}");
        atomic_write(&path, |w| w.write_all(b"new")).expect("write");
        assert_eq!(std::fs::read(&path).expect("read back"), b"new");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn files_that_belong_together_are_replaced_all_or_none() {
        let dir = scratch("all");
        let (a, b) = (dir.join("a.webp"), dir.join("meta.json"));
        std::fs::write(&a, b"old a").expect("seed file");
        std::fs::write(&b, b"old meta").expect("seed file");
        // The second file's temporary cannot be made (a folder holds its
        // name), as a full disk would refuse it after the first was written.
        let blocked = temp_path(&b);
        std::fs::create_dir(&blocked).expect("a folder");
        let (path, e) = replace_all(&[(a.clone(), b"new a"), (b.clone(), b"new meta")]).expect_err("a blocked write");
        assert_eq!(path, b, "the error names the file: {e}");
        assert_eq!(std::fs::read(&a).expect("read back"), b"old a", "the first file was replaced alone");
        assert_eq!(std::fs::read(&b).expect("read back"), b"old meta");
        assert!(!temp_path(&a).exists(), "the first file's temporary was left");
        std::fs::remove_dir(&blocked).expect("a folder");
        replace_all(&[(a.clone(), b"new a"), (b.clone(), b"new meta")]).expect("both written");
        assert_eq!(std::fs::read(&a).expect("read back"), b"new a");
        assert_eq!(std::fs::read(&b).expect("read back"), b"new meta");
        assert_eq!(std::fs::read_dir(&dir).expect("list").count(), 2, "a temporary file was left");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn an_image_past_the_decode_limit_is_said_with_its_size() {
        // A PNG header for 20,000 × 20,000 RGB pixels (1.12 GiB decoded), then no pixels.
        fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
            let body = [kind.as_slice(), data].concat();
            let crc = !body.iter().fold(!0u32, |c, &b| {
                (0..8).fold(c ^ u32::from(b), |c, _| if c & 1 == 1 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 })
            });
            [&(data.len() as u32).to_be_bytes()[..], &body, &crc.to_be_bytes()].concat()
        }
        let side = 20_000u32.to_be_bytes();
        let ihdr = [&side[..], &side, &[8, 2, 0, 0, 0]].concat();
        let png = [
            &b"\x89PNG\r\n\x1a\n"[..],
            &chunk(b"IHDR", &ihdr),
            &chunk(b"IDAT", &[0x78, 0x9c, 3, 0, 0, 0, 0, 1]),
            &chunk(b"IEND", &[]),
        ]
        .concat();
        let dir = scratch("big-image");
        let path = dir.join("big.png");
        std::fs::write(&path, png).expect("a PNG");
        let said = open_image(&path).expect_err("past the limit");
        assert_eq!(
            said,
            "a 20000x20000 image, which takes 1.12 GiB decoded, more than the 512 MiB one image may take here; \
             downscale it (to about 8,000 px on its longer side)"
        );
        // An image within the limit decodes.
        write_png_rgb(&dir.join("small.png"), 3, 2, &[0.5; 18]).expect("a PNG");
        assert_eq!(open_image(&dir.join("small.png")).expect("decodes").width(), 3);
        // A folder says so ("The image format could not be determined" before).
        assert_eq!(open_image(&dir).expect_err("a folder"), "a folder");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_read_only_file_is_refused_not_replaced() {
        let dir = scratch("ro");
        let path = dir.join("original.bin");
        std::fs::write(&path, b"original").expect("seed file");
        set_readonly(&path, true);
        let err = write_bytes(&path, b"new").expect_err("a read-only file is kept").to_string();
        assert!(err.contains("original.bin: expected a file that may be replaced, found a read-only one"), "{err}");
        assert_eq!(std::fs::read(&path).expect("read back"), b"original");
        assert_eq!(std::fs::read_dir(&dir).expect("list").count(), 1, "a temporary file was left");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_read_only_folder_is_not_written_in() {
        let dir = scratch("ro-dir");
        // A dead process's temporary (pid beyond Linux's 2^22): a refused write sweeps nothing either.
        let stale = dir.join(".old.bin.tmp-99999999");
        std::fs::write(&stale, b"left by a killed run").expect("a stale temporary");
        set_readonly(&dir, true);
        let said = format!("expected a folder that may be written in, found a read-only one, {}", dir.display());
        let err = write_bytes(&dir.join("new.bin"), b"new").expect_err("a read-only folder").to_string();
        assert!(err.contains(&said), "{err}");
        // A folder made inside it, however deep, is refused at the read-only one.
        let err = create_folder(dir.join("a/b")).expect_err("a read-only folder").to_string();
        assert!(err.contains(&said), "{err}");
        let err = write_bytes(&dir.join("a/b/new.bin"), b"new").expect_err("a read-only folder").to_string();
        assert!(err.contains(&said), "{err}");
        assert_eq!(std::fs::read_dir(&dir).expect("list").count(), 1, "something was written in the folder");
        assert!(stale.exists(), "a refused write swept the read-only folder");
        set_readonly(&dir, false);
        write_bytes(&dir.join("a/new.bin"), b"new").expect("a writable folder");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn png_and_exr_round_trip() {
        let dir = scratch("img");
        let (w, h) = (5u32, 3u32);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| i as f32 / 45.0).collect();
        write_png_rgb(&dir.join("a.png"), w, h, &rgb).expect("png");
        let back = image::open(dir.join("a.png")).expect("decode").to_rgb8();
        assert_eq!(back.dimensions(), (w, h));
        assert_eq!(back.as_raw()[7], to_u8(rgb[7]));
        let depth: Vec<f32> = (0..w * h).map(|i| 0.1 * i as f32).collect();
        write_exr_depth(&dir.join("d.exr"), w, h, &depth).expect("exr");
        let img = exr::prelude::read_first_flat_layer_from_file(dir.join("d.exr")).expect("read exr");
        let samples: Vec<f32> = img.layer_data.channel_data.list[0].sample_data.values_as_f32().collect();
        assert_eq!(samples, depth);
        assert!(matches!(write_png_rgb(&dir.join("b.png"), w, h, &rgb[1..]), Err(OutputError::Size { .. })));
        std::fs::remove_dir_all(&dir).ok();
    }
}
