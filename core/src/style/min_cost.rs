//! The least-cost one-to-one assignment the assignment terms pair by
//! ([`super::assignment`]): rows to distinct columns of a dense cost matrix.
//!
//! [`assign_min_cost`] follows Jonker and Volgenant ("A shortest augmenting
//! path algorithm for dense and sparse linear assignment problems",
//! Computing 38, 1987): a cheap start (column reduction and the reduction's
//! transfer: each column's potential its least cost, a row taking a column
//! where it is the cheapest) and shortest augmenting paths, a whole level of
//! equally near columns at a time, for the rows left free. Their augmenting
//! row reduction (auction-like bids of the free rows on their two cheapest
//! columns) is left out: on the crowded relu3 cosine costs the assignment
//! terms pair, where many rows are cheapest in the same few columns, its bids
//! move the potentials by tiny steps, and with it the assignment took 1.5–1.9
//! times the plain paths' time instead of 0.7 (`gast bench pairing`,
//! `docs/figures.md`). The plain shortest augmenting paths, every row
//! searched from an empty assignment ([`assign_shortest_paths`]), stay as
//! its reference: both give an assignment of least cost, the same one when
//! that is unique.

const NONE: usize = usize::MAX;
/// What a cost that is not finite counts as.
const HUGE: f64 = 1e30;

/// `cost` with every non-finite entry replaced by [`HUGE`], or `None` when all are finite.
fn finite_costs(cost: &[f64]) -> Option<Vec<f64>> {
    (!cost.iter().all(|c| c.is_finite())).then(|| cost.iter().map(|&c| if c.is_finite() { c } else { HUGE }).collect())
}

/// For each of the `n` rows of the row-major `n × k` matrix `cost` (`n ≤ k`),
/// the column it takes in an assignment of distinct columns of least total
/// cost. Costs that are not finite count as very large. A rectangular matrix
/// is solved as a square one whose `k − n` extra rows cost nothing anywhere.
pub fn assign_min_cost(cost: &[f64], n: usize, k: usize) -> Vec<usize> {
    assert!(n <= k, "assign_min_cost: {n} rows need at least as many columns, found {k}");
    assert_eq!(cost.len(), n * k, "assign_min_cost: the cost matrix's size");
    if n == 0 {
        return Vec::new();
    }
    let mut square = finite_costs(cost).unwrap_or_else(|| if n < k { cost.to_vec() } else { Vec::new() });
    if n < k {
        square.resize(k * k, 0.0);
    }
    let c = if square.is_empty() { cost } else { &square };
    let mut col_of = jonker_volgenant(c, k);
    col_of.truncate(n);
    col_of
}

/// [`assign_min_cost`] of a square `n × n` matrix of finite costs.
fn jonker_volgenant(c: &[f64], n: usize) -> Vec<usize> {
    let (mut col_of, mut row_of) = (vec![NONE; n], vec![NONE; n]);
    // Column reduction: each column's potential is its least cost; a row
    // takes the last column that is cheapest in it.
    let mut v = vec![f64::INFINITY; n];
    let mut cheapest = vec![0usize; n];
    for i in 0..n {
        for (j, &x) in c[i * n..(i + 1) * n].iter().enumerate() {
            if x < v[j] {
                v[j] = x;
                cheapest[j] = i;
            }
        }
    }
    let mut unique = vec![true; n];
    for j in (0..n).rev() {
        let i = cheapest[j];
        if col_of[i] == NONE {
            col_of[i] = j;
            row_of[j] = i;
        } else {
            unique[i] = false;
        }
    }
    // Reduction transfer: a row that took a single column lowers its
    // potential to the row's next cheapest reduced cost.
    let mut free = Vec::new();
    for i in 0..n {
        if col_of[i] == NONE {
            free.push(i);
        } else if unique[i] && n > 1 {
            let j = col_of[i];
            let row = &c[i * n..(i + 1) * n];
            let next = (0..n).filter(|&t| t != j).map(|t| row[t] - v[t]).fold(f64::INFINITY, f64::min);
            v[j] -= next;
        }
    }
    let mut work = PathWork { d: vec![0.0; n], cols: vec![0; n], pred: vec![0; n] };
    for &start in &free {
        augment(c, n, start, &mut col_of, &mut row_of, &mut v, &mut work);
    }
    col_of
}

/// A shortest path search's arrays, reused from row to row.
struct PathWork {
    /// Shortest reduced distance found to each column.
    d: Vec<f64>,
    /// The columns: settled ones first, then those at the current least
    /// distance still to scan, then the rest.
    cols: Vec<usize>,
    /// The row each column was reached from.
    pred: Vec<usize>,
}

/// Assigns the free row `start` along a shortest augmenting path of reduced
/// costs (Dijkstra over the columns, a whole level of equally near columns
/// at a time), then updates the settled columns' potentials.
// The scans run over the columns past `hi` as it was when each began; `hi`
// grows within them as columns join the level (those are swapped to it).
#[allow(clippy::mut_range_bound)]
fn augment(
    c: &[f64],
    n: usize,
    start: usize,
    col_of: &mut [usize],
    row_of: &mut [usize],
    v: &mut [f64],
    work: &mut PathWork,
) {
    let PathWork { d, cols, pred } = work;
    for j in 0..n {
        cols[j] = j;
        pred[j] = start;
        d[j] = c[start * n + j] - v[j];
    }
    // cols[..ready] settled, cols[lo..hi] at the least distance, to scan.
    let (mut lo, mut hi, mut ready) = (0usize, 0usize, 0usize);
    let sink = 'search: loop {
        if lo == hi {
            // The next level: every column at the least distance left.
            ready = lo;
            hi = lo + 1;
            let mut least = d[cols[lo]];
            for t in hi..n {
                let j = cols[t];
                if d[j] <= least {
                    if d[j] < least {
                        hi = lo;
                        least = d[j];
                    }
                    cols.swap(t, hi);
                    hi += 1;
                }
            }
            if let Some(&j) = cols[lo..hi].iter().find(|&&j| row_of[j] == NONE) {
                break 'search j;
            }
        }
        // Scan the level's columns through the rows that hold them.
        while lo != hi {
            let j = cols[lo];
            lo += 1;
            let i = row_of[j];
            let least = d[j];
            let row = &c[i * n..(i + 1) * n];
            let h = row[j] - v[j] - least;
            for t in hi..n {
                let j = cols[t];
                let reduced = row[j] - v[j] - h;
                if reduced < d[j] {
                    d[j] = reduced;
                    pred[j] = i;
                    if reduced == least {
                        if row_of[j] == NONE {
                            break 'search j;
                        }
                        cols.swap(t, hi);
                        hi += 1;
                    }
                }
            }
        }
    };
    // The settled columns' potentials, then the path flipped.
    let reach = d[sink];
    for &j in &cols[..ready] {
        v[j] += d[j] - reach;
    }
    let mut j = sink;
    loop {
        let i = pred[j];
        row_of[j] = i;
        std::mem::swap(&mut col_of[i], &mut j);
        if i == start {
            break;
        }
    }
}

/// The total cost of an assignment: row `i` takes column `sigma[i]` of the
/// `n × k` row-major `cost` (`n = sigma.len()`).
pub fn assignment_cost(cost: &[f64], k: usize, sigma: &[usize]) -> f64 {
    sigma.iter().enumerate().map(|(i, &j)| cost[i * k + j]).sum()
}

/// For each of the `n` rows of the row-major `n × k` matrix `cost` (`n ≤ k`),
/// the column it takes in an assignment of distinct columns of least total
/// cost. Costs that are not finite count as very large.
///
/// The shortest augmenting path algorithm with dual potentials, in the form
/// of Crouse ("On implementing 2D rectangular assignment algorithms", IEEE
/// TAES 2016): each row's Dijkstra search scans only the columns it has not
/// reached yet and updates the potentials once, at its end, so a search
/// costs one pass over the remaining columns per step of its path. On the
/// relu3 cosine costs of a 1,024 px guitar render against wave (512 × 512)
/// it takes 27 ms where the textbook Hungarian form (two passes over every
/// column per step) took 74 ms, with the same assignment (`docs/figures.md`).
/// [`assign_min_cost`] starts it from Jonker and Volgenant's initial
/// assignment; this plain form stays as the reference it is tested and
/// benchmarked against (`gast bench pairing`).
pub fn assign_shortest_paths(cost: &[f64], n: usize, k: usize) -> Vec<usize> {
    assert!(n <= k, "assign_shortest_paths: {n} rows need at least as many columns, found {k}");
    assert_eq!(cost.len(), n * k, "assign_shortest_paths: the cost matrix's size");
    let finite = finite_costs(cost);
    let cost = finite.as_deref().unwrap_or(cost);
    let (mut u, mut v) = (vec![0.0f64; n], vec![0.0f64; k]);
    let mut shortest = vec![f64::INFINITY; k];
    let mut path = vec![NONE; k];
    let (mut col_of, mut row_of) = (vec![NONE; n], vec![NONE; k]);
    let (mut rows_seen, mut cols_seen) = (vec![false; n], vec![false; k]);
    let mut remaining = vec![0usize; k];
    for start in 0..n {
        // Dijkstra from `start` over reduced costs until a free column.
        let mut min_val = 0.0f64;
        let mut i = start;
        for (t, r) in remaining.iter_mut().enumerate() {
            *r = k - 1 - t;
        }
        let mut left = k;
        rows_seen.fill(false);
        cols_seen.fill(false);
        shortest.fill(f64::INFINITY);
        let sink = loop {
            rows_seen[i] = true;
            let row = &cost[i * k..(i + 1) * k];
            let base = min_val - u[i];
            let (mut index, mut lowest) = (0, f64::INFINITY);
            for (t, &j) in remaining[..left].iter().enumerate() {
                let reduced = base + row[j] - v[j];
                if reduced < shortest[j] {
                    path[j] = i;
                    shortest[j] = reduced;
                }
                // Ties go to a free column, which ends the search.
                if shortest[j] < lowest || (shortest[j] == lowest && row_of[j] == NONE) {
                    lowest = shortest[j];
                    index = t;
                }
            }
            min_val = lowest;
            let j = remaining[index];
            cols_seen[j] = true;
            left -= 1;
            remaining[index] = remaining[left];
            if row_of[j] == NONE {
                break j;
            }
            i = row_of[j];
        };
        // The potentials of the rows and columns the search reached.
        u[start] += min_val;
        for r in (0..n).filter(|&r| rows_seen[r] && r != start) {
            u[r] += min_val - shortest[col_of[r]];
        }
        for j in (0..k).filter(|&j| cols_seen[j]) {
            v[j] -= min_val - shortest[j];
        }
        // Flip the augmenting path.
        let mut j = sink;
        loop {
            let r = path[j];
            row_of[j] = r;
            std::mem::swap(&mut col_of[r], &mut j);
            if r == start {
                break;
            }
        }
    }
    col_of
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

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
                for solve in [assign_min_cost, assign_shortest_paths] {
                    let sigma = solve(&cost, n, k);
                    let mut seen = vec![false; k];
                    for &j in &sigma {
                        assert!(!seen[j], "column {j} taken twice ({n}×{k})");
                        seen[j] = true;
                    }
                    let total = assignment_cost(&cost, k, &sigma);
                    assert!(
                        (total - brute(&cost, n, k)).abs() < 1e-9,
                        "{n}×{k}: {total} against {}",
                        brute(&cost, n, k)
                    );
                }
            }
        }
        // Non-finite costs are avoided, not looped on.
        let cost = [f64::NAN, 1.0, 2.0, f64::INFINITY];
        assert_eq!(assign_min_cost(&cost, 2, 2), vec![1, 0]);
        assert_eq!(assign_shortest_paths(&cost, 2, 2), vec![1, 0]);
    }

    /// Both methods give assignments of the same least cost on larger
    /// matrices, continuous (where the assignment is unique: the same one)
    /// and of few distinct values (many ties), crowded as relu3 cosine costs
    /// are (many rows cheapest in the same few columns).
    #[test]
    fn jonker_volgenant_matches_the_plain_shortest_paths() {
        let mut rng = Rng::new(3);
        for (n, k, levels, crowd) in [
            (40, 40, 0, 0.0),
            (64, 64, 5, 0.0),
            (50, 70, 0, 0.0),
            (120, 120, 0, 2.0),
            (90, 90, 3, 1.0),
            (200, 200, 0, 4.0),
        ] {
            for _ in 0..3 {
                // A crowd: columns below k/8 are cheaper for every row by `crowd` spread.
                let cost: Vec<f64> = (0..n * k)
                    .map(|ij| {
                        let x = f64::from(rng.uniform());
                        let x = if levels > 0 { (x * levels as f64).floor() } else { x };
                        if ij % k < k / 8 { x - crowd * f64::from(rng.uniform()) } else { x }
                    })
                    .collect();
                let (a, b) = (assign_min_cost(&cost, n, k), assign_shortest_paths(&cost, n, k));
                let total = |s: &[usize]| assignment_cost(&cost, k, s);
                let mut seen = vec![false; k];
                for &j in &a {
                    assert!(!seen[j], "{n}×{k}: column {j} taken twice");
                    seen[j] = true;
                }
                assert!(
                    (total(&a) - total(&b)).abs() < 1e-9,
                    "{n}×{k}, {levels} levels: {} against {}",
                    total(&a),
                    total(&b)
                );
                if levels == 0 {
                    assert_eq!(a, b, "{n}×{k}: a unique least-cost assignment");
                }
            }
        }
    }
}
