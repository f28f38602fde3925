//! The DPT neck and relative-depth head of Depth Anything V2 on the GPU
//! (`shaders/depth_dpt.wgsl` around the GEMM), the twin of
//! [`crate::vision::depth`]'s `dpt.rs`, launched by [`super::depth_net`].
//!
//! Convolutions are im2col + GEMM in bands of output rows, as in
//! [`super::vgg`], so the head's 3×3 convolutions at the input resolution
//! (≈300 MB of columns at 518 px) stay under the device's binding limit.
//! Biases and the ReLU after a convolution go into the GEMM's epilogue, the
//! ReLU before one into im2col, and a residual unit's sum into the GEMM's
//! accumulate flag. The bilinear resizes use the taps the CPU computes, so
//! their weights are the CPU's to the bit.

use super::depth_rec::{GpuLinear, Rec};
use super::gemm::{GemmSpec, Strided};
use super::{Bind, GpuContext, Kernel};
use crate::vision::depth::dpt::{Dpt, Resize};
use crate::vision::depth::ops::{Conv, ConvUp};
use crate::vision::resize::{aligned_linear_taps, bilinear_taps};

/// Largest im2col band, in f32 elements (32 MiB), as VGG's.
const BAND_ELEMS: usize = 1 << 23;

/// The uniform block of `depth_dpt.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct DptParams {
    c: u32,
    h: u32,
    w: u32,
    k: u32,
    stride: u32,
    pad: u32,
    oh: u32,
    ow: u32,
    y0: u32,
    nb: u32,
    len: u32,
    flags: u32,
    scale: f32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<DptParams>() == 64);

/// A convolution on the device.
#[derive(Debug)]
struct GpuConv {
    w: wgpu::Buffer,
    b: wgpu::Buffer,
    c_out: usize,
    c_in: usize,
    k: usize,
    stride: usize,
    pad: usize,
}

impl GpuConv {
    fn new(ctx: &GpuContext, c: &Conv) -> Self {
        Self {
            w: ctx.upload("depth.conv.w", &c.w),
            b: ctx.upload("depth.conv.b", &c.b),
            c_out: c.c_out(),
            c_in: c.c_in,
            k: c.k,
            stride: c.stride,
            pad: c.pad,
        }
    }

    fn out_size(&self, h: usize, w: usize) -> (usize, usize) {
        ((h + 2 * self.pad - self.k) / self.stride + 1, (w + 2 * self.pad - self.k) / self.stride + 1)
    }
}

/// The transposed convolution with kernel = stride `f`: `c_in × c_out·f·f` weights.
#[derive(Debug)]
struct GpuConvUp {
    w: wgpu::Buffer,
    b: wgpu::Buffer,
    c_out: usize,
    c_in: usize,
    f: usize,
}

#[derive(Debug)]
enum GpuResize {
    Up(GpuConvUp),
    Same,
    Down(GpuConv),
}

#[derive(Debug)]
struct Residual {
    conv1: GpuConv,
    conv2: GpuConv,
}

#[derive(Debug)]
struct Fusion {
    residual1: Residual,
    residual2: Residual,
    projection: GpuLinear,
}

#[derive(Debug)]
struct DptKernels {
    im2col: Kernel,
    conv_up: Kernel,
    resize: Kernel,
    add: Kernel,
    head_out: Kernel,
}

/// The neck's and head's weights on the device.
#[derive(Debug)]
pub(super) struct GpuDpt {
    k: DptKernels,
    reassemble: Vec<(GpuLinear, GpuResize)>,
    convs: Vec<GpuConv>,
    fusion: Vec<Fusion>,
    head1: GpuConv,
    head2: GpuConv,
    head3: GpuLinear,
    patch_size: usize,
    metric: bool,
    scale: f32,
    dummy: wgpu::Buffer,
}

fn u32_of(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

/// A `c × h × w` map in a buffer.
struct Map {
    buf: wgpu::Buffer,
    c: usize,
    h: usize,
    w: usize,
}

impl GpuDpt {
    /// Uploads the neck and head of `dpt` and compiles `depth_dpt.wgsl`.
    pub fn new(ctx: &GpuContext, dpt: &Dpt) -> Self {
        let src = include_str!("../../../../shaders/depth_dpt.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite];
        let kernel = |entry: &str| Kernel::new(ctx, &format!("depth_dpt.{entry}"), src, entry, &binds);
        let up = |u: &ConvUp| GpuConvUp {
            w: ctx.upload("depth.up.w", &u.w),
            b: ctx.upload("depth.up.b", &u.b),
            c_out: u.b.len(),
            c_in: u.c_in,
            f: u.f,
        };
        let residual = |r: &crate::vision::depth::dpt::Residual| Residual {
            conv1: GpuConv::new(ctx, &r.conv1),
            conv2: GpuConv::new(ctx, &r.conv2),
        };
        Self {
            k: DptKernels {
                im2col: kernel("im2col"),
                conv_up: kernel("conv_up"),
                resize: kernel("resize"),
                add: kernel("add"),
                head_out: kernel("head_out"),
            },
            reassemble: dpt
                .reassemble
                .iter()
                .map(|r| {
                    let resize = match &r.resize {
                        Resize::Up(u) => GpuResize::Up(up(u)),
                        Resize::Same => GpuResize::Same,
                        Resize::Down(c) => GpuResize::Down(GpuConv::new(ctx, c)),
                    };
                    (GpuLinear::new(ctx, &r.projection), resize)
                })
                .collect(),
            convs: dpt.convs.iter().map(|c| GpuConv::new(ctx, c)).collect(),
            fusion: dpt
                .fusion
                .iter()
                .map(|f| Fusion {
                    residual1: residual(&f.residual1),
                    residual2: residual(&f.residual2),
                    projection: GpuLinear::new(ctx, &f.projection),
                })
                .collect(),
            head1: GpuConv::new(ctx, &dpt.head1),
            head2: GpuConv::new(ctx, &dpt.head2),
            head3: GpuLinear::new(ctx, &dpt.head3),
            patch_size: dpt.patch_size,
            metric: dpt.metric,
            scale: dpt.scale,
            dummy: ctx.zeros("depth.dummy", 1),
        }
    }

    /// Records the neck and head on the backbone `stages` (each
    /// `d × (1 + rows·cols)`, CLS first); returns the buffer that will hold
    /// the depth, `rows·patch × cols·patch`.
    pub fn record(&self, rec: &mut Rec, stages: &[wgpu::Buffer], (rows, cols): (usize, usize)) -> wgpu::Buffer {
        let (np, n) = (rows * cols, rows * cols + 1);
        let mut maps = Vec::with_capacity(stages.len());
        for ((tokens, (proj, resize)), conv) in stages.iter().zip(&self.reassemble).zip(&self.convs) {
            let c = proj.out;
            let x = rec.scratch("depth.reassemble", c * np);
            // The patch tokens are columns 1… of the stage: no copy.
            rec.linear(proj, tokens, (1, n), np, &x, (0, np), false);
            let x = Map { buf: x, c, h: rows, w: cols };
            let x = match resize {
                GpuResize::Up(up) => self.conv_up(rec, up, &x),
                GpuResize::Same => x,
                GpuResize::Down(down) => self.conv(rec, down, &x, (false, false), None),
            };
            maps.push(self.conv(rec, conv, &x, (false, false), None));
        }
        // Fusion, coarsest first.
        let mut fused: Option<Map> = None;
        for (idx, layer) in self.fusion.iter().enumerate() {
            let map = &maps[maps.len() - 1 - idx];
            let x = match fused.take() {
                None => {
                    let x = rec.scratch("depth.fused", map.c * map.h * map.w);
                    rec.enc.copy_buffer_to_buffer(&map.buf, 0, &x, 0, (map.c * map.h * map.w * 4) as u64);
                    Map { buf: x, c: map.c, h: map.h, w: map.w }
                }
                Some(x) => {
                    let resized;
                    let r = if (x.h, x.w) == (map.h, map.w) {
                        map
                    } else {
                        resized = self.resize(rec, map, (x.h, x.w), false);
                        &resized
                    };
                    let len = r.c * r.h * r.w;
                    let p = DptParams { len: u32_of(len), ..Default::default() };
                    rec.launch(&self.k.add, &p, len, (&r.buf, &self.dummy, &x.buf));
                    self.residual(rec, &layer.residual1, r, &x);
                    x
                }
            };
            self.residual(rec, &layer.residual2, &x, &x);
            let (oh, ow) = if idx + 1 < maps.len() {
                let next = &maps[maps.len() - 2 - idx];
                (next.h, next.w)
            } else {
                (2 * x.h, 2 * x.w)
            };
            let up = self.resize(rec, &x, (oh, ow), true);
            let f = layer.projection.out;
            let y = rec.scratch("depth.fused", f * oh * ow);
            rec.linear(&layer.projection, &up.buf, (0, oh * ow), oh * ow, &y, (0, oh * ow), false);
            fused = Some(Map { buf: y, c: f, h: oh, w: ow });
        }
        let Some(x) = fused else { return rec.scratch("depth.out", rows * cols) };
        // Head.
        let y = self.conv(rec, &self.head1, &x, (false, false), None);
        let (oh, ow) = (rows * self.patch_size, cols * self.patch_size);
        let y = self.resize(rec, &y, (oh, ow), true);
        let y = self.conv(rec, &self.head2, &y, (false, true), None);
        let depth = rec.scratch("depth.out", oh * ow);
        rec.linear(&self.head3, &y.buf, (0, oh * ow), oh * ow, &depth, (0, oh * ow), false);
        let p =
            DptParams { len: u32_of(oh * ow), flags: u32::from(self.metric), scale: self.scale, ..Default::default() };
        rec.launch(&self.k.head_out, &p, oh * ow, (&self.dummy, &self.dummy, &depth));
        depth
    }

    /// `out += x + conv2(relu(conv1(relu(x))))` minus the `x` (the caller
    /// adds it, or `out` is `x`): the pre-activation residual unit.
    fn residual(&self, rec: &mut Rec, r: &Residual, x: &Map, out: &Map) {
        let t = self.conv(rec, &r.conv1, x, (true, true), None);
        self.conv(rec, &r.conv2, &t, (false, false), Some(out));
    }

    /// A convolution of `x` with ReLU on its input and/or output
    /// (`relu = (input, output)`), into a new map, or added onto `onto`.
    fn conv(&self, rec: &mut Rec, conv: &GpuConv, x: &Map, relu: (bool, bool), onto: Option<&Map>) -> Map {
        let (oh, ow) = conv.out_size(x.h, x.w);
        let kk = conv.c_in * conv.k * conv.k;
        let budget = BAND_ELEMS.min((rec.ctx.max_binding_bytes() / 4) as usize);
        let band = (budget / (kk * ow).max(1)).clamp(1, oh.max(1));
        let cols = rec.cols(kk * band * ow);
        let out = match onto {
            Some(m) => Map { buf: m.buf.clone(), c: m.c, h: m.h, w: m.w },
            None => Map { buf: rec.scratch("depth.conv", conv.c_out * oh * ow), c: conv.c_out, h: oh, w: ow },
        };
        let mut y0 = 0;
        while y0 < oh {
            let y1 = (y0 + band).min(oh);
            let nb = (y1 - y0) * ow;
            let p = DptParams {
                c: u32_of(conv.c_in),
                h: u32_of(x.h),
                w: u32_of(x.w),
                k: u32_of(conv.k),
                stride: u32_of(conv.stride),
                pad: u32_of(conv.pad),
                oh: u32_of(oh),
                ow: u32_of(ow),
                y0: u32_of(y0),
                nb: u32_of(nb),
                len: u32_of(kk * nb),
                flags: u32::from(relu.0),
                ..Default::default()
            };
            rec.launch(&self.k.im2col, &p, kk * nb, (&x.buf, &self.dummy, &cols));
            let spec = GemmSpec {
                a: Strided::rows(0, kk),
                b: Strided::rows(0, nb),
                c: Strided { offset: y0 * ow, row_stride: oh * ow, col_stride: 1, batch_stride: 0 },
                bias: Some(0),
                relu: relu.1,
                accumulate: onto.is_some(),
                ..GemmSpec::plain(conv.c_out, nb, kk)
            };
            rec.gemm(&spec, &conv.w, &cols, Some(&conv.b), &out.buf);
            y0 = y1;
        }
        out
    }

    /// The transposed convolution: the product `Wᵀ x` (`c_out·f·f × h·w`),
    /// then each input pixel painted into its `f × f` block with the bias.
    fn conv_up(&self, rec: &mut Rec, up: &GpuConvUp, x: &Map) -> Map {
        let (hw, m) = (x.h * x.w, up.c_out * up.f * up.f);
        let t = rec.scratch("depth.up", m * hw);
        let spec = GemmSpec { a: Strided::transposed(0, m), ..GemmSpec::plain(m, hw, up.c_in) };
        rec.gemm(&spec, &up.w, &x.buf, None, &t);
        let (oh, ow) = (x.h * up.f, x.w * up.f);
        let y = rec.scratch("depth.upsampled", up.c_out * oh * ow);
        let len = up.c_out * oh * ow;
        let p = DptParams { h: u32_of(x.h), w: u32_of(x.w), k: u32_of(up.f), len: u32_of(len), ..Default::default() };
        rec.launch(&self.k.conv_up, &p, len, (&t, &up.b, &y));
        Map { buf: y, c: up.c_out, h: oh, w: ow }
    }

    /// Bilinear resize of every plane of `x` to `oh × ow`: with aligned
    /// corners (fusion and head upsampling) or half-pixel centres (a map
    /// brought to the fused size), the CPU's taps uploaded.
    fn resize(&self, rec: &mut Rec, x: &Map, (oh, ow): (usize, usize), align_corners: bool) -> Map {
        let taps = |src: usize, dst: usize| -> Vec<[f32; 4]> {
            if align_corners {
                aligned_linear_taps(src, dst)
                    .iter()
                    .map(|t| {
                        let (i0, w0) = t.first().copied().unwrap_or((0, 0.0));
                        let (i1, w1) = t.get(1).copied().unwrap_or((i0, 0.0));
                        [i0 as f32, i1 as f32, w0, w1]
                    })
                    .collect()
            } else {
                bilinear_taps(src, dst, src as f64 / dst as f64)
                    .iter()
                    .map(|&(i0, i1, w0, w1)| [i0 as f32, i1 as f32, w0, w1])
                    .collect()
            }
        };
        let mut table = taps(x.h, oh);
        table.extend(taps(x.w, ow));
        let table = rec.ctx.upload("depth.taps", &table);
        let len = x.c * oh * ow;
        let y = rec.scratch("depth.resized", len);
        let p = DptParams {
            h: u32_of(x.h),
            w: u32_of(x.w),
            oh: u32_of(oh),
            ow: u32_of(ow),
            len: u32_of(len),
            ..Default::default()
        };
        rec.launch(&self.k.resize, &p, len, (&x.buf, &table, &y));
        Map { buf: y, c: x.c, h: oh, w: ow }
    }
}
