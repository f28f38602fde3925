//! VGG relu3 features against the independent float64 reference in
//! `golden/losses_seed1.safetensors` (computed with the shared VGG19-conv3
//! weights and torchvision normalisation).

use anyhow::{Context, Result, bail};
use gast_core::vision::Vgg;
use gast_tests::shared_file;
use safetensors::SafeTensors;

fn f64s(st: &SafeTensors, name: &str) -> Result<(Vec<usize>, Vec<f64>)> {
    let t = st.tensor(name).with_context(|| format!("golden tensor {name}"))?;
    let data = t.data().chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).collect();
    Ok((t.shape().to_vec(), data))
}

#[test]
fn relu3_features_match_golden() -> Result<()> {
    let (Some(wp), Some(gp)) =
        (shared_file("data/weights/vgg19-conv3.safetensors"), shared_file("golden/losses_seed1.safetensors"))
    else {
        return Ok(());
    };
    let vgg = Vgg::load(&wp)?;
    let bytes = std::fs::read(&gp)?;
    let st = SafeTensors::deserialize(&bytes)?;
    let (shape, rgb) = f64s(&st, "render_rgb")?;
    let (h, w) = (shape[0], shape[1]);
    let rgb: Vec<f32> = rgb.iter().map(|&v| v as f32).collect();
    let (gshape, golden) = f64s(&st, "vgg_relu3_of_render_rgb")?;
    let f = vgg.features(&rgb, h, w);
    assert_eq!(vec![f.c, f.h, f.w], gshape, "feature map shape");
    let max_mag = golden.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let max_err = f.data.iter().zip(&golden).fold(0.0f64, |m, (a, b)| m.max((*a as f64 - b).abs()));
    let rel = max_err / max_mag;
    println!(
        "VGG relu3 vs golden ({h}×{w}): max |err| {max_err:.3e}, largest |value| {max_mag:.3e}, relative {rel:.3e}"
    );
    if rel > 1e-4 {
        bail!("relu3 features differ from golden: relative error {rel:.3e} > 1e-4");
    }
    // The saving forward must agree with the plain one.
    let (f2, _) = vgg.forward(&rgb, h, w);
    assert!(f2 == f, "forward and features disagree");
    Ok(())
}
