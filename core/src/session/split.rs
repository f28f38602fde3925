//! Splitting the Gaussians that are large on screen, so the geometry has room
//! for the style's pattern ([`StyleConfig::split_px`](crate::style::StyleConfig::split_px)).
//!
//! A Gaussian whose standard deviation spans more pixels than one pattern
//! cell of the style can only move as a whole: its opacity, scale and depth
//! change the render everywhere it covers, so a relief finer than it cannot
//! form there. A trained scene keeps few, large Gaussians on smooth surfaces
//! (fern's wall and ceiling), where the photos need no more; those are the
//! places the reference's dense scenes (0.5–4 M Gaussians) tile with the
//! style's structure and ours did not. Measured on fern (`docs/geometry.md`),
//! density alone does not bring that structure: 8× the Gaussians move the
//! depth measures as the fitted scene does. It is an option, off by default.
//!
//! Each split replaces a Gaussian by two along its longest axis `a` (scale
//! `s`): centres `μ ± δ·s·a`, that axis's scale `s·√(1 − δ²)`, the other axes
//! unchanged. The pair's mixture keeps the parent's mean and covariance
//! exactly (`(s√(1−δ²))² + (δs)² = s²`), and each child's opacity is
//! about `o/(2√(1−δ²))` (see [`child_logit`]), so the pair renders close to
//! the parent. Colours and rotations are copied. Splits repeat until no Gaussian's
//! largest standard deviation spans more than `max_px` pixels in any view, or
//! the count would pass `max_count` (the largest on screen go first).

use glam::{Mat3, Quat, Vec3};

use crate::camera::Camera;
use crate::scene::Gaussians;

/// Half the distance between a split pair's centres, in units of the
/// parent's scale along the split axis: at 0.7 the children (scale 0.71 of
/// the parent's) stand 1.96 of their own scale apart, so the pair's profile
/// keeps a single peak (two equal Gaussians do up to 2).
const DELTA: f32 = 0.7;

/// Passes at most (each shrinks the largest footprints by about 0.71).
const MAX_PASSES: usize = 24;

/// How a split went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitReport {
    /// Gaussians before.
    pub before: usize,
    /// Gaussians after.
    pub after: usize,
    /// Passes run.
    pub passes: usize,
    /// Whether the count cap stopped the splitting before every Gaussian was small enough.
    pub capped: bool,
}

/// The largest standard deviation of each Gaussian in pixels over the views
/// that see its centre in front of them (0 where none does).
pub fn footprints(g: &Gaussians, cams: &[Camera]) -> Vec<f32> {
    use rayon::prelude::*;
    (0..g.len())
        .into_par_iter()
        .map(|i| {
            let s = g.log_scales[i].iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)).exp();
            let p = Vec3::from(g.means[i]);
            cams.iter()
                .filter_map(|c| {
                    // One transform per camera: the projection from the camera-space point.
                    let q = c.world_to_camera(p);
                    if q.z <= 1e-3 {
                        return None;
                    }
                    let uv = c.pixel_of(q);
                    let inside = uv.x >= 0.0 && uv.y >= 0.0 && uv.x < c.width as f32 && uv.y < c.height as f32;
                    inside.then(|| s * c.fx.max(c.fy) / q.z)
                })
                .fold(0.0f32, f32::max)
        })
        .collect()
}

/// `g` with its Gaussians split until none spans more than `max_px` pixels
/// (one standard deviation) in any of `cams`, never past `max_count`
/// Gaussians. See the module's documentation for the rule.
pub fn split_large(g: &Gaussians, cams: &[Camera], max_px: f32, max_count: usize) -> (Gaussians, SplitReport) {
    let before = g.len();
    let mut cur = g.clone();
    let mut capped = false;
    let mut passes = 0;
    while passes < MAX_PASSES {
        let fp = footprints(&cur, cams);
        let mut large: Vec<usize> = (0..cur.len()).filter(|&i| fp[i] > max_px).collect();
        if large.is_empty() {
            break;
        }
        let room = max_count.saturating_sub(cur.len());
        if large.len() > room {
            capped = true;
            large.sort_by(|&a, &b| fp[b].total_cmp(&fp[a]));
            large.truncate(room);
        }
        if large.is_empty() {
            break;
        }
        cur = split_these(&cur, &large);
        passes += 1;
    }
    let report = SplitReport { before, after: cur.len(), passes, capped };
    (cur, report)
}

/// `g` with each Gaussian in `which` replaced by its two children (the rest
/// first, in order, then the children in pairs).
fn split_these(g: &Gaussians, which: &[usize]) -> Gaussians {
    let k = g.sh_coeffs() * 3;
    let mut chosen = vec![false; g.len()];
    which.iter().for_each(|&i| chosen[i] = true);
    let mut out = Gaussians::with_capacity(g.len() + which.len(), g.sh_degree);
    let push = |out: &mut Gaussians, i: usize, mean: [f32; 3], log_scale: [f32; 3], logit: f32| {
        out.means.push(mean);
        out.log_scales.push(log_scale);
        out.quats.push(g.quats[i]);
        out.opacity_logits.push(logit);
        out.sh.extend_from_slice(&g.sh[i * k..(i + 1) * k]);
    };
    for i in (0..g.len()).filter(|&i| !chosen[i]) {
        push(&mut out, i, g.means[i], g.log_scales[i], g.opacity_logits[i]);
    }
    for &i in which {
        let ls = g.log_scales[i];
        let axis = (0..3).max_by(|&a, &b| ls[a].total_cmp(&ls[b])).unwrap_or(0);
        let [w, x, y, z] = g.quats[i];
        let rot = Mat3::from_quat(Quat::from_xyzw(x, y, z, w).normalize());
        let offset = rot.col(axis) * (DELTA * ls[axis].exp());
        let mut child_scale = ls;
        child_scale[axis] += 0.5 * (1.0 - DELTA * DELTA).ln();
        let logit = child_logit(g.opacity_logits[i]);
        let mean = Vec3::from(g.means[i]);
        push(&mut out, i, (mean + offset).into(), child_scale, logit);
        push(&mut out, i, (mean - offset).into(), child_scale, logit);
    }
    out
}

/// A child's opacity logit for a parent of logit `l` (`o = σ(l)`):
/// `o_c = o · (1 + o/10) / (2√(1 − δ²))`. The children's footprints share the
/// parent's area, so `o/(2√(1−δ²))` each keeps the sum of α over the plane
/// where opacities are small; the factor `1 + o/10` makes up for what
/// compositing loses where they overlap (fitted: it is within 0.01 of the
/// opacity that best matches the parent's α profile for `o` from 0.05 to
/// 0.99, leaving 11–18% of the profile's L2 norm).
fn child_logit(l: f32) -> f32 {
    let o = 1.0 / (1.0 + (-f64::from(l)).exp());
    let c = o * (1.0 + 0.1 * o) / (2.0 * (1.0 - f64::from(DELTA * DELTA)).sqrt());
    let c = c.clamp(1e-12, 1.0 - 1e-12);
    (c / (1.0 - c)).ln() as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{RenderOptions, forward};

    fn camera(size: u32) -> Camera {
        // Looking down +z from the origin.
        let f = size as f32;
        Camera {
            name: "front".into(),
            width: size,
            height: size,
            fx: f,
            fy: f,
            cx: size as f32 / 2.0,
            cy: size as f32 / 2.0,
            rotation: Mat3::IDENTITY,
            translation: Vec3::ZERO,
        }
    }

    /// A wall of `n × n` large flat Gaussians at depth 4, and a few small ones in front.
    fn wall(n: usize) -> Gaussians {
        let mut g = Gaussians::with_capacity(n * n + 3, 0);
        for a in 0..n {
            for b in 0..n {
                let x = (a as f32 + 0.5) / n as f32 * 4.0 - 2.0;
                let y = (b as f32 + 0.5) / n as f32 * 4.0 - 2.0;
                g.means.push([x, y, 4.0]);
                g.log_scales.push([(2.0 / n as f32).ln(), (1.5 / n as f32).ln(), -5.0]);
                g.quats.push([0.9, 0.1, 0.3, 0.2]);
                g.opacity_logits.push(2.0);
                g.sh.extend_from_slice(&[0.3 * x, -0.2 * y, 0.5]);
            }
        }
        for (k, x) in [-0.5f32, 0.0, 0.5].into_iter().enumerate() {
            g.means.push([x, 0.2 * k as f32, 2.0]);
            g.log_scales.push([-4.0, -4.0, -4.0]);
            g.quats.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity_logits.push(1.0);
            g.sh.extend_from_slice(&[1.0, 1.0, -1.0]);
        }
        g
    }

    fn covariance(g: &Gaussians, i: usize) -> Mat3 {
        let [w, x, y, z] = g.quats[i];
        let r = Mat3::from_quat(Quat::from_xyzw(x, y, z, w).normalize());
        let s = Vec3::from(g.log_scales[i].map(f32::exp));
        r * Mat3::from_diagonal(s * s) * r.transpose()
    }

    #[test]
    fn a_split_pair_keeps_the_parents_mean_covariance_and_opacity() {
        let g = wall(2);
        let out = split_these(&g, &[1]);
        assert_eq!(out.len(), g.len() + 1);
        let (a, b) = (out.len() - 2, out.len() - 1);
        let (ma, mb) = (Vec3::from(out.means[a]), Vec3::from(out.means[b]));
        let mean = (ma + mb) / 2.0;
        assert!((mean - Vec3::from(g.means[1])).length() < 1e-6, "{mean}");
        // Mixture covariance: the children's plus the spread of their centres.
        let d = (ma - mb) / 2.0;
        let mix = covariance(&out, a) + Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        let want = covariance(&g, 1);
        for c in 0..3 {
            assert!((mix.col(c) - want.col(c)).length() < 1e-5 * want.col(c).length().max(1e-3), "{mix} vs {want}");
        }
        let o = |l: f32| 1.0 / (1.0 + (-l).exp());
        let (child, parent) = (o(out.opacity_logits[a]), o(g.opacity_logits[1]));
        let share = 1.0 / (2.0 * (1.0 - DELTA * DELTA).sqrt());
        assert!((child - share * parent * (1.0 + 0.1 * parent)).abs() < 1e-5, "{child} from {parent}");
        assert_eq!(out.sh[3 * a..3 * a + 3], g.sh[3..6]);
        // The others keep their place and values.
        assert_eq!(out.means[0], g.means[0]);
        assert_eq!(out.means[1], g.means[2]);
    }

    #[test]
    fn splitting_leaves_nothing_large_on_screen_and_the_render_close() {
        let g = wall(4);
        let cams = [camera(64)];
        let before = footprints(&g, &cams);
        assert!(before.iter().cloned().fold(0.0, f32::max) >= 8.0, "{before:?}");
        let (out, report) = split_large(&g, &cams, 2.0, usize::MAX);
        assert!(!report.capped && report.passes > 0, "{report:?}");
        assert_eq!(report.after, out.len());
        let after = footprints(&out, &cams);
        assert!(after.iter().all(|&f| f <= 2.0), "largest {}", after.iter().cloned().fold(0.0, f32::max));
        // The small Gaussians in front are kept as they are.
        assert!(out.log_scales.iter().filter(|s| s[0] == -4.0).count() == 3);
        let opts = RenderOptions { background: [0.0; 3] };
        let (a, b) = (forward(&g, &cams[0], &opts).0, forward(&out, &cams[0], &opts).0);
        let mse: f32 = a.rgb.iter().zip(&b.rgb).map(|(x, y)| (x - y).powi(2)).sum::<f32>() / a.rgb.len() as f32;
        let psnr = -10.0 * mse.log10();
        assert!(psnr > 24.0, "render after the split: {psnr:.1} dB");
    }

    #[test]
    fn the_cap_bounds_the_count_and_splits_the_largest_first() {
        let g = wall(4);
        let cams = [camera(64)];
        let (out, report) = split_large(&g, &cams, 0.5, g.len() + 5);
        assert!(report.capped);
        assert_eq!(out.len(), g.len() + 5);
        // Gaussians no camera sees are never split.
        let behind = Gaussians { means: vec![[0.0, 0.0, -3.0]], ..wall_one() };
        let (same, r) = split_large(&behind, &cams, 0.5, 100);
        assert_eq!((same.len(), r.passes), (1, 0));
    }

    fn wall_one() -> Gaussians {
        let mut g = wall(1);
        g.means.truncate(1);
        g.log_scales.truncate(1);
        g.quats.truncate(1);
        g.opacity_logits.truncate(1);
        g.sh.truncate(3);
        g
    }
}
