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

/// How many times wider than tall, or taller than wide, a style image may
/// be. A run resizes the style to the texture scale's height: a 4000×8
/// strip became 128,000 pixels wide at 256 px, whose VGG activations took
/// more memory than the machine had; an 8×3000 one became 1 pixel wide,
/// with no feature position left to match. The styles shipped are at most
/// 2.1:1 (wave).
pub const MAX_STYLE_ASPECT: usize = 8;

/// The fewest pixels a style may have on a side once resized to the texture
/// scale: VGG's relu3 features, which the losses match, are a quarter of it.
pub const MIN_SCALED_SIDE: usize = 4;

impl StyleImage {
    /// Reads any image the `image` crate decodes (PNG, JPEG, WebP) as RGB.
    pub fn open(path: &Path) -> Result<Self, String> {
        let img = crate::io::open_image(path)
            .map_err(|e| format!("{}: expected an RGB image (PNG, JPEG or WebP), found: {e}", path.display()))?;
        Self::from_rgb(path, img.into_rgb8())
    }

    /// The style of a decoded image read from `path` (named in the message),
    /// refused when it is smaller than 4×4 pixels or longer on one side than
    /// [`MAX_STYLE_ASPECT`] times the other.
    pub fn from_rgb(path: &Path, rgb: image::RgbImage) -> Result<Self, String> {
        let (w, h) = rgb.dimensions();
        if w < 4 || h < 4 {
            return Err(format!("{}: expected an image of at least 4x4 pixels, found {w}x{h}", path.display()));
        }
        let (long, short) = (w.max(h) as usize, w.min(h) as usize);
        if long > MAX_STYLE_ASPECT * short {
            return Err(format!(
                "{}: expected a style image at most {MAX_STYLE_ASPECT} times as long on one side as on the other, \
                 found {w}x{h} ({:.0}:1); crop it nearer to square",
                path.display(),
                long as f64 / short as f64
            ));
        }
        Ok(Self { width: w as usize, height: h as usize, rgb: rgb.into_raw() })
    }

    /// Why the style cannot be used at texture scale `scale` (its height
    /// there, in pixels), if it cannot: a side under [`MIN_SCALED_SIDE`], or
    /// style features that need more memory than the machine has available
    /// (MemAvailable on Linux; not checked elsewhere). A run's peak holds
    /// the three maps' relu3 features (768 floats a position) over two
    /// times over, the session's, the preview measures' and their work
    /// (wave at 1,024 px high: 1.27 GB of features, 3.29 GB peak resident;
    /// at 2,048 px 5.07 GB, and 12.6 GB resident when a run cut at 580 s
    /// ended): the estimate is three times, about 56.7 GiB at 4,096 px.
    pub fn problem_at_scale(&self, scale: u32) -> Option<String> {
        self.problem_at_scale_with(scale, available_memory())
    }

    /// [`StyleImage::problem_at_scale`] with `available` bytes of memory.
    pub fn problem_at_scale_with(&self, scale: u32, available: Option<u64>) -> Option<String> {
        let (h, w) = crate::vision::resize::size_for_height(self.height, self.width, scale as usize);
        if h.min(w) < MIN_SCALED_SIDE {
            return Some(format!(
                "the style ({}x{}) at texture scale {scale} px would be {w}x{h} pixels; expected at least \
                 {MIN_SCALED_SIDE} on each side: raise the texture scale",
                self.width, self.height
            ));
        }
        let need = 3 * (3 * crate::vision::vgg::FEATURE_CHANNELS * 4 * (h / 4) * (w / 4)) as u64;
        let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
        match available {
            Some(have) if need > have => Some(format!(
                "the style at texture scale {scale} px ({w}x{h}) has {} feature positions, whose features a run \
                 holds need about {:.1} GiB, and {:.1} GiB of memory is available: lower the texture scale (256 is \
                 the paper's)",
                (h / 4) * (w / 4),
                gib(need),
                gib(have)
            )),
            _ => None,
        }
    }

    /// The pixels as floats in [0, 1].
    pub fn to_f32(&self) -> Vec<f32> {
        self.rgb.iter().map(|&v| f32::from(v) / 255.0).collect()
    }
}

/// The memory the system can give without swapping (Linux's MemAvailable),
/// or `None` where it cannot be read.
fn available_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strip(w: u32, h: u32) -> Result<StyleImage, String> {
        StyleImage::from_rgb(Path::new("strip.png"), image::RgbImage::new(w, h))
    }

    /// A 4000×8 strip ran out of memory at texture scale 256 (128,000 pixels
    /// wide) and an 8×3000 one panicked with no feature column: both are
    /// refused when read, naming the file; 8:1 either way is taken.
    #[test]
    fn long_narrow_styles_are_refused_when_read() {
        for (w, h) in [(4000, 8), (8, 3000), (2049, 256), (3, 64)] {
            let err = strip(w, h).expect_err("a strip");
            assert!(err.starts_with("strip.png: expected"), "{err}");
            assert!(err.contains(&format!("found {w}x{h}")), "{err}");
        }
        for (w, h) in [(2048, 256), (256, 2048), (4, 4)] {
            assert!(strip(w, h).is_ok(), "{w}x{h}");
        }
    }

    /// At texture scale 16 a 1:8 style is 2 pixels wide, under relu3's
    /// reach; at 256 it is 32.
    #[test]
    fn a_texture_scale_too_small_for_the_style_is_named() {
        let tall = strip(32, 256).expect("8:1");
        let problem = tall.problem_at_scale(16).expect("2 pixels wide");
        assert!(problem.contains("would be 2x16 pixels"), "{problem}");
        assert_eq!(tall.problem_at_scale_with(256, None), None);
        assert_eq!(strip(40, 40).expect("square").problem_at_scale_with(16, None), None);
    }

    /// Wave's shape at 4,096 px high: 2,150 × 1,024 feature positions,
    /// about 56.7 GiB over a run, refused with 32 GiB available and taken
    /// with 64.
    #[test]
    fn a_texture_scale_whose_features_exceed_the_memory_is_named() {
        let wave = strip(4200, 2000).expect("wave's shape");
        let problem = wave.problem_at_scale_with(4096, Some(32 << 30)).expect("too large");
        assert!(problem.contains("(8601x4096) has 2201600 feature positions"), "{problem}");
        assert!(problem.contains("need about 56.7 GiB, and 32.0 GiB of memory is available"), "{problem}");
        assert_eq!(wave.problem_at_scale_with(4096, Some(64 << 30)), None);
        assert_eq!(wave.problem_at_scale_with(256, Some(1 << 30)), None);
    }
}
