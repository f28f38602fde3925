//! The sizes of a Depth Anything V2 network, read from the checkpoint's
//! `config.json` so that Small, Base and Large load through the same code.
//!
//! Published configs leave out fields that equal `transformers`' defaults, so
//! every field here has the default of `DepthAnythingConfig` or
//! `Dinov2Config`; the loader then checks every tensor's shape against these
//! sizes, which catches a config that does not belong to its weights.

use serde::Deserialize;

/// The DINOv2 backbone's part of the config (`backbone_config`).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(default)]
pub struct BackboneConfig {
    /// Token width (384 for ViT-S, 768 for ViT-B, 1024 for ViT-L).
    pub hidden_size: usize,
    /// Transformer layers.
    pub num_hidden_layers: usize,
    /// Attention heads per layer.
    pub num_attention_heads: usize,
    /// MLP width as a multiple of `hidden_size` (what `transformers` uses;
    /// `intermediate_size` is ignored, as there).
    pub mlp_ratio: f64,
    /// Layer-norm epsilon.
    pub layer_norm_eps: f64,
    /// Patch side in pixels.
    pub patch_size: usize,
    /// Training resolution; the position embeddings cover `(image_size / patch_size)²` patches.
    pub image_size: usize,
    /// Activation of the MLP (`gelu` is the only one the checkpoints use).
    pub hidden_act: String,
    /// Whether the MLP is SwiGLU (ViT-g only; not supported).
    pub use_swiglu_ffn: bool,
    /// Whether the final layer norm is applied to every stage the neck reads.
    pub apply_layernorm: bool,
    /// Hidden states the neck reads: 0 is the embedding output, `i` the output of layer `i`.
    pub out_indices: Option<Vec<usize>>,
    /// The same as names (`stage3`, …), used when `out_indices` is absent.
    pub out_features: Option<Vec<String>>,
}

impl Default for BackboneConfig {
    fn default() -> Self {
        Self {
            hidden_size: 768,
            num_hidden_layers: 12,
            num_attention_heads: 12,
            mlp_ratio: 4.0,
            layer_norm_eps: 1e-6,
            patch_size: 14,
            image_size: 518,
            hidden_act: "gelu".into(),
            use_swiglu_ffn: false,
            apply_layernorm: true,
            out_indices: None,
            out_features: None,
        }
    }
}

/// `config.json` of `DepthAnythingForDepthEstimation`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(default)]
pub struct DepthConfig {
    /// The DINOv2 backbone.
    pub backbone_config: BackboneConfig,
    /// Patch side in pixels (the head upsamples to `patch_size ×` the patch grid).
    pub patch_size: usize,
    /// Channels of the backbone states the reassemble stage projects.
    pub reassemble_hidden_size: usize,
    /// Spatial factor of each reassemble layer: 4, 2, 1, 0.5.
    pub reassemble_factors: Vec<f64>,
    /// Channels after each reassemble projection.
    pub neck_hidden_sizes: Vec<usize>,
    /// Channels of the fusion stage.
    pub fusion_hidden_size: usize,
    /// Channels of the head's second convolution.
    pub head_hidden_size: usize,
    /// `relative` (ReLU output) or `metric` (sigmoid × `max_depth`).
    pub depth_estimation_type: String,
    /// Scale of the output (1 for relative depth).
    pub max_depth: Option<f64>,
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self {
            backbone_config: BackboneConfig::default(),
            patch_size: 14,
            reassemble_hidden_size: 384,
            reassemble_factors: vec![4.0, 2.0, 1.0, 0.5],
            neck_hidden_sizes: vec![48, 96, 192, 384],
            fusion_hidden_size: 64,
            head_hidden_size: 32,
            depth_estimation_type: "relative".into(),
            max_depth: None,
        }
    }
}

impl DepthConfig {
    /// The published Small model's sizes (`depth-anything/Depth-Anything-V2-Small-hf`):
    /// ViT-S/14, 12 layers, 6 heads, DPT features 64.
    pub fn small() -> Self {
        Self {
            backbone_config: BackboneConfig {
                hidden_size: 384,
                num_attention_heads: 6,
                out_indices: Some(vec![3, 6, 9, 12]),
                ..BackboneConfig::default()
            },
            ..Self::default()
        }
    }

    /// Parses `config.json`; the error says what is wrong in words.
    pub fn from_json(text: &str) -> Result<Self, String> {
        let c: Self = serde_json::from_str(text).map_err(|e| e.to_string())?;
        c.validate()?;
        Ok(c)
    }

    /// The backbone stages the neck reads, as hidden-state indices.
    pub fn out_indices(&self) -> Result<Vec<usize>, String> {
        let b = &self.backbone_config;
        if let Some(ix) = &b.out_indices {
            return Ok(ix.clone());
        }
        if let Some(names) = &b.out_features {
            return names
                .iter()
                .map(|n| {
                    n.strip_prefix("stage")
                        .and_then(|s| s.parse().ok())
                        .ok_or_else(|| format!("out_features entry `{n}`"))
                })
                .collect();
        }
        // Dinov2Config's default: the last layer only; Depth Anything needs four.
        Ok(vec![b.num_hidden_layers])
    }

    /// MLP width of each transformer layer.
    pub fn mlp_hidden(&self) -> usize {
        (self.backbone_config.hidden_size as f64 * self.backbone_config.mlp_ratio) as usize
    }

    /// Output scale: `max_depth` for metric models, 1 for relative ones.
    pub fn output_scale(&self) -> f32 {
        self.max_depth.unwrap_or(1.0) as f32
    }

    fn validate(&self) -> Result<(), String> {
        let b = &self.backbone_config;
        if b.use_swiglu_ffn {
            return Err("use_swiglu_ffn: expected false (ViT-S/B/L), found true (ViT-g is not supported)".into());
        }
        if b.hidden_act != "gelu" {
            return Err(format!("backbone_config.hidden_act: expected \"gelu\", found {:?}", b.hidden_act));
        }
        if b.num_attention_heads == 0 || !b.hidden_size.is_multiple_of(b.num_attention_heads) {
            return Err(format!(
                "hidden_size {} must be a multiple of num_attention_heads {}",
                b.hidden_size, b.num_attention_heads
            ));
        }
        if b.patch_size == 0 || b.patch_size != self.patch_size {
            return Err(format!("patch_size: backbone {} and model {} must agree", b.patch_size, self.patch_size));
        }
        if self.depth_estimation_type != "relative" && self.depth_estimation_type != "metric" {
            return Err(format!(
                "depth_estimation_type: expected \"relative\" or \"metric\", found {:?}",
                self.depth_estimation_type
            ));
        }
        let ix = self.out_indices()?;
        let n = self.neck_hidden_sizes.len();
        if ix.len() != n || self.reassemble_factors.len() != n || n == 0 {
            return Err(format!(
                "expected as many backbone stages ({}) as neck_hidden_sizes ({n}) and reassemble_factors ({})",
                ix.len(),
                self.reassemble_factors.len()
            ));
        }
        if let Some(&bad) = ix.iter().find(|&&i| i > b.num_hidden_layers) {
            return Err(format!("out index {bad} beyond the {} layers", b.num_hidden_layers));
        }
        for &f in &self.reassemble_factors {
            let ok = f == 1.0 || (f > 1.0 && f.fract() == 0.0) || (f < 1.0 && f > 0.0 && (1.0 / f).fract() == 0.0);
            if !ok {
                return Err(format!("reassemble factor {f}: expected an integer or 1/integer"));
            }
        }
        if self.reassemble_hidden_size != b.hidden_size {
            return Err(format!(
                "reassemble_hidden_size {} differs from the backbone's hidden_size {}",
                self.reassemble_hidden_size, b.hidden_size
            ));
        }
        Ok(())
    }
}
