//! Geometry-aware contrastive feature matching (GCFM) on VGG features.
//!
//! Every rendered feature position `x` is matched to the style position whose
//! joint RGB|depth|edge feature (3 × 768 channels) is the most similar (`y+`,
//! smallest cosine distance) and the least similar (`y−`). The loss pulls each
//! modality's rendered feature towards its `y+` counterpart and pushes it away
//! from its `y−` counterpart:
//!
//! `L = Σ_m mean_x(1 − cos(F_m^R(x), F_m^S(y+))) + mean_x(1 + cos(F_m^R(x), F_m^S(y−)))`.
//!
//! Matching is the expensive part: all rendered against all style positions.
//! It runs as `gemm` matrix products over tiles of rendered positions, so
//! memory stays at one tile of scores (never the full N × M matrix), and the
//! style side (its norms) is prepared once per style image in
//! [`StyleFeatures`]. Near-ties of the `f32` product are re-decided in `f64`.
//! Cosines use the reference's `v / (‖v‖ + 1e-8)`; the joint vectors for
//! matching use `v / (sqrt(‖v‖² + 1e-8) + 1e-8)` as the reference does.

use std::sync::OnceLock;

use rayon::prelude::*;

pub use super::distinct::Matches;
use super::distinct::search_distinct;
use super::sliced::{SLICED_PROJECTIONS, SlicedTarget};

/// The epsilon of the reference's normalisations.
pub(super) const EPS: f64 = 1e-8;
/// Score-matrix elements per tile at most (4 MiB of `f32`).
const TILE_ELEMS: usize = 1 << 20;
/// Scores within this fraction of the rendered vector's norm of the best (or
/// worst) one are re-evaluated in `f64`.
const TIE_MARGIN: f64 = 1e-5;

/// Style-side features of the three modalities, prepared once per style image.
#[derive(Clone, Debug)]
pub struct StyleFeatures {
    /// Channels per modality (768 for VGG relu3_1..3).
    pub channels: usize,
    /// Feature-map height.
    pub height: usize,
    /// Feature-map width.
    pub width: usize,
    /// RGB, depth and edge features, each `channels × height × width` (CHW).
    feats: [Vec<f32>; 3],
    /// `1 / (sqrt(‖joint‖² + 1e-8) + 1e-8)` per position (matching).
    joint_inv_norm: Vec<f32>,
    /// `1 / (‖F_m‖ + 1e-8)` per modality and position (loss).
    modal_inv_norm: [Vec<f64>; 3],
    /// The RGB features' mean per channel (the feature-mean term's target).
    rgb_mean: Vec<f32>,
    /// The sliced Wasserstein targets per modality (λ_sw on RGB, λ_swd on
    /// depth), each made on first use.
    sliced: [OnceLock<SlicedTarget>; 3],
}

impl StyleFeatures {
    /// Takes the style features of the RGB, depth and edge maps (each
    /// `channels × height × width`, CHW) and precomputes their norms.
    pub fn new(feats: [Vec<f32>; 3], channels: usize, height: usize, width: usize) -> Self {
        let m = height * width;
        for f in &feats {
            assert_eq!(f.len(), channels * m, "StyleFeatures: feature size mismatch");
        }
        let modal_sq: Vec<Vec<f64>> = feats.iter().map(|f| column_sq_norms(f, channels, m)).collect();
        let joint_inv_norm = (0..m)
            .map(|y| {
                let sq: f64 = modal_sq.iter().map(|s| s[y]).sum();
                (1.0 / ((sq + EPS).sqrt() + EPS)) as f32
            })
            .collect();
        let modal_inv_norm = std::array::from_fn(|k| modal_sq[k].iter().map(|&s| 1.0 / (s.sqrt() + EPS)).collect());
        let rgb_mean = super::feature_mean::channel_means(&feats[0], channels);
        Self { channels, height, width, feats, joint_inv_norm, modal_inv_norm, rgb_mean, sliced: Default::default() }
    }

    /// Number of style positions.
    pub fn positions(&self) -> usize {
        self.height * self.width
    }

    /// The features of one modality (0 RGB, 1 depth, 2 edge), CHW.
    pub fn modality(&self, m: usize) -> &[f32] {
        &self.feats[m]
    }

    /// The RGB features' mean per channel.
    pub fn rgb_mean(&self) -> &[f32] {
        &self.rgb_mean
    }

    /// The sliced Wasserstein target of one modality's features (0 RGB for
    /// λ_sw, 1 depth for λ_swd): projected and sorted on the first call.
    pub fn sliced(&self, m: usize) -> &SlicedTarget {
        self.sliced[m].get_or_init(|| SlicedTarget::new(&self.feats[m], self.channels, SLICED_PROJECTIONS))
    }

    /// The matching's style-side scale `1 / (sqrt(‖joint‖² + 1e-8) + 1e-8)`, per position.
    pub(crate) fn joint_inv_norm(&self) -> &[f32] {
        &self.joint_inv_norm
    }

    /// The loss's `1 / (‖F_m‖ + 1e-8)` of modality `m`, per position.
    pub(crate) fn modal_inv_norm(&self, m: usize) -> &[f64] {
        &self.modal_inv_norm[m]
    }
}

/// Squared norm of every column of a `c × n` row-major matrix, in f64.
pub(super) fn column_sq_norms(f: &[f32], c: usize, n: usize) -> Vec<f64> {
    let mut s = vec![0f64; n];
    for k in 0..c {
        for (acc, &v) in s.iter_mut().zip(&f[k * n..(k + 1) * n]) {
            *acc += f64::from(v) * f64::from(v);
        }
    }
    s
}

/// Result of [`gcfm_loss`].
#[derive(Clone, Debug)]
pub struct GcfmOutput {
    /// The (unweighted) loss.
    pub loss: f32,
    /// Per-modality contributions (RGB, depth, edge).
    pub terms: [f32; 3],
    /// Gradient w.r.t. each modality's rendered features (CHW, like the input).
    pub v_rendered: [Vec<f32>; 3],
    /// The matches the loss used.
    pub matches: Matches,
}

/// The rendered rows of each tile of a search against `m` style positions
/// over `n` rows, and how each tile's product runs. A tile holds at most
/// [`TILE_ELEMS`] scores; the tiles are made even, and when they are at
/// least as many as the threads, a multiple of them, so no thread ends with
/// a long tile alone (fern's 768 rows against 2,304 style positions were
/// tiles of 455 and 313 rows on two threads). When they are fewer, each
/// tile's product is spread over the threads itself: an object's few covered
/// positions against a large style are one tile (41 to 136 rows against
/// 8,576 style positions at guitar's 256 px), which was the one serial part
/// of a CPU step.
pub(super) fn row_tiles(n: usize, m: usize) -> (usize, gemm::Parallelism) {
    let most = (TILE_ELEMS / m.max(1)).clamp(8, n.max(8));
    let threads = rayon::current_num_threads().max(1);
    let tiles = n.div_ceil(most).max(1);
    if tiles < threads {
        (n.div_ceil(tiles).max(1), gemm::Parallelism::Rayon(0))
    } else {
        (n.div_ceil(tiles.next_multiple_of(threads)).max(1), gemm::Parallelism::None)
    }
}

/// `dst (t × m) = lhs (t × c, element (x, k) at lhs[k·n + x0 + x]) · rhs (c × m)`,
/// accumulating into `dst` when `accumulate`, on `par`'s threads.
#[allow(unsafe_code)]
#[allow(clippy::too_many_arguments)]
pub(super) fn gemm_tile(
    dst: &mut [f32],
    t: usize,
    m: usize,
    lhs: &[f32],
    n: usize,
    x0: usize,
    c: usize,
    rhs: &[f32],
    accumulate: bool,
    par: gemm::Parallelism,
) {
    assert!(dst.len() >= t * m && x0 + t <= n && lhs.len() >= c * n && rhs.len() >= c * m);
    if t == 0 || m == 0 || c == 0 {
        return;
    }
    let lhs = &lhs[x0..];
    // SAFETY: the asserts above keep every access in bounds: dst (i, j) at
    // i·m + j < t·m; lhs (i, k) at k·n + i ≤ (c−1)·n + t−1 < c·n − x0 (the slice
    // starts at x0); rhs (k, j) at k·m + j < c·m. dst does not alias the inputs.
    unsafe {
        gemm::gemm(
            t,
            m,
            c,
            dst.as_mut_ptr(),
            1,
            m as isize,
            accumulate,
            lhs.as_ptr(),
            n as isize,
            1,
            rhs.as_ptr(),
            1,
            m as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            par,
        );
    }
}

/// Matches rendered features (three modalities, each `channels × n` CHW with
/// `n` positions) against the style: tiled `gemm`, parallel over tiles, once
/// per distinct joint vector ([`search_distinct`]: the background's copies
/// take their representative's matches).
pub fn match_features(style: &StyleFeatures, rendered: [&[f32]; 3], n: usize) -> Matches {
    for r in &rendered {
        assert_eq!(r.len(), style.channels * n, "match_features: rendered feature size mismatch");
    }
    search_distinct(rendered, style.channels, n, |r, u| match_every_position(style, r, u))
}

/// [`match_features`] searching every position, copies included.
pub fn match_every_position(style: &StyleFeatures, rendered: [&[f32]; 3], n: usize) -> Matches {
    let (c, m) = (style.channels, style.positions());
    for r in &rendered {
        assert_eq!(r.len(), c * n, "match_features: rendered feature size mismatch");
    }
    if n == 0 || m == 0 {
        return Matches { best: vec![0; n], worst: vec![0; n] };
    }
    let joint_sq: Vec<f64> = {
        let per: Vec<Vec<f64>> = rendered.iter().map(|r| column_sq_norms(r, c, n)).collect();
        (0..n).map(|x| per.iter().map(|p| p[x]).sum()).collect()
    };
    let (tile, par) = row_tiles(n, m);
    let starts: Vec<usize> = (0..n).step_by(tile).collect();
    let parts: Vec<(Vec<u32>, Vec<u32>)> = starts
        .par_iter()
        .map(|&x0| {
            let t = tile.min(n - x0);
            let mut scores = vec![0f32; t * m];
            for (k, r) in rendered.iter().enumerate() {
                gemm_tile(&mut scores, t, m, r, n, x0, c, &style.feats[k], k > 0, par);
            }
            let mut best = Vec::with_capacity(t);
            let mut worst = Vec::with_capacity(t);
            let mut cands = Vec::new();
            for i in 0..t {
                let row = &mut scores[i * m..(i + 1) * m];
                for (s, &inv) in row.iter_mut().zip(&style.joint_inv_norm) {
                    *s *= inv;
                }
                let margin = (TIE_MARGIN * joint_sq[x0 + i].sqrt()) as f32;
                best.push(decide(row, margin, true, &mut cands, |y| exact_score(style, &rendered, n, x0 + i, y)));
                worst.push(decide(row, margin, false, &mut cands, |y| exact_score(style, &rendered, n, x0 + i, y)));
            }
            (best, worst)
        })
        .collect();
    parts.into_iter().collect()
}

/// Index of the largest (`want_max`) or smallest score, the first on ties;
/// candidates within `margin` of it are re-scored exactly.
fn decide(row: &[f32], margin: f32, want_max: bool, cands: &mut Vec<usize>, exact: impl Fn(usize) -> f64) -> u32 {
    let better = |a: f32, b: f32| if want_max { a > b } else { a < b };
    let mut arg = 0;
    for (y, &s) in row.iter().enumerate() {
        if better(s, row[arg]) {
            arg = y;
        }
    }
    let top = row[arg];
    cands.clear();
    cands.extend(row.iter().enumerate().filter(|&(_, &s)| (s - top).abs() <= margin).map(|(y, _)| y));
    if cands.len() <= 1 {
        return arg as u32;
    }
    let mut arg = cands[0];
    let mut top = exact(arg);
    for &y in &cands[1..] {
        let s = exact(y);
        if (want_max && s > top) || (!want_max && s < top) {
            arg = y;
            top = s;
        }
    }
    arg as u32
}

/// Joint score `⟨r(x), s(y)⟩ / ‖s(y)‖'` in f64 (the rendered norm does not
/// change the arg-extrema).
fn exact_score(style: &StyleFeatures, rendered: &[&[f32]; 3], n: usize, x: usize, y: usize) -> f64 {
    let (c, m) = (style.channels, style.positions());
    let mut dot = 0f64;
    let mut sq = 0f64;
    for (r, f) in rendered.iter().zip(&style.feats) {
        for ch in 0..c {
            let s = f64::from(f[ch * m + y]);
            dot += f64::from(r[ch * n + x]) * s;
            sq += s * s;
        }
    }
    dot / ((sq + EPS).sqrt() + EPS)
}

/// The slow, obvious matching (every pair in f64), for tests.
pub fn match_features_dense(style: &StyleFeatures, rendered: [&[f32]; 3], n: usize) -> Matches {
    let m = style.positions();
    let mut out = Matches::default();
    for x in 0..n {
        let scores: Vec<f64> = (0..m).map(|y| exact_score(style, &rendered, n, x, y)).collect();
        let mut b = 0;
        let mut w = 0;
        for y in 0..m {
            if scores[y] > scores[b] {
                b = y;
            }
            if scores[y] < scores[w] {
                w = y;
            }
        }
        out.best.push(b as u32);
        out.worst.push(w as u32);
    }
    out
}

/// The GCFM loss and its gradient w.r.t. the rendered features of each
/// modality (`channels × n` CHW each), the matches held fixed.
pub fn gcfm_loss(style: &StyleFeatures, rendered: [&[f32]; 3], n: usize) -> GcfmOutput {
    let matches = match_features(style, rendered, n);
    gcfm_loss_with_matches(style, rendered, n, matches)
}

/// [`gcfm_loss`] with given matches.
pub fn gcfm_loss_with_matches(style: &StyleFeatures, rendered: [&[f32]; 3], n: usize, matches: Matches) -> GcfmOutput {
    let (c, m) = (style.channels, style.positions());
    assert_eq!(matches.best.len(), n, "gcfm_loss: one match per rendered position");
    let per: Vec<(f64, Vec<f32>)> = (0..3)
        .into_par_iter()
        .map(|k| modality_loss(rendered[k], &style.feats[k], &style.modal_inv_norm[k], c, n, m, &matches))
        .collect();
    let mut terms = [0f32; 3];
    let mut total = 0f64;
    let mut grads: Vec<Vec<f32>> = Vec::with_capacity(3);
    for (k, (l, g)) in per.into_iter().enumerate() {
        terms[k] = l as f32;
        total += l;
        grads.push(g);
    }
    let mut it = grads.into_iter();
    let v_rendered = std::array::from_fn(|_| it.next().unwrap_or_default());
    GcfmOutput { loss: total as f32, terms, v_rendered, matches }
}

/// One modality's `mean(1 − cos⁺) + mean(1 + cos⁻)` and its gradient.
fn modality_loss(r: &[f32], s: &[f32], s_inv: &[f64], c: usize, n: usize, m: usize, mt: &Matches) -> (f64, Vec<f32>) {
    let (mut dot_b, mut dot_w, mut sq) = (vec![0f64; n], vec![0f64; n], vec![0f64; n]);
    for ch in 0..c {
        let rr = &r[ch * n..(ch + 1) * n];
        let ss = &s[ch * m..(ch + 1) * m];
        for x in 0..n {
            let v = f64::from(rr[x]);
            dot_b[x] += v * f64::from(ss[mt.best[x] as usize]);
            dot_w[x] += v * f64::from(ss[mt.worst[x] as usize]);
            sq[x] += v * v;
        }
    }
    let inv_n = 1.0 / n.max(1) as f64;
    let mut loss = 0f64;
    // v = (1/n)·(−α⁺ s⁺ + α⁻ s⁻ + (β⁺ − β⁻) r) with α = ŝ-scale/(‖r‖+ε), β = cos·…/‖r‖.
    let mut alpha_b = vec![0f32; n];
    let mut alpha_w = vec![0f32; n];
    let mut beta = vec![0f32; n];
    for x in 0..n {
        let nr = sq[x].sqrt();
        let ar = 1.0 / (nr + EPS);
        let (sb, sw) = (s_inv[mt.best[x] as usize], s_inv[mt.worst[x] as usize]);
        let cos_b = dot_b[x] * ar * sb;
        let cos_w = dot_w[x] * ar * sw;
        loss += (1.0 - cos_b) + (1.0 + cos_w);
        alpha_b[x] = (inv_n * sb * ar) as f32;
        alpha_w[x] = (inv_n * sw * ar) as f32;
        if nr > 0.0 {
            let k = ar * ar / nr;
            beta[x] = (inv_n * k * (dot_b[x] * sb - dot_w[x] * sw)) as f32;
        }
    }
    let mut g = vec![0f32; c * n];
    for ch in 0..c {
        let rr = &r[ch * n..(ch + 1) * n];
        let ss = &s[ch * m..(ch + 1) * m];
        let gg = &mut g[ch * n..(ch + 1) * n];
        for x in 0..n {
            gg[x] = -alpha_b[x] * ss[mt.best[x] as usize] + alpha_w[x] * ss[mt.worst[x] as usize] + beta[x] * rr[x];
        }
    }
    (loss * inv_n, g)
}

#[cfg(test)]
#[path = "gcfm_tests.rs"]
mod tests;
