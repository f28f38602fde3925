//! Clustering for the SOG writer: 256-entry codebooks of scalars and the
//! palette of higher-order SH vectors.
//!
//! SOG stores scales, DC colours and SH coefficients as byte indices into
//! 256-entry codebooks, and the higher SH bands as one 16-bit label per
//! Gaussian into a palette of at most 65,536 vectors. Both are k-means
//! problems. The scalar one is solved exactly per iteration on sorted values
//! (Lloyd's steps with prefix sums). The vector one would cost
//! `n · 65536 · dim` per iteration if done directly (10^12 flops for 500,000
//! Gaussians of degree 2), so it is done in two levels: a coarse k-means with
//! √k clusters, then within each coarse cluster a k-means with a share of the
//! palette proportional to its size. Points never move between coarse
//! clusters, which costs a little accuracy and makes it ~√k times cheaper.
//! When the vectors have at most `k` distinct values (a scene that was read
//! from SOG), the palette is those values and nothing is lost.

use std::collections::HashMap;

use rayon::prelude::*;

/// Lloyd iterations of the scalar codebook.
const SCALAR_ITERS: usize = 30;
/// Lloyd iterations of each level of the vector palette.
const VECTOR_ITERS: usize = 8;
/// Points the coarse level of the palette is fitted on.
const COARSE_SAMPLE: usize = 32_768;

/// A sorted codebook of exactly `k` scalars fitted to `values` by k-means
/// (entries repeat when there are fewer than `k` distinct values).
pub(crate) fn codebook(values: &[f32], k: usize) -> Vec<f32> {
    let mut sorted: Vec<f32> = values.to_vec();
    sorted.sort_by(f32::total_cmp);
    let mut distinct = sorted.clone();
    distinct.dedup();
    if distinct.len() <= k {
        let last = distinct.last().copied().unwrap_or(0.0);
        distinct.resize(k, last);
        return distinct;
    }
    // Prefix sums in f64 give any segment's mean in O(1).
    let mut prefix = Vec::with_capacity(sorted.len() + 1);
    prefix.push(0.0f64);
    for &v in &sorted {
        prefix.push(prefix[prefix.len() - 1] + v as f64);
    }
    let n = sorted.len();
    let mut centres: Vec<f32> = (0..k).map(|j| sorted[((2 * j + 1) * n) / (2 * k)]).collect();
    for _ in 0..SCALAR_ITERS {
        centres.dedup();
        let mut next = Vec::with_capacity(k);
        let mut start = 0;
        for j in 0..centres.len() {
            let end = if j + 1 == centres.len() {
                n
            } else {
                let mid = 0.5 * (centres[j] + centres[j + 1]);
                sorted.partition_point(|&v| v < mid)
            };
            if end > start {
                next.push(((prefix[end] - prefix[start]) / (end - start) as f64) as f32);
            }
            start = end;
        }
        let converged = next == centres;
        centres = next;
        if converged {
            break;
        }
    }
    let last = centres.last().copied().unwrap_or(0.0);
    centres.resize(k, last);
    centres
}

/// Index of the entry of a sorted codebook nearest to `v`.
pub(crate) fn nearest(codebook: &[f32], v: f32) -> usize {
    let i = codebook.partition_point(|&c| c < v);
    match (i.checked_sub(1), codebook.get(i)) {
        (Some(lo), Some(&hi)) if (v - codebook[lo]) <= (hi - v) => lo,
        (_, Some(_)) => i,
        (Some(lo), None) => lo,
        (None, None) => 0,
    }
}

fn dist2(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Index of the centre (rows of `dim` in `centres`) nearest to `v`.
fn nearest_vector(centres: &[f32], dim: usize, v: &[f32]) -> usize {
    let mut best = (f32::INFINITY, 0);
    for (j, c) in centres.chunks_exact(dim).enumerate() {
        let d = dist2(c, v);
        if d < best.0 {
            best = (d, j);
        }
    }
    best.1
}

/// Up to `k` starting centres among `points` by k-means++ (each next centre
/// drawn with probability proportional to its squared distance from the
/// nearest chosen one; a fixed seed keeps files reproducible). Fewer come back
/// when the points have fewer than `k` distinct values.
fn seeds(data: &[f32], dim: usize, points: &[usize], k: usize) -> Vec<f32> {
    let row = |i: usize| &data[i * dim..(i + 1) * dim];
    let mut state = 0x2545_f491_4f6c_dd1d_u64 ^ points.len() as u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut centres: Vec<f32> = row(points[points.len() / 2]).to_vec();
    let mut d2: Vec<f32> = points.iter().map(|&p| dist2(row(p), &centres)).collect();
    while centres.len() / dim < k {
        let total: f64 = d2.iter().map(|&d| d as f64).sum();
        if total <= 0.0 {
            break;
        }
        let mut target = uniform() * total;
        let mut pick = d2.iter().rposition(|&d| d > 0.0).unwrap_or(0);
        for (j, &d) in d2.iter().enumerate() {
            target -= d as f64;
            if target < 0.0 && d > 0.0 {
                pick = j;
                break;
            }
        }
        let c = row(points[pick]).to_vec();
        for (d, &p) in d2.iter_mut().zip(points) {
            *d = d.min(dist2(row(p), &c));
        }
        centres.extend_from_slice(&c);
    }
    centres
}

/// Lloyd's k-means of the rows `points` (indices into `data`) with up to `k`
/// centres seeded by [`seeds`]; returns the centres. Empty clusters keep their
/// previous centre.
fn lloyd(data: &[f32], dim: usize, points: &[usize], k: usize, iters: usize) -> Vec<f32> {
    let row = |i: usize| &data[i * dim..(i + 1) * dim];
    let mut centres = seeds(data, dim, points, k);
    let k = centres.len() / dim;
    for _ in 0..iters {
        let mut sums = vec![0.0f64; k * dim];
        let mut counts = vec![0usize; k];
        for &p in points {
            let j = nearest_vector(&centres, dim, row(p));
            counts[j] += 1;
            for (s, v) in sums[j * dim..(j + 1) * dim].iter_mut().zip(row(p)) {
                *s += *v as f64;
            }
        }
        for j in 0..k {
            if counts[j] > 0 {
                for d in 0..dim {
                    centres[j * dim + d] = (sums[j * dim + d] / counts[j] as f64) as f32;
                }
            }
        }
    }
    centres
}

/// A palette of at most `k` vectors of `dim` floats for the rows of `data`,
/// and each row's label. `progress` receives the fraction done.
pub(crate) fn palette(data: &[f32], dim: usize, k: usize, progress: &mut dyn FnMut(f32)) -> (Vec<f32>, Vec<u32>) {
    let n = data.len() / dim.max(1);
    if n == 0 || dim == 0 {
        return (vec![0.0; dim], vec![0; n]);
    }
    // Exact palette when the distinct rows fit.
    let mut index: HashMap<Vec<u32>, u32> = HashMap::new();
    let mut labels = Vec::with_capacity(n);
    let mut centres = Vec::new();
    for row in data.chunks_exact(dim) {
        let key: Vec<u32> = row.iter().map(|v| v.to_bits()).collect();
        let next = index.len() as u32;
        let label = *index.entry(key).or_insert_with(|| {
            centres.extend_from_slice(row);
            next
        });
        labels.push(label);
        if index.len() > k {
            break;
        }
    }
    if index.len() <= k {
        return (centres, labels);
    }
    drop(index);

    // Coarse level on a sample, then every row to its coarse cluster.
    let groups = ((k as f64).sqrt().ceil() as usize).clamp(1, 256);
    let stride = n.div_ceil(COARSE_SAMPLE).max(1);
    let sample: Vec<usize> = (0..n).step_by(stride).collect();
    let coarse = lloyd(data, dim, &sample, groups.min(sample.len()), VECTOR_ITERS);
    progress(0.1);
    let coarse_label: Vec<usize> = data.par_chunks_exact(dim).map(|row| nearest_vector(&coarse, dim, row)).collect();
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); coarse.len() / dim];
    for (i, &c) in coarse_label.iter().enumerate() {
        members[c].push(i);
    }
    progress(0.2);

    // One palette entry per non-empty cluster, the rest shared by size
    // (largest remainders), never more entries than members.
    let nonempty = members.iter().filter(|m| !m.is_empty()).count();
    let spare = k.saturating_sub(nonempty);
    let mut share: Vec<usize> =
        members.iter().map(|m| if m.is_empty() { 0 } else { 1 + (m.len() - 1) * spare / n }).collect();
    for (s, m) in share.iter_mut().zip(&members) {
        *s = (*s).min(m.len());
    }
    let mut order: Vec<usize> = (0..members.len()).collect();
    order.sort_by_key(|&c| std::cmp::Reverse((members[c].len().saturating_sub(1) * spare) % n));
    let mut left = k.saturating_sub(share.iter().sum::<usize>());
    while left > 0 {
        let before = left;
        for &c in &order {
            if left > 0 && share[c] < members[c].len() {
                share[c] += 1;
                left -= 1;
            }
        }
        if left == before {
            break;
        }
    }

    // Fine level, cluster by cluster in parallel.
    let fine: Vec<Vec<f32>> = members
        .par_iter()
        .zip(&share)
        .map(|(m, &s)| if m.is_empty() { Vec::new() } else { lloyd(data, dim, m, s, VECTOR_ITERS) })
        .collect();
    progress(0.9);
    let mut offsets = Vec::with_capacity(fine.len());
    let mut all = Vec::with_capacity(k * dim);
    for f in &fine {
        offsets.push((all.len() / dim) as u32);
        all.extend_from_slice(f);
    }
    let labels: Vec<u32> = data
        .par_chunks_exact(dim)
        .zip(&coarse_label)
        .map(|(row, &c)| offsets[c] + nearest_vector(&fine[c], dim, row) as u32)
        .collect();
    (all, labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codebook_is_exact_for_few_values_and_close_for_many() {
        let few = [3.0, 1.0, 2.0, 1.0];
        let cb = codebook(&few, 256);
        assert_eq!(cb.len(), 256);
        for v in few {
            assert_eq!(cb[nearest(&cb, v)], v);
        }
        let many: Vec<f32> = (0..10_000).map(|i| ((i * 7919) % 10_000) as f32 / 1000.0).collect();
        let cb = codebook(&many, 256);
        let worst = many.iter().map(|&v| (cb[nearest(&cb, v)] - v).abs()).fold(0.0, f32::max);
        // Uniform on [0, 10): 256 evenly spaced centres are 10/256 apart.
        assert!(worst < 0.5 * 10.0 / 256.0 * 1.1, "worst error {worst}");
    }

    #[test]
    fn palette_is_exact_when_rows_fit_and_clusters_otherwise() {
        let data: Vec<f32> = (0..300).flat_map(|i| [(i % 7) as f32, (i % 5) as f32]).collect();
        let (centres, labels) = palette(&data, 2, 35, &mut |_| {});
        assert_eq!(centres.len(), 35 * 2);
        for (i, &l) in labels.iter().enumerate() {
            assert_eq!(&centres[l as usize * 2..l as usize * 2 + 2], &data[i * 2..i * 2 + 2]);
        }
        // Four well separated blobs, palette of 4: every row lands near its blob.
        let blobs: Vec<f32> = (0..400).flat_map(|i| [(i % 4) as f32 * 10.0 + (i % 3) as f32 * 0.01, 0.0]).collect();
        let (centres, labels) = palette(&blobs, 2, 4, &mut |_| {});
        for (i, &l) in labels.iter().enumerate() {
            assert!((centres[l as usize * 2] - blobs[i * 2]).abs() < 0.05, "row {i}");
        }
    }
}
