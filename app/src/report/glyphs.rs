//! Text for the chart PNG: advances and glyph outlines from the Ubuntu font
//! that egui embeds, so charts need no system font. The SVG layout uses the
//! same advances to size its margins.

use skrifa::instance::{LocationRef, Size};
use skrifa::{FontRef, GlyphId, MetadataProvider as _};
use vello_cpu::kurbo::BezPath;

/// The embedded font used for metrics and glyphs; `None` only if it cannot be parsed.
fn font() -> Option<FontRef<'static>> {
    FontRef::new(epaint_default_fonts::UBUNTU_LIGHT).ok()
}

/// Lays `text` out at `size` pixels (no kerning) and returns its advance; the
/// glyph outlines go into `path` with the origin at the start of the baseline.
pub(super) fn shape_text(text: &str, size: f64, mut path: Option<&mut BezPath>) -> f64 {
    let Some(font) = font() else {
        return 0.55 * size * text.chars().count() as f64;
    };
    let px = Size::new(size as f32);
    let (charmap, outlines) = (font.charmap(), font.outline_glyphs());
    let metrics = font.glyph_metrics(px, LocationRef::default());
    let mut x = 0.0;
    for ch in text.chars() {
        let glyph = charmap.map(ch).unwrap_or(GlyphId::NOTDEF);
        if let (Some(path), Some(outline)) = (path.as_deref_mut(), outlines.get(glyph)) {
            // A glyph that fails to draw is left out; the rest of the text still reads.
            let _ = outline.draw(px, &mut Pen { path, x });
        }
        x += f64::from(metrics.advance_width(glyph).unwrap_or(0.0));
    }
    x
}

/// The advance of `text` at `size` pixels.
pub(super) fn text_width(text: &str, size: f64) -> f64 {
    shape_text(text, size, None)
}

/// Collects a glyph outline (y up) into a path (y down), shifted right by `x`.
struct Pen<'a> {
    path: &'a mut BezPath,
    x: f64,
}

impl skrifa::outline::OutlinePen for Pen<'_> {
    fn move_to(&mut self, x: f32, y: f32) {
        self.path.move_to((self.x + f64::from(x), -f64::from(y)));
    }
    fn line_to(&mut self, x: f32, y: f32) {
        self.path.line_to((self.x + f64::from(x), -f64::from(y)));
    }
    fn quad_to(&mut self, cx: f32, cy: f32, x: f32, y: f32) {
        let c = (self.x + f64::from(cx), -f64::from(cy));
        self.path.quad_to(c, (self.x + f64::from(x), -f64::from(y)));
    }
    fn curve_to(&mut self, cx0: f32, cy0: f32, cx1: f32, cy1: f32, x: f32, y: f32) {
        let c0 = (self.x + f64::from(cx0), -f64::from(cy0));
        let c1 = (self.x + f64::from(cx1), -f64::from(cy1));
        self.path.curve_to(c0, c1, (self.x + f64::from(x), -f64::from(y)));
    }
    fn close(&mut self) {
        self.path.close_path();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_font_measures_and_draws() {
        assert!(font().is_some(), "the embedded font parses");
        let mut path = BezPath::new();
        let width = shape_text("Wall time (s)", 12.0, Some(&mut path));
        assert!((50.0..100.0).contains(&width), "advance {width}");
        assert!(path.elements().len() > 50, "outlines drawn");
        assert!(text_width("iii", 12.0) < text_width("WWW", 12.0));
    }
}
