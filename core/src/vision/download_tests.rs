//! The download path against a tiny HTTP/1.1 server on 127.0.0.1 that each
//! test starts itself: full download, resume after a broken connection,
//! checksum mismatch, server down, and the lookup order.

use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use super::*;

/// Serves `body` for every path except `/missing` (404); honours `Range:
/// bytes=N-`; the first `cut_first` responses stop after half the bytes.
/// Records each request's Range header.
pub(crate) struct Server {
    pub port: u16,
    ranges: Arc<Mutex<Vec<Option<u64>>>>,
}

fn serve(body: Vec<u8>, cut_first: usize) -> Server {
    serve_routes(vec![Route { path: String::new(), body, headers: String::new() }], cut_first)
}

/// One file the test server knows: the first route whose `path` the request
/// line contains is served, with `headers` (`Name: value\r\n` lines) added.
pub(crate) struct Route {
    pub path: String,
    pub body: Vec<u8>,
    pub headers: String,
}

/// [`serve`] with several files.
pub(crate) fn serve_routes(routes: Vec<Route>, cut_first: usize) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind a local port");
    let port = listener.local_addr().map(|a| a.port()).unwrap_or(0);
    let ranges = Arc::new(Mutex::new(Vec::new()));
    let log = ranges.clone();
    std::thread::spawn(move || {
        for (i, stream) in listener.incoming().enumerate() {
            let Ok(mut stream) = stream else { continue };
            let mut reader = BufReader::new(stream.try_clone().expect("clone stream"));
            let mut first = String::new();
            let _ = reader.read_line(&mut first);
            let mut start = None;
            loop {
                let mut line = String::new();
                if reader.read_line(&mut line).unwrap_or(0) == 0 || line.trim().is_empty() {
                    break;
                }
                let lower = line.to_ascii_lowercase();
                if let Some(v) = lower.strip_prefix("range: bytes=") {
                    start = v.trim().trim_end_matches('-').parse::<u64>().ok();
                }
            }
            log.lock().map(|mut l| l.push(start)).ok();
            let Some(route) = routes.iter().find(|r| first.contains(&r.path)).filter(|_| !first.contains("/missing"))
            else {
                let _ = stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n");
                continue;
            };
            let (body, extra) = (&route.body, &route.headers);
            let s = start.unwrap_or(0) as usize;
            let head = match start {
                Some(_) if s >= body.len() => {
                    let _ = write!(
                        stream,
                        "HTTP/1.1 416 Range Not Satisfiable\r\nContent-Range: bytes */{}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
                        body.len()
                    );
                    continue;
                }
                Some(_) => format!(
                    "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes {s}-{}/{}\r\nContent-Length: {}\r\n{extra}Connection: close\r\n\r\n",
                    body.len() - 1,
                    body.len(),
                    body.len() - s
                ),
                None => {
                    format!("HTTP/1.1 200 OK\r\nContent-Length: {}\r\n{extra}Connection: close\r\n\r\n", body.len())
                }
            };
            let _ = stream.write_all(head.as_bytes());
            let end = if i < cut_first { s + (body.len() - s) / 2 } else { body.len() };
            let _ = stream.write_all(&body[s..end]);
            let _ = stream.flush();
        }
    });
    Server { port, ranges }
}

fn body() -> Option<Vec<u8>> {
    let base = std::env::var_os("GAST_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let p = base.join("data/weights/vgg19-conv3.safetensors");
    match std::fs::read(&p) {
        Ok(b) => Some(b),
        Err(_) => {
            eprintln!("\n!!!!!!!! SKIPPED: shared data file {} is absent !!!!!!!!\n", p.display());
            None
        }
    }
}

pub(crate) fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gast-dl-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// The shared file's sha256 begins with e61f7f6b (data/README.md).
const GOOD_NAME: &str = "vgg19-conv3-e61f7f6b.safetensors";

#[test]
fn full_download_checks_and_renames() -> Result<(), WeightsError> {
    let Some(body) = body() else { return Ok(()) };
    let server = serve(body.clone(), 0);
    let dir = temp_dir("full");
    let url = format!("http://127.0.0.1:{}/models/{GOOD_NAME}", server.port);
    let mut seen = Vec::new();
    let path = download(&url, &dir, &mut |done, total| seen.push((done, total)))?;
    assert_eq!(path, dir.join(GOOD_NAME));
    assert!(std::fs::read(&path).ok() == Some(body.clone()), "downloaded bytes differ");
    assert!(!dir.join(format!("{GOOD_NAME}.part")).exists(), "the .part file must be gone");
    assert_eq!(seen.last(), Some(&(body.len() as u64, Some(body.len() as u64))));
    assert!(seen.windows(2).all(|w| w[0].0 <= w[1].0), "progress must not go backwards");
    // Resolution now finds the cached file without asking the server again.
    let loc = WeightsLocations { explicit: None, cache_dir: Some(dir.clone()), torch_hub_dir: None, url };
    let before = server.ranges.lock().map(|r| r.len()).unwrap_or(0);
    assert_eq!(loc.resolve(&mut |_, _| {})?, path);
    assert_eq!(server.ranges.lock().map(|r| r.len()).unwrap_or(0), before);
    crate::vision::VggWeights::load(&path)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

#[test]
fn broken_connection_keeps_part_and_next_attempt_resumes() -> Result<(), WeightsError> {
    let Some(body) = body() else { return Ok(()) };
    let server = serve(body.clone(), 1);
    let dir = temp_dir("resume");
    let url = format!("http://127.0.0.1:{}/{GOOD_NAME}", server.port);
    let loc = WeightsLocations { explicit: None, cache_dir: Some(dir.clone()), torch_hub_dir: None, url };
    let err = loc.resolve(&mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    println!("broken transfer: {err}");
    assert!(err.contains("resume"), "a broken transfer should say it will resume: {err}");
    let part = dir.join(format!("{GOOD_NAME}.part"));
    let kept = std::fs::metadata(&part).map(|m| m.len()).unwrap_or(0);
    assert!(kept > 0 && kept < body.len() as u64, "partial file of {kept} bytes");
    let mut first_report = None;
    let path = loc.resolve(&mut |done, _| {
        first_report.get_or_insert(done);
    })?;
    assert_eq!(first_report, Some(kept), "progress starts at the resumed size");
    assert!(std::fs::read(&path).ok() == Some(body), "resumed bytes differ");
    let ranges = server.ranges.lock().map(|r| r.clone()).unwrap_or_default();
    assert_eq!(ranges, vec![None, Some(kept)], "second request must ask for the rest");
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

#[test]
fn checksum_mismatch_leaves_nothing() {
    let Some(body) = body() else { return };
    let server = serve(body, 0);
    let dir = temp_dir("badsum");
    let url = format!("http://127.0.0.1:{}/vgg19-conv3-deadbeef.safetensors", server.port);
    let err = download(&url, &dir, &mut |_, _| {}).err();
    println!("checksum: {}", err.as_ref().map(|e| e.to_string()).unwrap_or_default());
    assert!(
        matches!(&err, Some(WeightsError::Checksum { expected, found, .. }) if expected == "deadbeef" && found.starts_with("e61f7f6b")),
        "{err:?}"
    );
    let left: Vec<_> = std::fs::read_dir(&dir).map(|d| d.flatten().map(|e| e.path()).collect()).unwrap_or_default();
    assert!(left.is_empty(), "cache should be empty, holds {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn server_down_and_http_errors_are_clear() {
    let port = TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).unwrap_or(9);
    let dir = temp_dir("down");
    let url = format!("http://127.0.0.1:{port}/{GOOD_NAME}");
    let err = download(&url, &dir, &mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    println!("server down: {err}");
    assert!(err.contains(&url) && err.contains("refused") && err.contains("vgg16-397923af.pth"), "{err}");

    let server = serve(Vec::new(), 0);
    let url = format!("http://127.0.0.1:{}/missing", server.port);
    let err = download(&url, &dir, &mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("HTTP 404"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn lookup_order_and_explicit_paths() -> Result<(), Box<dyn std::error::Error>> {
    let root = temp_dir("order");
    let (cache, hub) = (root.join("gast"), root.join("hub"));
    std::fs::create_dir_all(&cache)?;
    std::fs::create_dir_all(&hub)?;
    let mut loc = WeightsLocations {
        explicit: None,
        cache_dir: Some(cache.clone()),
        torch_hub_dir: Some(hub.clone()),
        url: "http://127.0.0.1:9/vgg16-397923af.pth".into(),
    };
    std::fs::write(hub.join("vgg19-dcbb9e9d.pth"), b"x")?;
    assert_eq!(loc.find()?, hub.join("vgg19-dcbb9e9d.pth"));
    std::fs::write(hub.join("vgg16-397923af.pth"), b"x")?;
    assert_eq!(loc.find()?, hub.join("vgg16-397923af.pth"));
    std::fs::write(cache.join("vgg16-397923af.pth"), b"x")?;
    assert_eq!(loc.find()?, cache.join("vgg16-397923af.pth"));
    loc.explicit = Some(root.join("nope.pth"));
    let err = loc.resolve(&mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    println!("explicit missing: {err}");
    assert!(err.contains("nope.pth") && err.contains("GAST_WEIGHTS"), "{err}");
    // A folder named as the weights is said to be one.
    loc.explicit = Some(hub.clone());
    let err = loc.resolve(&mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.ends_with("expected a VGG weights file (.pth or .safetensors), found a folder"), "{err}");
    loc.explicit = None;
    loc.cache_dir = None;
    loc.torch_hub_dir = None;
    assert!(matches!(loc.resolve(&mut |_, _| {}), Err(WeightsError::NotFound { .. })));
    assert_eq!(hash_prefix("vgg16-397923af.pth"), Some("397923af"));
    assert_eq!(hash_prefix("weights.pth"), None);
    let _ = std::fs::remove_dir_all(&root);
    Ok(())
}
