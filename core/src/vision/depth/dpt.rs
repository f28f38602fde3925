//! The DPT neck and the relative-depth head that turn the backbone's token
//! states into a depth map at the input's resolution.
//!
//! Reassemble: each stage's patch tokens become a `d × rows × cols` map,
//! projected (1×1) to its neck width and resized by its factor (transposed
//! convolution for 4 and 2, identity for 1, a stride-2 3×3 convolution for
//! 0.5), then brought to the fusion width by a 3×3 convolution without bias.
//! Fusion runs from the coarsest map up: add the pre-activation residual unit
//! of the next finer map, another residual unit, a bilinear upsample with
//! aligned corners to the next finer map's size (×2 after the last), a 1×1
//! projection. The head: 3×3 convolution to half the width, bilinear upsample
//! to `patch_size ×` the grid, 3×3 convolution, ReLU, 1×1 to one channel, and
//! ReLU (relative depth) or sigmoid × `max_depth` (metric).

use super::DepthModelError;
use super::config::DepthConfig;
use super::ops::{Conv, ConvUp, Linear, resize_planes};
use super::profile::Clock;
use super::vit::linear;
use super::weights::Checkpoint;
use crate::vision::resize::{resize_bilinear, resize_bilinear_align_corners};

pub(crate) enum Resize {
    Up(ConvUp),
    Same,
    Down(Conv),
}

pub(crate) struct Reassemble {
    pub(crate) projection: Linear,
    pub(crate) resize: Resize,
}

/// Pre-activation residual unit: `x + conv2(relu(conv1(relu(x))))`.
pub(crate) struct Residual {
    pub(crate) conv1: Conv,
    pub(crate) conv2: Conv,
}

pub(crate) struct Fusion {
    pub(crate) residual1: Residual,
    pub(crate) residual2: Residual,
    pub(crate) projection: Linear,
}

/// The neck and head's weights.
pub(crate) struct Dpt {
    pub(crate) reassemble: Vec<Reassemble>,
    pub(crate) convs: Vec<Conv>,
    pub(crate) fusion: Vec<Fusion>,
    pub(crate) head1: Conv,
    pub(crate) head2: Conv,
    pub(crate) head3: Linear,
    pub(crate) patch_size: usize,
    pub(crate) metric: bool,
    pub(crate) scale: f32,
}

fn conv(
    ck: &Checkpoint,
    prefix: &str,
    (c_out, c_in, k): (usize, usize, usize),
    bias: bool,
) -> Result<Conv, DepthModelError> {
    let w = ck.take(&format!("{prefix}.weight"), &[c_out, c_in, k, k])?;
    let b = if bias { ck.take(&format!("{prefix}.bias"), &[c_out])? } else { vec![0.0; c_out] };
    Ok(Conv::new(w, b, c_in, k, 1, k / 2))
}

fn residual(ck: &Checkpoint, prefix: &str, f: usize) -> Result<Residual, DepthModelError> {
    Ok(Residual {
        conv1: conv(ck, &format!("{prefix}.convolution1"), (f, f, 3), true)?,
        conv2: conv(ck, &format!("{prefix}.convolution2"), (f, f, 3), true)?,
    })
}

impl Dpt {
    /// Reads the neck's and head's tensors (`neck.*`, `head.*`), checking shapes against `cfg`.
    pub(crate) fn load(ck: &Checkpoint, cfg: &DepthConfig) -> Result<Self, DepthModelError> {
        let (d, f) = (cfg.reassemble_hidden_size, cfg.fusion_hidden_size);
        let mut reassemble = Vec::new();
        let mut convs = Vec::new();
        let mut fusion = Vec::new();
        for (i, (&c, &factor)) in cfg.neck_hidden_sizes.iter().zip(&cfg.reassemble_factors).enumerate() {
            let r = format!("neck.reassemble_stage.layers.{i}");
            let resize = if factor > 1.0 {
                let k = factor as usize;
                Resize::Up(ConvUp {
                    w: ck.take(&format!("{r}.resize.weight"), &[c, c, k, k])?,
                    b: ck.take(&format!("{r}.resize.bias"), &[c])?,
                    c_in: c,
                    f: k,
                })
            } else if factor == 1.0 {
                Resize::Same
            } else {
                let w = ck.take(&format!("{r}.resize.weight"), &[c, c, 3, 3])?;
                let b = ck.take(&format!("{r}.resize.bias"), &[c])?;
                Resize::Down(Conv::new(w, b, c, 3, (1.0 / factor).round() as usize, 1))
            };
            reassemble.push(Reassemble { projection: linear(ck, &format!("{r}.projection"), c, d, true)?, resize });
            convs.push(conv(ck, &format!("neck.convs.{i}"), (f, c, 3), false)?);
            let l = format!("neck.fusion_stage.layers.{i}");
            fusion.push(Fusion {
                residual1: residual(ck, &format!("{l}.residual_layer1"), f)?,
                residual2: residual(ck, &format!("{l}.residual_layer2"), f)?,
                projection: linear(ck, &format!("{l}.projection"), f, f, true)?,
            });
        }
        let hh = cfg.head_hidden_size;
        Ok(Self {
            reassemble,
            convs,
            fusion,
            head1: conv(ck, "head.conv1", (f / 2, f, 3), true)?,
            head2: conv(ck, "head.conv2", (hh, f / 2, 3), true)?,
            head3: linear(ck, "head.conv3", 1, hh, true)?,
            patch_size: cfg.patch_size,
            metric: cfg.depth_estimation_type == "metric",
            scale: cfg.output_scale(),
        })
    }

    /// Depth at `patch_size · (rows × cols)` from the backbone stages (each
    /// `d × (1 + rows·cols)`, CLS first).
    pub(crate) fn forward(&self, stages: &[Vec<f32>], rows: usize, cols: usize, clock: &mut Clock) -> Vec<f32> {
        let n = rows * cols + 1;
        // Reassemble and bring every map to the fusion width.
        let mut maps: Vec<(Vec<f32>, usize, usize)> = Vec::with_capacity(stages.len());
        for ((tokens, r), conv) in stages.iter().zip(&self.reassemble).zip(&self.convs) {
            let d = r.projection.inp;
            let mut img = Vec::with_capacity(d * (n - 1));
            for c in 0..d {
                img.extend_from_slice(&tokens[c * n + 1..(c + 1) * n]);
            }
            let x = r.projection.forward(&img, n - 1);
            let (x, h, w) = match &r.resize {
                Resize::Up(up) => (up.forward(&x, rows, cols), rows * up.f, cols * up.f),
                Resize::Same => (x, rows, cols),
                Resize::Down(down) => {
                    let (h, w) = down.out_size(rows, cols);
                    (down.forward(&x, rows, cols), h, w)
                }
            };
            clock.lap("reassemble");
            maps.push((conv.forward(&x, h, w), h, w));
            clock.lap("neck convs");
        }
        // Fusion, coarsest first.
        let f = self.fusion[0].projection.out();
        let mut fused: Option<(Vec<f32>, usize, usize)> = None;
        for (idx, layer) in self.fusion.iter().enumerate() {
            let (map, mh, mw) = &maps[maps.len() - 1 - idx];
            let (mut x, h, w) = match fused.take() {
                None => (map.clone(), *mh, *mw),
                Some((mut x, h, w)) => {
                    let res = if (h, w) == (*mh, *mw) {
                        layer.residual1.forward(map, (f, h, w))
                    } else {
                        let r = resize_planes(map, (f, *mh, *mw), (h, w), resize_bilinear);
                        layer.residual1.forward(&r, (f, h, w))
                    };
                    x.iter_mut().zip(&res).for_each(|(a, b)| *a += b);
                    (x, h, w)
                }
            };
            x = layer.residual2.forward(&x, (f, h, w));
            clock.lap("fusion residual units");
            let (oh, ow) = if idx + 1 < maps.len() {
                let (_, nh, nw) = &maps[maps.len() - 2 - idx];
                (*nh, *nw)
            } else {
                (2 * h, 2 * w)
            };
            let up = resize_planes(&x, (f, h, w), (oh, ow), resize_bilinear_align_corners);
            clock.lap("fusion resize");
            fused = Some((layer.projection.forward(&up, oh * ow), oh, ow));
            clock.lap("fusion projection");
        }
        let Some((x, h, w)) = fused else { return Vec::new() };
        // Head.
        let y = self.head1.forward(&x, h, w);
        clock.lap("head conv1");
        let (oh, ow) = (rows * self.patch_size, cols * self.patch_size);
        let y = resize_planes(&y, (self.head1.c_out(), h, w), (oh, ow), resize_bilinear_align_corners);
        clock.lap("head resize");
        let mut y = self.head2.forward(&y, oh, ow);
        y.iter_mut().for_each(|v| *v = v.max(0.0));
        clock.lap("head conv2");
        let mut depth = self.head3.forward(&y, oh * ow);
        let scale = self.scale;
        if self.metric {
            depth.iter_mut().for_each(|v| *v = scale / (1.0 + (-*v).exp()));
        } else {
            depth.iter_mut().for_each(|v| *v = v.max(0.0) * scale);
        }
        clock.lap("head conv3");
        depth
    }
}

impl Residual {
    fn forward(&self, x: &[f32], (_, h, w): (usize, usize, usize)) -> Vec<f32> {
        let relu = |v: &[f32]| v.iter().map(|a| a.max(0.0)).collect::<Vec<f32>>();
        let y = self.conv1.forward(&relu(x), h, w);
        let mut y = self.conv2.forward(&relu(&y), h, w);
        y.iter_mut().zip(x).for_each(|(a, b)| *a += b);
        y
    }
}
