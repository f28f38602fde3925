//! Searching each distinct rendered feature vector once.
//!
//! With the paper's whole-frame losses most of an object scene's rendered
//! positions see nothing but the background: their receptive fields hold the
//! same constant RGB, depth and edge values, so VGG gives them bit-identical
//! joint features, and their nearest and farthest style positions are the
//! same. [`search_distinct`] hashes every position's joint vector (all three
//! modalities, compared bit for bit), runs the search on one representative
//! per distinct vector and copies its matches to the others. The result is the
//! search's own on every distinct vector, so an exact search stays exact.
//!
//! How many copies there are depends on the convolution: with im2col the
//! guitar's 256-px orbit views hold 650–675 distinct vectors of 1,024 (the
//! background away from the object and the borders), so the exact
//! whole-frame search does a third less work; Winograd's 4×4 output tiles
//! round the same input differently at different offsets in a tile, which
//! leaves 940–977 distinct, and the search then runs on every position (the
//! hashing reads each feature twice: two passes over the `3c × n` values
//! against the search's `3c × n × m` multiply-adds).
//!
//! It fills [`Matches`], the search's result, which lives here because
//! GCFM (`gcfm.rs`, which calls this) and the matching index share it.

use rayon::prelude::*;

/// For every rendered position, the flat (row-major) index into the style
/// feature map of its best and worst match.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Matches {
    /// `y+`: argmin of the joint cosine distance.
    pub best: Vec<u32>,
    /// `y−`: argmax of the joint cosine distance.
    pub worst: Vec<u32>,
}

/// Chunks of consecutive positions' `(best, worst)`, joined in order.
impl FromIterator<(Vec<u32>, Vec<u32>)> for Matches {
    fn from_iter<I: IntoIterator<Item = (Vec<u32>, Vec<u32>)>>(chunks: I) -> Self {
        let mut out = Matches::default();
        for (b, w) in chunks {
            out.best.extend(b);
            out.worst.extend(w);
        }
        out
    }
}

/// Positions a thread hashes and checks at once.
const POSITIONS_PER_TASK: usize = 512;

/// Below this share of distinct positions, the search runs on the
/// representatives only (above it the gather costs more than it saves).
const WORTH_IT: f64 = 0.75;

/// For each of the `n` positions of `rendered` (three modalities, each
/// `c × n`, CHW), the first position holding a bit-identical joint vector,
/// and the number of distinct vectors.
pub fn representatives(rendered: [&[f32]; 3], c: usize, n: usize) -> (Vec<u32>, usize) {
    // FNV-style hash per position, channel by channel (rows are contiguous),
    // the positions in blocks on the threads (one thread hashing 3 × 768
    // rows took 1.4 % of a fern run's samples while the other waited).
    let rows = || rendered.into_iter().flat_map(|r| r.chunks_exact(n).take(c));
    let mut hash = vec![0xcbf2_9ce4_8422_2325u64; n];
    hash.par_chunks_mut(POSITIONS_PER_TASK).enumerate().for_each(|(b, hs)| {
        let at = b * POSITIONS_PER_TASK;
        for row in rows() {
            for (h, v) in hs.iter_mut().zip(&row[at..]) {
                *h = (*h ^ u64::from(v.to_bits())).wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    });
    let mut first = std::collections::HashMap::with_capacity(n);
    let mut rep: Vec<u32> = hash.iter().enumerate().map(|(x, h)| *first.entry(*h).or_insert(x as u32)).collect();
    // A position whose hash met a different vector is its own representative.
    rep.par_chunks_mut(POSITIONS_PER_TASK).enumerate().for_each(|(b, reps)| {
        let at = b * POSITIONS_PER_TASK;
        let mut same = vec![true; reps.len()];
        for row in rows() {
            for ((ok, &r), v) in same.iter_mut().zip(reps.iter()).zip(&row[at..]) {
                *ok &= v.to_bits() == row[r as usize].to_bits();
            }
        }
        for (i, (r, ok)) in reps.iter_mut().zip(same).enumerate() {
            if !ok {
                *r = (at + i) as u32;
            }
        }
    });
    let distinct = rep.iter().enumerate().filter(|&(x, &r)| r as usize == x).count();
    (rep, distinct)
}

/// Runs `search` (matches of `rendered`'s `n` positions) on one position per
/// distinct joint vector and gives every position its representative's
/// matches; `search` sees all positions when most are distinct.
pub fn search_distinct(
    rendered: [&[f32]; 3],
    c: usize,
    n: usize,
    search: impl FnOnce([&[f32]; 3], usize) -> Matches,
) -> Matches {
    if n < 2 || c == 0 {
        return search(rendered, n);
    }
    let (rep, distinct) = representatives(rendered, c, n);
    if distinct as f64 > WORTH_IT * n as f64 {
        return search(rendered, n);
    }
    // Compact the representatives: slot[x] is x's column among them.
    let keep: Vec<usize> = (0..n).filter(|&x| rep[x] as usize == x).collect();
    let mut slot = vec![0u32; n];
    for (j, &x) in keep.iter().enumerate() {
        slot[x] = j as u32;
    }
    let u = keep.len();
    let compact: Vec<Vec<f32>> = rendered
        .iter()
        .map(|r| r.chunks_exact(n).take(c).flat_map(|row| keep.iter().map(move |&x| row[x])).collect())
        .collect();
    let found = search([&compact[0], &compact[1], &compact[2]], u);
    let of = |x: usize| slot[rep[x] as usize] as usize;
    Matches { best: (0..n).map(|x| found.best[of(x)]).collect(), worst: (0..n).map(|x| found.worst[of(x)]).collect() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_share_a_representative_and_distinct_vectors_keep_their_own() {
        let (c, n) = (3, 6);
        // Positions 0, 2, 5 hold one vector; 1 and 4 another; 3 differs from 1 only in modality 2.
        let col = |x: usize| match x {
            0 | 2 | 5 => [1.0f32, 2.0, 3.0],
            _ => [4.0, 5.0, 6.0],
        };
        let m: [Vec<f32>; 3] = std::array::from_fn(|k| {
            (0..c).flat_map(|ch| (0..n).map(move |x| if k == 2 && x == 3 { -1.0 } else { col(x)[ch] })).collect()
        });
        let (rep, distinct) = representatives([&m[0], &m[1], &m[2]], c, n);
        assert_eq!(rep, vec![0, 1, 0, 3, 1, 0]);
        assert_eq!(distinct, 3);
        // −0.0 and 0.0 are different bits: kept apart (the search decides both).
        let z = [vec![0.0f32, -0.0], vec![0.0, 0.0], vec![0.0, 0.0]];
        assert_eq!(representatives([&z[0], &z[1], &z[2]], 1, 2).1, 2);
    }

    #[test]
    fn the_search_runs_once_per_distinct_vector() {
        let (c, n) = (2, 8);
        // Six copies of one vector, two others.
        let m: [Vec<f32>; 3] = std::array::from_fn(|k| {
            (0..c)
                .flat_map(|ch| (0..n).map(move |x| if x == 3 || x == 6 { (x + ch + k) as f32 } else { 0.5 }))
                .collect()
        });
        let mut seen = 0;
        let out = search_distinct([&m[0], &m[1], &m[2]], c, n, |r, u| {
            seen = u;
            // A "search" that returns each column's first value as its match.
            let best: Vec<u32> = (0..u).map(|x| (r[0][x] * 10.0) as u32).collect();
            Matches { worst: best.iter().map(|b| b + 1).collect(), best }
        });
        assert_eq!(seen, 3);
        assert_eq!(out.best, vec![5, 5, 5, 30, 5, 5, 60, 5]);
        assert_eq!(out.worst, vec![6, 6, 6, 31, 6, 6, 61, 6]);
    }
}
