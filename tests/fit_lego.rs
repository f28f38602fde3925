//! The fitter on the real NeRF-synthetic lego data: 20 views at 64 px, a few
//! hundred iterations. The fit must beat its own starting point by a clear
//! margin on the training views.

use gast_core::fit::{FitConfig, fit, initial_scene, load_posed_images, mean_psnr};
use gast_tests::shared_file;

#[test]
fn fit_lego_improves_on_the_initialisation() {
    let Some(dataset) = shared_file("data/datasets/lego/transforms_train.json") else { return };
    let cfg = FitConfig { iterations: 300, resolution: 64, initial_gaussians: 10_000, ..FitConfig::default() };
    let data = load_posed_images(&dataset, None, cfg.resolution, 20, cfg.background).expect("lego loads");
    assert_eq!(data.views.len(), 20);
    assert_eq!((data.views[0].0.width, data.views[0].0.height), (64, 64));
    let cameras: Vec<_> = data.views.iter().map(|v| v.0.clone()).collect();
    let before = mean_psnr(&initial_scene(&cameras, &cfg), &data.views, cfg.background);
    let start = std::time::Instant::now();
    let scene = fit(&data.views, &cfg, &mut |_, _| std::ops::ControlFlow::Continue(()));
    let after = mean_psnr(&scene, &data.views, cfg.background);
    println!(
        "lego 64 px, 20 views, {} iterations: PSNR {before:.2} dB at the start, {after:.2} dB after ({} Gaussians, {:.1} s)",
        cfg.iterations,
        scene.len(),
        start.elapsed().as_secs_f64()
    );
    // Measured with seeds 0–2: 7.9–8.0 dB at the start, 20.9–21.2 dB after.
    // +10 dB is a clear margin that a broken gradient, loss or schedule misses.
    assert!(after > before + 10.0 && after > 18.0, "PSNR {before:.2} → {after:.2} dB");
}
