//! Generated cameras: they look at the robust centre, see the robust box from
//! the expected distance, and ignore far outliers.

use glam::Vec3;

use crate::camera::{OrbitLayout, OrbitOptions, orbit_cameras, robust_bounds};

/// A deterministic cloud: a box of points plus a few far floaters.
fn cloud() -> Vec<[f32; 3]> {
    let mut pts = Vec::new();
    let mut s = 12345u32;
    let mut rnd = || {
        s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (s >> 8) as f32 / (1u32 << 24) as f32
    };
    for _ in 0..5000 {
        pts.push([1.0 + 2.0 * rnd(), -0.5 + rnd(), 3.0 + 4.0 * rnd()]);
    }
    pts.extend([[1e4, 0.0, 0.0], [0.0, -3e3, 0.0], [0.0, 0.0, 5e5], [f32::NAN, 0.0, 0.0], [0.0, f32::INFINITY, 0.0]]);
    pts
}

#[test]
fn robust_bounds_ignore_outliers() {
    let b = robust_bounds(&cloud()).expect("finite points");
    assert!(b.min.abs_diff_eq(Vec3::new(1.04, -0.48, 3.08), 0.03), "{:?}", b.min);
    assert!(b.max.abs_diff_eq(Vec3::new(2.96, 0.48, 6.92), 0.03), "{:?}", b.max);
    assert!(b.center.abs_diff_eq(Vec3::new(2.0, 0.0, 5.0), 0.05), "{:?}", b.center);
    assert!(robust_bounds(&[]).is_none());
    assert!(robust_bounds(&[[f32::NAN, 0.0, 0.0]]).is_none());
}

#[test]
fn orbit_views_see_the_robust_box() {
    let pts = cloud();
    let b = robust_bounds(&pts).expect("finite points");
    let layouts = [
        OrbitLayout::Ring { elevation_degrees: 20.0 },
        OrbitLayout::Sphere { min_elevation_degrees: -30.0, max_elevation_degrees: 30.0 },
    ];
    for layout in layouts {
        for (w, h) in [(256, 256), (320, 180), (120, 200)] {
            let opts = OrbitOptions { width: w, height: h, layout, count: 24, ..OrbitOptions::default() };
            let cams = orbit_cameras(&pts, &opts);
            assert_eq!(cams.len(), 24);
            let tan_min = (25f32.to_radians().tan() * (w.min(h) as f32 / h as f32)).atan();
            let expect_dist = 1.1 * b.radius() / tan_min.sin();
            for c in &cams {
                assert_eq!((c.width, c.height), (w, h));
                let p = c.project(b.center).expect("centre in front");
                assert!(p.abs_diff_eq(glam::Vec2::new(c.cx, c.cy), 1e-3), "{}: {p:?}", c.name);
                assert!((c.center().distance(b.center) - expect_dist).abs() < 1e-3 * expect_dist, "{}", c.name);
                for corner in b.corners() {
                    let q = c.project(corner).expect("corner in front");
                    let inside = q.x > 0.0 && q.y > 0.0 && q.x < w as f32 && q.y < h as f32;
                    assert!(inside, "{} ({w}x{h}, {layout:?}): corner {corner:?} at {q:?}", c.name);
                }
                // The scene's up (−y) is up on screen.
                let above = c.project(b.center + Vec3::new(0.0, -0.01, 0.0)).expect("front");
                assert!(above.y < c.cy, "{}", c.name);
            }
        }
    }
}

#[test]
fn orbit_layouts_spread_the_views() {
    let pts = cloud();
    let b = robust_bounds(&pts).expect("finite points");
    let ring = orbit_cameras(
        &pts,
        &OrbitOptions { layout: OrbitLayout::Ring { elevation_degrees: 0.0 }, count: 8, ..Default::default() },
    );
    for c in &ring {
        assert!((c.center().y - b.center.y).abs() < 1e-3, "ring at elevation 0 stays level");
    }
    let sphere = orbit_cameras(&pts, &OrbitOptions::default());
    assert_eq!(sphere.len(), 36);
    let elevations: Vec<f32> = sphere
        .iter()
        .map(|c| ((b.center.y - c.center().y) / c.center().distance(b.center)).asin().to_degrees())
        .collect();
    let (lo, hi) = elevations.iter().fold((f32::MAX, f32::MIN), |(l, h), &e| (l.min(e), h.max(e)));
    assert!(lo > -30.01 && hi < 30.01 && lo < -25.0 && hi > 25.0, "{lo}..{hi}");
    // Names are unique and ordered.
    assert_eq!(sphere[7].name, "orbit_007");
    // Degenerate inputs still give finite cameras.
    for pts in [vec![], vec![[1.0, 2.0, 3.0]]] {
        let cams = orbit_cameras(&pts, &OrbitOptions { count: 4, ..Default::default() });
        assert!(cams.iter().all(|c| c.rotation.is_finite() && c.translation.is_finite()));
    }
    assert!(orbit_cameras(&pts, &OrbitOptions { count: 0, ..Default::default() }).is_empty());
}

#[test]
fn orbit_options_serialise_with_defaults() {
    let o: OrbitOptions = serde_json::from_str(r#"{"count": 8, "layout": {"Ring": {"elevation_degrees": 10.0}}}"#)
        .expect("partial preset");
    assert_eq!(o.count, 8);
    assert_eq!(o.layout, OrbitLayout::Ring { elevation_degrees: 10.0 });
    assert_eq!((o.width, o.fov_y_degrees, o.up), (256, 50.0, [0.0, -1.0, 0.0]));
    let back: OrbitOptions = serde_json::from_str(&serde_json::to_string(&o).expect("serialise")).expect("parse");
    assert_eq!(back, o);
    // Out-of-range options still give usable cameras.
    let odd = OrbitOptions { fov_y_degrees: 0.0, margin: f32::NAN, up: [0.0; 3], count: 3, ..o };
    for c in orbit_cameras(&cloud(), &odd) {
        assert!(c.fx.is_finite() && c.fx > 0.0 && c.translation.is_finite() && c.rotation.is_finite());
    }
}
