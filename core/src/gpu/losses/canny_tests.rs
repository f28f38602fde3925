//! The GPU edge map against [`render_edges`] on random images and on real
//! renders of the guitar: exact equality, with every differing pixel reported.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::style::step::replicate3;
use crate::vision::canny::render_edges;

/// Runs the GPU map on `rgb` (`h × w × 3`, already in [0, 1]) with the state
/// and output pre-filled with noise; returns the map and the passes that changed a border.
fn gpu_edges(ctx: &GpuContext, map: &EdgeMap, rgb: &[f32]) -> (Vec<f32>, usize, bool) {
    let n = map.h * map.w;
    let noise_u32: Vec<u32> = noise(3 * n, 5).iter().map(|v| (v.abs() * 3.0) as u32).collect();
    ctx.write(&map.state, &noise_u32);
    let rgb_buf = ctx.upload("rgb", rgb);
    let edge = ctx.upload("edge", &noise(3 * n, 6));
    let mut enc = ctx.encoder("canny test");
    map.record(ctx, &mut enc, &rgb_buf, &edge);
    ctx.submit(enc);
    let (busy, done) = map.converged(ctx).expect("flags");
    (ctx.read(&edge).expect("read"), busy, done)
}

/// Pixels where the GPU map differs from the CPU's, as "(row, col): gpu vs cpu".
fn differences(gpu: &[f32], rgb: &[f32], h: usize, w: usize) -> Vec<String> {
    let want = replicate3(&render_edges(rgb, h, w));
    (0..h * w)
        .filter(|&p| (0..3).any(|k| gpu[3 * p + k] != want[3 * p + k]))
        .map(|p| format!("({}, {}): {} vs {}", p / w, p % w, gpu[3 * p], want[3 * p]))
        .collect()
}

/// A smooth random image (sums of a few random waves per channel), whose
/// edges form long chains rather than the speckle of white noise.
fn waves(h: usize, w: usize, seed: u64) -> Vec<f32> {
    let r = noise(3 * 8, seed);
    let mut img = vec![0f32; h * w * 3];
    for i in 0..h {
        for j in 0..w {
            for k in 0..3 {
                let mut v = 0.5;
                for t in 0..2 {
                    let c = &r[(k * 2 + t) * 4..(k * 2 + t) * 4 + 4];
                    v += 0.25
                        * ((c[0] * 0.4 * i as f32 + c[1] * 0.4 * j as f32 + 3.0 * c[2]).sin()).signum()
                        * c[3].abs();
                }
                img[(i * w + j) * 3 + k] = v.clamp(0.0, 1.0);
            }
        }
    }
    img
}

#[test]
fn random_images_give_the_cpu_map_exactly() {
    let ctx = ctx();
    let kernels = CannyKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    for (s, &(h, w)) in [(61usize, 47usize), (97, 83), (5, 3), (33, 130)].iter().enumerate() {
        let map = EdgeMap::new(ctx, &kernels, &reduce, h, w).expect("plan");
        let speckle: Vec<f32> = noise(h * w * 3, 700 + s as u64).iter().map(|v| 0.5 + 0.5 * v).collect();
        for (name, img) in [("noise", speckle), ("waves", waves(h, w, 800 + s as u64))] {
            let (got, busy, done) = gpu_edges(ctx, &map, &img);
            assert!(done, "{name} {h}×{w}: hysteresis did not settle ({busy} passes changed a border)");
            let diff = differences(&got, &img, h, w);
            assert!(diff.is_empty(), "{name} {h}×{w}: {} pixels differ:\n{}", diff.len(), diff.join("\n"));
            eprintln!("{name} {h}×{w}: identical, {busy} hysteresis passes crossed a border");
        }
    }
}

/// A step edge strong over its last 4 rows (or columns) and weak elsewhere:
/// `h × w`, the step at row/column 10 of the other axis.
fn weak_step(h: usize, w: usize, across: bool) -> Vec<f32> {
    let mut rgb = vec![0f32; h * w * 3];
    for i in 0..h {
        for j in 0..w {
            let (along, side, len) = if across { (j, i, w) } else { (i, j, h) };
            if side >= 10 {
                let v = if along >= len - 4 { 1.0 } else { 0.1 };
                rgb[(i * w + j) * 3..(i * w + j) * 3 + 3].copy_from_slice(&[v, v, v]);
            }
        }
    }
    rgb
}

#[test]
fn a_long_weak_chain_needs_its_passes_and_gets_them() {
    // A step strong at its far end and weak before it (as the CPU's
    // hysteresis test, reversed): the edge grows back through 7 tiles, one
    // per pass (lavapipe runs workgroups in order, so growing forward would
    // cross several tiles in one pass); down the rows, then along them,
    // across the bit words of each tile's rows.
    let ctx = ctx();
    let kernels = CannyKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    for (h, w, across) in [(7 * TILE, 20, false), (20, 7 * TILE, true)] {
        let rgb = weak_step(h, w, across);
        let short = EdgeMap::with_passes(ctx, &kernels, &reduce, h, w, 2).expect("plan");
        let (got, _, done) = gpu_edges(ctx, &short, &rgb);
        assert!(!done, "{h}×{w}: two passes cannot carry the edge through 7 tiles");
        assert!(!differences(&got, &rgb, h, w).is_empty());
        let full = EdgeMap::new(ctx, &kernels, &reduce, h, w).expect("plan");
        let (got, busy, done) = gpu_edges(ctx, &full, &rgb);
        assert!(done && busy >= 3, "{h}×{w}: settled: {done}, passes crossing a border: {busy}");
        eprintln!("{h}×{w} weak chain through 7 tiles: {busy} passes crossed a border");
        let diff = differences(&got, &rgb, h, w);
        assert!(diff.is_empty(), "{h}×{w}: {} pixels differ:\n{}", diff.len(), diff.join("\n"));
    }
}

#[test]
fn guitar_renders_give_the_cpu_map_exactly() {
    use crate::camera::{OrbitOptions, orbit_cameras};
    use crate::raster::{RenderOptions, render};
    let Some(path) = crate::vision::weights::tests::shared("data/scenes/guitar.compressed.ply") else { return };
    let g = crate::scene::load(&path).expect("guitar");
    let (h, w) = (97usize, 128usize);
    let cams = orbit_cameras(
        &g.means,
        &OrbitOptions { count: 3, width: w as u32, height: h as u32, ..OrbitOptions::default() },
    );
    let ctx = ctx();
    let kernels = CannyKernels::new(ctx);
    let reduce = ReduceKernels::new(ctx);
    let map = EdgeMap::new(ctx, &kernels, &reduce, h, w).expect("plan");
    let mut edge_pixels = 0;
    for (v, cam) in cams.iter().enumerate() {
        let r = render(&g, cam, &RenderOptions::default());
        let rgb: Vec<f32> = r.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        let (got, busy, done) = gpu_edges(ctx, &map, &rgb);
        assert!(done, "view {v}: hysteresis did not settle");
        let diff = differences(&got, &rgb, h, w);
        assert!(diff.is_empty(), "guitar view {v}: {} pixels differ:\n{}", diff.len(), diff.join("\n"));
        let count = got.iter().step_by(3).filter(|&&e| e > 0.0).count();
        eprintln!("guitar view {v} ({w}×{h}): identical, {count} edge pixels, {busy} passes crossed a border");
        edge_pixels += count;
    }
    assert!(edge_pixels > 100, "the renders have edges to compare ({edge_pixels})");
}
