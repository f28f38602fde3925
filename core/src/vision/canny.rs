//! Canny edges exactly as OpenCV's `cv2.Canny(img, low, high)` computes them,
//! and the two edge maps of the algorithm (style edges, render edges).
//!
//! GCFM compares edge features of renders and of the style, so the edges have
//! to be the same function the reference uses: OpenCV's Canny with the L1
//! gradient (`L2gradient=false`). That is: 3×3 Sobel with replicated borders,
//! magnitude `|gx| + |gy|` (for multi-channel input, per pixel the channel with
//! the largest magnitude, the first one on ties), non-maximum suppression with
//! OpenCV's integer sector test (tan 22.5° in Q15), thresholds compared as
//! `m > floor(low)` and `m > floor(high)`, and hysteresis over 8-neighbours.
//!
//! `cv2.Canny` does **not** blur first. The issue text asks for a Gaussian blur
//! step, so [`CannyParams::blur_sigma`] offers one; its default `None` is what
//! matches the reference (and the golden maps).

/// Thresholds and options of [`canny`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CannyParams {
    /// Lower hysteresis threshold on `|gx| + |gy|` (OpenCV floors it).
    pub low: f32,
    /// Upper hysteresis threshold (OpenCV floors it).
    pub high: f32,
    /// Optional Gaussian blur (σ in pixels, 5×5 kernel for σ ≤ 1.1, else
    /// `2·ceil(3σ)+1`) before Sobel, result rounded back to 8-bit. `None`, the
    /// default, matches `cv2.Canny` and the reference.
    pub blur_sigma: Option<f32>,
}

impl Default for CannyParams {
    /// The algorithm's thresholds: low 25, high 200, no blur.
    fn default() -> Self {
        Self { low: 25.0, high: 200.0, blur_sigma: None }
    }
}

/// Canny edges of an 8-bit image with `channels` interleaved channels (HWC).
/// Returns an `h × w` map with 1 on edges and 0 elsewhere.
pub fn canny(img: &[u8], h: usize, w: usize, channels: usize, params: &CannyParams) -> Vec<u8> {
    assert_eq!(img.len(), h * w * channels, "canny: image size mismatch");
    if h == 0 || w == 0 {
        return Vec::new();
    }
    let blurred;
    let img = match params.blur_sigma {
        Some(s) if s > 0.0 => {
            blurred = gaussian_blur_u8(img, h, w, channels, s);
            &blurred[..]
        }
        _ => img,
    };
    let (dx, dy, mag) = sobel_max_channel(img, h, w, channels);
    let (low, high) = {
        let (a, b) = (params.low.min(params.high), params.low.max(params.high));
        (a.floor() as i32, b.floor() as i32)
    };
    // 0: candidate (local maximum above low), 2: strong edge, 1: nothing.
    let mut map = vec![1u8; h * w];
    let mut stack = Vec::new();
    let m_at = |i: isize, j: isize| -> i32 {
        if i < 0 || j < 0 || i >= h as isize || j >= w as isize { 0 } else { mag[i as usize * w + j as usize] }
    };
    const SHIFT: i32 = 15;
    let tg22 = (0.414_213_562_373_095_05_f64 * f64::from(1 << SHIFT) + 0.5) as i64;
    for i in 0..h {
        for j in 0..w {
            let idx = i * w + j;
            let m = mag[idx];
            if m <= low {
                continue;
            }
            let (ii, jj) = (i as isize, j as isize);
            let xs = dx[idx];
            let ys = dy[idx];
            let x = i64::from(xs.abs());
            let y = i64::from(ys.abs()) << SHIFT;
            let tg22x = x * tg22;
            let is_max = if y < tg22x {
                m > m_at(ii, jj - 1) && m >= m_at(ii, jj + 1)
            } else {
                let tg67x = tg22x + (x << (SHIFT + 1));
                if y > tg67x {
                    m > m_at(ii - 1, jj) && m >= m_at(ii + 1, jj)
                } else {
                    let s: isize = if (xs ^ ys) < 0 { -1 } else { 1 };
                    m > m_at(ii - 1, jj - s) && m > m_at(ii + 1, jj + s)
                }
            };
            if !is_max {
                continue;
            }
            if m > high {
                map[idx] = 2;
                stack.push(idx);
            } else {
                map[idx] = 0;
            }
        }
    }
    // Hysteresis: grow strong edges through 8-connected candidates.
    while let Some(idx) = stack.pop() {
        let (i, j) = ((idx / w) as isize, (idx % w) as isize);
        for di in -1..=1isize {
            for dj in -1..=1isize {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni >= h as isize || nj >= w as isize {
                    continue;
                }
                let n = ni as usize * w + nj as usize;
                if map[n] == 0 {
                    map[n] = 2;
                    stack.push(n);
                }
            }
        }
    }
    map.into_iter().map(|v| u8::from(v == 2)).collect()
}

/// Sobel 3×3 (replicated borders) per channel, keeping per pixel the channel
/// with the largest `|gx| + |gy|`. Returns `(gx, gy, magnitude)`.
fn sobel_max_channel(img: &[u8], h: usize, w: usize, c: usize) -> (Vec<i32>, Vec<i32>, Vec<i32>) {
    let mut dx = vec![0i32; h * w];
    let mut dy = vec![0i32; h * w];
    let mut mag = vec![-1i32; h * w];
    let px = |i: usize, j: usize, k: usize| i32::from(img[(i * w + j) * c + k]);
    for i in 0..h {
        let (iu, id) = (i.saturating_sub(1), (i + 1).min(h - 1));
        for j in 0..w {
            let (jl, jr) = (j.saturating_sub(1), (j + 1).min(w - 1));
            let idx = i * w + j;
            for k in 0..c {
                let gx = (px(iu, jr, k) - px(iu, jl, k))
                    + 2 * (px(i, jr, k) - px(i, jl, k))
                    + (px(id, jr, k) - px(id, jl, k));
                let gy = (px(id, jl, k) - px(iu, jl, k))
                    + 2 * (px(id, j, k) - px(iu, j, k))
                    + (px(id, jr, k) - px(iu, jr, k));
                let m = gx.abs() + gy.abs();
                if m > mag[idx] {
                    mag[idx] = m;
                    dx[idx] = gx;
                    dy[idx] = gy;
                }
            }
        }
    }
    (dx, dy, mag)
}

/// Separable Gaussian blur of an 8-bit image with replicated borders, rounded.
fn gaussian_blur_u8(img: &[u8], h: usize, w: usize, c: usize, sigma: f32) -> Vec<u8> {
    let radius = if sigma <= 1.1 { 2 } else { (3.0 * sigma).ceil() as isize };
    let mut k: Vec<f32> = (-radius..=radius).map(|t| (-(t * t) as f32 / (2.0 * sigma * sigma)).exp()).collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    let clampi = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let mut tmp = vec![0f32; h * w * c];
    for i in 0..h {
        for j in 0..w {
            for ch in 0..c {
                let mut acc = 0.0;
                for (t, kv) in k.iter().enumerate() {
                    let jj = clampi(j as isize + t as isize - radius, w);
                    acc += kv * f32::from(img[(i * w + jj) * c + ch]);
                }
                tmp[(i * w + j) * c + ch] = acc;
            }
        }
    }
    let mut out = vec![0u8; h * w * c];
    for i in 0..h {
        for j in 0..w {
            for ch in 0..c {
                let mut acc = 0.0;
                for (t, kv) in k.iter().enumerate() {
                    let ii = clampi(i as isize + t as isize - radius, h);
                    acc += kv * tmp[(ii * w + j) * c + ch];
                }
                out[(i * w + j) * c + ch] = acc.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    out
}

/// Style edges: Canny(25, 200) on the JET-coloured style depth (RGB, 8-bit),
/// values {0, 1}. The channels are visited in OpenCV's BGR order so that ties
/// between channels resolve as in the reference.
pub fn style_edges(jet_rgb: &[u8], h: usize, w: usize) -> Vec<f32> {
    let bgr: Vec<u8> = jet_rgb.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect();
    canny(&bgr, h, w, 3, &CannyParams::default()).into_iter().map(f32::from).collect()
}

/// Style edges straight from a normalised style depth map (`h × w`, [0, 1]):
/// re-normalised and truncated to 8-bit, JET-coloured, then [`style_edges`].
pub fn style_edges_from_depth(depth: &[f32], h: usize, w: usize) -> Vec<f32> {
    use super::colormap::{apply_jet, to_u8_truncating};
    style_edges(&apply_jet(&to_u8_truncating(depth)), h, w)
}

/// Render edges: the render (HWC, 3 channels) min-max normalised over the whole
/// image and truncated to 8-bit (`(x − min)/(max − min)·255`, `astype(uint8)`),
/// Canny(25, 200) per channel, averaged over channels. `h × w`, values in
/// {0, ⅓, ⅔, 1}. A constant for the optimiser (no gradient).
pub fn render_edges(rgb: &[f32], h: usize, w: usize) -> Vec<f32> {
    assert_eq!(rgb.len(), h * w * 3, "render_edges: image size mismatch");
    let (lo, hi) = rgb.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let range = hi - lo;
    let to_u8 = |v: f32| {
        if range > 0.0 { ((v - lo) / range * 255.0).clamp(0.0, 255.0) as u8 } else { 0 }
    };
    let mut acc = vec![0f32; h * w];
    for ch in 0..3 {
        let plane: Vec<u8> = (0..h * w).map(|p| to_u8(rgb[p * 3 + ch])).collect();
        let e = canny(&plane, h, w, 1, &CannyParams::default());
        for (a, v) in acc.iter_mut().zip(e) {
            *a += f32::from(v);
        }
    }
    acc.iter_mut().for_each(|a| *a /= 3.0);
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(h: usize, w: usize, lo: u8, hi: u8) -> Vec<u8> {
        let mut img = vec![lo; h * w];
        for i in 8..24 {
            for j in 8..24 {
                img[i * w + j] = hi;
            }
        }
        img
    }

    #[test]
    fn square_has_edges_on_its_border_only() {
        let (h, w) = (32, 32);
        let e = canny(&square(h, w, 0, 200), h, w, 1, &CannyParams::default());
        // Nothing deep inside or far outside.
        for i in 0..h {
            for j in 0..w {
                let inside = (10..22).contains(&i) && (10..22).contains(&j);
                let outside = !(6..26).contains(&i) || !(6..26).contains(&j);
                if inside || outside {
                    assert_eq!(e[i * w + j], 0, "unexpected edge at {i},{j}");
                }
            }
        }
        // Every side of the square carries an edge near its border.
        for t in 10..22 {
            assert!((7..=8).any(|i| e[i * w + t] == 1), "top edge missing at column {t}");
            assert!((23..=24).any(|i| e[i * w + t] == 1), "bottom edge missing at column {t}");
            assert!((7..=8).any(|j| e[t * w + j] == 1), "left edge missing at row {t}");
            assert!((23..=24).any(|j| e[t * w + j] == 1), "right edge missing at row {t}");
        }
        // Thin edges: one pixel across per side (non-maximum suppression).
        let row: u32 = (0..h).map(|i| u32::from(e[i * w + 16])).sum();
        assert_eq!(row, 2);
    }

    #[test]
    fn thresholds_are_respected() {
        let (h, w) = (32, 32);
        // A step of 12 gives |gx| = 48 on the edge: above 25, below 200: weak only.
        let weak = canny(&square(h, w, 100, 112), h, w, 1, &CannyParams::default());
        assert!(weak.iter().all(|&v| v == 0));
        let low = CannyParams { low: 10.0, high: 40.0, blur_sigma: None };
        let strong = canny(&square(h, w, 100, 112), h, w, 1, &low);
        assert!(strong.contains(&1));
        // A straight step of 6 (|gx| = 24) stays below low = 25 even with high
        // lowered; one of 7 (|gx| = 28) passes.
        let p = CannyParams { low: 25.0, high: 26.0, blur_sigma: None };
        let step = |d: u8| -> Vec<u8> { (0..h * w).map(|i| if i % w >= 16 { 100 + d } else { 100 }).collect() };
        assert!(canny(&step(6), h, w, 1, &p).iter().all(|&v| v == 0));
        let e = canny(&step(7), h, w, 1, &p);
        assert!((0..h).all(|i| e[i * w + 15] == 1));
    }

    #[test]
    fn hysteresis_follows_eight_connected_weak_pixels() {
        // A vertical line whose contrast fades: strong at the top, weak below.
        let (h, w) = (24, 16);
        let mut img = vec![0u8; h * w];
        for i in 0..h {
            let v = if i < 6 { 200 } else { 20 };
            for j in 8..w {
                img[i * w + j] = v;
            }
        }
        let e = canny(&img, h, w, 1, &CannyParams::default());
        // The weak part (|gx| = 80 > 25) is kept because it connects to the strong part.
        let col_has_edge = |i: usize| (0..w).any(|j| e[i * w + j] == 1);
        assert!(col_has_edge(2));
        assert!(col_has_edge(18));
        // The same weak step alone has no strong seed: nothing.
        let mut lone = vec![0u8; h * w];
        for i in 0..h {
            for j in 8..w {
                lone[i * w + j] = 20;
            }
        }
        let e2 = canny(&lone, h, w, 1, &CannyParams::default());
        assert!(e2.iter().all(|&v| v == 0));
    }

    #[test]
    fn multi_channel_takes_the_strongest_channel() {
        let (h, w) = (32, 32);
        let g = square(h, w, 0, 200);
        let rgb: Vec<u8> = g.iter().flat_map(|&v| [0, v, 0]).collect();
        let e3 = canny(&rgb, h, w, 3, &CannyParams::default());
        let e1 = canny(&g, h, w, 1, &CannyParams::default());
        assert_eq!(e3, e1);
    }

    #[test]
    fn blur_option_runs_and_keeps_strong_edges() {
        let (h, w) = (32, 32);
        let p = CannyParams { blur_sigma: Some(1.0), ..CannyParams::default() };
        let e = canny(&square(h, w, 0, 255), h, w, 1, &p);
        assert!(e.contains(&1));
    }

    #[test]
    fn render_edges_average_channels() {
        let (h, w) = (32, 32);
        let g = square(h, w, 0, 1);
        // Only the red channel has the square: edges count 1/3.
        let rgb: Vec<f32> = g.iter().flat_map(|&v| [f32::from(v), 0.0, 0.0]).collect();
        let e = render_edges(&rgb, h, w);
        let max = e.iter().cloned().fold(0.0, f32::max);
        assert!((max - 1.0 / 3.0).abs() < 1e-6);
    }
}
