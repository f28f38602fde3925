//! COLMAP `points3D`: the real fern file (10,091 points, in the frame of its
//! `poses_bounds.npy`), the text and binary encodings of one small set, and
//! truncated or malformed files refused with the record at fault.

use glam::Vec3;

use super::temp_dir;
use crate::camera::{CameraError, ColmapPoints, find_colmap_points, load, load_colmap_points};
use crate::vision::weights::tests::shared;

const POINTS_TXT: &str = "# 3D point list with one line of data per point:\n\
#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
# Number of points: 3, mean track length: 1.6666\n\
1 0.5 -1.25 3 255 0 10 0.7 1 4 2 9\n\
\n\
7 -2 0 1e-3 12 34 56 1.5 3 1\n\
8 10 20 30 0 0 0 0 1 2 3 4 5 6\n";

fn expected() -> ColmapPoints {
    ColmapPoints {
        positions: vec![Vec3::new(0.5, -1.25, 3.0), Vec3::new(-2.0, 0.0, 1e-3), Vec3::new(10.0, 20.0, 30.0)],
        colors: vec![[255, 0, 10], [12, 34, 56], [0, 0, 0]],
    }
}

/// One binary record: id, position, colour, track as (image id, point index) pairs.
type Record = (u64, [f64; 3], [u8; 3], &'static [i32]);

/// The same three points in the binary encoding.
fn points_bin() -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&3u64.to_le_bytes());
    let recs: [Record; 3] = [
        (1, [0.5, -1.25, 3.0], [255, 0, 10], &[1, 4, 2, 9]),
        (7, [-2.0, 0.0, 1e-3], [12, 34, 56], &[3, 1]),
        (8, [10.0, 20.0, 30.0], [0, 0, 0], &[1, 2, 3, 4, 5, 6]),
    ];
    for (id, xyz, rgb, track) in recs {
        b.extend_from_slice(&id.to_le_bytes());
        xyz.iter().for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
        b.extend_from_slice(&rgb);
        b.extend_from_slice(&0.5f64.to_le_bytes());
        b.extend_from_slice(&(track.len() as u64 / 2).to_le_bytes());
        track.iter().for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    }
    b
}

#[test]
fn fern_points_lie_in_front_of_its_llff_cameras() {
    let Some(path) = shared("data/datasets/fern/sparse/0/points3D.bin") else { return };
    let points = load_colmap_points(&path).expect("fern points3D.bin");
    assert_eq!(points.len(), 10_091);
    assert_eq!(points.colors.len(), 10_091);
    // The first record, read by hand: id 14662 at (−1.5073, 10.2857, 26.3389), colour (154, 154, 150).
    assert!(points.positions[0].abs_diff_eq(Vec3::new(-1.507_302, 10.285_668, 26.338_946), 1e-4));
    assert_eq!(points.colors[0], [154, 154, 150]);
    let dataset = path.ancestors().nth(3).expect("dataset folder");
    assert_eq!(find_colmap_points(dataset).as_deref(), Some(path.as_path()));
    assert_eq!(find_colmap_points(&dataset.join("poses_bounds.npy")).as_deref(), Some(path.as_path()));
    // Same world frame as the poses: nearly every point is seen by camera 0
    // (99.2% when written, all of them in front of it).
    let cams = load(dataset).expect("fern cameras").cameras;
    let cam = &cams[0];
    let inside = points
        .positions
        .iter()
        .filter_map(|p| cam.project(*p))
        .filter(|uv| uv.x >= 0.0 && uv.y >= 0.0 && uv.x < cam.width as f32 && uv.y < cam.height as f32)
        .count();
    assert!(inside as f32 > 0.95 * points.len() as f32, "{inside} of {} points in view", points.len());
    assert!(points.positions.iter().all(|p| cam.world_to_camera(*p).z > 0.0));

    // The real file cut short fails inside a record, naming the point (a cut
    // inside a track shows as a track length that no longer fits).
    let d = temp_dir("fern-points");
    let bytes = std::fs::read(&path).expect("read");
    for keep in [bytes.len() * 9 / 10, bytes.len() - 1] {
        std::fs::write(d.join("points3D.bin"), &bytes[..keep]).expect("write");
        let err = load_colmap_points(d.join("points3D.bin")).expect_err("truncated");
        let record = match &err {
            CameraError::Truncated { record, .. } | CameraError::Format { record, .. } => record.clone(),
            other => panic!("{other:?}"),
        };
        assert!(record.starts_with("point ") && err.to_string().contains("points3D.bin"), "{err}");
    }
}

#[test]
fn text_and_binary_points_agree() {
    let d = temp_dir("points");
    let model = d.join("sparse/0");
    std::fs::create_dir_all(&model).expect("mkdir");
    std::fs::write(model.join("points3D.txt"), POINTS_TXT).expect("write");
    assert_eq!(find_colmap_points(&d), Some(model.join("points3D.txt")));
    assert_eq!(load_colmap_points(&d).expect("text from the scene folder"), expected());
    std::fs::write(model.join("points3D.bin"), points_bin()).expect("write");
    assert_eq!(find_colmap_points(&d), Some(model.join("points3D.bin")), "binary preferred");
    assert_eq!(load_colmap_points(model.join("points3D.bin")).expect("binary"), expected());
    let empty = d.join("empty");
    std::fs::create_dir_all(&empty).expect("mkdir");
    assert_eq!(find_colmap_points(&empty), None);
    assert!(matches!(load_colmap_points(&empty), Err(CameraError::NotFound { .. })));
}

#[test]
fn truncated_and_malformed_points_are_refused() {
    let d = temp_dir("points-bad");
    let bin = d.join("points3D.bin");
    let full = points_bin();
    let fail = |bytes: &[u8]| {
        std::fs::write(&bin, bytes).expect("write");
        load_colmap_points(&bin).expect_err("malformed")
    };
    // Cut inside the last point's error: 8, then 51 + 16 and 51 + 8 for the
    // first two points, 35 bytes of the third's id, xyz and rgb, 3 of its error.
    let cut = 8 + (51 + 16) + (51 + 8) + 35 + 3;
    let err = fail(&full[..cut]);
    assert!(
        matches!(&err, CameraError::Truncated { record, needed: 8, available: 3, .. } if record == "point 8.error"),
        "{err:?}"
    );
    // Cut inside a track: its length no longer fits, named as such.
    let err = fail(&full[..full.len() - 5]);
    assert!(err.to_string().contains("point 8.track_length"), "{err}");
    assert!(err.to_string().contains("points3D.bin"), "{err}");
    // A count larger than the file can hold fails before anything is allocated.
    let mut huge = full.clone();
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(fail(&huge).to_string().contains("num_points3D"));
    // A track longer than the file.
    let mut track = full.clone();
    track[51..59].copy_from_slice(&1000u64.to_le_bytes());
    assert!(fail(&track).to_string().contains("point 1.track_length"));
    let mut extra = full.clone();
    extra.push(0);
    assert!(fail(&extra).to_string().contains("1 more bytes"));
    let mut nan = full;
    nan[16..24].copy_from_slice(&f64::NAN.to_le_bytes());
    assert!(fail(&nan).to_string().contains("point 1.xyz"));

    let txt = d.join("points3D.txt");
    for (text, needle) in [
        ("1 0 0 0 255 0 0\n", "7 fields"),
        ("1 0 0 0 255 0 0 0.5 3\n", "9 fields"),
        ("1 0 0 zero 255 0 0 0.5\n", "line 1.Z"),
        ("# c\n1 0 0 0 256 0 0 0.5\n", "line 2.R"),
        ("1 0 0 inf 1 2 3 0.5\n", "line 1.xyz"),
    ] {
        std::fs::write(&txt, text).expect("write");
        let err = load_colmap_points(&txt).expect_err(text);
        assert!(err.to_string().contains(needle) && err.to_string().contains("points3D.txt"), "{needle}: {err}");
    }
}
