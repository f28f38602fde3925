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
    let an = min_max_backward(&d, &v);
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
        let fd = (lp.total - lm.total) / (2.0 * eps);
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
        let fd = (lp.total - lm.total) / (2.0 * eps);
        if (fd - base.v_inv_depth[i]).abs() > 2e-3 + 2e-2 * fd.abs() {
            bad.push(format!("inv_depth {i}: fd {fd} analytic {}", base.v_inv_depth[i]));
        }
    }
    assert!(bad.is_empty(), "{} failures:\n{}", bad.len(), bad.join("\n"));
}
