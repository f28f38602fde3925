//! `tools/gpu-check run --dry-run`: the path a lent GPU machine runs, taken
//! here on whatever adapter there is (lavapipe in CI) at tiny sizes, so that a
//! broken step, a missing file or a changed flag shows before a loan.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn the_gpu_check_dry_run_measures_every_step_it_can_here() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let shared = std::env::var_os("GAST_SHARED").map_or_else(|| root.join("../shared"), PathBuf::from);
    if !shared.join("data/weights/vgg19-conv3.safetensors").exists() {
        eprintln!("\n!!!!!!!! SKIPPED: no shared data at {} (set GAST_SHARED) !!!!!!!!\n", shared.display());
        return;
    }
    let out = std::env::temp_dir().join(format!("gast-gpu-check-{}", std::process::id()));
    std::fs::create_dir_all(&out).expect("temp dir");
    let run = Command::new("bash")
        .arg(root.join("tools/gpu-check"))
        .args(["run", "--dry-run", "--bin", env!("CARGO_BIN_EXE_gast"), "--data"])
        .arg(&shared)
        .env("OUT", &out)
        .env("GPU_CHECK_DEADLINE", "600")
        .output()
        .expect("bash runs tools/gpu-check");
    let log = String::from_utf8_lossy(&run.stdout);
    let tail: String = log.lines().rev().take(40).collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>().join("\n");
    assert!(run.status.success(), "tools/gpu-check run --dry-run failed: {}\n{tail}", run.status);
    println!("{tail}");
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("gpu-check.json")).expect("gpu-check.json written"))
            .expect("gpu-check.json parses");
    for step in [
        "golden",
        "guitar_32",
        "guitar_48",
        "full_guitar",
        "guitar_64",
        "compare_assign",
        "compare_sliced_depth",
        "playbot_32",
        "studio",
    ] {
        assert_eq!(doc["steps"][step]["rc"], 0, "step {step}: {}\n{tail}", doc["steps"][step]);
    }
    let figures = doc["figures"].as_array().expect("figures");
    let golden = figures.iter().find(|f| f["what"] == "golden files, GPU engine").expect("golden figure");
    assert_eq!(golden["ok"], true, "{golden}");
    let step = figures.iter().find(|f| f["what"] == "guitar step at 48 px").expect("step figure");
    assert!(step["value"].as_f64().is_some_and(|ms| ms > 0.0), "{step}");
    // The studio drawn headless (`gast studio --headless`), at the window size the step asks for.
    let shot = image::open(out.join("studio.png")).expect("the headless studio's screenshot").to_rgb8();
    assert_eq!((shot.width(), shot.height()), (1600, 1000), "the studio's screenshot");
    let table = std::fs::read_to_string(out.join("gpu-check.md")).expect("gpu-check.md");
    assert!(table.contains("| what | measured | target | notes |"), "{table}");
    std::fs::remove_dir_all(&out).ok();
}
