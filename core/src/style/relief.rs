//! The depth map's relief: both depth maps (the render's, min-max normalised,
//! and the style's) minus their blur at a pattern's scale, centred on 0.5,
//! before VGG ([`StyleConfig::depth_relief_px`](super::StyleConfig::depth_relief_px)).
//!
//! Min-max normalisation over a whole object or frame gives its 0–1 range to
//! the layout (a near neck, a far body), while a style's depth spans 0–1
//! within one texture patch: VGG may see layout where the style has relief.
//! Taking the blur away compares relief with relief. The blur is a box
//! filter of radius `r` applied twice (a tent of half-width `2r`), each pass
//! normalised by the mask's own box sum so uncovered pixels do not pull a
//! silhouette's relief down: a linear map for a fixed mask, whose adjoint
//! ([`relief_backward`]) takes the gradient back. The relief is then centred
//! on 0.5 ([`centred`]), so the background, which has none, leaves no edge
//! at an object's silhouette.

/// The box sum of radius `r` over rows then columns of `h × w` values
/// (clipped at the borders): a symmetric linear map, its own adjoint.
fn box_sum(src: &[f32], h: usize, w: usize, r: usize) -> Vec<f32> {
    let line = |src: &[f32], len: usize, stride: usize, start: usize, out: &mut [f32]| {
        let mut prefix = vec![0f64; len + 1];
        for i in 0..len {
            prefix[i + 1] = prefix[i] + f64::from(src[start + i * stride]);
        }
        for i in 0..len {
            let (a, b) = (i.saturating_sub(r), (i + r + 1).min(len));
            out[start + i * stride] = (prefix[b] - prefix[a]) as f32;
        }
    };
    let mut rows = vec![0f32; h * w];
    for y in 0..h {
        line(src, w, 1, y * w, &mut rows);
    }
    let mut out = vec![0f32; h * w];
    for x in 0..w {
        line(&rows, h, w, x, &mut out);
    }
    out
}

/// The mask as 0/1 and `1 / box_sum(mask)` (0 where no covered pixel is near).
fn weights(h: usize, w: usize, mask: Option<&[bool]>, r: usize) -> (Vec<f32>, Vec<f32>) {
    let m: Vec<f32> = (0..h * w).map(|k| if mask.is_none_or(|m| m[k]) { 1.0 } else { 0.0 }).collect();
    let inv_n = box_sum(&m, h, w, r).iter().map(|&n| if n > 0.0 { 1.0 / n } else { 0.0 }).collect();
    (m, inv_n)
}

/// `d` minus its masked blur `B d` of radius `r` inside `mask` (all of `h ×
/// w` without one), 0 outside, with `B d = (1/n)·K(m·(1/n)·K(m·d))`: two box
/// passes `K`, each normalised by the mask's box sum `n`. Not yet normalised.
pub fn relief(d: &[f32], h: usize, w: usize, mask: Option<&[bool]>, r: usize) -> Vec<f32> {
    assert_eq!(d.len(), h * w, "relief: map size");
    let (m, inv_n) = weights(h, w, mask, r);
    let pass = |x: &[f32]| -> Vec<f32> {
        let masked: Vec<f32> = x.iter().zip(&m).map(|(a, b)| a * b).collect();
        box_sum(&masked, h, w, r).iter().zip(&inv_n).map(|(s, i)| s * i).collect()
    };
    let blurred = pass(&pass(d));
    (0..h * w).map(|k| m[k] * (d[k] - blurred[k])).collect()
}

/// The adjoint of [`relief`] (a linear map for a fixed mask): `m·v − Bᵀ(m·v)`
/// with `Bᵀ u = m·K((1/n)·m·K((1/n)·u))`.
pub fn relief_backward(v: &[f32], h: usize, w: usize, mask: Option<&[bool]>, r: usize) -> Vec<f32> {
    assert_eq!(v.len(), h * w, "relief_backward: map size");
    let (m, inv_n) = weights(h, w, mask, r);
    let mv: Vec<f32> = v.iter().zip(&m).map(|(a, b)| a * b).collect();
    let pass = |x: &[f32]| -> Vec<f32> {
        let scaled: Vec<f32> = x.iter().zip(&inv_n).map(|(a, i)| a * i).collect();
        box_sum(&scaled, h, w, r).iter().zip(&m).map(|(s, b)| s * b).collect()
    };
    let bt = pass(&pass(&mv));
    mv.iter().zip(bt).map(|(a, b)| a - b).collect()
}

/// The relief `rel` (0 outside `mask`) centred on 0.5: `0.5 + rel / (2M)`
/// with `M = max |rel|` over `mask`, so no relief, and every uncovered pixel,
/// reads 0.5 (an object's silhouette leaves no edge in it) and the map spans
/// at most 0–1.
pub fn centred(rel: &[f32], mask: Option<&[bool]>) -> Vec<f32> {
    let m = peak(rel, mask);
    rel.iter().map(|&x| 0.5 + x / (2.0 * m)).collect()
}

/// `max |rel| + 1e-8` over `mask`.
fn peak(rel: &[f32], mask: Option<&[bool]>) -> f32 {
    largest(rel, mask) + 1e-8
}

/// `max |rel|` over `mask`.
fn largest(rel: &[f32], mask: Option<&[bool]>) -> f32 {
    let inside = |k: usize| mask.is_none_or(|m| m[k]);
    (0..rel.len()).filter(|&k| inside(k)).fold(0.0f32, |a, k| a.max(rel[k].abs()))
}

/// The adjoint of [`centred`] at `rel`: `v / (2M)` inside the mask, plus the
/// peak's share `−sign · Σ v·rel / (2M²)` (ties at the peak share it).
pub fn centred_backward(rel: &[f32], v: &[f32], mask: Option<&[bool]>) -> Vec<f32> {
    let inside = |k: usize| mask.is_none_or(|m| m[k]);
    let (top, m) = (largest(rel, mask), peak(rel, mask));
    let at_peak = |k: usize| inside(k) && rel[k].abs() == top;
    let ties = (0..rel.len()).filter(|&k| at_peak(k)).count().max(1) as f64;
    let dot: f64 = rel.iter().zip(v).map(|(a, b)| f64::from(a * b)).sum();
    let g_peak = -dot / (2.0 * f64::from(m) * f64::from(m)) / ties;
    (0..rel.len())
        .map(|k| {
            if !inside(k) {
                return 0.0;
            }
            let mut o = f64::from(v[k]) / (2.0 * f64::from(m));
            if at_peak(k) {
                o += g_peak * f64::from(rel[k].signum());
            }
            o as f32
        })
        .collect()
}

/// What VGG sees of a depth map `d` with
/// [`StyleConfig::depth_relief_px`](super::StyleConfig::depth_relief_px) `r`:
/// its relief ([`relief`]) [`centred`].
pub fn relief_normalised(d: &[f32], h: usize, w: usize, mask: Option<&[bool]>, r: usize) -> Vec<f32> {
    centred(&relief(d, h, w, mask, r), mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_has_no_relief_and_a_bump_keeps_its_shape() {
        let (h, w) = (24, 30);
        // A tilted plane: the blur of a linear function is itself away from the borders.
        let plane: Vec<f32> = (0..h * w).map(|k| 0.01 * (k / w) as f32 + 0.02 * (k % w) as f32).collect();
        let rel = relief(&plane, h, w, None, 3);
        for y in 6..h - 6 {
            for x in 6..w - 6 {
                assert!(rel[y * w + x].abs() < 1e-4, "plane relief at {y},{x}: {}", rel[y * w + x]);
            }
        }
        // A bump on the plane: its relief peaks at the bump, at 1 in the centred map, within 0–1.
        let mut bumped = plane.clone();
        bumped[12 * w + 15] += 1.0;
        let n = relief_normalised(&bumped, h, w, None, 3);
        let peak = (0..h * w).max_by(|&a, &b| n[a].total_cmp(&n[b])).expect("a peak");
        assert_eq!(peak, 12 * w + 15);
        assert!((n[peak] - 1.0).abs() < 1e-5 && n.iter().all(|v| (0.0..=1.0).contains(v)));
    }

    #[test]
    fn uncovered_pixels_neither_count_nor_pull_the_edge() {
        let (h, w) = (10, 12);
        // Constant 0.7 on the covered left half, 0 (background) elsewhere.
        let mask: Vec<bool> = (0..h * w).map(|k| k % w < 6).collect();
        let d: Vec<f32> = mask.iter().map(|&m| if m { 0.7 } else { 0.0 }).collect();
        let rel = relief(&d, h, w, Some(&mask), 2);
        assert!(rel.iter().all(|v| v.abs() < 1e-6), "a flat object has no relief at its silhouette: {rel:?}");
    }

    #[test]
    fn the_centring_backward_matches_finite_differences() {
        let mut rel: Vec<f32> = (0..40).map(|k| ((k as f32) * 0.7).sin() * 0.3).collect();
        // One clear peak, so the finite differences do not cross to another.
        rel[5] = -0.6;
        let mask: Vec<bool> = (0..40).map(|k| k % 6 != 0).collect();
        let v: Vec<f32> = (0..40).map(|k| ((k as f32) * 0.23).cos()).collect();
        let f = |x: &[f32]| -> f64 { centred(x, Some(&mask)).iter().zip(&v).map(|(a, b)| f64::from(a * b)).sum() };
        let g = centred_backward(&rel, &v, Some(&mask));
        for k in (0..40).filter(|&k| mask[k]) {
            let (mut p, mut m) = (rel.clone(), rel.clone());
            p[k] += 1e-3;
            m[k] -= 1e-3;
            let fd = (f(&p) - f(&m)) / 2e-3;
            assert!((fd - f64::from(g[k])).abs() < 2e-3 * fd.abs().max(1.0), "{k}: fd {fd} vs {}", g[k]);
        }
        assert!(centred(&rel, Some(&mask)).iter().all(|v| (0.0..=1.0).contains(v)));
    }

    #[test]
    fn the_backward_is_the_adjoint() {
        let (h, w, r) = (13, 17, 2);
        let wave = |seed: f32| -> Vec<f32> { (0..h * w).map(|k| ((k as f32) * seed).sin()).collect() };
        let mask: Vec<bool> = (0..h * w).map(|k| (k * 7) % 5 != 0).collect();
        for mask in [None, Some(mask.as_slice())] {
            let (d, v) = (wave(0.37), wave(0.11));
            // ⟨relief(d), v⟩ = ⟨d, relief_backward(v)⟩ for a linear map.
            let lhs: f64 = relief(&d, h, w, mask, r).iter().zip(&v).map(|(a, b)| f64::from(a * b)).sum();
            let rhs: f64 = d.iter().zip(relief_backward(&v, h, w, mask, r)).map(|(a, b)| f64::from(a * b)).sum();
            assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
        }
    }
}
