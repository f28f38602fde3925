//! Timings of the rasterizer on large synthetic scenes and on the real scenes
//! of the shared data, from an orbit view at 256×256. Ignored by default: run
//! with `cargo test --release -p gast-tests --test raster_perf -- --ignored --nocapture`
//! (`GAST_PERF_RUNS`, `GAST_PERF_SIZES`, and `GAST_PERF_PPM=<dir>` to save the
//! real-scene renders).

use std::time::Instant;

use gast_core::camera::Camera;
use gast_core::raster::{RenderOptions, backward, forward, render};
use gast_core::scene::Gaussians;
use glam::{Mat3, Vec3};

/// A pinhole camera at `eye` looking at `target` with world `up` at the top
/// of the image (image y down).
fn look_at(eye: Vec3, target: Vec3, up: Vec3, width: u32, height: u32, focal: f32) -> Camera {
    let fwd = (target - eye).normalize();
    let right = fwd.cross(up).normalize();
    let down = fwd.cross(right);
    let rotation = Mat3::from_cols(right, down, fwd).transpose();
    Camera {
        name: "orbit".into(),
        width,
        height,
        fx: focal,
        fy: focal,
        cx: width as f32 / 2.0,
        cy: height as f32 / 2.0,
        rotation,
        translation: -(rotation * eye),
    }
}

struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
    fn u(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * self.f()
    }
}

/// A scene shaped like a captured one: most Gaussians small and on surfaces
/// (a ground disc, a blob, scattered clutter), a tail of large ones, opacities
/// spread from nearly transparent to opaque, SH degree 3.
fn synthetic_scene(n: usize) -> Gaussians {
    let mut rng = Rng(42);
    let mut g = Gaussians::with_capacity(n, 3);
    for i in 0..n {
        let kind = i % 10;
        let p = if kind < 4 {
            let (r, a) = (2.0 * rng.f().sqrt(), rng.u(0.0, std::f32::consts::TAU));
            [r * a.cos(), -0.5 + rng.u(-0.01, 0.01), r * a.sin()]
        } else if kind < 8 {
            let v = Vec3::new(rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), rng.u(-1.0, 1.0)).normalize_or_zero() * 0.6;
            [v.x, v.y, v.z]
        } else {
            [rng.u(-2.0, 2.0), rng.u(-0.5, 1.5), rng.u(-2.0, 2.0)]
        };
        g.means.push(p);
        let big = rng.f() < 0.03;
        let s = if big { rng.u(-3.5, -2.0) } else { rng.u(-6.0, -4.0) };
        g.log_scales.push([s + rng.u(-0.5, 0.5), s + rng.u(-0.5, 0.5), s - rng.u(0.0, 1.5)]);
        g.quats.push([rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), rng.u(-1.0, 1.0)]);
        g.opacity_logits.push(rng.u(-4.0, 6.0));
        for k in 0..16 {
            for _ in 0..3 {
                g.sh.push(if k == 0 { rng.u(-1.5, 1.5) } else { rng.u(-0.1, 0.1) });
            }
        }
    }
    g
}

/// CPU time of this process (all threads), ms, from `/proc/self/stat`
/// (10 ms resolution); 0 where unavailable.
fn cpu_ms() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    let Some(rest) = stat.rsplit(')').next() else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
    // Fields 14 and 15 (utime, stime) are at 11 and 12 after the command name.
    (ticks(11) + ticks(12)) * 10.0
}

/// Best wall time (ms), mean CPU time per run over all threads (ms), last result.
/// On a busy machine the CPU time is the steadier figure of the work done.
fn time_it<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    let c0 = cpu_ms();
    for _ in 0..runs {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        out = Some(r);
    }
    let cpu = (cpu_ms() - c0) / runs as f64;
    (best, cpu, out.expect("at least one run"))
}

fn bench(label: &str, g: &Gaussians, cam: &Camera) {
    let opts = RenderOptions::default();
    let runs = std::env::var("GAST_PERF_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(10);
    let (t_render, c_render, _) = time_it(runs, || render(g, cam, &opts));
    let (t_fwd, c_fwd, (img, state)) = time_it(runs, || forward(g, cam, &opts));
    let npx = (cam.width * cam.height) as usize;
    let v_rgb: Vec<f32> = (0..3 * npx).map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.5).collect();
    let v_d: Vec<f32> = (0..npx).map(|i| ((i * 104_729) % 11) as f32 / 11.0 - 0.5).collect();
    let (t_bwd, c_bwd, _) = time_it(runs, || backward(g, cam, &opts, &state, &v_rgb, &v_d));
    let cover = img.alpha.iter().sum::<f32>() / npx as f32;
    println!(
        "{label}: {} Gaussians, {}×{}: best wall: render {t_render:.1} ms, forward {t_fwd:.1} ms, backward {t_bwd:.1} ms; \
         CPU per call: {c_render:.0}, {c_fwd:.0}, {c_bwd:.0} ms \
         ({} visible, {} tile pairs, mean alpha {cover:.2}, {} threads)",
        g.len(),
        cam.width,
        cam.height,
        state.visible(),
        state.pairs(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
}

#[test]
#[ignore = "timing; run explicitly"]
fn raster_timing_synthetic() {
    // GAST_PERF_SIZES=90000,500000 (the default) picks the scene sizes.
    let sizes: Vec<usize> = std::env::var("GAST_PERF_SIZES")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![90_000, 500_000]);
    for n in sizes {
        let g = synthetic_scene(n);
        let cam =
            look_at(Vec3::new(2.2, 1.2, -2.2), Vec3::new(0.0, -0.2, 0.0), Vec3::Y, 256, 256, 256.0 / (2.0 * 0.45));
        bench(&format!("synthetic {n}"), &g, &cam);
    }
}

/// A camera on an orbit around the scene: centred on the median of the means,
/// at 2.2× the 75th-percentile distance of the means from that centre, 60°
/// horizontal field of view, slightly above the horizon. Captured scenes
/// (COLMAP convention) have world −y up.
fn orbit_camera(g: &Gaussians, width: u32, height: u32, azimuth: f32) -> Camera {
    let median = |axis: usize| {
        let mut v: Vec<f32> = g.means.iter().map(|m| m[axis]).collect();
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let centre = Vec3::new(median(0), median(1), median(2));
    let mut d: Vec<f32> = g.means.iter().map(|m| (Vec3::from(*m) - centre).length()).collect();
    d.sort_by(f32::total_cmp);
    let radius = 2.2 * d[d.len() * 3 / 4];
    let eye = centre + radius * Vec3::new(azimuth.cos() * 0.94, -0.34, azimuth.sin() * 0.94);
    look_at(eye, centre, Vec3::NEG_Y, width, height, width as f32 / (2.0 * (30f32).to_radians().tan()))
}

/// Writes an 8-bit binary PPM (for eyeballing the framing).
fn write_ppm(path: &std::path::Path, img: &gast_core::raster::Render) {
    let mut bytes = format!("P6 {} {} 255\n", img.width, img.height).into_bytes();
    bytes.extend(img.rgb.iter().map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8));
    if let Err(e) = std::fs::write(path, bytes) {
        eprintln!("could not write {}: {e}", path.display());
    }
}

#[test]
#[ignore = "timing; run explicitly"]
fn raster_timing_real_scenes() {
    // GAST_PERF_SCENES=guitar keeps the scenes whose path contains that text.
    let only = std::env::var("GAST_PERF_SCENES").unwrap_or_default();
    for rel in
        ["data/scenes/guitar.compressed.ply", "data/scenes/playbot-sog"].into_iter().filter(|r| r.contains(&only))
    {
        let Some(path) = gast_tests::shared_file(rel) else { continue };
        let g = match gast_core::scene::load(&path) {
            Ok(g) => g,
            Err(e) => panic!("{}: {e}", path.display()),
        };
        let cam = orbit_camera(&g, 256, 256, 0.6);
        if let Some(dir) = std::env::var_os("GAST_PERF_PPM") {
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            write_ppm(
                &std::path::Path::new(&dir).join(format!("{name}.ppm")),
                &render(&g, &cam, &RenderOptions::default()),
            );
        }
        bench(rel, &g, &cam);
    }
}
