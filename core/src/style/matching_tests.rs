//! The index against the exact search: exhaustive re-ranking is exact; the
//! approximation agrees on structured features.

use super::*;
use crate::style::gcfm::match_features_dense;

/// Non-negative, ReLU-like features with a low-rank structure plus noise
/// (like VGG's), `c × n`.
fn feats(c: usize, n: usize, seed: u64) -> Vec<f32> {
    let base = noise(4 * c, 77);
    let mix = noise(4 * n, seed);
    let jitter = noise(c * n, seed + 1);
    (0..c * n)
        .map(|i| {
            let (ch, x) = (i / n, i % n);
            let v: f32 = (0..4).map(|r| base[r * c + ch] * mix[r * n + x]).sum();
            (v + 0.2 * jitter[i]).max(0.0)
        })
        .collect()
}

fn style(c: usize, hs: usize, ws: usize) -> StyleFeatures {
    let m = hs * ws;
    StyleFeatures::new([feats(c, m, 1), feats(c, m, 2), feats(c, m, 3)], c, hs, ws)
}

#[test]
fn exhaustive_candidates_return_the_exact_matches() {
    let (c, n) = (24, 200);
    let st = style(c, 9, 13);
    let r = [feats(c, n, 4), feats(c, n, 5), feats(c, n, 6)];
    let rr = [&r[0][..], &r[1][..], &r[2][..]];
    let exact = match_features(&st, rr, n);
    assert_eq!(exact, match_features_dense(&st, rr, n));
    for dims in [1, 8, 3 * c] {
        let ix = MatchIndex::build(&st, dims);
        assert_eq!(ix.search(rr, n, st.positions()), exact, "{dims} dimensions, every position re-ranked");
    }
    let config = MatchingConfig { method: MatchMethod::Pca, candidates: u32::MAX, ..MatchingConfig::default() };
    let ix = MatchIndex::build(&st, 4);
    assert_eq!(find_matches(&st, Some(&ix), &config, rr, n), exact);
    assert_eq!(agreement(&exact, &exact), (1.0, 1.0));
}

#[test]
fn full_subspace_with_few_candidates_is_exact_and_a_small_one_mostly_agrees() {
    let (c, n) = (16, 300);
    let st = style(c, 12, 15);
    let r = [feats(c, n, 7), feats(c, n, 8), feats(c, n, 9)];
    let rr = [&r[0][..], &r[1][..], &r[2][..]];
    let exact = match_features(&st, rr, n);
    // The whole space: subspace scores are the exact ones up to f32 rounding, so
    // the exact extremum is among a few candidates.
    let full = MatchIndex::build(&st, 3 * c).search(rr, n, 16);
    assert_eq!(agreement(&full, &exact), (1.0, 1.0));
    let (b, w) = agreement(&MatchIndex::build(&st, 8).search(rr, n, 16), &exact);
    println!(
        "8 of {} dimensions, 16 candidates: {:.1}% nearest, {:.1}% farthest identical",
        3 * c,
        b * 100.0,
        w * 100.0
    );
    assert!(b > 0.5 && w > 0.5, "the index should find most matches of rank-4 features: {b} {w}");
}

/// The one-pass selection keeps exactly the k largest keys, ties included
/// up to which of the tied ones it keeps.
#[test]
fn top_k_keeps_the_largest_keys() {
    let keys: Vec<f32> = noise(5000, 31).iter().map(|v| (v * 40.0).round()).collect();
    for k in [1, 7, 32, 4999] {
        let mut top = TopK::new(k);
        for round in 0..2 {
            top.clear();
            keys.iter().enumerate().for_each(|(y, &v)| top.offer(if round == 0 { v } else { -v }, y as u32));
            let mut got: Vec<f32> =
                top.finish().iter().map(|&y| if round == 0 { keys[y as usize] } else { -keys[y as usize] }).collect();
            let mut want: Vec<f32> = keys.iter().map(|&v| if round == 0 { v } else { -v }).collect();
            want.sort_by(|a, b| b.total_cmp(a));
            want.truncate(k);
            got.sort_by(|a, b| b.total_cmp(a));
            assert_eq!(got, want, "k = {k}, round {round}");
        }
    }
}
