//! Back-to-front order of the Gaussians for the current camera: a CPU radix
//! sort of view depths. Pure and allocation-light so it can run on any thread.

use glam::Vec3;

/// Near plane below which Gaussians are left out (same as splat_project.wgsl and
/// the CPU rasterizer).
pub const NEAR: f32 = 0.2;

/// Indices of the Gaussians in front of the camera, farthest first.
pub fn back_to_front(means: &[[f32; 3]], rotation_row_z: Vec3, translation_z: f32) -> Vec<u32> {
    let mut keys = Vec::with_capacity(means.len());
    let mut idx = Vec::with_capacity(means.len());
    for (i, m) in means.iter().enumerate() {
        let z = rotation_row_z.dot(Vec3::from_array(*m)) + translation_z;
        if z > NEAR {
            // Positive floats order like their bits; invert so farthest comes first.
            keys.push(!z.to_bits());
            idx.push(i as u32);
        }
    }
    radix_sort_pairs(&mut keys, &mut idx);
    idx
}

/// Sorts `(keys, values)` by key ascending: LSD radix, 16 bits a pass, stable.
pub fn radix_sort_pairs(keys: &mut Vec<u32>, values: &mut Vec<u32>) {
    let n = keys.len();
    let mut k2 = vec![0u32; n];
    let mut v2 = vec![0u32; n];
    for shift in [0u32, 16] {
        let mut count = vec![0usize; 1 << 16];
        for &k in keys.iter() {
            count[((k >> shift) & 0xffff) as usize] += 1;
        }
        let mut sum = 0;
        for c in count.iter_mut() {
            let here = *c;
            *c = sum;
            sum += here;
        }
        for i in 0..n {
            let b = ((keys[i] >> shift) & 0xffff) as usize;
            let dst = count[b];
            count[b] += 1;
            k2[dst] = keys[i];
            v2[dst] = values[i];
        }
        std::mem::swap(keys, &mut k2);
        std::mem::swap(values, &mut v2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn farthest_first_and_behind_dropped() {
        let means = [[0.0, 0.0, 2.0], [0.0, 0.0, 0.1], [0.0, 0.0, 5.0], [1.0, 0.0, 0.5], [0.0, 0.0, 2.0]];
        let order = back_to_front(&means, Vec3::Z, 0.0);
        assert_eq!(order, vec![2, 0, 4, 3]);
    }

    #[test]
    fn radix_matches_std_sort() {
        let mut keys: Vec<u32> = (0..10_000u32).map(|i| i.wrapping_mul(2_654_435_761)).collect();
        let mut vals: Vec<u32> = (0..10_000).collect();
        let mut want: Vec<(u32, u32)> = keys.iter().copied().zip(vals.iter().copied()).collect();
        want.sort_by_key(|p| p.0);
        radix_sort_pairs(&mut keys, &mut vals);
        assert_eq!(keys, want.iter().map(|p| p.0).collect::<Vec<_>>());
        assert_eq!(vals, want.iter().map(|p| p.1).collect::<Vec<_>>());
    }

    #[test]
    fn sort_time_500k() {
        let means: Vec<[f32; 3]> = (0..500_000u32)
            .map(|i| [0.0, 0.0, 1.0 + (i.wrapping_mul(2_654_435_761) % 100_000) as f32 * 1e-3])
            .collect();
        let t = std::time::Instant::now();
        let order = back_to_front(&means, Vec3::Z, 0.0);
        println!("back_to_front of 500k: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        assert_eq!(order.len(), 500_000);
    }
}
