//! The contact sheet of a stylization run: one image a person reads at a
//! glance. The style with its depth and edge maps, then four views, each
//! before / colour-matched / after in RGB, in inverse depth (grey) and in
//! inverse depth as the reference draws it (min-max, JET), labelled, with
//! the run's settings and time. `gast stylize` writes it as `sheet.png`; the
//! studio exports the same sheet for its current run.
//!
//! Tiles are letterboxed into boxes `TILE` wide so that views of any aspect
//! ratio (the fitted framing gives each view its own) line up in a grid; a
//! row is as tall as its tallest tile at that width (at most `TILE`), so
//! wide views leave no empty bands above and below.

use std::path::Path;

use gast_core::io::depth_to_gray;
use gast_core::raster::{self, Render, RenderOptions};
use gast_core::style::config::{LossWeights, ParamRegulariser};
use gast_core::style::{StyleConfig, StyleMaps};
use gast_core::vision::colormap::depth_to_jet;
use gast_core::{Camera, Gaussians};
use image::{Rgb, RgbImage};
use vello_cpu::color::AlphaColor;
use vello_cpu::kurbo::{Affine, BezPath};

use super::glyphs::shape_text;

/// Width of one tile, and the most a row of tiles is high, pixels.
const TILE: u32 = 200;
/// Gap between tiles, pixels.
const GAP: u32 = 6;
/// Height of a label line above a row of tiles.
const LABEL: u32 = 22;
/// Columns of the grid: RGB, grey depth and JET depth of before / colour-matched / after.
const COLUMNS: u32 = 9;
const BACKGROUND: Rgb<u8> = Rgb([28, 28, 32]);
const LETTERBOX: Rgb<u8> = Rgb([48, 48, 54]);

/// One picture of the sheet: an 8-bit RGB image of any size.
pub struct Tile {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width · height · 3` bytes.
    pub rgb: Vec<u8>,
}

impl Tile {
    /// Colour of a float RGB image (clamped to [0, 1]).
    pub fn from_rgb(width: u32, height: u32, rgb: &[f32]) -> Self {
        Self { width, height, rgb: rgb.iter().map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect() }
    }

    /// A single-channel map in grey, min-max normalised.
    pub fn from_gray(width: u32, height: u32, values: &[f32]) -> Self {
        let (lo, hi) = gast_core::io::finite_range(values);
        let s = if hi > lo { 255.0 / (hi - lo) } else { 0.0 };
        Self {
            width,
            height,
            rgb: values.iter().flat_map(|&v| [((v - lo) * s).round().clamp(0.0, 255.0) as u8; 3]).collect(),
        }
    }

    /// The colour of a render.
    pub fn render_rgb(r: &Render) -> Self {
        Self::from_rgb(r.width, r.height, &r.rgb)
    }

    /// The inverse depth of a render, as `write_depth_png` draws it (near bright, background black).
    pub fn render_depth(r: &Render) -> Self {
        let g = depth_to_gray(&r.inv_depth, &r.alpha);
        Self { width: r.width, height: r.height, rgb: g.iter().flat_map(|&v| [v; 3]).collect() }
    }

    /// The inverse depth of a render in JET, as the reference draws its depth figures.
    pub fn render_depth_jet(r: &Render) -> Self {
        Self { width: r.width, height: r.height, rgb: depth_to_jet(&r.inv_depth, &r.alpha) }
    }
}

/// Everything the sheet shows.
pub struct SheetContent {
    /// The first line: what ran (scene, style).
    pub title: String,
    /// The second line: the settings and the time.
    pub settings: String,
    /// The style, its depth and its edges.
    pub style: [Tile; 3],
    /// Per view: before, colour-matched and after renders.
    pub views: Vec<[Render; 3]>,
}

/// The three scenes of a run and the cameras they are seen from.
pub struct RunViews<'a> {
    /// The scene as loaded.
    pub input: &'a Gaussians,
    /// The colour-matched scene before optimisation.
    pub colour_matched: &'a Gaussians,
    /// The current (or final) result.
    pub result: &'a Gaussians,
    /// The optimisation cameras.
    pub cameras: &'a [Camera],
    /// Background colour of the renders.
    pub background: [f32; 3],
}

impl RunViews<'_> {
    /// Before, colour-matched and after renders from `count` cameras spread over the set.
    pub fn render(&self, count: usize) -> Vec<[Render; 3]> {
        let opts = RenderOptions { background: self.background };
        spread(self.cameras, count)
            .map(|cam| {
                [
                    raster::render(self.input, cam, &opts),
                    raster::render(self.colour_matched, cam, &opts),
                    raster::render(self.result, cam, &opts),
                ]
            })
            .collect()
    }
}

/// `count` cameras evenly spread over `cameras` (all of them when fewer).
pub fn spread(cameras: &[Camera], count: usize) -> impl Iterator<Item = &Camera> {
    let step = (cameras.len() / count.max(1)).max(1);
    cameras.iter().step_by(step).take(count)
}

/// Style maps (RGB, depth, edges) as tiles.
pub fn maps_tiles(m: &StyleMaps) -> [Tile; 3] {
    let (w, h) = (m.width as u32, m.height as u32);
    [Tile::from_rgb(w, h, &m.rgb), Tile::from_gray(w, h, &m.depth), Tile::from_gray(w, h, &m.edge)]
}

/// The sheet's settings line: mode, steps, sizes, focus, the learning rates
/// the collapse study varies (colour, and the means' per unit of extent), the
/// colour floor, the loss weights that differ from the defaults and the time
/// of the steps `from..steps` (`from` > 0: a run resumed there).
pub fn settings_line(
    config: &StyleConfig,
    (from, steps): (u32, u32),
    seconds: f64,
    focus_on_object: bool,
    coverage: f32,
) -> String {
    let focus = if focus_on_object { "object" } else { "frame" };
    let defaults = LossWeights::default();
    let weights: String = config
        .weights
        .terms()
        .filter(|(t, v)| *v != t.get(&defaults))
        .map(|(t, v)| format!(", {} {v}", t.symbol))
        .collect();
    // The geometry options that are off by default, when on.
    let mut options = String::new();
    if config.depth_relief_px > 0 {
        options += &format!(", depth relief {} px", config.depth_relief_px);
    }
    if config.param_regulariser == ParamRegulariser::MeanSquare {
        options += ", mean-square regulariser";
    }
    if config.split_px > 0.0 {
        options += &format!(", split {} px", config.split_px);
    }
    if config.leaks_between_phases() {
        options += ", phase leak";
    }
    format!(
        "{} {} steps ({} cycles x {}), {} px, texture {} px, focus {focus} (asked {:?}, coverage {:.0}%), lr colour {}, means {:e} x extent, colour floor {}{weights}{options}; {:.0} s ({:.2} s/step)",
        config.mode.name(),
        steps,
        config.cycles,
        config.steps_per_cycle,
        config.resolution,
        config.texture_scale,
        config.focus,
        100.0 * coverage,
        config.lr.color,
        config.lr.means_per_extent,
        if config.color_floor { "on" } else { "off" },
        seconds,
        seconds / f64::from(steps.saturating_sub(from).max(1)),
    ) + &if from > 0 { format!(", resumed at step {from}") } else { String::new() }
}

/// The sheet as an RGB image.
pub fn contact_sheet(content: &SheetContent) -> RgbImage {
    let width = COLUMNS * TILE + (COLUMNS + 1) * GAP;
    let header = 2 * LABEL + GAP;
    let style_h = content.style.iter().map(fitted_height).max().unwrap_or(TILE);
    let view_h: Vec<u32> = content
        .views
        .iter()
        .map(|rs| rs.iter().map(|r| row_height(r.width, r.height)).max())
        .map(|h| h.unwrap_or(TILE))
        .collect();
    let row = |h: u32| LABEL + h + GAP;
    let height = header + row(style_h) + view_h.iter().map(|&h| row(h)).sum::<u32>() + GAP;
    let mut img = RgbImage::from_pixel(width, height, BACKGROUND);
    let mut labels: Vec<(f64, f64, f64, String)> = vec![
        (f64::from(GAP), 17.0, 16.0, content.title.clone()),
        (f64::from(GAP), f64::from(LABEL) + 15.0, 13.0, content.settings.clone()),
    ];
    let col_x = |c: u32| GAP + c * (TILE + GAP);
    let mut y = header;
    for (c, (tile, name)) in content.style.iter().zip(["style", "style depth", "style edges"]).enumerate() {
        labels.push((f64::from(col_x(c as u32)), f64::from(y + 16), 13.0, name.into()));
        blit(&mut img, tile, col_x(c as u32), y + LABEL, style_h);
    }
    y += row(style_h);
    let names = ["before", "colour-matched", "after"];
    for (v, (renders, &h)) in content.views.iter().zip(&view_h).enumerate() {
        for (k, r) in renders.iter().enumerate() {
            let (rgb_col, depth_col, jet_col) = (k as u32, 3 + k as u32, 6 + k as u32);
            labels.push((f64::from(col_x(rgb_col)), f64::from(y + 16), 13.0, format!("view {} {}", v + 1, names[k])));
            labels.push((f64::from(col_x(depth_col)), f64::from(y + 16), 13.0, format!("{} depth", names[k])));
            labels.push((f64::from(col_x(jet_col)), f64::from(y + 16), 13.0, format!("{} depth, JET", names[k])));
            blit(&mut img, &Tile::render_rgb(r), col_x(rgb_col), y + LABEL, h);
            blit(&mut img, &Tile::render_depth(r), col_x(depth_col), y + LABEL, h);
            blit(&mut img, &Tile::render_depth_jet(r), col_x(jet_col), y + LABEL, h);
        }
        y += row(h);
    }
    draw_text(&mut img, &labels);
    img
}

/// Writes the sheet as a PNG (atomically).
pub fn write_sheet(path: &Path, content: &SheetContent) -> anyhow::Result<()> {
    let img = contact_sheet(content);
    // The error names the file already; its Display carries the cause.
    gast_core::io::write_png_rgb8(path, img.width(), img.height(), img.as_raw())
        .map_err(|e| anyhow::anyhow!("cannot write the contact sheet: {e}"))
}

/// The scale that fits `tile` into a `TILE × TILE` square, and its size at it.
fn fit(tile: &Tile) -> (f64, u32, u32) {
    let (tw, th) = (tile.width.max(1), tile.height.max(1));
    let s = f64::from(TILE) / f64::from(tw.max(th));
    let size = |v: u32| ((f64::from(v) * s).round() as u32).clamp(1, TILE);
    (s, size(tw), size(th))
}

/// How high `tile` is drawn ([`blit`]): `TILE` for a tall or square one.
fn fitted_height(tile: &Tile) -> u32 {
    fit(tile).2
}

/// The height of a sheet row whose pictures are `width × height` (all of a
/// view's are): they are drawn `TILE` wide, or `TILE` high when taller.
pub fn row_height(width: u32, height: u32) -> u32 {
    fitted_height(&Tile { width, height, rgb: Vec::new() })
}

/// Draws `tile` scaled (nearest neighbour) into the box `TILE` wide and
/// `box_h` high at `(x0, y0)`, centred, keeping its aspect ratio (at most
/// `TILE × TILE`); the rest is letterbox grey.
fn blit(img: &mut RgbImage, tile: &Tile, x0: u32, y0: u32, box_h: u32) {
    let (tw, th) = (tile.width.max(1), tile.height.max(1));
    let (s, dw, dh) = fit(tile);
    let (ox, oy) = ((TILE - dw) / 2, (box_h.saturating_sub(dh)) / 2);
    for y in 0..box_h {
        for x in 0..TILE {
            let inside = x >= ox && x < ox + dw && y >= oy && y < oy + dh;
            let px = if inside && tile.rgb.len() == (tw * th * 3) as usize {
                let sx = ((f64::from(x - ox) + 0.5) / s) as u32;
                let sy = ((f64::from(y - oy) + 0.5) / s) as u32;
                let k = 3 * (sy.min(th - 1) * tw + sx.min(tw - 1)) as usize;
                Rgb([tile.rgb[k], tile.rgb[k + 1], tile.rgb[k + 2]])
            } else {
                LETTERBOX
            };
            if x0 + x < img.width() && y0 + y < img.height() {
                img.put_pixel(x0 + x, y0 + y, px);
            }
        }
    }
}

/// Draws white text (x, baseline y, size, text) over the image.
fn draw_text(img: &mut RgbImage, labels: &[(f64, f64, f64, String)]) {
    let (w, h) = (img.width().min(u16::MAX.into()) as u16, img.height().min(u16::MAX.into()) as u16);
    let mut ctx = vello_cpu::RenderContext::new(w, h);
    ctx.set_paint(AlphaColor::from_rgb8(235, 235, 235));
    for (x, y, size, text) in labels {
        let mut path = BezPath::new();
        shape_text(text, *size, Some(&mut path));
        ctx.set_transform(Affine::translate((*x, *y)));
        ctx.fill_path(&path);
    }
    ctx.flush();
    let mut pixmap = vello_cpu::Pixmap::new(w, h);
    ctx.render(&mut pixmap, &mut vello_cpu::Resources::new());
    for (i, p) in pixmap.take_unpremultiplied().into_iter().enumerate() {
        if p.a == 0 {
            continue;
        }
        let (x, y) = (i as u32 % u32::from(w), i as u32 / u32::from(w));
        let a = f32::from(p.a) / 255.0;
        let dst = img.get_pixel_mut(x, y);
        for (d, s) in dst.0.iter_mut().zip([p.r, p.g, p.b]) {
            *d = (f32::from(s) * a + f32::from(*d) * (1.0 - a)).round() as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_settings_line_names_both_learning_rates_and_fits_the_sheet() {
        let mut config = StyleConfig { cycles: 30, resolution: 576, ..StyleConfig::default() };
        config.lr.means_per_extent = 1e-5;
        let line = settings_line(&config, (0, 3000), 1733.0, true, 0.2);
        assert!(line.contains("lr colour 0.01, means 1e-5 x extent, colour floor off;"), "{line}");
        // The weights that differ from the defaults follow, and still fit.
        config.weights.assignment_cosine = 10.0;
        config.weights.assignment = 0.003;
        config.weights.outside = 100000.0;
        let line = settings_line(&config, (0, 3000), 1733.0, true, 0.2);
        assert!(line.contains("colour floor off, λ_out 100000, λ_as 0.003, λ_asc 10;"), "{line}");
        // The geometry options that are off by default, when on.
        config.depth_relief_px = 8;
        config.phase_leak = true;
        config.split_px = 2.0;
        let line = settings_line(&config, (0, 3000), 1733.0, true, 0.2);
        assert!(line.contains("λ_asc 10, depth relief 8 px, split 2 px, phase leak;"), "{line}");
        let width = shape_text(&line, 13.0, None);
        let sheet = f64::from(COLUMNS * TILE + (COLUMNS + 1) * GAP);
        assert!(width + f64::from(GAP) < sheet, "{width} px of {sheet}: {line}");
    }

    #[test]
    fn the_sheet_has_every_tile_and_its_labels() {
        let view = |v: f32| {
            let (w, h) = (40u32, 24u32);
            let mut r = Render::zeros(w, h);
            for (k, a) in r.alpha.iter_mut().enumerate() {
                let x = k as u32 % w;
                *a = if (8..32).contains(&x) { 1.0 } else { 0.0 };
                r.inv_depth[k] = *a * (0.5 + x as f32 / 80.0);
                r.rgb[3 * k..3 * k + 3].copy_from_slice(&[v * *a, 0.5 * *a, 1.0 - v]);
            }
            r
        };
        let style = Tile::from_rgb(8, 8, &[0.6; 8 * 8 * 3]);
        let gray = Tile::from_gray(8, 8, &(0..64).map(|v| v as f32).collect::<Vec<_>>());
        let content = SheetContent {
            title: "guitar × block2".into(),
            settings: "300 steps, 256 px".into(),
            style: [style, Tile::from_gray(8, 8, &[0.0; 64]), gray],
            views: (0..4).map(|i| [view(0.1 * i as f32), view(0.5), view(0.8)]).collect(),
        };
        let img = contact_sheet(&content);
        assert_eq!(img.width(), COLUMNS * TILE + (COLUMNS + 1) * GAP);
        // The square style's row is a square tile high; the 40 × 24 views'
        // rows as high as the views drawn TILE wide, with no letterbox bands.
        let view_h = TILE * 24 / 40;
        assert_eq!(img.height(), 2 * LABEL + GAP + (LABEL + TILE + GAP) + 4 * (LABEL + view_h + GAP) + GAP);
        // The style tile is its colour, the after tile of the last view its render.
        let header = 2 * LABEL + GAP;
        assert_eq!(img.get_pixel(GAP + TILE / 2, header + LABEL + TILE / 2).0, [153, 153, 153]);
        let last = header + (LABEL + TILE + GAP) + 3 * (LABEL + view_h + GAP) + LABEL;
        let after = img.get_pixel(GAP + 2 * (TILE + GAP) + TILE / 2, last + view_h / 2).0;
        assert_eq!(after, [204, 128, 51]);
        // The view's first and last rows are drawn: no letterbox above or below.
        let first_col = GAP + 2 * (TILE + GAP) + TILE / 2;
        assert_ne!(img.get_pixel(first_col, last).0, [48, 48, 54]);
        assert_ne!(img.get_pixel(first_col, last + view_h - 1).0, [48, 48, 54]);
        // Labels are drawn: light pixels in the title line.
        let bright = (0..img.width())
            .flat_map(|x| (0..LABEL).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0[0] > 150);
        assert!(bright.count() > 100, "no title text");
        // Not blank: many distinct colours.
        let mut colours: Vec<[u8; 3]> = img.pixels().map(|p| p.0).collect();
        colours.sort_unstable();
        colours.dedup();
        assert!(colours.len() > 20, "{} colours", colours.len());
    }
}
