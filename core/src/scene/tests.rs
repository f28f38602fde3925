//! Robustness of the scene readers on small synthetic files: every encoding
//! the readers accept, and every way a file can be broken. Each broken file
//! must give an error (never a panic, never a huge allocation) that names the
//! file, the element or field, and what was expected and found.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::test_util::{sample, scratch};
use super::{Gaussians, SceneError, atomic_write, load, save_ply};

/// The 14 properties of a degree-0 INRIA file, in a non-trainer order, plus
/// normals and an unknown extra.
pub(super) const PROPS: [&str; 14] = [
    "x", "y", "z", "opacity", "f_dc_0", "f_dc_1", "f_dc_2", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2",
    "rot_3",
];

fn row(i: usize) -> [f64; 14] {
    let f = i as f64;
    [f, -f, 0.5 * f, 0.25, 0.1, 0.2, 0.3, -1.0, -2.0, -3.0, 1.0, 0.0, 0.5, 0.0]
}

fn header(format: &str, n: usize, props: &[(&str, &str)]) -> String {
    let mut h = format!("ply\nformat {format} 1.0\ncomment synthetic\nelement vertex {n}\n");
    for (ty, name) in props {
        h.push_str(&format!("property {ty} {name}\n"));
    }
    h + "end_header\n"
}

fn float_props() -> Vec<(&'static str, &'static str)> {
    PROPS.iter().map(|p| ("float", *p)).collect()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write test file");
    p
}

/// A binary little-endian file of `n` rows of `row()`, every property float.
pub(super) fn binary_le(n: usize) -> Vec<u8> {
    let mut b = header("binary_little_endian", n, &float_props()).into_bytes();
    for i in 0..n {
        for v in row(i) {
            b.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    b
}

fn check_row(g: &Gaussians, i: usize) {
    let r = row(i).map(|v| v as f32);
    assert_eq!(g.means[i], [r[0], r[1], r[2]]);
    assert_eq!(g.opacity_logits[i], r[3]);
    assert_eq!(&g.sh_of(i)[..3], &[r[4], r[5], r[6]]);
    assert_eq!(g.log_scales[i], [r[7], r[8], r[9]]);
    assert_eq!(g.quats[i], [r[10], r[11], r[12], r[13]]);
}

/// Loads `path`, expects an error whose message contains the file name and every needle.
fn expect_err(path: &Path, needles: &[&str]) -> SceneError {
    let err = match load(path) {
        Ok(g) => panic!("{} loaded ({} Gaussians) but should have failed", path.display(), g.len()),
        Err(e) => e,
    };
    let msg = err.to_string();
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    assert!(msg.contains(&name), "error does not name the file {name}: {msg}");
    for n in needles {
        assert!(msg.contains(n), "error lacks {n:?}: {msg}");
    }
    err
}

#[test]
fn ascii_big_endian_little_endian_and_double_agree() {
    let dir = scratch("encodings");
    let n = 3;
    let le = load(write(&dir, "le.ply", &binary_le(n))).expect("little-endian");
    for i in 0..n {
        check_row(&le, i);
    }

    let mut be = header("binary_big_endian", n, &float_props()).into_bytes();
    let mut ascii = header("ascii", n, &float_props());
    let mut dbl_props = float_props();
    dbl_props[0].0 = "double";
    dbl_props[8].0 = "double";
    let mut dbl = header("binary_little_endian", n, &dbl_props).into_bytes();
    for i in 0..n {
        for (j, v) in row(i).into_iter().enumerate() {
            be.extend_from_slice(&(v as f32).to_be_bytes());
            ascii.push_str(&format!("{v} "));
            if j == 0 || j == 8 {
                dbl.extend_from_slice(&v.to_le_bytes());
            } else {
                dbl.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
        ascii.push('\n');
    }
    assert_eq!(load(write(&dir, "be.ply", &be)).expect("big-endian"), le);
    assert_eq!(load(write(&dir, "ascii.ply", ascii.as_bytes())).expect("ascii"), le);
    assert_eq!(load(write(&dir, "double.ply", &dbl)).expect("double"), le);
}

#[test]
fn unknown_properties_and_elements_are_ignored() {
    let dir = scratch("extras");
    let mut props = vec![("float", "nx"), ("uchar", "red"), ("double", "curvature")];
    props.extend(float_props());
    let mut b = header("binary_little_endian", 2, &props).into_bytes();
    // An extra element after the vertices.
    let h = String::from_utf8(b.clone())
        .expect("utf8")
        .replace("end_header\n", "element extra 1\nproperty int k\nend_header\n");
    b = h.into_bytes();
    for i in 0..2 {
        b.extend_from_slice(&9.0f32.to_le_bytes());
        b.push(7);
        b.extend_from_slice(&1.5f64.to_le_bytes());
        for v in row(i) {
            b.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    b.extend_from_slice(&42i32.to_le_bytes());
    let g = load(write(&dir, "extras.ply", &b)).expect("load");
    check_row(&g, 0);
    check_row(&g, 1);
}

#[test]
fn sh_degree_from_f_rest_count() {
    let dir = scratch("frest");
    for (count, ok) in [(9, true), (24, true), (45, true), (10, false), (3, false)] {
        let mut props = float_props();
        let names: Vec<String> = (0..count).map(|j| format!("f_rest_{j}")).collect();
        props.extend(names.iter().map(|n| ("float", n.as_str())));
        let mut b = header("binary_little_endian", 1, &props).into_bytes();
        b.extend(row(0).iter().flat_map(|&v| (v as f32).to_le_bytes()));
        b.extend((0..count).flat_map(|j| (j as f32).to_le_bytes()));
        let p = write(&dir, &format!("rest{count}.ply"), &b);
        if ok {
            let g = load(&p).expect("load");
            assert_eq!(g.sh_coeffs() * 3 - 3, count);
        } else {
            expect_err(&p, &["f_rest", &format!("{count} f_rest properties"), "0, 9, 24 or 45"]);
        }
    }
    // Right count, wrong names: f_rest_8 missing, f_rest_9 instead.
    let mut props = float_props();
    let names: Vec<String> = (0..10).filter(|&j| j != 8).map(|j| format!("f_rest_{j}")).collect();
    props.extend(names.iter().map(|n| ("float", n.as_str())));
    let mut b = header("binary_little_endian", 1, &props).into_bytes();
    b.extend(std::iter::repeat_n(0u8, 4 * (14 + 9)));
    expect_err(&write(&dir, "misnamed_rest.ply", &b), &["vertex.f_rest_8", "f_rest_0 … f_rest_8"]);
}

#[test]
fn missing_misnamed_and_mistyped_properties() {
    let dir = scratch("props");
    let mut props = float_props();
    props.retain(|p| p.1 != "opacity");
    let b = header("binary_little_endian", 0, &props);
    expect_err(&write(&dir, "missing.ply", b.as_bytes()), &["vertex.opacity", "property opacity", "no such property"]);

    let mut props = float_props();
    props[8].1 = "scale1";
    let b = header("binary_little_endian", 0, &props);
    expect_err(&write(&dir, "misnamed.ply", b.as_bytes()), &["vertex.scale_1", "scale1"]);

    let mut props = float_props();
    props[3].0 = "uchar";
    let b = header("binary_little_endian", 0, &props);
    expect_err(&write(&dir, "uchar.ply", b.as_bytes()), &["vertex.opacity", "float or double", "uchar"]);

    let b =
        header("binary_little_endian", 0, &float_props()).replace("property float x\n", "property list uchar int x\n");
    expect_err(&write(&dir, "list.ply", b.as_bytes()), &["vertex.x", "list"]);

    let b = header("binary_little_endian", 0, &float_props()).replace("property float y\n", "property float16 y\n");
    expect_err(&write(&dir, "badtype.ply", b.as_bytes()), &["vertex.y", "float16"]);

    let b = "ply\nformat binary_little_endian 1.0\nelement face 0\nend_header\n";
    expect_err(&write(&dir, "novertex.ply", b.as_bytes()), &["element vertex", "face"]);
}

#[test]
fn truncated_and_oversized_counts_fail_before_allocating() {
    let dir = scratch("truncated");
    let full = binary_le(4);
    let cut = &full[..full.len() - 5];
    expect_err(&write(&dir, "cut.ply", cut), &["element vertex", "a count of 4"]);

    let mut ascii = header("ascii", 3, &float_props());
    ascii.push_str("1 2 3 4 5 6 7 8 9 10 11 12 13 14\n1 2 3 4 5 6 7 8 9 10 11 12 13 14\n1.000000000000000000000000000000 2.0000000000000000000000000000 3\n");
    expect_err(&write(&dir, "cut_ascii.ply", ascii.as_bytes()), &["vertex[2].", "truncated"]);

    let mut ascii = header("ascii", 1, &float_props());
    ascii.push_str("1 2 3 4 5 abc 7 8 9 10 11 12 13 14\n");
    expect_err(&write(&dir, "bad_token.ply", ascii.as_bytes()), &["vertex[0].f_dc_1", "\"abc\""]);

    for (name, format) in [("huge.ply", "binary_little_endian"), ("huge_ascii.ply", "ascii")] {
        let mut b = header(format, 1_000_000_000_000, &float_props()).into_bytes();
        b.extend_from_slice(&full[full.len() - 56..]);
        let t = Instant::now();
        expect_err(&write(&dir, name, &b), &["element vertex", "1000000000000"]);
        assert!(t.elapsed().as_secs_f64() < 0.5, "a huge count must fail at once");
    }
    let b = header("binary_little_endian", usize::MAX, &float_props());
    expect_err(&write(&dir, "overflow.ply", b.as_bytes()), &["overflows"]);

    let b = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n";
    expect_err(&write(&dir, "no_end.ply", b), &["header", "end_header"]);
}

#[test]
fn non_finite_values_and_zero_quaternions_name_the_vertex() {
    let dir = scratch("nonfinite");
    let bytes_with = |vertex: usize, prop: usize, v: f32| {
        let mut b = binary_le(4);
        let at = b.len() - 4 * 14 * 4 + (vertex * 14 + prop) * 4;
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        b
    };
    expect_err(&write(&dir, "nan.ply", &bytes_with(2, 8, f32::NAN)), &["vertex 2", "scale_1", "finite", "NaN"]);
    // Infinite opacities and log-scales are clamped (tests_write.rs); elsewhere inf is refused.
    expect_err(&write(&dir, "inf.ply", &bytes_with(3, 1, f32::INFINITY)), &["vertex 3", "position y", "inf"]);
    expect_err(&write(&dir, "nan_sh.ply", &bytes_with(1, 5, f32::NAN)), &["vertex 1", "SH coefficient 0, channel 1"]);
    let mut b = bytes_with(1, 10, 0.0);
    let at = b.len() - 4 * 14 * 4 + 14 * 4 + 12 * 4;
    b[at..at + 4].copy_from_slice(&0.0f32.to_le_bytes());
    expect_err(&write(&dir, "zeroq.ply", &b), &["vertex 1", "rotation", "non-zero quaternion"]);
    // A double too large for f32 becomes infinite and is reported.
    let mut props = float_props();
    props[0].0 = "double";
    let mut b = header("binary_little_endian", 1, &props).into_bytes();
    b.extend_from_slice(&1e300f64.to_le_bytes());
    b.extend(row(0)[1..].iter().flat_map(|&v| (v as f32).to_le_bytes()));
    expect_err(&write(&dir, "big_double.ply", &b), &["vertex 0", "position x"]);
}

#[test]
fn garbage_empty_and_missing_files() {
    let dir = scratch("garbage");
    let e = expect_err(&write(&dir, "empty.ply", b""), &["empty file", "\"ply\""]);
    assert!(matches!(e, SceneError::UnknownFormat { .. }));
    let e = expect_err(&write(&dir, "noise.txt", &[0xde, 0xad, 0xbe, 0xef, 1, 2, 3]), &["\"txt\"", "de ad be ef"]);
    assert!(matches!(e, SceneError::UnknownFormat { .. }));
    expect_err(&write(&dir, "plyish.ply", b"ply\n\x00\xff\xfe garbage end_header\n"), &["header"]);
    let e = expect_err(&dir.join("absent.ply"), &[]);
    assert!(matches!(e, SceneError::Io { .. }));
    let empty_dir = dir.join("not_a_sog");
    std::fs::create_dir_all(&empty_dir).expect("mkdir");
    let e = load(&empty_dir).expect_err("directory without meta.json");
    assert!(e.to_string().contains("meta.json"), "{e}");
}

#[test]
fn save_ply_never_half_overwrites() {
    let dir = scratch("atomic");
    let p = dir.join("scene.ply");
    let g = sample(10, 1);
    save_ply(&p, &g).expect("save");
    let before = std::fs::read(&p).expect("read");

    // A writer that fails halfway leaves the old file intact and no temporary behind.
    let err = atomic_write(&p, |w| {
        use std::io::Write;
        w.write_all(b"ply\nformat binary_little_endian 1.0\n")?;
        Err(std::io::Error::other("disk full (simulated)"))
    })
    .expect_err("must fail");
    assert!(err.to_string().contains("scene.ply") && err.to_string().contains("disk full"), "{err}");
    assert_eq!(std::fs::read(&p).expect("read"), before);
    let leftovers: Vec<_> =
        std::fs::read_dir(&dir).expect("ls").filter_map(|e| e.ok()).map(|e| e.file_name()).collect();
    assert_eq!(leftovers.len(), 1, "temporary file left behind: {leftovers:?}");

    // Inconsistent Gaussians are refused before anything is written.
    let mut bad = sample(3, 0);
    bad.quats.pop();
    assert!(save_ply(&p, &bad).is_err());
    assert_eq!(std::fs::read(&p).expect("read"), before);
    // So are scenes no reader would accept.
    let mut nan = sample(3, 0);
    nan.log_scales[2][1] = f32::NAN;
    let e = save_ply(&p, &nan).expect_err("NaN refused").to_string();
    assert!(e.contains("vertex 2") && e.contains("scale_1"), "{e}");
    assert_eq!(std::fs::read(&p).expect("read"), before);

    // A successful save replaces the file.
    let g2 = sample(5, 3);
    save_ply(&p, &g2).expect("save over");
    assert_eq!(load(&p).expect("load"), g2);
}

#[path = "tests_packed.rs"]
mod packed;
