//! The GPU rasterizer against the CPU one (`crate::raster`): random scenes
//! from random cameras, a cut-down real scene, and the golden files; both
//! atomic paths of the backward pass. Every buffer is filled with noise
//! before the kernels run.

use std::path::PathBuf;

use glam::Vec3;

use super::raster_kernels::Accumulation;
use super::test_util::{ctx, noise};
use super::{GpuGaussians, GpuGrads, GpuRaster, RasterKernels};
use crate::camera::{Camera, OrbitOptions, orbit_cameras};
use crate::golden::{GoldenFile, Tolerance, compare, widen};
use crate::raster::{Grads, Render, RenderOptions, backward, forward};
use crate::scene::{Gaussians, sh_coeffs_for_degree};

/// Uniform values in `[a, b)` from the test noise.
fn uniform(len: usize, seed: u64, a: f32, b: f32) -> Vec<f32> {
    noise(len, seed).into_iter().map(|x| a + (b - a) * 0.5 * (x + 1.0)).collect()
}

/// `n` random Gaussians in a ball of radius 1.3 around the origin, some of
/// them off screen, log-scales in `scales`, and a camera at a random point of a sphere of radius 4
/// looking at the origin.
fn random_case(seed: u64, n: usize, deg: u32, scales: (f32, f32), width: u32, height: u32) -> (Gaussians, Camera) {
    let dir = Vec3::from_slice(&noise(3, seed * 101)).normalize_or(Vec3::Z);
    let cam = Camera::look_at("random", 4.0 * dir, Vec3::ZERO, Vec3::NEG_Y, width, height, 55.0);
    let pos = noise(3 * n, seed * 7 + 1);
    let k = sh_coeffs_for_degree(deg);
    let dc = uniform(3 * n, seed * 7 + 5, -0.5, 1.5);
    let rest = uniform(3 * n * k, seed * 7 + 6, -0.08, 0.08);
    let g = Gaussians {
        means: pos.chunks_exact(3).map(|c| [1.3 * c[0], 1.3 * c[1], 1.3 * c[2]]).collect(),
        log_scales: uniform(3 * n, seed * 7 + 2, scales.0, scales.1)
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
        quats: noise(4 * n, seed * 7 + 3).chunks_exact(4).map(|c| [c[0] + 0.1, c[1], c[2], c[3]]).collect(),
        opacity_logits: uniform(n, seed * 7 + 4, -3.0, 4.0),
        sh_degree: deg,
        sh: (0..n * k * 3).map(|i| if i % (3 * k) < 3 { dc[i / (3 * k) * 3 + i % 3] } else { rest[i] }).collect(),
    };
    (g, cam)
}

/// The GPU forward and backward of one case (with `splits` backward slices
/// per tile, else the size's own choice), every buffer noise-filled first.
fn gpu_run(
    k: &RasterKernels,
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    v_rgb: &[f32],
    v_d: &[f32],
    splits: Option<u32>,
) -> (Render, Grads) {
    let ctx = ctx();
    let gg = GpuGaussians::upload(ctx, g);
    let mut raster = GpuRaster::fitted(ctx, k, &gg, cam, opts).expect("workspace");
    if let Some(s) = splits {
        raster = raster.with_splits(ctx, s);
    }
    raster.fill_noise(ctx, 77);
    let grads = GpuGrads::new(ctx, &gg);
    for (i, b) in [&grads.v_means, &grads.v_log_scales, &grads.v_quats, &grads.v_opacity_logits, &grads.v_sh]
        .into_iter()
        .enumerate()
    {
        ctx.write(b, &noise((b.size() / 4) as usize, 900 + i as u64));
    }
    let (vr, vd) = (ctx.upload("v_rgb", v_rgb), ctx.upload("v_inv_depth", v_d));
    let mut enc = ctx.encoder("raster test");
    raster.forward(ctx, k, &mut enc, &gg, cam, opts);
    raster.backward(ctx, k, &mut enc, &gg, &vr, &vd, &grads);
    ctx.submit(enc);
    assert!(raster.pairs(ctx).expect("pairs") <= raster.capacity());
    (raster.download(ctx).expect("image"), grads.download(ctx).expect("grads"))
}

/// Compares GPU and CPU; returns the failures and the number of pixels that differ (near-ties).
fn compare_with_cpu(
    name: &str,
    k: &RasterKernels,
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    seed: u64,
    splits: Option<u32>,
) -> (Vec<String>, usize) {
    let npx = (cam.width * cam.height) as usize;
    let v_rgb = noise(3 * npx, seed ^ 0x55);
    let v_d = noise(npx, seed ^ 0x66);
    let (img, state) = forward(g, cam, opts);
    let want = backward(g, cam, opts, &state, &v_rgb, &v_d);
    let (got_img, got) = gpu_run(k, g, cam, opts, &v_rgb, &v_d, splits);
    let mut failures = Vec::new();
    // A case worth comparing: most pixels covered, many Gaussians composited.
    let covered = img.alpha.iter().filter(|&&a| a > 0.1).count();
    if covered < npx / 8 || state.pairs() < 200 {
        failures.push(format!("{name}: a trivial case ({covered} of {npx} pixels covered, {} pairs)", state.pairs()));
    }
    let worst_image = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    println!(
        "{name}: {} visible, {} pairs, {covered}/{npx} px covered; max abs rgb {:.2e}, inv_depth {:.2e}, alpha {:.2e}",
        state.visible(),
        state.pairs(),
        worst_image(&img.rgb, &got_img.rgb),
        worst_image(&img.inv_depth, &got_img.inv_depth),
        worst_image(&img.alpha, &got_img.alpha)
    );
    let mut differing = 0;
    for q in 0..npx {
        let e = (0..3)
            .map(|c| (img.rgb[3 * q + c] - got_img.rgb[3 * q + c]).abs())
            .chain([(img.inv_depth[q] - got_img.inv_depth[q]).abs(), (img.alpha[q] - got_img.alpha[q]).abs()])
            .fold(0.0f32, |m, x| if x.is_nan() { f32::INFINITY } else { m.max(x) });
        if e >= 1e-4 {
            differing += 1;
            println!("{name}: pixel {q} differs by {e:.3e}");
        }
    }
    let groups: [(&str, &[f32], &[f32]); 5] = [
        ("v_means", want.v_means.as_flattened(), got.v_means.as_flattened()),
        ("v_log_scales", want.v_log_scales.as_flattened(), got.v_log_scales.as_flattened()),
        ("v_quats", want.v_quats.as_flattened(), got.v_quats.as_flattened()),
        ("v_opacity_logits", &want.v_opacity_logits, &got.v_opacity_logits),
        ("v_sh", &want.v_sh, &got.v_sh),
    ];
    for (group, w, gv) in groups {
        let scale = w.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        let worst = w
            .iter()
            .zip(gv)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, |m, x| if x.is_nan() { f32::INFINITY } else { m.max(x) });
        println!("{name} {group}: worst {worst:.3e} of largest {scale:.3e}");
        if w.len() != gv.len() || worst > 1e-3 * scale {
            failures.push(format!("{name} {group}: worst difference {worst:.3e}, largest magnitude {scale:.3e}"));
        }
    }
    (failures, differing)
}

fn check_random_scenes(float_atomics: bool, subgroups: bool) {
    let ctx = ctx();
    let k = RasterKernels::with_accumulation(ctx, Accumulation { float_atomics, subgroups });
    let mut failures = Vec::new();
    let mut differing = 0;
    // The last case is dense: many layers per pixel, transmittance running out.
    for (seed, deg, n, scales) in [
        (1u64, 0u32, 300, (-3.6, -1.6)),
        (2, 3, 300, (-3.6, -1.6)),
        (3, 1, 300, (-3.6, -1.6)),
        (4, 2, 800, (-2.6, -1.2)),
    ] {
        let (g, cam) = random_case(seed, n, deg, scales, 40, 32);
        let opts = RenderOptions { background: [0.2, 0.4, 0.7] };
        let (f, d) = compare_with_cpu(&format!("seed {seed} deg {deg}"), &k, &g, &cam, &opts, seed, None);
        failures.extend(f);
        differing += d;
    }
    assert!(differing <= 2, "{differing} pixels differ by 1e-4 or more: more than α = 1/255 ties explain");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn matches_the_cpu_on_random_scenes_with_float_atomics_and_subgroups() {
    let caps = ctx().caps;
    // Lavapipe has both; an adapter without them tests what it has.
    println!("adapter {}: {caps:?}", ctx().describe());
    check_random_scenes(caps.float_atomics, caps.subgroups);
    if caps.subgroups {
        check_random_scenes(caps.float_atomics, false);
    }
}

#[test]
fn matches_the_cpu_on_random_scenes_with_the_cas_fallback_and_no_subgroups() {
    check_random_scenes(false, false);
}

#[test]
fn matches_the_cpu_on_random_scenes_with_subgroups_and_the_cas_fallback() {
    let subgroups = ctx().caps.subgroups;
    check_random_scenes(false, subgroups);
}

/// Thousands of faint splats at 40×32: long lists whose pixels composite
/// hundreds of them, so that a slice spans several batches of 256 and the
/// later slices start deep in the list.
fn faint_crowd() -> (Gaussians, Camera, RenderOptions) {
    let n = 3000;
    let (mut g, cam) = random_case(6, n, 1, (-1.6, -0.8), 40, 32);
    g.opacity_logits = uniform(n, 66, -5.3, -3.5);
    (g, cam, RenderOptions { background: [0.9, 0.3, 0.1] })
}

#[test]
fn matches_the_cpu_whatever_the_backward_slices() {
    let ctx = ctx();
    let k = RasterKernels::new(ctx);
    let (g, cam, opts) = faint_crowd();
    let (_, state) = forward(&g, &cam, &opts);
    let deepest = state.n_contrib.iter().copied().max().unwrap_or(0);
    println!("{} pairs over 6 tiles, the deepest pixel composites up to list position {deepest}", state.pairs());
    assert!(deepest > 3 * 256, "a case too shallow for the slices: deepest position {deepest}");
    let mut failures = Vec::new();
    let mut differing = 0;
    for splits in [Some(1), Some(2), Some(3), Some(16), None] {
        let (f, d) = compare_with_cpu(&format!("{splits:?} slices"), &k, &g, &cam, &opts, 6, splits);
        failures.extend(f);
        differing += d;
    }
    assert!(differing <= 2, "{differing} pixels differ by 1e-4 or more");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn one_slice_keeps_each_pixels_final_state_and_no_more() {
    // With one slice the buffer has room for no slice record (and the
    // forward pass writes none: lavapipe drops writes past a buffer's end,
    // so only the size shows here); each pixel's final transmittance and
    // count, all the backward pass reads, are the CPU's.
    let ctx = ctx();
    let k = RasterKernels::new(ctx);
    let (g, cam, opts) = faint_crowd();
    let (_, state) = forward(&g, &cam, &opts);
    let gg = GpuGaussians::upload(ctx, &g);
    let raster = GpuRaster::fitted(ctx, &k, &gg, &cam, &opts).expect("workspace").with_splits(ctx, 1);
    raster.fill_noise(ctx, 78);
    let mut enc = ctx.encoder("one slice");
    raster.forward(ctx, &k, &mut enc, &gg, &cam, &opts);
    ctx.submit(enc);
    let words: Vec<u32> = ctx.read(&raster.px_state).expect("px_state");
    let npx = (cam.width * cam.height) as usize;
    assert_eq!(words.len(), 2 * npx);
    let mut wrong = Vec::new();
    for q in 0..npx {
        let t = f32::from_bits(words[2 * q]);
        let t_close = (t - state.final_t[q]).abs() < 1e-4; // false for NaN
        if words[2 * q + 1] != state.n_contrib[q] || !t_close {
            wrong.push(format!(
                "pixel {q}: T {t} count {} (CPU {} {})",
                words[2 * q + 1],
                state.final_t[q],
                state.n_contrib[q]
            ));
        }
    }
    assert!(wrong.len() <= 2, "{} pixels' state differs: {}", wrong.len(), wrong.join("; "));
}

#[test]
fn the_backward_slices_follow_the_tile_count() {
    use super::raster_forward::backward_splits;
    // 1,024 px square and fern's 1,008×756 walk each tile in one workgroup;
    // 512 px square in two slices, 256 px in eight, tiny images in sixteen.
    assert_eq!(backward_splits(64 * 64), 1);
    assert_eq!(backward_splits(63 * 48), 1);
    assert_eq!(backward_splits(32 * 32), 2);
    assert_eq!(backward_splits(16 * 16), 8);
    assert_eq!(backward_splits(3 * 2), 16);
    assert_eq!(backward_splits(0), 16);
}

#[test]
fn the_slice_records_exist_only_with_more_than_one_slice() {
    use super::raster_forward::state_words;
    // One slice: each pixel's final transmittance and count, nothing more
    // (1,008×756 keeps 6 MB, not 21); eight: five words more per slice.
    assert_eq!(state_words(1, 1008 * 756), 2 * 1008 * 756);
    assert_eq!(state_words(8, 256 * 256), 42 * 256 * 256);
    assert_eq!(state_words(2, 10), 120);
}

/// A file of the shared data (`$GAST_SHARED`, else `../shared` beside the
/// checkout), or `None` after a loud message when it is absent (CI has it).
fn shared(rel: &str) -> Option<PathBuf> {
    let p = std::env::var_os("GAST_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"))
        .join(rel);
    if p.exists() {
        return Some(p);
    }
    eprintln!("\n!!!!!!!! SKIPPED: shared data file {} is absent (set GAST_SHARED) !!!!!!!!\n", p.display());
    None
}

#[test]
fn matches_the_cpu_on_part_of_the_guitar() {
    let Some(path) = shared("data/scenes/guitar.compressed.ply") else { return };
    let full = crate::scene::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    // The file's first 4,000 Gaussians: compressed PLY stores them in
    // spatially ordered chunks, so this is one dense piece of the real scene.
    let keep: Vec<usize> = (0..full.len().min(4000)).collect();
    let k3 = full.sh_coeffs() * 3;
    let g = Gaussians {
        means: keep.iter().map(|&i| full.means[i]).collect(),
        log_scales: keep.iter().map(|&i| full.log_scales[i]).collect(),
        quats: keep.iter().map(|&i| full.quats[i]).collect(),
        opacity_logits: keep.iter().map(|&i| full.opacity_logits[i]).collect(),
        sh_degree: full.sh_degree,
        sh: keep.iter().flat_map(|&i| full.sh[i * k3..(i + 1) * k3].iter().copied()).collect(),
    };
    let cams = orbit_cameras(&g.means, &OrbitOptions { count: 3, width: 64, height: 64, ..Default::default() });
    let ctx = ctx();
    let k = RasterKernels::new(ctx);
    let mut failures = Vec::new();
    let mut differing = 0;
    for (i, cam) in cams.iter().enumerate() {
        let (f, d) = compare_with_cpu(
            &format!("guitar[..4000] view {i}"),
            &k,
            &g,
            cam,
            &RenderOptions::default(),
            40 + i as u64,
            None,
        );
        failures.extend(f);
        differing += d;
    }
    assert!(differing <= 2, "{differing} pixels differ by 1e-4 or more");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn matches_the_golden_rasterizer_files() {
    let ctx = ctx();
    let k = RasterKernels::new(ctx);
    let mut failures = Vec::new();
    for name in ["raster_deg0_seed1", "raster_deg3_seed1"] {
        let Some(path) = shared(&format!("golden/{name}.safetensors")) else { return };
        let file = GoldenFile::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let case = crate::golden::raster_case(&file).expect("raster case");
        let (img, grads) = gpu_run(
            &k,
            &case.gaussians,
            &case.camera,
            &case.options,
            &case.cotangent_rgb,
            &case.cotangent_inv_depth,
            None,
        );
        const IMAGE: Tolerance = Tolerance::Abs(1e-5);
        const GRAD: Tolerance = Tolerance::RelToMax(1e-3);
        let outputs: [(&str, &[f32], Tolerance); 8] = [
            ("out_rgb", &img.rgb, IMAGE),
            ("out_inv_depth", &img.inv_depth, IMAGE),
            ("out_alpha", &img.alpha, IMAGE),
            ("grad_means", grads.v_means.as_flattened(), GRAD),
            ("grad_log_scales", grads.v_log_scales.as_flattened(), GRAD),
            ("grad_quats", grads.v_quats.as_flattened(), GRAD),
            ("grad_opacity_logits", &grads.v_opacity_logits, GRAD),
            ("grad_sh", &grads.v_sh, GRAD),
        ];
        for (out, values, tol) in outputs {
            let c = compare(out, &widen(values), file.get(out).expect("reference tensor"), tol);
            println!("{name} {out}: max abs {:.3e}, rel {:.3e} ({})", c.max_abs, c.rel, c.tolerance);
            if !c.passed {
                failures.push(format!(
                    "{name} {out}: max abs {:.3e}, rel {:.3e}, tolerance {}",
                    c.max_abs, c.rel, c.tolerance
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A tile whose list is long (65,025 splats, past 254 batches of 256) and
/// whose centre pixels saturate early while its edges run to the end: on
/// lavapipe the early pixels came out empty when they wrote their result
/// after the list, as on playbot's densest tiles.
#[test]
fn a_long_tile_list_keeps_the_pixels_that_stop_early() {
    let ctx = ctx();
    let n = 65_025;
    let r = noise(3 * n, 5);
    let g = Gaussians {
        means: (0..n).map(|i| [0.3 * r[3 * i], 0.3 * r[3 * i + 1], 0.3 * r[3 * i + 2]]).collect(),
        log_scales: vec![[-1.0; 3]; n],
        quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacity_logits: vec![-5.0; n],
        sh_degree: 0,
        sh: (0..3 * n).map(|i| (i % 7) as f32 * 0.2).collect(),
    };
    let cam =
        orbit_cameras(&g.means, &OrbitOptions { count: 1, width: 16, height: 16, ..Default::default() })[0].clone();
    let o = RenderOptions::default();
    let (want, state) = forward(&g, &cam, &o);
    assert_eq!(state.pairs(), n, "one tile holds every splat");
    let got = super::render_gpu(ctx, &g, &cam, &o).expect("GPU render");
    let worst = want.alpha.iter().zip(&got.alpha).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    let worst_rgb = want.rgb.iter().zip(&got.rgb).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4 && worst_rgb < 1e-4, "alpha off by {worst}, colour by {worst_rgb}");
}
