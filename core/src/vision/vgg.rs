//! VGG up to relu3_3, forward and backward, on the CPU.
//!
//! GAST compares images in the space of torchvision VGG's relu3_1, relu3_2 and
//! relu3_3 activations (768 channels at a quarter of the resolution). The
//! losses need these features for style maps and content renders (forward
//! only, [`Vgg::features`]) and, for the rendered view, the gradient of a loss
//! on them back to the image pixels ([`Vgg::forward`] then [`Vgg::backward`]).
//! Only the input gradient is ever needed (the network is frozen), so the
//! saved state is small: a ReLU mask per convolution and the winners of the
//! two max-pools.
//!
//! Convolutions are im2col + `gemm` (see `conv.rs`) or Winograd F(4×4, 3×3)
//! (`winograd.rs`), chosen by [`Vgg::with_conv`]; the ImageNet normalisation
//! torchvision's weights expect happens inside. [`Vgg::forward_within`]
//! computes only the cone of a box of relu3 positions (`vgg_cone.rs`), for
//! losses that read only the object's positions.

use rayon::prelude::*;

use super::conv::{ConvAlgo, add_bias, conv_backward, conv_relu, max_pool, max_pool_backward};
use super::vgg_cone::{ConePlan, Region, crop_planes, embed_planes};
use super::weights::VggWeights;
use super::winograd::{WinogradKernel, winograd_conv, winograd_flops};

/// torchvision's ImageNet normalisation, per RGB channel.
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// torchvision's ImageNet normalisation, per RGB channel.
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// Channels of the feature map: relu3_1, relu3_2, relu3_3 concatenated.
pub const FEATURE_CHANNELS: usize = 768;

/// Rows of relu3 positions [`Vgg::features_banded`] computes at once (256
/// pixel rows: the style at the default texture scale, 256, is one band).
pub const BAND_ROWS: usize = 64;

/// Values per rayon item in the backward pass's element-wise loops.
const CHUNK: usize = 1 << 14;

/// A CHW feature map.
#[derive(Clone, Debug, PartialEq)]
pub struct Features {
    /// Channels (768: relu3_1 in 0..256, relu3_2 in 256..512, relu3_3 in 512..768).
    pub c: usize,
    /// Height, `floor(floor(H/2)/2)` of the input.
    pub h: usize,
    /// Width, `floor(floor(W/2)/2)` of the input.
    pub w: usize,
    /// `c · h · w` values, channel-major.
    pub data: Vec<f32>,
}

/// What [`Vgg::backward`] needs from a forward pass.
#[derive(Clone, Debug, Default)]
pub struct VggState {
    /// Input size (H, W).
    size: (usize, usize),
    /// For each of the seven convolutions, whether its ReLU passed (output > 0),
    /// on the region of its output that was kept.
    relu_open: Vec<Vec<bool>>,
    /// For the two max-pools, the in-plane index of each output's maximum.
    pool_argmax: [Vec<u32>; 2],
    /// The regions each convolution ran on and kept ([`super::vgg_cone`]);
    /// `None` when the input had no features.
    plan: Option<ConePlan>,
}

/// The network: the seven convolutions conv1_1 … conv3_3.
#[derive(Clone, Debug)]
pub struct Vgg {
    weights: VggWeights,
    conv: ConvAlgo,
    /// Per convolution, the forward and input-gradient kernels in the Winograd
    /// domain (empty unless `conv` is Winograd).
    winograd: Vec<[WinogradKernel; 2]>,
}

/// Index of each convolution's stage (0: full resolution, 1: ½, 2: ¼).
pub(crate) const STAGE: [usize; 7] = [0, 0, 1, 1, 2, 2, 2];

impl Vgg {
    /// Wraps loaded weights (see [`VggWeights::load`]).
    pub fn from_weights(weights: VggWeights) -> Self {
        Self { weights, conv: ConvAlgo::default(), winograd: Vec::new() }
    }

    /// The same network computing its convolutions with `conv` (transforms
    /// the kernels once for Winograd).
    pub fn with_conv(mut self, conv: ConvAlgo) -> Self {
        self.winograd = match conv {
            ConvAlgo::Im2col => Vec::new(),
            ConvAlgo::Winograd => self
                .weights
                .convs
                .iter()
                .map(|c| {
                    [
                        WinogradKernel::forward(&c.weight, c.c_out, c.c_in),
                        WinogradKernel::input_gradient(&c.weight, c.c_out, c.c_in),
                    ]
                })
                .collect(),
        };
        self.conv = conv;
        self
    }

    /// How the convolutions are computed.
    pub fn conv(&self) -> ConvAlgo {
        self.conv
    }

    /// `out = relu(conv_layer(input) + bias)` at `h × w`, by the chosen algorithm.
    fn conv_relu(&self, layer: usize, input: &[f32], (h, w): (usize, usize), out: &mut [f32], scratch: &mut Vec<f32>) {
        let c = &self.weights.convs[layer];
        match self.winograd.get(layer) {
            Some([k, _]) => {
                winograd_conv(input, (c.c_in, h, w), k, out, scratch);
                add_bias(out, h * w, &c.bias, true);
            }
            None => conv_relu(input, (c.c_in, h, w), &c.weight, &c.bias, out, scratch),
        }
    }

    /// Input gradient of convolution `layer` at `h × w` (overwrites `v_input`).
    fn conv_backward(
        &self,
        layer: usize,
        v_out: &[f32],
        (h, w): (usize, usize),
        v_input: &mut [f32],
        scratch: &mut Vec<f32>,
    ) {
        let c = &self.weights.convs[layer];
        match self.winograd.get(layer) {
            Some([_, k]) => winograd_conv(v_out, (c.c_out, h, w), k, v_input, scratch),
            None => conv_backward(v_out, (c.c_in, h, w), &c.weight, c.c_out, v_input, scratch),
        }
    }

    /// Loads the weights from a `.safetensors` or `.pth` file (see
    /// [`super::resolve_weights`] for finding one).
    pub fn load(path: &std::path::Path) -> Result<Self, super::WeightsError> {
        VggWeights::load(path).map(Self::from_weights)
    }

    /// The convolution weights.
    pub fn weights(&self) -> &VggWeights {
        &self.weights
    }

    /// The relu3 features of an RGB image (`h × w × 3`, HWC, values in [0, 1]),
    /// saving nothing for a backward pass.
    ///
    /// An image smaller than 4×4 has an empty feature map (`h` or `w` 0), as in torch.
    ///
    /// # Panics
    /// If `rgb.len() != h·w·3`.
    pub fn features(&self, rgb: &[f32], h: usize, w: usize) -> Features {
        self.run(rgb, h, w, None, None)
    }

    /// As [`Vgg::features`], also returning what [`Vgg::backward`] needs.
    pub fn forward(&self, rgb: &[f32], h: usize, w: usize) -> (Features, VggState) {
        let mut state = VggState::default();
        let f = self.run(rgb, h, w, None, Some(&mut state));
        (f, state)
    }

    /// Gradient with respect to the input image (HWC, `h × w × 3`) of a loss
    /// whose gradient with respect to the features is `v_features`
    /// (same layout as [`Features::data`]).
    ///
    /// # Panics
    /// If `v_features` does not have the feature map's size.
    pub fn backward(&self, state: &VggState, v_features: &[f32]) -> Vec<f32> {
        let (h, w) = state.size;
        let (fh, fw) = (h / 4, w / 4);
        let n3 = fh * fw;
        assert_eq!(v_features.len(), FEATURE_CHANNELS * n3, "backward: v_features has the wrong size");
        let Some(plan) = state.plan.filter(|_| n3 > 0) else {
            return vec![0.0; h * w * 3];
        };
        let grid = Region::full(fh, fw);
        let block = |k: usize, r: Region| crop_planes(&v_features[k * 256 * n3..(k + 1) * 256 * n3], 256, grid, r);
        let convs = &self.weights.convs;
        let mut scratch = Vec::new();
        // v holds the gradient of the current layer's kept output (post-ReLU).
        let mut v = block(2, plan.output[6]);
        let mut v_in = Vec::new();
        for layer in (0..7).rev() {
            let c = &convs[layer];
            let (inr, outr) = (plan.input[layer], plan.output[layer]);
            if layer == 5 || layer == 4 {
                // relu3_2 and relu3_1 are features themselves as well as the next layer's input.
                let b = block(layer - 4, outr);
                v.par_chunks_mut(CHUNK).zip(b.par_chunks(CHUNK)).for_each(|(a, b)| {
                    a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
                });
            }
            // In chunks the loop vectorises; one rayon item per value cost
            // 2.5 % of a CPU step's samples.
            v.par_chunks_mut(CHUNK).zip(state.relu_open[layer].par_chunks(CHUNK)).for_each(|(g, open)| {
                g.iter_mut().zip(open).for_each(|(g, &open)| *g = if open { *g } else { 0.0 });
            });
            // The convolution ran on its input's region; the cut ring has no gradient.
            if inr != outr {
                v = embed_planes(&v, c.c_out, inr, outr);
            }
            v_in.resize(c.c_in * inr.area(), 0.0);
            self.conv_backward(layer, &v, (inr.height(), inr.width()), &mut v_in, &mut scratch);
            std::mem::swap(&mut v, &mut v_in);
            if layer == 4 || layer == 2 {
                // Through the pool in front of this stage, onto the previous convolution's kept output.
                let p = if layer == 2 { 0 } else { 1 };
                let prev = plan.output[layer - 1];
                v_in.resize(c.c_in * prev.area(), 0.0);
                max_pool_backward(&v, &state.pool_argmax[p], (c.c_in, prev.height(), prev.width()), &mut v_in);
                std::mem::swap(&mut v, &mut v_in);
            }
        }
        // v is the gradient of the normalised CHW input on the first region.
        let r0 = plan.input[0];
        if r0 != Region::full(h, w) {
            v = embed_planes(&v, 3, Region::full(h, w), r0);
        }
        let n = h * w;
        let mut v_rgb = vec![0.0; n * 3];
        for (p, px) in v_rgb.chunks_exact_mut(3).enumerate() {
            for ch in 0..3 {
                px[ch] = v[ch * n + p] / IMAGENET_STD[ch];
            }
        }
        v_rgb
    }

    /// As [`Vgg::forward`], computing only the cone of the relu3 positions in
    /// `cells` ([`super::vgg_cone`]): the features there (and the input
    /// gradient of a loss on them) equal the whole pass's; the features
    /// elsewhere are 0.
    pub fn forward_within(&self, rgb: &[f32], h: usize, w: usize, cells: Region) -> (Features, VggState) {
        let mut state = VggState::default();
        let f = self.run(rgb, h, w, Some(cells), Some(&mut state));
        (f, state)
    }

    /// As [`Vgg::features`] on the cone of `cells` (see [`Vgg::forward_within`]).
    pub fn features_within(&self, rgb: &[f32], h: usize, w: usize, cells: Region) -> Features {
        self.run(rgb, h, w, Some(cells), None)
    }

    /// As [`Vgg::features`], computed in bands of [`BAND_ROWS`] rows of
    /// relu3 positions, each band's cone apart ([`super::vgg_cone`]): the
    /// activations held at once are a band's, not the whole image's (the
    /// style at a large texture scale: with wave at 1,024 px high the style
    /// features' stage peaked at 3.37 GB resident, 1.69 GB in bands). The
    /// features equal the whole pass's to rounding (a band's
    /// convolutions tile from its own origin); an image of one band is the
    /// whole pass, bit for bit.
    pub fn features_banded(&self, rgb: &[f32], h: usize, w: usize) -> Features {
        let (fh, fw) = (h / 4, w / 4);
        if fh <= BAND_ROWS || fw == 0 {
            return self.features(rgb, h, w);
        }
        let n3 = fh * fw;
        let mut data = vec![0.0; FEATURE_CHANNELS * n3];
        for y0 in (0..fh).step_by(BAND_ROWS) {
            let cells = Region { y0, y1: (y0 + BAND_ROWS).min(fh), x0: 0, x1: fw };
            let rows = cells.height() * fw;
            self.pass(rgb, h, w, Some(cells), None, &mut |k, part| {
                for (c, plane) in part.chunks_exact(rows).enumerate() {
                    let at = (k * 256 + c) * n3 + y0 * fw;
                    data[at..at + rows].copy_from_slice(plane);
                }
            });
        }
        Features { c: FEATURE_CHANNELS, h: fh, w: fw, data }
    }

    fn run(&self, rgb: &[f32], h: usize, w: usize, cells: Option<Region>, save: Option<&mut VggState>) -> Features {
        let (fh, fw) = (h / 4, w / 4);
        let n3 = fh * fw;
        let mut feats = vec![0.0; FEATURE_CHANNELS * n3];
        if n3 == 0 {
            self.pass(rgb, h, w, cells, save, &mut |_, _| {});
            return Features { c: FEATURE_CHANNELS, h: fh, w: fw, data: feats };
        }
        let grid = Region::full(fh, fw);
        let out = ConePlan::new(cells.unwrap_or(grid), (h, w)).output[6];
        self.pass(rgb, h, w, cells, save, &mut |k, part| {
            let full = embed_planes(part, 256, grid, out);
            feats[k * 256 * n3..(k + 1) * 256 * n3].copy_from_slice(&full);
        });
        Features { c: FEATURE_CHANNELS, h: fh, w: fw, data: feats }
    }

    /// The forward pass over the cone of `cells` (the whole grid when
    /// `None`), handing `emit(k, part)` relu3_{k+1}'s features on the cells
    /// (256 planes over the cells, CHW) as each is computed.
    fn pass(
        &self,
        rgb: &[f32],
        h: usize,
        w: usize,
        cells: Option<Region>,
        mut save: Option<&mut VggState>,
        emit: &mut dyn FnMut(usize, &[f32]),
    ) {
        assert_eq!(rgb.len(), h * w * 3, "VGG input must be h·w·3 RGB values");
        let (fh, fw) = (h / 4, w / 4);
        if let Some(s) = save.as_deref_mut() {
            s.size = (h, w);
            s.relu_open.clear();
            s.plan = None;
        }
        if fh == 0 || fw == 0 {
            return;
        }
        let grid = Region::full(fh, fw);
        let plan = ConePlan::new(cells.unwrap_or(grid), (h, w));
        let r0 = plan.input[0];
        let mut x = vec![0.0; 3 * r0.area()];
        for y in r0.y0..r0.y1 {
            for xx in r0.x0..r0.x1 {
                let (p, q) = (y * w + xx, (y - r0.y0) * r0.width() + xx - r0.x0);
                for ch in 0..3 {
                    x[ch * r0.area() + q] = (rgb[3 * p + ch] - IMAGENET_MEAN[ch]) / IMAGENET_STD[ch];
                }
            }
        }
        let convs = &self.weights.convs;
        let mut scratch = Vec::new();
        let mut y = Vec::new();
        for (layer, c) in convs.iter().enumerate().take(7) {
            let (inr, outr) = (plan.input[layer], plan.output[layer]);
            y.resize(c.c_out * inr.area(), 0.0);
            self.conv_relu(layer, &x, (inr.height(), inr.width()), &mut y, &mut scratch);
            // x becomes the kept output (y keeps a buffer to reuse).
            if inr == outr {
                std::mem::swap(&mut x, &mut y);
            } else {
                x = crop_planes(&y, c.c_out, inr, outr);
            }
            if let Some(s) = save.as_deref_mut() {
                s.relu_open.push(x.par_iter().map(|&v| v > 0.0).collect());
            }
            if layer >= 4 {
                // relu3_1..3 on the cells.
                emit(layer - 4, &crop_planes(&x, 256, outr, plan.output[6]));
            }
            if layer == 1 || layer == 3 {
                let next = plan.input[layer + 1];
                y.resize(c.c_out * next.area(), 0.0);
                let p = layer / 2;
                max_pool(
                    &x,
                    (c.c_out, outr.height(), outr.width()),
                    &mut y,
                    save.as_deref_mut().map(|s| &mut s.pool_argmax[p]),
                );
                std::mem::swap(&mut x, &mut y);
            }
        }
        if let Some(s) = save {
            s.plan = Some(plan);
        }
    }

    /// Floating-point operations of one forward pass at `h × w` (multiply and add counted apart).
    pub fn forward_flops(&self, h: usize, w: usize) -> f64 {
        let dims = [(h, w), (h / 2, w / 2), (h / 4, w / 4)];
        self.weights
            .convs
            .iter()
            .zip(STAGE)
            .map(|(c, s)| 2.0 * (c.c_out * c.c_in * 9) as f64 * (dims[s].0 * dims[s].1) as f64)
            .sum()
    }

    /// Floating-point operations one forward pass at `h × w` executes with the
    /// chosen convolution (for Winograd: its products plus both transforms;
    /// the backward does about as many).
    pub fn executed_forward_flops(&self, h: usize, w: usize) -> f64 {
        if self.conv == ConvAlgo::Im2col {
            return self.forward_flops(h, w);
        }
        let dims = [(h, w), (h / 2, w / 2), (h / 4, w / 4)];
        self.weights
            .convs
            .iter()
            .zip(STAGE)
            .map(|(c, s)| winograd_flops(c.c_in, c.c_out, dims[s].0, dims[s].1).iter().sum::<f64>())
            .sum()
    }
}

/// Timings of [`bench()`].
#[derive(Clone, Copy, Debug)]
pub struct VggTiming {
    /// Image height and width.
    pub size: (usize, usize),
    /// Best time of one [`Vgg::forward`], seconds.
    pub forward_s: f64,
    /// Best time of one [`Vgg::backward`], seconds.
    pub backward_s: f64,
    /// Forward floating-point operations.
    pub forward_flops: f64,
    /// CPU seconds (all threads) of the best forward and backward, where the
    /// platform reports them (Linux): on a shared machine wall time measures
    /// the neighbours, CPU time what the kernels cost.
    pub cpu_s: Option<(f64, f64)>,
}

/// CPU time of this process so far, in seconds (Linux `/proc`, 10 ms ticks).
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit(')').next()?.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

impl std::fmt::Display for VggTiming {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = self.forward_flops * 1e-9;
        write!(
            f,
            "VGG relu3 at {}×{} on {} threads: forward {:.1} ms ({:.1} GFLOP/s of {g:.2} GFLOP), backward {:.1} ms ({:.1} GFLOP/s, {:.2}× forward)",
            self.size.0,
            self.size.1,
            rayon::current_num_threads(),
            self.forward_s * 1e3,
            g / self.forward_s,
            self.backward_s * 1e3,
            g / self.backward_s,
            self.backward_s / self.forward_s
        )?;
        if let Some((cf, cb)) = self.cpu_s {
            write!(f, "; per CPU-second: forward {:.1}, backward {:.1} GFLOP/s", g / cf, g / cb)?;
        }
        Ok(())
    }
}

/// Times forward and backward at `h × w` (best of `reps` after a warm-up run)
/// on a smooth test image; the backward has about the forward's FLOPs.
pub fn bench(vgg: &Vgg, h: usize, w: usize, reps: usize) -> VggTiming {
    let rgb: Vec<f32> = (0..h * w * 3).map(|i| 0.5 + 0.4 * ((i as f32) * 0.37).sin()).collect();
    let (f, state) = vgg.forward(&rgb, h, w);
    let v: Vec<f32> = (0..f.data.len()).map(|i| ((i as f32) * 0.11).cos()).collect();
    let _ = vgg.backward(&state, &v);
    let (mut fwd, mut bwd) = (f64::INFINITY, f64::INFINITY);
    let (mut cpu_f, mut cpu_b) = (f64::INFINITY, f64::INFINITY);
    let reps = reps.max(1);
    for _ in 0..reps {
        let (c0, t) = (process_cpu_seconds(), std::time::Instant::now());
        let (_, state) = vgg.forward(&rgb, h, w);
        fwd = fwd.min(t.elapsed().as_secs_f64());
        let (c1, t) = (process_cpu_seconds(), std::time::Instant::now());
        let _ = vgg.backward(&state, &v);
        bwd = bwd.min(t.elapsed().as_secs_f64());
        if let (Some(c0), Some(c1), Some(c2)) = (c0, c1, process_cpu_seconds()) {
            cpu_f = cpu_f.min(c1 - c0);
            cpu_b = cpu_b.min(c2 - c1);
        }
    }
    let cpu_s = (cpu_f.is_finite() && cpu_f > 0.0 && cpu_b > 0.0).then_some((cpu_f, cpu_b));
    VggTiming { size: (h, w), forward_s: fwd, backward_s: bwd, forward_flops: vgg.forward_flops(h, w), cpu_s }
}

#[cfg(test)]
#[path = "vgg_tests.rs"]
pub(crate) mod tests;
