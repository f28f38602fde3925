//! The depth network against the golden reference, and the loader's errors.

use super::*;
use crate::vision::weights::tests::shared;

#[test]
fn input_size_follows_the_image_processor() {
    // Landscape: the height goes to 518, the width follows and snaps to 14.
    assert_eq!(input_size(480, 640, 518, 14), (518, 686));
    // Portrait and square.
    assert_eq!(input_size(1000, 500, 518, 14), (1036, 518));
    assert_eq!(input_size(256, 256, 518, 14), (518, 518));
}

#[test]
fn golden_forward_matches() -> Result<(), DepthModelError> {
    let Some(p) = shared("golden/depth/depth_seed1.safetensors") else { return Ok(()) };
    let model = DepthAnything::load_with_metadata_config(&p)?;
    let ck = Checkpoint::read(&p)?;
    let x = ck.take("input_pixel_values", &[1, 3, 70, 98])?;
    let expected = ck.take("out_predicted_depth", &[1, 70, 98])?;
    let out = model.forward(&x, 70, 98);
    let max_ref = expected.iter().fold(0f32, |m, v| m.max(v.abs()));
    let err = out.iter().zip(&expected).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(max_ref > 0.0 && err <= 1e-4 * max_ref, "max abs error {err} against max |ref| {max_ref}");
    Ok(())
}

#[test]
fn preprocess_reads_a_style_in_place_as_its_f32_copy() -> Result<(), Box<dyn std::error::Error>> {
    // A run hands the network the style's 8-bit pixels (a 12,000-px style's
    // f32 copy took 1.6 GiB); the input must be the copy's to the bit.
    let (Some(p), Some(style)) = (shared("golden/depth/depth_seed1.safetensors"), shared("data/styles/hydrangea.jpg"))
    else {
        return Ok(());
    };
    let model = DepthAnything::load_with_metadata_config(&p)?;
    let style = crate::session::StyleImage::open(&style)?;
    let (h, w) = (style.height, style.width);
    let (ih, iw) = input_size(h, w, INPUT_SIZE, model.config().patch_size);
    let from_bytes = model.preprocess(&style.rgb[..], h, w, ih, iw);
    assert_eq!(from_bytes.len(), 3 * ih * iw);
    assert!(from_bytes == model.preprocess(&style.to_f32(), h, w, ih, iw), "the inputs differ");
    Ok(())
}

/// The golden file's bytes with its header edited by `edit` (data unchanged).
fn edited(golden: &[u8], edit: impl FnOnce(&mut serde_json::Map<String, serde_json::Value>)) -> Vec<u8> {
    let n = u64::from_le_bytes(golden[..8].try_into().unwrap_or([0; 8])) as usize;
    let mut header: serde_json::Map<String, serde_json::Value> =
        serde_json::from_slice(&golden[8..8 + n]).unwrap_or_default();
    edit(&mut header);
    let text = serde_json::to_vec(&header).unwrap_or_default();
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend(text);
    out.extend_from_slice(&golden[8 + n..]);
    out
}

/// Writes `bytes` as `name` in a fresh temporary folder and returns the load error.
fn load_error(tag: &str, name: &str, bytes: &[u8], config: Option<&str>) -> String {
    let dir = crate::vision::download::tests::temp_dir(&format!("depth-{tag}"));
    let _ = std::fs::create_dir_all(&dir);
    let p = dir.join(name);
    let _ = std::fs::write(&p, bytes);
    if let Some(c) = config {
        let _ = std::fs::write(dir.join("config.json"), c);
    }
    let msg = match DepthAnything::load_path(&p) {
        Ok(_) => "loaded without error".to_string(),
        Err(e) => e.to_string(),
    };
    let _ = std::fs::remove_dir_all(&dir);
    msg
}

#[test]
fn loader_errors_name_the_file_and_the_tensor() {
    let Some(p) = shared("golden/depth/depth_seed1.safetensors") else { return };
    let Ok(golden) = std::fs::read(&p) else { panic!("cannot read {}", p.display()) };
    let config = Checkpoint::read(&p).ok().and_then(|c| c.metadata.get("config").cloned()).unwrap_or_default();

    // A tensor left out.
    let name = "backbone.encoder.layer.2.mlp.fc1.weight";
    let missing = edited(&golden, |h| {
        h.remove(name);
    });
    let e = load_error("missing", "model.safetensors", &missing, None);
    assert!(e.contains("model.safetensors") && e.contains(name) && e.contains("missing"), "{e}");

    // A misnamed tensor: the message shows the name the file has instead.
    let wrong = "backbone.encoder.layer.2.mlp.fc_1.weight";
    let misnamed = edited(&golden, |h| {
        if let Some(v) = h.remove(name) {
            h.insert(wrong.into(), v);
        }
    });
    let e = load_error("misnamed", "model.safetensors", &misnamed, None);
    assert!(e.contains(name) && e.contains(wrong), "{e}");

    // config.json that disagrees with the weights: the neck is wider than the file's.
    let wider = config.replace(
        "\"neck_hidden_sizes\": [\n    8,\n    16,\n    24,\n    32\n  ]",
        "\"neck_hidden_sizes\": [8, 16, 24, 40]",
    );
    assert_ne!(wider, config, "the golden config's layout changed; update this test");
    let e = load_error("shape", "model.safetensors", &golden, Some(&wider));
    assert!(
        e.contains("model.safetensors")
            && e.contains("neck.reassemble_stage.layers.3.resize.weight")
            && e.contains("[40, 40, 3, 3]")
            && e.contains("[32, 32, 3, 3]"),
        "{e}"
    );

    // A truncated download.
    let cut = &golden[..golden.len() / 2];
    let e = load_error("truncated", "model.safetensors", cut, Some(&config));
    assert!(e.contains("model.safetensors") && e.contains("truncated") && e.contains("tensor `"), "{e}");

    // Not a safetensors file at all, and an unreadable config.
    let e = load_error("garbage", "model.safetensors", b"\x05\x00\x00\x00\x00\x00\x00\x00{oops", Some(&config));
    assert!(e.contains("model.safetensors") && e.contains("expected a safetensors file"), "{e}");
    let e = load_error("config", "model.safetensors", &golden, Some("{\"neck_hidden_sizes\": \"wide\"}"));
    assert!(e.contains("config.json") && e.contains("config"), "{e}");
}

#[test]
fn lookup_order_and_download_from_a_local_server() -> Result<(), Box<dyn std::error::Error>> {
    use crate::vision::download::tests::{Route, serve_routes, temp_dir};
    use sha2::{Digest, Sha256};
    let Some(p) = shared("golden/depth/depth_seed1.safetensors") else { return Ok(()) };
    let weights = std::fs::read(&p)?;
    let config = Checkpoint::read(&p)?.metadata.get("config").cloned().unwrap_or_default();
    let sha: String = Sha256::digest(&weights).iter().map(|b| format!("{b:02x}")).collect();
    let route = |path: &str, body: Vec<u8>, headers: String| Route { path: path.into(), body, headers };

    // Nothing on disk: both files are fetched into the cache and load.
    let root = temp_dir("depth-resolve");
    let server = serve_routes(
        vec![
            route("/config.json", config.clone().into_bytes(), String::new()),
            route("/model.safetensors", weights.clone(), format!("X-Linked-Etag: \"{sha}\"\r\n")),
        ],
        0,
    );
    let locations = DepthModelLocations {
        explicit: None,
        cache_dir: Some(root.join("cache")),
        hub_dir: Some(root.join("hub")),
        base_url: format!("http://127.0.0.1:{}/repo/resolve/main", server.port),
    };
    assert!(locations.find().is_err());
    let mut last = (0, None);
    let got = locations.resolve(&mut |a, b| last = (a, b))?;
    assert_eq!(got, root.join("cache").join("depth-anything-v2-small"));
    assert_eq!(last, (weights.len() as u64, Some(weights.len() as u64)));
    assert!(DepthAnything::load_path(&got).is_ok());

    // A hub snapshot is found without the cache; an explicit path wins over both.
    let snap = root.join("hub/models--depth-anything--Depth-Anything-V2-Small-hf/snapshots/abc123");
    std::fs::create_dir_all(&snap)?;
    std::fs::write(snap.join("model.safetensors"), &weights)?;
    std::fs::write(snap.join("config.json"), &config)?;
    let hub_only = DepthModelLocations { cache_dir: Some(root.join("elsewhere")), ..locations.clone() };
    assert_eq!(hub_only.find()?, snap);
    let explicit = DepthModelLocations { explicit: Some(p.clone()), ..locations.clone() };
    assert_eq!(explicit.find()?, p);
    let absent = DepthModelLocations { explicit: Some(root.join("nope")), ..locations.clone() };
    let e = absent.resolve(&mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(e.contains("nope") && e.contains("GAST_DEPTH_MODEL"), "{e}");

    // A server whose announced sha256 disagrees: nothing lands in the cache.
    let bad = serve_routes(
        vec![
            route("/config.json", config.into_bytes(), String::new()),
            route("/model.safetensors", weights, format!("X-Linked-Etag: \"{}\"\r\n", "0".repeat(64))),
        ],
        0,
    );
    let fresh = DepthModelLocations {
        cache_dir: Some(root.join("cache2")),
        hub_dir: None,
        base_url: format!("http://127.0.0.1:{}/r", bad.port),
        ..locations
    };
    let e = fresh.resolve(&mut |_, _| {}).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(e.contains("sha256"), "{e}");
    assert!(!root.join("cache2/depth-anything-v2-small/model.safetensors").exists());
    let _ = std::fs::remove_dir_all(&root);
    Ok(())
}
