//! Photometric reconstruction: a 3DGS scene fitted to posed photographs with
//! the project's own differentiable rasterizer.
//!
//! Why it exists: datasets such as NeRF-synthetic come with images and poses
//! but no Gaussian scene, and stylization needs one. This is plain 3DGS
//! training kept small: the dataset's SfM points as the initial Gaussians when
//! it has COLMAP's `points3D` (else random ones in the region the cameras look
//! at, e.g. for NeRF-synthetic), an L1 photometric loss on one view per
//! iteration, Adam with the original trainer's learning rates (the means' rate
//! decays exponentially and scales with the scene extent), and the trainer's
//! clone/split/prune densification driven by the view-space gradient of the
//! means. Departures from the original, for brevity: no D-SSIM term, no
//! opacity reset, and the Adam moments restart after each densification (the
//! trainer keeps those of the surviving Gaussians). One addition: photos with
//! an alpha channel are composited on a random colour at each iteration
//! ([`FitConfig::random_background`]), where the trainer keeps one fixed
//! background, so that the space around an object ends transparent. A checkpoint keeps the
//! fit's whole state ([`FitState`]), so a fit resumed from one is the fit run
//! through.
//!
//! The view-space gradient is not exposed by the rasterizer, so it is
//! recovered from the world-space gradient of the mean: `∂L/∂t = R ∂L/∂μ` in
//! camera space, times `z/f` per pixel and `W/2` into NDC. It also contains the
//! covariance's and the colour's dependence on the mean, which the trainer's
//! does not; the threshold is the trainer's (2e-4) and behaves alike in practice.

mod data;
mod init;
mod state;
#[cfg(test)]
mod tests;

use std::ops::ControlFlow;
use std::time::Instant;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::camera::{Camera, ColmapPoints, scene_extent};
use crate::raster::{self, Grads, RenderOptions};
use crate::scene::Gaussians;
use crate::session::subset;
use crate::style::adam::{Adam, AdamConfig, AdamState};

pub use data::{FitDataError, PosedImages, find_image, image_candidates, load_posed_images, photo_folders, read_rgb};
pub use init::look_at_region;
use init::{Rng, random_gaussians, sfm_gaussians};
pub use state::FitState;

/// Everything that shapes a fit. Learning rates are the 3DGS trainer's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FitConfig {
    /// Optimisation steps, one view each.
    pub iterations: u32,
    /// Working resolution: the longer image side in pixels (used by the loaders).
    pub resolution: u32,
    /// Gaussians at the start.
    pub initial_gaussians: usize,
    /// SH degree of the result (0 or 1 is sensible at these resolutions).
    pub sh_degree: u32,
    /// Opacity of the initial Gaussians.
    pub initial_opacity: f32,
    /// Learning rate of the means at the start, times the scene extent.
    pub lr_means_init: f32,
    /// Learning rate of the means at the end, times the scene extent.
    pub lr_means_final: f32,
    /// Learning rate of the SH band-0 coefficients (higher bands get 1/20 of it).
    pub lr_sh_dc: f32,
    /// Learning rate of the opacity logits.
    pub lr_opacity: f32,
    /// Learning rate of the log-scales.
    pub lr_scales: f32,
    /// Learning rate of the quaternions.
    pub lr_quats: f32,
    /// Background colour the renders (and the composited images) use.
    pub background: [f32; 3],
    /// For a view whose image has an alpha channel (NeRF-synthetic's RGBA
    /// photos), each iteration composites it on a random colour and renders
    /// on the same colour, as nerfstudio's `random` background does: empty
    /// space then has to stay transparent. On one fixed background a dark
    /// floater in front of black costs nothing, and lego's fit kept a haze
    /// around the model that its depth showed and a stylization's colour
    /// matching lit up. Views without alpha use `background` regardless.
    pub random_background: bool,
    /// Seed of the initial points and the view order.
    pub seed: u64,
    /// Densification and pruning.
    pub densify: DensifyConfig,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            iterations: 3000,
            resolution: 200,
            initial_gaussians: 50_000,
            sh_degree: 0,
            initial_opacity: 0.1,
            lr_means_init: 1.6e-4,
            lr_means_final: 1.6e-6,
            lr_sh_dc: 2.5e-3,
            lr_opacity: 0.05,
            lr_scales: 5e-3,
            lr_quats: 1e-3,
            background: [0.0; 3],
            random_background: true,
            seed: 0,
            densify: DensifyConfig::default(),
        }
    }
}

/// The initial Gaussian counts a fit accepts (20 million is about 5 GB of
/// parameters and Adam moments).
pub const INITIAL_GAUSSIANS: std::ops::RangeInclusive<usize> = 1..=20_000_000;

impl FitConfig {
    /// Reads a preset: a JSON object of the settings' keys, the missing ones
    /// taking their defaults; an unknown key or anything but an object is
    /// refused ([`crate::settings::from_json`]).
    pub fn from_json(text: &str) -> Result<Self, serde_json::Error> {
        crate::settings::from_json(text)
    }

    /// Problems that make the configuration unusable, as sentences (empty when fine).
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let sides = crate::camera::IMAGE_SIDES;
        if !sides.contains(&self.resolution) {
            out.push(format!("resolution must lie in {sides:?} pixels, found {}", self.resolution));
        }
        if !INITIAL_GAUSSIANS.contains(&self.initial_gaussians) {
            out.push(format!("initial_gaussians must lie in {INITIAL_GAUSSIANS:?}, found {}", self.initial_gaussians));
        }
        if self.sh_degree > 3 {
            out.push(format!("sh_degree must be 0 to 3, found {}", self.sh_degree));
        }
        if !(self.initial_opacity > 0.0 && self.initial_opacity < 1.0) {
            out.push(format!("initial_opacity must lie strictly between 0 and 1, found {}", self.initial_opacity));
        }
        if !self.background.iter().all(|c| (0.0..=1.0).contains(c)) {
            out.push(format!("background must be three values in [0, 1], found {:?}", self.background));
        }
        let d = &self.densify;
        for (name, v) in [
            ("lr_means_init", self.lr_means_init),
            ("lr_means_final", self.lr_means_final),
            ("lr_sh_dc", self.lr_sh_dc),
            ("lr_opacity", self.lr_opacity),
            ("lr_scales", self.lr_scales),
            ("lr_quats", self.lr_quats),
            ("densify.grad_threshold", d.grad_threshold),
            ("densify.percent_dense", d.percent_dense),
            ("densify.min_opacity", d.min_opacity),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                out.push(format!("{name} must be a finite non-negative number, found {v}"));
            }
        }
        if !(0.0..=1.0).contains(&d.until_fraction) {
            out.push(format!("densify.until_fraction must lie in [0, 1], found {}", d.until_fraction));
        }
        if d.enabled && (d.interval == 0 || d.max_gaussians == 0) {
            out.push(format!(
                "densify.interval and densify.max_gaussians must be positive, found {} and {}",
                d.interval, d.max_gaussians
            ));
        }
        out
    }
}

/// When and how Gaussians are cloned, split and pruned (the trainer's rules).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DensifyConfig {
    /// Densify at all.
    pub enabled: bool,
    /// First iteration that densifies.
    pub from: u32,
    /// No densification from this fraction of the iterations on.
    pub until_fraction: f32,
    /// Iterations between densifications.
    pub interval: u32,
    /// Mean view-space (NDC) gradient norm above which a Gaussian is densified.
    pub grad_threshold: f32,
    /// Gaussians larger than this fraction of the extent are split, smaller ones cloned.
    pub percent_dense: f32,
    /// Gaussians less opaque than this are removed at each densification.
    pub min_opacity: f32,
    /// No more Gaussians than this.
    pub max_gaussians: usize,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            from: 300,
            until_fraction: 0.6,
            interval: 100,
            grad_threshold: 2e-4,
            percent_dense: 0.01,
            min_opacity: 0.005,
            max_gaussians: 200_000,
        }
    }
}

/// Reported after every iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitProgress {
    /// Iterations done (1-based).
    pub iteration: u32,
    /// Iterations in all.
    pub iterations: u32,
    /// L1 loss of this iteration's view.
    pub loss: f32,
    /// Gaussians now.
    pub gaussians: usize,
    /// Seconds since the fit started.
    pub elapsed_s: f64,
}

/// Peak signal-to-noise ratio in dB of two images in `[0, 1]` (∞ when equal).
pub fn psnr(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "psnr: images differ in size");
    let mse = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum::<f64>() / a.len().max(1) as f64;
    (-10.0 * mse.log10()) as f32
}

/// Mean PSNR of the renders of `g` against the views.
pub fn mean_psnr(g: &Gaussians, views: &[(Camera, Vec<f32>)], background: [f32; 3]) -> f32 {
    let opts = RenderOptions { background };
    let sum: f32 = views.iter().map(|(cam, gt)| psnr(&raster::render(g, cam, &opts).rgb, gt)).sum();
    sum / views.len().max(1) as f32
}

/// The initial scene [`fit`] starts from (random points in the cameras' common view).
pub fn initial_scene(cameras: &[Camera], cfg: &FitConfig) -> Gaussians {
    let mut rng = Rng::new(cfg.seed);
    random_gaussians(cameras, cfg.initial_gaussians.max(1), cfg.sh_degree.min(3), cfg.initial_opacity, &mut rng)
}

/// An initial scene from SfM points, for [`fit_from`]: one Gaussian per point
/// with its colour, the RMS distance to its three nearest neighbours as its
/// (isotropic) scale, identity rotation and `cfg.initial_opacity`, as the 3DGS
/// trainer starts. `cfg.initial_gaussians` does not apply.
pub fn initial_scene_from_points(points: &ColmapPoints, cfg: &FitConfig) -> Gaussians {
    sfm_gaussians(points, cfg.sh_degree.min(3), cfg.initial_opacity)
}

/// Fits a scene to posed images from random initial Gaussians
/// ([`initial_scene`]): `views` holds each camera with its RGB image
/// (`height × width × 3` in `[0, 1]`, already composited on
/// `cfg.background`). `progress` is called after every iteration with the
/// fit as it stands ([`FitRun`]: its scene before [`finished`]'s pruning,
/// and its whole state, which a checkpoint writes); its `Break` stops the
/// fit there (a user's Ctrl-C), which then ends as after the last iteration.
///
/// # Panics
/// When an image's size does not match its camera (a caller bug).
pub fn fit(
    views: &[(Camera, Vec<f32>)],
    cfg: &FitConfig,
    progress: &mut dyn FnMut(FitProgress, &FitRun<'_>) -> ControlFlow<()>,
) -> Gaussians {
    let cameras: Vec<Camera> = views.iter().map(|(c, _)| c.clone()).collect();
    fit_from(views, &[], initial_scene(&cameras, cfg), cfg, progress)
}

/// As [`fit`], starting from `initial` (e.g. [`initial_scene_from_points`]),
/// with each view's alpha where its image has one (`alphas[i]` for
/// `views[i]`, as [`PosedImages::alphas`]; an empty slice when none has).
///
/// # Panics
/// When an image's size does not match its camera (a caller bug).
pub fn fit_from(
    views: &[(Camera, Vec<f32>)],
    alphas: &[Option<Vec<f32>>],
    initial: Gaussians,
    cfg: &FitConfig,
    progress: &mut dyn FnMut(FitProgress, &FitRun<'_>) -> ControlFlow<()>,
) -> Gaussians {
    fit_resumed(views, alphas, initial, cfg, 0, None, progress)
}

/// As [`fit_from`], from iteration `start` (a checkpoint's scene after
/// `start` iterations of the same `cfg`): the learning-rate schedule and
/// densification go on from there. With `state` (the fit's [`FitRun::state`]
/// at `start`, which must pass [`FitState::check`] for `initial`) the Adam
/// moments, the densification's gradient statistics, the view order and the
/// generator go on as they were, and the resumed fit is the fit run through,
/// to the bit; without, they start afresh and the view order is drawn anew.
///
/// # Panics
/// When an image's size does not match its camera, an alpha's size its
/// image, or `state` does not fit `initial` (caller bugs).
pub fn fit_resumed(
    views: &[(Camera, Vec<f32>)],
    alphas: &[Option<Vec<f32>>],
    initial: Gaussians,
    cfg: &FitConfig,
    start: u32,
    state: Option<FitState>,
    progress: &mut dyn FnMut(FitProgress, &FitRun<'_>) -> ControlFlow<()>,
) -> Gaussians {
    for (cam, img) in views {
        assert_eq!(
            img.len(),
            3 * cam.width as usize * cam.height as usize,
            "fit: image of {} has the wrong size",
            cam.name
        );
    }
    assert!(alphas.is_empty() || alphas.len() == views.len(), "fit: one alpha (or none) per view");
    for ((cam, img), alpha) in views.iter().zip(alphas) {
        assert!(
            alpha.as_ref().is_none_or(|a| 3 * a.len() == img.len()),
            "fit: alpha of {} has the wrong size",
            cam.name
        );
    }
    let cameras: Vec<Camera> = views.iter().map(|(c, _)| c.clone()).collect();
    let mut g = initial;
    if views.is_empty() {
        return g;
    }
    let extent = scene_extent(&cameras);
    let mut rng = Rng::new(cfg.seed ^ 0xA5A5_5A5A ^ u64::from(start));
    let mut opt = Optimisers::new(&g);
    let mut stats = GradStats::new(g.len());
    let mut order: Vec<usize> = Vec::new();
    if let Some(state) = state {
        if let Err(e) = state.check(&g, start, views.len()) {
            panic!("fit: the state to resume from does not fit: {e}");
        }
        opt.set_state(state.groups);
        stats = GradStats { sum: state.grad_sum, count: state.grad_count };
        order = state.order.iter().map(|&v| v as usize).collect();
        rng = Rng::from_state(state.rng);
    }
    let t0 = Instant::now();
    let densify_until = (cfg.densify.until_fraction * cfg.iterations as f32) as u32;
    for it in start.min(cfg.iterations)..cfg.iterations {
        if order.is_empty() {
            order = (0..views.len()).collect();
            for i in (1..order.len()).rev() {
                order.swap(i, rng.below(i + 1));
            }
        }
        let vi = order.pop().unwrap_or(0);
        let (cam, gt) = &views[vi];
        let alpha = alphas.get(vi).and_then(Option::as_ref).filter(|_| cfg.random_background);
        let (opts, gt) = match alpha {
            // The photo was composited on `cfg.background`: moved onto `b`.
            Some(alpha) => {
                let b = [rng.uniform(), rng.uniform(), rng.uniform()];
                let shift: [f32; 3] = std::array::from_fn(|c| b[c] - cfg.background[c]);
                let moved = gt.chunks_exact(3).zip(alpha).flat_map(|(p, &a)| {
                    let t = 1.0 - a;
                    [p[0] + t * shift[0], p[1] + t * shift[1], p[2] + t * shift[2]]
                });
                (RenderOptions { background: b }, std::borrow::Cow::Owned(moved.collect()))
            }
            None => (RenderOptions { background: cfg.background }, std::borrow::Cow::Borrowed(gt)),
        };
        let gt: &[f32] = &gt;
        let (render, state) = raster::forward(&g, cam, &opts);
        let npx = render.alpha.len();
        let scale = 1.0 / (3 * npx) as f32;
        let mut loss = 0.0f64;
        let v_rgb: Vec<f32> = render
            .rgb
            .iter()
            .zip(gt)
            .map(|(r, t)| {
                let d = r - t;
                loss += f64::from(d.abs());
                if d > 0.0 {
                    scale
                } else if d < 0.0 {
                    -scale
                } else {
                    0.0
                }
            })
            .collect();
        let grads = raster::backward(&g, cam, &opts, &state, &v_rgb, &vec![0.0; npx]);
        drop(state);
        if cfg.densify.enabled {
            stats.add(&g, cam, &grads);
        }
        let t = it as f32 / cfg.iterations.saturating_sub(1).max(1) as f32;
        let lr_means = extent * (cfg.lr_means_init.ln() * (1.0 - t) + cfg.lr_means_final.ln() * t).exp();
        opt.step(&mut g, &grads, cfg, lr_means);

        let done = it + 1;
        if cfg.densify.enabled
            && done >= cfg.densify.from
            && done < densify_until
            && done % cfg.densify.interval.max(1) == 0
        {
            g = densify(&g, &stats, &cfg.densify, extent, &mut rng);
            opt = Optimisers::new(&g);
            stats = GradStats::new(g.len());
        }
        let run = FitRun { g: &g, opt: &opt, stats: &stats, order: &order, rng: &rng, iteration: done };
        let said = progress(
            FitProgress {
                iteration: done,
                iterations: cfg.iterations,
                loss: (loss * f64::from(scale)) as f32,
                gaussians: g.len(),
                elapsed_s: t0.elapsed().as_secs_f64(),
            },
            &run,
        );
        if said.is_break() {
            break;
        }
    }
    finished(&g, cfg)
}

/// A fit as it stands after an iteration, as [`fit`]'s `progress` sees it.
pub struct FitRun<'a> {
    g: &'a Gaussians,
    opt: &'a Optimisers,
    stats: &'a GradStats,
    order: &'a [usize],
    rng: &'a Rng,
    iteration: u32,
}

impl FitRun<'_> {
    /// The scene, before [`finished`]'s pruning.
    pub fn scene(&self) -> &Gaussians {
        self.g
    }

    /// Everything else a fit resumed from here needs to go on as this one
    /// does ([`fit_resumed`]).
    pub fn state(&self) -> FitState {
        FitState {
            iteration: self.iteration,
            groups: self.opt.state(),
            grad_sum: self.stats.sum.clone(),
            grad_count: self.stats.count.clone(),
            order: self.order.iter().map(|&v| v as u32).collect(),
            rng: self.rng.state(),
        }
    }
}

/// The scene a fit hands out: `g` without the Gaussians that ended up
/// (nearly) invisible, below `cfg.densify.min_opacity`. [`fit_from`] ends
/// with it; a checkpoint taken during the fit writes it too.
pub fn finished(g: &Gaussians, cfg: &FitConfig) -> Gaussians {
    let keep: Vec<u32> =
        (0..g.len() as u32).filter(|&i| sigmoid(g.opacity_logits[i as usize]) >= cfg.densify.min_opacity).collect();
    subset(g, &keep)
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// One Adam per parameter group; SH band 0 and the higher bands apart.
struct Optimisers {
    means: Adam,
    scales: Adam,
    quats: Adam,
    opacity: Adam,
    dc: Adam,
    rest: Adam,
}

impl Optimisers {
    fn new(g: &Gaussians) -> Self {
        let c = AdamConfig::default();
        let n = g.len();
        let rest = (g.sh_coeffs() - 1) * 3;
        Self {
            means: Adam::new(3 * n, c),
            scales: Adam::new(3 * n, c),
            quats: Adam::new(4 * n, c),
            opacity: Adam::new(n, c),
            dc: Adam::new(3 * n, c),
            rest: Adam::new(rest * n, c),
        }
    }

    /// Every group's state, in the order of [`state::GROUPS`].
    fn state(&self) -> Vec<AdamState> {
        [&self.means, &self.scales, &self.quats, &self.opacity, &self.dc, &self.rest].map(Adam::state).to_vec()
    }

    /// Goes on from [`Self::state`]'s groups, checked to fit ([`FitState::check`]).
    fn set_state(&mut self, groups: Vec<AdamState>) {
        let mine =
            [&mut self.means, &mut self.scales, &mut self.quats, &mut self.opacity, &mut self.dc, &mut self.rest];
        for (adam, g) in mine.into_iter().zip(groups) {
            adam.set_state(g).unwrap_or_else(|e| panic!("fit: the state to resume from does not fit: {e}"));
        }
    }

    fn step(&mut self, g: &mut Gaussians, v: &Grads, cfg: &FitConfig, lr_means: f32) {
        self.means.step(g.means.as_flattened_mut(), v.v_means.as_flattened(), lr_means);
        self.scales.step(g.log_scales.as_flattened_mut(), v.v_log_scales.as_flattened(), cfg.lr_scales);
        self.quats.step(g.quats.as_flattened_mut(), v.v_quats.as_flattened(), cfg.lr_quats);
        self.opacity.step(&mut g.opacity_logits, &v.v_opacity_logits, cfg.lr_opacity);
        let k = g.sh_coeffs() * 3;
        let split = |a: &[f32]| -> (Vec<f32>, Vec<f32>) {
            let (mut dc, mut rest) = (Vec::with_capacity(a.len() / k * 3), Vec::with_capacity(a.len() / k * (k - 3)));
            for c in a.chunks_exact(k) {
                dc.extend_from_slice(&c[..3]);
                rest.extend_from_slice(&c[3..]);
            }
            (dc, rest)
        };
        let (mut dc, mut rest) = split(&g.sh);
        let (v_dc, v_rest) = split(&v.v_sh);
        self.dc.step(&mut dc, &v_dc, cfg.lr_sh_dc);
        self.rest.step(&mut rest, &v_rest, cfg.lr_sh_dc / 20.0);
        for (i, c) in g.sh.chunks_exact_mut(k).enumerate() {
            c[..3].copy_from_slice(&dc[3 * i..3 * i + 3]);
            c[3..].copy_from_slice(&rest[(k - 3) * i..(k - 3) * (i + 1)]);
        }
    }
}

/// Accumulated view-space gradient norms per Gaussian since the last densification.
struct GradStats {
    sum: Vec<f32>,
    count: Vec<u32>,
}

impl GradStats {
    fn new(n: usize) -> Self {
        Self { sum: vec![0.0; n], count: vec![0; n] }
    }

    /// Adds this view's gradient of every Gaussian that received one.
    fn add(&mut self, g: &Gaussians, cam: &Camera, v: &Grads) {
        let (w2, h2) = (0.5 * cam.width as f32, 0.5 * cam.height as f32);
        for (i, vm) in v.v_means.iter().enumerate() {
            if *vm == [0.0; 3] {
                continue;
            }
            let z = cam.world_to_camera(Vec3::from(g.means[i])).z;
            let vt = cam.rotation * Vec3::from(*vm);
            let gx = vt.x * z / cam.fx * w2;
            let gy = vt.y * z / cam.fy * h2;
            self.sum[i] += (gx * gx + gy * gy).sqrt();
            self.count[i] += 1;
        }
    }
}

/// The trainer's densification: Gaussians whose mean view-space gradient is
/// above the threshold are cloned (small) or split in two (large, samples
/// from the Gaussian, scales ÷1.6); then the nearly transparent ones go.
fn densify(g: &Gaussians, stats: &GradStats, cfg: &DensifyConfig, extent: f32, rng: &mut Rng) -> Gaussians {
    let big = cfg.percent_dense * extent;
    let mut keep = Vec::with_capacity(g.len());
    let mut clones = Vec::new();
    let mut splits = Vec::new();
    let mut room = cfg.max_gaussians.saturating_sub(g.len());
    for i in 0..g.len() {
        if sigmoid(g.opacity_logits[i]) < cfg.min_opacity {
            continue;
        }
        let hot = stats.count[i] > 0 && stats.sum[i] / stats.count[i] as f32 >= cfg.grad_threshold;
        if hot && room > 0 {
            room -= 1;
            let size = g.log_scales[i].iter().copied().fold(f32::MIN, f32::max).exp();
            if size > big {
                splits.push(i as u32);
            } else {
                keep.push(i as u32);
                clones.push(i as u32);
            }
        } else {
            keep.push(i as u32);
        }
    }
    let n_keep = keep.len() + clones.len();
    keep.extend_from_slice(&clones);
    keep.extend(splits.iter().flat_map(|&i| [i, i]));
    let mut out = subset(g, &keep);
    for j in n_keep..out.len() {
        let [w, x, y, z] = out.quats[j];
        let rot = Quat::from_xyzw(x, y, z, w).normalize();
        let s = Vec3::from(out.log_scales[j]).exp();
        let offset = rot * (s * Vec3::new(rng.normal(), rng.normal(), rng.normal()));
        out.means[j] = (Vec3::from(out.means[j]) + offset).to_array();
        out.log_scales[j] = out.log_scales[j].map(|v| v - 1.6f32.ln());
    }
    out
}
