//! VGG relu3 forward and input gradient on the GPU (`shaders/vgg.wgsl` around
//! the GEMM of `gpu/ops/gemm.rs`), repeating the CPU [`crate::vision::Vgg`].
//!
//! Convolutions are im2col + GEMM (bias and ReLU in the GEMM's epilogue); the
//! input gradient is the transposed GEMM + col2im, done as a gather so no
//! atomics are needed. The im2col matrix is built for a band of output rows at
//! a time, as on the CPU, so it stays under the device's storage-binding limit
//! (lavapipe's is 128 MiB) at any image size.
//!
//! Memory is allocated once per image size, never per step: a [`GpuVggWorkspace`]
//! holds the scratch (column matrix, two ping-pong planes) and every launch's
//! uniform; a [`GpuVggState`] per map holds what the backward pass reads (the
//! four stage-1/2 activations and the features, whose signs are the ReLU masks
//! and whose values decide the max-pool routing again, first maximum on ties
//! as torch and the CPU do). The three maps of a step (RGB, depth, edges) each
//! have a state and share one workspace.

use std::sync::OnceLock;

use super::Commands;
use super::gemm::{Gemm, GemmPlan, GemmSpec, Strided};
use super::kernel::Launch;
use super::{Bind, GpuContext, Kernel};
use crate::vision::Vgg;
use crate::vision::vgg::{FEATURE_CHANNELS, STAGE};

/// Threads per workgroup of the `vgg.wgsl` kernels.
const WORKGROUP: u32 = 256;
/// Largest im2col band, in f32 elements (32 MiB), as on the CPU.
const BAND_ELEMS: usize = 1 << 23;

/// The uniform block of `vgg.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct VggParams {
    c: u32,
    h: u32,
    w: u32,
    y0: u32,
    y1: u32,
    in_off: u32,
    out_off: u32,
    extra_off: u32,
    len: u32,
    flags: u32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<VggParams>() == 48);

/// A launch of `p.len` threads of one `vgg.wgsl` entry point.
fn launch(ctx: &GpuContext, label: &str, p: VggParams) -> Launch {
    Launch::new(ctx, label, &p, p.len as usize, WORKGROUP)
}

/// The entry points of `vgg.wgsl`.
#[derive(Debug)]
struct Kernels {
    normalize: Kernel,
    to_image: Kernel,
    im2col: Kernel,
    col2im: Kernel,
    pool: Kernel,
    pool_back: Kernel,
    relu_back: Kernel,
}

/// The network on the device: weights and biases of conv1_1 … conv3_3.
#[derive(Debug)]
pub struct GpuVgg {
    gemm: Gemm,
    k: Kernels,
    weights: Vec<wgpu::Buffer>,
    biases: Vec<wgpu::Buffer>,
    /// (c_out, c_in) per convolution.
    shapes: Vec<(usize, usize)>,
    dummy: wgpu::Buffer,
}

/// One band of output rows of one convolution.
#[derive(Debug)]
struct Band {
    im2col: Launch,
    forward: GemmPlan,
    backward: GemmPlan,
    col2im: Launch,
}

/// The launches of one convolution at one size.
#[derive(Debug)]
struct LayerPlan {
    bands: Vec<Band>,
    relu_back: Launch,
    /// Input planes (`c_in · h · w`), cleared before banded col2im.
    input_len: usize,
}

/// Scratch buffers and launch uniforms for one input size, shared by every
/// map of that size.
#[derive(Debug)]
pub struct GpuVggWorkspace {
    size: (usize, usize),
    cols: wgpu::Buffer,
    ping: wgpu::Buffer,
    pong: wgpu::Buffer,
    normalize: Launch,
    to_image: Launch,
    layers: Vec<LayerPlan>,
    pools: Vec<Launch>,
    pool_backs: Vec<Launch>,
}

/// What the backward pass of one map reads: the activations of conv1_1,
/// conv1_2, conv2_1, conv2_2, and the features (relu3_1 | relu3_2 | relu3_3).
#[derive(Debug)]
pub struct GpuVggState {
    size: (usize, usize),
    /// conv1_1, conv1_2, conv2_1 and conv2_2's outputs, made by the first
    /// pass that runs on this state: a step loss that runs VGG on the
    /// object's window never makes its whole-frame states' (three quarters
    /// of a state's bytes).
    acts: OnceLock<Vec<wgpu::Buffer>>,
    features: wgpu::Buffer,
}

impl GpuVggState {
    /// Buffers for one map of `h × w` pixels (the activations on first use).
    pub fn new(ctx: &GpuContext, h: usize, w: usize) -> Self {
        let n = stage_dims(h, w)[2];
        Self { size: (h, w), acts: OnceLock::new(), features: ctx.zeros("vgg.features", FEATURE_CHANNELS * n.0 * n.1) }
    }

    /// Whether a pass has run on this state (its activations are made).
    pub fn has_activations(&self) -> bool {
        self.acts.get().is_some()
    }

    /// The activations a pass writes and its backward reads, made on the first call.
    fn acts(&self, ctx: &GpuContext) -> &[wgpu::Buffer] {
        self.acts.get_or_init(|| {
            let dims = stage_dims(self.size.0, self.size.1);
            let n = |s: usize| dims[s].0 * dims[s].1;
            [(64, 0), (64, 0), (128, 1), (128, 1)].iter().map(|&(c, s)| ctx.zeros("vgg.act", c * n(s))).collect()
        })
    }

    /// The features of the last forward pass: 768 channels (relu3_1, relu3_2,
    /// relu3_3) at `h/4 × w/4`, CHW, as [`crate::style::step::FeatureMap`] lays them out.
    pub fn features(&self) -> &wgpu::Buffer {
        &self.features
    }

    /// Feature-map height and width, `(h/2)/2 × (w/2)/2` as torch floors.
    pub fn feature_size(&self) -> (usize, usize) {
        stage_dims(self.size.0, self.size.1)[2]
    }
}

/// Plane sizes of the three stages of an `h × w` input.
fn stage_dims(h: usize, w: usize) -> [(usize, usize); 3] {
    [(h, w), (h / 2, w / 2), (h / 4, w / 4)]
}

fn u32_of(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

impl GpuVgg {
    /// Uploads the convolutions of `vgg` and compiles the kernels.
    pub fn new(ctx: &GpuContext, vgg: &Vgg) -> Self {
        let src = include_str!("../../../../shaders/vgg.wgsl");
        use Bind::{Read, ReadWrite, Uniform};
        let binds = [Uniform, Read, Read, ReadWrite, Read];
        let kernel = |entry: &str| Kernel::new(ctx, &format!("vgg.{entry}"), src, entry, &binds);
        let convs = &vgg.weights().convs;
        Self {
            gemm: Gemm::new(ctx),
            k: Kernels {
                normalize: kernel("normalize"),
                to_image: kernel("to_image"),
                im2col: kernel("im2col"),
                col2im: kernel("col2im"),
                pool: kernel("pool"),
                pool_back: kernel("pool_back"),
                relu_back: kernel("relu_back"),
            },
            weights: convs.iter().map(|c| ctx.upload("vgg.weight", &c.weight)).collect(),
            biases: convs.iter().map(|c| ctx.upload("vgg.bias", &c.bias)).collect(),
            shapes: convs.iter().map(|c| (c.c_out, c.c_in)).collect(),
            dummy: ctx.zeros("vgg.dummy", 1),
        }
    }

    /// Scratch and launch uniforms for `h × w` inputs.
    pub fn workspace(&self, ctx: &GpuContext, h: usize, w: usize) -> GpuVggWorkspace {
        self.workspace_banded(ctx, h, w, BAND_ELEMS.min((ctx.max_binding_bytes() / 4) as usize))
    }

    /// [`GpuVgg::workspace`] with im2col bands of at most `band_elems` elements.
    fn workspace_banded(&self, ctx: &GpuContext, h: usize, w: usize, band_elems: usize) -> GpuVggWorkspace {
        let dims = stage_dims(h, w);
        let n3 = dims[2].0 * dims[2].1;
        let mut cols_len = 1;
        let mut layers = Vec::with_capacity(7);
        for (layer, &(c_out, c_in)) in self.shapes.iter().enumerate() {
            let (lh, lw) = dims[STAGE[layer]];
            let k = c_in * 9;
            let rows = (band_elems / (k * lw).max(1)).clamp(1, lh.max(1));
            let plane = lh * lw;
            // Layers 4..6 read and write the concatenated feature map.
            let in_off = if layer >= 5 { (layer - 5) * 256 * n3 } else { 0 };
            let out_off = if layer >= 4 { (layer - 4) * 256 * n3 } else { 0 };
            let several = lh > rows;
            let mut bands = Vec::new();
            let mut y0 = 0;
            while y0 < lh {
                let y1 = (y0 + rows).min(lh);
                let nb = (y1 - y0) * lw;
                cols_len = cols_len.max(k * nb);
                let p = |len: usize, flags: u32, in_off: usize| VggParams {
                    c: u32_of(c_in),
                    h: u32_of(lh),
                    w: u32_of(lw),
                    y0: u32_of(y0),
                    y1: u32_of(y1),
                    in_off: u32_of(in_off),
                    len: u32_of(len),
                    flags,
                    ..Default::default()
                };
                let touched = (y1 + 1).min(lh) - y0.saturating_sub(1);
                bands.push(Band {
                    im2col: launch(ctx, "vgg.im2col", p(k * nb, 0, in_off)),
                    forward: self.gemm.plan(
                        ctx,
                        &GemmSpec {
                            a: Strided::rows(0, k),
                            b: Strided::rows(0, nb),
                            c: Strided { offset: out_off + y0 * lw, row_stride: plane, col_stride: 1, batch_stride: 0 },
                            bias: Some(0),
                            relu: true,
                            ..GemmSpec::plain(c_out, nb, k)
                        },
                    ),
                    backward: self.gemm.plan(
                        ctx,
                        &GemmSpec {
                            a: Strided::transposed(0, k),
                            b: Strided { offset: y0 * lw, row_stride: plane, col_stride: 1, batch_stride: 0 },
                            ..GemmSpec::plain(k, nb, c_out)
                        },
                    ),
                    col2im: launch(ctx, "vgg.col2im", p(c_in * touched * lw, u32::from(several), 0)),
                });
                y0 = y1;
            }
            // relu_back: activation at out_off; the propagated gradient at
            // offset 0 of the ping-pong plane, except for relu3_3 whose
            // gradient is the caller's feature gradient itself; relu3_1 and
            // relu3_2 add their block of the feature gradient.
            let relu_back = VggParams {
                c: u32_of(out_off),
                in_off: u32_of(out_off),
                extra_off: if layer == 6 { u32_of(out_off) } else { 0 },
                len: u32_of(c_out * plane),
                flags: u32::from(layer == 4 || layer == 5),
                ..Default::default()
            };
            layers.push(LayerPlan {
                bands,
                relu_back: launch(ctx, "vgg.relu_back", relu_back),
                input_len: c_in * plane,
            });
        }
        let mut pools = Vec::new();
        let mut pool_backs = Vec::new();
        for (c, (ph, pw)) in [(64, dims[0]), (128, dims[1])] {
            let p = VggParams { c: u32_of(c), h: u32_of(ph), w: u32_of(pw), ..Default::default() };
            pools.push(launch(ctx, "vgg.pool", VggParams { len: u32_of(c * (ph / 2) * (pw / 2)), ..p }));
            pool_backs.push(launch(ctx, "vgg.pool_back", VggParams { len: u32_of(c * ph * pw), ..p }));
        }
        let image = VggParams { h: u32_of(h), w: u32_of(w), len: u32_of(h * w * 3), ..Default::default() };
        let plane_len = 64 * h * w;
        GpuVggWorkspace {
            size: (h, w),
            cols: ctx.zeros("vgg.cols", cols_len),
            ping: ctx.zeros("vgg.ping", plane_len),
            pong: ctx.zeros("vgg.pong", plane_len),
            normalize: launch(ctx, "vgg.normalize", image),
            to_image: launch(ctx, "vgg.to_image", image),
            layers,
            pools,
            pool_backs,
        }
    }

    /// Records an elementwise launch with bindings (src, aux, dst, extra).
    #[allow(clippy::too_many_arguments)]
    fn launch(
        &self,
        ctx: &GpuContext,
        enc: &mut dyn Commands,
        kernel: &Kernel,
        l: &Launch,
        src: &wgpu::Buffer,
        aux: Option<&wgpu::Buffer>,
        dst: &wgpu::Buffer,
        extra: Option<&wgpu::Buffer>,
    ) {
        let aux = aux.unwrap_or(&self.dummy);
        let extra = extra.unwrap_or(&self.dummy);
        kernel.dispatch(ctx, enc, &[&l.uniform, src, aux, dst, extra], l.groups);
    }

    /// Records the forward pass of `input` (HWC RGB, `h × w × 3`, values in
    /// [0, 1], ImageNet-normalised here as on the CPU) into `state`; the
    /// features are then in [`GpuVggState::features`].
    ///
    /// # Panics
    /// When the workspace or the state was made for another size (a caller bug).
    pub fn forward(
        &self,
        ctx: &GpuContext,
        enc: &mut dyn Commands,
        ws: &GpuVggWorkspace,
        input: &wgpu::Buffer,
        state: &GpuVggState,
    ) {
        assert_eq!(ws.size, state.size, "GpuVgg::forward: workspace and state sizes differ");
        let (h3, w3) = state.feature_size();
        if h3 == 0 || w3 == 0 {
            return;
        }
        let (k, acts) = (&self.k, state.acts(ctx));
        self.launch(ctx, enc, &k.normalize, &ws.normalize, input, None, &ws.ping, None);
        for (layer, plan) in ws.layers.iter().enumerate() {
            let src = match layer {
                0 | 2 | 4 => &ws.ping,
                1 | 3 => &acts[layer - 1],
                _ => &state.features,
            };
            let out = if layer < 4 { &acts[layer] } else { &state.features };
            for band in &plan.bands {
                self.launch(ctx, enc, &k.im2col, &band.im2col, src, None, &ws.cols, None);
                self.gemm.record(
                    ctx,
                    enc,
                    &band.forward,
                    &self.weights[layer],
                    &ws.cols,
                    Some(&self.biases[layer]),
                    out,
                );
            }
            if layer == 1 || layer == 3 {
                self.launch(ctx, enc, &k.pool, &ws.pools[layer / 2], out, None, &ws.ping, None);
            }
        }
    }

    /// Records the gradient w.r.t. the input image (HWC, `h × w × 3`, written
    /// to `v_input`) of a loss whose gradient w.r.t. the features of the
    /// forward pass saved in `state` is `v_features` (768 × h/4 × w/4, CHW).
    ///
    /// # Panics
    /// When the workspace or the state was made for another size (a caller bug).
    pub fn backward(
        &self,
        ctx: &GpuContext,
        enc: &mut dyn Commands,
        ws: &GpuVggWorkspace,
        state: &GpuVggState,
        v_features: &wgpu::Buffer,
        v_input: &wgpu::Buffer,
    ) {
        assert_eq!(ws.size, state.size, "GpuVgg::backward: workspace and state sizes differ");
        let (h3, w3) = state.feature_size();
        if h3 == 0 || w3 == 0 {
            let (h, w) = state.size;
            enc.encoder().clear_buffer(v_input, 0, Some((h * w * 3 * 4) as u64));
            return;
        }
        let (k, acts) = (&self.k, state.acts(ctx));
        // `cur` holds the gradient of the current layer's output; `tmp` the masked one.
        let (mut cur, mut tmp) = (&ws.ping, &ws.pong);
        for layer in (0..7).rev() {
            let plan = &ws.layers[layer];
            let act = if layer < 4 { &acts[layer] } else { &state.features };
            let (grad, extra) = match layer {
                6 => (v_features, None),
                4 | 5 => (cur, Some(v_features)),
                _ => (cur, None),
            };
            self.launch(ctx, enc, &k.relu_back, &plan.relu_back, act, Some(grad), tmp, extra);
            if plan.bands.len() > 1 {
                enc.encoder().clear_buffer(cur, 0, Some((plan.input_len * 4) as u64));
            }
            for band in &plan.bands {
                self.gemm.record(ctx, enc, &band.backward, &self.weights[layer], tmp, None, &ws.cols);
                self.launch(ctx, enc, &k.col2im, &band.col2im, &ws.cols, None, cur, None);
            }
            if layer == 4 || layer == 2 {
                // Through the pool in front of this stage, from its saved input.
                let p = layer / 2 - 1;
                let pooled_from = &acts[2 * p + 1];
                self.launch(ctx, enc, &k.pool_back, &ws.pool_backs[p], pooled_from, Some(cur), tmp, None);
                std::mem::swap(&mut cur, &mut tmp);
            }
        }
        self.launch(ctx, enc, &k.to_image, &ws.to_image, cur, None, v_input, None);
    }
}

/// Milliseconds of one forward and one backward pass at `h × w` (best of
/// `reps` after a warm-up), for `gast bench`.
pub fn bench_vgg(ctx: &GpuContext, vgg: &Vgg, h: usize, w: usize, reps: usize) -> Vec<(String, f64)> {
    let net = GpuVgg::new(ctx, vgg);
    let ws = net.workspace(ctx, h, w);
    let state = GpuVggState::new(ctx, h, w);
    let input: Vec<f32> = (0..h * w * 3).map(|i| 0.5 + 0.4 * ((i as f32) * 0.37).sin()).collect();
    let input = ctx.upload("bench.input", &input);
    let (h3, w3) = state.feature_size();
    let v: Vec<f32> = (0..FEATURE_CHANNELS * h3 * w3).map(|i| ((i as f32) * 0.11).cos()).collect();
    let v = ctx.upload("bench.v", &v);
    let v_input = ctx.zeros("bench.v_input", h * w * 3);
    let time = |backward: bool| -> Option<f64> {
        let t = std::time::Instant::now();
        let mut enc = ctx.encoder("bench vgg");
        if backward {
            net.backward(ctx, &mut enc, &ws, &state, &v, &v_input);
        } else {
            net.forward(ctx, &mut enc, &ws, &input, &state);
        }
        ctx.submit(enc);
        ctx.wait().ok()?;
        Some(t.elapsed().as_secs_f64() * 1e3)
    };
    let (mut fwd, mut bwd) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..reps.max(1) + 1 {
        match (time(false), time(true)) {
            (Some(f), Some(b)) => {
                fwd = fwd.min(f);
                bwd = bwd.min(b);
            }
            _ => return Vec::new(),
        }
    }
    vec![(format!("vgg forward {h}×{w} ms"), fwd), (format!("vgg backward {h}×{w} ms"), bwd)]
}

#[cfg(test)]
#[path = "vgg_tests.rs"]
mod tests;
