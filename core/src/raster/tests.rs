//! Unit tests of the rasterizer: the tiled path against the dense reference on
//! random scenes, and the backward pass against central finite differences of
//! the dense `f64` renderer.

use glam::{Mat3, Vec3};

use super::dense::render_f64;
use super::forward::gaussian_ref;
use super::project::{CamConsts, project};
use super::{RenderOptions, backward, dense, forward, render};
use crate::camera::Camera;
use crate::scene::{Gaussians, sh_coeffs_for_degree};

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in `[a, b)`.
    fn uniform(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * ((self.next_u64() >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// A pinhole camera at `eye` looking at `target` (y down in the image).
pub(crate) fn look_at(eye: Vec3, target: Vec3, width: u32, height: u32, focal: f32) -> Camera {
    let fwd = (target - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let down = fwd.cross(right);
    // Rows of R are the camera axes in world space.
    let rotation = Mat3::from_cols(right, down, fwd).transpose();
    Camera {
        name: "test".into(),
        width,
        height,
        fx: focal,
        fy: focal,
        cx: width as f32 / 2.0,
        cy: height as f32 / 2.0,
        rotation,
        translation: -(rotation * eye),
    }
}

/// Random Gaussians spread over (and past) the view of `cam`, camera-space
/// depth in `[z0, z1]`, log-scales in `[s0, s1]`, opacity logits in `[o0, o1]`.
#[allow(clippy::too_many_arguments)]
fn random_scene(
    rng: &mut Rng,
    cam: &Camera,
    n: usize,
    deg: u32,
    (z0, z1): (f32, f32),
    (s0, s1): (f32, f32),
    (o0, o1): (f32, f32),
    spread: f32,
) -> Gaussians {
    let mut g = Gaussians::with_capacity(n, deg);
    let (tx, ty) = cam.tan_half_fov();
    let inv = cam.rotation.transpose();
    for _ in 0..n {
        let z = rng.uniform(z0, z1);
        let x = rng.uniform(-spread, spread) * tx * z;
        let y = rng.uniform(-spread, spread) * ty * z;
        g.means.push((inv * (Vec3::new(x, y, z) - cam.translation)).to_array());
        g.log_scales.push(std::array::from_fn(|_| rng.uniform(s0, s1)));
        g.quats.push(std::array::from_fn(|_| rng.uniform(-1.0, 1.0)));
        g.opacity_logits.push(rng.uniform(o0, o1));
        for k in 0..sh_coeffs_for_degree(deg) {
            for _ in 0..3 {
                g.sh.push(if k == 0 { rng.uniform(-0.5, 1.5) } else { rng.uniform(-0.05, 0.05) });
            }
        }
    }
    g
}

/// Whether some Gaussian's α at pixel `q` lies within `f32` rounding of the
/// 1/255 cut-off, where the `f32` and `f64` renderers may legitimately decide
/// differently.
fn near_cutoff(g: &Gaussians, cam: &Camera, q: usize) -> bool {
    let cc = CamConsts::new(cam);
    let (px, py) = ((q % cam.width as usize) as f32 + 0.5, (q / cam.width as usize) as f32 + 0.5);
    (0..g.len()).filter_map(|i| project(&gaussian_ref(g, i), &cc)).any(|s| {
        let (dx, dy) = (px - s.xy[0], py - s.xy[1]);
        let power = -0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
        (s.opacity * power.exp() * 255.0 - 1.0).abs() < 1e-4
    })
}

#[test]
fn tiled_matches_dense_on_random_scenes() {
    let mut report = Vec::new();
    let mut ties = 0;
    for seed in 0..6u64 {
        for deg in [0, 3] {
            let mut rng = Rng(seed * 17 + u64::from(deg));
            // Not a multiple of the tile size, so edge tiles are partial.
            let cam = look_at(Vec3::new(0.3, -0.2, -4.0), Vec3::ZERO, 75, 53, 60.0);
            // Spread 1.2: some Gaussians sit across and beyond the image border.
            let g = random_scene(&mut rng, &cam, 400, deg, (1.0, 6.0), (-4.5, -1.5), (-3.0, 4.0), 1.2);
            let opts = RenderOptions { background: [0.2, 0.4, 0.7] };
            let fast = render(&g, &cam, &opts);
            let slow = dense::render(&g, &cam, &opts);
            for q in 0..fast.alpha.len() {
                let e = (0..3)
                    .map(|c| (fast.rgb[3 * q + c] - slow.rgb[3 * q + c]).abs())
                    .chain([(fast.inv_depth[q] - slow.inv_depth[q]).abs(), (fast.alpha[q] - slow.alpha[q]).abs()])
                    .fold(0.0f32, |m, x| if x.is_nan() { f32::INFINITY } else { m.max(x) });
                if e >= 1e-5 {
                    if near_cutoff(&g, &cam, q) {
                        ties += 1;
                        println!("seed {seed} deg {deg} pixel {q}: differs by {e:.3e} at an α = 1/255 tie");
                    } else {
                        report.push(format!("seed {seed} deg {deg} pixel {q}: max abs diff {e:.3e}"));
                    }
                }
            }
            // The same pass with state must give the same image.
            assert_eq!(forward(&g, &cam, &opts).0, fast);
        }
    }
    assert!(ties <= 3, "{ties} pixels at α = 1/255 ties: more than rounding explains");
    assert!(report.is_empty(), "tiled and dense renders differ:\n{}", report.join("\n"));
}

#[test]
fn empty_and_offscreen_scenes_render_background() {
    let cam = look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, 33, 17, 30.0);
    let opts = RenderOptions { background: [0.1, 0.2, 0.3] };
    let mut g = Gaussians::with_capacity(1, 0);
    let img = render(&g, &cam, &opts);
    assert!(img.rgb.chunks_exact(3).all(|p| p == [0.1, 0.2, 0.3]));
    // One Gaussian behind the camera.
    g.means.push([0.0, 0.0, -6.0]);
    g.log_scales.push([0.0; 3]);
    g.quats.push([1.0, 0.0, 0.0, 0.0]);
    g.opacity_logits.push(5.0);
    g.sh.extend([1.0; 3]);
    let (img, state) = forward(&g, &cam, &opts);
    assert_eq!(state.visible(), 0);
    assert!(img.alpha.iter().all(|&a| a == 0.0));
    let grads = backward(&g, &cam, &opts, &state, &vec![1.0; 33 * 17 * 3], &vec![1.0; 33 * 17]);
    assert_eq!(grads.v_means, vec![[0.0; 3]]);
}

/// A scene for finite differences: few, large, half-transparent Gaussians at
/// well separated depths, all inside the view, so that at every pixel every
/// Gaussian has 1/255 < α < 0.99, the transmittance stays far above 1e-4,
/// colours stay positive and the Jacobian clamp is inactive.
///
/// With `beyond_clamp`, the first Gaussian sits right of the view at
/// `x/z = 1.7·tan(half-fov)`, where the Jacobian clamps `x/z` to 1.3, and is
/// made large enough to cover the whole image.
fn fd_scene(seed: u64, deg: u32, beyond_clamp: bool) -> (Gaussians, Camera) {
    let mut rng = Rng(seed);
    let cam = look_at(Vec3::new(0.2, 0.1, -3.0), Vec3::ZERO, 40, 36, 30.0);
    let n = 6;
    let mut g = random_scene(&mut rng, &cam, n, deg, (2.0, 4.0), (1.1, 1.8), (-0.8, 0.4), 0.6);
    // Depths 2.0, 2.35, 2.7, … in camera space, whatever the random draw.
    let inv = cam.rotation.transpose();
    for (k, m) in g.means.iter_mut().enumerate() {
        let mut c = cam.world_to_camera(Vec3::from(*m));
        c *= (2.0 + 0.35 * k as f32) / c.z;
        if beyond_clamp && k == 0 {
            c.x = 1.7 * cam.tan_half_fov().0 * c.z;
            g.log_scales[0] = [2.0, 1.9, 2.1];
        }
        *m = (inv * (c - cam.translation)).to_array();
    }
    (g, cam)
}

/// `L = Σ rgb·cot_rgb + Σ inv_depth·cot_depth` of the dense `f64` render.
fn dense_loss(g: &Gaussians, cam: &Camera, opts: &RenderOptions, cot_rgb: &[f32], cot_d: &[f32]) -> f64 {
    let r = render_f64(g, cam, opts);
    let a: f64 = r.rgb.iter().zip(cot_rgb).map(|(x, c)| x * f64::from(*c)).sum();
    let b: f64 = r.inv_depth.iter().zip(cot_d).map(|(x, c)| x * f64::from(*c)).sum();
    a + b
}

/// Which parameter array a finite difference perturbs.
#[derive(Clone, Copy, Debug)]
enum Group {
    Means,
    LogScales,
    Quats,
    Opacity,
    Sh,
}

fn param(g: &mut Gaussians, group: Group, k: usize) -> &mut f32 {
    match group {
        Group::Means => &mut g.means[k / 3][k % 3],
        Group::LogScales => &mut g.log_scales[k / 3][k % 3],
        Group::Quats => &mut g.quats[k / 4][k % 4],
        Group::Opacity => &mut g.opacity_logits[k],
        Group::Sh => &mut g.sh[k],
    }
}

fn check_fd(seed: u64, deg: u32, background: [f32; 3], beyond_clamp: bool) -> Vec<String> {
    let (g, cam) = fd_scene(seed, deg, beyond_clamp);
    let opts = RenderOptions { background };
    let npx = (cam.width * cam.height) as usize;
    let mut rng = Rng(seed ^ 0xabc);
    let cot_rgb: Vec<f32> = (0..3 * npx).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let cot_d: Vec<f32> = (0..npx).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let (_, state) = forward(&g, &cam, &opts);
    assert_eq!(state.visible(), g.len(), "every Gaussian of the FD scene must be visible");
    let grads = backward(&g, &cam, &opts, &state, &cot_rgb, &cot_d);
    let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let groups = [
        (Group::Means, flat(&grads.v_means)),
        (Group::LogScales, flat(&grads.v_log_scales)),
        (Group::Quats, grads.v_quats.iter().flatten().copied().collect()),
        (Group::Opacity, grads.v_opacity_logits.clone()),
        (Group::Sh, grads.v_sh.clone()),
    ];
    let mut failures = Vec::new();
    for (group, analytic) in groups {
        let scale = analytic.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        for (k, &a) in analytic.iter().enumerate() {
            let mut gp = g.clone();
            let x0 = *param(&mut gp, group, k);
            let h = 1e-3 * x0.abs().max(1.0);
            *param(&mut gp, group, k) = x0 + h;
            let xp = *param(&mut gp, group, k);
            let lp = dense_loss(&gp, &cam, &opts, &cot_rgb, &cot_d);
            *param(&mut gp, group, k) = x0 - h;
            let xm = *param(&mut gp, group, k);
            let lm = dense_loss(&gp, &cam, &opts, &cot_rgb, &cot_d);
            let numeric = (lp - lm) / f64::from(xp - xm);
            let tol = 1e-4 * f64::from(scale) + 1e-2 * numeric.abs();
            if (f64::from(a) - numeric).abs() > tol || a.is_nan() {
                failures.push(format!(
                    "seed {seed} deg {deg} {group:?}[{k}]: analytic {a:.6e}, numeric {numeric:.6e} (tol {tol:.2e})"
                ));
            }
        }
    }
    failures
}

#[test]
fn backward_matches_finite_differences() {
    let mut failures = Vec::new();
    for (seed, deg, bg, clamp) in [
        (1, 0, [0.0; 3], false),
        (2, 3, [0.3, 0.6, 0.9], false),
        (3, 1, [1.0, 0.0, 0.5], false),
        (4, 3, [0.0; 3], false),
        (5, 2, [0.2; 3], true),
    ] {
        failures.extend(check_fd(seed, deg, bg, clamp));
    }
    assert!(failures.is_empty(), "{} gradient entries disagree:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn backward_is_deterministic() {
    let (g, cam) = fd_scene(7, 3, false);
    let opts = RenderOptions::default();
    let npx = (cam.width * cam.height) as usize;
    let (_, state) = forward(&g, &cam, &opts);
    let a = backward(&g, &cam, &opts, &state, &vec![0.5; 3 * npx], &vec![-0.25; npx]);
    let b = backward(&g, &cam, &opts, &state, &vec![0.5; 3 * npx], &vec![-0.25; npx]);
    assert_eq!(a, b);
}

/// Asking for the DC's SH gradient, or none, leaves every other gradient as
/// the whole backward's to the bit, on a degree-3 scene (the direction's
/// gradient through the colour counts every coefficient either way).
#[test]
fn backward_of_fewer_sh_coefficients_keeps_the_other_gradients() {
    use super::{ShGrads, backward_sh};
    let (g, cam) = fd_scene(7, 3, false);
    let opts = RenderOptions::default();
    let npx = (cam.width * cam.height) as usize;
    let (_, state) = forward(&g, &cam, &opts);
    let (v_rgb, v_d): (Vec<f32>, Vec<f32>) =
        ((0..3 * npx).map(|i| ((i * 37 % 101) as f32 - 50.0) / 50.0).collect(), vec![-0.25; npx]);
    let all = backward(&g, &cam, &opts, &state, &v_rgb, &v_d);
    let dc = backward_sh(&g, &cam, &opts, &state, &v_rgb, &v_d, ShGrads::Dc);
    let skip = backward_sh(&g, &cam, &opts, &state, &v_rgb, &v_d, ShGrads::Skip);
    let k = g.sh_coeffs() * 3;
    assert_eq!(k, 48);
    let all_dc: Vec<f32> = all.v_sh.chunks_exact(k).flat_map(|c| c[..3].to_vec()).collect();
    assert_eq!(dc.v_sh, all_dc);
    assert!(all_dc.iter().any(|&v| v != 0.0) && all.v_sh.len() == g.len() * k && skip.v_sh.is_empty());
    for other in [&dc, &skip] {
        assert_eq!(other.v_means, all.v_means);
        assert_eq!(other.v_log_scales, all.v_log_scales);
        assert_eq!(other.v_quats, all.v_quats);
        assert_eq!(other.v_opacity_logits, all.v_opacity_logits);
    }
}

#[test]
fn exp_neg_is_accurate() {
    let mut worst = 0.0f64;
    for k in 0..=200_000 {
        let x = -20.0 * k as f32 / 200_000.0;
        let want = f64::from(x).exp();
        worst = worst.max((f64::from(super::splat::exp_neg(x)) - want).abs() / want);
    }
    assert!(worst < 3e-7, "exp_neg relative error {worst:.3e}");
    assert_eq!(super::splat::exp_neg(0.0), 1.0);
}

#[test]
fn tile_test_and_row_spans_cover_every_reachable_pixel() {
    // Random splats of every shape against one tile: wherever a pixel can reach
    // α ≥ 1/255, the tile test must say yes and the row span must include it.
    let mut rng = Rng(99);
    let cam = look_at(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO, 64, 64, 50.0);
    let cc = CamConsts::new(&cam);
    let g = random_scene(&mut rng, &cam, 3000, 0, (1.0, 5.0), (-5.0, -0.5), (-5.0, 6.0), 1.5);
    let (x0, x1, y0, y1) = (16, 32, 32, 48);
    let mut misses = Vec::new();
    for i in 0..g.len() {
        let Some(s) = project(&gaussian_ref(&g, i), &cc) else { continue };
        let touches = s.touches_rect(x0, x1, y0, y1);
        for y in y0..y1 {
            let (ja, jb) = s.row_span(i64::from(y), x0, x1);
            for x in x0..x1 {
                let (dx, dy) = (x as f32 + 0.5 - s.xy[0], y as f32 + 0.5 - s.xy[1]);
                let power = -0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
                if s.opacity * f64::from(power).exp() as f32 >= 1.0 / 255.0 {
                    let in_span = (ja..=jb).contains(&i64::from(x));
                    if !touches || !in_span {
                        misses.push(format!("Gaussian {i} pixel ({x}, {y}): tile {touches}, span {in_span}"));
                    }
                }
            }
        }
    }
    assert!(misses.is_empty(), "{} reachable pixels missed:\n{}", misses.len(), misses.join("\n"));
}

#[test]
fn non_finite_gaussians_are_skipped() {
    let cam = look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, 32, 32, 30.0);
    let mut rng = Rng(5);
    let mut g = random_scene(&mut rng, &cam, 4, 0, (2.0, 3.0), (-2.0, -1.0), (0.0, 2.0), 0.5);
    g.opacity_logits[0] = f32::NAN;
    g.means[1][0] = f32::NAN;
    g.log_scales[2][1] = f32::INFINITY;
    g.quats[3] = [0.0; 4];
    let (img, state) = forward(&g, &cam, &RenderOptions::default());
    assert_eq!(state.visible(), 0);
    assert!(img.rgb.iter().chain(&img.alpha).all(|&v| v == 0.0));
}

#[test]
fn gradients_follow_their_gaussians_when_the_order_changes() {
    // Enough Gaussians to span several parallel chunks of the per-Gaussian
    // pass; reversing their order must reverse the gradients, bit for bit
    // (compositing order is by depth, not by index).
    let mut rng = Rng(2024);
    let cam = look_at(Vec3::new(0.4, -0.3, -4.0), Vec3::ZERO, 64, 48, 50.0);
    let g = random_scene(&mut rng, &cam, 10_000, 1, (1.0, 6.0), (-4.5, -2.5), (-3.0, 3.0), 1.1);
    let mut rev = g.clone();
    rev.means.reverse();
    rev.log_scales.reverse();
    rev.quats.reverse();
    rev.opacity_logits.reverse();
    rev.sh = g.sh.chunks_exact(12).rev().flatten().copied().collect();
    let opts = RenderOptions { background: [0.1, 0.2, 0.3] };
    let npx = 64 * 48;
    let v_rgb: Vec<f32> = (0..3 * npx).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let v_d: Vec<f32> = (0..npx).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let (img, state) = forward(&g, &cam, &opts);
    let (img_rev, state_rev) = forward(&rev, &cam, &opts);
    assert_eq!(img, img_rev);
    let a = backward(&g, &cam, &opts, &state, &v_rgb, &v_d);
    let mut b = backward(&rev, &cam, &opts, &state_rev, &v_rgb, &v_d);
    b.v_means.reverse();
    b.v_log_scales.reverse();
    b.v_quats.reverse();
    b.v_opacity_logits.reverse();
    b.v_sh = b.v_sh.chunks_exact(12).rev().flatten().copied().collect();
    assert_eq!(a, b);
    assert!(a.v_means.iter().filter(|m| **m != [0.0; 3]).count() > 1000, "too few Gaussians got a gradient");
}
