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
        // About 310 s on a quiet 2-core machine on 2026-12-03 (363 s before its first bench
        // timed each part once and full_guitar took 4 views; 500 s before its benches other
        // than the first left out the per-part timings); beside another job it passed 900 s.
        .env("GPU_CHECK_DEADLINE", "1500")
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
        "compare_palette",
        "compare_relief",
        "relief_check",
        "pairing",
        "compare_sliced_depth",
        "playbot_32",
        "cpu_threads_1",
        "cpu_threads_2",
        "studio",
    ] {
        assert_eq!(doc["steps"][step]["rc"], 0, "step {step}: {}\n{tail}", doc["steps"][step]);
    }
    let figures = doc["figures"].as_array().expect("figures");
    let golden = figures.iter().find(|f| f["what"] == "golden files, GPU engine").expect("golden figure");
    assert_eq!(golden["ok"], true, "{golden}");
    // The relief's arms, each against the run without it.
    for arm in ["relief 8 px", "relief 8 px + phase leak"] {
        let what = format!("{arm}, step time with / without");
        let f = figures.iter().find(|f| f["what"] == what.as_str()).unwrap_or_else(|| panic!("{what}\n{tail}"));
        assert!(f["value"].as_f64().is_some_and(|r| r > 0.0), "{f}");
    }
    // The relief's forward on this adapter against the CPU engine's.
    let what = "depth relief 8 px + phase leak, GPU against the CPU engine: first step's GCFM, relative difference";
    let agree = figures.iter().find(|f| f["what"] == what).unwrap_or_else(|| panic!("{what}\n{tail}"));
    assert_eq!(agree["ok"], true, "{agree}");
    // The CPU engine alone on one thread and on two, the second against the first.
    let two = figures.iter().find(|f| f["what"] == "CPU engine, guitar step at 32 px on 2 threads").expect("2 threads");
    assert!(two["value"].as_f64().is_some_and(|ms| ms > 0.0), "{two}");
    assert!(two["note"].as_str().is_some_and(|n| n.contains("x one thread's step")), "{two}");
    let step = figures.iter().find(|f| f["what"] == "guitar step at 48 px").expect("step figure");
    assert!(step["value"].as_f64().is_some_and(|ms| ms > 0.0), "{step}");
    // The studio drawn headless (`gast studio --headless`), at the window size the step asks for.
    let shot = image::open(out.join("studio.png")).expect("the headless studio's screenshot").to_rgb8();
    assert_eq!((shot.width(), shot.height()), (1600, 1000), "the studio's screenshot");
    let table = std::fs::read_to_string(out.join("gpu-check.md")).expect("gpu-check.md");
    assert!(table.contains("| what | measured | target | notes |"), "{table}");
    std::fs::remove_dir_all(&out).ok();
}

/// The report's side-by-side figures from a baseline build's and this build's
/// bench logs (`ab_RES_ARMROUND`, as `run` writes them when a baseline is
/// packed), from the GEMM tilings' (`tile_RES_ARMROUND`), from the
/// assignment pairing's blocks (`blk_RES_ARMROUND`), from the compute
/// passes' (`pass_RES_ARMROUND`) and from the kept bind groups'
/// (`bind_RES_ARMROUND`): the step
/// medians' ratio and each GPU part's. The runs themselves
/// are `gast bench step`, which the dry run above takes; at the dry run's
/// sizes on lavapipe two more would double its time, so the report is given
/// their files here.
#[test]
fn the_gpu_check_report_gives_this_build_against_the_baseline() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = std::env::temp_dir().join(format!("gast-gpu-check-ab-{}", std::process::id()));
    let (raw, out) = (dir.join("raw"), dir.join("out"));
    std::fs::create_dir_all(&raw).expect("raw dir");
    std::fs::create_dir_all(&out).expect("out dir");
    let write = |name: &str, text: String| std::fs::write(raw.join(name), text).expect("write");
    write("meta.json", r#"{"date":"2026-11-27T00:00:00Z","card":"","cores":2,"dry_run":1}"#.into());
    write("baseline.txt", "37a1bd3 the build before".into());
    // colour ms, geometry ms, edge map ms, raster backward tiles ms, per arm and round.
    let runs = [
        ("base", 1, 40.0, 44.0, 6.5, 16.0),
        ("new", 1, 20.0, 23.0, 2.0, 9.0),
        ("base", 2, 42.0, 46.0, 6.7, 16.4),
        ("new", 2, 22.0, 25.0, 2.2, 9.4),
    ];
    // The same figures as the GEMM tilings' arms (64² first, like the baseline;
    // every product in 128² blocks as fast as auto).
    let tiles = runs.map(|(arm, round, c, g, e, b)| (if arm == "base" { "t64" } else { "auto" }, round, c, g, e, b));
    let wide = runs.iter().filter(|r| r.0 == "new").map(|&(_, round, c, g, e, b)| ("t128", round, c, g, e, b));
    // And as the pairing's arms: one block of 512 rows first, blocks of 256 second.
    let blocks = runs.map(|(arm, round, c, g, e, b)| (if arm == "base" { "one" } else { "two" }, round, c, g, e, b));
    // And as the compute passes' arms: a pass per dispatch first, shared passes second.
    let passes =
        runs.map(|(arm, round, c, g, e, b)| (if arm == "base" { "each" } else { "shared" }, round, c, g, e, b));
    // And as the bind groups' arms: made every step first, kept second.
    let binds = runs.map(|(arm, round, c, g, e, b)| (if arm == "base" { "off" } else { "on" }, round, c, g, e, b));
    let named = runs
        .iter()
        .map(|r| ("ab", *r))
        .chain(tiles.iter().map(|r| ("tile", *r)))
        .chain(wide.map(|r| ("tile", r)))
        .chain(blocks.iter().map(|r| ("blk", *r)))
        .chain(passes.iter().map(|r| ("pass", *r)))
        .chain(binds.iter().map(|r| ("bind", *r)));
    for (prefix, (arm, round, colour, geometry, edge, backward)) in named {
        let name = format!("{prefix}_256_{arm}{round}");
        write(&format!("{name}.rc.json"), format!(r#"{{"name":"{name}","rc":0,"wall_s":9.5}}"#));
        write(
            &format!("{name}.json"),
            format!(
                r#"{{"runs":[{{"label":"gpu","device":"GPU: test","steps":12,"ms_per_step":{colour},"colour_step_median_ms":{colour},"geometry_step_median_ms":{geometry}}}]}}"#
            ),
        );
        write(
            &format!("{name}.log"),
            format!(
                "step benchmark: ...\n\nGPU parts on test (median ms)\n  edge map 256²                       {edge:>9.3}\n  raster backward tiles               {backward:>9.3}\n\nschedule: ...\n"
            ),
        );
    }
    // A fern step on its LLFF cameras and its GPU parts.
    write("fern_parts.rc.json", r#"{"name":"fern_parts","rc":0,"wall_s":30.0}"#.into());
    write(
        "fern_parts.json",
        r#"{"resolution":1008,"runs":[{"label":"gpu","device":"GPU: test","steps":12,"ms_per_step":80.0,"colour_step_median_ms":78.5,"geometry_step_median_ms":81.25}]}"#.into(),
    );
    write(
        "fern_parts.log",
        "step benchmark: ...\n\nGPU parts on test (median ms)\n  vgg forward 504×504 ms                5.250\n  raster backward tiles               3.000\n\nschedule: ...\n".into(),
    );
    // The guitar's full schedule: its report's distance on the object.
    write("full_guitar.rc.json", r#"{"name":"full_guitar","rc":0,"wall_s":150.0}"#.into());
    std::fs::create_dir_all(raw.join("full_guitar")).expect("full_guitar dir");
    write(
        "full_guitar/report.json",
        r#"{"config":{"resolution":512},"steps":[{},{}],"summary":{"on_object":{"nn_distance_matched":0.2265,"nn_distance_after":0.1971}}}"#.into(),
    );
    let run = Command::new("python3")
        .arg(root.join("tools/gpu_check_report.py"))
        .args([&raw, &out])
        .arg("60")
        .output()
        .expect("python3 runs the report");
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("gpu-check.json")).expect("gpu-check.json")).expect("parses");
    let figure = |what: &str| {
        doc["figures"].as_array().expect("figures").iter().find(|f| f["what"] == what).cloned().expect(what)
    };
    // Medians of the two rounds: colour 21 / 41, geometry 24 / 45.
    let colour = figure("guitar colour step at 256 px, this build / baseline");
    assert!((colour["value"].as_f64().expect("ratio") - 21.0 / 41.0).abs() < 1e-9, "{colour}");
    assert!(colour["note"].as_str().is_some_and(|n| n.contains("37a1bd3") && n.contains("40.00, 42.00")), "{colour}");
    let geometry = figure("guitar geometry step at 256 px, this build / baseline");
    assert!((geometry["value"].as_f64().expect("ratio") - 24.0 / 45.0).abs() < 1e-9, "{geometry}");
    let parts = doc["ab_parts"].as_array().expect("ab_parts");
    let part = |name: &str| parts.iter().find(|p| p["part"] == name).cloned().expect(name);
    assert!((part("edge map 256²")["ratio"].as_f64().expect("ratio") - 2.1 / 6.6).abs() < 1e-9, "{parts:?}");
    assert!((part("raster backward tiles")["ratio"].as_f64().expect("ratio") - 9.2 / 16.2).abs() < 1e-9, "{parts:?}");
    let tiled = figure("guitar colour step at 256 px, GEMM tiles auto / 64²");
    assert!((tiled["value"].as_f64().expect("ratio") - 21.0 / 41.0).abs() < 1e-9, "{tiled}");
    assert!(tiled["note"].as_str().is_some_and(|n| n.contains("GAST_GEMM_TILE=64: 40.00, 42.00")), "{tiled}");
    let tile_parts = doc["tile_parts"].as_array().expect("tile_parts");
    assert_eq!(tile_parts.len(), 2, "{tile_parts:?}");
    let paired = figure("guitar geometry step at 256 px, pairing in blocks of 256 / one block");
    assert!((paired["value"].as_f64().expect("ratio") - 24.0 / 45.0).abs() < 1e-9, "{paired}");
    assert!(paired["note"].as_str().is_some_and(|n| n.contains("--assign-block 512: 44.00, 46.00")), "{paired}");
    let full = figure("full schedule, guitar × block2 (load to export)");
    let note = full["note"].as_str().unwrap_or_default();
    assert!(note.contains("2 steps at 512 px") && note.contains("on the object 0.2265 -> 0.1971"), "{full}");
    let shared = figure("guitar colour step at 256 px, shared passes / a pass per dispatch");
    assert!((shared["value"].as_f64().expect("ratio") - 21.0 / 41.0).abs() < 1e-9, "{shared}");
    assert!(shared["note"].as_str().is_some_and(|n| n.contains("GAST_GPU_PASSES=each: 40.00, 42.00")), "{shared}");
    let kept = figure("guitar geometry step at 256 px, kept bind groups / made every step");
    assert!((kept["value"].as_f64().expect("ratio") - 24.0 / 45.0).abs() < 1e-9, "{kept}");
    assert!(kept["note"].as_str().is_some_and(|n| n.contains("GAST_BIND_CACHE=0: 44.00, 46.00")), "{kept}");
    let wide = figure("guitar geometry step at 256 px, GEMM tiles 128² / 64²");
    assert!((wide["value"].as_f64().expect("ratio") - 24.0 / 45.0).abs() < 1e-9, "{wide}");
    let fern = figure("fern step at 1008 px on the longer side (its LLFF cameras, frame recipe)");
    assert_eq!((fern["value"].as_f64(), fern["ok"].as_bool()), (Some(81.25), Some(false)), "{fern}");
    assert!(fern["note"].as_str().is_some_and(|n| n.contains("colour 78.50 ms, geometry 81.25 ms")), "{fern}");
    let table = std::fs::read_to_string(out.join("gpu-check.md")).expect("gpu-check.md");
    assert!(table.contains("| 256 | edge map 256² | 6.600 | 2.100 | 0.318 |"), "{table}");
    assert!(table.contains("| vgg forward 504×504 ms | 5.250 |"), "{table}");
    assert!(table.contains("| 64² ms | auto ms | auto / 64² | 128² ms | 128² / 64² |"), "{table}");
    assert!(table.contains("| 256 | edge map 256² | 6.600 | 2.100 | 0.318 | 2.100 | 0.318 |"), "{table}");
    std::fs::remove_dir_all(&dir).ok();
}
