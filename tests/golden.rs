//! Every golden file against the project's code, through the same
//! `gast_core::golden::check_file` that `gast check golden` runs: rasterizer
//! forward and gradients, VGG features, GCFM (loss, gradients, matches),
//! content, TV, the colour transfer and the Depth Anything V2 forward pass,
//! each with the tolerance of the issue.

use gast_core::golden::{CheckContext, check_file};
use gast_core::vision::ConvAlgo;
use gast_tests::shared_file;

fn check(rel: &str) {
    check_on(rel, ConvAlgo::Im2col, None);
}

fn check_with(rel: &str, conv: ConvAlgo) {
    check_on(rel, conv, None);
}

/// The same check with the rasterizer, the losses and the depth network on the GPU engine
/// (lavapipe in CI), to the same tolerances (`gast check golden --device gpu`).
fn check_on_gpu(rel: &str) {
    let gpu = match gast_core::gpu::DeviceChoice::Gpu.resolve() {
        Ok(Some(g)) => g,
        other => panic!("the GPU golden checks need a wgpu adapter (lavapipe: mesa-vulkan-drivers): {other:?}"),
    };
    check_on(rel, ConvAlgo::Im2col, Some(gpu));
}

fn check_on(rel: &str, conv: ConvAlgo, gpu: Option<gast_core::gpu::GpuContext>) {
    let Some(path) = shared_file(rel) else { return };
    let weights = shared_file("data/weights/vgg19-conv3.safetensors");
    let checks = check_file(&path, &CheckContext { weights, gpu, conv }).unwrap_or_else(|e| panic!("{e}"));
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
fn depth_anything_matches_golden() {
    check("golden/depth/depth_seed1.safetensors");
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

#[test]
fn losses_match_golden_on_the_gpu() {
    check_on_gpu("golden/losses_seed1.safetensors");
}

#[test]
fn depth_anything_matches_golden_on_the_gpu() {
    check_on_gpu("golden/depth/depth_seed1.safetensors");
}

#[test]
fn rasterizer_matches_golden_degree_0_on_the_gpu() {
    check_on_gpu("golden/raster_deg0_seed1.safetensors");
}

#[test]
fn rasterizer_matches_golden_degree_3_on_the_gpu() {
    check_on_gpu("golden/raster_deg3_seed1.safetensors");
}
