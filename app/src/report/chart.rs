//! Line and scatter charts as SVG and PNG, for benchmark reports ("quality
//! against wall time", "quality against iterations").
//!
//! A chart is laid out once into a short list of drawing items (rectangles,
//! polylines, markers, text) that two small back ends turn into SVG text and
//! into pixels, so both files show the same picture. The PNG is drawn by
//! `vello_cpu`, with text from the font in `glyphs` (the machines that run
//! benchmarks have no system fonts); tick values come from `axis`.

use std::f64::consts::FRAC_PI_2;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use vello_cpu::color::{AlphaColor, Srgb};
use vello_cpu::kurbo::{Affine, BezPath, Cap, Circle, Join, Rect, Shape as _, Stroke};

use super::axis::{Scale, fit_ticks};
use super::glyphs::{shape_text, text_width};

/// One data series: points in data units, drawn as markers and optionally joined.
#[derive(Clone, Debug)]
pub struct Series {
    /// Name shown in the legend.
    pub name: String,
    /// `(x, y)` points; non-finite ones, and non-positive ones on a log axis, are skipped.
    pub points: Vec<(f64, f64)>,
    /// sRGB colour of the markers and the line.
    pub color: [u8; 3],
    /// Join the points with a line in the given order; a skipped point breaks the line.
    pub line: bool,
    /// Draw the line dashed.
    pub dashed: bool,
    /// Draw a marker at each point (and in the legend's swatch); off for a
    /// reference line, whose end points are not data.
    pub markers: bool,
}

/// A chart with axes, light grid lines, its series and a legend.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title at the top.
    pub title: String,
    /// Horizontal axis label with its unit, e.g. "wall time (s)".
    pub x_label: String,
    /// Vertical axis label with its unit.
    pub y_label: String,
    /// Logarithmic horizontal axis.
    pub x_log: bool,
    /// Logarithmic vertical axis.
    pub y_log: bool,
    /// The data, drawn in order (later series on top).
    pub series: Vec<Series>,
    /// Width in pixels (user units in the SVG).
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// A small line under the title, e.g. "lower is better".
    pub note: Option<String>,
}

impl Default for Chart {
    fn default() -> Self {
        Self {
            title: String::new(),
            x_label: String::new(),
            y_label: String::new(),
            x_log: false,
            y_log: false,
            series: Vec::new(),
            width: 800,
            height: 500,
            note: None,
        }
    }
}

/// Matplotlib's "tab10" colours, distinct on white and for most colour-blind readers.
const TAB10: [u32; 10] =
    [0x1f77b4, 0xff7f0e, 0x2ca02c, 0xd62728, 0x9467bd, 0x8c564b, 0xe377c2, 0x7f7f7f, 0xbcbd22, 0x17becf];

/// The `i`-th of ten distinct series colours; they repeat after ten.
pub fn palette(i: usize) -> [u8; 3] {
    let [_, r, g, b] = TAB10[i % TAB10.len()].to_be_bytes();
    [r, g, b]
}

impl Chart {
    /// The chart as a standalone SVG document.
    pub fn to_svg(&self) -> String {
        let (w, h) = self.size();
        let mut s = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" \
             font-family=\"sans-serif\">\n"
        );
        for item in layout(self) {
            svg_item(&mut s, &item);
        }
        s.push_str("</svg>\n");
        s
    }

    /// The chart as an opaque RGBA image of `width × height` pixels.
    pub fn to_rgba(&self) -> image::RgbaImage {
        let (w, h) = self.size();
        let mut ctx = vello_cpu::RenderContext::new(w, h);
        for item in layout(self) {
            paint_item(&mut ctx, &item);
        }
        ctx.flush();
        let mut pixmap = vello_cpu::Pixmap::new(w, h);
        ctx.render(&mut pixmap, &mut vello_cpu::Resources::new());
        let bytes = pixmap.take_unpremultiplied().into_iter().flat_map(|p| [p.r, p.g, p.b, p.a]).collect();
        image::RgbaImage::from_raw(w.into(), h.into(), bytes)
            .unwrap_or_else(|| image::RgbaImage::new(w.into(), h.into()))
    }

    /// Writes `<stem>.svg` and `<stem>.png`, each atomically (a temporary file, then a rename).
    pub fn write(&self, stem: &Path) -> anyhow::Result<()> {
        let with_ext = |ext: &str| {
            let mut name = stem.as_os_str().to_owned();
            name.push(ext);
            PathBuf::from(name)
        };
        let svg_path = with_ext(".svg");
        let svg = self.to_svg();
        gast_core::io::write_bytes(&svg_path, svg.as_bytes())
            .with_context(|| format!("writing the chart {}", svg_path.display()))?;
        let png_path = with_ext(".png");
        let rgb = image::DynamicImage::ImageRgba8(self.to_rgba()).to_rgb8();
        gast_core::io::write_png_rgb8(&png_path, rgb.width(), rgb.height(), rgb.as_raw())
            .with_context(|| format!("writing the chart {}", png_path.display()))?;
        Ok(())
    }

    /// The drawn size: at least one pixel, at most what the rasterizer takes.
    fn size(&self) -> (u16, u16) {
        let clamp = |v: u32| v.clamp(1, u16::MAX.into()) as u16;
        (clamp(self.width), clamp(self.height))
    }
}

// ---------------------------------------------------------------------------
// Layout

/// Which point of a text line its position names.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Anchor {
    Start,
    Middle,
    End,
}

/// One line of text; `(x, y)` is on its baseline. Vertical text reads bottom to top.
#[derive(Clone, Debug)]
struct Text {
    x: f64,
    y: f64,
    text: String,
    size: f64,
    color: [u8; 3],
    anchor: Anchor,
    vertical: bool,
    bold: bool,
}

/// What the back ends draw, in pixels with y down.
#[derive(Clone, Debug)]
enum Item {
    Rect { rect: Rect, fill: Option<[u8; 3]>, stroke: Option<[u8; 3]> },
    Line { points: Vec<(f64, f64)>, color: [u8; 3], width: f64, dashed: bool },
    Dot { x: f64, y: f64, r: f64, color: [u8; 3] },
    Text(Text),
}

const TITLE: f64 = 17.0;
const NOTE: f64 = 12.0;
const TICK: f64 = 11.5;
const AXIS: f64 = 13.0;
const LEGEND: f64 = 12.0;
const PAD: f64 = 14.0;
const SWATCH: f64 = 26.0;
const ROW: f64 = 20.0;
/// Room for text in a wider font than the one measured: an SVG viewer's sans-serif.
const SLACK: f64 = 1.12;
const WHITE: [u8; 3] = [255, 255, 255];
const INK: [u8; 3] = [30, 30, 30];
const SOFT: [u8; 3] = [95, 95, 95];
const GRID: [u8; 3] = [225, 225, 225];
const MINOR_GRID: [u8; 3] = [244, 244, 244];
const FRAME: [u8; 3] = [150, 150, 150];

/// Text at `(x, y)` in the regular weight.
fn text(x: f64, y: f64, t: &str, size: f64, color: [u8; 3], anchor: Anchor) -> Item {
    Item::Text(text_of(x, y, t, size, color, anchor))
}

/// Lays the chart out: margins sized to the title, tick labels and legend,
/// the plot area, then the series and the legend.
fn layout(c: &Chart) -> Vec<Item> {
    let (w, h) = c.size();
    let (w, h) = (f64::from(w), f64::from(h));
    let mut items = vec![Item::Rect { rect: Rect::new(0.0, 0.0, w, h), fill: Some(WHITE), stroke: None }];

    let mut top = PAD;
    if !c.title.is_empty() {
        top += TITLE;
        items.push(Item::Text(Text { bold: true, ..text_of(w / 2.0, top, &c.title, TITLE, INK, Anchor::Middle) }));
        top += 6.0;
    }
    if let Some(note) = c.note.as_deref().filter(|n| !n.is_empty()) {
        top += NOTE;
        items.push(text(w / 2.0, top, note, NOTE, SOFT, Anchor::Middle));
    }
    top = (top + 12.0).round();

    // The accepted points of each series; `None` breaks a line.
    let points: Vec<Vec<Option<(f64, f64)>>> = c
        .series
        .iter()
        .map(|s| {
            let ok = |&(x, y): &(f64, f64)| Scale::accepts(c.x_log, x) && Scale::accepts(c.y_log, y);
            s.points.iter().map(|p| ok(p).then_some(*p)).collect()
        })
        .collect();
    let all: Vec<(f64, f64)> = points.iter().flatten().flatten().copied().collect();
    let xs: Vec<f64> = all.iter().map(|p| p.0).collect();
    let ys: Vec<f64> = all.iter().map(|p| p.1).collect();
    let (sx, sy) = (Scale::fit(&xs, c.x_log), Scale::fit(&ys, c.y_log));

    // The legend goes right of the plot when it is narrow, else in rows below.
    let entries: Vec<f64> = c.series.iter().map(|s| SWATCH + 6.0 + SLACK * text_width(&s.name, LEGEND)).collect();
    let widest = entries.iter().copied().fold(0.0, f64::max);
    let legend_w = widest + 2.0 * 10.0;
    let legend_right = !entries.is_empty() && legend_w + 16.0 <= 0.3 * w;
    let mut rows: Vec<Vec<usize>> = Vec::new();
    if !legend_right {
        let mut used = f64::INFINITY;
        for (i, e) in entries.iter().enumerate() {
            if used + e > w - 2.0 * PAD {
                rows.push(Vec::new());
                used = 0.0;
            }
            used += e + 18.0;
            if let Some(row) = rows.last_mut() {
                row.push(i);
            }
        }
    }

    let right = if legend_right { PAD + legend_w + 16.0 } else { PAD + 10.0 };
    let below = 6.0 + TICK + 10.0 + AXIS;
    let y1 = (h - PAD - 0.3 * AXIS - below - rows.len() as f64 * ROW).round().max(top + 1.0);
    let y_ticks = fit_ticks(&sy, y1 - top, ((y1 - top) / 45.0) as usize, |_| TICK);
    let y_label_w = y_ticks.iter().map(|t| SLACK * text_width(&t.1, TICK)).fold(0.0, f64::max);
    let x0 = (PAD + AXIS + 10.0 + y_label_w + 8.0).round();
    let x1 = (w - right).round().max(x0 + 1.0);
    let x_ticks = fit_ticks(&sx, x1 - x0, ((x1 - x0) / 80.0) as usize, |s| text_width(s, TICK));
    let (pw, ph) = (x1 - x0, y1 - top);
    let px = |v: f64| x0 + sx.frac(v) * pw;
    let py = |v: f64| y1 - sy.frac(v) * ph;
    let crisp = |v: f64| v.floor() + 0.5;

    // Grid, frame, ticks and their labels.
    let vline =
        |x: f64, color, a: f64, b: f64| Item::Line { points: vec![(x, a), (x, b)], color, width: 1.0, dashed: false };
    let hline =
        |y: f64, color, a: f64, b: f64| Item::Line { points: vec![(a, y), (b, y)], color, width: 1.0, dashed: false };
    for v in sx.minor(&x_ticks) {
        items.push(vline(crisp(px(v)), MINOR_GRID, top, y1));
    }
    for v in sy.minor(&y_ticks) {
        items.push(hline(crisp(py(v)), MINOR_GRID, x0, x1));
    }
    for (v, label) in &x_ticks {
        let x = crisp(px(*v));
        items.push(vline(x, GRID, top, y1));
        items.push(vline(x, FRAME, y1, y1 + 5.0));
        items.push(text(x, y1 + 6.0 + TICK, label, TICK, INK, Anchor::Middle));
    }
    for (v, label) in &y_ticks {
        let y = crisp(py(*v));
        items.push(hline(y, GRID, x0, x1));
        items.push(hline(y, FRAME, x0 - 5.0, x0));
        items.push(text(x0 - 8.0, y + 0.35 * TICK, label, TICK, INK, Anchor::End));
    }
    items.push(Item::Rect {
        rect: Rect::new(x0 + 0.5, top + 0.5, x1 - 0.5, y1 - 0.5),
        fill: None,
        stroke: Some(FRAME),
    });
    items.push(text((x0 + x1) / 2.0, y1 + below, &c.x_label, AXIS, INK, Anchor::Middle));
    let y_label = text_of(PAD + 0.8 * AXIS, (top + y1) / 2.0, &c.y_label, AXIS, INK, Anchor::Middle);
    items.push(Item::Text(Text { vertical: true, ..y_label }));

    // The series: lines under their markers; markers shrink when there are many.
    for (s, pts) in c.series.iter().zip(&points) {
        if s.line {
            for run in pts.split(Option::is_none).filter(|r| r.len() >= 2) {
                let line = run.iter().flatten().map(|&(x, y)| (px(x), py(y))).collect();
                items.push(Item::Line { points: line, color: s.color, width: 2.0, dashed: s.dashed });
            }
        }
        let n = pts.iter().flatten().count();
        let r = if n > 200 {
            1.8
        } else if n > 50 {
            2.5
        } else {
            3.5
        };
        if s.markers {
            items.extend(pts.iter().flatten().map(|&(x, y)| Item::Dot { x: px(x), y: py(y), r, color: s.color }));
        }
    }
    if all.is_empty() {
        items.push(text((x0 + x1) / 2.0, (top + y1) / 2.0 + 5.0, "no data", 14.0, SOFT, Anchor::Middle));
    }

    // The legend: a swatch (line and marker) and the name of every series.
    let legend_x = x1 + 16.0;
    if legend_right {
        let bottom = top + c.series.len() as f64 * ROW + 16.0;
        let rect = Rect::new(legend_x + 0.5, top + 0.5, legend_x + legend_w - 0.5, bottom - 0.5);
        items.push(Item::Rect { rect, fill: Some(WHITE), stroke: Some(GRID) });
    }
    let mut entry = |s: &Series, x: f64, cy: f64| {
        if s.line {
            let line = vec![(x, cy), (x + SWATCH, cy)];
            items.push(Item::Line { points: line, color: s.color, width: 2.0, dashed: s.dashed });
        }
        if s.markers {
            items.push(Item::Dot { x: x + SWATCH / 2.0, y: cy, r: 3.5, color: s.color });
        }
        items.push(text(x + SWATCH + 6.0, cy + 0.35 * LEGEND, &s.name, LEGEND, INK, Anchor::Start));
    };
    if legend_right {
        for (i, s) in c.series.iter().enumerate() {
            entry(s, legend_x + 10.0, top + 8.0 + ROW * (i as f64 + 0.5));
        }
    } else {
        for (r, row) in rows.iter().enumerate() {
            // From the chart's left margin: the rows were wrapped to `w − 2·PAD`.
            let mut x = PAD;
            for &i in row {
                entry(&c.series[i], x, y1 + below + 0.3 * AXIS + ROW * (r as f64 + 0.5) + 4.0);
                x += entries[i] + 18.0;
            }
        }
    }
    items
}

/// A text item, to be adjusted with struct-update syntax.
fn text_of(x: f64, y: f64, t: &str, size: f64, color: [u8; 3], anchor: Anchor) -> Text {
    Text { x, y, text: t.into(), size, color, anchor, vertical: false, bold: false }
}

// ---------------------------------------------------------------------------
// Back ends

/// `#rrggbb`.
fn hex([r, g, b]: [u8; 3]) -> String {
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// `text` with the XML special characters escaped.
fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Appends one item as SVG.
fn svg_item(s: &mut String, item: &Item) {
    // Writing to a String cannot fail.
    let _ = match item {
        Item::Rect { rect, fill, stroke } => writeln!(
            s,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\" stroke=\"{}\"/>",
            rect.x0,
            rect.y0,
            rect.width(),
            rect.height(),
            fill.map_or("none".into(), hex),
            stroke.map_or("none".into(), hex),
        ),
        Item::Line { points, color, width, dashed } => {
            let pts: Vec<String> = points.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
            let dash = if *dashed { " stroke-dasharray=\"6 4\"" } else { "" };
            writeln!(
                s,
                "<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"{width}\" \
                 stroke-linejoin=\"round\"{dash}/>",
                pts.join(" "),
                hex(*color),
            )
        }
        Item::Dot { x, y, r, color } => writeln!(
            s,
            "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"{r}\" fill=\"{}\" stroke=\"#ffffff\" stroke-width=\"0.8\"/>",
            hex(*color)
        ),
        Item::Text(t) => {
            let anchor = match t.anchor {
                Anchor::Start => "start",
                Anchor::Middle => "middle",
                Anchor::End => "end",
            };
            let weight = if t.bold { " font-weight=\"bold\"" } else { "" };
            let rotate =
                if t.vertical { format!(" transform=\"rotate(-90 {:.1} {:.1})\"", t.x, t.y) } else { String::new() };
            writeln!(
                s,
                "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"{}\" fill=\"{}\" text-anchor=\"{anchor}\"{weight}{rotate}>{}</text>",
                t.x,
                t.y,
                t.size,
                hex(t.color),
                xml_escape(&t.text)
            )
        }
    };
}

/// An opaque paint colour.
fn paint_color([r, g, b]: [u8; 3]) -> AlphaColor<Srgb> {
    AlphaColor::from_rgb8(r, g, b)
}

/// Draws one item into the render context.
fn paint_item(ctx: &mut vello_cpu::RenderContext, item: &Item) {
    match item {
        Item::Rect { rect, fill, stroke } => {
            if let Some(c) = fill {
                ctx.set_paint(paint_color(*c));
                ctx.fill_rect(rect);
            }
            if let Some(c) = stroke {
                ctx.set_paint(paint_color(*c));
                ctx.set_stroke(Stroke::new(1.0));
                ctx.stroke_rect(rect);
            }
        }
        Item::Line { points, color, width, dashed } => {
            let mut path = BezPath::new();
            for (i, &p) in points.iter().enumerate() {
                if i == 0 { path.move_to(p) } else { path.line_to(p) }
            }
            let stroke = Stroke::new(*width).with_join(Join::Round);
            let stroke = if *dashed { stroke.with_dashes(0.0, [6.0, 4.0]) } else { stroke.with_caps(Cap::Round) };
            ctx.set_stroke(stroke);
            ctx.set_paint(paint_color(*color));
            ctx.stroke_path(&path);
        }
        Item::Dot { x, y, r, color } => {
            let circle = Circle::new((*x, *y), *r).to_path(0.05);
            ctx.set_paint(paint_color(*color));
            ctx.fill_path(&circle);
            ctx.set_paint(paint_color(WHITE));
            ctx.set_stroke(Stroke::new(0.8));
            ctx.stroke_path(&circle);
        }
        Item::Text(t) => {
            let mut path = BezPath::new();
            let width = shape_text(&t.text, t.size, Some(&mut path));
            let dx = match t.anchor {
                Anchor::Start => 0.0,
                Anchor::Middle => -width / 2.0,
                Anchor::End => -width,
            };
            let rotate = if t.vertical { Affine::rotate(-FRAC_PI_2) } else { Affine::IDENTITY };
            ctx.set_transform(Affine::translate((t.x, t.y)) * rotate * Affine::translate((dx, 0.0)));
            ctx.set_paint(paint_color(t.color));
            ctx.fill_path(&path);
            // The font is a light weight: a thin outline makes small text read as regular, the title as bold.
            ctx.set_stroke(Stroke::new(if t.bold { 0.8 } else { 0.3 }).with_join(Join::Round));
            ctx.stroke_path(&path);
            ctx.reset_transform();
        }
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    /// Two series against iterations and one against wall time on a log axis.
    fn sample() -> Chart {
        let iters: Vec<f64> = (0..40).map(|i| f64::from(i) * 25.0).collect();
        let series = |name: &str, i: usize, scale: f64, dashed: bool| Series {
            name: name.into(),
            points: iters.iter().map(|&t| (t, 0.05 + scale / (1.0 + t / 80.0))).collect(),
            color: palette(i),
            line: true,
            dashed,
            markers: true,
        };
        Chart {
            title: "Quality against iterations".into(),
            note: Some("style loss, lower is better".into()),
            x_label: "iteration".into(),
            y_label: "style loss".into(),
            series: vec![series("GAST (ours)", 0, 1.0, false), series("baseline & <ref>", 1, 1.6, true)],
            ..Chart::default()
        }
    }

    fn timed() -> Chart {
        let points = |a: f64, b: f64| (0..12).map(|i| (a * 1.8f64.powi(i), b / (1.0 + f64::from(i)))).collect();
        Chart {
            title: "Quality against wall time".into(),
            x_label: "wall time (s)".into(),
            y_label: "LPIPS".into(),
            x_log: true,
            series: vec![
                Series {
                    name: "GPU".into(),
                    points: points(0.2, 0.6),
                    color: palette(0),
                    line: true,
                    dashed: false,
                    markers: true,
                },
                Series {
                    name: "CPU".into(),
                    points: points(3.0, 0.7),
                    color: palette(1),
                    line: true,
                    dashed: false,
                    markers: true,
                },
                Series {
                    name: "reference".into(),
                    points: vec![(40.0, 0.1)],
                    color: palette(2),
                    line: false,
                    dashed: false,
                    markers: true,
                },
            ],
            ..Chart::default()
        }
    }

    #[test]
    fn svg_is_well_formed_and_complete() {
        let chart = sample();
        let svg = chart.to_svg();
        assert!(svg.starts_with("<svg ") && svg.trim_end().ends_with("</svg>"));
        assert_eq!(svg.matches('<').count(), svg.matches('>').count());
        let opened = svg.matches('<').count() - svg.matches("</").count() - svg.matches("/>").count();
        assert_eq!(opened, svg.matches("</").count(), "every open tag is closed");
        assert!(svg.contains("GAST (ours)"));
        assert!(svg.contains("baseline &amp; &lt;ref&gt;"), "names are escaped");
        assert!(!svg.contains("& <"));
        for needle in ["iteration", "style loss", "Quality against iterations", "lower is better", "sans-serif"] {
            assert!(svg.contains(needle), "{needle} missing");
        }
        assert!(svg.contains("stroke-dasharray"));
        assert!(svg.contains(&hex(palette(1))));
    }

    #[test]
    fn png_has_text_and_series_colours() {
        let chart = Chart { width: 640, height: 400, ..timed() };
        let img = chart.to_rgba();
        assert_eq!(img.dimensions(), (640, 400));
        let first = *img.get_pixel(0, 0);
        assert!(img.pixels().any(|p| *p != first), "image is uniform");
        let dark = |x: u32, y: u32| img.get_pixel(x, y).0[..3].iter().all(|&c| c < 100);
        let title_dark = (0..40).flat_map(|y| (160..480).map(move |x| (x, y))).filter(|&(x, y)| dark(x, y)).count();
        assert!(title_dark > 100, "title should have dark glyph pixels, found {title_dark}");
        let near = |p: &image::Rgba<u8>, c: [u8; 3]| p.0.iter().zip(c).all(|(&a, b)| a.abs_diff(b) < 12);
        for s in &chart.series {
            let hits = img.pixels().filter(|p| near(p, s.color)).count();
            assert!(hits > 20, "{} colour found on {hits} pixels", s.name);
        }
    }

    #[test]
    fn empty_and_bad_data_do_not_panic() {
        let empty = Chart { title: "nothing".into(), ..Chart::default() };
        assert!(empty.to_svg().contains("no data"));
        assert_eq!(empty.to_rgba().dimensions(), (800, 500));
        let bad = Chart {
            x_log: true,
            y_log: true,
            series: vec![
                Series {
                    name: "bad".into(),
                    points: vec![(f64::NAN, 1.0), (1.0, f64::INFINITY), (-1.0, 2.0), (0.0, 0.0)],
                    color: palette(3),
                    line: true,
                    dashed: true,
                    markers: true,
                },
                Series {
                    name: "empty".into(),
                    points: vec![],
                    color: palette(4),
                    line: true,
                    dashed: false,
                    markers: true,
                },
            ],
            ..Chart::default()
        };
        let svg = bad.to_svg();
        assert!(svg.contains("no data") && svg.contains("bad") && svg.contains("empty"));
        bad.to_rgba();
        let single = Chart {
            series: vec![Series {
                name: "one".into(),
                points: vec![(2.0, 2.0), (f64::NAN, 3.0)],
                ..bad.series[0].clone()
            }],
            ..bad
        };
        assert!(!single.to_svg().contains("no data"));
        single.to_rgba();
        let tiny = Chart { width: 0, height: 3, ..sample() };
        assert_eq!(tiny.to_rgba().dimensions(), (1, 3));
        let huge = Chart {
            series: vec![Series { points: vec![(0.0, 1e300), (1.0, -1e300)], ..sample().series[0].clone() }],
            ..sample()
        };
        huge.to_svg();
    }

    #[test]
    fn write_makes_both_files() {
        let dir = std::env::temp_dir().join(format!("gast-chart-{}", std::process::id()));
        let stem = dir.join("quality.v1");
        sample().write(&stem).expect("write chart");
        let png = image::open(dir.join("quality.v1.png")).expect("decode png");
        assert_eq!((png.width(), png.height()), (800, 500));
        let svg = std::fs::read_to_string(dir.join("quality.v1.svg")).expect("read svg");
        assert!(svg.contains("</svg>"));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A legend in rows below the plot stays inside the chart: the defaults
    /// study's margin chart, with "guitar stone (colours collapsed)" among
    /// nine entries, once cut its last column at the right edge.
    #[test]
    fn a_legend_below_the_plot_stays_inside_the_chart() {
        let names = ["guitar block2", "guitar fire", "guitar galaxy", "guitar hydrangea", "guitar mosaic"]
            .into_iter()
            .chain(["guitar particle", "guitar starry", "guitar stone (colours collapsed)", "guitar wave"]);
        let series: Vec<Series> = names
            .enumerate()
            .map(|(i, name)| Series {
                name: name.into(),
                points: vec![(i as f64, 1.0 + i as f64)],
                color: palette(i),
                line: false,
                dashed: false,
                markers: true,
            })
            .collect();
        let chart = Chart { series, ..sample() };
        let (w, _) = chart.size();
        let mut legend = 0;
        for item in layout(&chart) {
            if let Item::Text(t) = item
                && t.text.starts_with("guitar ")
            {
                legend += 1;
                let end = t.x + SLACK * text_width(&t.text, t.size);
                assert!(t.x >= 0.0 && end <= f64::from(w), "{:?} ends at {end:.0} of {w}", t.text);
            }
        }
        assert_eq!(legend, 9);
    }

    #[test]
    fn a_series_without_markers_draws_its_line_and_no_dot() {
        let floor = Series {
            name: "one seed floor".into(),
            points: vec![(0.0, 1.0), (5.0, 1.0)],
            color: [90, 90, 90],
            line: true,
            dashed: true,
            markers: false,
        };
        let chart = Chart { series: vec![floor.clone()], ..sample() };
        let items = layout(&chart);
        assert!(!items.iter().any(|i| matches!(i, Item::Dot { .. })), "no dot, in the plot or the legend");
        assert_eq!(
            items.iter().filter(|i| matches!(i, Item::Line { dashed: true, .. })).count(),
            2,
            "the line and its swatch"
        );
        let with = Chart { series: vec![Series { markers: true, ..floor }], ..sample() };
        assert_eq!(
            layout(&with).iter().filter(|i| matches!(i, Item::Dot { .. })).count(),
            3,
            "two points and the swatch"
        );
    }

    /// Writes sample charts to look at: `cargo test -p gast chart -- --ignored`.
    #[test]
    #[ignore = "writes /tmp/chart_sample*.{png,svg} for a person to look at"]
    fn write_samples() {
        timed().write(Path::new("/tmp/chart_sample")).expect("write sample");
        sample().write(Path::new("/tmp/chart_sample_iter")).expect("write sample");
        let wide_legend = Chart {
            series: (0..5u8)
                .map(|i| {
                    let scale = 1.0 + 0.3 * f64::from(i);
                    let points = sample().series[0].points.iter().map(|&(x, y)| (x, y * scale)).collect();
                    let name = format!("a rather long configuration name {i}");
                    Series { name, points, color: palette(i as usize), ..sample().series[0].clone() }
                })
                .collect(),
            y_log: true,
            width: 560,
            height: 380,
            ..sample()
        };
        wide_legend.write(Path::new("/tmp/chart_sample_wide")).expect("write sample");
        Chart { title: "Empty".into(), x_label: "x".into(), y_label: "y".into(), ..Chart::default() }
            .write(Path::new("/tmp/chart_sample_empty"))
            .expect("write sample");
    }
}
