//! The starting scene: one Gaussian per SfM point when the dataset has
//! COLMAP's `points3D` (as the 3DGS trainer starts), else random Gaussians in
//! the region every camera looks at.
//!
//! From SfM points, each Gaussian takes its point's colour (as the SH band-0
//! coefficient) and an isotropic scale from the root mean square distance to
//! its three nearest neighbours (the trainer's `distCUDA2`), with identity
//! rotation and the configured opacity.
//!
//! The region is derived from the cameras alone: the point closest (least
//! squares) to all optical axes is the centre, and the half-width of the view
//! at that point (mean distance × the smaller `tan(half-fov)`) is the radius
//! of a cube around it. Points of the cube that some camera cannot see (behind
//! it or outside its image) are rejected, so the samples fill the intersection
//! of the frusta. For NeRF-synthetic lego this gives a cube of half-side ≈1.45
//! around the origin, the box the object sits in.

use glam::{DMat3, DVec3, Vec3};

use crate::camera::{Camera, ColmapPoints};
use crate::scene::{Gaussians, SH_C0};

pub(crate) use crate::rng::Rng;

/// The centre and half-side of the cube the cameras look at.
pub fn look_at_region(cameras: &[Camera]) -> (Vec3, f32) {
    if cameras.is_empty() {
        return (Vec3::ZERO, 1.0);
    }
    // Σ (I − d dᵀ) p = Σ (I − d dᵀ) c over the optical axes (c, d).
    let (mut a, mut b) = (DMat3::ZERO, DVec3::ZERO);
    for cam in cameras {
        let c = cam.center().as_dvec3();
        let d = (cam.rotation.transpose() * Vec3::Z).as_dvec3().normalize_or_zero();
        let m = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += m;
        b += m * c;
    }
    let centroid = cameras.iter().map(|c| c.center()).sum::<Vec3>() / cameras.len() as f32;
    // Parallel axes (a single camera, a forward-facing rig) leave `a` singular:
    // then the point on the mean axis at the mean distance stands in.
    let centre = if a.determinant().abs() > 1e-6 * cameras.len() as f64 {
        (a.inverse() * b).as_vec3()
    } else {
        let d = cameras.iter().map(|c| c.rotation.transpose() * Vec3::Z).sum::<Vec3>().normalize_or(Vec3::Z);
        centroid + d * centroid.length().max(1.0)
    };
    let mut dist = 0.0;
    let mut tan = f32::INFINITY;
    for cam in cameras {
        dist += cam.world_to_camera(centre).z.max(1e-3);
        let (tx, ty) = cam.tan_half_fov();
        tan = tan.min(tx.min(ty));
    }
    let radius = dist / cameras.len() as f32 * tan;
    (centre, if radius.is_finite() && radius > 0.0 { radius } else { 1.0 })
}

/// Whether every camera sees `p` (in front of it and inside its image).
fn seen_by_all(cameras: &[Camera], p: Vec3) -> bool {
    cameras.iter().all(|cam| {
        cam.project(p)
            .is_some_and(|uv| uv.x >= 0.0 && uv.y >= 0.0 && uv.x < cam.width as f32 && uv.y < cam.height as f32)
    })
}

/// `n` random Gaussians in the cameras' common view: random colours,
/// isotropic scales from the mean distance to the three nearest neighbours,
/// identity rotations and opacity `opacity`.
pub(crate) fn random_gaussians(cameras: &[Camera], n: usize, sh_degree: u32, opacity: f32, rng: &mut Rng) -> Gaussians {
    let (centre, radius) = look_at_region(cameras);
    let mut means = Vec::with_capacity(n);
    // Rejection sampling; after many misses (cameras that share no view) the
    // cube itself is used.
    let mut tries = 0usize;
    while means.len() < n {
        let p = centre + radius * Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()).map(|v| 2.0 * v - 1.0);
        tries += 1;
        if tries > 200 * n.max(1) || seen_by_all(cameras, p) {
            means.push(p);
        }
    }
    let dists = mean_knn_distance(&means, 3, KnnMean::Arithmetic);
    let mut g = Gaussians::with_capacity(n, sh_degree);
    let k = g.sh_coeffs() * 3;
    let logit = (opacity / (1.0 - opacity)).ln();
    for (p, d) in means.iter().zip(dists) {
        g.means.push(p.to_array());
        g.log_scales.push([d.max(1e-7).ln(); 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(logit);
        let start = g.sh.len();
        g.sh.resize(start + k, 0.0);
        for c in 0..3 {
            g.sh[start + c] = (rng.uniform() - 0.5) / SH_C0;
        }
    }
    g
}

/// One Gaussian per SfM point: the point's colour, isotropic scale from the
/// root mean square distance to its three nearest neighbours, identity
/// rotation and opacity `opacity`.
pub(crate) fn sfm_gaussians(points: &ColmapPoints, sh_degree: u32, opacity: f32) -> Gaussians {
    let dists = mean_knn_distance(&points.positions, 3, KnnMean::Quadratic);
    let mut g = Gaussians::with_capacity(points.len(), sh_degree);
    let k = g.sh_coeffs() * 3;
    let logit = (opacity / (1.0 - opacity)).ln();
    for ((p, rgb), d) in points.positions.iter().zip(&points.colors).zip(dists) {
        g.means.push(p.to_array());
        g.log_scales.push([d.max(1e-7).ln(); 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(logit);
        let start = g.sh.len();
        g.sh.resize(start + k, 0.0);
        for (c, v) in rgb.iter().enumerate() {
            g.sh[start + c] = (f32::from(*v) / 255.0 - 0.5) / SH_C0;
        }
    }
    g
}

/// How [`mean_knn_distance`] averages the neighbour distances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum KnnMean {
    /// The mean distance.
    Arithmetic,
    /// The root of the mean squared distance (the 3DGS trainer's SfM scales).
    Quadratic,
}

/// Per point, the mean distance to its `k` nearest other points (`k ≤ 8`; with
/// fewer other points, all of them), on a uniform grid with about two points
/// per cell. The search grows shell by shell of cells around a point until no
/// unsearched cell can hold a nearer point, so the result is exact; for dense
/// points only the 27 cells around each are read. One point alone gets 1e-3.
pub(crate) fn mean_knn_distance(points: &[Vec3], k: usize, mean: KnnMean) -> Vec<f32> {
    let n = points.len();
    if n < 2 {
        return vec![1e-3; n];
    }
    let (lo, hi) =
        points.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(l, h), &p| (l.min(p), h.max(p)));
    let size = (hi - lo).max(Vec3::splat(1e-6));
    let cell = (size.x * size.y * size.z * 2.0 / n as f32).cbrt().max(size.max_element() / 1024.0);
    let dims = ((size / cell).floor().as_uvec3() + 1).min(glam::UVec3::splat(1024));
    let index = |p: Vec3| ((p - lo) / cell).floor().as_uvec3().min(dims - 1);
    let flat = |c: glam::UVec3| ((c.z * dims.y + c.y) * dims.x + c.x) as usize;
    let ncell = (dims.x * dims.y * dims.z) as usize;
    let mut starts = vec![0u32; ncell + 1];
    for &p in points {
        starts[flat(index(p)) + 1] += 1;
    }
    for i in 0..ncell {
        starts[i + 1] += starts[i];
    }
    let mut fill = starts.clone();
    let mut order = vec![0u32; n];
    for (i, &p) in points.iter().enumerate() {
        let c = flat(index(p));
        order[fill[c] as usize] = i as u32;
        fill[c] += 1;
    }
    use rayon::prelude::*;
    (0..n)
        .into_par_iter()
        .map(|i| {
            let p = points[i];
            let c = index(p).as_ivec3();
            let mut best = [f32::INFINITY; 8];
            let k = k.clamp(1, 8);
            let visit = |q: glam::IVec3, best: &mut [f32; 8]| {
                let f = flat(q.as_uvec3());
                for &j in &order[starts[f] as usize..starts[f + 1] as usize] {
                    if j as usize == i {
                        continue;
                    }
                    let d2 = p.distance_squared(points[j as usize]);
                    if d2 < best[k - 1] {
                        let mut s = k - 1;
                        while s > 0 && best[s - 1] > d2 {
                            best[s] = best[s - 1];
                            s -= 1;
                        }
                        best[s] = d2;
                    }
                }
            };
            let hi = dims.as_ivec3() - 1;
            let mut r = 0i32;
            loop {
                // The shell of cells at Chebyshev distance r, clipped to the grid.
                let (lo_q, hi_q) = ((c - r).max(glam::IVec3::ZERO), (c + r).min(hi));
                for z in lo_q.z..=hi_q.z {
                    for y in lo_q.y..=hi_q.y {
                        if (z - c.z).abs() == r || (y - c.y).abs() == r {
                            (lo_q.x..=hi_q.x).for_each(|x| visit(glam::IVec3::new(x, y, z), &mut best));
                        } else {
                            // Inside the shell's faces (r > 0 here): only its two x walls.
                            for x in [c.x - r, c.x + r] {
                                if x >= 0 && x <= hi.x {
                                    visit(glam::IVec3::new(x, y, z), &mut best);
                                }
                            }
                        }
                    }
                }
                // Points outside the searched cube are at least r cells away.
                let reach = r as f32 * cell;
                if best[k - 1] <= reach * reach || r >= hi.max_element() {
                    break;
                }
                r += 1;
            }
            let found = best[..k].iter().filter(|d| d.is_finite()).count().max(1);
            let d = best[..k].iter().filter(|d| d.is_finite()).map(|d| d.sqrt());
            match mean {
                KnnMean::Arithmetic => d.sum::<f32>() / found as f32,
                KnnMean::Quadratic => (d.map(|d| d * d).sum::<f32>() / found as f32).sqrt(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knn_matches_brute_force() {
        let mut rng = Rng::new(3);
        let pts: Vec<Vec3> = (0..500).map(|_| Vec3::new(rng.uniform(), rng.uniform(), 2.0 * rng.uniform())).collect();
        let fast = mean_knn_distance(&pts, 3, KnnMean::Arithmetic);
        let rms = mean_knn_distance(&pts, 3, KnnMean::Quadratic);
        for (i, p) in pts.iter().enumerate() {
            let mut d: Vec<f32> =
                pts.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, q)| p.distance(*q)).collect();
            d.sort_by(f32::total_cmp);
            let want = (d[0] + d[1] + d[2]) / 3.0;
            assert!((fast[i] - want).abs() <= 1e-5 * want, "point {i}: {} vs {want}", fast[i]);
            let want = ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / 3.0).sqrt();
            assert!((rms[i] - want).abs() <= 1e-5 * want, "point {i}: rms {} vs {want}", rms[i]);
        }
    }

    #[test]
    fn sfm_points_keep_their_colour_and_neighbour_scale() {
        // Four corners of a unit square: the three nearest of each are at 1, 1 and √2.
        let positions: Vec<Vec3> =
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]].map(Vec3::from).to_vec();
        let colors = vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]];
        let g = sfm_gaussians(&ColmapPoints { positions: positions.clone(), colors }, 1, 0.1);
        assert_eq!(g.len(), 4);
        assert!(g.check_consistent().is_ok());
        let want = (4.0f32 / 3.0).sqrt().ln();
        for (i, p) in positions.iter().enumerate() {
            assert_eq!(g.means[i], p.to_array());
            assert!(g.log_scales[i].iter().all(|s| (s - want).abs() < 1e-5), "{:?} vs {want}", g.log_scales[i]);
            assert_eq!(g.quats[i], [1.0, 0.0, 0.0, 0.0]);
            assert!((1.0 / (1.0 + (-g.opacity_logits[i]).exp()) - 0.1).abs() < 1e-6);
        }
        // Band 0 decodes to the point's colour; the higher band starts at zero.
        let k = g.sh_coeffs() * 3;
        assert!((g.sh[0] * SH_C0 + 0.5 - 1.0).abs() < 1e-6 && (g.sh[1] * SH_C0 + 0.5).abs() < 1e-6);
        assert!((g.sh[3 * k + 2] * SH_C0 + 0.5 - 128.0 / 255.0).abs() < 1e-6);
        assert!(g.sh[3..k].iter().all(|v| *v == 0.0));
    }

    #[test]
    fn region_of_a_ring_of_cameras_is_their_target() {
        let cams: Vec<Camera> = (0..8)
            .map(|i| {
                let a = i as f32 * std::f32::consts::TAU / 8.0;
                let eye = Vec3::new(4.0 * a.cos(), 1.0, 4.0 * a.sin()) + Vec3::new(0.5, 0.0, 0.0);
                Camera::look_at(format!("c{i}"), eye, Vec3::new(0.5, 0.0, 0.0), Vec3::Y, 64, 64, 40.0)
            })
            .collect();
        let (c, r) = look_at_region(&cams);
        assert!(c.distance(Vec3::new(0.5, 0.0, 0.0)) < 1e-3, "{c}");
        let want = 17f32.sqrt() * 20f32.to_radians().tan();
        assert!((r - want).abs() < 1e-3, "{r} vs {want}");
    }
}
