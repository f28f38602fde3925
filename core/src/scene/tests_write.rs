//! The writers on small synthetic scenes: the format chosen by the name,
//! bad output paths, atomic replacement, and INRIA files with infinite
//! opacity logits or log-scales. Per-field accuracy on real scenes is
//! checked in `tests/scene_writers.rs`.

use std::path::Path;

use super::test_util::{sample, scratch};
use super::{
    Gaussians, LOG_SCALE_INF, LOG_SCALE_NEG_INF, OPACITY_LOGIT_INF, OPACITY_LOGIT_NEG_INF, SaveOptions, SceneError,
    SceneFormat, load, load_with_warnings, save, save_ply,
};

const NAMES: [&str; 6] = ["a.ply", "a.compressed.ply", "a.spz", "a.sog", "folder/", "other/meta.json"];

#[test]
fn the_name_chooses_the_format() {
    let f = |p: &str| SceneFormat::from_output(Path::new(p)).expect(p);
    assert_eq!(f("x/a.PLY"), SceneFormat::Ply);
    assert_eq!(f("a.compressed.ply"), SceneFormat::CompressedPly);
    assert_eq!(f("a.spz"), SceneFormat::Spz);
    assert_eq!(f("a.sog"), SceneFormat::SogBundle);
    assert_eq!(f("out/"), SceneFormat::SogFolder("out/".into()));
    assert_eq!(f("out/meta.json"), SceneFormat::SogFolder("out".into()));
    for bad in ["a.splat", "noext"] {
        let msg = SceneFormat::from_output(Path::new(bad)).expect_err(bad).to_string();
        assert!(msg.contains(bad) && msg.contains(".compressed.ply") && msg.contains(".spz"), "{msg}");
    }
    assert!(SceneFormat::from_output(Path::new("a.splat")).expect_err("").to_string().contains(".splat"));
}

#[test]
fn every_writer_reads_back_with_count_degree_and_order() {
    let dir = scratch("writers_small");
    for degree in 0..=3 {
        let g = sample(300, degree);
        for name in NAMES {
            let out = dir.join(format!("d{degree}")).join(name);
            std::fs::create_dir_all(dir.join(format!("d{degree}"))).expect("dir");
            save(&out, &g, &SaveOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
            let back = load(&out).expect(name);
            assert_eq!((back.len(), back.sh_degree), (g.len(), degree), "{name}");
            // Order kept: every position within 1/1000 of the scene's extent
            // (the coarsest steps: compressed PLY's 1/1023 of a chunk's range,
            // SPZ's fixed point scaled to the largest coordinate).
            let extent = g.means.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
            for i in 0..g.len() {
                for a in 0..3 {
                    let err = (back.means[i][a] - g.means[i][a]).abs();
                    assert!(err <= 1e-3 * extent, "{name}: Gaussian {i} axis {a} off by {err}");
                }
            }
        }
    }
}

#[test]
fn spz_version_3_is_gzip_and_4_is_zstd() {
    let dir = scratch("spz_versions");
    let g = sample(50, 1);
    for (version, magic) in [(3, &[0x1f, 0x8b][..]), (4, &b"NGSP"[..])] {
        let p = dir.join(format!("v{version}.spz"));
        save(&p, &g, &SaveOptions { spz_version: version, ..SaveOptions::default() }).expect("save");
        assert!(std::fs::read(&p).expect("read").starts_with(magic), "version {version}");
        assert_eq!(load(&p).expect("load").len(), 50);
    }
    let err = save(dir.join("v5.spz"), &g, &SaveOptions { spz_version: 5, ..SaveOptions::default() });
    assert!(err.expect_err("v5").to_string().contains("3 or 4"));
}

/// Lists a folder's entries (names), to check nothing was left behind.
fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn bad_output_paths_are_clear_errors_and_leave_nothing() {
    let dir = scratch("bad_outputs");
    let g = sample(20, 1);
    // A regular file where a folder should be: even root cannot write under it.
    std::fs::write(dir.join("file"), b"x").expect("file");
    for name in NAMES {
        for (parent, found) in [("missing", "No such file"), ("file", "a file")] {
            let out = dir.join(parent).join(name);
            let msg = save(&out, &g, &SaveOptions::default()).expect_err(name).to_string();
            assert!(msg.contains(parent) && msg.contains("output folder") && msg.contains(found), "{name}: {msg}");
        }
    }
    assert_eq!(entries(&dir), ["file"]);
    // A failure while writing (here: the target is a folder that cannot be
    // replaced by a file) leaves neither a partial file nor a temporary one.
    std::fs::create_dir_all(dir.join("taken.ply/inner")).expect("dir");
    let err = save_ply(dir.join("taken.ply"), &g).expect_err("rename over a folder");
    assert!(matches!(err, SceneError::Io { .. }), "{err}");
    assert_eq!(entries(&dir), ["file", "taken.ply"]);
    // An existing folder named as a file format's is not taken for a SOG
    // folder (it was: `gast convert` wrote SOG textures into `taken.ply/`),
    // unless the name ends in `/`.
    let msg = save(dir.join("taken.ply"), &g, &SaveOptions::default()).expect_err("a folder named .ply").to_string();
    assert!(
        msg.contains("taken.ply") && msg.contains("existing folder") && msg.contains("end the name with /"),
        "{msg}"
    );
    assert_eq!(entries(&dir.join("taken.ply")), ["inner"]);
    save(dir.join("taken.ply/"), &g, &SaveOptions::default()).expect("a SOG folder asked for with /");
    assert!(dir.join("taken.ply/meta.json").is_file());
}

#[test]
fn rewriting_a_sog_folder_replaces_it_whole() {
    let dir = scratch("sog_rewrite");
    let out = dir.join("scene/");
    save(&out, &sample(40, 2), &SaveOptions::default()).expect("first");
    save(&out, &sample(70, 1), &SaveOptions::default()).expect("second");
    let back = load(dir.join("scene")).expect("load");
    assert_eq!((back.len(), back.sh_degree), (70, 1));
    assert_eq!(entries(&dir), ["scene"]);
}

/// A folder of other work is not a SOG output to fill: a `meta.json` that
/// is not SOG metadata, or a file of a texture's name with no `meta.json`,
/// is refused before the encoding and kept; files of other names beside a
/// new SOG scene stay as they are.
#[test]
fn a_sog_output_never_replaces_another_folders_files() {
    let dir = scratch("sog_foreign");
    let work = dir.join("work");
    std::fs::create_dir_all(&work).expect("dir");
    std::fs::write(work.join("meta.json"), br#"{"my": "project settings"}"#).expect("meta");
    std::fs::write(work.join("notes.txt"), b"notes").expect("notes");
    let e = super::check_output(&work).expect_err("a foreign meta.json");
    let said = e.to_string();
    assert!(said.contains("work/meta.json: output folder: expected a SOG scene's meta.json to replace"), "{said}");
    let e = save(&work, &sample(10, 0), &SaveOptions::default()).expect_err("the writer refuses it too");
    assert!(matches!(e, SceneError::Format { .. }), "{e}");
    assert_eq!(std::fs::read(work.join("meta.json")).expect("kept"), br#"{"my": "project settings"}"#);
    // A texture's name with no SOG scene beside it.
    std::fs::remove_file(work.join("meta.json")).expect("rm");
    std::fs::write(work.join("sh0.webp"), b"a picture").expect("webp");
    let said = super::check_output(&work).expect_err("a foreign sh0.webp").to_string();
    assert!(said.contains("work/sh0.webp: output folder: expected no file of a SOG texture's name"), "{said}");
    // Without them the folder takes the scene, its other files kept; then it holds
    // a SOG scene, which a rewrite replaces.
    std::fs::remove_file(work.join("sh0.webp")).expect("rm");
    save(&work, &sample(10, 0), &SaveOptions::default()).expect("into a folder of other files");
    assert_eq!(std::fs::read(work.join("notes.txt")).expect("kept"), b"notes");
    super::check_output(&work).expect("a SOG scene's folder");
    save(&work, &sample(12, 1), &SaveOptions::default()).expect("replaced");
    assert_eq!(load(work.join("meta.json")).expect("load").len(), 12);
}

#[test]
fn a_sog_rewrite_that_fails_midway_keeps_the_old_scene_whole() {
    let dir = scratch("sog_midway");
    let out = dir.join("scene");
    std::fs::create_dir_all(&out).expect("dir");
    save(&out, &sample(10, 0), &SaveOptions::default()).expect("the first scene");
    let before: Vec<_> =
        super::sog_write::FILE_NAMES.iter().filter_map(|n| std::fs::read(out.join(n)).ok().map(|b| (*n, b))).collect();
    assert!(before.len() >= 6, "a SOG scene's files: {}", before.len());
    // The rotations' temporary cannot be made (a folder holds its name), as a
    // full disk refuses a file after the first few: before, the files written
    // until then replaced theirs, a scene of two scenes' textures.
    let blocked = crate::io::temp_path(&out.join("quats.webp"));
    std::fs::create_dir(&blocked).expect("a folder");
    let e = save(&out, &sample(12, 1), &SaveOptions::default()).expect_err("a blocked write");
    assert!(e.to_string().contains("quats.webp"), "the error names the file: {e}");
    for (name, bytes) in &before {
        assert_eq!(&std::fs::read(out.join(name)).expect("kept"), bytes, "{name} was replaced");
    }
    assert_eq!(load(out.join("meta.json")).expect("the old scene").len(), 10);
    std::fs::remove_dir(&blocked).expect("a folder");
    let left: Vec<_> = std::fs::read_dir(&out)
        .expect("list")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "temporaries left: {left:?}");
    save(&out, &sample(12, 1), &SaveOptions::default()).expect("then replaced");
    assert_eq!(load(out.join("meta.json")).expect("load").len(), 12);
}

/// An INRIA file whose opacities and log-scales include ±inf, as
/// splat-transform writes for an opacity of exactly 1.
fn with_infinities(dir: &Path) -> (std::path::PathBuf, Gaussians) {
    let mut g = sample(10, 0);
    g.opacity_logits[1] = f32::INFINITY;
    g.opacity_logits[4] = f32::INFINITY;
    g.opacity_logits[7] = f32::NEG_INFINITY;
    g.log_scales[2][1] = f32::NEG_INFINITY;
    g.log_scales[3][0] = f32::INFINITY;
    let p = dir.join("inf.ply");
    // save_ply refuses non-finite values, so write through the raw writer.
    super::atomic_write(&p, |w| super::ply::write_ply_to(w, &g)).expect("write");
    (p, g)
}

#[test]
fn infinite_opacity_and_scale_are_clamped_with_one_warning() {
    let dir = scratch("inf_ply");
    let (p, g) = with_infinities(&dir);
    let (back, warnings) = load_with_warnings(&p).expect("load");
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let w = &warnings[0];
    assert!(w.contains("inf.ply") && w.contains("3 infinite opacity") && w.contains("2 infinite log-scales"), "{w}");
    assert_eq!(back.opacity_logits[1], OPACITY_LOGIT_INF);
    assert_eq!(back.opacity_logits[7], OPACITY_LOGIT_NEG_INF);
    assert_eq!(back.log_scales[2][1], LOG_SCALE_NEG_INF);
    assert_eq!(back.log_scales[3][0], LOG_SCALE_INF);
    assert_eq!(back.opacity_logits[0], g.opacity_logits[0]);
    // They render the same: the sigmoid is exactly 1 and 0 in f32, computed either way.
    for (x, want) in [(OPACITY_LOGIT_INF, 1.0f32), (OPACITY_LOGIT_NEG_INF, 0.0)] {
        assert_eq!(1.0 / (1.0 + (-x).exp()), want);
        assert_eq!(x.exp() / (1.0 + x.exp()), want);
    }
    // A clean file gives no warning; a NaN is still refused.
    save_ply(dir.join("clean.ply"), &sample(5, 0)).expect("clean");
    assert!(load_with_warnings(dir.join("clean.ply")).expect("clean").1.is_empty());
    let mut nan = g.clone();
    nan.opacity_logits[1] = f32::NAN;
    let p = dir.join("nan.ply");
    super::atomic_write(&p, |w| super::ply::write_ply_to(w, &nan)).expect("write");
    let msg = load(&p).expect_err("NaN").to_string();
    assert!(msg.contains("nan.ply") && msg.contains("opacity") && msg.contains("NaN"), "{msg}");
}
