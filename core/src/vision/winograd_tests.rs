//! Winograd against the im2col reference on random layers: odd sizes, planes
//! thinner than a tile, the padding edges, several bands; forward and input
//! gradient.

use super::*;
use crate::vision::conv::tests::noise;
use crate::vision::conv::{conv_affine, conv_backward};

/// Largest |a − b| over the largest |b|.
fn rel_err(a: &[f32], b: &[f32]) -> f64 {
    let max_ref = b.iter().fold(0f64, |m, v| m.max(f64::from(v.abs())));
    let max_diff = a.iter().zip(b).fold(0f64, |m, (x, y)| m.max(f64::from((x - y).abs())));
    max_diff / max_ref.max(1e-30)
}

#[test]
fn winograd_matches_im2col_forward_and_backward() {
    let mut failures = Vec::new();
    // (c_in, c_out, h, w, band): odd sizes, 1-pixel planes, exact tiles, tiny bands.
    let cases = [
        (3, 5, 7, 9, BAND_ELEMS),
        (4, 6, 9, 5, 1),
        (2, 3, 1, 6, BAND_ELEMS),
        (5, 2, 6, 1, BAND_ELEMS),
        (1, 1, 1, 1, BAND_ELEMS),
        (8, 8, 8, 8, BAND_ELEMS),
        (16, 24, 13, 17, XI * 40 * 5 * 2),
        (64, 32, 11, 10, BAND_ELEMS),
        (3, 64, 4, 4, BAND_ELEMS),
        // Rows of 8 tiles and more: the lanes' path, at the edges and inside.
        (3, 4, 21, 70, BAND_ELEMS),
        (5, 3, 9, 32, BAND_ELEMS),
        (2, 2, 10, 33, XI * 7 * 9 * 2),
    ];
    for (seed, &(c_in, c_out, h, w, band)) in cases.iter().enumerate() {
        let seed = seed as u64 * 10;
        let x = noise(c_in * h * w, seed + 1);
        let wt = noise(c_out * c_in * 9, seed + 2);
        let zero_bias = vec![0.0; c_out];
        let (mut reference, mut fast) = (vec![0.0; c_out * h * w], vec![7.0; c_out * h * w]);
        let mut scratch = Vec::new();
        conv_affine(&x, (c_in, h, w), &wt, &zero_bias, &mut reference, &mut scratch);
        let k = WinogradKernel::forward(&wt, c_out, c_in);
        winograd_conv_banded(&x, (c_in, h, w), &k, &mut fast, &mut scratch, band);
        let e = rel_err(&fast, &reference);
        if e > 1e-5 {
            failures.push(format!("{c_in}→{c_out} at {h}×{w} forward: relative error {e:.2e}"));
        }
        let v = noise(c_out * h * w, seed + 3);
        let (mut v_ref, mut v_fast) = (vec![0.0; c_in * h * w], vec![7.0; c_in * h * w]);
        conv_backward(&v, (c_in, h, w), &wt, c_out, &mut v_ref, &mut scratch);
        let kb = WinogradKernel::input_gradient(&wt, c_out, c_in);
        winograd_conv_banded(&v, (c_out, h, w), &kb, &mut v_fast, &mut scratch, band);
        let e = rel_err(&v_fast, &v_ref);
        if e > 1e-5 {
            failures.push(format!("{c_in}→{c_out} at {h}×{w} input gradient: relative error {e:.2e}"));
        }
    }
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn eight_tiles_at_once_are_eight_tiles_one_by_one_to_the_bit() {
    // A plane wide enough for two groups of lanes inside it and one at its edges.
    let (h, w) = (14, 80);
    let plane = noise(h * w, 41);
    for oy in [0, 4, 8] {
        for ox in [0, 4, 32, 44] {
            let d = gather_lanes(&plane, h, w, oy, ox);
            let v = input_transform_lanes(&d);
            let tiles = (0..LANES).map(|l| input_transform(&gather(&plane, h, w, oy, ox + l * TILE)));
            for (l, one) in tiles.enumerate() {
                let lane: [f32; XI] = std::array::from_fn(|xi| v[xi][l]);
                assert_eq!(lane.map(f32::to_bits), one.map(f32::to_bits), "input at ({oy}, {ox}), lane {l}");
            }
        }
    }
    let m: [Lanes; XI] = std::array::from_fn(|xi| std::array::from_fn(|l| plane[xi * LANES + l]));
    let y = output_transform_lanes(&m);
    for l in 0..LANES {
        let one = output_transform(&std::array::from_fn(|xi| m[xi][l]));
        for (r, row) in one.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert_eq!(y[r][c][l].to_bits(), v.to_bits(), "output lane {l} ({r}, {c})");
            }
        }
    }
}
