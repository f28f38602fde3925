//! Finite-difference checks of [`step_loss`] with a small stand-in network.

use super::*;

/// `f[c, i, j] = tanh(b_c + Σ W_c · block(4i.., 4j..))`: a smooth stand-in for
/// VGG with the same 1/4 resolution.
struct ToyNet {
    c: usize,
    w: Vec<f32>,
}

impl ToyNet {
    fn new(c: usize) -> Self {
        let w = (0..c * 48).map(|i| (((i * 7919) % 97) as f32 / 97.0 - 0.5) * 0.4).collect();
        Self { c, w }
    }
    fn pre(&self, rgb: &[f32], h: usize, w: usize) -> (Vec<f32>, usize, usize) {
        let (fh, fw) = (h / 4, w / 4);
        let mut out = vec![0f32; self.c * fh * fw];
        for ch in 0..self.c {
            for i in 0..fh {
                for j in 0..fw {
                    let mut s = 0.1 * ch as f32;
                    for a in 0..4 {
                        for b in 0..4 {
                            for k in 0..3 {
                                s += self.w[ch * 48 + (a * 4 + b) * 3 + k] * rgb[((4 * i + a) * w + 4 * j + b) * 3 + k];
                            }
                        }
                    }
                    out[(ch * fh + i) * fw + j] = s;
                }
            }
        }
        (out, fh, fw)
    }
}

impl FeatureNet for ToyNet {
    type State = (Vec<f32>, usize, usize);
    fn features(&self, rgb: &[f32], h: usize, w: usize) -> FeatureMap {
        self.forward(rgb, h, w).0
    }
    fn forward(&self, rgb: &[f32], h: usize, w: usize) -> (FeatureMap, Self::State) {
        let (pre, fh, fw) = self.pre(rgb, h, w);
        let data: Vec<f32> = pre.iter().map(|v| v.tanh()).collect();
        (FeatureMap { channels: self.c, height: fh, width: fw, data: data.clone() }, (data, h, w))
    }
    fn backward(&self, state: &Self::State, v: &[f32]) -> Vec<f32> {
        let (f, h, w) = (&state.0, state.1, state.2);
        let (fh, fw) = (h / 4, w / 4);
        let mut g = vec![0f32; h * w * 3];
        for ch in 0..self.c {
            for i in 0..fh {
                for j in 0..fw {
                    let idx = (ch * fh + i) * fw + j;
                    let d = v[idx] * (1.0 - f[idx] * f[idx]);
                    for a in 0..4 {
                        for b in 0..4 {
                            for k in 0..3 {
                                g[((4 * i + a) * w + 4 * j + b) * 3 + k] += d * self.w[ch * 48 + (a * 4 + b) * 3 + k];
                            }
                        }
                    }
                }
            }
        }
        g
    }
}

fn noise(n: usize, seed: u32, lo: f32, hi: f32) -> Vec<f32> {
    let mut x = seed.wrapping_mul(2_654_435_761) | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            lo + (hi - lo) * ((x >> 8) as f32 / (1u32 << 24) as f32)
        })
        .collect()
}

#[test]
fn min_max_adjoint_matches_finite_differences() {
    let d = noise(20, 3, 0.2, 1.2);
    let v = noise(20, 4, -1.0, 1.0);
    let f = |d: &[f32]| -> f64 {
        let lo = d.iter().cloned().fold(f32::INFINITY, f32::min);
        let hi = d.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        d.iter().zip(&v).map(|(&x, &g)| f64::from((x - lo) / (hi - lo + 1e-8) * g)).sum()
    };
    let an = min_max_backward(&d, &v, None);
    for i in 0..d.len() {
        let mut p = d.clone();
        p[i] += 1e-3;
        let mut m = d.clone();
        m[i] -= 1e-3;
        let fd = (f(&p) - f(&m)) / 2e-3;
        assert!((fd as f32 - an[i]).abs() < 2e-3, "{i}: {fd} vs {}", an[i]);
    }
}

#[test]
fn step_loss_gradients_match_finite_differences() {
    let (h, w) = (16, 24);
    let net = ToyNet::new(5);
    let (hs, ws) = (12, 16);
    let st = StyleTargets::new(
        &net,
        &noise(hs * ws * 3, 1, 0.0, 1.0),
        &noise(hs * ws, 2, 0.0, 1.0),
        &noise(hs * ws, 9, 0.0, 1.0).iter().map(|v| v.round()).collect::<Vec<_>>(),
        hs,
        ws,
    );
    let rgb = noise(h * w * 3, 5, 0.1, 0.9);
    let inv_depth = noise(h * w, 6, 0.3, 1.0);
    let edge = vec![0.0f32; h * w];
    let content = content_target(&net, &noise(h * w * 3, 7, 0.0, 1.0), h, w);
    let dref = noise(h * w, 8, 0.3, 1.0);
    let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, depth: 0.1, ..LossWeights::default() };
    let eval = |rgb: &[f32], d: &[f32]| {
        let maps = RenderedMaps { rgb, inv_depth: d, edge: &edge, height: h, width: w };
        step_loss(&net, &st, maps, Some(&content), Some(&dref), &weights, true)
    };
    let base = eval(&rgb, &inv_depth);
    let mut bad = Vec::new();
    let eps = 1e-3f32;
    for i in (0..rgb.len()).step_by(7) {
        let mut p = rgb.clone();
        p[i] += eps;
        let mut m = rgb.clone();
        m[i] -= eps;
        let (lp, lm) = (eval(&p, &inv_depth), eval(&m, &inv_depth));
        if lp.matches != base.matches || lm.matches != base.matches {
            continue;
        }
        let fd = (lp.terms.total - lm.terms.total) / (2.0 * eps);
        if (fd - base.v_rgb[i]).abs() > 2e-3 + 2e-2 * fd.abs() {
            bad.push(format!("rgb {i}: fd {fd} analytic {}", base.v_rgb[i]));
        }
    }
    for i in (0..inv_depth.len()).step_by(3) {
        let mut p = inv_depth.clone();
        p[i] += eps;
        let mut m = inv_depth.clone();
        m[i] -= eps;
        let (lp, lm) = (eval(&rgb, &p), eval(&rgb, &m));
        if lp.matches != base.matches || lm.matches != base.matches || (inv_depth[i] - dref[i]).abs() < 2.0 * eps {
            continue;
        }
        let fd = (lp.terms.total - lm.terms.total) / (2.0 * eps);
        if (fd - base.v_inv_depth[i]).abs() > 2e-3 + 2e-2 * fd.abs() {
            bad.push(format!("inv_depth {i}: fd {fd} analytic {}", base.v_inv_depth[i]));
        }
    }
    assert!(bad.is_empty(), "{} failures:\n{}", bad.len(), bad.join("\n"));
}

/// A small scene for the focus tests: 16 × 24 pixels, a 2 × 3 feature grid
/// (each cell 8 × 8 pixels after the 0.5× downscale and the net's 1/4).
fn focus_inputs() -> (ToyNet, StyleTargets, Vec<f32>, Vec<f32>, FeatureMap, Vec<f32>) {
    let (h, w) = (16, 24);
    let net = ToyNet::new(5);
    let (hs, ws) = (12, 16);
    let st = StyleTargets::new(
        &net,
        &noise(hs * ws * 3, 11, 0.0, 1.0),
        &noise(hs * ws, 12, 0.0, 1.0),
        &noise(hs * ws, 13, 0.0, 1.0).iter().map(|v| v.round()).collect::<Vec<_>>(),
        hs,
        ws,
    );
    let content = content_target(&net, &noise(h * w * 3, 17, 0.0, 1.0), h, w);
    (net, st, noise(h * w * 3, 15, 0.1, 0.9), noise(h * w, 16, 0.3, 1.0), content, noise(h * w, 18, 0.3, 1.0))
}

#[test]
fn an_all_ones_mask_equals_the_unmasked_loss() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, dref) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, depth: 0.1, ..LossWeights::default() };
    let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
    let ones = vec![true; h * w];
    let a = step_loss(&net, &st, maps, Some(&content), Some(&dref), &weights, true);
    let b = step_loss_masked(&net, &st, maps, Some(&content), Some(&dref), &weights, true, Some(&ones));
    let close = |x: f32, y: f32| (x - y).abs() <= 1e-6 * (1.0 + x.abs());
    for (name, x, y) in [
        ("gcfm", a.terms.gcfm, b.terms.gcfm),
        ("content", a.terms.content, b.terms.content),
        ("tv", a.terms.tv, b.terms.tv),
        ("total", a.terms.total, b.terms.total),
    ] {
        assert!(close(x, y), "{name}: unmasked {x}, all-ones mask {y}");
    }
    assert!(a.terms.content > 0.0 && a.terms.tv > 0.0);
    assert_eq!(a.matches, b.matches);
    for (name, u, v) in [("v_rgb", &a.v_rgb, &b.v_rgb), ("v_inv_depth", &a.v_inv_depth, &b.v_inv_depth)] {
        let worst = u.iter().zip(v.iter()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-7, "{name}: worst difference {worst}");
    }
}

/// A mask too small to cover half of any feature cell is dropped whole, the
/// depth map's normalisation with it, as the GPU engine does (before, the
/// depth was normalised over the mask and its backward pass ran over the
/// frame): the loss and gradients are the unmasked ones, with and without
/// the depth relief.
#[test]
fn a_mask_that_covers_no_feature_cell_is_the_whole_frame() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, dref) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, depth: 0.1, ..LossWeights::default() };
    let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
    // A 5 × 5 patch: 25 of a cell's 64 pixels, under half of any cell.
    let mask: Vec<bool> = (0..h * w).map(|k| (k / w) < 5 && (k % w) < 5).collect();
    for relief_px in [0, 3] {
        let run = |mask: Option<&[bool]>| {
            let exact = &mut |r: [&[f32]; 3], n: usize| match_features(&st.features, r, n);
            let focus = LossFocus { mask, window: true, relief_px, ..LossFocus::default() };
            step_loss_with(&net, &st, maps, Some(&content), Some(&dref), &weights, true, focus, exact)
        };
        let (a, b) = (run(None), run(Some(&mask)));
        assert_eq!(a.terms, b.terms, "relief {relief_px}");
        assert_eq!(a.v_rgb, b.v_rgb, "relief {relief_px}");
        assert_eq!(a.v_inv_depth, b.v_inv_depth, "relief {relief_px}");
    }
}

#[test]
fn a_mask_ignores_uncovered_positions_with_exactly_zero_gradient() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, _) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, ..LossWeights::default() };
    // The left two feature cells (pixel columns 0..16) are covered.
    let mask: Vec<bool> = (0..h * w).map(|k| k % w < 16).collect();
    let eval = |rgb: &[f32], d: &[f32]| {
        let maps = RenderedMaps { rgb, inv_depth: d, edge: &edge, height: h, width: w };
        step_loss_masked(&net, &st, maps, Some(&content), None, &weights, true, Some(&mask))
    };
    let base = eval(&rgb, &inv_depth);
    let full = step_loss(
        &net,
        &st,
        RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w },
        Some(&content),
        None,
        &weights,
        true,
    );
    assert!((base.terms.total - full.terms.total).abs() > 1e-4, "the mask changed nothing: {}", base.terms.total);
    let mut bad = Vec::new();
    for k in (0..h * w).filter(|&k| !mask[k]) {
        if base.v_inv_depth[k] != 0.0 {
            bad.push(format!("v_inv_depth at pixel {k}: {}", base.v_inv_depth[k]));
        }
        for c in 0..3 {
            if base.v_rgb[3 * k + c] != 0.0 {
                bad.push(format!("v_rgb at pixel {k}.{c}: {}", base.v_rgb[3 * k + c]));
            }
        }
    }
    assert!(bad.is_empty(), "{} non-zero gradients outside the mask:\n{}", bad.len(), bad.join("\n"));
    assert!(mask.iter().zip(base.v_rgb.chunks(3)).any(|(&m, g)| m && g.iter().any(|&v| v != 0.0)));
    // Changing what lies outside the mask changes nothing.
    let (mut rgb2, mut d2) = (rgb.clone(), inv_depth.clone());
    for k in (0..h * w).filter(|&k| !mask[k]) {
        rgb2[3 * k] = 1.0 - rgb2[3 * k];
        d2[k] *= 3.0;
    }
    let moved = eval(&rgb2, &d2);
    assert_eq!(
        (moved.terms.gcfm, moved.terms.content, moved.terms.tv, moved.terms.total),
        (base.terms.gcfm, base.terms.content, base.terms.tv, base.terms.total)
    );
    assert!(base.matches.best[2] == u32::MAX && base.matches.best[0] != u32::MAX);
}

/// VGG on the covered window gives the whole frame's losses and gradients:
/// random VGG weights, both convolutions, a small object in a larger frame.
#[test]
fn vgg_on_the_covered_window_equals_the_whole_frame() {
    use crate::vision::ConvAlgo;
    use crate::vision::vgg::tests::random_vgg;
    let (h, w) = (254, 198);
    let (hs, ws) = (40, 36);
    // The object: a disc left of the centre; its windows' share of the frame is printed.
    let mask: Vec<bool> = (0..h * w)
        .map(|k| {
            let (y, x) = ((k / w) as f32 - 140.0, (k % w) as f32 - 80.0);
            y * y + x * x < 30.0 * 30.0
        })
        .collect();
    let weights = LossWeights { gcfm: 2.0, content: 1e-3, tv: 0.02, depth: 10.0, ..LossWeights::default() };
    for conv in ConvAlgo::ALL {
        let net = random_vgg(3).with_conv(conv);
        let st = StyleTargets::new(
            &net,
            &noise(hs * ws * 3, 21, 0.0, 1.0),
            &noise(hs * ws, 22, 0.0, 1.0),
            &noise(hs * ws, 23, 0.0, 1.0).iter().map(|v| v.round()).collect::<Vec<_>>(),
            hs,
            ws,
        );
        let rgb = noise(h * w * 3, 25, 0.0, 1.0);
        let (inv_depth, dref) = (noise(h * w, 26, 0.3, 1.0), noise(h * w, 27, 0.3, 1.0));
        let edge: Vec<f32> = noise(h * w, 28, 0.0, 1.0).iter().map(|v| v.round()).collect();
        let content = content_target(&net, &noise(h * w * 3, 29, 0.0, 1.0), h, w);
        let run = |window: bool| {
            let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
            let exact = &mut |r: [&[f32]; 3], n: usize| match_features(&st.features, r, n);
            let focus = LossFocus { mask: Some(&mask), window, ..LossFocus::default() };
            step_loss_with(&net, &st, maps, Some(&content), Some(&dref), &weights, true, focus, exact)
        };
        let (whole, windowed) = (run(false), run(true));
        let fmask = feature_mask(&mask, h, w, h / 2 / 4, w / 2 / 4);
        let win = FeatureWindow::covering(&fmask, h / 2 / 4, w / 2 / 4).expect("the disc needs less than the frame");
        println!("{conv}: window {:?}, {:.0}% of the feature grid", win, 100.0 * win.share());
        assert!(win.share() < 0.8);
        assert_eq!(whole.matches, windowed.matches, "{conv}: matches");
        for (name, a, b) in [
            ("gcfm", whole.terms.gcfm, windowed.terms.gcfm),
            ("content", whole.terms.content, windowed.terms.content),
            ("tv", whole.terms.tv, windowed.terms.tv),
            ("total", whole.terms.total, windowed.terms.total),
        ] {
            assert!((a - b).abs() <= 1e-5 * a.abs().max(1e-3), "{conv} {name}: whole frame {a}, window {b}");
        }
        for (name, u, v) in
            [("v_rgb", &whole.v_rgb, &windowed.v_rgb), ("v_inv_depth", &whole.v_inv_depth, &windowed.v_inv_depth)]
        {
            let scale = u.iter().fold(0.0f32, |m, x| m.max(x.abs()));
            let worst = u.iter().zip(v.iter()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
            assert!(scale > 0.0 && worst <= 1e-5 * scale, "{conv} {name}: worst difference {worst} of {scale}");
        }
    }
}

/// λ_mean, λ_sw, λ_as and λ_asc: each adds exactly its weight times its term to the
/// total, moves the gradient, and leaves the pixels outside the mask alone.
#[test]
fn the_feature_statistics_terms_add_their_weighted_values_and_stay_inside_the_mask() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, _) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let mask: Vec<bool> = (0..h * w).map(|k| k % w < 16).collect();
    type Term = (&'static str, fn(&mut LossWeights, f32), fn(&StepLoss) -> f32);
    let terms: [Term; 4] = [
        ("feature mean", |w, l| w.feature_mean = l, |s| s.terms.feature_mean),
        ("sliced", |w, l| w.sliced = l, |s| s.terms.sliced),
        ("assignment", |w, l| w.assignment = l, |s| s.terms.assignment),
        ("cosine assignment", |w, l| w.assignment_cosine = l, |s| s.terms.assignment_cosine),
    ];
    for (name, set, get) in terms {
        let eval = |lambda: f32| {
            let mut weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, ..LossWeights::default() };
            set(&mut weights, lambda);
            let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
            step_loss_masked(&net, &st, maps, Some(&content), None, &weights, false, Some(&mask))
        };
        let (off, on) = (eval(0.0), eval(0.7));
        assert_eq!(get(&off), 0.0, "{name}");
        assert!(get(&on) > 0.0, "{name}: the rendered and style features differ: {}", get(&on));
        assert!(
            (on.terms.total - off.terms.total - 0.7 * get(&on)).abs() < 1e-5 * on.terms.total.abs().max(1.0),
            "{name}"
        );
        assert!(off.v_rgb.iter().zip(&on.v_rgb).any(|(a, b)| a != b), "{name}: the term moved no gradient");
        for k in (0..h * w).filter(|&k| !mask[k]) {
            assert!(on.v_rgb[3 * k..3 * k + 3].iter().all(|&v| v == 0.0), "{name}: pixel {k} outside the mask");
        }
    }
}

/// λ_swd, the sliced Wasserstein term on the depth features: on a step that
/// takes the depth's gradient it adds exactly its weight times its value and
/// moves the inverse depth's gradient (inside the mask only), never the
/// colours'; on a step that does not (a colour step) it is 0.
#[test]
fn the_depth_sliced_term_moves_the_depth_gradient_inside_the_mask() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, _) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let mask: Vec<bool> = (0..h * w).map(|k| k % w < 16).collect();
    let eval = |lambda: f32, depth_grad: bool| {
        let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, sliced_depth: lambda, ..LossWeights::default() };
        let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
        step_loss_masked(&net, &st, maps, Some(&content), None, &weights, depth_grad, Some(&mask))
    };
    let (off, on) = (eval(0.0, true), eval(0.7, true));
    assert_eq!(off.terms.sliced_depth, 0.0);
    assert!(on.terms.sliced_depth > 0.0, "the rendered and style depth features differ: {}", on.terms.sliced_depth);
    assert!(
        (on.terms.total - off.terms.total - 0.7 * on.terms.sliced_depth).abs() < 1e-5 * on.terms.total.abs().max(1.0)
    );
    assert_eq!(off.v_rgb, on.v_rgb, "the depth term leaves the colours' gradient");
    assert!(off.v_inv_depth.iter().zip(&on.v_inv_depth).any(|(a, b)| a != b), "the term moved no depth gradient");
    for k in (0..h * w).filter(|&k| !mask[k]) {
        assert_eq!(on.v_inv_depth[k], 0.0, "pixel {k} outside the mask");
    }
    let colour_step = eval(0.7, false);
    assert_eq!((colour_step.terms.sliced_depth, colour_step.terms.total), (0.0, eval(0.0, false).terms.total));
}

#[test]
fn the_background_hold_adds_its_weighted_value_and_moves_only_the_held_pixels() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, _) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let mask: Vec<bool> = (0..h * w).map(|k| k % w < 16).collect();
    let held: Vec<bool> = (0..h * w).map(|k| k % w >= 20).collect();
    let target = vec![0.0f32; h * w * 3];
    let eval = |lambda: f32| {
        let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, outside: lambda, ..LossWeights::default() };
        let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
        let exact = &mut |r: [&[f32]; 3], n: usize| match_features(&st.features, r, n);
        let focus = LossFocus {
            mask: Some(&mask),
            window: true,
            outside: Some(Outside { mask: &held, rgb: &target }),
            ..LossFocus::default()
        };
        step_loss_with(&net, &st, maps, Some(&content), None, &weights, false, focus, exact)
    };
    let (off, on) = (eval(0.0), eval(3.0));
    assert_eq!(off.terms.outside, 0.0, "λ_out = 0 measures nothing");
    let (want, grad) = outside_loss(&rgb, Outside { mask: &held, rgb: &target });
    assert!(want > 0.0);
    assert_eq!(on.terms.outside, want);
    assert!((on.terms.total - off.terms.total - 3.0 * want).abs() < 1e-5 * on.terms.total.abs().max(1.0));
    for k in 0..h * w * 3 {
        let moved = on.v_rgb[k] - off.v_rgb[k];
        assert!((moved - 3.0 * grad[k]).abs() <= 1e-6 * grad[k].abs().max(1e-3), "channel {k}: moved {moved}");
        if !held[k / 3] {
            assert_eq!(on.v_rgb[k], off.v_rgb[k], "channel {k} is not held");
        }
    }
}

#[test]
fn the_palette_hold_adds_its_weighted_value_and_moves_only_the_covered_pixels() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, _) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let mask: Vec<bool> = (0..h * w).map(|k| k % w < 16).collect();
    // A darker, flatter palette than the render's.
    let reference = [0.2, 0.25, 0.3, 0.05, 0.05, 0.05];
    let eval = |lambda: f32| {
        let weights = LossWeights { gcfm: 2.0, content: 0.5, tv: 0.02, palette: lambda, ..LossWeights::default() };
        let maps = RenderedMaps { rgb: &rgb, inv_depth: &inv_depth, edge: &edge, height: h, width: w };
        let exact = &mut |r: [&[f32]; 3], n: usize| match_features(&st.features, r, n);
        let focus = LossFocus { mask: Some(&mask), window: true, palette: Some(reference), ..LossFocus::default() };
        step_loss_with(&net, &st, maps, Some(&content), None, &weights, false, focus, exact)
    };
    let (off, on) = (eval(0.0), eval(3.0));
    assert_eq!(off.terms.palette, 0.0, "λ_pal = 0 measures nothing");
    let (want, grad) = crate::style::palette::palette_loss(&rgb, &mask, &reference);
    assert!(want > 0.0);
    assert_eq!(on.terms.palette, want);
    assert!((on.terms.total - off.terms.total - 3.0 * want).abs() < 1e-5 * on.terms.total.abs().max(1.0));
    for k in 0..h * w * 3 {
        let moved = on.v_rgb[k] - off.v_rgb[k];
        // The other terms' gradient is there too: f32 rounds the sum at its size.
        let size = off.v_rgb[k].abs() + 3.0 * grad[k].abs();
        assert!(
            (moved - 3.0 * grad[k]).abs() <= 1e-6 * size.max(1e-3),
            "channel {k}: moved {moved}, want {}",
            3.0 * grad[k]
        );
        if !mask[k / 3] {
            assert_eq!(on.v_rgb[k], off.v_rgb[k], "channel {k} is not covered");
        }
    }
}

#[test]
fn the_depth_relief_gradient_matches_finite_differences_inside_the_mask() {
    let (h, w) = (16, 24);
    let (net, st, rgb, inv_depth, content, _) = focus_inputs();
    let edge = vec![0.0f32; h * w];
    let mask: Vec<bool> = (0..h * w).map(|k| k % w < 16).collect();
    let weights = LossWeights { gcfm: 2.0, sliced_depth: 0.7, ..LossWeights::default() };
    let eval = |d: &[f32], relief_px: usize| {
        let maps = RenderedMaps { rgb: &rgb, inv_depth: d, edge: &edge, height: h, width: w };
        let focus = LossFocus { mask: Some(&mask), relief_px, ..LossFocus::default() };
        let exact = &mut |r: [&[f32]; 3], n: usize| crate::style::gcfm::match_features(&st.features, r, n);
        step_loss_with(&net, &st, maps, Some(&content), None, &weights, true, focus, exact)
    };
    let (global, base) = (eval(&inv_depth, 0), eval(&inv_depth, 2));
    assert!(base.terms.gcfm != global.terms.gcfm, "the relief changed what VGG sees of the depth");
    let mut bad = Vec::new();
    let eps = 1e-3f32;
    for i in (0..h * w).step_by(5) {
        let (mut p, mut m) = (inv_depth.clone(), inv_depth.clone());
        p[i] += eps;
        m[i] -= eps;
        let (lp, lm) = (eval(&p, 2), eval(&m, 2));
        if !mask[i] {
            assert_eq!(base.v_inv_depth[i], 0.0, "pixel {i} outside the mask");
            continue;
        }
        if lp.matches != base.matches || lm.matches != base.matches {
            continue;
        }
        let fd = (lp.terms.total - lm.terms.total) / (2.0 * eps);
        if (fd - base.v_inv_depth[i]).abs() > 2e-3 + 3e-2 * fd.abs() {
            bad.push(format!("inv_depth {i}: fd {fd} analytic {}", base.v_inv_depth[i]));
        }
    }
    assert!(bad.is_empty(), "{} failures:\n{}", bad.len(), bad.join("\n"));
}
