//! Every golden file against the project's code, through the same
//! `gast_core::golden::check_file` that `gast check golden` runs: rasterizer
//! forward and gradients, VGG features, GCFM (loss, gradients, matches),
//! content, TV and the colour transfer, each with the tolerance of the issue.

use gast_core::golden::{CheckContext, check_file};
use gast_core::vision::ConvAlgo;
use gast_tests::shared_file;

fn check(rel: &str) {
    check_with(rel, ConvAlgo::Im2col);
}

fn check_with(rel: &str, conv: ConvAlgo) {
    let Some(path) = shared_file(rel) else { return };
    let weights = shared_file("data/weights/vgg19-conv3.safetensors");
    let checks = check_file(&path, &CheckContext { weights, conv }).unwrap_or_else(|e| panic!("{e}"));
    assert!(!checks.is_empty(), "{rel}: no output was compared");
    let mut failed = Vec::new();
    for c in &checks {
        println!(
            "{rel} {conv} {:<26} max abs {:>10.3e} max |ref| {:>10.3e} rel {:>10.3e} ({}) {}",
            c.name,
            c.max_abs,
            c.max_ref,
            c.rel,
            c.tolerance,
            if c.passed { "ok" } else { "FAIL" }
        );
        if !c.passed {
            failed.push(c.name.clone());
        }
    }
    assert!(failed.is_empty(), "{rel}: outputs beyond tolerance: {failed:?}");
}

#[test]
fn losses_match_golden() {
    check("golden/losses_seed1.safetensors");
}

/// The fast convolution is exact too: the same tolerances hold with it.
#[test]
fn losses_match_golden_with_winograd() {
    check_with("golden/losses_seed1.safetensors", ConvAlgo::Winograd);
}

#[test]
fn colour_transfer_matches_golden() {
    check("golden/color_seed1.safetensors");
}

#[test]
fn rasterizer_matches_golden_degree_0() {
    check("golden/raster_deg0_seed1.safetensors");
}

#[test]
fn rasterizer_matches_golden_degree_3() {
    check("golden/raster_deg3_seed1.safetensors");
}
