//! Viewport tests on a headless device (lavapipe here): every shader
//! validates, the GPU viewport and its depth sort draw what the CPU
//! rasterizer and sort do, the before/after blit, the SH split across two
//! bindings; and the 500k frame-time benchmark behind `GAST_BENCH`.

use std::path::PathBuf;
use std::sync::Arc;

use super::*;
use crate::studio::assets;
use crate::studio::tests::{demo_camera, device_or_skip};
use gast_core::raster::{RenderOptions, render};

fn shader_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("shaders")
}

#[test]
fn every_wgsl_file_validates_with_naga() {
    let mut checked = 0;
    let mut failures = Vec::new();
    for entry in std::fs::read_dir(shader_dir()).expect("shaders/ folder") {
        let path = entry.expect("entry").path();
        if path.extension().is_none_or(|e| e != "wgsl") {
            continue;
        }
        let mut src = std::fs::read_to_string(&path).expect("read shader");
        // The raster shaders take their uniform block from raster_camera.wgsl, as the engine composes them.
        if src.contains(": Cam;") && !src.contains("struct Cam ") {
            src = std::fs::read_to_string(shader_dir().join("raster_camera.wgsl")).expect("raster_camera.wgsl") + &src;
        }
        let result = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src)).and_then(|module| {
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
                .validate(&module)
                .map(|_| ())
                .map_err(|e| format!("{e:?}"))
        });
        if let Err(e) = result {
            failures.push(format!("{}: {e}", path.display()));
        }
        checked += 1;
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(checked >= 3, "only {checked} shaders found");
}

#[test]
fn sh_packing_round_trips_through_f16() {
    let g = bench::synthetic_scene(10);
    let (words, per) = super::pack_sh_f16(&g, 3);
    assert_eq!(per, 24);
    let back = super::f16_to_f32((words[0] & 0xffff) as u16);
    assert!((back - g.sh[0]).abs() < 1e-3);
}

#[test]
fn gpu_viewport_matches_the_cpu_reference() {
    let Some((device, queue, adapter)) = device_or_skip("gpu_viewport_matches_the_cpu_reference") else { return };
    let g: SharedGaussians = Arc::new(assets::demo_scene()).into();
    let (w, h) = (320, 240);
    let cam = demo_camera(&g, w, h);
    let mut r = SplatRenderer::new(&device);
    r.set_scene(&device, Side::Before, 1, &g).expect("upload");
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    assert!(r.render(&device, &queue, &mut encoder, Side::Before, &cam));
    queue.submit([encoder.finish()]);
    let (texture, _) = r.target(Side::Before).expect("target");
    let gpu = read_target(&device, &queue, texture);
    let cpu = render(&g, &cam, &RenderOptions::default());
    let mut sum = 0.0f64;
    let mut max = 0.0f32;
    for (p, px) in gpu.iter().enumerate() {
        for (ch, &v) in px.iter().take(3).enumerate() {
            let d = (v - cpu.rgb[p * 3 + ch]).abs();
            sum += d as f64;
            max = max.max(d);
        }
    }
    let mean = sum / (w * h * 3) as f64;
    let coverage = cpu.alpha.iter().filter(|&&a| a > 0.5).count() as f32 / (w * h) as f32;
    println!(
        "GPU viewport vs CPU rasterizer on {adapter}: mean |diff| {mean:.5}, max {max:.3}, coverage {coverage:.2}"
    );
    assert!(coverage > 0.1, "the demo scene covers only {coverage} of the view");
    assert!(mean < 0.01, "mean abs difference {mean}");
    // Save both for a look.
    let out = std::env::temp_dir().join("gast-studio-gpu-vs-cpu");
    let gpu_rgb: Vec<f32> = gpu.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
    gast_core::io::write_png_rgb(&out.join("gpu.png"), w, h, &gpu_rgb).expect("png");
    gast_core::io::write_png_rgb(&out.join("cpu.png"), w, h, &cpu.rgb).expect("png");
    println!("wrote {}", out.display());
}

/// The GPU depth sort (keys from the projection pass, the engine's radix sort)
/// draws what the CPU sort draws: the same order of every visible splat.
#[test]
fn gpu_depth_sort_draws_what_the_cpu_sort_draws() {
    use gast_core::gpu::{AdapterPolicy, GpuContext};
    let ctx = GpuContext::headless(AdapterPolicy::AnyAdapter).expect("a wgpu adapter (lavapipe)");
    let (device, queue) = (&ctx.device, &ctx.queue);
    let g: SharedGaussians = Arc::new(assets::demo_scene()).into();
    let (w, h) = (160, 120);
    let cam = demo_camera(&g, w, h);
    let mut images = Vec::new();
    for gpu_sort in [false, true] {
        let mut r = SplatRenderer::new(device);
        if gpu_sort {
            r.use_gpu_sort(ctx.clone());
        }
        r.set_scene(device, Side::Before, 1, &g).expect("upload");
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        assert!(r.render(device, queue, &mut encoder, Side::Before, &cam));
        queue.submit([encoder.finish()]);
        let (texture, _) = r.target(Side::Before).expect("target");
        images.push(read_target(device, queue, texture));
        if gpu_sort {
            // Every Gaussian once, the visible ones farthest first.
            let order: Vec<u32> = ctx.read(r.order_buffer(Side::Before).expect("order")).expect("read back");
            let order = &order[..g.len()];
            let mut seen = vec![false; g.len()];
            order.iter().for_each(|&i| seen[i as usize] = true);
            assert!(seen.iter().all(|&s| s), "the GPU order is not a permutation");
            let row = cam.rotation.row(2);
            let z = |i: u32| row.dot(glam::Vec3::from_array(g.means[i as usize])) + cam.translation.z;
            let cpu = super::sort::back_to_front(&g.means, row, cam.translation.z);
            let visible: Vec<u32> = order.iter().copied().filter(|&i| cpu.contains(&i)).collect();
            assert!(visible.windows(2).all(|p| z(p[0]) >= z(p[1])), "the GPU order is not back to front");
        }
    }
    let worst = images[0]
        .iter()
        .zip(&images[1])
        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "GPU-sorted frame differs from the CPU-sorted one by {worst}");
}

#[test]
fn viewport_frame_time_500k() {
    if std::env::var_os("GAST_BENCH").is_none() {
        eprintln!("SKIPPED viewport_frame_time_500k: set GAST_BENCH=1 (takes a minute on lavapipe)");
        return;
    }
    if device_or_skip("viewport_frame_time_500k").is_none() {
        return;
    }
    // The shared 500k scene when it is there, a synthetic one of the same size otherwise.
    let playbot = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/scenes/playbot-sog");
    let scene = playbot.exists().then_some(playbot.as_path());
    println!("{}", bench::run(scene, 500_000, 5, 1280, 720).expect("bench"));
}

#[test]
fn blit_composites_the_before_after_split() {
    let Some((device, queue, _)) = device_or_skip("blit_composites_the_before_after_split") else { return };
    let before: SharedGaussians = Arc::new(assets::demo_scene()).into();
    let mut dark = (*before).clone();
    // Recolour the "after" side blue so the halves are easy to tell apart.
    let k = dark.sh_coeffs() * 3;
    for dc in dark.sh.chunks_exact_mut(k) {
        dc[0] -= 1.0;
        dc[1] -= 0.3;
    }
    let after: SharedGaussians = Arc::new(dark).into();
    // The studio's viewport at 1600×1000 (an odd width, as a window's often is).
    let (w, h) = (1107u32, 690u32);
    let cam = demo_camera(&before, w, h);
    let mut r = SplatRenderer::new(&device);
    r.set_scene(&device, Side::Before, 1, &before).expect("upload");
    r.set_scene(&device, Side::After, 2, &after).expect("upload");
    let format = wgpu::TextureFormat::Rgba8Unorm;
    let blit = super::blit::BlitPipeline::new(&device, format);
    let out = device.create_texture(&wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let out_view = out.create_view(&Default::default());
    let mut encoder = device.create_command_encoder(&Default::default());
    r.render(&device, &queue, &mut encoder, Side::Before, &cam);
    r.render(&device, &queue, &mut encoder, Side::After, &cam);
    // The middle of an odd width falls on a pixel's centre, where the line's
    // columns were decided by the interpolated coordinate's rounding.
    let split = 0.5;
    let params =
        super::gpu_types::BlitUniform { background: [0.1, 0.1, 0.12, 1.0], split: [split, 0.0, w as f32, 0.0] };
    let bind = blit.prepare(
        &device,
        &queue,
        params,
        r.target(Side::Before).expect("before").1,
        r.target(Side::After).expect("after").1,
    );
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: None,
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &out_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::RED), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        blit.draw(&mut pass, &bind);
    }
    queue.submit([encoder.finish()]);
    let rows = read_texture_rows(&device, &queue, &out, 4).expect("read back the blit");
    let mut img = image::RgbImage::new(w, h);
    for (y, line) in rows.iter().enumerate() {
        for (x, px) in line.chunks_exact(4).enumerate() {
            img.put_pixel(x as u32, y as u32, image::Rgb([px[0], px[1], px[2]]));
        }
    }
    let path = std::env::temp_dir().join("gast-studio-gpu-vs-cpu").join("split.png");
    std::fs::create_dir_all(path.parent().expect("parent")).expect("dir");
    img.save(&path).expect("save");
    println!("wrote {}", path.display());
    // The background fills the corners, the split line is drawn, halves differ in colour.
    assert_eq!(img.get_pixel(2, 2).0, [26, 26, 31]);
    let line = img.get_pixel(w / 2, h / 2).0;
    assert!(line[0] > 200 && line[2] < 100, "split line {line:?}");
    // The line is straight and two pixels wide: the same columns in every row.
    let columns = |y: u32| (0..w).filter(|&x| img.get_pixel(x, y).0 == [255, 217, 51]).collect::<Vec<_>>();
    let first = columns(0);
    assert_eq!(first.len(), 2, "line columns {first:?}");
    for y in 1..h {
        assert_eq!(columns(y), first, "row {y}: the line steps");
    }
    let mean = |x0: u32, x1: u32| {
        let mut s = [0f64; 3];
        for y in 0..h {
            for x in x0..x1 {
                for (acc, v) in s.iter_mut().zip(img.get_pixel(x, y).0) {
                    *acc += v as f64;
                }
            }
        }
        s
    };
    let (l, r) = (mean(0, w / 2 - 2), mean(w / 2 + 2, w));
    println!("left RGB sums {l:?}, right {r:?}");
    assert!(l[0] > r[0] * 1.2, "the right (after) side should be less red");
}

#[test]
fn sh_split_across_two_bindings_renders_the_same() {
    let Some((device, queue, _)) = device_or_skip("sh_split_across_two_bindings_renders_the_same") else { return };
    let g: SharedGaussians = Arc::new(bench::synthetic_scene(3000)).into();
    let cam = demo_camera(&g, 160, 120);
    let mut images = Vec::new();
    for limit in [None, Some(1500 * 24 * 4)] {
        let mut r = SplatRenderer::new(&device);
        // Lowered: 1500 Gaussians in each binding.
        r.sh_binding_limit = limit;
        assert_eq!(r.set_scene(&device, Side::Before, 1, &g), Ok(None));
        let mut encoder = device.create_command_encoder(&Default::default());
        r.render(&device, &queue, &mut encoder, Side::Before, &cam);
        queue.submit([encoder.finish()]);
        images.push(read_target(&device, &queue, r.target(Side::Before).expect("target").0));
    }
    let lit = images[0].iter().filter(|p| p[3] > 0.1).count();
    assert!(lit > 1000, "only {lit} pixels drawn");
    assert!(images[0] == images[1], "splitting the SH bindings changed the render");
    // Two bindings of 1000 cannot hold 3000 Gaussians of SH3: degree 2 is drawn, and said.
    let mut r = SplatRenderer::new(&device);
    r.sh_binding_limit = Some(1000 * 24 * 4);
    let note = r.set_scene(&device, Side::Before, 1, &g).expect("upload").expect("a note");
    assert!(note.contains("SH degree 2 of 3"), "{note}");
}

#[test]
fn a_still_view_of_the_same_scene_keeps_its_image() {
    let Some((device, queue, _)) = device_or_skip("a_still_view_of_the_same_scene_keeps_its_image") else { return };
    let g: SharedGaussians = Arc::new(assets::demo_scene()).into();
    let cam = demo_camera(&g, 160, 120);
    let mut r = SplatRenderer::new(&device);
    r.set_scene(&device, Side::Before, 1, &g).expect("upload");
    let frame = |r: &mut SplatRenderer, cam: &Camera| {
        r.begin_frame();
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        assert!(r.render(&device, &queue, &mut encoder, Side::Before, cam));
        queue.submit([encoder.finish()]);
        let (texture, _) = r.target(Side::Before).expect("target");
        (r.stats, read_target(&device, &queue, texture))
    };
    let (first, image) = frame(&mut r, &cam);
    assert_eq!(first.kept, 0);
    assert!(first.drawn > 0);
    // The same camera and scene: nothing drawn, the same image, the same count.
    let (again, kept_image) = frame(&mut r, &cam);
    assert_eq!((again.kept, again.drawn), (1, first.drawn));
    assert_eq!(kept_image, image);
    // Another camera, or another version of the scene, is drawn.
    let mut moved = cam.clone();
    moved.translation.x += 0.05;
    assert_eq!(frame(&mut r, &moved).0.kept, 0);
    r.set_scene(&device, Side::Before, 2, &g).expect("upload");
    assert_eq!(frame(&mut r, &moved).0.kept, 0);
    assert_eq!(frame(&mut r, &moved).0.kept, 1);
}
