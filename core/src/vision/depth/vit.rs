//! The DINOv2 backbone: patch embedding, CLS token, position embeddings
//! interpolated to the input's patch grid, pre-norm transformer layers with
//! layer scale, and the final layer norm applied to the stages the neck reads.
//!
//! Details follow `transformers`' `Dinov2Backbone`: the position embeddings
//! of the training grid are resized with `F.interpolate(size=(rows, cols),
//! mode='bicubic', align_corners=False)` (the current `size=` form, not the
//! older `scale_factor` with its +0.1 offset), attention scales by
//! `1/√d_head`, the MLP is fc1 → exact GELU → fc2.

use super::DepthModelError;
use super::config::DepthConfig;
use super::ops::{Linear, Norm, attention};
use super::profile::Clock;
use super::weights::Checkpoint;
use crate::vision::resize::resize_bicubic;

/// One transformer layer.
///
/// The loader folds what is linear into the weights: query, key and value
/// are one `3d × d` product whose query rows carry `1/√d_head`, and the layer
/// scales λ₁, λ₂ multiply the rows of the attention output and of fc2, which
/// then add onto the token stream in place.
pub(crate) struct Layer {
    pub(crate) norm1: Norm,
    pub(crate) qkv: Linear,
    pub(crate) output: Linear,
    pub(crate) norm2: Norm,
    pub(crate) fc1: Linear,
    pub(crate) fc2: Linear,
}

/// The backbone's weights and sizes.
pub(crate) struct Vit {
    pub(crate) patch: Linear,
    pub(crate) patch_size: usize,
    pub(crate) cls: Vec<f32>,
    /// `(grid² + 1) × d`, token-major as stored.
    pos: Vec<f32>,
    grid: usize,
    pub(crate) layers: Vec<Layer>,
    pub(crate) final_norm: Norm,
    pub(crate) heads: usize,
    pub(crate) out_indices: Vec<usize>,
    pub(crate) apply_layernorm: bool,
}

/// Reads `prefix.weight` and `prefix.bias` of a linear layer or 1×1 convolution.
pub(crate) fn linear(
    ck: &Checkpoint,
    prefix: &str,
    out: usize,
    inp: usize,
    conv: bool,
) -> Result<Linear, DepthModelError> {
    let shape = if conv { vec![out, inp, 1, 1] } else { vec![out, inp] };
    Ok(Linear { w: ck.take(&format!("{prefix}.weight"), &shape)?, b: ck.take(&format!("{prefix}.bias"), &[out])?, inp })
}

fn norm(ck: &Checkpoint, prefix: &str, d: usize, eps: f64) -> Result<Norm, DepthModelError> {
    Ok(Norm {
        w: ck.take(&format!("{prefix}.weight"), &[d])?,
        b: ck.take(&format!("{prefix}.bias"), &[d])?,
        eps: eps as f32,
    })
}

impl Vit {
    /// Reads the backbone's tensors (`backbone.*`), checking every shape against `cfg`.
    pub(crate) fn load(ck: &Checkpoint, cfg: &DepthConfig) -> Result<Self, DepthModelError> {
        let b = &cfg.backbone_config;
        let (d, p, eps) = (b.hidden_size, b.patch_size, b.layer_norm_eps);
        let e = "backbone.embeddings";
        let grid = b.image_size / p;
        let patch_w = ck.take(&format!("{e}.patch_embeddings.projection.weight"), &[d, 3, p, p])?;
        let patch_b = ck.take(&format!("{e}.patch_embeddings.projection.bias"), &[d])?;
        let cls = ck.take(&format!("{e}.cls_token"), &[1, 1, d])?;
        let pos = ck.take(&format!("{e}.position_embeddings"), &[1, grid * grid + 1, d])?;
        let mlp = cfg.mlp_hidden();
        let layers = (0..b.num_hidden_layers)
            .map(|i| {
                let l = format!("backbone.encoder.layer.{i}");
                let a = format!("{l}.attention.attention");
                let q_scale = vec![1.0 / ((d / b.num_attention_heads) as f32).sqrt(); d];
                let scale1 = ck.take(&format!("{l}.layer_scale1.lambda1"), &[d])?;
                let scale2 = ck.take(&format!("{l}.layer_scale2.lambda1"), &[d])?;
                Ok(Layer {
                    norm1: norm(ck, &format!("{l}.norm1"), d, eps)?,
                    qkv: Linear::stacked(vec![
                        linear(ck, &format!("{a}.query"), d, d, false)?.scaled_rows(&q_scale),
                        linear(ck, &format!("{a}.key"), d, d, false)?,
                        linear(ck, &format!("{a}.value"), d, d, false)?,
                    ]),
                    output: linear(ck, &format!("{l}.attention.output.dense"), d, d, false)?.scaled_rows(&scale1),
                    norm2: norm(ck, &format!("{l}.norm2"), d, eps)?,
                    fc1: linear(ck, &format!("{l}.mlp.fc1"), mlp, d, false)?,
                    fc2: linear(ck, &format!("{l}.mlp.fc2"), d, mlp, false)?.scaled_rows(&scale2),
                })
            })
            .collect::<Result<Vec<_>, DepthModelError>>()?;
        Ok(Self {
            patch: Linear { w: patch_w, b: patch_b, inp: 3 * p * p },
            patch_size: p,
            cls,
            pos,
            grid,
            layers,
            final_norm: norm(ck, "backbone.layernorm", d, eps)?,
            heads: b.num_attention_heads,
            out_indices: cfg
                .out_indices()
                .map_err(|detail| DepthModelError::Config { path: ck.path().into(), detail })?,
            apply_layernorm: b.apply_layernorm,
        })
    }

    /// Token width.
    pub(crate) fn width(&self) -> usize {
        self.cls.len()
    }

    /// Runs the backbone on a normalised CHW image whose sides are multiples
    /// of the patch size. Returns the hidden states the neck reads, each
    /// `d × (1 + rows·cols)` channel-major with the CLS token first.
    pub(crate) fn forward(&self, img: &[f32], h: usize, w: usize, clock: &mut Clock) -> Vec<Vec<f32>> {
        let (p, d) = (self.patch_size, self.width());
        let (rows, cols) = (h / p, w / p);
        let np = rows * cols;
        let n = np + 1;
        // Patch embedding: the stride-p convolution is a product with the
        // non-overlapping patches laid out as columns.
        let k = 3 * p * p;
        let mut patches = vec![0f32; k * np];
        for c in 0..3 {
            for ky in 0..p {
                for kx in 0..p {
                    let r = (c * p + ky) * p + kx;
                    for py in 0..rows {
                        for px in 0..cols {
                            patches[r * np + py * cols + px] = img[(c * h + py * p + ky) * w + px * p + kx];
                        }
                    }
                }
            }
        }
        let emb = self.patch.forward(&patches, np);
        let pos = self.position_embeddings(rows, cols);
        let mut x = vec![0f32; d * n];
        for (c, &cls) in self.cls.iter().enumerate() {
            x[c * n] = cls + pos[c];
            for t in 0..np {
                x[c * n + 1 + t] = emb[c * np + t] + pos[(1 + t) * d + c];
            }
        }
        clock.lap("patch embed");
        let mut stages = Vec::with_capacity(self.out_indices.len());
        let mut keep = |i: usize, x: &[f32], clock: &mut Clock| {
            if self.out_indices.contains(&i) {
                stages.push(if self.apply_layernorm { self.final_norm.forward(x, n) } else { x.to_vec() });
                clock.lap("final norm");
            }
        };
        keep(0, &x, clock);
        for (i, layer) in self.layers.iter().enumerate() {
            layer.forward(&mut x, n, self.heads, clock);
            keep(i + 1, &x, clock);
        }
        stages
    }

    /// The position embeddings for a `rows × cols` patch grid, token-major
    /// (`(1 + rows·cols) × d`), CLS first.
    pub(crate) fn position_embeddings(&self, rows: usize, cols: usize) -> Vec<f32> {
        let (d, g) = (self.width(), self.grid);
        if rows == g && cols == g {
            return self.pos.clone();
        }
        let mut out = self.pos[..d].to_vec();
        out.extend(resize_bicubic(&self.pos[d..], g, g, d, rows, cols));
        out
    }
}

impl Layer {
    /// `x ← x + λ₁·attn(norm1 x)`, then `x ← x + λ₂·mlp(norm2 x)`, on `d × n` tokens.
    fn forward(&self, x: &mut [f32], n: usize, heads: usize, clock: &mut Clock) {
        let d = self.output.out();
        let h = self.norm1.forward(x, n);
        clock.lap("layer norm");
        let qkv = self.qkv.forward(&h, n);
        clock.lap("qkv");
        let (q, kv) = qkv.split_at(d * n);
        let a = attention(q, &kv[..d * n], &kv[d * n..], d, n, heads);
        clock.lap("attention");
        self.output.accumulate(&a, n, x);
        clock.lap("attention output");
        let h = self.norm2.forward(x, n);
        clock.lap("layer norm");
        let m = self.fc1.forward_gelu(&h, n);
        clock.lap("mlp fc1 + gelu");
        self.fc2.accumulate(&m, n, x);
        clock.lap("mlp fc2");
    }
}
