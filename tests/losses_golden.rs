//! Golden checks of the style losses against the independent float64
//! reference in `golden/` (colour transfer, TV; GCFM and content
//! through VGG). The golden `render_edge` and `style_edge` are random sparse
//! constant inputs, not Canny outputs, so they cannot check the Canny code
//! (its unit tests do). Tolerances: losses 1e-4 relative, gradients 1e-3 of the
//! largest magnitude, matches identical.

use std::collections::HashMap;

use gast_core::style::color_transfer::ColorTransfer;
use gast_core::style::tv::tv_loss;
use gast_tests::shared_file;
use safetensors::SafeTensors;

/// A golden file's tensors by name: shape and f64 values.
type Golden = HashMap<String, (Vec<usize>, Vec<f64>)>;

/// All tensors of a golden file as f64 vectors with their shapes.
fn load(rel: &str) -> Option<Golden> {
    let path = shared_file(rel)?;
    let bytes = std::fs::read(&path).expect("read golden file");
    let st = SafeTensors::deserialize(&bytes).expect("parse golden file");
    let mut out = HashMap::new();
    for (name, view) in st.tensors() {
        assert_eq!(view.dtype(), safetensors::Dtype::F64, "{name}: golden tensors are f64");
        let v: Vec<f64> = view
            .data()
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect();
        out.insert(name, (view.shape().to_vec(), v));
    }
    Some(out)
}

fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// Largest absolute difference divided by the largest reference magnitude.
fn rel_to_max(got: &[f32], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    got.iter().zip(want).map(|(&g, &w)| (f64::from(g) - w).abs()).fold(0.0, f64::max) / scale
}

fn rel(got: f64, want: f64) -> f64 {
    (got - want).abs() / want.abs().max(1e-300)
}

#[test]
fn colour_transfer_matches_golden() {
    let Some(g) = load("golden/color_seed1.safetensors") else { return };
    let t = ColorTransfer::fit(&f32s(&g["content_pixels"].1), &f32s(&g["style_pixels"].1));
    let a = &g["A"].1;
    let b = &g["b"].1;
    let mut worst = 0f64;
    for i in 0..3 {
        for j in 0..3 {
            worst = worst.max((f64::from(t.a[i][j]) - a[i * 3 + j]).abs());
        }
        worst = worst.max((f64::from(t.b[i]) - b[i]).abs());
    }
    eprintln!("colour transfer: max |A, b error| = {worst:.3e}");
    assert!(worst < 1e-4, "A/b differ from golden by {worst}");
}

#[test]
fn tv_matches_golden() {
    let Some(g) = load("golden/losses_seed1.safetensors") else { return };
    let (shape, rgb) = &g["render_rgb"];
    let (h, w) = (shape[0], shape[1]);
    let (l, grad) = tv_loss(&f32s(rgb), h, w, 3);
    let el = rel(f64::from(l), g["tv_loss"].1[0]);
    let eg = rel_to_max(&grad, &g["grad_tv_rgb"].1);
    eprintln!("tv: loss rel error {el:.3e}, grad error / max {eg:.3e}");
    assert!(el < 1e-4, "tv loss {l} vs {}", g["tv_loss"].1[0]);
    assert!(eg < 1e-3, "tv gradient error {eg}");
}
