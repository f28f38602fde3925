//! Tests of the GCFM matching and loss: tiled against dense, finite differences, timing.

use super::*;

fn feats(c: usize, n: usize, seed: u64) -> Vec<f32> {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..c * n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // ReLU-like: non-negative with some zeros.
            (((x >> 11) as f64 / (1u64 << 53) as f64) as f32 - 0.3).max(0.0)
        })
        .collect()
}

fn style(c: usize, hs: usize, ws: usize) -> StyleFeatures {
    let m = hs * ws;
    StyleFeatures::new([feats(c, m, 1), feats(c, m, 2), feats(c, m, 3)], c, hs, ws)
}

#[test]
fn tiled_matching_equals_dense() {
    let (c, n) = (24, 300);
    let st = style(c, 9, 13);
    let r = [feats(c, n, 4), feats(c, n, 5), feats(c, n, 6)];
    let rr = [&r[0][..], &r[1][..], &r[2][..]];
    assert_eq!(match_features(&st, rr, n), match_features_dense(&st, rr, n));
}

/// A search's tiles are even, a multiple of the threads when they fill them,
/// and otherwise spread each product over the threads; the matches are the
/// dense search's on 1, 2 and 5 threads either way.
#[test]
fn row_tiles_balance_the_threads_and_keep_the_matches() {
    let on = |threads: usize, n: usize, m: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
        let (tile, par) = pool.install(|| row_tiles(n, m));
        (tile, matches!(par, gemm::Parallelism::Rayon(_)))
    };
    // fern at 256 px: 768 rows against 2,304 style positions, tiles of 455 and 313 rows before.
    assert_eq!(on(2, 768, 2304), (384, false));
    assert_eq!(on(1, 768, 2304), (384, false));
    assert_eq!(on(2, 5000, 2304), (417, false), "11 tiles of at most 455 rows made 12");
    // An object's few rows against a large style: one tile, its product spread.
    assert_eq!(on(2, 100, 8576), (100, true));
    assert_eq!(on(16, 768, 2304), (384, true));
    assert_eq!(on(2, 0, 10), (1, true), "no rows");

    let (c, n) = (24, 300);
    let st = style(c, 60, 64); // 3,840 positions: two tiles of 150 rows
    let r = [feats(c, n, 4), feats(c, n, 5), feats(c, n, 6)];
    let rr = [&r[0][..], &r[1][..], &r[2][..]];
    let dense = match_features_dense(&st, rr, n);
    for threads in [1, 2, 5] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
        assert_eq!(pool.install(|| match_every_position(&st, rr, n)), dense, "{threads} threads");
    }
}

#[test]
fn exact_copy_matches_itself() {
    let (c, hs, ws) = (16, 5, 7);
    let st = style(c, hs, ws);
    let m = hs * ws;
    // Rendered = style columns 3, 10, 20.
    let pick = [3usize, 10, 20];
    let r: [Vec<f32>; 3] = std::array::from_fn(|k| {
        let s = st.modality(k);
        (0..c).flat_map(|ch| pick.iter().map(move |&y| s[ch * m + y])).collect()
    });
    let mt = match_features(&st, [&r[0], &r[1], &r[2]], pick.len());
    assert_eq!(mt.best, vec![3, 10, 20]);
    let out = gcfm_loss(&st, [&r[0], &r[1], &r[2]], pick.len());
    // Attract terms vanish: each modality contributes mean(1 + cos⁻) only.
    assert!(out.loss >= 0.0 && out.loss < 6.0);
}

/// Timing at realistic sizes: `cargo test -p gast-core --lib bench_matching -- --ignored --nocapture`.
#[test]
fn gradient_matches_finite_differences() {
    let (c, n) = (8, 6);
    let st = style(c, 3, 4);
    let r: [Vec<f32>; 3] = std::array::from_fn(|k| feats(c, n, 10 + k as u64).iter().map(|v| v + 0.05).collect());
    let base = gcfm_loss(&st, [&r[0], &r[1], &r[2]], n);
    let mut bad = Vec::new();
    for k in 0..3 {
        for i in 0..c * n {
            let eval = |d: f32| {
                let mut p = r.clone();
                p[k][i] += d;
                gcfm_loss_with_matches(&st, [&p[0], &p[1], &p[2]], n, base.matches.clone()).loss
            };
            let h = 1e-3;
            let fd = (eval(h) - eval(-h)) / (2.0 * h);
            let an = base.v_rendered[k][i];
            if (fd - an).abs() > 2e-3 + 1e-2 * an.abs() {
                bad.push(format!("modality {k} element {i}: fd {fd} analytic {an}"));
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn matching_with_copied_positions_equals_dense() {
    // Most positions copy one of three vectors (a background), a few are their own.
    let (c, n) = (24, 200);
    let st = style(c, 9, 13);
    let base = [feats(c, 8, 7), feats(c, 8, 8), feats(c, 8, 9)];
    let src = |x: usize| if x.is_multiple_of(17) { 3 + x % 5 } else { x % 3 };
    let r: [Vec<f32>; 3] = std::array::from_fn(|k| {
        (0..c).flat_map(|ch| (0..n).map(move |x| (ch, src(x)))).map(|(ch, s)| base[k][ch * 8 + s]).collect()
    });
    let rr = [&r[0][..], &r[1][..], &r[2][..]];
    assert!(crate::style::distinct::representatives(rr, c, n).1 <= 8);
    let fast = match_features(&st, rr, n);
    assert_eq!(fast, match_features_dense(&st, rr, n));
    assert_eq!(fast, match_every_position(&st, rr, n));
}
