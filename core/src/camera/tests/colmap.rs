//! COLMAP: the text and binary encodings of one model agree, the writer round
//! trips, and malformed files fail with errors (never panics).

use std::path::Path;

use glam::{Mat3, Vec3};

use super::{assert_close, temp_dir};
use crate::camera::{Camera, CameraError, load, load_colmap, write_colmap_binary, write_colmap_text};

/// Little-endian byte builder for synthetic `.bin` files.
#[derive(Default)]
struct B(Vec<u8>);

impl B {
    fn u32(mut self, v: u32) -> Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn i32(mut self, v: i32) -> Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u64(mut self, v: u64) -> Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn f64s(mut self, vs: &[f64]) -> Self {
        vs.iter().for_each(|v| self.0.extend_from_slice(&v.to_le_bytes()));
        self
    }
    fn name(mut self, s: &str) -> Self {
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
        self
    }
}

const CAMERAS_TXT: &str = "# Camera list with one line of data per camera:\n\
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n\
1 PINHOLE 640 480 500.5 510.25 320 240\n\
\n\
3 OPENCV 800 600 700 705 401.5 299.5 0.01 -0.02 0.001 0.002\n\
7 SIMPLE_PINHOLE 100 50 90 50 25\n";

const IMAGES_TXT: &str = "# Image list with two lines of data per image:\n\
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
#   POINTS2D[] as (X, Y, POINT3D_ID)\n\
5 0.5 0.5 0.5 0.5 1 2 3 3 b.png\n\
10.5 20.25 7 30 40 -1\n\
2 1 0 0 0 0 0 4 1 a.png\n\
\n\
9 2 0 0 0 -1 0.5 2 7 c.jpg\n\
1 2 -1\n";

fn cameras_bin() -> Vec<u8> {
    B::default()
        .u64(3)
        .u32(1)
        .i32(1)
        .u64(640)
        .u64(480)
        .f64s(&[500.5, 510.25, 320.0, 240.0])
        .u32(3)
        .i32(4)
        .u64(800)
        .u64(600)
        .f64s(&[700.0, 705.0, 401.5, 299.5, 0.01, -0.02, 0.001, 0.002])
        .u32(7)
        .i32(0)
        .u64(100)
        .u64(50)
        .f64s(&[90.0, 50.0, 25.0])
        .0
}

fn images_bin() -> Vec<u8> {
    B::default()
        .u64(3)
        .u32(5)
        .f64s(&[0.5, 0.5, 0.5, 0.5, 1.0, 2.0, 3.0])
        .u32(3)
        .name("b.png")
        .u64(2)
        .f64s(&[10.5, 20.25])
        .u64(7)
        .f64s(&[30.0, 40.0])
        .u64(u64::MAX)
        .u32(2)
        .f64s(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 4.0])
        .u32(1)
        .name("a.png")
        .u64(0)
        .u32(9)
        .f64s(&[2.0, 0.0, 0.0, 0.0, -1.0, 0.5, 2.0])
        .u32(7)
        .name("c.jpg")
        .u64(1)
        .f64s(&[1.0, 2.0])
        .u64(u64::MAX)
        .0
}

fn write(dir: &Path, files: &[(&str, &[u8])]) {
    std::fs::create_dir_all(dir).expect("mkdir");
    for (name, bytes) in files {
        std::fs::write(dir.join(name), bytes).expect("write");
    }
}

#[test]
fn text_and_binary_give_identical_cameras() {
    let d = temp_dir("colmap-both");
    let txt = d.join("txt/sparse/0");
    let bin = d.join("bin/sparse/0");
    write(&txt, &[("cameras.txt", CAMERAS_TXT.as_bytes()), ("images.txt", IMAGES_TXT.as_bytes())]);
    write(&bin, &[("cameras.bin", &cameras_bin()), ("images.bin", &images_bin())]);
    let a = load_colmap(d.join("txt")).expect("text model");
    let b = load_colmap(d.join("bin")).expect("binary model");
    assert_eq!(a.cameras, b.cameras);

    let names: Vec<&str> = a.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["a.png", "b.png", "c.jpg"], "sorted by image name");
    let [ca, cb, cc] = [&a.cameras[0], &a.cameras[1], &a.cameras[2]];
    assert_eq!((ca.width, ca.height, ca.fx, ca.fy, ca.cx, ca.cy), (640, 480, 500.5, 510.25, 320.0, 240.0));
    assert_eq!(ca.rotation, Mat3::IDENTITY);
    assert_eq!(ca.center(), Vec3::new(0.0, 0.0, -4.0));
    // q = (½,½,½,½): 120° about (1,1,1), x → y → z → x.
    let expect = Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X);
    assert!(cb.rotation.abs_diff_eq(expect, 1e-6), "{:?}", cb.rotation);
    assert_eq!(cb.translation, Vec3::new(1.0, 2.0, 3.0));
    assert_eq!((cb.fx, cb.fy, cb.cx, cb.cy), (700.0, 705.0, 401.5, 299.5));
    // SIMPLE_PINHOLE shares f; an unnormalised quaternion is normalised.
    assert_eq!((cc.fx, cc.fy, cc.cx, cc.cy, cc.width), (90.0, 90.0, 50.0, 25.0, 100));
    assert_eq!(cc.rotation, Mat3::IDENTITY);
    // The OPENCV camera warns once that distortion is ignored.
    assert_eq!(a.warnings.len(), 1, "{:?}", a.warnings);
    assert!(a.warnings[0].contains("OPENCV") && a.warnings[0].contains("camera 3"));
}

#[test]
fn path_forms_are_all_accepted() {
    let d = temp_dir("colmap-paths");
    let m = d.join("sparse/0");
    write(&m, &[("cameras.txt", CAMERAS_TXT.as_bytes()), ("images.txt", IMAGES_TXT.as_bytes())]);
    write(&m, &[("cameras.bin", &cameras_bin()), ("images.bin", &images_bin())]);
    let want = load_colmap(&d).expect("scene folder");
    for p in [m.clone(), m.join("cameras.txt"), m.join("images.bin")] {
        assert_eq!(load_colmap(&p).expect("colmap path").cameras, want.cameras, "{}", p.display());
        assert_eq!(load(&p).expect("detected").cameras, want.cameras, "{}", p.display());
    }
    assert_eq!(load(&d).expect("detected from the scene folder"), want);
    // A broken binary file is not silently replaced by the text one when asked for.
    std::fs::write(m.join("images.bin"), b"junk").expect("write");
    assert!(load_colmap(&d).is_err());
    assert_eq!(load_colmap(m.join("images.txt")).expect("text chosen").cameras, want.cameras);
}

fn sample_cameras() -> Vec<Camera> {
    let mut cams: Vec<Camera> = (0..7)
        .map(|i| {
            let a = i as f32 * 0.9;
            let eye = Vec3::new(3.0 * a.cos(), -1.0 + 0.3 * i as f32, 3.0 * a.sin());
            let mut c = Camera::look_at(
                format!("img_{i:02}.png"),
                eye,
                Vec3::new(0.1, 0.2, 0.3),
                Vec3::NEG_Y,
                640 + i,
                480,
                40.0 + i as f32,
            );
            c.cx += 3.25;
            c.fy *= 1.01;
            c
        })
        .collect();
    cams.sort_by(|a, b| a.name.cmp(&b.name));
    cams
}

#[test]
fn writer_round_trips_text_and_binary() {
    let cams = sample_cameras();
    let d = temp_dir("colmap-rt");
    write_colmap_text(d.join("t"), &cams).expect("write text");
    write_colmap_binary(d.join("b"), &cams).expect("write bin");
    let t = load_colmap(d.join("t")).expect("read text");
    let b = load_colmap(d.join("b")).expect("read bin");
    assert_eq!(t.cameras, b.cameras, "text and binary read back the same");
    assert!(t.warnings.is_empty());
    for (x, y) in cams.iter().zip(&t.cameras) {
        assert_close(x, y, 1e-6);
        assert!(x.center().abs_diff_eq(y.center(), 1e-5));
    }
}

fn expect_err(d: &Path, files: &[(&str, &[u8])], what: &str) -> CameraError {
    let _ = std::fs::remove_dir_all(d);
    write(d, files);
    match load_colmap(d) {
        Ok(set) => panic!("{what}: expected an error, got {} cameras", set.cameras.len()),
        Err(e) => e,
    }
}

#[test]
fn truncated_binary_files_fail_cleanly() {
    let d = temp_dir("colmap-trunc");
    let (cams, ims) = (cameras_bin(), images_bin());
    for cut in 0..cams.len() {
        expect_err(&d, &[("cameras.bin", &cams[..cut]), ("images.bin", &ims)], &format!("cameras cut at {cut}"));
    }
    for cut in 0..ims.len() {
        expect_err(&d, &[("cameras.bin", &cams), ("images.bin", &ims[..cut])], &format!("images cut at {cut}"));
    }
    let mut longer = ims.clone();
    longer.push(0);
    let e = expect_err(&d, &[("cameras.bin", &cams), ("images.bin", &longer)], "trailing byte");
    assert!(e.to_string().contains("1 more bytes"), "{e}");
}

#[test]
fn absurd_binary_counts_fail_at_once() {
    let d = temp_dir("colmap-counts");
    let ims = images_bin();
    let huge = B::default().u64(u64::MAX).0;
    let e = expect_err(&d, &[("cameras.bin", &huge), ("images.bin", &ims)], "camera count");
    assert!(e.to_string().contains("num_cameras") && e.to_string().contains(&u64::MAX.to_string()), "{e}");
    let e =
        expect_err(&d, &[("cameras.bin", &cameras_bin()), ("images.bin", &B::default().u64(1 << 40).0)], "image count");
    assert!(e.to_string().contains("num_reg_images"), "{e}");
    // A 2D point count far beyond the file.
    let mut bad = images_bin();
    let at = 8 + 4 + 56 + 4 + "b.png".len() + 1;
    bad[at..at + 8].copy_from_slice(&(u64::MAX / 2).to_le_bytes());
    let e = expect_err(&d, &[("cameras.bin", &cameras_bin()), ("images.bin", &bad)], "points count");
    assert!(e.to_string().contains("num_points2D") && e.to_string().contains("b.png"), "{e}");
    // Unknown model id; a size beyond u32; a zero focal length.
    let mut bad = cameras_bin();
    bad[12..16].copy_from_slice(&99i32.to_le_bytes());
    let e = expect_err(&d, &[("cameras.bin", &bad), ("images.bin", &ims)], "model id");
    assert!(matches!(e, CameraError::UnknownModel { .. }) && e.to_string().contains("99"), "{e}");
    let mut bad = cameras_bin();
    bad[16..24].copy_from_slice(&(1u64 << 33).to_le_bytes());
    let e = expect_err(&d, &[("cameras.bin", &bad), ("images.bin", &ims)], "width");
    assert!(e.to_string().contains("width"), "{e}");
    let mut bad = cameras_bin();
    bad[32..40].copy_from_slice(&0f64.to_le_bytes());
    let e = expect_err(&d, &[("cameras.bin", &bad), ("images.bin", &ims)], "focal");
    assert!(e.to_string().contains("params[0]"), "{e}");
}

#[test]
fn malformed_text_files_name_the_line_and_field() {
    let d = temp_dir("colmap-text");
    let ims = IMAGES_TXT.as_bytes();
    let cases: [(&str, &str, &str); 5] = [
        ("1 PINHOLE 640 480 500 abc 320 240\n", "\"abc\"", "PARAMS[1]"),
        ("1 PINHOLE 640 480 500 500 320\n", "4 parameters for PINHOLE", "found 3"),
        ("1 FISHEYE_X 640 480 500 500 320 240\n", "FISHEYE_X", "OPENCV"),
        ("1 PINHOLE -640 480 500 500 320 240\n", "WIDTH", "\"-640\""),
        ("1 PINHOLE 640 480 500 500 320 240\n1 PINHOLE 640 480 500 500 320 240\n", "unique camera ids", "camera 1"),
    ];
    for (cams, a, b) in cases {
        let e = expect_err(&d, &[("cameras.txt", cams.as_bytes()), ("images.txt", ims)], cams);
        let msg = e.to_string();
        assert!(msg.contains(a) && msg.contains(b) && msg.contains("cameras.txt"), "{msg}");
    }
    let cams = CAMERAS_TXT.as_bytes();
    let cases: [(&str, &str); 5] = [
        ("1 1 0 0 0 0 0 4 1\n\n", "10 fields"),
        ("1 1 0 0 x 0 0 4 1 a.png\n\n", "QVEC[3]"),
        ("1 0 0 0 0 0 0 4 1 a.png\n\n", "non-zero quaternion"),
        ("1 1 0 0 0 0 0 4 2 a.png\n\n", "camera_id"),
        ("# nothing\n", "at least one registered image"),
    ];
    for (images, a) in cases {
        let e = expect_err(&d, &[("cameras.txt", cams), ("images.txt", images.as_bytes())], images);
        assert!(e.to_string().contains(a) && e.to_string().contains("images.txt"), "{e}");
    }
    let e = expect_err(&d, &[("cameras.txt", cams)], "no images file");
    assert!(matches!(e, CameraError::NotFound { .. }) && e.to_string().contains("images.bin or images.txt"), "{e}");
}
