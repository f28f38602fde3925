//! Turntables: a scene seen from a ring of cameras around its up axis (or,
//! for a forward-facing capture such as LLFF's fern, from a loop through its
//! own cameras: [`gast_core::camera::forward_sweep`]), as numbered PNG frames
//! and one looping animated GIF, the form a chat or a web page shows without
//! a viewer. With a second scene the two are rendered from
//! the same cameras and put side by side in each frame (before | after), so a
//! stylization can be shared as one moving picture.
//!
//! `gast render --turntable` and the studio's "Export turntable" both call
//! [`write()`], so the two give the same files.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use gast_core::camera::{OrbitLayout, OrbitOptions, forward_sweep, orbit_cameras};
use gast_core::io::{write_bytes, write_png_rgb};
use gast_core::raster::{self, RenderOptions};
use gast_core::{Camera, Gaussians};
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};

/// File name of the animated GIF inside the output folder.
pub const GIF_NAME: &str = "turntable.gif";

/// How a turntable is shot.
#[derive(Clone, Debug)]
pub struct TurntableOptions {
    /// Frames in one full turn.
    pub frames: usize,
    /// Width and height of one view in pixels (a side-by-side frame is twice as wide).
    pub size: u32,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f32,
    /// Height of the ring above the scene's centre, degrees.
    pub elevation_degrees: f32,
    /// The scene's up direction in world space.
    pub up: [f32; 3],
    /// Background colour, RGB in [0, 1].
    pub background: [f32; 3],
    /// The scene's training cameras, when it has them: forward-facing ones
    /// replace the ring by a loop through them (their field of view, not
    /// `fov_y_degrees`).
    pub training: Vec<Camera>,
}

impl Default for TurntableOptions {
    fn default() -> Self {
        Self {
            frames: 36,
            size: 512,
            fov_y_degrees: 50.0,
            elevation_degrees: 20.0,
            up: OrbitOptions::default().up,
            background: [0.0; 3],
            training: Vec::new(),
        }
    }
}

/// What [`write()`] produced.
#[derive(Clone, Debug)]
pub struct Turntable {
    /// The PNG frames, in turning order.
    pub frames: Vec<PathBuf>,
    /// The looping animated GIF of all frames.
    pub gif: PathBuf,
    /// Width of a frame in pixels.
    pub width: u32,
    /// Height of a frame in pixels.
    pub height: u32,
}

/// The ring of cameras around `scene` (evenly spaced over one turn), or the
/// loop through forward-facing training cameras.
pub fn cameras(scene: &Gaussians, opts: &TurntableOptions) -> Vec<Camera> {
    let size = opts.size.max(1);
    if let Some(sweep) = forward_sweep(&opts.training, &scene.means, opts.frames.max(1), size, size) {
        return sweep;
    }
    let orbit = OrbitOptions {
        count: opts.frames.max(1),
        width: size,
        height: size,
        fov_y_degrees: opts.fov_y_degrees,
        up: opts.up,
        layout: OrbitLayout::Ring { elevation_degrees: opts.elevation_degrees },
        ..OrbitOptions::default()
    };
    orbit_cameras(&scene.means, &orbit)
}

/// Time each frame stays on screen: a full turn in about four seconds,
/// between 40 ms and 250 ms a frame, in the GIF's 10 ms steps.
fn frame_delay_ms(frames: usize) -> u32 {
    let ms = 4000 / frames.max(1) as u32;
    (ms.clamp(40, 250) / 10) * 10
}

/// Renders `scene` (and `after` beside it, from the same cameras) on the
/// turntable ring and writes `turntable_NNN.png` and [`GIF_NAME`] into `out`,
/// each file atomically. `progress(done, total)` is called after every frame.
pub fn write(
    out: &Path,
    scene: &Gaussians,
    after: Option<&Gaussians>,
    opts: &TurntableOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> anyhow::Result<Turntable> {
    anyhow::ensure!(opts.frames > 0, "a turntable needs at least one frame, found --turntable 0");
    let panels = if after.is_some() { 2 } else { 1 };
    let (width, height) = (opts.size.max(1) * panels, opts.size.max(1));
    anyhow::ensure!(
        width <= u32::from(u16::MAX),
        "a GIF frame is at most {} pixels wide, the turntable's would be {width}",
        u16::MAX
    );
    gast_core::io::create_folder(out).with_context(|| format!("could not create the folder {}", out.display()))?;
    let render_opts = RenderOptions { background: opts.background };
    let cams = cameras(scene, opts);
    let delay = Delay::from_numer_denom_ms(frame_delay_ms(cams.len()), 1);
    let mut frames = Vec::with_capacity(cams.len());
    let mut gif_frames = Vec::with_capacity(cams.len());
    for (i, cam) in cams.iter().enumerate() {
        let views: Vec<raster::Render> =
            std::iter::once(scene).chain(after).map(|g| raster::render(g, cam, &render_opts)).collect();
        let rgb = side_by_side(&views);
        let path = out.join(format!("turntable_{i:03}.png"));
        write_png_rgb(&path, width, height, &rgb)?;
        frames.push(path);
        let rgba: Vec<u8> = rgb.chunks_exact(3).flat_map(|p| [to_u8(p[0]), to_u8(p[1]), to_u8(p[2]), 255]).collect();
        let image = RgbaImage::from_raw(width, height, rgba).context("a turntable frame has the wrong size")?;
        gif_frames.push(Frame::from_parts(image, 0, 0, delay));
        progress(i + 1, cams.len());
    }
    let gif = out.join(GIF_NAME);
    write_bytes(&gif, &encode_gif(gif_frames).with_context(|| format!("encoding {}", gif.display()))?)?;
    // A longer turntable's frames from before would read as this one's.
    gast_core::io::remove_series_tail(out, "turntable_", &[".png"], cams.len())
        .map_err(|(path, e)| anyhow::anyhow!("{}: removing an earlier turntable's frame: {e}", path.display()))?;
    Ok(Turntable { frames, gif, width, height })
}

/// A colour channel in [0, 1] as an 8-bit value.
fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Renders of equal height as one row-major RGB image, left to right.
fn side_by_side(views: &[raster::Render]) -> Vec<f32> {
    let height = views.first().map_or(0, |v| v.height) as usize;
    let mut rgb = Vec::with_capacity(views.iter().map(|v| v.rgb.len()).sum());
    for y in 0..height {
        for v in views {
            let row = 3 * v.width as usize;
            rgb.extend_from_slice(&v.rgb[y * row..(y + 1) * row]);
        }
    }
    rgb
}

/// A looping GIF of `frames` (each quantised to its own 256-colour palette).
fn encode_gif(frames: Vec<Frame>) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    {
        let mut encoder = GifEncoder::new_with_speed(&mut bytes, 10);
        encoder.set_repeat(Repeat::Infinite)?;
        encoder.encode_frames(frames)?;
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turn_lasts_about_four_seconds_within_the_bounds() {
        assert_eq!(frame_delay_ms(36), 110);
        assert_eq!(frame_delay_ms(4), 250);
        assert_eq!(frame_delay_ms(400), 40);
    }

    #[test]
    fn the_ring_turns_once_around_the_up_axis_at_one_height() {
        let scene = crate::studio::assets::demo_scene();
        let opts = TurntableOptions { frames: 8, size: 32, ..TurntableOptions::default() };
        let cams = cameras(&scene, &opts);
        assert_eq!(cams.len(), 8);
        let up = glam::Vec3::from(opts.up);
        let heights: Vec<f32> = cams.iter().map(|c| c.center().dot(up)).collect();
        for h in &heights {
            assert!((h - heights[0]).abs() < 1e-3, "heights differ: {heights:?}");
        }
        // Opposite frames sit on opposite sides of the centre.
        let (a, b) = (cams[0].center(), cams[4].center());
        let mid = (a + b) * 0.5;
        let horizontal = |v: glam::Vec3| v - up * v.dot(up);
        assert!(horizontal(a - mid).dot(horizontal(b - mid)) < 0.0);
    }
}
