//! Cameras on a real dataset: NeRF-synthetic lego (`transforms_train.json`,
//! OpenGL convention, no image size in the json). The object sits at the world
//! origin, so every converted camera must look at it.

use gast_core::camera::{self, scene_extent, write_colmap_binary};
use gast_tests::shared_file;
use glam::Vec3;

#[test]
fn lego_transforms_train() -> anyhow::Result<()> {
    let Some(path) = shared_file("data/datasets/lego/transforms_train.json") else {
        return Ok(());
    };
    let set = camera::load(&path)?;
    assert!(set.warnings.is_empty(), "{:?}", set.warnings);
    assert_eq!(set.cameras.len(), 100);
    let angle_x = 0.691_111_2_f32;
    let f = 400.0 / (0.5 * angle_x).tan();
    for c in &set.cameras {
        assert_eq!((c.width, c.height), (800, 800), "{}: size from the PNG header", c.name);
        assert!((c.fx - f).abs() < 1e-2 && (c.fy - f).abs() < 1e-2, "{}: fx {}", c.name, c.fx);
        assert_eq!((c.cx, c.cy), (400.0, 400.0));
        let d = c.center().length();
        assert!((d - 4.031).abs() < 0.01, "{}: centre at distance {d}", c.name);
        let origin = c.world_to_camera(Vec3::ZERO);
        assert!((origin.z - d).abs() < 0.05, "{}: the origin is straight ahead ({origin:?})", c.name);
        let p = c.project(Vec3::ZERO).expect("origin in front");
        assert!((p - glam::Vec2::splat(400.0)).length() < 1.0, "{}: origin projects to {p:?}", c.name);
        assert!((c.rotation.determinant() - 1.0).abs() < 1e-4);
        // Blender's world is z-up: the world +z axis appears upwards on screen.
        let up = c.project(Vec3::new(0.0, 0.0, 0.5)).expect("in front");
        assert!(up.y < p.y, "{}: world +z should be up on screen", c.name);
    }
    assert!(set.cameras[0].name.ends_with("r_0"));

    // The whole folder is detected too (transforms_train.json is the first choice there).
    let dir = path.parent().expect("dataset folder");
    assert_eq!(camera::load(dir)?.cameras, set.cameras);

    // Cameras on the upper hemisphere of radius ≈ 4.03: their centroid sits above
    // the origin, so the largest distance from it lies between 4.03 and 2 × 4.03.
    let extent = scene_extent(&set.cameras);
    let worst = set
        .cameras
        .iter()
        .filter_map(|c| c.project(Vec3::ZERO))
        .map(|p| (p - glam::Vec2::splat(400.0)).length())
        .fold(0.0f32, f32::max);
    eprintln!("lego: scene extent {extent:.3}, origin at most {worst:.2} px from the image centre");
    assert!(extent > 1.1 * 4.03 && extent < 1.1 * 8.06, "extent {extent}");
    assert!((extent - 5.202).abs() < 0.01, "extent {extent} (measured 5.202 when written)");

    // Export as COLMAP and read back.
    let out = std::env::temp_dir().join(format!("gast-lego-colmap-{}", std::process::id()));
    write_colmap_binary(&out, &set.cameras)?;
    let back = camera::load(&out)?;
    let _ = std::fs::remove_dir_all(&out);
    let mut sorted = set.cameras.clone();
    sorted.sort_by(|a, b| a.name.cmp(&b.name));
    for (a, b) in sorted.iter().zip(&back.cameras) {
        assert_eq!(a.name, b.name);
        assert!(a.center().abs_diff_eq(b.center(), 1e-4) && a.rotation.abs_diff_eq(b.rotation, 1e-5));
    }
    Ok(())
}
