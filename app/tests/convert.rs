//! `gast convert` end to end: every output format from a real scene, names it
//! cannot write, bad output folders, and an INRIA file with infinite opacity
//! logits as splat-transform writes them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use gast_tests::shared_file;

fn gast(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gast")).args(args).output().expect("run gast")
}

fn temp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gast-convert-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Makes `path` (a file or a folder) read-only, or writable again.
fn set_readonly(path: &Path, on: bool) {
    let mut perms = std::fs::metadata(path).expect("stat").permissions();
    #[allow(clippy::permissions_set_readonly_false)]
    perms.set_readonly(on);
    std::fs::set_permissions(path, perms).expect("chmod");
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn converts_guitar_to_every_format_and_refuses_bad_outputs() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("all");
    let input = gast_core::scene::load(&scene).expect("input");
    for name in ["g.ply", "g.compressed.ply", "g.spz", "g3.spz", "g.sog", "g-sog/"] {
        let path = out.join(name);
        let version = if name == "g3.spz" { "3" } else { "4" };
        let o = gast(&["convert", s(&scene), s(&path), "--spz-version", version]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert!(stderr(&o).contains("converted") && stderr(&o).contains("90854 Gaussians"), "{}", stderr(&o));
        let back = gast_core::scene::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(back.len(), input.len(), "{name}");
    }
    let before = listing(&out);

    let o = gast(&["convert", s(&scene), s(&out.join("g.splat"))]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("g.splat") && e.contains(".splat") && e.contains(".compressed.ply") && e.contains(".sog"),
        "{e}"
    );

    // A missing folder, and a folder that is really a file (even root cannot write under it).
    for bad in [out.join("missing/g.spz"), out.join("g.ply/g.spz"), out.join("g.ply/sog/")] {
        let o = gast(&["convert", s(&scene), s(&bad)]);
        assert!(!o.status.success(), "{}", bad.display());
        let e = stderr(&o);
        assert!(e.contains(s(&bad)) && e.contains("output folder"), "{e}");
    }
    assert_eq!(listing(&out), before, "a failed conversion left files behind");

    // stylize refuses a scene name it cannot write before any work.
    let o = gast(&["stylize", s(&scene), s(&scene), "--out", s(&out), "--scene-name", "x.splat"]);
    assert!(!o.status.success() && stderr(&o).contains("x.splat"), "{}", stderr(&o));
    std::fs::remove_dir_all(&out).ok();
}

/// The originals are kept: converting a scene onto itself (or stylizing into
/// its own name) is refused, and so is replacing a read-only file, which the
/// rename of an atomic write would have passed over (`gast convert
/// guitar.compressed.ply guitar.compressed.ply` re-encoded the shared,
/// read-only original in place). The files stay byte for byte.
#[test]
fn the_input_and_read_only_files_are_not_replaced() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("keep");
    let original = out.join("g.compressed.ply");
    std::fs::copy(&scene, &original).expect("copy");
    let bytes = std::fs::read(&original).expect("read");
    for args in [
        &["convert", s(&original), s(&original)][..],
        &["stylize", s(&original), s(&original), "--out", s(&out), "--scene-name", "g.compressed.ply"],
    ] {
        let o = gast(args);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            stderr(&o).contains("expected an output other than the input scene, found the input itself"),
            "{}",
            stderr(&o)
        );
    }
    // Nor is the colour-matched scene stylize writes beside its result the input, or the result's name.
    let matched = out.join("colour_matched.ply");
    std::fs::rename(&original, &matched).expect("rename");
    let o = gast(&["stylize", s(&matched), s(&matched), "--out", s(&out)]);
    assert!(stderr(&o).contains("colour_matched.ply: expected an output other than the input scene"), "{}", stderr(&o));
    std::fs::rename(&matched, &original).expect("rename");
    let o = gast(&["stylize", s(&original), s(&original), "--out", s(&out), "--scene-name", "colour_matched.ply"]);
    assert!(stderr(&o).contains("--scene-name colour_matched.ply: expected another name"), "{}", stderr(&o));
    // A style or preset taken from an earlier run's folder, which the run would write over.
    let style = shared_file("data/styles/wave.jpg").expect("the shared styles beside the scenes");
    for (name, flag) in [("style.png", None), ("view0_after.png", None), ("report.json", Some("--preset"))] {
        let input = out.join(name);
        std::fs::write(&input, b"an earlier run's output").expect("write");
        let mut args =
            vec!["stylize", s(&original), if flag.is_none() { s(&input) } else { s(&style) }, "--out", s(&out)];
        if let Some(flag) = flag {
            args.extend([flag, s(&input)]);
        }
        let o = gast(&args);
        assert!(!o.status.success(), "{args:?}");
        let said = format!("{}: expected an input outside what the run writes into", input.display());
        assert!(stderr(&o).contains(&said), "{}", stderr(&o));
        assert_eq!(std::fs::read(&input).expect("kept"), b"an earlier run's output");
        std::fs::remove_file(&input).expect("remove");
    }
    let locked = out.join("locked.ply");
    let o = gast(&["convert", s(&original), s(&locked)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let kept = std::fs::read(&locked).expect("read");
    set_readonly(&locked, true);
    let o = gast(&["convert", s(&original), s(&locked)]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("locked.ply: expected a file that may be replaced, found a read-only one"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&original).expect("read"), bytes);
    assert_eq!(std::fs::read(&locked).expect("read"), kept);
    // A SOG folder with one read-only texture is refused before any file is replaced.
    let sog = out.join("sog/");
    let o = gast(&["convert", s(&original), s(&sog)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let texture = sog.join("quats.webp");
    assert!(texture.is_file(), "a SOG folder holds quats.webp");
    set_readonly(&texture, true);
    let folder: Vec<_> = listing(&sog).iter().map(|f| (f.clone(), std::fs::read(sog.join(f)).expect("read"))).collect();
    let o = gast(&["convert", s(&locked), s(&sog)]);
    assert!(
        stderr(&o).contains("quats.webp: expected a file that may be replaced, found a read-only one"),
        "{}",
        stderr(&o)
    );
    for (f, bytes) in &folder {
        assert!(std::fs::read(sog.join(f)).expect("read") == *bytes, "{f} was replaced");
    }
    assert_eq!(listing(&out), ["g.compressed.ply", "locked.ply", "sog"], "a refused write left files behind");
    std::fs::remove_dir_all(&out).ok();
}

/// No command adds to a read-only folder, as root or not (root's writes pass
/// over its permissions: a `--preview` folder among the shared, read-only
/// photos was written in). A file, a new folder inside it and a SOG folder
/// are refused, each naming the read-only folder, and it stays as it was.
#[test]
fn nothing_is_written_in_a_read_only_folder() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("ro-folder");
    let locked = out.join("locked");
    std::fs::create_dir_all(&locked).expect("dir");
    std::fs::copy(&scene, locked.join("g.compressed.ply")).expect("copy");
    set_readonly(&locked, true);
    let input = locked.join("g.compressed.ply");
    let style = shared_file("data/styles/wave.jpg").expect("the shared styles beside the scenes");
    for target in [locked.join("g.ply"), locked.join("g.sog"), locked.join("sog/")] {
        let o = gast(&["convert", s(&input), s(&target)]);
        assert!(!o.status.success(), "{}", target.display());
        let said = format!("expected a folder that may be written in, found a read-only one, {}", locked.display());
        assert!(stderr(&o).contains(&said), "{}: {}", target.display(), stderr(&o));
    }
    for args in [
        &["render", s(&input), "--out", s(&locked.join("renders")), "--views", "1", "--size", "16"][..],
        &["stylize", s(&input), s(&style), "--out", s(&locked.join("run"))],
        &["assets", "--out", s(&locked.join("assets"))],
    ] {
        let o = gast(args);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains("found a read-only one"), "{args:?}: {}", stderr(&o));
    }
    assert_eq!(listing(&locked), ["g.compressed.ply"], "a refused write added to the read-only folder");
    set_readonly(&locked, false);
    std::fs::remove_dir_all(&out).ok();
}

/// An INRIA `.ply` written by `gast`, with some opacities patched to +inf and
/// −inf as splat-transform writes them: it converts with one warning that
/// counts them, and the Gaussians come out fully opaque and fully transparent.
#[test]
fn infinite_opacity_logits_read_with_one_warning() {
    let Some(scene) = shared_file("data/scenes/guitar.compressed.ply") else { return };
    let out = temp("inf");
    let ply = out.join("g.ply");
    let o = gast(&["convert", s(&scene), s(&ply)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut bytes = std::fs::read(&ply).expect("read");
    let body = bytes.windows(11).position(|w| w == b"end_header\n").expect("header") + 11;
    // 17 floats a row (x y z nx ny nz f_dc×3 opacity scale×3 rot×4); opacity is the 10th.
    let patched = [(3usize, f32::INFINITY), (130, f32::INFINITY), (500, f32::NEG_INFINITY)];
    for (row, v) in patched {
        let at = body + (row * 17 + 9) * 4;
        bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }
    let inf = out.join("inf.ply");
    std::fs::write(&inf, &bytes).expect("write");
    let o = gast(&["convert", s(&inf), s(&out.join("back.spz"))]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.matches("warning").count(), 1, "{e}");
    assert!(e.contains("inf.ply") && e.contains("3 infinite opacity logits"), "{e}");
    let back = gast_core::scene::load(out.join("back.spz")).expect("spz");
    let alpha = |o: f32| 1.0 / (1.0 + (-o).exp());
    assert!((alpha(back.opacity_logits[3]) - 1.0).abs() < 1e-5);
    assert!((alpha(back.opacity_logits[130]) - 1.0).abs() < 1e-5);
    assert!(alpha(back.opacity_logits[500]) < 1e-5);
    // NaN stays an error.
    let at = body + (7 * 17 + 9) * 4;
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&inf, &bytes).expect("write");
    let o = gast(&["convert", s(&inf), s(&out.join("nan.spz"))]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("vertex 7: opacity") && stderr(&o).contains("NaN"), "{}", stderr(&o));
    assert!(!out.join("nan.spz").exists());
    std::fs::remove_dir_all(&out).ok();
}
