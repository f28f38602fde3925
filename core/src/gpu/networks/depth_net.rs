//! Depth Anything V2 on the GPU engine: the style depth network's forward
//! pass (`shaders/depth_net.wgsl` for the backbone, [`super::depth_dpt`] for
//! the neck and head), repeating the CPU [`DepthAnything`] layer for layer.
//!
//! The network runs once per style, but on the CPU that pass costs seconds
//! (≈100 GFLOP for the Small model at 518 px), so a session on the GPU engine
//! runs it here. Every linear layer and convolution is the engine's GEMM
//! ([`super::gemm`]): the patch embedding is a product with the 14×14 patches
//! as columns, attention is two batched GEMMs per group of heads around a
//! column softmax, the 3×3 convolutions are banded im2col + GEMM as in
//! [`super::vgg`]. Token states stay channel-major (`d × n`) as on the CPU,
//! so the folded weights of [`crate::vision::depth`] (query scale, layer
//! scales) are uploaded as they are. The position embeddings are interpolated
//! on the CPU for each input size, as there, and uploaded.
//!
//! Buffers are made for one forward and dropped after it: the pass runs once
//! per style and its scratch (≈300 MB at 518 px for the Small model) should
//! not stay on the device.
//!
//! [`super::depth_dpt`] (the neck and head) runs after the backbone: one
//! network split in two files by size, both recording through
//! [`super::depth_rec`]'s linear layers and recorder.

use super::depth_dpt::GpuDpt;
use super::depth_rec::{GpuLinear, Rec};
use super::gemm::{Gemm, GemmSpec, Strided};
use super::{Bind, GpuContext, GpuError, Kernel};
use crate::vision::depth::ops::Norm;
use crate::vision::depth::{DepthAnything, INPUT_SIZE, input_size};
use crate::vision::resize::{Unit, resize_bicubic};
use crate::vision::style_depth::DepthImage;

/// Largest attention-score block, in f32 elements (64 MiB), below lavapipe's
/// 128 MiB binding limit.
const SCORE_ELEMS: usize = 1 << 24;

/// The uniform block of `depth_net.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct NetParams {
    d: u32,
    n: u32,
    h: u32,
    w: u32,
    p: u32,
    cols: u32,
    len: u32,
    eps: f32,
}
const _: () = assert!(std::mem::size_of::<NetParams>() == 32);

/// A layer norm's scale then shift in one buffer, and its epsilon.
#[derive(Debug)]
struct GpuNorm {
    wb: wgpu::Buffer,
    eps: f32,
}

impl GpuNorm {
    fn new(ctx: &GpuContext, n: &Norm) -> Self {
        let wb: Vec<f32> = n.w.iter().chain(&n.b).copied().collect();
        Self { wb: ctx.upload("depth.norm", &wb), eps: n.eps }
    }
}

#[derive(Debug)]
struct GpuLayer {
    norm1: GpuNorm,
    qkv: GpuLinear,
    output: GpuLinear,
    norm2: GpuNorm,
    fc1: GpuLinear,
    fc2: GpuLinear,
}

#[derive(Debug)]
struct NetKernels {
    patchify: Kernel,
    layer_norm: Kernel,
    softmax: Kernel,
    gelu: Kernel,
}

/// The network on the device, with the CPU network it was uploaded from
/// (the reference, and the position embeddings' source for each input size).
pub struct GpuDepthNet {
    net: DepthAnything,
    gemm: Gemm,
    k: NetKernels,
    patch: GpuLinear,
    layers: Vec<GpuLayer>,
    final_norm: GpuNorm,
    dpt: GpuDpt,
    dummy: wgpu::Buffer,
    poison: bool,
    /// Largest attention-score block in f32s ([`SCORE_ELEMS`]; tests lower it).
    score_elems: usize,
}

fn u32_of(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

impl GpuDepthNet {
    /// Uploads `net`'s weights once and compiles the kernels.
    pub fn new(ctx: &GpuContext, net: DepthAnything) -> Self {
        let src = include_str!("../../../../shaders/depth_net.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite];
        let kernel = |entry: &str| Kernel::new(ctx, &format!("depth_net.{entry}"), src, entry, &binds);
        let (vit, dpt) = net.parts();
        let layers = vit
            .layers
            .iter()
            .map(|l| GpuLayer {
                norm1: GpuNorm::new(ctx, &l.norm1),
                qkv: GpuLinear::new(ctx, &l.qkv),
                output: GpuLinear::new(ctx, &l.output),
                norm2: GpuNorm::new(ctx, &l.norm2),
                fc1: GpuLinear::new(ctx, &l.fc1),
                fc2: GpuLinear::new(ctx, &l.fc2),
            })
            .collect();
        Self {
            gemm: Gemm::new(ctx),
            k: NetKernels {
                patchify: kernel("patchify"),
                layer_norm: kernel("layer_norm"),
                softmax: kernel("softmax_columns"),
                gelu: kernel("gelu"),
            },
            patch: GpuLinear::new(ctx, &vit.patch),
            layers,
            final_norm: GpuNorm::new(ctx, &vit.final_norm),
            dpt: GpuDpt::new(ctx, dpt),
            dummy: ctx.zeros("depth.dummy", 1),
            poison: false,
            score_elems: SCORE_ELEMS,
            net,
        }
    }

    /// The CPU network the weights came from.
    pub fn cpu(&self) -> &DepthAnything {
        &self.net
    }

    /// The network on a normalised CHW image (`3 × h × w`, sides multiples of
    /// the patch size): the predicted depth, `h × w`, as
    /// [`DepthAnything::forward`] computes it.
    ///
    /// # Panics
    /// When the sides are not multiples of the patch size or `pixels` is not
    /// `3 · h · w` long (a caller bug, as on the CPU).
    pub fn forward(&self, ctx: &GpuContext, pixels: &[f32], h: usize, w: usize) -> Result<Vec<f32>, GpuError> {
        let p = self.net.config().patch_size;
        assert!(
            h.is_multiple_of(p) && w.is_multiple_of(p) && pixels.len() == 3 * h * w,
            "GpuDepthNet::forward: bad input size"
        );
        let mut rec = Rec::new(ctx, "depth forward", &self.gemm, self.poison);
        let img = ctx.upload("depth.input", pixels);
        let stages = self.backbone(&mut rec, &img, h, w);
        let depth = self.dpt.record(&mut rec, &stages, (h / p, w / p));
        ctx.submit(rec.enc);
        let mut out: Vec<f32> = ctx.read(&depth)?;
        out.truncate(h * w);
        Ok(out)
    }

    /// [`DepthAnything::depth_image`] with the network on the GPU: the
    /// estimate of an RGB image (HWC, `f32` in [0, 1] or 8-bit, [`Unit`],
    /// `h × w`) at the network's input size, near = larger.
    pub fn depth_image<T: Unit>(
        &self,
        ctx: &GpuContext,
        rgb: &[T],
        h: usize,
        w: usize,
    ) -> Result<DepthImage, GpuError> {
        let (ih, iw) = input_size(h, w, INPUT_SIZE, self.net.config().patch_size);
        let values = self.forward(ctx, &self.net.preprocess(rgb, h, w, ih, iw), ih, iw)?;
        Ok(DepthImage { values, height: ih, width: iw, near_is_larger: true })
    }

    /// Relative inverse depth of an RGB image at its own size, as
    /// [`DepthAnything::estimate_rgb`] (the resize back on the CPU).
    pub fn estimate_rgb<T: Unit>(&self, ctx: &GpuContext, rgb: &[T], h: usize, w: usize) -> Result<Vec<f32>, GpuError> {
        let d = self.depth_image(ctx, rgb, h, w)?;
        Ok(resize_bicubic(&d.values, d.height, d.width, 1, h, w))
    }

    /// Records the backbone on `img` (`3 × h × w`); returns the stages the
    /// neck reads, each `d × (1 + rows·cols)`.
    fn backbone(&self, rec: &mut Rec, img: &wgpu::Buffer, h: usize, w: usize) -> Vec<wgpu::Buffer> {
        let (vit, _) = self.net.parts();
        let p = vit.patch_size;
        let (rows, cols) = (h / p, w / p);
        let (np, d) = (rows * cols, vit.width());
        let n = np + 1;
        let k = 3 * p * p;
        let base = NetParams { d: u32_of(d), n: u32_of(n), ..Default::default() };
        let patches = rec.scratch("depth.patches", k * np);
        let pp = NetParams {
            n: u32_of(np),
            h: u32_of(h),
            w: u32_of(w),
            p: u32_of(p),
            cols: u32_of(cols),
            len: u32_of(k * np),
            ..base
        };
        rec.launch(&self.k.patchify, &pp, k * np, (img, &self.dummy, &patches));
        // The stream starts as the position embeddings (channel-major, the
        // CLS column holding cls + pos₀); the patch embedding adds onto columns 1…
        let pos = vit.position_embeddings(rows, cols);
        let mut start = vec![0f32; d * n];
        for c in 0..d {
            start[c * n] = vit.cls[c] + pos[c];
            for t in 1..n {
                start[c * n + t] = pos[t * d + c];
            }
        }
        let x = rec.ctx.upload("depth.x", &start);
        rec.linear(&self.patch, &patches, (0, np), np, &x, (1, n), true);

        let hbuf = rec.scratch("depth.h", d * n);
        let mlp = self.layers.first().map_or(0, |l| l.fc1.out);
        let qkv = rec.scratch("depth.qkv", 3 * d * n);
        let attn = rec.scratch("depth.attn", d * n);
        let m = rec.scratch("depth.mlp", mlp * n);
        let mut stages = Vec::with_capacity(vit.out_indices.len());
        let keep = |i: usize, rec: &mut Rec, stages: &mut Vec<wgpu::Buffer>| {
            if vit.out_indices.contains(&i) {
                let s = rec.scratch("depth.stage", d * n);
                if vit.apply_layernorm {
                    self.norm(rec, &self.final_norm, &x, &s, base);
                } else {
                    rec.enc.copy_buffer_to_buffer(&x, 0, &s, 0, (d * n * 4) as u64);
                }
                stages.push(s);
            }
        };
        keep(0, rec, &mut stages);
        for (i, l) in self.layers.iter().enumerate() {
            self.norm(rec, &l.norm1, &x, &hbuf, base);
            rec.linear(&l.qkv, &hbuf, (0, n), n, &qkv, (0, n), false);
            self.attention(rec, &qkv, &attn, d, n, vit.heads);
            rec.linear(&l.output, &attn, (0, n), n, &x, (0, n), true);
            self.norm(rec, &l.norm2, &x, &hbuf, base);
            rec.linear(&l.fc1, &hbuf, (0, n), n, &m, (0, n), false);
            let gp = NetParams { len: u32_of(mlp * n), ..base };
            rec.launch(&self.k.gelu, &gp, mlp * n, (&self.dummy, &self.dummy, &m));
            rec.linear(&l.fc2, &m, (0, n), n, &x, (0, n), true);
            keep(i + 1, rec, &mut stages);
        }
        stages
    }

    fn norm(&self, rec: &mut Rec, norm: &GpuNorm, x: &wgpu::Buffer, y: &wgpu::Buffer, base: NetParams) {
        let p = NetParams { len: base.n, eps: norm.eps, ..base };
        rec.launch(&self.k.layer_norm, &p, base.n as usize, (x, &norm.wb, y));
    }

    /// Multi-head self-attention of the `3d × n` query/key/value stack into
    /// `out` (`d × n`); the query rows already carry `1/√d_head`. Scores are
    /// keys × queries per head, computed for a group of heads and a block of
    /// queries at a time so one block stays under [`SCORE_ELEMS`].
    fn attention(&self, rec: &mut Rec, qkv: &wgpu::Buffer, out: &wgpu::Buffer, d: usize, n: usize, heads: usize) {
        let dh = d / heads;
        let budget = self.score_elems.min((rec.ctx.max_binding_bytes() / 4) as usize);
        let (group, qb) =
            if n * n <= budget { ((budget / (n * n)).clamp(1, heads), n) } else { (1, (budget / n).clamp(1, n)) };
        let scores = rec.scratch("depth.scores", group * n * qb);
        let (q_off, k_off, v_off) = (0, d * n, 2 * d * n);
        let mut h0 = 0;
        while h0 < heads {
            let hb = group.min(heads - h0);
            let mut q0 = 0;
            while q0 < n {
                let bq = qb.min(n - q0);
                let head = h0 * dh * n;
                // S = Kᵀ Q: keys × queries, one block per head.
                let s = GemmSpec {
                    batch: hb,
                    a: Strided::transposed(k_off + head, n).batched(dh * n),
                    b: Strided::rows(q_off + head + q0, n).batched(dh * n),
                    c: Strided::rows(0, bq).batched(n * bq),
                    ..GemmSpec::plain(n, bq, dh)
                };
                rec.gemm(&s, qkv, qkv, None, &scores);
                let sp = NetParams { d: u32_of(n), n: u32_of(bq), len: u32_of(hb * bq), ..Default::default() };
                rec.launch(&self.k.softmax, &sp, hb * bq, (&self.dummy, &self.dummy, &scores));
                // O = V S: d_head × queries, into the head's rows of `out`.
                let o = GemmSpec {
                    batch: hb,
                    a: Strided::rows(v_off + head, n).batched(dh * n),
                    b: Strided::rows(0, bq).batched(n * bq),
                    c: Strided::rows(head + q0, n).batched(dh * n),
                    ..GemmSpec::plain(dh, bq, n)
                };
                rec.gemm(&o, qkv, &scores, None, out);
                q0 += bq;
            }
            h0 += hb;
        }
    }
}

#[cfg(test)]
impl GpuDepthNet {
    /// Fills every scratch buffer of later forwards with NaN.
    pub(super) fn poison_scratch(&mut self) {
        self.poison = true;
    }

    /// Limits attention-score blocks to `elems` f32s, to exercise the blocking.
    pub(super) fn limit_score_block(&mut self, elems: usize) {
        self.score_elems = elems;
    }
}

#[cfg(test)]
#[path = "depth_net_tests.rs"]
mod tests;
