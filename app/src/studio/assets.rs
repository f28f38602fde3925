//! The project's own demo assets, generated procedurally and deterministically:
//! a small demo scene (a red-capped mushroom on a checkered plinth), three style
//! images (blocks, waves, particles) and the app icon. `gast assets` writes them
//! into `assets/`; a test checks that regenerating reproduces the committed bytes,
//! and the studio falls back to generating them in memory when the folder is absent.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use gast_core::Gaussians;
use gast_core::scene::SH_C0;
use image::{Rgb, RgbImage, Rgba, RgbaImage};

/// File name of the demo scene inside `assets/`.
pub const DEMO_SCENE: &str = "demo_scene.ply";
/// File names of the demo styles inside `assets/`, the first is opened at start.
pub const DEMO_STYLES: [&str; 3] = ["style_waves.png", "style_blocks.png", "style_particles.png"];
/// File name of the app icon inside `assets/`.
pub const ICON: &str = "icon.png";
/// Side of the known-depth relief styles (`relief_*.png` with `relief_*_depth.png`).
pub const RELIEF_SIZE: usize = 256;

/// The committed assets folder of this source tree.
pub fn source_assets_dir() -> PathBuf {
    let app = Path::new(env!("CARGO_MANIFEST_DIR"));
    app.parent().unwrap_or(app).join("assets")
}

/// A small deterministic generator (SplitMix64), so the assets need no RNG crate.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn f(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn push(g: &mut Gaussians, mean: [f32; 3], sigma: [f32; 3], quat: [f32; 4], opacity: f32, rgb: [f32; 3], shimmer: f32) {
    g.means.push(mean);
    g.log_scales.push(sigma.map(f32::ln));
    g.quats.push(quat);
    g.opacity_logits.push((opacity / (1.0 - opacity)).ln());
    // Degree 1: DC from the colour, a little view dependence along x.
    g.sh.extend(rgb.map(|c| (c - 0.5) / SH_C0));
    g.sh.extend([0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    g.sh.extend([shimmer, shimmer, shimmer]);
}

/// Quaternion (w, x, y, z) turning local z onto the unit vector `n`.
fn quat_z_to(n: [f32; 3]) -> [f32; 4] {
    let (x, y, z) = (n[0], n[1], n[2]);
    // Half-way quaternion between (0,0,1) and n.
    let w = 1.0 + z;
    if w < 1e-6 {
        return [0.0, 1.0, 0.0, 0.0];
    }
    let (qx, qy, qz) = (-y, x, 0.0);
    let norm = (w * w + qx * qx + qy * qy + qz * qz).sqrt();
    [w / norm, qx / norm, qy / norm, qz / norm]
}

/// The demo scene: −Y is up; a checkered plinth at y = 0, a mushroom on it.
pub fn demo_scene() -> Gaussians {
    let mut g = Gaussians::with_capacity(5000, 1);
    let mut rng = Rng(7);
    let tau = std::f32::consts::TAU;
    // Plinth: a disc of flat Gaussians, a checkerboard of slate and cream.
    for i in 0..1800 {
        let r = 1.6 * ((i as f32 + 0.5) / 1800.0).sqrt();
        let a = i as f32 * 2.399_963; // golden angle
        let (x, z) = (r * a.cos(), r * a.sin());
        let check = ((x * 2.5).floor() as i32 + (z * 2.5).floor() as i32).rem_euclid(2) == 0;
        let rgb = if check { [0.86, 0.83, 0.74] } else { [0.22, 0.27, 0.34] };
        let j = 0.03 * (rng.f() - 0.5);
        push(&mut g, [x, 0.0, z], [0.055, 0.012, 0.055], [1.0, 0.0, 0.0, 0.0], 0.95, rgb.map(|c| c + j), 0.0);
    }
    // Rim of the plinth.
    for i in 0..240 {
        let a = i as f32 / 240.0 * tau;
        for k in 0..2 {
            let y = 0.05 + 0.08 * k as f32;
            push(
                &mut g,
                [1.62 * a.cos(), y, 1.62 * a.sin()],
                [0.045, 0.045, 0.02],
                quat_z_to([a.cos(), 0.0, a.sin()]),
                0.9,
                [0.15, 0.18, 0.24],
                0.0,
            );
        }
    }
    // Stem: a slightly bulging cylinder, cream.
    for i in 0..700 {
        let t = i as f32 / 700.0;
        let y = -0.05 - 0.95 * t;
        let a = i as f32 * 2.399_963 * 7.0;
        let r = 0.26 + 0.05 * (t * std::f32::consts::PI).sin();
        let n = [a.cos(), 0.0, a.sin()];
        push(&mut g, [r * n[0], y, r * n[2]], [0.05, 0.05, 0.015], quat_z_to(n), 0.92, [0.93, 0.89, 0.78], 0.05);
    }
    // Cap: a dome, red with white spots; its underside (gills) beige.
    for i in 0..1400 {
        let u = (i as f32 + 0.5) / 1400.0;
        let polar = (1.0 - u).acos().min(1.45); // dome from the top down to near the rim
        let a = i as f32 * 2.399_963;
        let n = [polar.sin() * a.cos(), -polar.cos(), polar.sin() * a.sin()];
        let (rx, ry) = (0.95, 0.62);
        let p = [rx * n[0], -0.95 + ry * n[1], rx * n[2]];
        let spot = {
            let s = [(p[0] * 4.0).round() / 4.0, (p[1] * 4.0).round() / 4.0, (p[2] * 4.0).round() / 4.0];
            let d2 = (p[0] - s[0]).powi(2) + (p[1] - s[1]).powi(2) + (p[2] - s[2]).powi(2);
            d2 < 0.007
        };
        let rgb = if spot { [0.97, 0.96, 0.92] } else { [0.80 + 0.08 * rng.f(), 0.10, 0.08] };
        push(&mut g, p, [0.06, 0.06, 0.018], quat_z_to(n), 0.95, rgb, 0.12);
    }
    for i in 0..500 {
        let r = 0.3 + 0.62 * ((i as f32 + 0.5) / 500.0).sqrt();
        let a = i as f32 * 2.399_963;
        push(
            &mut g,
            [r * a.cos(), -0.97, r * a.sin()],
            [0.05, 0.012, 0.05],
            [1.0, 0.0, 0.0, 0.0],
            0.9,
            [0.78, 0.66, 0.50],
            0.0,
        );
    }
    g
}

fn lerp3(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

fn to_rgb8(c: [f32; 3]) -> Rgb<u8> {
    Rgb(c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
}

/// The demo style images, `(file name, image)`.
pub fn demo_styles() -> Vec<(&'static str, RgbImage)> {
    const S: u32 = 256;
    // Waves: bands of blue and teal with a sunset stripe.
    let waves = RgbImage::from_fn(S, S, |x, y| {
        let (fx, fy) = (x as f32 / S as f32, y as f32 / S as f32);
        let phase = fy * 18.0 + (fx * 9.0).sin() * 1.6 + (fx * 23.0 + fy * 5.0).sin() * 0.35;
        let band = 0.5 + 0.5 * phase.sin();
        let deep = lerp3([0.03, 0.10, 0.32], [0.10, 0.55, 0.70], band);
        let foam = if band > 0.93 { 1.0 } else { 0.0 };
        to_rgb8(lerp3(lerp3(deep, [0.98, 0.62, 0.25], (1.0 - fy * 3.0).max(0.0) * 0.8), [0.95, 0.97, 1.0], foam))
    });
    // Blocks: a Mondrian-like grid of coloured rectangles with black lines.
    let mut rng = Rng(42);
    let mut blocks = RgbImage::from_pixel(S, S, Rgb([240, 236, 226]));
    let palette = [[0.85, 0.12, 0.10], [0.10, 0.22, 0.62], [0.98, 0.80, 0.10], [0.94, 0.93, 0.88], [0.94, 0.93, 0.88]];
    let mut rects = vec![(0u32, 0u32, S, S)];
    for _ in 0..9 {
        let k = (rng.next_u64() % rects.len() as u64) as usize;
        let (x0, y0, x1, y1) = rects.swap_remove(k);
        if (x1 - x0).max(y1 - y0) < 40 {
            rects.push((x0, y0, x1, y1));
            continue;
        }
        if x1 - x0 > y1 - y0 {
            let cut = x0 + (x1 - x0) * (30 + (rng.next_u64() % 40) as u32) / 100;
            rects.extend([(x0, y0, cut, y1), (cut, y0, x1, y1)]);
        } else {
            let cut = y0 + (y1 - y0) * (30 + (rng.next_u64() % 40) as u32) / 100;
            rects.extend([(x0, y0, x1, cut), (x0, cut, x1, y1)]);
        }
    }
    for (x0, y0, x1, y1) in rects {
        let c = to_rgb8(palette[(rng.next_u64() % palette.len() as u64) as usize]);
        for y in y0..y1 {
            for x in x0..x1 {
                let line = x < x0 + 4 || y < y0 + 4 || x + 4 >= x1 || y + 4 >= y1;
                blocks.put_pixel(x, y, if line { Rgb([18, 18, 20]) } else { c });
            }
        }
    }
    // Particles: glowing dots on a dark violet ground.
    let mut rng = Rng(3);
    let dots: Vec<(f32, f32, f32, [f32; 3])> = (0..140)
        .map(|_| {
            let hue = rng.f();
            let c = lerp3([1.0, 0.45, 0.15], [0.35, 0.85, 1.0], hue);
            (rng.f() * S as f32, rng.f() * S as f32, 1.5 + 5.0 * rng.f() * rng.f(), c)
        })
        .collect();
    let particles = RgbImage::from_fn(S, S, |x, y| {
        let mut c = lerp3([0.05, 0.02, 0.10], [0.12, 0.04, 0.20], y as f32 / S as f32);
        for &(dx, dy, r, col) in &dots {
            let d2 = (x as f32 - dx).powi(2) + (y as f32 - dy).powi(2);
            let w = (-d2 / (2.0 * r * r)).exp();
            c = [c[0] + col[0] * w, c[1] + col[1] * w, c[2] + col[2] * w];
        }
        to_rgb8(c)
    });
    vec![(DEMO_STYLES[0], waves), (DEMO_STYLES[1], blocks), (DEMO_STYLES[2], particles)]
}

/// The app icon: three overlapping soft splats on a rounded dark square.
pub fn icon() -> RgbaImage {
    const S: u32 = 128;
    let blobs = [
        (48.0, 52.0, 26.0, [0.92, 0.25, 0.20]),
        (80.0, 56.0, 24.0, [0.20, 0.55, 0.95]),
        (64.0, 84.0, 25.0, [0.98, 0.80, 0.20]),
    ];
    RgbaImage::from_fn(S, S, |x, y| {
        let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
        // Rounded-square mask.
        let q = |v: f32| (v - 64.0).abs() - 46.0;
        let (qx, qy) = (q(fx).max(0.0), q(fy).max(0.0));
        let outside = (qx * qx + qy * qy).sqrt() - 14.0;
        let a = (0.5 - outside).clamp(0.0, 1.0);
        let mut c = [0.10, 0.11, 0.15];
        for &(bx, by, r, col) in &blobs {
            let d2 = (fx - bx).powi(2) + (fy - by).powi(2);
            let q = d2 / (r * r * 0.55);
            let w = 0.92 * (-0.5 * q * q).exp();
            c = lerp3(c, col, w);
        }
        let p = to_rgb8(c).0;
        Rgba([p[0], p[1], p[2], (a * 255.0 + 0.5) as u8])
    })
}

fn png_bytes<P: image::PixelWithColorType>(img: &image::ImageBuffer<P, Vec<P::Subpixel>>) -> anyhow::Result<Vec<u8>>
where
    [P::Subpixel]: image::EncodableLayout,
{
    use image::EncodableLayout as _;
    let mut out = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut out),
        img.as_raw().as_bytes(),
        img.width(),
        img.height(),
        P::COLOR_TYPE,
    )
    .context("encoding a PNG")?;
    Ok(out)
}

/// Writes every asset into `dir` (each file atomically); returns the paths.
pub fn generate(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    gast_core::io::create_folder(dir).with_context(|| format!("creating {}", dir.display()))?;
    let scene = dir.join(DEMO_SCENE);
    gast_core::scene::save_ply(&scene, &demo_scene())?;
    let mut paths = vec![scene];
    let mut images: Vec<(String, Vec<u8>)> = demo_styles()
        .into_iter()
        .map(|(n, img)| Ok((n.to_string(), png_bytes(&img)?)))
        .collect::<anyhow::Result<_>>()?;
    images.push((ICON.to_string(), png_bytes(&icon())?));
    // Styles whose depth is known (relief height fields), with that depth as a 16-bit PNG
    // for `--style-depth`.
    for kind in gast_core::vision::relief_styles::ReliefKind::ALL {
        let r = gast_core::vision::relief_styles::relief_style(kind, RELIEF_SIZE);
        let (w, h) = (r.width as u32, r.height as u32);
        let rgb = RgbImage::from_raw(w, h, r.rgb).context("relief style size")?;
        let depth: Vec<u16> = r.depth.iter().map(|&d| (d.clamp(0.0, 1.0) * 65535.0).round() as u16).collect();
        let depth =
            image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(w, h, depth).context("relief depth size")?;
        images.push((format!("{}.png", kind.name()), png_bytes(&rgb)?));
        images.push((format!("{}_depth.png", kind.name()), png_bytes(&depth)?));
    }
    for (name, bytes) in images {
        let path = dir.join(&name);
        gast_core::io::write_bytes(&path, &bytes).with_context(|| format!("writing {}", path.display()))?;
        paths.push(path);
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The committed assets are exactly what the generator makes today.
    /// Run `cargo run -p gast -- assets` after changing the generator.
    #[test]
    fn committed_assets_are_reproducible() {
        let dir = source_assets_dir();
        let fresh = std::env::temp_dir().join(format!("gast-assets-{}", std::process::id()));
        let mut total = 0;
        for made in generate(&fresh).expect("generate") {
            let bytes = std::fs::read(&made).expect("read generated");
            let path = dir.join(made.file_name().expect("name"));
            let committed = std::fs::read(&path)
                .unwrap_or_else(|e| panic!("{}: {e}; run `cargo run -p gast -- assets`", path.display()));
            assert!(
                committed == bytes,
                "{} differs from the generator's output; run `cargo run -p gast -- assets`",
                path.display()
            );
            total += bytes.len();
        }
        std::fs::remove_dir_all(&fresh).ok();
        println!("assets: {total} bytes");
        assert!(total < 2 << 20, "assets too large: {total} bytes");
    }

    #[test]
    fn demo_scene_is_consistent() {
        let g = demo_scene();
        g.check_consistent().expect("consistent");
        assert!((3000..10000).contains(&g.len()), "{} Gaussians", g.len());
    }
}
