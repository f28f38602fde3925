//! The `gast` binary end to end on the shared data: render, golden checks,
//! a short stylization, and bad input that must fail with a clear message.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use gast_tests::{shared_dir, shared_file};

fn gast(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gast")).args(args).output().expect("run gast")
}

fn temp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gast-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn help_lists_every_subcommand() {
    let o = gast(&["--help"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    for sub in ["render", "stylize", "check", "bench"] {
        assert!(text.contains(sub), "--help does not mention {sub}:\n{text}");
    }
}

#[test]
fn render_writes_colour_and_depth_of_every_view() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("render");
    let o = gast(&["render", s(&scene), "--out", s(&out), "--views", "3", "--size", "96"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for v in 0..3 {
        let png = image::open(out.join(format!("orbit_{v:03}.png"))).expect("colour PNG").to_rgb8();
        assert_eq!(png.dimensions(), (96, 96));
        let lit = png.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count();
        assert!(lit > 200, "view {v}: only {lit} lit pixels");
        assert!(out.join(format!("orbit_{v:03}_depth.exr")).is_file());
        assert!(out.join(format!("orbit_{v:03}_depth.png")).is_file());
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn check_golden_passes_on_the_shared_files_and_fails_on_others() {
    let dir = shared_dir().join("golden");
    let Some(weights) = shared_file("data/weights/vgg19-conv3.safetensors") else { return };
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "safetensors"))
                .map(|p| p.display().to_string())
                .collect()
        })
        .unwrap_or_default();
    if files.is_empty() {
        eprintln!("!!!!!!!! SKIPPED: no golden files under {} !!!!!!!!", dir.display());
        return;
    }
    files.sort();
    let mut args = vec!["check", "golden", "--weights", s(&weights)];
    args.extend(files.iter().map(String::as_str));
    let o = gast(&args);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}\n{}", stderr(&o));
    assert!(text.contains(" 0 failed"), "{text}");
    // A file that is not a golden file: non-zero exit, the file named.
    let o = gast(&["check", "golden", s(&weights)]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("vgg19-conv3.safetensors"));
}

#[test]
fn stylize_writes_a_scene_renders_and_a_report() {
    let (Some(scene), Some(style), Some(weights)) = (
        shared_file("data/scenes/guitar.compressed.ply"),
        shared_file("data/styles/block2.jpg"),
        shared_file("data/weights/vgg19-conv3.safetensors"),
    ) else {
        return;
    };
    let out = temp("stylize");
    let o = gast(&[
        "stylize",
        s(&scene),
        s(&style),
        "--weights",
        s(&weights),
        "--out",
        s(&out),
        "--cycles",
        "2",
        "--steps-per-cycle",
        "3",
        "--ratio-geo",
        "0.67",
        "--resolution",
        "64",
        "--texture-scale",
        "64",
        "--views",
        "4",
        "--preview-views",
        "1",
        "--depth-provider",
        "heuristic",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let input = gast_core::scene::load(&scene).expect("input scene");
    let result = gast_core::scene::load(out.join("stylized.ply")).expect("stylized scene loads");
    assert_eq!(result.len(), input.len(), "the export keeps every Gaussian");
    let moved = input.means.iter().zip(&result.means).filter(|(a, b)| a != b).count();
    assert!(moved > 1000, "geometry steps moved only {moved} means");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("json");
    let steps = report["steps"].as_array().expect("steps");
    assert_eq!(steps.len(), 6);
    assert_eq!(steps.iter().filter(|s| s["phase"] == "color").count(), 2);
    assert!(steps.iter().all(|s| s["losses"]["total"].as_f64().is_some_and(f64::is_finite)));
    assert!(report["gaussians_optimised"].as_u64().expect("count") <= input.len() as u64);
    for f in ["view0_before.png", "view0_after.png", "view0_after_depth.exr", "style_depth.png", "style_edge.png"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn bad_inputs_fail_with_the_file_named_and_keep_existing_outputs() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("bad");
    std::fs::create_dir_all(&out).expect("dir");
    // A style that is not an image.
    let bogus = out.join("style.jpg");
    std::fs::write(&bogus, b"not a jpeg").expect("write");
    let o = gast(&["stylize", s(&scene), s(&bogus), "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("style.jpg"), "{}", stderr(&o));
    // A scene that is not a scene.
    let o = gast(&["render", s(&bogus), "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("style.jpg") && stderr(&o).contains("expected"), "{}", stderr(&o));
    // Invalid parameters are refused before any work.
    let o = gast(&["stylize", s(&scene), s(&bogus), "--ratio-geo", "1.5", "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("ratio_geo"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&bogus).expect("kept"), b"not a jpeg");
    std::fs::remove_dir_all(&out).ok();
}
