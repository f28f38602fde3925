//! Depth of the style image, the geometry cue GCFM matches rendered depth against.
//!
//! The reference runs Depth Anything V2-L (a 335 M-parameter network) on the
//! style image. The studio runs the same network family ([`super::depth`],
//! the Small model by default, fetched once), and depth comes from a
//! [`StyleDepthProvider`] chosen by [`DepthProvider`]: that network, a depth
//! image the user supplies (made with any estimator they like: PNG 8/16-bit
//! grey or EXR), or a built-in heuristic that needs no weights. Either way the result is resized to the style image,
//! min-max normalised to [0, 1] and oriented by [`DepthPolarity`].

use std::path::Path;

use super::resize::resize_bilinear;

/// Failures while reading a user depth image.
#[derive(Debug, thiserror::Error)]
pub enum StyleDepthError {
    /// The PNG (or other raster image) could not be read.
    #[error("{path}: expected a depth image (PNG 8- or 16-bit grey, or EXR), found: {message}")]
    Image {
        /// The file.
        path: String,
        /// What the decoder said.
        message: String,
    },
    /// The EXR file could not be read.
    #[error("{path}: expected an EXR depth image, found: {source}")]
    Exr {
        /// The file.
        path: String,
        /// What the decoder said.
        source: exr::error::Error,
    },
    /// The file holds no usable channel.
    #[error("{path}: expected a depth image with at least one channel and a pixel, found {found}")]
    Empty {
        /// The file.
        path: String,
        /// What was found instead.
        found: String,
    },
}

/// Orientation of the normalised style depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum DepthPolarity {
    /// Near is bright (1), like the rendered inverse depth. The studio's default:
    /// both sides of the matching use the same polarity.
    #[default]
    NearBright,
    /// Near is dark (0): the reference's `1 − d` on the style side, kept to
    /// compare with it (ALGORITHM.md, "Depth polarity").
    NearDark,
}

/// Where the style's depth comes from (the config's `depth_provider`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthProvider {
    /// Depth Anything V2 ([`super::depth`]), found or downloaded once; the
    /// heuristic, with a warning, when it cannot be had.
    #[default]
    Learned,
    /// A depth image the user supplies for the style; the heuristic, with a
    /// warning, when none is given.
    Image,
    /// The built-in [`HeuristicDepth`], which needs no weights.
    Heuristic,
}

impl DepthProvider {
    /// All choices, in the order the studio lists them.
    pub const ALL: [DepthProvider; 3] = [DepthProvider::Learned, DepthProvider::Image, DepthProvider::Heuristic];

    /// The name used in presets and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DepthProvider::Learned => "learned",
            DepthProvider::Image => "image",
            DepthProvider::Heuristic => "heuristic",
        }
    }

    /// Parses [`DepthProvider::name`].
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("expected learned, image or heuristic, found {s:?}"))
    }
}

/// Something that estimates a depth map for an RGB image.
pub trait StyleDepthProvider {
    /// Depth of the `h × w` RGB image (HWC, values in [0, 1]) as an `h × w`
    /// map, any range, **near = larger**. Callers normalise with
    /// [`style_depth_map`].
    fn estimate(&self, rgb: &[f32], h: usize, w: usize) -> Vec<f32>;
}

/// Min-max normalisation as the reference does it: `(d − min)/(max − min + 1e-8)`.
pub fn min_max_normalise(d: &[f32]) -> Vec<f32> {
    let (lo, hi) = d.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let r = hi - lo + 1e-8;
    d.iter().map(|&v| (v - lo) / r).collect()
}

/// The style depth the loss uses: the provider's estimate, min-max normalised
/// to [0, 1], then oriented by `polarity`.
pub fn style_depth_map(
    provider: &dyn StyleDepthProvider,
    rgb: &[f32],
    h: usize,
    w: usize,
    polarity: DepthPolarity,
) -> Vec<f32> {
    let mut d = min_max_normalise(&provider.estimate(rgb, h, w));
    if polarity == DepthPolarity::NearDark {
        d.iter_mut().for_each(|v| *v = 1.0 - *v);
    }
    d
}

/// A depth image supplied by the user, resized (bilinear, as the reference
/// resizes its estimate) to whatever style image it is asked about.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    /// Values, `height × width`, row-major, as read (8-bit and 16-bit PNGs
    /// scaled to [0, 1]).
    pub values: Vec<f32>,
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// Whether larger values mean nearer (inverse depth or disparity, what
    /// monocular estimators usually write). Set to `false` for metric depth or
    /// z-buffers (EXR renders): the values are then negated.
    pub near_is_larger: bool,
}

impl DepthImage {
    /// What a run should be told about this depth image for a `style_w ×
    /// style_h` style, if anything: one value everywhere (min-max
    /// normalised, it leaves the geometry no relief to take), or a shape
    /// more than 5 % off the style's (it is stretched onto the style).
    pub fn doubts(&self, style_w: usize, style_h: usize) -> Option<String> {
        let (lo, hi) = self.values.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let mut said = Vec::new();
        if (hi - lo).is_nan() || hi - lo <= 1e-6 {
            said.push(format!(
                "the style depth image ({}x{}) holds one value everywhere ({lo}): it gives the geometry no relief to take",
                self.width, self.height
            ));
        }
        let ratio = (self.width as f64 / self.height as f64) / (style_w as f64 / style_h.max(1) as f64);
        if (ratio - 1.0).abs() > 0.05 {
            said.push(format!(
                "the style depth image is {}x{} and the style {style_w}x{style_h}: it is stretched onto the style's \
                 shape ({:+.0} % in width); a depth map made from the style image itself fits it",
                self.width,
                self.height,
                100.0 * (1.0 / ratio - 1.0)
            ));
        }
        (!said.is_empty()).then(|| said.join("; "))
    }

    /// Reads a grey PNG (8 or 16 bit; colour images are converted to luma) or an
    /// EXR (channel `Z`, `depth`, `Y` or `R`, else the first). PNGs are taken as
    /// near = bright, EXRs as metric depth (near = small); change
    /// [`DepthImage::near_is_larger`] when a file says otherwise.
    pub fn from_file(path: &Path) -> Result<Self, StyleDepthError> {
        let shown = path.display().to_string();
        let is_exr = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if is_exr {
            return Self::from_exr(path, shown);
        }
        let img =
            crate::io::open_image(path).map_err(|message| StyleDepthError::Image { path: shown.clone(), message })?;
        let luma = img.to_luma16();
        let (width, height) = (luma.width() as usize, luma.height() as usize);
        if width == 0 || height == 0 {
            return Err(StyleDepthError::Empty { path: shown, found: "an empty image".into() });
        }
        let values = luma.as_raw().iter().map(|&v| f32::from(v) / 65535.0).collect();
        Ok(Self { values, height, width, near_is_larger: true })
    }

    fn from_exr(path: &Path, shown: String) -> Result<Self, StyleDepthError> {
        use exr::prelude::FlatSamples;
        let img = exr::prelude::read_first_flat_layer_from_file(path)
            .map_err(|source| StyleDepthError::Exr { path: shown.clone(), source })?;
        let layer = &img.layer_data;
        let (width, height) = (layer.size.0, layer.size.1);
        let list = &layer.channel_data.list;
        let pick = ["Z", "depth", "Y", "R"]
            .iter()
            .find_map(|n| list.iter().find(|c| c.name.to_string().eq_ignore_ascii_case(n)))
            .or_else(|| list.first());
        let Some(ch) = pick else {
            return Err(StyleDepthError::Empty { path: shown, found: "no channels".into() });
        };
        let values: Vec<f32> = match &ch.sample_data {
            FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
            FlatSamples::F32(v) => v.clone(),
            FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
        };
        if width == 0 || height == 0 || values.len() != width * height {
            return Err(StyleDepthError::Empty {
                path: shown,
                found: format!("{} samples for {width}×{height}", values.len()),
            });
        }
        Ok(Self { values, height, width, near_is_larger: false })
    }
}

impl StyleDepthProvider for DepthImage {
    fn estimate(&self, _rgb: &[f32], h: usize, w: usize) -> Vec<f32> {
        // Non-finite samples (EXR background at infinity) become the far end.
        let finite = |v: f32| if v.is_finite() { v } else { f32::NAN };
        let sign = if self.near_is_larger { 1.0 } else { -1.0 };
        let vals: Vec<f32> = self.values.iter().map(|&v| finite(v) * sign).collect();
        let far = vals.iter().copied().filter(|v| !v.is_nan()).fold(f32::INFINITY, f32::min);
        let far = if far.is_finite() { far } else { 0.0 };
        let vals: Vec<f32> = vals.into_iter().map(|v| if v.is_nan() { far } else { v }).collect();
        if (self.height, self.width) == (h, w) {
            vals
        } else {
            resize_bilinear(&vals, self.height, self.width, 1, h, w)
        }
    }
}

/// A weight-free depth guess from image cues. **It is not a depth estimator**:
/// it encodes three photographic priors that hold for many landscapes and
/// paintings and fail for others (portraits, top-down views, abstract art):
///
/// - position: lower rows are nearer (ground plane seen from eye height);
/// - sharpness: local contrast (blurred gradient magnitude) is higher near,
///   where texture is resolved and in focus;
/// - aerial perspective: far regions are hazier, i.e. brighter and less
///   saturated.
///
/// The cues are each normalised to [0, 1], mixed with the weights below and
/// smoothed with a box filter so the result reads as layered regions rather
/// than texture. Use a [`DepthImage`] from a real estimator for faithful
/// geometry transfer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeuristicDepth {
    /// Weight of the vertical-position prior.
    pub position_weight: f32,
    /// Weight of the local-contrast cue.
    pub sharpness_weight: f32,
    /// Weight of the aerial-perspective (haze) cue.
    pub haze_weight: f32,
    /// Box-filter radius as a fraction of the image height.
    pub smoothing: f32,
}

impl Default for HeuristicDepth {
    fn default() -> Self {
        Self { position_weight: 0.5, sharpness_weight: 0.3, haze_weight: 0.2, smoothing: 0.03 }
    }
}

impl StyleDepthProvider for HeuristicDepth {
    fn estimate(&self, rgb: &[f32], h: usize, w: usize) -> Vec<f32> {
        assert_eq!(rgb.len(), h * w * 3, "HeuristicDepth: image size mismatch");
        let n = h * w;
        let lum: Vec<f32> = rgb.chunks_exact(3).map(|p| 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]).collect();
        // Local contrast: gradient magnitude of luminance, smoothed.
        let mut grad = vec![0f32; n];
        for i in 0..h {
            for j in 0..w {
                let l = |y: usize, x: usize| lum[y * w + x];
                let gx = l(i, (j + 1).min(w - 1)) - l(i, j.saturating_sub(1));
                let gy = l((i + 1).min(h - 1), j) - l(i.saturating_sub(1), j);
                grad[i * w + j] = (gx * gx + gy * gy).sqrt();
            }
        }
        let r = ((self.smoothing * h as f32).round() as usize).max(1);
        let sharp = min_max_normalise(&box_blur(&grad, h, w, 2 * r));
        // Haze: bright and unsaturated.
        let haze: Vec<f32> = rgb
            .chunks_exact(3)
            .map(|p| {
                let mx = p[0].max(p[1]).max(p[2]);
                let mn = p[0].min(p[1]).min(p[2]);
                let sat = if mx > 1e-6 { (mx - mn) / mx } else { 0.0 };
                0.5 * mx + 0.5 * (1.0 - sat)
            })
            .collect();
        let haze = min_max_normalise(&box_blur(&haze, h, w, r));
        let mut d = vec![0f32; n];
        for i in 0..h {
            let pos = if h > 1 { i as f32 / (h - 1) as f32 } else { 0.5 };
            for j in 0..w {
                let p = i * w + j;
                d[p] =
                    self.position_weight * pos + self.sharpness_weight * sharp[p] + self.haze_weight * (1.0 - haze[p]);
            }
        }
        box_blur(&d, h, w, r)
    }
}

/// Separable box filter of radius `r` with clamped borders.
pub(crate) fn box_blur(src: &[f32], h: usize, w: usize, r: usize) -> Vec<f32> {
    let pass = |src: &[f32], len: usize, count: usize, at: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![0f32; src.len()];
        for line in 0..count {
            for t in 0..len {
                let (a, b) = (t.saturating_sub(r), (t + r).min(len - 1));
                let s: f32 = (a..=b).map(|u| src[at(line, u)]).sum();
                out[at(line, t)] = s / (b - a + 1) as f32;
            }
        }
        out
    };
    let tmp = pass(src, w, h, &|line, t| line * w + t);
    pass(&tmp, h, w, &|line, t| t * w + line)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat depth image or one of another shape than the style is said;
    /// a graded one of the style's shape is not.
    #[test]
    fn flat_or_misshapen_depth_images_are_doubted() {
        let image = |w: usize, h: usize, f: &dyn Fn(usize) -> f32| DepthImage {
            values: (0..w * h).map(f).collect(),
            height: h,
            width: w,
            near_is_larger: true,
        };
        let graded = |i: usize| (i % 7) as f32;
        assert_eq!(image(420, 200, &graded).doubts(4200, 2000), None);
        let flat = image(420, 200, &|_| 0.5).doubts(4200, 2000).expect("flat");
        assert!(flat.contains("holds one value everywhere (0.5)") && !flat.contains("stretched"), "{flat}");
        let narrow = image(37, 11, &graded).doubts(4200, 2000).expect("another shape");
        assert!(narrow.contains("is 37x11 and the style 4200x2000") && narrow.contains("-38 % in width"), "{narrow}");
    }

    #[test]
    fn normalised_and_polarity() {
        let img = DepthImage { values: vec![2.0, 4.0, 6.0, 8.0], height: 2, width: 2, near_is_larger: true };
        let d = style_depth_map(&img, &[0.0; 12], 2, 2, DepthPolarity::NearBright);
        assert!((d[0]).abs() < 1e-6 && (d[3] - 1.0).abs() < 1e-6);
        let d2 = style_depth_map(&img, &[0.0; 12], 2, 2, DepthPolarity::NearDark);
        assert!((d2[0] - 1.0).abs() < 1e-6 && d2[3].abs() < 1e-6);
        // Metric depth: small = near = bright after normalisation.
        let metric = DepthImage { near_is_larger: false, ..img };
        let d3 = style_depth_map(&metric, &[0.0; 12], 2, 2, DepthPolarity::NearBright);
        assert!((d3[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn user_depth_is_resized() {
        let img = DepthImage { values: vec![0.0, 1.0, 0.0, 1.0], height: 2, width: 2, near_is_larger: true };
        let d = img.estimate(&[], 4, 6);
        assert_eq!(d.len(), 24);
        assert!(d[0] < d[5]);
    }

    #[test]
    fn png_round_trip() {
        let dir = std::env::temp_dir().join(format!("gast-depth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let p = dir.join("d.png");
        let buf =
            image::ImageBuffer::<image::Luma<u16>, _>::from_fn(4, 3, |x, y| image::Luma([(x * 1000 + y * 10) as u16]));
        buf.save(&p).expect("write png");
        let d = DepthImage::from_file(&p).expect("read png");
        assert_eq!((d.height, d.width), (3, 4));
        assert!((d.values[1] - 1000.0 / 65535.0).abs() < 1e-7);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn heuristic_prefers_the_bottom_and_stays_in_range() {
        let (h, w) = (32, 24);
        let rgb: Vec<f32> = (0..h * w * 3).map(|i| ((i * 7) % 13) as f32 / 13.0).collect();
        let d = style_depth_map(&HeuristicDepth::default(), &rgb, h, w, DepthPolarity::NearBright);
        assert!(d.iter().all(|v| (0.0..=1.0).contains(v)));
        let top: f32 = d[..w].iter().sum();
        let bottom: f32 = d[(h - 1) * w..].iter().sum();
        assert!(bottom > top);
    }
}
