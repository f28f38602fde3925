//! Multi-view consistency: does the stylized scene show the same colours at
//! the same surface point from different views?
//!
//! A 2D style transfer applied per frame flickers; a stylized 3D scene should
//! not, except for view-dependent effects. The measure warps view A into view
//! B through A's own rendered depth and the known poses, masks what B cannot
//! see (occlusion, leaving the frame, holes), and reports the RMSE of the colour
//! differences over the pixels that remain. Forward warping splats each covered
//! pixel of A onto the nearest pixel of B, keeping the nearest sample (a z-buffer).
//! Two baselines are measured because a short one tests flicker and a long one
//! tests that the texture is attached to the surface.

use glam::Vec3;

use super::geometry::{back_project, pixel_depth};
use crate::Camera;
use crate::raster::Render;

/// Default relative depth tolerance of the occlusion test: a warped sample at
/// depth `z_w` is visible in B when `|z_w − z_B| ≤ tol · z_B`. 5 % accepts the
/// depth noise of a splatted surface while rejecting surfaces behind others.
pub const DEFAULT_DEPTH_TOLERANCE: f32 = 0.05;

/// The result of warping one view into another.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Consistency {
    /// `sqrt( Σ_valid Σ_c (A_warped − B)² / (3 · valid) )`, RGB clamped to `[0, 1]`
    /// as displayed, so at most 1;
    /// 0 when no pixel is valid.
    pub rmse: f32,
    /// The number of valid pixels: pixels of B covered in B, hit by a warped
    /// covered pixel of A, and passing the occlusion test.
    pub valid: usize,
    /// `valid` over the number of covered pixels of B (alpha ≥ 0.5); 0 when B covers none.
    pub valid_fraction: f32,
}

/// Warps render `a` (from `cam_a`) into render `b` (from `cam_b`) using `a`'s
/// depth (`alpha / inv_depth` where alpha ≥ 0.5) and compares colours; see
/// [`Consistency`] and [`DEFAULT_DEPTH_TOLERANCE`] for `depth_tolerance`.
/// Renders whose size does not match their camera give the default (empty) result.
pub fn warp_consistency(a: &Render, cam_a: &Camera, b: &Render, cam_b: &Camera, depth_tolerance: f32) -> Consistency {
    warp(a, cam_a, b, cam_b, depth_tolerance, None)
}

/// [`warp_consistency`] on the object: only pixels of A marked in `mask_a`
/// are warped and only pixels of B marked in `mask_b` are compared (and count
/// as covered for [`Consistency::valid_fraction`]). With the coverage masks of
/// the colour-matched renders ([`crate::style::focus::coverage_mask`]), what a
/// stylization adds around the object (grown or drifting splats over the
/// background) does not enter the measure. Masks of all ones give
/// [`warp_consistency`]; masks whose size does not match their render give the
/// default (empty) result.
pub fn warp_consistency_masked(
    a: &Render,
    cam_a: &Camera,
    b: &Render,
    cam_b: &Camera,
    depth_tolerance: f32,
    (mask_a, mask_b): (&[bool], &[bool]),
) -> Consistency {
    let pixels = |r: &Render| r.width as usize * r.height as usize;
    if mask_a.len() != pixels(a) || mask_b.len() != pixels(b) {
        return Consistency::default();
    }
    warp(a, cam_a, b, cam_b, depth_tolerance, Some((mask_a, mask_b)))
}

fn warp(
    a: &Render,
    cam_a: &Camera,
    b: &Render,
    cam_b: &Camera,
    depth_tolerance: f32,
    masks: Option<(&[bool], &[bool])>,
) -> Consistency {
    let (wa, ha) = (a.width as usize, a.height as usize);
    let (wb, hb) = (b.width as usize, b.height as usize);
    let sized = |r: &Render, c: &Camera, w: usize, h: usize| {
        (r.width, r.height) == (c.width, c.height) && r.rgb.len() == 3 * w * h && r.alpha.len() == w * h
    };
    if !sized(a, cam_a, wa, ha) || !sized(b, cam_b, wb, hb) {
        return Consistency::default();
    }
    let in_a = |i: usize| masks.is_none_or(|(m, _)| m[i]);
    let in_b = |j: usize| masks.is_none_or(|(_, m)| m[j]);
    // z-buffer of the warped samples in B: (depth in B, source pixel in A).
    let mut zbuf: Vec<Option<(f32, usize)>> = vec![None; wb * hb];
    let a_to_world = cam_a.rotation.transpose();
    for y in 0..ha {
        for x in 0..wa {
            let i = y * wa + x;
            if !in_a(i) {
                continue;
            }
            let Some(z) = pixel_depth(a, i) else { continue };
            let world = a_to_world * (back_project(cam_a, x, y, z) - cam_a.translation);
            let pb: Vec3 = cam_b.world_to_camera(world);
            if pb.z <= 0.0 {
                continue;
            }
            let (u, v) = cam_b.pixel_of(pb).into();
            if !(u >= 0.0 && v >= 0.0 && u < wb as f32 && v < hb as f32) {
                continue;
            }
            let j = v as usize * wb + u as usize;
            if zbuf[j].is_none_or(|(zj, _)| pb.z < zj) {
                zbuf[j] = Some((pb.z, i));
            }
        }
    }
    let (mut sq, mut valid, mut covered) = (0.0f64, 0usize, 0usize);
    for (j, slot) in zbuf.iter().enumerate().filter(|(j, _)| in_b(*j)) {
        let Some(zb) = pixel_depth(b, j) else { continue };
        covered += 1;
        let Some((zw, i)) = *slot else { continue };
        if (zw - zb).abs() > depth_tolerance * zb {
            continue;
        }
        valid += 1;
        for c in 0..3 {
            sq += (f64::from(a.rgb[3 * i + c].clamp(0.0, 1.0)) - f64::from(b.rgb[3 * j + c].clamp(0.0, 1.0))).powi(2);
        }
    }
    let rmse = if valid == 0 { 0.0 } else { (sq / (3 * valid) as f64).sqrt() as f32 };
    let valid_fraction = if covered == 0 { 0.0 } else { valid as f32 / covered as f32 };
    Consistency { rmse, valid, valid_fraction }
}

/// Two view pairs to measure consistency on, as indices into a camera list.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ViewPairs {
    /// The pair with the smallest angle between camera centres seen from the scene centre.
    pub short: Option<(usize, usize)>,
    /// The pair whose angle is closest to [`LONG_BASELINE_DEGREES`].
    pub long: Option<(usize, usize)>,
}

/// The target angle of the long-baseline pair, degrees (middle of 30°–45°).
pub const LONG_BASELINE_DEGREES: f32 = 37.5;

/// Picks a short- and a long-baseline pair from `cameras`, by the angle
/// `∠(c_i − center, c_j − center)` between camera centres around the scene
/// centre `center` (e.g. the robust bounds' centre): the short pair has the
/// smallest positive angle, the long pair the angle closest to
/// [`LONG_BASELINE_DEGREES`]. Ties go to the lowest indices (`i < j`, in order),
/// so the choice is fixed for a camera list. Cameras at the centre or with
/// non-finite centres are skipped; fewer than two usable cameras give no pairs.
pub fn pick_view_pairs(cameras: &[Camera], center: Vec3) -> ViewPairs {
    let dirs: Vec<Option<Vec3>> = cameras.iter().map(|c| (c.center() - center).try_normalize()).collect();
    let mut out = ViewPairs::default();
    let (mut best_short, mut best_long) = (f32::INFINITY, f32::INFINITY);
    for i in 0..dirs.len() {
        let Some(di) = dirs[i] else { continue };
        for (j, dj) in dirs.iter().enumerate().skip(i + 1) {
            let Some(dj) = dj else { continue };
            let angle = di.dot(*dj).clamp(-1.0, 1.0).acos().to_degrees();
            if angle > 1e-3 && angle < best_short {
                (best_short, out.short) = (angle, Some((i, j)));
            }
            let off = (angle - LONG_BASELINE_DEGREES).abs();
            if off < best_long {
                (best_long, out.long) = (off, Some((i, j)));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Gaussians;
    use crate::raster::{RenderOptions, render};

    const C0: f32 = 0.282_094_8;

    /// A square of flat, opaque Gaussians on the plane z = 0 spanning [-1, 1]²,
    /// coloured by `colour(x, y)`.
    fn plane(colour: impl Fn(f32, f32) -> [f32; 3]) -> Gaussians {
        let k = 40;
        let mut g = Gaussians::with_capacity(k * k, 0);
        let step = 2.0 / (k - 1) as f32;
        for a in 0..k {
            for b in 0..k {
                let (x, y) = (-1.0 + a as f32 * step, -1.0 + b as f32 * step);
                g.means.push([x, y, 0.0]);
                g.log_scales.push([(0.8 * step).ln(), (0.8 * step).ln(), (0.01f32).ln()]);
                g.quats.push([1.0, 0.0, 0.0, 0.0]);
                g.opacity_logits.push(5.0);
                g.sh.extend(colour(x, y).map(|c| (c - 0.5) / C0));
            }
        }
        g
    }

    fn cam_at(degrees: f32) -> Camera {
        let t = degrees.to_radians();
        let eye = Vec3::new(3.0 * t.sin(), 0.0, -3.0 * t.cos());
        Camera::look_at(format!("c{degrees}"), eye, Vec3::ZERO, Vec3::NEG_Y, 96, 80, 45.0)
    }

    #[test]
    fn a_static_scene_warps_consistently_and_per_view_colours_do_not() {
        let smooth = |x: f32, y: f32| [0.5 + 0.3 * x, 0.5 + 0.3 * y, 0.5];
        let scene = plane(smooth);
        let (ca, cb) = (cam_at(0.0), cam_at(12.0));
        let opts = RenderOptions::default();
        let (ra, rb) = (render(&scene, &ca, &opts), render(&scene, &cb, &opts));
        let same = warp_consistency(&ra, &ca, &rb, &cb, DEFAULT_DEPTH_TOLERANCE);
        assert!(same.valid_fraction > 0.6, "{same:?}");
        // What remains (≈ 0.02) is the plane's anti-aliased border and the
        // nearest-pixel rounding of the forward warp.
        assert!(same.rmse < 0.03, "{same:?}");

        // The same geometry with other colours from view B: the colours no longer agree.
        let other = plane(|x, y| [0.5 - 0.3 * x, 0.5 - 0.3 * y, 0.9]);
        let rb_other = render(&other, &cb, &opts);
        let differ = warp_consistency(&ra, &ca, &rb_other, &cb, DEFAULT_DEPTH_TOLERANCE);
        assert!(differ.valid_fraction > 0.6, "{differ:?}");
        assert!(differ.rmse > 0.2 && differ.rmse > 10.0 * same.rmse, "{differ:?} vs {same:?}");
    }

    #[test]
    fn the_masked_measure_ignores_pixels_outside_the_masks() {
        let scene = plane(|x, y| [0.5 + 0.3 * x, 0.5 + 0.3 * y, 0.5]);
        let (ca, cb) = (cam_at(0.0), cam_at(12.0));
        let opts = RenderOptions::default();
        let (ra, rb) = (render(&scene, &ca, &opts), render(&scene, &cb, &opts));
        let ones = |r: &Render| vec![true; r.alpha.len()];
        let plain = warp_consistency(&ra, &ca, &rb, &cb, DEFAULT_DEPTH_TOLERANCE);
        let all = warp_consistency_masked(&ra, &ca, &rb, &cb, DEFAULT_DEPTH_TOLERANCE, (&ones(&ra), &ones(&rb)));
        assert_eq!(all, plain, "masks of all ones are the unmasked measure");

        // The right half of each image keeps only its left half: repainting the
        // right halves (in A and in B) changes the plain measure, not the masked one.
        let left = |r: &Render| -> Vec<bool> { (0..r.alpha.len()).map(|i| i % r.width as usize <= 40).collect() };
        let (ma, mb) = (left(&ra), left(&rb));
        let masked = warp_consistency_masked(&ra, &ca, &rb, &cb, DEFAULT_DEPTH_TOLERANCE, (&ma, &mb));
        assert!(masked.valid > 100 && masked.valid < plain.valid, "{masked:?} vs {plain:?}");
        let repaint = |r: &Render, colour: [f32; 3]| {
            let mut r = r.clone();
            let w = r.width as usize;
            for (i, px) in r.rgb.chunks_exact_mut(3).enumerate() {
                if i % w > 40 {
                    px.copy_from_slice(&colour);
                }
            }
            r
        };
        let (pa, pb) = (repaint(&ra, [1.0, 0.0, 0.0]), repaint(&rb, [0.0, 0.0, 1.0]));
        let plain_painted = warp_consistency(&pa, &ca, &pb, &cb, DEFAULT_DEPTH_TOLERANCE);
        assert!(plain_painted.rmse > 5.0 * plain.rmse.max(0.01), "{plain_painted:?} vs {plain:?}");
        let masked_painted = warp_consistency_masked(&pa, &ca, &pb, &cb, DEFAULT_DEPTH_TOLERANCE, (&ma, &mb));
        assert_eq!(masked_painted, masked);
        // A mask of the wrong size: no result.
        let short = vec![true; 3];
        assert_eq!(
            warp_consistency_masked(&ra, &ca, &rb, &cb, DEFAULT_DEPTH_TOLERANCE, (&short, &mb)),
            Consistency::default()
        );
    }

    #[test]
    fn occluded_and_empty_views_have_no_valid_pixels() {
        let scene = plane(|_, _| [0.7, 0.2, 0.2]);
        let (ca, cb) = (cam_at(0.0), cam_at(12.0));
        let opts = RenderOptions::default();
        let ra = render(&scene, &ca, &opts);
        // B sees the same plane moved 1 unit back: every warped sample fails the depth test.
        let mut behind = scene.clone();
        behind.means.iter_mut().for_each(|m| m[2] += 1.0);
        let rb = render(&behind, &cb, &opts);
        let c = warp_consistency(&ra, &ca, &rb, &cb, DEFAULT_DEPTH_TOLERANCE);
        assert_eq!((c.valid, c.rmse), (0, 0.0), "{c:?}");
        assert!(c.valid_fraction == 0.0);
        let empty = Render::zeros(0, 0);
        let c0 = Camera { width: 0, height: 0, ..ca.clone() };
        assert_eq!(warp_consistency(&empty, &c0, &empty, &c0, 0.05), Consistency::default());
        assert_eq!(warp_consistency(&ra, &cb, &empty, &c0, 0.05), Consistency::default());
    }

    #[test]
    fn view_pairs_are_the_nearest_and_the_one_nearest_37_5_degrees() {
        let cams: Vec<Camera> = [0.0, 50.0, 10.0, 4.0, 90.0].into_iter().map(cam_at).collect();
        let pairs = pick_view_pairs(&cams, Vec3::ZERO);
        assert_eq!(pairs.short, Some((0, 3))); // 4°
        // 50 − 10 = 40° is closest to 37.5° (|2.5|); 50 − 4 = 46 (8.5), 90 − 50 = 40 too but later.
        assert_eq!(pairs.long, Some((1, 2)));
        assert_eq!(pick_view_pairs(&cams[..1], Vec3::ZERO), ViewPairs::default());
        assert_eq!(pick_view_pairs(&[], Vec3::ZERO), ViewPairs::default());
    }
}
