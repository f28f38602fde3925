//! Finding the VGG weights on this machine, or fetching them once.
//!
//! Users should not have to know that the style losses need a 528 MB ImageNet
//! network. The lookup order is: a path the user gave (argument or
//! `GAST_WEIGHTS`), our cache (`$XDG_CACHE_HOME/gast`, else `~/.cache/gast`),
//! torch's hub cache (`$TORCH_HOME/hub/checkpoints`, else
//! `~/.cache/torch/hub/checkpoints`, where anyone who has used torchvision's
//! VGG already has the file), and only then a download of torchvision's file
//! into our cache. The download reports progress (the app draws a bar),
//! resumes a partial `.part` file with an HTTP Range request, checks the
//! sha256 prefix that torch puts in the file name (`vgg16-397923af.pth`: the
//! hash starts with `397923af`) and renames into place only when it matches,
//! so the cache never holds a damaged file.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use sha2::{Digest, Sha256};

use super::weights::WeightsError;

/// torchvision's VGG16 ImageNet weights, the reference implementation's network.
pub const DEFAULT_URL: &str = "https://download.pytorch.org/models/vgg16-397923af.pth";

/// torchvision file names that hold usable weights, looked for in both caches.
const KNOWN_FILES: [&str; 2] = ["vgg16-397923af.pth", "vgg19-dcbb9e9d.pth"];

/// Where to look for weights and where to fetch them from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WeightsLocations {
    /// A file the user named; when set, nothing else is tried.
    pub explicit: Option<PathBuf>,
    /// Our cache folder, where downloads go.
    pub cache_dir: Option<PathBuf>,
    /// torch's hub checkpoint folder, read only.
    pub torch_hub_dir: Option<PathBuf>,
    /// Address of the file to download when nothing is found; its last path
    /// segment is the cached file's name and carries the sha256 prefix.
    pub url: String,
}

impl WeightsLocations {
    /// The standard locations: `explicit` or `GAST_WEIGHTS`, the user cache,
    /// torch's hub cache, and `GAST_WEIGHTS_URL` or [`DEFAULT_URL`].
    pub fn from_env(explicit: Option<&Path>) -> Self {
        let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
        let home = var("HOME");
        let cache_home = var("XDG_CACHE_HOME").or_else(|| home.as_ref().map(|h| h.join(".cache")));
        Self {
            explicit: explicit.map(Path::to_path_buf).or_else(|| var("GAST_WEIGHTS")),
            cache_dir: cache_home.as_ref().map(|c| c.join("gast")),
            torch_hub_dir: var("TORCH_HOME")
                .or_else(|| cache_home.as_ref().map(|c| c.join("torch")))
                .map(|t| t.join("hub").join("checkpoints")),
            url: std::env::var("GAST_WEIGHTS_URL").ok().filter(|u| !u.is_empty()).unwrap_or_else(|| DEFAULT_URL.into()),
        }
    }

    /// The first weights file already on disk, without downloading.
    pub fn find(&self) -> Result<PathBuf, WeightsError> {
        if let Some(p) = &self.explicit {
            if p.is_dir() {
                let expected = "a VGG weights file (.pth or .safetensors)";
                return Err(WeightsError::format(p, expected, "a folder"));
            }
            return if p.is_file() { Ok(p.clone()) } else { Err(WeightsError::NotFound { searched: vec![p.clone()] }) };
        }
        let first = file_name(&self.url);
        let mut names = vec![first];
        names.extend(KNOWN_FILES.into_iter().filter(|s| *s != first));
        let mut searched = Vec::new();
        for dir in [&self.cache_dir, &self.torch_hub_dir].into_iter().flatten() {
            for name in &names {
                let p = dir.join(name);
                if p.is_file() {
                    return Ok(p);
                }
                searched.push(p);
            }
        }
        Err(WeightsError::NotFound { searched })
    }

    /// [`WeightsLocations::find`], else download [`WeightsLocations::url`] into
    /// the cache folder, reporting `(bytes so far, total if known)`.
    pub fn resolve(&self, progress: &mut dyn FnMut(u64, Option<u64>)) -> Result<PathBuf, WeightsError> {
        match self.find() {
            Ok(p) => Ok(p),
            Err(e) if self.explicit.is_some() => Err(e),
            Err(e) => match &self.cache_dir {
                Some(dir) => download(&self.url, dir, progress),
                None => Err(e),
            },
        }
    }
}

/// Finds the VGG weights, downloading them once if needed (see the module docs).
pub fn resolve_weights(
    explicit: Option<&Path>,
    progress: &mut dyn FnMut(u64, Option<u64>),
) -> Result<PathBuf, WeightsError> {
    WeightsLocations::from_env(explicit).resolve(progress)
}

fn file_name(url: &str) -> &str {
    url.rsplit('/').next().unwrap_or(url).split(['?', '#']).next().unwrap_or(url)
}

/// The sha256 prefix torch's convention puts in a file name: the hex digits
/// after the last `-` of the stem (`vgg16-397923af.pth` → `397923af`).
pub fn hash_prefix(name: &str) -> Option<&str> {
    let stem = name.split('.').next()?;
    let (_, tail) = stem.rsplit_once('-')?;
    (tail.len() >= 8 && tail.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))).then_some(tail)
}

/// Downloads `url` into `dir` (named after its last path segment), resuming
/// `<name>.part` if an earlier attempt left one, and checks the name's sha256
/// prefix before the atomic rename. Returns the final path.
pub fn download(url: &str, dir: &Path, progress: &mut dyn FnMut(u64, Option<u64>)) -> Result<PathBuf, WeightsError> {
    download_verified(url, dir, None, progress)
}

/// [`download`] with the sha256 (or a prefix of it) to check: `expected` when
/// given, else the prefix in the file name, else the `X-Linked-Etag` header
/// by which the Hugging Face hub announces the sha256 of the files it serves.
pub fn download_verified(
    url: &str,
    dir: &Path,
    expected: Option<&str>,
    progress: &mut dyn FnMut(u64, Option<u64>),
) -> Result<PathBuf, WeightsError> {
    let name = file_name(url);
    if name.is_empty() {
        return Err(WeightsError::Download { url: url.into(), detail: "the address names no file".into() });
    }
    std::fs::create_dir_all(dir).map_err(|e| WeightsError::io(dir, e))?;
    let dest = dir.join(name);
    let part = dir.join(format!("{name}.part"));
    let fail = |detail: String| WeightsError::Download { url: url.into(), detail };

    // Hash what an earlier attempt already has, then ask for the rest.
    let mut hasher = Sha256::new();
    let mut have = 0u64;
    if let Ok(mut f) = File::open(&part) {
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = f.read(&mut buf).map_err(|e| WeightsError::io(&part, e))?;
            if n == 0 {
                break;
            }
            hasher.update(&buf[..n]);
            have += n as u64;
        }
    }
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_connect(Some(Duration::from_secs(20)))
        .timeout_recv_response(Some(Duration::from_secs(60)))
        .build()
        .into();
    let mut request = agent.get(url);
    if have > 0 {
        request = request.header("Range", format!("bytes={have}-"));
    }
    let response = request.call().map_err(|e| fail(describe(&e)))?;
    let status = response.status().as_u16();
    let length = response.body().content_length();
    let range_start = response
        .headers()
        .get("content-range")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("bytes "))
        .and_then(|v| v.split('-').next())
        .and_then(|v| v.trim().parse::<u64>().ok());
    let announced = response
        .headers()
        .get("x-linked-etag")
        .and_then(|v| v.to_str().ok())
        .map(|v| v.trim().trim_start_matches("W/").trim_matches('"').to_ascii_lowercase())
        .filter(|v| v.len() == 64 && v.bytes().all(|b| b.is_ascii_hexdigit()));
    let (append, total) = match status {
        206 if range_start.is_some_and(|s| s != have) => {
            return Err(fail(format!("asked for bytes from {have}, the server sent from {range_start:?}")));
        }
        206 => (true, length.map(|l| l + have)),
        200 => (false, length),
        416 if have > 0 => (true, Some(have)), // the part is already complete
        s => return Err(fail(format!("the server answered HTTP {s}"))),
    };
    if !append {
        hasher = Sha256::new();
        have = 0;
    }
    let mut out = OpenOptions::new()
        .create(true)
        .write(true)
        .append(append)
        .truncate(!append)
        .open(&part)
        .map_err(|e| WeightsError::io(&part, e))?;
    progress(have, total);
    if status != 416 {
        let mut body = response.into_body().into_reader();
        let mut buf = vec![0u8; 1 << 16];
        loop {
            let n = match body.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => n,
                Err(e) => {
                    let _ = out.flush();
                    return Err(fail(format!(
                        "the connection broke after {have} bytes ({e}); the partial file {} is kept and the next attempt resumes it",
                        part.display()
                    )));
                }
            };
            out.write_all(&buf[..n]).map_err(|e| WeightsError::io(&part, e))?;
            hasher.update(&buf[..n]);
            have += n as u64;
            progress(have, total);
        }
    }
    out.sync_all().map_err(|e| WeightsError::io(&part, e))?;
    drop(out);
    if let Some(t) = total.filter(|&t| t != have) {
        return Err(fail(format!("expected {t} bytes, received {have}; the next attempt resumes {}", part.display())));
    }
    let digest: String = hasher.finalize().iter().map(|b| format!("{b:02x}")).collect();
    let expected = expected.map(str::to_ascii_lowercase).or_else(|| hash_prefix(name).map(String::from)).or(announced);
    if let Some(expected) = expected
        && !digest.starts_with(&expected)
    {
        let _ = std::fs::remove_file(&part);
        return Err(WeightsError::Checksum { url: url.into(), expected, found: digest });
    }
    std::fs::rename(&part, &dest).map_err(|e| WeightsError::io(&dest, e))?;
    Ok(dest)
}

/// A one-line reason for a failed request, with the usual causes spelled out.
fn describe(e: &ureq::Error) -> String {
    match e {
        ureq::Error::Io(io) if io.kind() == std::io::ErrorKind::ConnectionRefused => {
            format!("could not connect: the server refused the connection ({io})")
        }
        ureq::Error::HostNotFound => "could not resolve the host name (offline?)".into(),
        ureq::Error::Timeout(t) => format!("timed out ({t})"),
        other => other.to_string(),
    }
}

#[cfg(test)]
#[path = "download_tests.rs"]
pub(crate) mod tests;
