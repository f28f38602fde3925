//! The style image as a run holds it: 8-bit RGB, read from any file the
//! `image` crate decodes. Its own file because the run's preparation and the
//! Stage-1 cache both take it.

use std::path::Path;

/// An 8-bit RGB image (the style), row-major HWC.
#[derive(Clone, Debug, PartialEq)]
pub struct StyleImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width · height · 3` bytes.
    pub rgb: Vec<u8>,
}

impl StyleImage {
    /// Reads any image the `image` crate decodes (PNG, JPEG, WebP) as RGB.
    pub fn open(path: &Path) -> Result<Self, String> {
        let img = image::open(path)
            .map_err(|e| format!("{}: expected an RGB image (PNG, JPEG or WebP), found: {e}", path.display()))?;
        let rgb = img.to_rgb8();
        let (w, h) = rgb.dimensions();
        if w < 4 || h < 4 {
            return Err(format!("{}: expected an image of at least 4x4 pixels, found {w}x{h}", path.display()));
        }
        Ok(Self { width: w as usize, height: h as usize, rgb: rgb.into_raw() })
    }

    /// The pixels as floats in [0, 1].
    pub fn to_f32(&self) -> Vec<f32> {
        self.rgb.iter().map(|&v| f32::from(v) / 255.0).collect()
    }
}
