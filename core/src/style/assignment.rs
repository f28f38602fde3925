//! The assignment term (λ_as; not in the reference, off by default): every
//! covered rendered RGB relu3 feature is paired with a *distinct* style
//! feature, drawn anew each step, by the one-to-one assignment of least total
//! squared distance, and pulled to it:
//!
//! `(1/(r·C)) Σ_i ‖F(x_i) − F^S(y_σ(i))‖²`
//!
//! over the `r` rendered positions `x_i` (the object's with object focus) and
//! `r` style positions `y_j` drawn uniformly without repetition, `σ` the
//! minimum-cost assignment (Hungarian algorithm, [`assign_min_cost`]).
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
//! set is pulled toward a sample of the style's distribution.
//!
//! The draw is seeded by the rendered features' own bits, so a run is
//! reproducible and each step draws anew. At most [`ASSIGN_MAX`] rendered
//! positions take part in a step (a fresh random subset when more are
//! covered): the assignment costs `O(r³)`.

use super::focus::gather_positions;
use super::gcfm::column_sq_norms;
use crate::rng::Rng;
use crate::vision::matmul;

/// Most rendered positions one step's assignment pairs (its cost is cubic in it).
pub const ASSIGN_MAX: usize = 512;

/// For each of the `n` rows of the row-major `n × k` matrix `cost` (`n ≤ k`),
/// the column it takes in an assignment of distinct columns of least total
/// cost (the Hungarian algorithm with potentials, `O(n²k)`). Costs that are
/// not finite count as very large.
pub fn assign_min_cost(cost: &[f64], n: usize, k: usize) -> Vec<usize> {
    assert!(n <= k, "assign_min_cost: {n} rows need at least as many columns, found {k}");
    assert_eq!(cost.len(), n * k, "assign_min_cost: the cost matrix's size");
    const HUGE: f64 = 1e30;
    let at = |i: usize, j: usize| {
        let c = cost[i * k + j];
        if c.is_finite() { c } else { HUGE }
    };
    // 1-based rows and columns; column 0 is the algorithm's virtual one.
    let (mut u, mut v) = (vec![0.0f64; n + 1], vec![0.0f64; k + 1]);
    let (mut owner, mut way) = (vec![0usize; k + 1], vec![0usize; k + 1]);
    let (mut min_v, mut used) = (vec![0.0f64; k + 1], vec![false; k + 1]);
    for i in 1..=n {
        owner[0] = i;
        let mut j0 = 0;
        min_v.fill(f64::INFINITY);
        used.fill(false);
        loop {
            used[j0] = true;
            let i0 = owner[j0];
            let (mut delta, mut j1) = (f64::INFINITY, 0);
            for j in 1..=k {
                if !used[j] {
                    let reduced = at(i0 - 1, j - 1) - u[i0] - v[j];
                    if reduced < min_v[j] {
                        min_v[j] = reduced;
                        way[j] = j0;
                    }
                    if min_v[j] < delta {
                        delta = min_v[j];
                        j1 = j;
                    }
                }
            }
            for j in 0..=k {
                if used[j] {
                    u[owner[j]] += delta;
                    v[j] -= delta;
                } else {
                    min_v[j] -= delta;
                }
            }
            j0 = j1;
            if owner[j0] == 0 {
                break;
            }
        }
        // Flip the augmenting path.
        while j0 != 0 {
            let j1 = way[j0];
            owner[j0] = owner[j1];
            j0 = j1;
        }
    }
    let mut column = vec![0usize; n];
    for j in 1..=k {
        if owner[j] != 0 {
            column[owner[j] - 1] = j - 1;
        }
    }
    column
}

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

/// The term and its gradient w.r.t. `rendered` (`channels × n`, CHW) against
/// the style features `style` (`channels × m`, CHW), over the positions in
/// `mask` (all without one). Positions outside the mask, or left out of this
/// step's subset, get a zero gradient. An empty mask or style gives `(0, zeros)`.
pub fn assignment_loss(rendered: &[f32], channels: usize, style: &[f32], mask: Option<&[bool]>) -> (f32, Vec<f32>) {
    let channels = channels.max(1);
    let n = rendered.len() / channels;
    let m = style.len() / channels;
    let mut grad = vec![0.0f32; rendered.len()];
    let covered: Vec<usize> = (0..n).filter(|&i| mask.is_none_or(|k| k[i])).collect();
    if covered.is_empty() || m == 0 {
        return (0.0, grad);
    }
    let mut rng = Rng::new(seed_of(rendered, n, &covered));
    let rows: Vec<usize> = if covered.len() > ASSIGN_MAX {
        let mut pick: Vec<usize> = draw(&mut rng, covered.len(), ASSIGN_MAX).into_iter().map(|t| covered[t]).collect();
        pick.sort_unstable();
        pick
    } else {
        covered
    };
    let r = rows.len();
    let targets = draw(&mut rng, m, r);
    let x = gather_positions(rendered, channels, n, &rows);
    let s = gather_positions(style, channels, m, &targets);
    // Squared distances ‖x_i‖² + ‖s_j‖² − 2 x_i·s_j.
    let mut dot = vec![0.0f32; r * r];
    matmul(&mut dot, r, (&x, 1, r), (&s, r), (r, r, channels), false);
    let (xx, ss) = (column_sq_norms(&x, channels, r), column_sq_norms(&s, channels, r));
    let cost: Vec<f64> = (0..r * r).map(|ij| xx[ij / r] + ss[ij % r] - 2.0 * f64::from(dot[ij])).collect();
    let sigma = assign_min_cost(&cost, r, r);
    // The loss and its gradient from the features themselves (not the
    // cancelling expansion above).
    let scale = 1.0 / (r * channels) as f64;
    let mut loss = 0.0f64;
    for c in 0..channels {
        for (i, &pos) in rows.iter().enumerate() {
            let d = f64::from(x[c * r + i]) - f64::from(s[c * r + sigma[i]]);
            loss += d * d;
            grad[c * n + pos] = (2.0 * d * scale) as f32;
        }
    }
    ((loss * scale) as f32, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(c: usize, n: usize, phase: usize) -> Vec<f32> {
        (0..c * n).map(|i| (((i + phase) * 37 % 101) as f32 / 50.0 - 1.0).abs()).collect()
    }

    /// The least total cost over every injective choice of columns, by brute force.
    fn brute(cost: &[f64], n: usize, k: usize) -> f64 {
        fn go(row: usize, cost: &[f64], n: usize, k: usize, used: &mut Vec<bool>) -> f64 {
            if row == n {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            for j in 0..k {
                if !used[j] {
                    used[j] = true;
                    best = best.min(cost[row * k + j] + go(row + 1, cost, n, k, used));
                    used[j] = false;
                }
            }
            best
        }
        go(0, cost, n, k, &mut vec![false; k])
    }

    #[test]
    fn the_assignment_is_one_to_one_and_of_least_cost() {
        let mut rng = Rng::new(7);
        for (n, k) in [(1, 1), (3, 3), (4, 6), (6, 6), (5, 8)] {
            for _ in 0..20 {
                let cost: Vec<f64> = (0..n * k).map(|_| f64::from(rng.uniform() * 10.0).floor()).collect();
                let sigma = assign_min_cost(&cost, n, k);
                let mut seen = vec![false; k];
                for &j in &sigma {
                    assert!(!seen[j], "column {j} taken twice ({n}×{k})");
                    seen[j] = true;
                }
                let total: f64 = sigma.iter().enumerate().map(|(i, &j)| cost[i * k + j]).sum();
                assert!((total - brute(&cost, n, k)).abs() < 1e-9, "{n}×{k}: {total} against {}", brute(&cost, n, k));
            }
        }
        // Non-finite costs are avoided, not looped on.
        let cost = [f64::NAN, 1.0, 2.0, f64::INFINITY];
        assert_eq!(assign_min_cost(&cost, 2, 2), vec![1, 0]);
    }

    #[test]
    fn gradient_matches_finite_differences_for_the_assignment_drawn() {
        // The draw depends on the features' bits, so perturb through a fixed
        // assignment: the loss of `rendered` paired as the unperturbed step paired it.
        let (c, n, m) = (4, 9, 15);
        let f = features(c, n, 0);
        let style = features(c, m, 5);
        let mask: Vec<bool> = (0..n).map(|x| x % 4 != 1).collect();
        let (l, g) = assignment_loss(&f, c, &style, Some(&mask));
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
        assert_eq!(assignment_loss(&f, c, &style, Some(&all)), assignment_loss(&f, c, &style, None));
        let mask: Vec<bool> = (0..n).map(|x| x < 4).collect();
        let (l, g) = assignment_loss(&f, c, &style, Some(&mask));
        assert!(l > 0.0);
        for ch in 0..c {
            assert!(g[ch * n + 4..(ch + 1) * n].iter().all(|&v| v == 0.0), "channel {ch}");
        }
        let none = vec![false; n];
        assert_eq!(assignment_loss(&f, c, &style, Some(&none)), (0.0, vec![0.0; c * n]));
        assert_eq!(assignment_loss(&f, c, &[], None), (0.0, vec![0.0; c * n]));
    }

    #[test]
    fn a_rendered_set_equal_to_the_style_costs_nothing() {
        // The same features in another order: the assignment undoes the order.
        let (c, n) = (5, 11);
        let style = features(c, n, 2);
        let order: Vec<usize> = (0..n).map(|i| (i * 4) % n).collect();
        let rendered = gather_positions(&style, c, n, &order);
        let (l, g) = assignment_loss(&rendered, c, &style, None);
        assert!(l < 1e-10 && g.iter().all(|v| v.abs() < 1e-6), "{l}");
    }

    #[test]
    fn more_covered_positions_than_the_cap_pair_a_subset_and_fewer_style_ones_repeat() {
        let c = 2;
        let n = ASSIGN_MAX + 40;
        let f = features(c, n, 0);
        let style = features(c, 30, 9);
        let (l, g) = assignment_loss(&f, c, &style, None);
        assert!(l.is_finite() && l > 0.0);
        let moved = (0..n).filter(|&p| (0..c).any(|ch| g[ch * n + p] != 0.0)).count();
        assert!(moved <= ASSIGN_MAX && moved > ASSIGN_MAX / 2, "{moved} positions pulled");
        // Deterministic: the draw is seeded by the features.
        assert_eq!(assignment_loss(&f, c, &style, None), (l, g));
    }
}
