//! The assignment terms (λ_as and λ_asc; not in the reference, off by
//! default): every covered rendered RGB relu3 feature is paired with a
//! *distinct* style feature, drawn anew each step, by a one-to-one assignment
//! of least total cost, and pulled to it. Two pulls share the pairing:
//!
//! - λ_as, the squared distance: `(1/(r·C)) Σ_i ‖F(x_i) − F^S(y_σ(i))‖²`;
//! - λ_asc, the cosine distance GCFM and the NN-cos measure use:
//!   `(1/r) Σ_i (1 − cos(F(x_i), F^S(y_σ(i))))`.
//!
//! over the `r` rendered positions `x_i` (the object's with object focus) and
//! `r` style positions `y_j` drawn uniformly without repetition, `σ` the
//! minimum-cost assignment ([`assign_min_cost`], `super::min_cost`) under
//! the cosine distance when λ_asc is on, the squared distance otherwise.
//!
//! Why: GCFM pulls each rendered feature toward its *nearest* style feature,
//! so many rendered positions can crowd onto a few popular style features
//! and the object's feature distribution stays unlike the style's (the
//! sliced-Wasserstein measure). λ_mean and λ_sw fix the distribution's mean
//! or its 1-D marginals, but the features that satisfy them sit between the
//! style's modes, off every actual style feature, which costs the
//! nearest-neighbour measure (README, the focus study's rows). An assignment
//! to a sample of the style's features gives every rendered feature an actual
//! style feature as its target, and, because the pairing is one-to-one, the
//! targets are spread as the style's features are: over steps the rendered
//! set is pulled toward a sample of the style's distribution. The squared
//! pull alone also drags the features' lengths to their targets', which on
//! fire's saturated features lost NN-cos; the cosine pull turns the
//! directions only (alone it lets the lengths grow), and a small λ_as beside
//! it (0.003 to 0.015 with λ_asc 10) holds them (README, the focus study's
//! rows).
//!
//! The draw is seeded by the rendered features' own bits, so a run is
//! reproducible and each step draws anew. At most [`ASSIGN_MAX`] rendered
//! positions take part in a step (a fresh random subset when more are
//! covered). The least-cost assignment costs up to `O(r³)` and is serial, so
//! past [`ASSIGN_BLOCK`] rows (the default `StyleConfig::assign_block`) the
//! pairing is split: the `r` rows, and the style positions drawn with them,
//! are dealt into `⌈r / block⌉` interleaved blocks (row `i` to block
//! `i mod k`, spread over the object since the rows run in position order),
//! each paired one-to-one by its own least-cost assignment, the blocks in
//! parallel. The pairing stays one-to-one over all `r`; it is the least-cost
//! one among those that keep each block to itself. On real relu3 costs of
//! guitar × wave at 512 px (about 400 rows), two blocks raise the pairs'
//! mean cosine distance by about 2 % (0.434 → 0.444, against 0.620 for the
//! draw's own random pairing) for a third of the assignment's time on one
//! core
//! (`gast bench pairing`, `docs/figures.md`).

use super::focus::{gather_positions, scatter_positions};
use super::gcfm::{EPS, column_sq_norms};
pub use super::min_cost::assign_min_cost;
use crate::rng::Rng;
use crate::vision::matmul;

/// Most rendered positions one step's assignment pairs (its cost is cubic in it).
pub const ASSIGN_MAX: usize = 512;

/// Most rows of one least-cost block of the pairing by default
/// (`StyleConfig::assign_block`): more rows are dealt into blocks.
pub const ASSIGN_BLOCK: usize = 256;

/// A seed from the bits of the covered columns of `x` (`channels × n`, CHW).
fn seed_of(x: &[f32], n: usize, covered: &[usize]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for row in x.chunks_exact(n.max(1)) {
        for &i in covered {
            h = (h ^ u64::from(row[i].to_bits())).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// `count` distinct indices below `len` when `count ≤ len` (a partial
/// Fisher–Yates shuffle), otherwise every index as often as needed, each
/// round in a new order.
fn draw(rng: &mut Rng, len: usize, count: usize) -> Vec<usize> {
    let mut out = Vec::with_capacity(count);
    while out.len() < count && len > 0 {
        let mut pool: Vec<usize> = (0..len).collect();
        let take = (count - out.len()).min(len);
        for t in 0..take {
            let j = t + rng.below(len - t);
            pool.swap(t, j);
        }
        out.extend_from_slice(&pool[..take]);
    }
    out
}

/// The two assignment terms' values (unweighted) and the gradient of
/// `cosine_weight · cosine + l2_weight · l2` w.r.t. the rendered features.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    /// `(1/r) Σ (1 − cos)` over the pairs (λ_asc's term).
    pub cosine: f32,
    /// `(1/(r·C)) Σ ‖x − s‖²` over the pairs (λ_as's term).
    pub l2: f32,
    /// The weighted gradient, `channels × n` (CHW) like the rendered features.
    pub grad: Vec<f32>,
}

/// The terms and their weighted gradient w.r.t. `rendered` (`channels × n`,
/// CHW) against the style features `style` (`channels × m`, CHW), over the
/// positions in `mask` (all without one). The pairing minimises the cosine
/// distance when `cosine_weight > 0`, the squared distance otherwise, in
/// blocks of at most `block` rows. Positions outside the mask, or left out
/// of this step's subset, get a zero gradient. An empty mask or style gives
/// zeros.
pub fn assignment_loss(
    rendered: &[f32],
    channels: usize,
    style: &[f32],
    mask: Option<&[bool]>,
    cosine_weight: f32,
    l2_weight: f32,
    block: usize,
) -> Assignment {
    let channels = channels.max(1);
    let n = rendered.len() / channels;
    let m = style.len() / channels;
    let covered: Vec<usize> = (0..n).filter(|&i| mask.is_none_or(|k| k[i])).collect();
    if covered.is_empty() || m == 0 {
        return Assignment { cosine: 0.0, l2: 0.0, grad: vec![0.0; rendered.len()] };
    }
    let mut rng = Rng::new(seed_of(rendered, n, &covered));
    let (rows, targets) = draw_pairs(&mut rng, covered, m);
    let x = gather_positions(rendered, channels, n, &rows);
    let s = gather_positions(style, channels, m, &targets);
    let pulled = pull_pairs(&x, &s, channels, cosine_weight, l2_weight, block);
    Assignment { grad: scatter_positions(&pulled.grad, channels, n, &rows), ..pulled }
}

/// One step's draw from `rng`: the rendered positions that take part
/// (`covered`, or a random [`ASSIGN_MAX`] of them in ascending order) and, for
/// each, a style position among `m` (distinct while `m` suffices).
pub(crate) fn draw_pairs(rng: &mut Rng, covered: Vec<usize>, m: usize) -> (Vec<usize>, Vec<usize>) {
    let rows: Vec<usize> = if covered.len() > ASSIGN_MAX {
        let mut pick: Vec<usize> = draw(rng, covered.len(), ASSIGN_MAX).into_iter().map(|t| covered[t]).collect();
        pick.sort_unstable();
        pick
    } else {
        covered
    };
    let targets = draw(rng, m, rows.len());
    (rows, targets)
}

/// [`draw_pairs`] from a generator seeded by `seed` (for benchmarks: the
/// step seeds from the features, the GPU engine from a counter).
pub fn draw_pairs_seeded(seed: u64, covered: Vec<usize>, m: usize) -> (Vec<usize>, Vec<usize>) {
    draw_pairs(&mut Rng::new(seed), covered, m)
}

/// The assignment of the gathered rendered features `x` to the gathered style
/// features `s` (both `channels × r`, CHW, column `i` of `s` drawn for row
/// `i` of `x`'s step), made in blocks of at most `block` rows, and the two
/// pulls along it: the terms and the weighted gradient w.r.t. `x`
/// (`channels × r`). The CPU step and the GPU engine's (which gathers on
/// the device) share it.
pub fn pull_pairs(
    x: &[f32],
    s: &[f32],
    channels: usize,
    cosine_weight: f32,
    l2_weight: f32,
    block: usize,
) -> Assignment {
    let costs = PairCosts::new(x, s, channels, cosine_weight > 0.0, block);
    let sigma = costs.assign();
    costs.pull(x, s, &sigma, cosine_weight, l2_weight)
}

/// The rows `0..r` dealt into `⌈r / block⌉` interleaved blocks of at most
/// `block` rows (row `i` to block `i mod k`); one block when `r ≤ block`.
pub fn pair_blocks(r: usize, block: usize) -> Vec<Vec<usize>> {
    let k = r.div_ceil(block.max(1)).max(1);
    (0..k).map(|b| (b..r).step_by(k).collect()).collect()
}

/// One block of the pairing: its rows (the same indices on the style side,
/// each style column drawn with its row) and their costs.
#[derive(Clone, Debug)]
pub struct PairBlock {
    /// Indices into the `r` gathered columns, ascending.
    pub rows: Vec<usize>,
    /// `b × b` row-major, `b = rows.len()`: entry `(a, c)` is the cost
    /// between rendered column `rows[a]` and style column `rows[c]`.
    pub cost: Vec<f64>,
}

/// The pairing's cost matrices between gathered columns, block by block (the
/// first part of [`pull_pairs`]; `gast bench pairing` times the parts).
#[derive(Clone, Debug)]
pub struct PairCosts {
    /// Channels of a column.
    pub channels: usize,
    /// Columns on each side.
    pub r: usize,
    /// The blocks ([`pair_blocks`]), each paired on its own.
    pub blocks: Vec<PairBlock>,
    x_len: Vec<f64>,
    s_len: Vec<f64>,
}

impl PairCosts {
    /// The costs between the columns of `x` and `s` (both `channels × r`,
    /// CHW) within each block of at most `block` rows: cosine distances when
    /// `cosine`, squared distances otherwise.
    pub fn new(x: &[f32], s: &[f32], channels: usize, cosine: bool, block: usize) -> Self {
        use rayon::prelude::*;
        let channels = channels.max(1);
        let r = x.len() / channels;
        assert_eq!(s.len(), x.len(), "pull_pairs: one style column per rendered one");
        let (xx, ss) = (column_sq_norms(x, channels, r), column_sq_norms(s, channels, r));
        let (x_len, s_len): (Vec<f64>, Vec<f64>) =
            (xx.iter().map(|v| v.sqrt() + EPS).collect(), ss.iter().map(|v| v.sqrt() + EPS).collect());
        let one = |rows: Vec<usize>| {
            let b = rows.len();
            let whole = b == r;
            let (xb, sb) = if whole {
                (std::borrow::Cow::Borrowed(x), std::borrow::Cow::Borrowed(s))
            } else {
                (gather_positions(x, channels, r, &rows).into(), gather_positions(s, channels, r, &rows).into())
            };
            let mut dot = vec![0.0f32; b * b];
            if b > 0 {
                matmul(&mut dot, b, (&xb[..], 1, b), (&sb[..], b), (b, b, channels), false);
            }
            let cost: Vec<f64> = if cosine {
                (0..b * b).map(|ac| 1.0 - f64::from(dot[ac]) / (x_len[rows[ac / b]] * s_len[rows[ac % b]])).collect()
            } else {
                // Squared distances ‖x_i‖² + ‖s_j‖² − 2 x_i·s_j.
                (0..b * b).map(|ac| xx[rows[ac / b]] + ss[rows[ac % b]] - 2.0 * f64::from(dot[ac])).collect()
            };
            PairBlock { rows, cost }
        };
        let blocks: Vec<PairBlock> = pair_blocks(r, block).into_par_iter().map(one).collect();
        Self { channels, r, blocks, x_len, s_len }
    }

    /// The pairing: for each row, the style column it takes, by a least-cost
    /// one-to-one assignment within each block (the blocks in parallel).
    pub fn assign(&self) -> Vec<usize> {
        use rayon::prelude::*;
        let per_block: Vec<Vec<usize>> = self
            .blocks
            .par_iter()
            .map(|b| assign_min_cost(&b.cost, b.rows.len(), b.rows.len()).into_iter().map(|c| b.rows[c]).collect())
            .collect();
        let mut sigma = vec![0usize; self.r];
        for (b, cols) in self.blocks.iter().zip(per_block) {
            for (&i, j) in b.rows.iter().zip(cols) {
                sigma[i] = j;
            }
        }
        sigma
    }

    /// The total cost of `sigma` (row `i` to column `sigma[i]`, each pair
    /// inside a block) over all rows.
    pub fn total(&self, sigma: &[usize]) -> f64 {
        let mut at = vec![(0usize, 0usize); self.r];
        for (k, b) in self.blocks.iter().enumerate() {
            for (a, &i) in b.rows.iter().enumerate() {
                at[i] = (k, a);
            }
        }
        sigma
            .iter()
            .enumerate()
            .map(|(i, &j)| {
                let ((k, a), (kj, c)) = (at[i], at[j]);
                assert_eq!(k, kj, "PairCosts::total: row {i} and column {j} lie in different blocks");
                let b = &self.blocks[k];
                b.cost[a * b.rows.len() + c]
            })
            .sum()
    }

    /// The terms and the weighted gradient w.r.t. `x` along the assignment
    /// `sigma` (row `i` of `x` to column `sigma[i]` of `s`), computed from the
    /// features themselves (not the cancelling expansion of the costs).
    pub fn pull(&self, x: &[f32], s: &[f32], sigma: &[usize], cosine_weight: f32, l2_weight: f32) -> Assignment {
        let (channels, r) = (self.channels, self.r);
        let (x_len, s_len) = (&self.x_len, &self.s_len);
        let mut grad = vec![0.0f32; x.len()];
        if r == 0 {
            return Assignment { cosine: 0.0, l2: 0.0, grad };
        }
        let l2_scale = 1.0 / (r * channels) as f64;
        let cos_scale = 1.0 / r as f64;
        // Channel by channel over the pairs, so every pass reads the columns
        // contiguously (`s` brought into the rows' order first); each pair's
        // sums still run over the channels in order.
        let mut paired = vec![0.0f32; x.len()];
        for (to, from) in paired.chunks_exact_mut(r).zip(s.chunks_exact(r)) {
            for (t, &j) in to.iter_mut().zip(sigma) {
                *t = from[j];
            }
        }
        let mut dots = vec![0.0f64; r];
        for (xc, sc) in x.chunks_exact(r).zip(paired.chunks_exact(r)) {
            for ((d, &xv), &sv) in dots.iter_mut().zip(xc).zip(sc) {
                *d += f64::from(xv) * f64::from(sv);
            }
        }
        let lens: Vec<f64> = sigma.iter().enumerate().map(|(i, &j)| x_len[i] * s_len[j]).collect();
        let cos: Vec<f64> = dots.iter().zip(&lens).map(|(d, l)| d / l).collect();
        let cosine: f64 = cos.iter().map(|c| 1.0 - c).sum();
        let (l2_w, cos_w) = (f64::from(l2_weight) * 2.0 * l2_scale, f64::from(cosine_weight) * cos_scale);
        let mut l2_of = vec![0.0f64; r];
        for ((gc, xc), sc) in grad.chunks_exact_mut(r).zip(x.chunks_exact(r)).zip(paired.chunks_exact(r)) {
            for i in 0..r {
                let (xv, sv) = (f64::from(xc[i]), f64::from(sc[i]));
                let d = xv - sv;
                l2_of[i] += d * d;
                // ∂(1 − cos)/∂x = −(s/(|x||s|) − cos·x/|x|²).
                let g_cos = -(sv / lens[i] - cos[i] * xv / (x_len[i] * x_len[i]));
                gc[i] = (l2_w * d + cos_w * g_cos) as f32;
            }
        }
        let l2: f64 = l2_of.iter().sum();
        Assignment { cosine: (cosine * cos_scale) as f32, l2: (l2 * l2_scale) as f32, grad }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// λ_as alone: its value and gradient.
    fn l2_only(f: &[f32], c: usize, style: &[f32], mask: Option<&[bool]>) -> (f32, Vec<f32>) {
        let a = assignment_loss(f, c, style, mask, 0.0, 1.0, ASSIGN_BLOCK);
        (a.l2, a.grad)
    }

    fn features(c: usize, n: usize, phase: usize) -> Vec<f32> {
        (0..c * n).map(|i| (((i + phase) * 37 % 101) as f32 / 50.0 - 1.0).abs()).collect()
    }

    #[test]
    fn gradient_matches_finite_differences_for_the_assignment_drawn() {
        // The draw depends on the features' bits, so perturb through a fixed
        // assignment: the loss of `rendered` paired as the unperturbed step paired it.
        let (c, n, m) = (4, 9, 15);
        let f = features(c, n, 0);
        let style = features(c, m, 5);
        let mask: Vec<bool> = (0..n).map(|x| x % 4 != 1).collect();
        let (l, g) = l2_only(&f, c, &style, Some(&mask));
        assert!(l > 0.0);
        // Recover each covered position's target from the gradient: s = x − g·r·C/2.
        let r = mask.iter().filter(|&&b| b).count();
        let target: Vec<f32> = f.iter().zip(&g).map(|(&x, &d)| x - d * (r * c) as f32 / 2.0).collect();
        let fixed = |x: &[f32]| -> f32 {
            let mut s = 0.0f64;
            for ch in 0..c {
                for p in (0..n).filter(|&p| mask[p]) {
                    let d = f64::from(x[ch * n + p]) - f64::from(target[ch * n + p]);
                    s += d * d;
                }
            }
            (s / (r * c) as f64) as f32
        };
        assert!((fixed(&f) - l).abs() < 1e-5, "{} against {l}", fixed(&f));
        let h = 1e-3;
        for i in 0..c * n {
            let (mut up, mut down) = (f.clone(), f.clone());
            up[i] += h;
            down[i] -= h;
            let fd = (fixed(&up) - fixed(&down)) / (2.0 * h);
            assert!((fd - g[i]).abs() < 1e-3, "element {i}: {fd} against {}", g[i]);
        }
        // Every target is one of the style's features, each used once.
        let mut used = Vec::new();
        for p in (0..n).filter(|&p| mask[p]) {
            let t: Vec<f32> = (0..c).map(|ch| target[ch * n + p]).collect();
            let y = (0..m)
                .find(|&y| (0..c).all(|ch| (style[ch * m + y] - t[ch]).abs() < 1e-4))
                .unwrap_or_else(|| panic!("position {p}'s target is no style feature: {t:?}"));
            assert!(!used.contains(&y), "style position {y} used twice");
            used.push(y);
        }
    }

    #[test]
    fn an_all_ones_mask_equals_none_and_uncovered_positions_get_nothing() {
        let (c, n, m) = (3, 10, 12);
        let f = features(c, n, 1);
        let style = features(c, m, 3);
        let all = vec![true; n];
        for (cw, lw) in [(0.0, 1.0), (1.0, 0.0), (2.0, 0.5)] {
            assert_eq!(
                assignment_loss(&f, c, &style, Some(&all), cw, lw, ASSIGN_BLOCK),
                assignment_loss(&f, c, &style, None, cw, lw, ASSIGN_BLOCK)
            );
        }
        let mask: Vec<bool> = (0..n).map(|x| x < 4).collect();
        let (l, g) = l2_only(&f, c, &style, Some(&mask));
        assert!(l > 0.0);
        for ch in 0..c {
            assert!(g[ch * n + 4..(ch + 1) * n].iter().all(|&v| v == 0.0), "channel {ch}");
        }
        let none = vec![false; n];
        let zero = Assignment { cosine: 0.0, l2: 0.0, grad: vec![0.0; c * n] };
        assert_eq!(assignment_loss(&f, c, &style, Some(&none), 1.0, 1.0, ASSIGN_BLOCK), zero);
        assert_eq!(assignment_loss(&f, c, &[], None, 1.0, 1.0, ASSIGN_BLOCK), zero);
        let a = assignment_loss(&f, c, &style, Some(&mask), 1.0, 0.0, ASSIGN_BLOCK);
        assert!(a.cosine > 0.0);
        for ch in 0..c {
            assert!(a.grad[ch * n + 4..(ch + 1) * n].iter().all(|&v| v == 0.0), "channel {ch}, cosine");
        }
    }

    #[test]
    fn a_rendered_set_equal_to_the_style_costs_nothing() {
        // The same features in another order: the assignment undoes the order.
        let (c, n) = (5, 11);
        let style = features(c, n, 2);
        let order: Vec<usize> = (0..n).map(|i| (i * 4) % n).collect();
        let rendered = gather_positions(&style, c, n, &order);
        let (l, g) = l2_only(&rendered, c, &style, None);
        assert!(l < 1e-10 && g.iter().all(|v| v.abs() < 1e-6), "{l}");
        // The cosine pull ignores lengths: thrice the permuted style costs it
        // nothing while the squared pull still pulls.
        let longer: Vec<f32> = rendered.iter().map(|v| 3.0 * v).collect();
        let a = assignment_loss(&longer, c, &style, None, 1.0, 0.0, ASSIGN_BLOCK);
        assert!(a.cosine.abs() < 1e-6 && a.grad.iter().all(|v| v.abs() < 1e-5), "{}", a.cosine);
        assert!(assignment_loss(&longer, c, &style, None, 1.0, 1.0, ASSIGN_BLOCK).l2 > 1.0);
    }

    #[test]
    fn more_covered_positions_than_the_cap_pair_a_subset_and_fewer_style_ones_repeat() {
        let c = 2;
        let n = ASSIGN_MAX + 40;
        let f = features(c, n, 0);
        let style = features(c, 30, 9);
        let (l, g) = l2_only(&f, c, &style, None);
        assert!(l.is_finite() && l > 0.0);
        let moved = (0..n).filter(|&p| (0..c).any(|ch| g[ch * n + p] != 0.0)).count();
        assert!(moved <= ASSIGN_MAX && moved > ASSIGN_MAX / 2, "{moved} positions pulled");
        // Deterministic: the draw is seeded by the features.
        assert_eq!(l2_only(&f, c, &style, None), (l, g));
    }

    #[test]
    fn both_pulls_match_finite_differences_when_the_whole_style_is_drawn() {
        // With as many style features as covered positions every draw takes
        // all of them, so the least-cost pairing, and the terms, are
        // functions of the rendered features alone (away from ties).
        let (c, n) = (4, 9);
        let mask: Vec<bool> = (0..n).map(|x| x != 2 && x != 6).collect();
        let m = mask.iter().filter(|&&b| b).count();
        let f = features(c, n, 0);
        let style: Vec<f32> = features(c, m, 5).iter().enumerate().map(|(i, v)| v + 0.1 * (i % 3) as f32).collect();
        for (cw, lw) in [(1.0f32, 0.0f32), (0.0, 1.0), (10.0, 0.003)] {
            let value = |x: &[f32]| {
                let a = assignment_loss(x, c, &style, Some(&mask), cw, lw, ASSIGN_BLOCK);
                f64::from(cw) * f64::from(a.cosine) + f64::from(lw) * f64::from(a.l2)
            };
            let g = assignment_loss(&f, c, &style, Some(&mask), cw, lw, ASSIGN_BLOCK).grad;
            let h = 1e-3;
            for i in 0..c * n {
                let (mut up, mut down) = (f.clone(), f.clone());
                up[i] += h;
                down[i] -= h;
                let fd = ((value(&up) - value(&down)) / (2.0 * f64::from(h))) as f32;
                let tol = 2e-3 * (1.0 + g[i].abs());
                assert!((fd - g[i]).abs() < tol, "λ_asc {cw}, λ_as {lw}, element {i}: {fd} against {}", g[i]);
            }
        }
    }

    #[test]
    fn the_cosine_pairing_takes_the_closest_directions_not_the_closest_points() {
        // Rendered (1, 0) at 0° and (3, 1) at 18.4°; style (1, 0.4) at 21.8°
        // and (3, 0) at 0°. The squared distance pairs the near points (each
        // 22° or 18° off in direction); the cosine distance pairs crosswise,
        // 0° and 3.4° off, at eight times the squared distance.
        let c = 2;
        let rendered = [1.0, 3.0, /* y: */ 0.0, 1.0];
        let style = [1.0, 3.0, /* y: */ 0.4, 0.0];
        let by_cos = assignment_loss(&rendered, c, &style, None, 1.0, 0.0, ASSIGN_BLOCK);
        let by_l2 = assignment_loss(&rendered, c, &style, None, 0.0, 1.0, ASSIGN_BLOCK);
        assert!(by_cos.cosine < 0.002 && by_l2.cosine > 0.05, "{} {}", by_cos.cosine, by_l2.cosine);
        assert!(by_l2.l2 < 0.3 && by_cos.l2 > 2.0, "{} {}", by_l2.l2, by_cos.l2);
    }

    #[test]
    fn the_blocks_deal_every_row_once_and_hold_at_most_a_block() {
        for (r, block) in [(0usize, 256usize), (1, 256), (256, 256), (257, 256), (405, 256), (512, 128), (10, 3)] {
            let blocks = pair_blocks(r, block);
            assert_eq!(blocks.len(), r.div_ceil(block).max(1), "{r} rows in blocks of {block}");
            let mut seen = vec![0u32; r];
            for b in &blocks {
                assert!(b.len() <= block, "{r} rows in blocks of {block}: a block of {}", b.len());
                assert!(b.windows(2).all(|w| w[0] < w[1]));
                for &i in b {
                    seen[i] += 1;
                }
            }
            assert!(seen.iter().all(|&n| n == 1), "{r} rows in blocks of {block}");
        }
    }

    /// The pairing in blocks is one-to-one over all rows, keeps each pair
    /// inside its block, takes each block's least cost (the plain shortest
    /// paths' on the block's own matrix), and with one block is the whole
    /// assignment of least cost.
    #[test]
    fn the_pairing_in_blocks_is_one_to_one_and_least_cost_in_each_block() {
        use super::super::min_cost::{assign_shortest_paths, assignment_cost};
        let (c, r) = (6, 70);
        let x: Vec<f32> = features(c, r, 3).iter().enumerate().map(|(i, v)| v + (i % 7) as f32 * 0.05).collect();
        let s = features(c, r, 11);
        for cosine in [true, false] {
            let whole = PairCosts::new(&x, &s, c, cosine, r);
            assert_eq!(whole.blocks.len(), 1);
            let best = whole.assign();
            let plain = assign_shortest_paths(&whole.blocks[0].cost, r, r);
            assert!((whole.total(&best) - assignment_cost(&whole.blocks[0].cost, r, &plain)).abs() < 1e-9);
            for block in [32usize, 25, 7] {
                let costs = PairCosts::new(&x, &s, c, cosine, block);
                assert_eq!(costs.blocks.len(), r.div_ceil(block));
                let sigma = costs.assign();
                let mut taken = vec![false; r];
                for &j in &sigma {
                    assert!(!taken[j], "block {block}: column {j} taken twice");
                    taken[j] = true;
                }
                let mut total = 0.0;
                for b in &costs.blocks {
                    let n = b.rows.len();
                    let local: Vec<usize> = b
                        .rows
                        .iter()
                        .map(|&i| b.rows.binary_search(&sigma[i]).expect("a pair across blocks"))
                        .collect();
                    let least = assign_shortest_paths(&b.cost, n, n);
                    let (got, want) = (assignment_cost(&b.cost, n, &local), assignment_cost(&b.cost, n, &least));
                    assert!((got - want).abs() < 1e-9, "block {block}: {got} against {want}");
                    // The block's costs are the whole matrix's entries.
                    for (a, &i) in b.rows.iter().enumerate() {
                        for (k, &j) in b.rows.iter().enumerate() {
                            assert!((b.cost[a * n + k] - whole.blocks[0].cost[i * r + j]).abs() < 1e-6);
                        }
                    }
                    total += got;
                }
                assert!((costs.total(&sigma) - total).abs() < 1e-9);
                // Blocks can only cost more than the whole assignment.
                assert!(total >= whole.total(&best) - 1e-9, "block {block}");
            }
        }
    }
}
