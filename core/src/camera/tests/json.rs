//! INRIA `cameras.json` and NeRF `transforms.json`: conventions on hand-made
//! poses, detection by `load`, and errors for malformed documents.

use glam::{Vec2, Vec3};
use serde_json::json;

use super::{assert_close, temp_dir};
use crate::camera::{Camera, CameraError, beside_scene, load, load_inria, load_transforms, write_inria};

/// A cameras.json entry the way the 3DGS trainer writes it: invert [R|t] and
/// write the inverse's rotation rows and translation.
fn inria_entry(id: usize, c: &Camera) -> serde_json::Value {
    let c2w = c.rotation.transpose();
    let rows: Vec<[f32; 3]> = (0..3).map(|i| c2w.row(i).to_array()).collect();
    json!({"id": id, "img_name": c.name, "width": c.width, "height": c.height,
           "position": c.center().to_array(), "rotation": rows, "fy": c.fy, "fx": c.fx})
}

#[test]
fn inria_by_hand_and_round_trip() {
    let d = temp_dir("inria");
    // At +x looking at the origin in a y-down world: right is +z, forward −x.
    let hand = json!([{"id": 0, "img_name": "side", "width": 40, "height": 30,
        "position": [5.0, 0.0, 0.0], "rotation": [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
        "fx": 50.0, "fy": 55.0}]);
    std::fs::write(d.join("hand.json"), hand.to_string()).expect("write");
    let set = load_inria(d.join("hand.json")).expect("hand-made cameras.json");
    let c = &set.cameras[0];
    assert_eq!((c.cx, c.cy, c.fx, c.fy), (20.0, 15.0, 50.0, 55.0));
    assert!(c.world_to_camera(Vec3::ZERO).abs_diff_eq(Vec3::new(0.0, 0.0, 5.0), 1e-6));
    assert!(c.project(Vec3::new(0.0, 0.0, 1.0)).expect("front").x > 20.0, "+z is to the right");
    assert!(c.project(Vec3::new(0.0, -1.0, 0.0)).expect("front").y < 15.0, "−y is up");

    let cams: Vec<Camera> = (0..5)
        .map(|i| {
            let eye = Vec3::new(i as f32 - 2.0, -1.5, 4.0 + 0.5 * i as f32);
            Camera::look_at(format!("{i:05}"), eye, Vec3::new(0.2, 0.0, -0.1), Vec3::NEG_Y, 320, 240, 45.0)
        })
        .collect();
    let doc = serde_json::Value::Array(cams.iter().enumerate().map(|(i, c)| inria_entry(i, c)).collect());
    std::fs::create_dir_all(d.join("out")).expect("mkdir");
    std::fs::write(d.join("out/cameras.json"), doc.to_string()).expect("write");
    let set = load(d.join("out")).expect("detected in a folder");
    assert!(set.warnings.is_empty(), "{:?}", set.warnings);
    for (a, b) in cams.iter().zip(&set.cameras) {
        assert_close(a, b, 1e-5);
    }
    assert_eq!(load(d.join("out/cameras.json")).expect("detected by content"), set);

    // What `write_inria` writes reads back as the cameras it was given.
    std::fs::create_dir_all(d.join("written")).expect("mkdir");
    assert_eq!(write_inria(d.join("written/cameras.json"), &cams).expect("written"), 0);
    let back = load(d.join("written")).expect("the written cameras.json");
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    for (a, b) in cams.iter().zip(&back.cameras) {
        assert_close(a, b, 1e-5);
    }
    // The format has no principal point: one off the centre is counted, and
    // kept in `cx`/`cy` keys that read back; the centred ones get none.
    let mut shifted = cams.clone();
    shifted[2].cx += 3.0;
    shifted[2].cy -= 1.5;
    assert_eq!(write_inria(d.join("written/cameras.json"), &shifted).expect("written"), 1);
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("written/cameras.json")).expect("read")).expect("json");
    assert_eq!((doc[2]["cx"].as_f64(), doc[2]["cy"].as_f64()), (Some(163.0), Some(118.5)));
    assert!(doc[1].get("cx").is_none() && doc[1].get("cy").is_none(), "{}", doc[1]);
    let back = load(d.join("written")).expect("the written cameras.json");
    for (a, b) in shifted.iter().zip(&back.cameras) {
        assert_close(a, b, 1e-5);
    }
    assert_eq!((back.cameras[2].cx, back.cameras[2].cy), (163.0, 118.5));
}

#[test]
fn transforms_convention_and_intrinsics() {
    let d = temp_dir("transforms");
    // Camera at +z (OpenGL: looking down −z with y up) towards the origin.
    let doc = json!({"camera_angle_x": 1.0, "w": 64, "h": 48, "frames": [
        {"file_path": "./a", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]},
        {"file_path": "b.png", "fl_x": 70.0, "cy": 20.0,
         "transform_matrix": [[0,0,1,4],[0,1,0,0],[-1,0,0,0]]}
    ]});
    std::fs::write(d.join("transforms.json"), doc.to_string()).expect("write");
    let set = load(&d).expect("transforms in a folder");
    let (a, b) = (&set.cameras[0], &set.cameras[1]);
    assert_eq!((a.name.as_str(), a.width, a.height), ("a", 64, 48));
    let f = 32.0 / 0.5f32.tan();
    assert!((a.fx - f).abs() < 1e-3 && (a.fy - f).abs() < 1e-3, "fy defaults to fx");
    assert!(a.world_to_camera(Vec3::ZERO).abs_diff_eq(Vec3::new(0.0, 0.0, 4.0), 1e-6));
    assert!(a.project(Vec3::ZERO).expect("front").abs_diff_eq(Vec2::new(32.0, 24.0), 1e-4));
    assert!(a.project(Vec3::new(0.0, 1.0, 0.0)).expect("front").y < 24.0, "world +y (up) is up");
    assert!(a.project(Vec3::new(1.0, 0.0, 0.0)).expect("front").x > 32.0, "world +x is right");
    assert_eq!((b.fx, b.fy, b.cx, b.cy), (70.0, 70.0, 32.0, 20.0));
    assert!(b.center().abs_diff_eq(Vec3::new(4.0, 0.0, 0.0), 1e-6));
    assert!(b.world_to_camera(Vec3::ZERO).z > 3.99);
}

#[test]
fn transforms_reads_missing_sizes_from_image_headers() {
    let d = temp_dir("transforms-img");
    std::fs::create_dir_all(d.join("train")).expect("mkdir");
    image::RgbImage::new(7, 5).save(d.join("train/r_0.png")).expect("png");
    let m = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]];
    let doc = json!({"camera_angle_x": 0.5, "camera_angle_y": 0.4,
        "frames": [{"file_path": "./train/r_0", "transform_matrix": m}]});
    std::fs::write(d.join("transforms_train.json"), doc.to_string()).expect("write");
    let set = load(d.join("transforms_train.json")).expect("size from the png header");
    let c = &set.cameras[0];
    assert_eq!((c.width, c.height, c.cx, c.cy), (7, 5, 3.5, 2.5));
    assert!((c.fy - 2.5 / 0.2f32.tan()).abs() < 1e-4);

    let doc = json!({"camera_angle_x": 0.5, "frames": [{"file_path": "./train/r_9", "transform_matrix": m}]});
    std::fs::write(d.join("transforms_val.json"), doc.to_string()).expect("write");
    let e = load_transforms(d.join("transforms_val.json")).expect_err("missing image");
    assert!(matches!(e, CameraError::NotFound { .. }) && e.to_string().contains("frames[0]"), "{e}");
}

/// Each message names the field: serde_json's own messages for a wrong type
/// ("invalid type: string \"wide\", expected f64") named none.
#[test]
fn malformed_json_gives_errors_naming_the_field() {
    let d = temp_dir("json-bad");
    let m = json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]);
    let cases: Vec<(String, &str)> = vec![
        ("{\"frames\": [".into(), "document"),
        (json!({"w": 4, "h": 4, "frames": [{"transform_matrix": m}]}).to_string(), "focal length"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"file_path": "x"}]}).to_string(), "transform_matrix"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": []}).to_string(), "at least one frame"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}]}).to_string(), "4x4"),
        (json!({"camera_angle_x": 1, "w": 4.5, "h": 4, "frames": [{"transform_matrix": m}]}).to_string(), "frames[0].w"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 4]]}]}).to_string(), "rotation"),
        (json!({"camera_angle_x": "wide", "w": 4, "h": 4, "frames": [{"transform_matrix": m}]}).to_string(), "document.camera_angle_x: expected a number, found a string"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": m, "fl_x": [2]}]}).to_string(), "frames[0].fl_x: expected a number, found [2]"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": "I"}]}).to_string(), "frames[0].transform_matrix: expected a list of rows of numbers, found a string"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": [[1, 0, 0, 0], [0, 1, "x", 0], [0, 0, 1, 4]]}]}).to_string(), "frames[0].transform_matrix: expected a list of rows of numbers, found [[1,0,0,0],[0,1,\"x\",0],"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": m, "file_path": 3}]}).to_string(), "frames[0].file_path: expected a string, found 3"),
        (json!([{"id": 0, "img_name": "a", "width": "4", "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2, "fy": 2}]).to_string(), "cameras[0].width: expected a whole number of pixels, found a string"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": -4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2, "fy": 2}]).to_string(), "cameras[0].height: expected a whole number of pixels, found -4"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2, "fy": 2}]).to_string(), "cameras[0].position: expected a list of 3 numbers, found [0,0]"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0]], "fx": 2, "fy": 2}]).to_string(), "cameras[0].rotation: expected a 3x3 matrix (3 lists of 3 numbers), found [[1,0,0],[0,1,0]]"),
        (json!([{"id": 0, "img_name": 5, "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2, "fy": 2}]).to_string(), "cameras[0].img_name: expected a string, found 5"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2}]).to_string(), "`fy`"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0]], "fx": 2, "fy": 2}]).to_string(), "cameras[0]"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": -2, "fy": 2}]).to_string(), "a).fx"),
        (json!([]).to_string(), "at least one camera"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": null, "fy": 2}]).to_string(), "cameras[0].fx: expected a number, found null"),
        (json!([{"id": 0, "img_name": null, "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2, "fy": 2}]).to_string(), "cameras[0].img_name: expected a string, found null"),
        (json!({"camera_angle_x": 1, "w": 4, "h": 4, "frames": [{"transform_matrix": null}]}).to_string(), "frames[0].transform_matrix: expected a list of rows of numbers, found null"),
        (json!([{"id": 0, "img_name": "a", "width": 4, "height": 4, "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 2, "fy": 2, "cx": "left"}]).to_string(), "cameras[0].cx: expected a number, found a string"),
        ("7".into(), "a number"),
    ];
    for (text, needle) in cases {
        std::fs::write(d.join("c.json"), &text).expect("write");
        let e = load(d.join("c.json")).expect_err(&text);
        let msg = e.to_string();
        assert!(msg.contains(needle) && msg.contains("c.json"), "{text}\n  → {msg}");
    }
}

#[test]
fn scaled_poses_are_orthonormalised_with_a_warning() {
    let d = temp_dir("json-scale");
    let doc = json!({"camera_angle_x": 1, "w": 4, "h": 4,
        "frames": [{"transform_matrix": [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 4], [0, 0, 0, 1]]}]});
    std::fs::write(d.join("transforms.json"), doc.to_string()).expect("write");
    let set = load(&d).expect("scaled pose");
    assert_eq!(set.warnings.len(), 1, "{:?}", set.warnings);
    assert!((set.cameras[0].rotation.determinant() - 1.0).abs() < 1e-6);
    assert_eq!(set.cameras[0].name, "frame_0000");
}

/// A mirrored pose is refused with its determinant (it printed glam's
/// `DMat3 { x_axis: DVec3(…) … }`).
#[test]
fn a_mirrored_pose_is_refused_with_its_determinant() {
    let d = temp_dir("json-mirror");
    let doc = json!({"camera_angle_x": 1, "w": 4, "h": 4,
        "frames": [{"transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1]]}]});
    std::fs::write(d.join("transforms.json"), doc.to_string()).expect("write");
    let err = load(&d).expect_err("a reflection is no rotation").to_string();
    assert!(err.contains("frames[0].transform_matrix"), "{err}");
    assert!(err.contains("expected a 3x3 rotation (orthonormal, determinant +1)"), "{err}");
    assert!(err.contains("found a matrix whose determinant is -1"), "{err}");
    assert!(!err.contains("DVec3"), "{err}");
}

/// A field of view of 0 or past π is named as such (0 read as "fl_x: found inf").
#[test]
fn a_field_of_view_outside_zero_to_pi_is_named() {
    let d = temp_dir("json-angle");
    for (angle, found) in [(0.0, "found 0"), (4.0, "found 4"), (-1.0, "found -1")] {
        let doc = json!({"camera_angle_x": angle, "w": 4, "h": 4,
            "frames": [{"transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]});
        std::fs::write(d.join("transforms.json"), doc.to_string()).expect("write");
        let err = load(&d).expect_err("no focal length").to_string();
        assert!(err.contains("frames[0].camera_angle_x: expected a field of view in radians between 0 and π"), "{err}");
        assert!(err.contains(found), "{err}");
    }
}

/// A number finite as read but past f32's range (1e39) became an infinite
/// camera that rendered nothing, silently; every format's cameras are
/// checked once converted.
#[test]
fn numbers_past_single_precision_are_named() {
    let d = temp_dir("json-overflow");
    let cases = [
        (
            json!({"camera_angle_x": 0.7, "w": 4, "h": 4, "frames": [{"file_path": "a",
            "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1e39], [0, 0, 0, 1]]}]}),
            "a position",
        ),
        (
            json!({"fl_x": 1e39, "w": 4, "h": 4, "frames": [{"file_path": "a",
            "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]}),
            "a focal length",
        ),
    ];
    for (doc, what) in cases {
        std::fs::write(d.join("transforms.json"), doc.to_string()).expect("write");
        let err = load(&d).expect_err("an infinite camera").to_string();
        assert!(err.contains("transforms.json: camera 0 (a)"), "{err}");
        assert!(err.contains(&format!("expected {what} within single precision")), "{err}");
    }
}

#[test]
fn the_cameras_beside_a_scene_are_found_in_its_folder_or_the_inria_model_folder() {
    let d = temp_dir("beside");
    let cams = vec![Camera::look_at("a", Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::NEG_Y, 64, 48, 50.0)];
    // A scene alone in its folder has none.
    std::fs::create_dir_all(d.join("alone")).expect("mkdir");
    assert!(beside_scene(&d.join("alone/scene.ply")).is_none());
    // `gast fit`'s output: cameras.json beside the scene.
    std::fs::create_dir_all(d.join("fit")).expect("mkdir");
    write_inria(d.join("fit/cameras.json"), &cams).expect("written");
    let (set, dir) = beside_scene(&d.join("fit/scene.ply")).expect("found").expect("read");
    assert_eq!((set.cameras.len(), dir), (1, d.join("fit")));
    // The INRIA trainer's layout: the model folder holds cameras.json.
    let iteration = d.join("model/point_cloud/iteration_30000");
    std::fs::create_dir_all(&iteration).expect("mkdir");
    write_inria(d.join("model/cameras.json"), &cams).expect("written");
    let (set, dir) = beside_scene(&iteration.join("point_cloud.ply")).expect("found").expect("read");
    assert_eq!((set.cameras.len(), dir), (1, d.join("model")));
    // Another folder two levels up is not looked in.
    std::fs::create_dir_all(d.join("fit/renders/iteration_1")).expect("mkdir");
    assert!(beside_scene(&d.join("fit/renders/iteration_1/scene.ply")).is_none());
    // A camera file that cannot be read is an error naming it, not an orbit.
    std::fs::create_dir_all(d.join("broken")).expect("mkdir");
    std::fs::write(d.join("broken/cameras.json"), "[{\"img_name\": 3}]").expect("write");
    let err = beside_scene(&d.join("broken/scene.ply")).expect("found").expect_err("malformed").to_string();
    assert!(err.contains("cameras.json") && err.contains("img_name"), "{err}");
}
