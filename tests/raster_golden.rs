//! The rasterizer (fast forward, backward, and the dense reference) against
//! the independent float64 reference in `golden/raster_deg*_seed1.safetensors`.

use gast_core::raster::golden::load_case;
use gast_tests::shared_file;

fn check(rel: &str) {
    let Some(path) = shared_file(rel) else { return };
    let case = match load_case(&path) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    let report = case.compare();
    let mut failures = Vec::new();
    for c in &report {
        println!(
            "{rel}: {:<22} max abs err {:.3e} (ref max {:.3e}, tolerance {:.3e}) {}",
            c.name,
            c.max_abs_err,
            c.ref_max_abs,
            c.tolerance,
            if c.passed() { "ok" } else { "FAIL" }
        );
        if !c.passed() {
            failures.push(c.name.clone());
        }
    }
    assert!(failures.is_empty(), "{rel}: outside tolerance: {failures:?}");
}

#[test]
fn raster_golden_deg0() {
    check("golden/raster_deg0_seed1.safetensors");
}

#[test]
fn raster_golden_deg3() {
    check("golden/raster_deg3_seed1.safetensors");
}
