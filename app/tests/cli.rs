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

/// Guitar, the style `style` (a file name under `styles/`) and the VGG
/// weights from the shared data; `None` when one is absent (the test then
/// returns, and `shared_file` has said which file it lacked).
fn guitar_with(style: &str) -> Option<(PathBuf, PathBuf, PathBuf)> {
    Some((
        shared_file("data/scenes/guitar.compressed.ply")?,
        shared_file(&format!("data/styles/{style}"))?,
        shared_file("data/weights/vgg19-conv3.safetensors")?,
    ))
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
    // The long-running commands say what Ctrl-C does.
    for sub in ["stylize", "fit"] {
        let o = gast(&[sub, "--help"]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains("Ctrl-C during the") && text.contains("a second Ctrl-C quits"), "{sub} --help:\n{text}");
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
    // A shorter orbit into the same folder removes the longer one's tail.
    std::fs::write(out.join("orbit_notes.txt"), b"kept").expect("a file of another name");
    let o = gast(&["render", s(&scene), "--out", s(&out), "--views", "2", "--size", "96"]);
    assert!(o.status.success() && stderr(&o).contains("removed 3 files of orbit views 2 and above"), "{}", stderr(&o));
    assert!(out.join("orbit_001_depth.exr").is_file() && !out.join("orbit_002.png").exists());
    assert!(out.join("orbit_notes.txt").is_file());
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
    // The folder stands for every golden file under it, depth/ included.
    let o = gast(&["check", "golden", "--weights", s(&weights), s(&dir)]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}\n{}", stderr(&o));
    assert!(text.contains(" 0 failed"), "{text}");
    for f in &files {
        assert!(text.lines().any(|l| l == f), "{f} not checked:\n{text}");
    }
    // A folder without golden files fails, saying so.
    let empty = temp("golden-empty");
    std::fs::create_dir_all(&empty).expect("dir");
    let o = gast(&["check", "golden", s(&empty)]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("expected golden files (.safetensors) in this folder, found none")
    );
    std::fs::remove_dir_all(&empty).ok();
    // A file that is not a golden file: non-zero exit, the file named.
    let o = gast(&["check", "golden", s(&weights)]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("vgg19-conv3.safetensors"));
}

#[test]
fn stylize_writes_a_scene_renders_and_a_report() {
    let Some((scene, style, weights)) = guitar_with("block2.jpg") else { return };
    let out = temp("stylize");
    // An earlier run's previews of views this run does not have: removed, not
    // left beside its own files; a file of another name stays.
    std::fs::create_dir_all(&out).expect("output folder");
    let earlier = ["view1_after.png", "view3_colour_matched_depth.exr", "view12_before_depth_jet.png"];
    for f in earlier.iter().chain(&["view1_notes.txt", "view1_after.png.bak"]) {
        std::fs::write(out.join(f), b"an earlier file").expect("plant a file");
    }
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
    // The guitar covers less than half of its views: the object recipe is on, and said.
    assert_eq!(report["config"]["weights"]["assignment_cosine"].as_f64(), Some(10.0));
    assert!(stderr(&o).contains("object recipe"), "{}", stderr(&o));
    assert_eq!(steps.iter().filter(|s| s["phase"] == "color").count(), 2);
    assert!(steps.iter().all(|s| s["losses"]["total"].as_f64().is_some_and(f64::is_finite)));
    assert!(report["gaussians_optimised"].as_u64().expect("count") <= input.len() as u64);
    for f in ["view0_before.png", "view0_after.png", "view0_after_depth.exr", "style_depth.png", "style_edge.png"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(earlier.iter().all(|f| !out.join(f).exists()), "an earlier run's previews are left");
    assert!(out.join("view1_notes.txt").is_file() && out.join("view1_after.png.bak").is_file());
    assert!(stderr(&o).contains("removed 3 preview files of views 1 and above"), "{}", stderr(&o));

    // Strength after the run: the colour-matched scene is written beside the
    // result, and `convert --blend` reproduces either end exactly.
    let matched = gast_core::scene::load(out.join("colour_matched.ply")).expect("colour_matched.ply loads");
    assert_eq!(matched.len(), result.len());
    let (stylized, toward) = (out.join("stylized.ply"), out.join("colour_matched.ply"));
    for (flags, expected) in [
        (&["--strength", "0"][..], &matched),
        (&["--strength", "100%"][..], &result),
        (&["--strength", "100", "--shape-strength", "0"][..], &matched),
    ] {
        let path = out.join("blended.ply");
        let mut args = vec!["convert", s(&stylized), s(&path), "--blend", s(&toward)];
        args.extend_from_slice(flags);
        let o = gast(&args);
        assert!(o.status.success(), "{flags:?}: {}", stderr(&o));
        let b = gast_core::scene::load(&path).expect("blended scene loads");
        if flags.len() == 2 {
            assert!(b == *expected, "{flags:?} does not reproduce its end");
        } else {
            assert_eq!((&b.means, &b.opacity_logits, &b.sh), (&matched.means, &matched.opacity_logits, &result.sh));
        }
    }
    let other = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/demo_scene.ply");
    let half = gast(&["convert", s(&stylized), s(&out.join("half.ply")), "--blend", s(&toward), "--strength", "50"]);
    assert!(half.status.success(), "{}", stderr(&half));
    for (bad, says) in [
        (vec!["--blend", s(&toward), "--strength", "150"], "from 0 to 100"),
        (vec!["--strength", "50"], "--blend"),
        (vec!["--blend", s(&toward)], "--strength"),
        (vec!["--blend", s(&other), "--strength", "50"], "same number of Gaussians"),
    ] {
        let bad_out = out.join("bad.ply");
        let mut args = vec!["convert", s(&stylized), s(&bad_out)];
        args.extend(bad.iter().copied());
        let o = gast(&args);
        assert!(!o.status.success() && stderr(&o).contains(says), "{bad:?}: {}", stderr(&o));
        assert!(!out.join("bad.ply").exists(), "{bad:?} wrote a file");
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
    // Inputs that fail leave no output folder behind: the folder is made
    // only once they are read.
    let missing = out.join("missing.ply");
    let fresh = out.join("fresh");
    for args in [
        &["render", s(&bogus), "--out", s(&fresh)][..],
        &["render", s(&scene), "--out", s(&fresh), "--cameras", s(&missing)],
        &["render", s(&scene), "--out", s(&fresh), "--turntable", "4", "--compare", s(&missing)],
    ] {
        let o = gast(args);
        assert!(!o.status.success(), "{args:?}");
        assert!(!fresh.exists(), "{args:?} failed and left {}", fresh.display());
    }
    // Invalid parameters are refused before any work.
    let o = gast(&["stylize", s(&scene), s(&bogus), "--ratio-geo", "1.5", "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("ratio_geo"), "{}", stderr(&o));
    // A folder of other work as a SOG output: its meta.json is not replaced.
    let work = out.join("work");
    std::fs::create_dir_all(&work).expect("dir");
    std::fs::write(work.join("meta.json"), b"{\"my\": \"settings\"}").expect("meta");
    let o = gast(&["convert", s(&scene), &format!("{}/", work.display())]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("work/meta.json: output folder: expected a SOG scene's meta.json"), "{}", stderr(&o));
    assert_eq!(std::fs::read(work.join("meta.json")).expect("kept"), b"{\"my\": \"settings\"}");
    // A preset's bad value names the preset, not only the setting.
    let preset = out.join("bad_preset.json");
    std::fs::write(&preset, r#"{"ratio_geo": 1.5}"#).expect("preset written");
    let o = gast(&["stylize", s(&scene), s(&bogus), "--preset", s(&preset), "--out", s(&out)]);
    assert!(!o.status.success());
    let said = stderr(&o);
    assert!(said.contains("ratio_geo") && said.contains(&format!("{} with the flags", preset.display())), "{said}");
    // --save-preset over a file that is not a preset is refused before any
    // work (`--save-preset wave.jpg` replaced the style with JSON).
    let style = shared_file("data/styles/wave.jpg").expect("the shared styles beside the scenes");
    let o = gast(&["stylize", s(&scene), s(&style), "--save-preset", s(&bogus), "--out", s(&out.join("run"))]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("style.jpg: expected a new file or a JSON file"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&bogus).expect("kept"), b"not a jpeg");
    // An output folder that is a file is refused as such (it said "File exists").
    for args in [&["render", s(&scene), "--out", s(&bogus)][..], &["stylize", s(&scene), s(&style), "--out", s(&bogus)]]
    {
        let o = gast(args);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("style.jpg: expected an output folder, found a file"), "{args:?}: {}", stderr(&o));
    }
    // A file further up the folder's path is named too (it said "Not a directory").
    let under = bogus.join("run");
    let o = gast(&["render", s(&scene), "--out", s(&under)]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("run: expected an output folder to make, found the file")
            && stderr(&o).contains("style.jpg in its path"),
        "{}",
        stderr(&o)
    );
    // A long, narrow style is refused as it is read (a 4000x8 one ran the
    // machine out of memory), before any folder is made.
    let strip = out.join("strip.png");
    image::RgbImage::new(400, 8).save(&strip).expect("write a strip");
    let fresh = out.join("strip-run");
    let o = gast(&["stylize", s(&scene), s(&strip), "--out", s(&fresh)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("strip.png: expected a style image at most 8 times as long"), "{}", stderr(&o));
    assert!(!fresh.exists());
    // A scene without Gaussians is named (it was "the scene has no Gaussians").
    let empty = out.join("empty.ply");
    gast_tests::write_empty_ply(&empty);
    let o = gast(&["stylize", s(&empty), s(&bogus), "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("empty.ply: expected a scene with Gaussians to stylize, found none"), "{}", stderr(&o));
    std::fs::remove_dir_all(&out).ok();
}

/// Runs `gast stylize` on guitar × block2 with `extra` flags and a learned
/// depth model that does not exist, in folder `out`; checks that it fails
/// without having looked for the model, and returns its stderr (`None`
/// without the shared data).
fn stylize_fails_before_the_depth_model(out: &Path, extra: &[&str]) -> Option<String> {
    let scene = shared_file("data/scenes/guitar.compressed.ply")?;
    let style = shared_file("data/styles/block2.jpg")?;
    let missing_model = out.join("no-such-model.safetensors");
    let run = out.join("run");
    let mut args = vec!["stylize", s(&scene), s(&style)];
    args.extend_from_slice(extra);
    args.extend(["--depth-provider", "learned", "--depth-model", s(&missing_model), "--out", s(&run)]);
    let o = gast(&args);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(!err.contains("no-such-model") && !err.contains("depth model"), "the depth model came first:\n{err}");
    Some(err)
}

#[test]
fn a_bad_camera_file_fails_before_the_depth_model_is_looked_for() {
    let out = temp("badcams");
    std::fs::create_dir_all(&out).expect("dir");
    let cams = out.join("cams.json");
    std::fs::write(&cams, b"{ not json").expect("write");
    if let Some(err) = stylize_fails_before_the_depth_model(&out, &["--cameras", s(&cams)]) {
        assert!(err.contains("cams.json"), "{err}");
        assert!(!out.join("run").exists(), "a run that failed on its cameras left its output folder");
    }
    std::fs::remove_dir_all(&out).ok();
}

/// Runs gast with `args`, sends it Ctrl-C (SIGINT) two seconds after it
/// printed a line containing `before` (the last before its loop starts), and
/// returns its exit status and everything it printed.
#[cfg(unix)]
fn interrupted(args: &[&str], before: &str) -> (std::process::ExitStatus, String) {
    signalled(args, before, "-INT", std::time::Duration::from_secs(2))
}

/// Runs `gast` with `args`, sends it `signal` (`-INT`, `-KILL`) `after` it
/// printed a line containing `before`, and returns its exit status and
/// everything it printed.
#[cfg(unix)]
fn signalled(
    args: &[&str],
    before: &str,
    signal: &str,
    after: std::time::Duration,
) -> (std::process::ExitStatus, String) {
    signalled_each(args, before, signal, &[after])
}

/// As [`signalled`], sending `signal` once per wait in `waits` (each wait
/// before its signal).
#[cfg(unix)]
fn signalled_each(
    args: &[&str],
    before: &str,
    signal: &str,
    waits: &[std::time::Duration],
) -> (std::process::ExitStatus, String) {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_gast"))
        .args(args)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn gast");
    let mut lines = BufReader::new(child.stderr.take().expect("stderr")).lines();
    let mut seen = Vec::new();
    for line in lines.by_ref() {
        let line = line.expect("stderr line");
        seen.push(line.clone());
        if line.contains(before) {
            break;
        }
    }
    for wait in waits {
        std::thread::sleep(*wait);
        let kill = Command::new("kill").args([signal, &child.id().to_string()]).status().expect("kill");
        assert!(kill.success());
    }
    seen.extend(lines.map_while(Result::ok));
    (child.wait().expect("wait"), seen.join("\n"))
}

/// `gast stylize` of `scene` with `style` into `out` at 48 px, one preview
/// view, the heuristic style depth: the small run the Ctrl-C, checkpoint and
/// resume tests stop, kill and resume; `flags` are its others.
fn small_run<'a>(
    scene: &'a Path,
    style: &'a Path,
    weights: &'a Path,
    out: &'a Path,
    flags: &[&'a str],
) -> Vec<&'a str> {
    let base = ["stylize", s(scene), s(style), "--weights", s(weights), "--out", s(out), "--resolution", "48"];
    [&base[..], &["--preview-views", "1", "--depth-provider", "heuristic"], flags].concat()
}

/// Ctrl-C during `stylize`: the run stops after its step and still writes the
/// scene, the renders and a report that says where it stopped, and keeps a
/// checkpoint with its record; `--resume` with other settings is refused,
/// saying which; the same command with `--resume` goes on from the step it
/// stopped at to the end, and then removes the checkpoint.
#[cfg(unix)]
#[test]
fn ctrl_c_stops_a_run_and_resume_goes_on_to_the_end() {
    let Some((scene, style, weights)) = guitar_with("block2.jpg") else { return };
    let out = temp("ctrlc");
    let flags = ["--cycles", "4", "--steps-per-cycle", "150", "--views", "2"];
    let run = small_run(&scene, &style, &weights, &out, &flags);
    let (status, text) = interrupted(&run, "object recipe");
    assert!(status.success(), "{text}");
    assert!(text.contains("stopped at step"), "{text}");
    assert!(text.contains("the same command with --resume goes on from it"), "{text}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("json");
    let at = report["stopped_at"].as_u64().expect("stopped_at");
    assert!((1..600).contains(&at), "stopped at {at}");
    assert_eq!(report["steps"].as_array().expect("steps").len() as u64, at);
    let result = gast_core::scene::load(out.join("stylized.ply")).expect("the stopped run's scene");
    let checkpoint = gast_core::scene::load(out.join("stylized.checkpoint.ply")).expect("the checkpoint");
    assert_eq!(checkpoint.len(), result.len());
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stylized.checkpoint.json")).expect("the record"))
            .expect("json");
    assert_eq!(record["step"].as_u64(), Some(at), "{record}");
    assert!(out.join("stylized.checkpoint.adam.safetensors").is_file(), "the optimiser's state beside it");

    let other =
        small_run(&scene, &style, &weights, &out, &["--cycles", "3", "--steps-per-cycle", "150", "--views", "3"]);
    let o = gast(&[&other[..], &["--resume"]].concat());
    assert!(!o.status.success());
    assert!(stderr(&o).contains("config.cycles: 4 then, 3 now"), "{}", stderr(&o));
    assert!(stderr(&o).contains("cameras: \"2 views, "), "{}", stderr(&o));
    if let Some(mosaic) = shared_file("data/styles/mosaic.jpg") {
        let elsewhere = small_run(&scene, &mosaic, &weights, &out, &flags);
        let o = gast(&[&elsewhere[..], &["--resume"]].concat());
        assert!(!o.status.success());
        assert!(
            stderr(&o).contains("block2.jpg\" then, ") && stderr(&o).contains("mosaic.jpg\" now"),
            "{}",
            stderr(&o)
        );
    }

    let o = gast(&[&run[..], &["--resume"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(iteration_after(&stderr(&o), "resuming from step "), at as u32, "{}", stderr(&o));
    assert!(stderr(&o).contains("(with the optimiser's moments)"), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("json");
    assert_eq!(report["resumed_from"].as_u64(), Some(at));
    assert!(report["stopped_at"].is_null());
    let steps = report["steps"].as_array().expect("steps");
    assert_eq!(steps.len() as u64, 600 - at, "the resumed run's own steps");
    assert_eq!(steps[0]["iter"].as_u64(), Some(at));
    for name in ["stylized.checkpoint.ply", "stylized.checkpoint.json", "stylized.checkpoint.adam.safetensors"] {
        assert!(!out.join(name).exists(), "{name} left after the whole run");
    }
    assert!(gast_core::scene::load(out.join("stylized.ply")).is_ok());
    std::fs::remove_dir_all(&out).ok();
}

/// One Ctrl-C delivered twice at once (`timeout -s INT` signals the command
/// and then its process group) still stops the run after its step, which
/// writes what it has; two presses apart quit at once, writing nothing.
#[cfg(unix)]
#[test]
fn a_doubled_ctrl_c_stops_a_run_and_a_second_press_quits() {
    let Some((scene, style, weights)) = guitar_with("block2.jpg") else { return };
    let out = temp("double-int");
    let run = small_run(&scene, &style, &weights, &out, &["--cycles", "1000", "--views", "2"]);
    let at_once = std::time::Duration::ZERO;
    let (status, text) = signalled_each(&run, "object recipe", "-INT", &[std::time::Duration::from_secs(1), at_once]);
    assert!(status.success(), "{text}");
    assert!(text.contains("stopped at step"), "{text}");
    assert!(out.join("stylized.ply").is_file());
    std::fs::remove_dir_all(&out).ok();

    let apart = std::time::Duration::from_millis(600);
    let (status, text) = signalled_each(&run, "object recipe", "-INT", &[std::time::Duration::from_secs(1), apart]);
    assert_eq!(status.code(), Some(130), "{text}");
    std::fs::remove_dir_all(&out).ok();
}

/// A `gast stylize` run killed outright keeps its last checkpoint (the
/// stylized scene as it stood, a whole INRIA .ply) with its record; the
/// checkpoint is no input for a run into the same folder (it would be
/// replaced, then removed); a run that ends removes it and its record, after
/// which `--resume` has nothing to go on from.
#[cfg(unix)]
#[test]
fn a_killed_stylize_run_leaves_its_checkpoint() {
    let Some((scene, style, weights)) = guitar_with("block2.jpg") else { return };
    let out = temp("killed-stylize");
    let run = |cycles| {
        let flags = ["--cycles", cycles, "--steps-per-cycle", "10", "--views", "2", "--checkpoint-every", "1"];
        small_run(&scene, &style, &weights, &out, &flags)
    };
    let long = run("1000");
    let (status, text) = signalled(&long, "checkpoint: step", "-KILL", std::time::Duration::ZERO);
    assert!(!status.success(), "{text}");
    assert!(!out.join("stylized.ply").exists(), "{text}");
    let checkpoint = out.join("stylized.checkpoint.ply");
    let kept = gast_core::scene::load(&checkpoint).expect("the killed run's checkpoint");
    let input = gast_core::scene::load(&scene).expect("guitar");
    assert_eq!(kept.len(), input.len(), "the checkpoint holds the whole scene");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stylized.checkpoint.json")).expect("the record"))
            .expect("json");
    let at = iteration_after(&text, "checkpoint: step ");
    assert!(record["step"].as_u64().is_some_and(|s| s >= u64::from(at)), "{record}");

    // A damaged optimiser's state: the run goes on with fresh moments, saying so.
    std::fs::write(out.join("stylized.checkpoint.adam.safetensors"), b"damaged").expect("write");
    let resumed = [&long[..], &["--resume"]].concat();
    let (status, text) = interrupted(&resumed, "resuming from step");
    assert!(status.success(), "{text}");
    assert!(text.contains("the optimiser's moments start afresh: ") && text.contains("is unreadable"), "{text}");

    let mut again = long.clone();
    again[1] = s(&checkpoint);
    let o = gast(&again);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("found one of its outputs (stylized.checkpoint.ply)"), "{}", stderr(&o));
    assert!(checkpoint.is_file());

    let short = run("1");
    let o = gast(&short);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("holds a checkpoint of an earlier stylization"), "{}", stderr(&o));
    assert!(out.join("stylized.ply").is_file() && !checkpoint.exists(), "{}", stderr(&o));
    assert!(!out.join("stylized.checkpoint.json").exists());

    // Nothing left to go on from.
    let o = gast(&[&short[..], &["--resume"]].concat());
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("expected the checkpoint of an earlier stylization to --resume from"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&out).ok();
}

/// The iteration after `marker` in `text` ("stopped at iteration 123 of …").
fn iteration_after(text: &str, marker: &str) -> u32 {
    let at = text.find(marker).unwrap_or_else(|| panic!("no {marker:?} in {text}")) + marker.len();
    text[at..].split(|c: char| !c.is_ascii_digit()).next().and_then(|n| n.parse().ok()).expect("an iteration")
}

/// Ctrl-C during `fit`: the fit stops after its iteration and still writes
/// the scene as it is, with its cameras, and keeps a checkpoint that the
/// same command with `--resume` goes on from (stopped again, later on);
/// with other settings `--resume` is refused, saying which.
#[cfg(unix)]
#[test]
fn ctrl_c_stops_a_fit_and_resume_goes_on_from_there() {
    let Some(fern) = shared_file("data/datasets/fern") else { return };
    let out = temp("ctrlc-fit");
    let scene = out.join("f.ply");
    let fit = ["fit", s(&fern), "--resolution", "64", "--iterations", "1000000", "--out", s(&scene)];
    let (status, text) = interrupted(&fit, "fitting 1000000 iterations");
    assert!(status.success(), "{text}");
    assert!(text.contains(" of 1000000 (Ctrl-C)"), "{text}");
    let stopped = iteration_after(&text, "stopped at iteration ");
    let fitted = gast_core::scene::load(&scene).expect("the stopped fit's scene");
    assert!(!fitted.is_empty());
    assert!(out.join("cameras.json").is_file(), "{text}");
    assert!(text.contains("the same command with --resume goes on from it"), "{text}");
    // The checkpoint holds the fit as it stood, before the output's pruning.
    let checkpoint = gast_core::scene::load(out.join("f.checkpoint.ply")).expect("the checkpoint");
    assert!(gast_core::fit::finished(&checkpoint, &gast_core::fit::FitConfig::default()) == fitted);
    assert!(out.join("f.checkpoint.adam.safetensors").is_file(), "the fit's state: {text}");

    let other = gast(&["fit", s(&fern), "--resolution", "64", "--iterations", "5", "--resume", "--out", s(&scene)]);
    assert!(!other.status.success());
    assert!(stderr(&other).contains("config.iterations: 1000000 then, 5 now"), "{}", stderr(&other));
    if let Some(lego) = shared_file("data/datasets/lego") {
        let o =
            gast(&["fit", s(&lego), "--resolution", "64", "--iterations", "1000000", "--resume", "--out", s(&scene)]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("datasets/fern\" then, ") && stderr(&o).contains("lego\" now"), "{}", stderr(&o));
    }

    let resumed = [&fit[..], &["--resume"]].concat();
    let (status, text) = interrupted(&resumed, "resuming from iteration");
    assert!(status.success(), "{text}");
    assert_eq!(iteration_after(&text, "resuming from iteration "), stopped, "{text}");
    assert!(iteration_after(&text, "stopped at iteration ") > stopped, "{text}");
    std::fs::remove_dir_all(&out).ok();
}

/// A fit killed outright after its first checkpoint (scene, state, record)
/// and resumed from it writes the scene a fit run through writes, to the
/// byte; without the state (an older checkpoint) it goes on, saying so.
#[cfg(unix)]
#[test]
fn a_fit_resumed_from_its_checkpoint_writes_the_scene_of_a_fit_run_through() {
    let Some(fern) = shared_file("data/datasets/fern") else { return };
    let out = temp("exact-fit");
    let (whole, part) = (out.join("whole.ply"), out.join("part.ply"));
    let fit = |scene: &Path| {
        let args = ["fit", s(&fern), "--resolution", "64", "--iterations", "600", "--checkpoint-every", "1"];
        [&args[..], &["--out", s(scene)]].concat().into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let run = |args: &[String]| gast(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let o = run(&fit(&whole));
    assert!(o.status.success(), "{}", stderr(&o));
    let killed = fit(&part);
    let killed: Vec<&str> = killed.iter().map(String::as_str).collect();
    let (status, text) = signalled(&killed, "checkpoint: iteration", "-KILL", std::time::Duration::ZERO);
    assert!(!status.success() && !part.exists(), "{text}");
    let at = iteration_after(&text, "checkpoint: iteration ");
    assert!(at < 600, "{text}");
    let resumed = [fit(&part), vec!["--resume".to_owned()]].concat();
    let o = run(&resumed);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("(with the fit's optimiser state, statistics and view order)"), "{}", stderr(&o));
    let (a, b) = (std::fs::read(&whole).expect("whole"), std::fs::read(&part).expect("resumed"));
    assert!(a == b, "the fit resumed from iteration {at} wrote another scene than the fit run through");

    // A record from before `random_background` (a build that fitted on the
    // plain background) goes on so, saying so; fern has no alpha, so the
    // scene is the same.
    let (status, text) = signalled(&killed, "checkpoint: iteration", "-KILL", std::time::Duration::ZERO);
    assert!(!status.success(), "{text}");
    let record_path = out.join("part.checkpoint.json");
    let record = std::fs::read_to_string(&record_path).expect("the record");
    let older: String =
        record.lines().filter(|l| !l.contains("\"random_background\"")).map(|l| format!("{l}\n")).collect();
    assert!(older != record, "{record}");
    std::fs::write(&record_path, older).expect("the older record");
    let o = run(&resumed);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("a build that fitted on the plain background; the fit goes on so"), "{}", stderr(&o));
    assert!(std::fs::read(&part).expect("resumed") == a, "the older record's resume wrote another scene");

    // Without its state (an older version's checkpoint) the fit still goes on, saying why.
    let (status, text) = signalled(&killed, "checkpoint: iteration", "-KILL", std::time::Duration::ZERO);
    assert!(!status.success(), "{text}");
    std::fs::remove_file(out.join("part.checkpoint.adam.safetensors")).expect("the state was written");
    let o = run(&resumed);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("the optimiser's moments and the view order start afresh: no "), "{}", stderr(&o));
    std::fs::remove_dir_all(&out).ok();
}

/// A fit killed outright (SIGKILL: no chance to write) leaves its last
/// checkpoint, a whole scene with its record and cameras, which `--resume`
/// accepts; a fit that ends removes its checkpoint.
#[cfg(unix)]
#[test]
fn a_killed_fit_leaves_its_checkpoint() {
    let Some(fern) = shared_file("data/datasets/fern") else { return };
    let out = temp("killed-fit");
    let scene = out.join("f.spz");
    let fit = [
        "fit",
        s(&fern),
        "--resolution",
        "64",
        "--iterations",
        "1000000",
        "--checkpoint-every",
        "1",
        "--out",
        s(&scene),
    ];
    let (status, text) = signalled(&fit, "checkpoint: iteration", "-KILL", std::time::Duration::ZERO);
    assert!(!status.success(), "{text}");
    assert!(!scene.exists(), "{text}");
    let at = iteration_after(&text, "checkpoint: iteration ");
    let checkpoint = gast_core::scene::load(out.join("f.checkpoint.ply")).expect("the killed fit's checkpoint");
    assert!(!checkpoint.is_empty());
    assert!(out.join("cameras.json").is_file(), "{text}");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("f.checkpoint.json")).expect("the record"))
            .expect("json");
    assert!(record["iteration"].as_u64().is_some_and(|i| i >= u64::from(at)), "{record}");

    // A short fit to the end writes its output and leaves no checkpoint.
    let o = gast(&[
        "fit",
        s(&fern),
        "--resolution",
        "64",
        "--iterations",
        "3",
        "--checkpoint-every",
        "1",
        "--out",
        s(&scene),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("holds a checkpoint of an earlier fit"), "{}", stderr(&o));
    assert!(scene.is_file() && !out.join("f.checkpoint.ply").exists() && !out.join("f.checkpoint.json").exists());
    std::fs::remove_dir_all(&out).ok();
}

/// Decodes an animated GIF: its frames' sizes.
fn gif_frames(path: &Path) -> Vec<(u32, u32)> {
    let file = std::io::BufReader::new(std::fs::File::open(path).expect("the GIF"));
    let decoder = image::codecs::gif::GifDecoder::new(file).expect("a GIF");
    let frames = image::AnimationDecoder::into_frames(decoder).collect_frames().expect("GIF frames");
    frames.iter().map(|f| f.buffer().dimensions()).collect()
}

/// Fern's own cameras look one way: its turntable loops through them (a
/// scene fitted for one iteration from its SfM points is enough to see it),
/// unless `--orbit` asks for the ring.
#[test]
fn a_forward_facing_capture_turntable_loops_through_its_cameras() {
    let Some(fern) =
        shared_file("data/datasets/fern/poses_bounds.npy").map(|p| p.parent().expect("dataset").to_path_buf())
    else {
        return;
    };
    let dir = temp("turntable-fern");
    let scene = dir.join("fern.ply");
    let o = gast(&["fit", s(&fern), "--iterations", "1", "--resolution", "64", "--out", s(&scene)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = dir.join("loop");
    let o = gast(&["render", s(&scene), "--out", s(&out), "--turntable", "4", "--size", "48"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("loops through its 20 cameras"), "{}", stderr(&o));
    for i in 0..4 {
        let img = image::open(out.join(format!("turntable_{i:03}.png"))).expect("a frame").to_rgb8();
        let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count();
        assert!(lit > 48 * 48 / 2, "frame {i}: the scene fills the view from its cameras' side, {lit} lit pixels");
    }
    let o = gast(&["render", s(&scene), "--out", s(&dir.join("ring")), "--turntable", "4", "--size", "48", "--orbit"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("loops through"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn turntables_write_frames_and_a_gif_and_compare_side_by_side() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("turntable");
    let o = gast(&["render", s(&scene), "--out", s(&out), "--turntable", "6", "--size", "64"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames: Vec<PathBuf> = (0..6).map(|i| out.join(format!("turntable_{i:03}.png"))).collect();
    let images: Vec<image::RgbImage> =
        frames.iter().map(|f| image::open(f).expect("a turntable frame").to_rgb8()).collect();
    assert!(!out.join("turntable_006.png").exists(), "more frames than asked");
    for (i, img) in images.iter().enumerate() {
        assert_eq!(img.dimensions(), (64, 64));
        let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count();
        assert!(lit > 300, "frame {i}: only {lit} lit pixels");
    }
    assert!(images[0] != images[3], "the turntable does not turn");
    assert_eq!(gif_frames(&out.join("turntable.gif")), vec![(64, 64); 6]);

    // Before | after from the same cameras: the scene beside itself gives two
    // halves equal to the turntable's own frames.
    let cmp = temp("turntable-compare");
    let o = gast(&["render", s(&scene), "--compare", s(&scene), "--out", s(&cmp), "--turntable", "6", "--size", "64"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(gif_frames(&cmp.join("turntable.gif")), vec![(128, 64); 6]);
    for (i, alone) in images.iter().enumerate() {
        let frame = image::open(cmp.join(format!("turntable_{i:03}.png"))).expect("a compare frame").to_rgb8();
        assert_eq!(frame.dimensions(), (128, 64));
        for x0 in [0, 64] {
            let half = image::imageops::crop_imm(&frame, x0, 0, 64, 64).to_image();
            assert!(half == *alone, "frame {i}: the half at x = {x0} is not the turntable's frame");
        }
    }

    let o = gast(&["render", s(&scene), "--compare", s(&scene), "--out", s(&cmp)]);
    assert!(!o.status.success(), "--compare without --turntable must be refused");
    // A shorter turntable into the same folder leaves none of the longer one's frames.
    let o = gast(&["render", s(&scene), "--out", s(&out), "--turntable", "4", "--size", "64"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("turntable_003.png").is_file() && !out.join("turntable_004.png").exists());
    assert_eq!(gif_frames(&out.join("turntable.gif")), vec![(64, 64); 4]);
    std::fs::remove_dir_all(&out).ok();
    std::fs::remove_dir_all(&cmp).ok();
}

/// `gast` with the display variables removed, run in `dir`.
fn gast_without_display(args: &[&str], dir: &Path, weights: &Path) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_gast"));
    for var in ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"] {
        cmd.env_remove(var);
    }
    cmd.args(args).current_dir(dir).env("GAST_WEIGHTS", weights).output().expect("run gast")
}

const NO_DESKTOP: &str = "the studio needs a desktop session, and none was found \
                          (DISPLAY, WAYLAND_DISPLAY and WAYLAND_SOCKET are unset); \
                          `gast studio --headless` draws it offscreen instead";

#[test]
fn without_a_display_gast_runs_the_headless_demo_and_studio_fails() {
    let Some(weights) = shared_file("data/weights/vgg19-conv3.safetensors") else { return };
    let dir = temp("first-run");
    std::fs::create_dir_all(&dir).expect("temp folder");

    let o = gast_without_display(&[], &dir, &weights);
    let (out, err) = (String::from_utf8_lossy(&o.stdout), stderr(&o));
    assert!(o.status.success(), "the demo failed:\n{out}\n{err}");
    assert!(err.lines().next().is_some_and(|l| l == format!("{NO_DESKTOP}.")), "no sentence first:\n{err}");
    let folder = out
        .lines()
        .find_map(|l| l.strip_prefix("the demo's outputs are in "))
        .map(PathBuf::from)
        .unwrap_or_else(|| panic!("the demo did not print its folder:\n{out}"));
    assert!(folder.starts_with(&dir) && folder.is_dir(), "{} is not a folder in the current one", folder.display());
    let stylized = gast_core::scene::load(folder.join("stylized.ply")).expect("the stylized demo scene");
    assert!(stylized.len() > 3000, "{} Gaussians", stylized.len());
    for v in 0..4 {
        for tag in ["before", "after"] {
            let png = image::open(folder.join(format!("view{v}_{tag}.png"))).expect("a demo render").to_rgb8();
            let lit = png.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count();
            assert!(lit > 1000, "view {v} {tag}: only {lit} lit pixels");
        }
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("report.json")).expect("report")).expect("json");
    assert_eq!(report["steps"].as_array().map(Vec::len), Some(200), "the demo's schedule");
    assert!(
        err.contains("optimisation on CPU") && err.contains(": 200 steps"),
        "the stylization's summary is missing:\n{err}"
    );
    // The first run shows the method: the after renders are measurably closer
    // to the style than the colour-matched ones, not only written.
    let summary = &report["summary"];
    let read = |k: &str| summary[k].as_f64().unwrap_or_else(|| panic!("summary.{k} missing"));
    let nn = read("nn_distance_matched") - read("nn_distance_after");
    let ms = read("mean_std_matched") - read("mean_std_after");
    assert!(
        nn > 0.01 && ms > 0.08,
        "the demo barely stylized (release: NN-cos 0.2608 -> 0.2414, mean-std 3.991 -> 3.829): NN-cos fell {nn:.4}, mean-std {ms:.4}"
    );

    let o = gast_without_display(&["studio"], &dir, &weights);
    assert!(!o.status.success(), "`gast studio` without a display must fail");
    assert_eq!(stderr(&o).trim(), format!("error: {NO_DESKTOP}"));
    std::fs::remove_dir_all(&dir).ok();

    // Without its weights the demo fails before writing, and leaves no empty folder.
    let dir = temp("first-run-no-weights");
    std::fs::create_dir_all(&dir).expect("temp folder");
    let o = gast_without_display(&[], &dir, Path::new("/nonexistent/vgg19.safetensors"));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/nonexistent/vgg19.safetensors"), "{}", stderr(&o));
    let left: Vec<_> = std::fs::read_dir(&dir).expect("the folder").flatten().map(|e| e.file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A bad `--assign-block` is refused before `gast bench step` loads anything:
/// the scene named does not exist, and the error is the setting's.
#[test]
fn bench_step_refuses_a_bad_block_before_loading_the_scene() {
    for fast in [&[][..], &["--conv", "im2col"][..]] {
        let mut args = vec!["bench", "step", "--scene", "/nonexistent/scene.ply", "--assign-block", "7"];
        args.extend_from_slice(fast);
        let o = gast(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains("assign_block must lie in 16..=512 rows, found 7"), "{args:?}: {err}");
        assert!(!err.contains("nonexistent"), "{args:?} loaded the scene first: {err}");
    }
}

/// Out-of-range view settings are refused with the value and the range
/// before anything loads: `--size 100000` used to abort on a 240 GB
/// allocation, `--size 0` and `--views 0` to write 1×1 images and one view,
/// `--fov 0` and `--fov 400` degenerate cameras, `gast fit --resolution 0`
/// to fit on 1-pixel photos.
#[test]
fn view_settings_out_of_range_are_refused_before_loading() {
    let scene = "/nonexistent/scene.ply";
    for (args, said) in [
        (&["render", scene, "--out", "/nonexistent/out", "--size", "100000"][..], "100000"),
        (&["render", scene, "--out", "/nonexistent/out", "--size", "0"][..], "16..=8192"),
        (&["render", scene, "--out", "/nonexistent/out", "--views", "0"][..], "1..=3600"),
        (&["render", scene, "--out", "/nonexistent/out", "--fov", "0"][..], "expected 1 to 170 degrees, found 0"),
        (&["stylize", scene, "/nonexistent/style.jpg", "--fov", "400"][..], "expected 1 to 170 degrees, found 400"),
        (&["stylize", scene, "/nonexistent/style.jpg", "--views", "0"][..], "1..=3600"),
        (&["bench", "raster", "--sizes", "256,0"][..], "16..=8192"),
        (&["fit", "/nonexistent/photos", "--out", "/nonexistent/f.ply", "--resolution", "0"][..], "16..=8192"),
        (&["fit", "/nonexistent/photos", "--out", "/nonexistent/f.ply", "--sh-degree", "9"][..], "0..=3"),
        (&["fit", "/nonexistent/photos", "--out", "/nonexistent/f.ply", "--gaussians", "0"][..], "1..=20000000"),
        (&["render", scene, "--out", "/nonexistent/out", "--turntable", "0"][..], "1..=3600"),
        (&["render", scene, "--out", "/nonexistent/out", "--background", "2,0,0"][..], "from 0 to 1, found 2"),
        (&["render", scene, "--out", "/nonexistent/out", "--background", "nan", "0", "0"][..], "found NaN"),
        (&["render", scene, "--out", "/nonexistent/out", "--background", "0.5,0.5"][..], "expected three values"),
        (&["bench", "raster", scene, "--views", "0"][..], "1..=3600"),
        (&["bench", "step", "--scene", scene, "--steps", "0"][..], "expected at least 1, found 0"),
        (&["bench", "depth", "--style", "/nonexistent/style.jpg", "--reps", "0"][..], "expected at least 1"),
        (&["bench", "pairing", "--scene", scene, "--draws", "0"][..], "expected at least 1, found 0"),
        (&["bench", "pairing", "--scene", scene, "--texture-scale", "100000"][..], "16..=4096"),
        (&["bench", "pairing", "--scene", scene, "--assign-block", "5"][..], "16..=512"),
        (&["bench", "viewport-live", "--scene", scene, "--reps", "0"][..], "expected at least 1"),
        (&["bench", "viewport", scene, "--frames", "0"][..], "expected at least 1"),
        (&["bench", "viewport", scene, "--width", "0"][..], "16..=8192"),
        (&["convert", scene, "/nonexistent/out.spz", "--spz-version", "7"][..], "3..=4"),
        (&["stylize", scene, "/nonexistent/style.jpg", "--sog-palette", "0"][..], "1..=65536"),
    ] {
        let o = gast(args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(said), "{args:?}: {err}");
        assert!(!err.contains("nonexistent"), "{args:?} looked for a file first: {err}");
    }
}

/// `--scene-name` names a file inside `--out`: a path that climbs out of it
/// or starts from the root is refused before the scene is read (`../x.ply`
/// was written beside the output folder).
#[test]
fn a_scene_name_that_leaves_the_output_folder_is_refused() {
    for name in ["../x.ply", "/tmp/x.ply", "sub/../../x.ply"] {
        let o = gast(&["stylize", "/nonexistent/scene.ply", "/nonexistent/style.jpg", "--scene-name", name]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{name} succeeded");
        assert!(
            err.contains(&format!("--scene-name {name}: expected a file name inside the output folder")),
            "{name}: {err}"
        );
        assert!(!err.contains("nonexistent"), "{name}: looked for the scene first: {err}");
    }
}

/// `gast fit` on fern says what it lacks: a missing `--images` folder by
/// name, a hold-out that leaves no view to fit (it said "no views to fit"),
/// and an output name it cannot write, before fitting (it fitted, then
/// failed on a folder, and wrote a PLY named `f.txt`).
#[test]
fn fit_names_a_missing_images_folder_and_an_empty_training_set() {
    let Some(fern) = shared_file("data/datasets/fern") else { return };
    let out = temp("fit-lacks");
    let o = gast(&["fit", s(&fern), "--images", "images_99", "--out", s(&out.join("f.ply"))]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("images_99: expected the images folder asked for, found no such folder"),
        "{}",
        stderr(&o)
    );
    let o = gast(&["fit", s(&fern), "--holdout-every", "1", "--iterations", "1", "--out", s(&out.join("f.ply"))]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("expected at least one view to fit, found 20 view(s), all held out by --holdout-every 1"),
        "{}",
        stderr(&o)
    );
    assert!(!out.join("f.ply").exists());
    // The output's name is checked before the fit: a folder, or a name that picks no format.
    std::fs::create_dir_all(&out).expect("dir");
    let o = gast(&["fit", s(&fern), "--out", s(&out)]);
    assert!(
        stderr(&o).contains("expected the fitted scene's file name (e.g. fit.ply), found a folder"),
        "{}",
        stderr(&o)
    );
    let o = gast(&["fit", s(&fern), "--out", s(&out.join("f.txt"))]);
    assert!(stderr(&o).contains("found the extension .txt"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("fitting"), "it fitted first: {}", stderr(&o));
    // So is a file where its folder should be (it fitted, then said "File exists").
    std::fs::write(out.join("taken"), b"kept").expect("a file");
    let o = gast(&["fit", s(&fern), "--iterations", "1", "--out", s(&out.join("taken/f.ply"))]);
    assert!(
        stderr(&o).contains("taken: expected an output folder, found a file; choose another --out"),
        "{}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("fitting"), "it fitted first: {}", stderr(&o));
    assert_eq!(std::fs::read(out.join("taken")).expect("kept"), b"kept");
    std::fs::remove_dir_all(&out).ok();
}

/// `gast fit` writes its cameras beside the scene as `cameras.json`, and
/// `render` (as `stylize` and the studio) starts from them without
/// `--cameras`: fern's scene was seen from an orbit outside the capture.
/// `--orbit` still generates views; cameras of other images, or a file that
/// cannot be read, are left as they are.
#[test]
fn a_fitted_scene_brings_its_cameras_to_render() {
    let Some(fern) = shared_file("data/datasets/fern") else { return };
    let out = temp("fit-cameras");
    let (scene, cameras) = (out.join("fit/f.ply"), out.join("fit/cameras.json"));
    let fit = ["fit", s(&fern), "--resolution", "16", "--iterations", "1", "--out", s(&scene)];
    let o = gast(&fit);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("cameras.json (20 cameras)"), "{}", stderr(&o));
    let o = gast(&["render", s(&scene), "--out", s(&out.join("views")), "--size", "32"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("the 20 views found beside the scene"), "{}", stderr(&o));
    let pngs = |d: &str| {
        let names = std::fs::read_dir(out.join(d)).expect("views").filter_map(|e| e.ok());
        let mut names: Vec<String> = names.map(|e| e.file_name().to_string_lossy().into_owned()).collect();
        names.retain(|n| n.ends_with(".png") && !n.ends_with("_depth.png"));
        names.sort();
        names
    };
    let views = pngs("views");
    assert_eq!((views.len(), views[0].as_str()), (20, "image000.png"), "{views:?}");
    let o = gast(&["render", s(&scene), "--out", s(&out.join("orbit")), "--size", "32", "--orbit", "--views", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(pngs("orbit"), ["orbit_000.png", "orbit_001.png"]);
    let o = gast(&["render", s(&scene), "--out", s(&out.join("x")), "--orbit", "--cameras", s(&fern)]);
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
    // A run on the fitted scene takes them too, and writes them beside its result.
    if let Some((_, style, weights)) = guitar_with("wave.jpg") {
        let run = out.join("run");
        let o = Command::new(env!("CARGO_BIN_EXE_gast"))
            .args(["stylize", s(&scene), s(&style), "--out", s(&run), "--resolution", "32", "--texture-scale", "32"])
            .args(["--cycles", "1", "--steps-per-cycle", "1", "--preview-views", "1", "--depth-provider", "heuristic"])
            .env("GAST_WEIGHTS", &weights)
            .output()
            .expect("run gast");
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains("the 20 views found beside the scene"), "{}", stderr(&o));
        let set = gast_core::camera::load(&run).expect("the run's cameras.json");
        assert_eq!((set.cameras.len(), set.cameras[0].width), (20, 32));
    }
    // A refit replaces its own cameras.json.
    let o = gast(&fit);
    assert!(o.status.success() && stderr(&o).contains("cameras.json (20 cameras)"), "{}", stderr(&o));
    // Cameras of other images are kept, with a warning.
    let other = r#"[{"img_name": "other", "width": 8, "height": 6, "position": [0, 0, -3],
        "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 8, "fy": 8}]"#;
    std::fs::write(&cameras, other).expect("write");
    let o = gast(&fit);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("already holds the cameras of other images (1 of them"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&cameras).expect("kept"), other);
    // One that cannot be read is named, not replaced by an orbit or by the fit's.
    std::fs::write(&cameras, "[{\"img_name\": 3}]").expect("write");
    let o = gast(&["render", s(&scene), "--out", s(&out.join("broken")), "--size", "32"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("cameras.json") && stderr(&o).contains("--orbit"), "{}", stderr(&o));
    let o = gast(&fit);
    assert!(o.status.success() && stderr(&o).contains("cameras.json is not written"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&cameras).expect("kept"), "[{\"img_name\": 3}]");
    std::fs::remove_dir_all(&out).ok();
}

/// Cameras found beside a scene that see none of it in most views are
/// another scene's (a folder of scenes with one camera file): `render` and
/// `stylize` leave them out with a warning and generate views; `--cameras`
/// still takes them.
#[test]
fn cameras_beside_an_unrelated_scene_are_left_out() {
    let (Some(guitar), Some(fern)) =
        (shared_file("data/scenes/guitar.compressed.ply"), shared_file("data/datasets/fern"))
    else {
        return;
    };
    let out = temp("foreign-cameras");
    std::fs::create_dir_all(&out).expect("dir");
    let scene = out.join("guitar.compressed.ply");
    std::fs::copy(&guitar, &scene).expect("copy the scene");
    let fern_cameras = gast_core::camera::load(&fern).expect("fern's cameras").cameras;
    gast_core::camera::write_inria(out.join("cameras.json"), &fern_cameras).expect("fern's cameras beside guitar");
    let o = gast(&["render", s(&scene), "--out", s(&out.join("views")), "--size", "32", "--views", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = stderr(&o);
    assert!(said.contains("are not used:") && said.contains("look like another scene's cameras"), "{said}");
    let count = |d: &str| std::fs::read_dir(out.join(d)).expect("views").filter(|e| e.is_ok()).count();
    assert_eq!(count("views"), 2 * 3, "two orbit views, a PNG, a depth PNG and an EXR each");
    let o = gast(&["render", s(&scene), "--out", s(&out.join("asked")), "--size", "32", "--cameras", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(count("asked"), 20 * 3, "--cameras takes them");
    std::fs::remove_dir_all(&out).ok();
}

/// A benchmark's default input missing from the shared data folder is named
/// with the folder it was looked for in and how to point elsewhere (it said
/// only "../shared/…: No such file or directory" from another folder).
#[test]
fn bench_defaults_say_where_the_shared_data_was_looked_for() {
    for args in [
        &["bench", "step", "--steps", "1", "--device", "cpu"][..],
        &["bench", "pairing"],
        &["bench", "depth"],
        &["bench", "raster"],
        &["bench", "viewport-live"],
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_gast"))
            .args(args)
            .env("GAST_SHARED", "/nonexistent/shared")
            .output()
            .expect("run gast");
        assert!(!o.status.success(), "{args:?}");
        let err = stderr(&o);
        assert!(err.contains("/nonexistent/shared/data/"), "{args:?}: {err}");
        assert!(
            err.contains("the default input, found no such file") && err.contains("set GAST_SHARED"),
            "{args:?}: {err}"
        );
    }
}

/// A `--depth-model` the user named that cannot be used (missing, or not a
/// checkpoint) stops the run before it starts, naming the file and why; it
/// went ahead on the built-in relief estimate with a warning.
#[test]
fn a_named_depth_model_that_cannot_be_used_is_an_error() {
    let Some((scene, style, weights)) = guitar_with("wave.jpg") else { return };
    let out = temp("depth-model");
    std::fs::create_dir_all(&out).expect("dir");
    let broken = out.join("broken.safetensors");
    std::fs::write(&broken, b"not a checkpoint").expect("write");
    for (model, said) in [
        (out.join("missing.safetensors"), "no Depth Anything V2 checkpoint found".to_owned()),
        (broken.clone(), format!("could not use it: {}: expected a safetensors file", broken.display())),
    ] {
        let run = out.join("run");
        let o = gast(&[
            "stylize",
            s(&scene),
            s(&style),
            "--weights",
            s(&weights),
            "--out",
            s(&run),
            "--resolution",
            "32",
            "--depth-model",
            s(&model),
        ]);
        assert!(!o.status.success(), "{}", model.display());
        let err = stderr(&o);
        assert!(
            err.contains(&format!("--depth-model {}: expected a Depth Anything V2 checkpoint", model.display())),
            "{err}"
        );
        assert!(err.contains(&said), "{err}");
        assert!(!err.contains("colour matching"), "the run started: {err}");
    }
    // The same checkpoint named by $GAST_DEPTH_MODEL (it fell back with a warning).
    let o = Command::new(env!("CARGO_BIN_EXE_gast"))
        .args(["stylize", s(&scene), s(&style), "--weights", s(&weights), "--out", s(&out.join("run"))])
        .args(["--resolution", "32"])
        .env("GAST_DEPTH_MODEL", &broken)
        .output()
        .expect("run gast");
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains(&format!("$GAST_DEPTH_MODEL {} (unset it", broken.display())), "{err}");
    assert!(!err.contains("colour matching"), "the run started: {err}");
    std::fs::remove_dir_all(&out).ok();
}

/// A writable copy of fern's poses and `images_8` photos in `to`.
fn copy_fern_poses_and_images_8(fern: &Path, to: &Path) {
    std::fs::create_dir_all(to.join("images_8")).expect("dir");
    std::fs::copy(fern.join("poses_bounds.npy"), to.join("poses_bounds.npy")).expect("copy");
    for e in std::fs::read_dir(fern.join("images_8")).expect("fern's images_8") {
        let e = e.expect("entry");
        std::fs::copy(e.path(), to.join("images_8").join(e.file_name())).expect("copy");
    }
}

/// `gast fit --preview` into the folder the photos are read from is refused
/// before the fit: its `view0_truth.png`, … and `sheet.png` mixed with the
/// photos (and an LLFF folder pairs its images with the poses by count).
#[test]
fn fit_previews_are_not_written_among_the_photos() {
    let Some(fern) = shared_file("data/datasets/fern") else { return };
    let copy = temp("fit-preview");
    let photos = copy.join("images_8");
    copy_fern_poses_and_images_8(&fern, &copy);
    let before = std::fs::read_dir(&photos).expect("list").count();
    let fitted = copy.join("f.ply");
    let args =
        ["fit", s(&copy), "--images", "images_8", "--resolution", "16", "--iterations", "1", "--out", s(&fitted)];
    let o = gast(&[&args[..], &["--preview", s(&photos)]].concat());
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("expected a folder apart from the photos, found a folder of the photos of"),
        "{}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("fitting"), "it fitted first: {}", stderr(&o));
    assert_eq!(std::fs::read_dir(&photos).expect("list").count(), before, "a preview was written among the photos");
    assert!(!fitted.exists());
    // Beside the photos is fine.
    let o = gast(&[&args[..], &["--preview", s(&copy.join("previews"))]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(copy.join("previews/sheet.png").is_file() && fitted.is_file());
    std::fs::remove_dir_all(&copy).ok();
}

/// `gast render` and `gast stylize` with a dataset's cameras refuse an
/// output folder holding its photos, before they write: a view of lego's
/// `./train/r_0` is `r_0.png`, which replaced the photo, and an LLFF
/// dataset's `images_4` holds the same names as the `images_8` its cameras
/// are read with.
#[test]
fn views_are_not_written_among_a_datasets_photos() {
    let (Some(lego), Some(fern), Some((scene, style, _))) =
        (shared_file("data/datasets/lego"), shared_file("data/datasets/fern"), guitar_with("wave.jpg"))
    else {
        return;
    };
    let copy = temp("photo-folders");
    let train = copy.join("lego/train");
    std::fs::create_dir_all(&train).expect("dir");
    // Lego's first frame alone, with the image size given (the file would
    // need every photo to read the sizes from).
    let frame = r#"{"file_path": "./train/r_0", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}"#;
    let json = format!(r#"{{"camera_angle_x": 0.69, "w": 800, "h": 800, "frames": [{frame}]}}"#);
    std::fs::write(copy.join("lego/transforms_train.json"), json).expect("write");
    std::fs::copy(lego.join("train/r_0.png"), train.join("r_0.png")).expect("copy");
    let llff = copy.join("fern");
    // The cameras read images_8 (one photo a row); images_4 holds one photo.
    std::fs::create_dir_all(llff.join("images_4")).expect("dir");
    std::fs::copy(fern.join("images_4/image000.png"), llff.join("images_4/image000.png")).expect("copy");
    copy_fern_poses_and_images_8(&fern, &llff);
    let photo = std::fs::read(train.join("r_0.png")).expect("read");
    for (cameras, out) in
        [(copy.join("lego/transforms_train.json"), train.clone()), (llff.clone(), llff.join("images_4"))]
    {
        let before = std::fs::read_dir(&out).expect("list").count();
        for args in [
            &["render", s(&scene), "--cameras", s(&cameras), "--out", s(&out), "--size", "16"][..],
            &["stylize", s(&scene), s(&style), "--cameras", s(&cameras), "--out", s(&out), "--cycles", "1"],
        ] {
            let o = gast(args);
            assert!(!o.status.success(), "{args:?}");
            assert!(
                stderr(&o).contains("expected a folder apart from the photos, found a folder of the photos of"),
                "{args:?}: {}",
                stderr(&o)
            );
            assert_eq!(std::fs::read_dir(&out).expect("list").count(), before, "{args:?} wrote among the photos");
        }
    }
    // Without the dataset's cameras too: an orbit render or a turntable into
    // a dataset's photo folder (the folder above it reads as the dataset).
    for out in [train.clone(), llff.join("images_4")] {
        let before = std::fs::read_dir(&out).expect("list").count();
        for args in [
            &["render", s(&scene), "--out", s(&out), "--size", "16", "--views", "1"][..],
            &["render", s(&scene), "--out", s(&out), "--size", "16", "--turntable", "2"],
        ] {
            let o = gast(args);
            assert!(!o.status.success(), "{args:?}");
            assert!(stderr(&o).contains("found a folder of the photos of"), "{args:?}: {}", stderr(&o));
            assert_eq!(std::fs::read_dir(&out).expect("list").count(), before, "{args:?} wrote among the photos");
        }
    }
    assert_eq!(std::fs::read(train.join("r_0.png")).expect("read"), photo, "the photo was replaced");
    // Beside the photos is fine.
    let o = gast(&["render", s(&scene), "--cameras", s(&llff), "--out", s(&copy.join("views")), "--size", "16"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(copy.join("views/image000.png").is_file());
    std::fs::remove_dir_all(&copy).ok();
}
