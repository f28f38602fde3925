//! LLFF `poses_bounds.npy`: the axis order against values worked out by hand
//! from row 0 of the real fern file, the focal per images folder, the row ↔
//! sorted image pairing, and malformed files refused with what was wrong.

use std::path::{Path, PathBuf};

use glam::Vec3;

use super::temp_dir;
use crate::camera::{CameraError, load, load_llff};
use crate::vision::weights::tests::shared;

/// The focal length in row 0 of fern's `poses_bounds.npy`, for the 4032×3024 photos.
const FERN_FOCAL: f32 = 3_260.526_3;

/// The fern dataset folder, or `None` (after a loud message) when absent.
fn fern() -> Option<PathBuf> {
    shared("data/datasets/fern/poses_bounds.npy").map(|p| p.parent().expect("dataset folder").to_path_buf())
}

/// An `.npy` file as `np.save` writes it (format 1.0, header padded to 64 bytes).
fn npy(descr: &str, fortran: bool, shape: &str, data: &[f64]) -> Vec<u8> {
    let fortran = if fortran { "True" } else { "False" };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    data.iter().for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
    out
}

/// A row whose camera has LLFF's identity-like pose (down = +y, right = +x,
/// back = −z, i.e. ours is the identity) at `centre`, with hwf for 12×16 photos.
fn row(centre: [f64; 3]) -> [f64; 17] {
    [
        0.0, 1.0, 0.0, centre[0], 12.0, //
        1.0, 0.0, 0.0, centre[1], 16.0, //
        0.0, 0.0, -1.0, centre[2], 20.0, //
        1.5, 9.0,
    ]
}

fn write_image(path: &Path, w: u32, h: u32) {
    image::RgbImage::new(w, h).save(path).expect("write image");
}

#[test]
fn fern_row_0_axes_match_the_hand_derived_pose() {
    let Some(dir) = fern() else { return };
    let set = load(&dir).expect("fern loads from its folder");
    assert!(set.warnings.is_empty(), "{:?}", set.warnings);
    assert_eq!(set.cameras.len(), 20);
    let c = &set.cameras[0];
    assert_eq!(c.name, "images_8/image000.png");
    assert_eq!((c.width, c.height), (504, 378));
    let f = FERN_FOCAL / 8.0;
    assert!((c.fx - f).abs() < 1e-3 && (c.fy - f).abs() < 1e-3, "fx {} fy {}", c.fx, c.fy);
    assert_eq!((c.cx, c.cy), (252.0, 189.0));
    // Row 0 of the file: columns (down, right, back) of the rotation, then the centre.
    let down = Vec3::new(0.022_422_516, 0.999_121, -0.035_418_003);
    let right = Vec3::new(0.989_630_7, -0.027_209_079, -0.141_034_27);
    let back = Vec3::new(-0.141_874, -0.031_888_4, -0.989_370_96);
    let centre = Vec3::new(-3.679_179, -1.603_791_6, -0.276_802_06);
    assert!(c.center().abs_diff_eq(centre, 1e-4), "{}", c.center());
    // Ours: x right, y down, z forward (= −back).
    let c2w = c.rotation.transpose();
    assert!((c2w * Vec3::X).abs_diff_eq(right, 1e-5), "right {}", c2w * Vec3::X);
    assert!((c2w * Vec3::Y).abs_diff_eq(down, 1e-5), "down {}", c2w * Vec3::Y);
    assert!((c2w * Vec3::Z).abs_diff_eq(-back, 1e-5), "forward {}", c2w * Vec3::Z);
    let [near, far] = set.depth_bounds[0];
    assert!((near - 17.747_087).abs() < 1e-4 && (far - 78.257_49).abs() < 1e-4, "{near} {far}");
    assert_eq!(set.depth_bounds.len(), 20);
    // Rows pair with the sorted images, and the file itself loads the same.
    for (i, c) in set.cameras.iter().enumerate() {
        assert_eq!(c.name, format!("images_8/image{i:03}.png"));
    }
    assert_eq!(load(dir.join("poses_bounds.npy")).expect("the .npy file loads").cameras, set.cameras);
}

#[test]
fn fern_focal_scales_with_the_images_folder() {
    let Some(dir) = fern() else { return };
    let eighth = load_llff(&dir, None).expect("images_8 by default");
    let quarter = load_llff(&dir, Some("images_4")).expect("images_4");
    assert_eq!(quarter.cameras.len(), 20);
    for (a, b) in eighth.cameras.iter().zip(&quarter.cameras) {
        assert_eq!((b.width, b.height), (1008, 756));
        assert!(b.name.starts_with("images_4/"), "{}", b.name);
        assert!((b.fx - FERN_FOCAL / 4.0).abs() < 1e-3 && (b.fx - 2.0 * a.fx).abs() < 1e-3);
        assert!((b.cx - 2.0 * a.cx).abs() < 1e-6 && (b.cy - 2.0 * a.cy).abs() < 1e-6);
        assert_eq!((a.rotation, a.translation), (b.rotation, b.translation));
    }
    let err = load_llff(&dir, Some("images_2")).expect_err("no images_2 in fern");
    assert!(matches!(err, CameraError::NoFolder { .. }) && err.to_string().contains("images_2"), "{err}");
}

#[test]
fn rows_pair_with_the_sorted_images_and_sparse_without_images_is_skipped() {
    let d = temp_dir("llff-order");
    let rows: Vec<f64> = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]].iter().flat_map(|c| row(*c)).collect();
    std::fs::write(d.join("poses_bounds.npy"), npy("<f8", false, "(3, 17)", &rows)).expect("write npy");
    let images = d.join("images");
    std::fs::create_dir_all(&images).expect("mkdir");
    // Created out of order; a non-image file is ignored.
    write_image(&images.join("c.png"), 8, 6);
    write_image(&images.join("a.png"), 8, 6);
    write_image(&images.join("b.jpg"), 8, 6);
    std::fs::write(images.join("notes.txt"), "not an image").expect("write");
    // An LLFF-style sparse/0 without images.bin is not a COLMAP model.
    std::fs::create_dir_all(d.join("sparse/0")).expect("mkdir");
    std::fs::write(d.join("sparse/0/cameras.bin"), [0u8; 8]).expect("write");

    let set = load(&d).expect("LLFF detected");
    let names: Vec<&str> = set.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["images/a.png", "images/b.jpg", "images/c.png"]);
    for (i, c) in set.cameras.iter().enumerate() {
        assert!(c.center().abs_diff_eq(Vec3::new(i as f32, 0.0, 0.0), 1e-6), "{}: {}", c.name, c.center());
        assert!(c.rotation.abs_diff_eq(glam::Mat3::IDENTITY, 1e-6), "{:?}", c.rotation);
        // 8×6 images of 16×12 photos: half the focal.
        assert_eq!((c.width, c.height, c.fx, c.fy, c.cx, c.cy), (8, 6, 10.0, 10.0, 4.0, 3.0));
    }
    assert_eq!(set.depth_bounds, vec![[1.5, 9.0]; 3]);

    // One image too many.
    write_image(&images.join("d.png"), 8, 6);
    let err = load(&d).expect_err("4 images for 3 rows");
    assert!(err.to_string().contains("3 images") && err.to_string().contains("found 4"), "{err}");
    // No images folder at all.
    std::fs::remove_dir_all(&images).expect("rm");
    let err = load(&d).expect_err("no images");
    assert!(matches!(err, CameraError::NotFound { .. }) && err.to_string().contains("images_8"), "{err}");
}

#[test]
fn malformed_npy_files_are_refused_with_what_was_found() {
    let d = temp_dir("llff-bad");
    std::fs::create_dir_all(d.join("images")).expect("mkdir");
    write_image(&d.join("images/a.png"), 8, 6);
    let good = npy("<f8", false, "(1, 17)", &row([0.0; 3]));
    let check = |bytes: &[u8], needles: &[&str]| {
        let p = d.join("poses_bounds.npy");
        std::fs::write(&p, bytes).expect("write");
        let err = load(&p).expect_err("malformed");
        let msg = err.to_string();
        assert!(msg.contains("poses_bounds.npy"), "names the file: {msg}");
        for n in needles {
            assert!(msg.contains(n), "{n:?} not in: {msg}");
        }
        err
    };
    assert!(load_llff(d.join("poses_bounds.npy"), None).is_err(), "absent file");
    std::fs::write(d.join("poses_bounds.npy"), &good).expect("write");
    assert!(load(&d).is_ok(), "the well-formed file loads");

    let err = check(&good[..good.len() - 5], &["truncated", "136"]);
    assert!(matches!(err, CameraError::Truncated { needed: 136, available: 131, .. }), "{err:?}");
    check(&good[..40], &["header", "truncated"]);
    check(&npy("<f4", false, "(1, 17)", &[0.0; 9]), &["header.descr", "'<f8'", "<f4"]);
    check(&npy(">f8", false, "(1, 17)", &row([0.0; 3])), &["header.descr", ">f8"]);
    check(&npy("<f8", false, "(1, 15)", &[0.0; 15]), &["header.shape", "(N, 17)", "(1, 15)"]);
    check(&npy("<f8", false, "(17,)", &[0.0; 17]), &["header.shape", "(17,)"]);
    check(&npy("<f8", true, "(1, 17)", &row([0.0; 3])), &["fortran_order", "C order", "True"]);
    check(b"PK\x03\x04 a zip, not an npy file", &["magic", "NUMPY"]);
    let mut extra = good.clone();
    extra.extend_from_slice(&[0; 8]);
    check(&extra, &["8 more bytes"]);
    let mut bad_hwf = row([0.0; 3]);
    bad_hwf[14] = 0.0;
    check(&npy("<f8", false, "(1, 17)", &bad_hwf), &["row 0.hwf"]);
    let mut nan = row([0.0; 3]);
    nan[3] = f64::NAN;
    check(&npy("<f8", false, "(1, 17)", &nan), &["row 0", "finite"]);
}
