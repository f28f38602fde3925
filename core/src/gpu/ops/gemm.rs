//! A tiled f32 matrix product on the GPU (`shaders/gemm.wgsl`), the one kernel
//! that VGG's convolutions (forward as im2col · W, input gradient as Wᵀ · v),
//! and the GCFM search (rendered · style scores) all run on.
//!
//! Matrices are described by an offset and two strides into a flat buffer, so
//! one kernel covers A·B, Aᵀ·B and A·Bᵀ, sub-blocks of larger buffers and
//! batches (workgroup z). The epilogue can add the old C, a per-row bias and a
//! ReLU, which saves the convolutions a pass over their output. The CPU twin
//! is `vision::conv::matmul`.
//!
//! Two tilings of the same kernel: `gemm` computes a 64×64 block of C per
//! workgroup, `gemm_wide` a 128×128 one with four times the outputs per
//! thread and half the workgroup-memory reads per multiply-add. Both read
//! workgroup memory in 16-byte vectors (a thread's outputs are runs of four
//! consecutive rows and columns) and load the next slice of `k` from global
//! memory before multiplying the current one. Both sum every output over
//! `k` in the same order, so their results are the same bits. [`Gemm::plan`] takes the wide one for products whose wide grid still
//! has [`WIDE_MIN_GROUPS`] workgroups (the GCFM search's scores, VGG's
//! input gradients), the narrow one otherwise; on a software adapter
//! (lavapipe, where the wide tiling ran twice as fast at the three shapes
//! `gast bench step` times) every product of a wide block or more.
//! `GAST_GEMM_TILE=64` or `128` forces one (the device check times both on
//! the same build).
//!
//! A call's sizes and strides live in a uniform made once by [`Gemm::plan`]
//! (a workspace allocates its plans with its buffers): uniforms written with
//! `queue.write_buffer` land before the whole encoder runs, so a uniform
//! cannot be rewritten between two dispatches of one step.

use super::Commands;
use super::{Bind, GpuContext, Kernel};

/// The uniform block of `gemm.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct GemmParams {
    m: u32,
    n: u32,
    k: u32,
    a_off: u32,
    a_rs: u32,
    a_cs: u32,
    b_off: u32,
    b_rs: u32,
    b_cs: u32,
    c_off: u32,
    c_rs: u32,
    bias_off: u32,
    a_bs: u32,
    b_bs: u32,
    c_bs: u32,
    flags: u32,
    alpha: f32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<GemmParams>() == 80);

/// Rows and columns of C computed by one workgroup of `gemm`.
const TILE: u32 = 64;
/// Rows and columns of C computed by one workgroup of `gemm_wide`.
const WIDE_TILE: u32 = 128;
/// The fewest workgroups a wide grid may have for [`Gemm::plan`] to choose
/// it: twice the streaming multiprocessors of an H100/H200 (132), so that
/// each holds at least two blocks. (A guess to be checked on the device:
/// `tools/gpu-check` times both tilings at the step's shapes.)
pub const WIDE_MIN_GROUPS: usize = 264;

/// Which tiling [`Gemm::plan`] uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GemmTile {
    /// The wide tiling for products large enough ([`WIDE_MIN_GROUPS`]), else the narrow one.
    #[default]
    Auto,
    /// Always 64×64 blocks.
    Narrow,
    /// Always 128×128 blocks.
    Wide,
}

impl GemmTile {
    /// `GAST_GEMM_TILE`: `64`, `128` or anything else (unset) for [`GemmTile::Auto`].
    pub fn from_env() -> Self {
        match std::env::var("GAST_GEMM_TILE").as_deref() {
            Ok("64") => Self::Narrow,
            Ok("128") => Self::Wide,
            _ => Self::Auto,
        }
    }

    /// Whether a product of `spec`'s sizes runs wide; on a `software`
    /// adapter (lavapipe: a few CPU threads, no grid to fill) every product
    /// of at least one wide block each way does.
    fn wide(self, spec: &GemmSpec, software: bool) -> bool {
        match self {
            Self::Narrow => false,
            Self::Wide => true,
            Self::Auto => {
                let tile = WIDE_TILE as usize;
                spec.m >= tile
                    && spec.n >= tile
                    && (software || spec.m.div_ceil(tile) * spec.n.div_ceil(tile) * spec.batch >= WIDE_MIN_GROUPS)
            }
        }
    }
}

/// Workgroups along one dispatch dimension (WebGPU's limit).
const MAX_GROUPS: usize = 65_535;

/// Where a matrix lives in its buffer: element (row, col) of batch `z` at
/// `offset + z·batch_stride + row·row_stride + col·col_stride` (in `f32`s).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Strided {
    /// First element.
    pub offset: usize,
    /// Distance between rows.
    pub row_stride: usize,
    /// Distance between columns (ignored for C, whose columns are contiguous).
    pub col_stride: usize,
    /// Distance between batches.
    pub batch_stride: usize,
}

impl Strided {
    /// A row-major `rows × cols` matrix at `offset` (row stride `cols`).
    pub fn rows(offset: usize, cols: usize) -> Self {
        Self { offset, row_stride: cols, col_stride: 1, batch_stride: 0 }
    }

    /// The transpose of a row-major matrix with `cols` columns stored at `offset`.
    pub fn transposed(offset: usize, cols: usize) -> Self {
        Self { offset, row_stride: 1, col_stride: cols, batch_stride: 0 }
    }

    /// The same matrix with a batch stride.
    pub fn batched(self, batch_stride: usize) -> Self {
        Self { batch_stride, ..self }
    }
}

/// One matrix product `C = act(alpha · A·B [+ C] [+ bias])`, A `m × k`, B `k × n`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GemmSpec {
    /// Rows of A and C.
    pub m: usize,
    /// Columns of B and C.
    pub n: usize,
    /// Columns of A, rows of B.
    pub k: usize,
    /// Independent products along the batch strides.
    pub batch: usize,
    /// Layout of A.
    pub a: Strided,
    /// Layout of B.
    pub b: Strided,
    /// Layout of C (`col_stride` ignored: columns are contiguous).
    pub c: Strided,
    /// Scale of the product.
    pub alpha: f32,
    /// Add the product to C's old values instead of overwriting them.
    pub accumulate: bool,
    /// Add `bias[offset + row]` (the bias buffer passed to [`Gemm::record`]).
    pub bias: Option<usize>,
    /// Clamp the result at 0.
    pub relu: bool,
}

impl GemmSpec {
    /// `C (m × n) = A (m × k) · B (k × n)`, all row-major and packed from offset 0.
    pub fn plain(m: usize, n: usize, k: usize) -> Self {
        Self {
            m,
            n,
            k,
            batch: 1,
            a: Strided::rows(0, k),
            b: Strided::rows(0, n),
            c: Strided::rows(0, n),
            alpha: 1.0,
            accumulate: false,
            bias: None,
            relu: false,
        }
    }
}

/// A planned call: its uniform (made once) and its workgroup counts.
#[derive(Debug)]
pub struct GemmPlan {
    uniform: wgpu::Buffer,
    groups: [u32; 3],
    uses_bias: bool,
    wide: bool,
}

impl GemmPlan {
    /// Whether the call runs the 128×128 tiling.
    pub fn is_wide(&self) -> bool {
        self.wide
    }
}

/// The compiled kernels and a placeholder for calls without bias.
#[derive(Debug)]
pub struct Gemm {
    kernel: Kernel,
    wide: Kernel,
    tile: GemmTile,
    /// Whether the adapter is a software rasterizer ([`GemmTile::wide`]).
    software: bool,
    no_bias: wgpu::Buffer,
}

fn u32_of(v: usize, what: &str) -> u32 {
    u32::try_from(v).unwrap_or_else(|_| panic!("gemm: {what} {v} exceeds u32 (a caller bug: chunk the work)"))
}

impl Gemm {
    /// Compiles `gemm.wgsl`'s two tilings, choosing between them as
    /// `GAST_GEMM_TILE` says ([`GemmTile::from_env`]).
    pub fn new(ctx: &GpuContext) -> Self {
        Self::with_tile(ctx, GemmTile::from_env())
    }

    /// [`Gemm::new`] with the tiling policy given.
    pub fn with_tile(ctx: &GpuContext, tile: GemmTile) -> Self {
        let src = include_str!("../../../../shaders/gemm.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::Read, Bind::ReadWrite];
        Self {
            kernel: Kernel::new(ctx, "gemm", src, "gemm", &binds),
            wide: Kernel::new(ctx, "gemm_wide", src, "gemm_wide", &binds),
            tile,
            software: ctx.is_software(),
            no_bias: ctx.zeros("gemm.no_bias", 1),
        }
    }

    /// Makes the uniform of one call.
    ///
    /// # Panics
    /// When a size or offset exceeds `u32` or the grid exceeds 65,535
    /// workgroups along one side (callers chunk far below both).
    pub fn plan(&self, ctx: &GpuContext, spec: &GemmSpec) -> GemmPlan {
        let flags = u32::from(spec.accumulate) | (u32::from(spec.bias.is_some()) << 1) | (u32::from(spec.relu) << 2);
        let p = GemmParams {
            m: u32_of(spec.m, "m"),
            n: u32_of(spec.n, "n"),
            k: u32_of(spec.k, "k"),
            a_off: u32_of(spec.a.offset, "A offset"),
            a_rs: u32_of(spec.a.row_stride, "A row stride"),
            a_cs: u32_of(spec.a.col_stride, "A column stride"),
            b_off: u32_of(spec.b.offset, "B offset"),
            b_rs: u32_of(spec.b.row_stride, "B row stride"),
            b_cs: u32_of(spec.b.col_stride, "B column stride"),
            c_off: u32_of(spec.c.offset, "C offset"),
            c_rs: u32_of(spec.c.row_stride, "C row stride"),
            bias_off: u32_of(spec.bias.unwrap_or(0), "bias offset"),
            a_bs: u32_of(spec.a.batch_stride, "A batch stride"),
            b_bs: u32_of(spec.b.batch_stride, "B batch stride"),
            c_bs: u32_of(spec.c.batch_stride, "C batch stride"),
            flags,
            alpha: spec.alpha,
            _pad: [0; 3],
        };
        let wide = self.tile.wide(spec, self.software);
        let tile = if wide { WIDE_TILE } else { TILE } as usize;
        let (gx, gy) = (spec.n.div_ceil(tile), spec.m.div_ceil(tile));
        assert!(gx <= MAX_GROUPS && gy <= MAX_GROUPS && spec.batch <= MAX_GROUPS, "gemm: grid too large: {spec:?}");
        GemmPlan {
            uniform: ctx.uniform("gemm.params", &p),
            groups: [gx as u32, gy as u32, spec.batch as u32],
            uses_bias: spec.bias.is_some(),
            wide,
        }
    }

    /// Records the planned product into `encoder`. `c` must be a different
    /// buffer from `a` and `b`; `bias` is needed when the plan has one.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        plan: &GemmPlan,
        a: &wgpu::Buffer,
        b: &wgpu::Buffer,
        bias: Option<&wgpu::Buffer>,
        c: &wgpu::Buffer,
    ) {
        debug_assert!(!plan.uses_bias || bias.is_some(), "gemm: the plan adds a bias but none was given");
        let bias = bias.unwrap_or(&self.no_bias);
        let kernel = if plan.wide { &self.wide } else { &self.kernel };
        kernel.dispatch(ctx, encoder, &[&plan.uniform, a, b, bias, c], plan.groups);
    }
}

/// Milliseconds per `m × n × k` product and its GFLOP/s, best of `reps`
/// (after a warm-up), for `gast bench`, with the tiling `tile` chooses.
pub fn bench_gemm(ctx: &GpuContext, m: usize, n: usize, k: usize, reps: usize, tile: GemmTile) -> Vec<(String, f64)> {
    let gemm = Gemm::with_tile(ctx, tile);
    let a = ctx.upload("bench.a", &vec![0.5f32; m * k]);
    let b = ctx.upload("bench.b", &vec![0.25f32; k * n]);
    let c = ctx.zeros("bench.c", m * n);
    let plan = gemm.plan(ctx, &GemmSpec::plain(m, n, k));
    let run = || {
        let mut enc = ctx.encoder("bench gemm");
        gemm.record(ctx, &mut enc, &plan, &a, &b, None, &c);
        ctx.submit(enc);
        ctx.wait()
    };
    let mut best = f64::INFINITY;
    if run().is_err() {
        return Vec::new();
    }
    for _ in 0..reps.max(1) {
        let t = std::time::Instant::now();
        if run().is_err() {
            return Vec::new();
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
    }
    let gflops = 2.0 * (m * n * k) as f64 / (best * 1e-3) / 1e9;
    let name = format!("gemm {m}×{n}×{k} {}", if plan.wide { "128²" } else { "64²" });
    vec![(format!("{name} ms"), best), (format!("{name} GFLOP/s"), gflops)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};

    /// The obvious product in f64 with the same addressing as the kernel.
    fn reference(spec: &GemmSpec, a: &[f32], b: &[f32], bias: &[f32], c_old: &[f32]) -> Vec<f32> {
        let mut c = c_old.to_vec();
        for z in 0..spec.batch {
            for i in 0..spec.m {
                for j in 0..spec.n {
                    let mut acc = 0f64;
                    for p in 0..spec.k {
                        let ai =
                            spec.a.offset + z * spec.a.batch_stride + i * spec.a.row_stride + p * spec.a.col_stride;
                        let bi =
                            spec.b.offset + z * spec.b.batch_stride + p * spec.b.row_stride + j * spec.b.col_stride;
                        acc += f64::from(a[ai]) * f64::from(b[bi]);
                    }
                    let at = spec.c.offset + z * spec.c.batch_stride + i * spec.c.row_stride + j;
                    let mut v = f64::from(spec.alpha) * acc;
                    if spec.accumulate {
                        v += f64::from(c_old[at]);
                    }
                    if let Some(o) = spec.bias {
                        v += f64::from(bias[o + i]);
                    }
                    if spec.relu {
                        v = v.max(0.0);
                    }
                    c[at] = v as f32;
                }
            }
        }
        c
    }

    #[test]
    fn matches_a_cpu_product_on_odd_sizes_and_every_layout() {
        for tile in [GemmTile::Narrow, GemmTile::Wide] {
            matches_a_cpu_product_with(tile, (67, 45, 33));
            // Past one wide block in every direction, k not a whole slice.
            matches_a_cpu_product_with(tile, (131, 140, 21));
        }
    }

    /// Both tilings sum each output in the same order: the same bits, on a
    /// product of several blocks each way with a partial last block.
    #[test]
    fn the_wide_tiling_gives_the_narrow_ones_bits() {
        let ctx = ctx();
        let (m, n, k) = (300, 270, 77);
        let (a, b) = (noise(m * k, 5), noise(k * n, 6));
        let (ab, bb) = (ctx.upload("a", &a), ctx.upload("b", &b));
        let spec = GemmSpec { a: Strided::transposed(0, m), ..GemmSpec::plain(m, n, k) };
        let mut results = Vec::new();
        for tile in [GemmTile::Narrow, GemmTile::Wide] {
            let gemm = Gemm::with_tile(ctx, tile);
            let plan = gemm.plan(ctx, &spec);
            assert_eq!(plan.is_wide(), tile == GemmTile::Wide);
            let cb = ctx.zeros("c", m * n);
            let mut enc = ctx.encoder("gemm tilings");
            gemm.record(ctx, &mut enc, &plan, &ab, &bb, None, &cb);
            ctx.submit(enc);
            results.push(ctx.read::<f32>(&cb).expect("read back"));
        }
        assert!(results[0].iter().any(|v| *v != 0.0));
        let differ = results[0].iter().zip(&results[1]).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
        assert_eq!(differ, 0, "{differ} of {} outputs differ between the tilings", m * n);
    }

    /// Auto takes the wide tiling where its grid still fills a GPU: the
    /// GCFM search's scores and VGG's input gradients, not conv3_1's forward
    /// at a 512 px step (256 × 4,096) nor small products; on a software
    /// adapter every product of a wide block or more.
    #[test]
    fn auto_tiles_wide_only_where_the_grid_stays_full() {
        let auto = |m, n, k| GemmTile::Auto.wide(&GemmSpec::plain(m, n, k), false);
        assert!(auto(4096, 4096, 256), "GCFM scores at 512 px");
        assert!(auto(1152, 4096, 256), "conv3_1's input gradient at 512 px");
        assert!(!auto(256, 4096, 1152), "conv3_1's forward at 512 px");
        assert!(!auto(64, 65536, 27), "conv1_1: fewer than 128 rows");
        assert!(!auto(67, 45, 33));
        let software = |m, n, k| GemmTile::Auto.wide(&GemmSpec::plain(m, n, k), true);
        assert!(software(256, 4096, 1152) && software(128, 128, 9));
        assert!(!software(64, 65536, 27) && !software(67, 45, 33));
        let (tiny, big) = (GemmSpec::plain(3, 3, 3), GemmSpec::plain(4096, 4096, 256));
        assert!(GemmTile::Wide.wide(&tiny, false) && !GemmTile::Narrow.wide(&big, true));
    }

    fn matches_a_cpu_product_with(tile: GemmTile, (m, n, k): (usize, usize, usize)) {
        let ctx = ctx();
        let gemm = Gemm::with_tile(ctx, tile);
        let mut cases = vec![
            ("A·B", GemmSpec::plain(m, n, k)),
            ("Aᵀ·B", GemmSpec { a: Strided::transposed(0, m), ..GemmSpec::plain(m, n, k) }),
            ("A·Bᵀ", GemmSpec { b: Strided::transposed(0, k), ..GemmSpec::plain(m, n, k) }),
            (
                "sub-block, bias, ReLU, accumulate",
                GemmSpec {
                    a: Strided::rows(5, k + 3),
                    b: Strided::rows(7, n + 2),
                    c: Strided::rows(11, n + 4),
                    alpha: 0.5,
                    accumulate: true,
                    bias: Some(2),
                    relu: true,
                    ..GemmSpec::plain(m, n, k)
                },
            ),
        ];
        let batched = GemmSpec {
            batch: 3,
            a: Strided::rows(0, k).batched(m * k),
            b: Strided::transposed(0, k).batched(n * k),
            c: Strided::rows(0, n).batched(m * n),
            ..GemmSpec::plain(m, n, k)
        };
        cases.push(("batched Aᵀ", batched));
        let len = 4 * (m + 8) * (n + 8) + 4 * (m + 8) * (k + 8) + 4 * (k + 8) * (n + 8);
        let (a, b, bias, c0) = (noise(len, 1), noise(len, 2), noise(m + 8, 3), noise(len, 4));
        let (ab, bb, biasb) = (ctx.upload("a", &a), ctx.upload("b", &b), ctx.upload("bias", &bias));
        let mut failures = Vec::new();
        for (name, spec) in &cases {
            let cb = ctx.upload("c", &c0);
            let plan = gemm.plan(ctx, spec);
            let mut enc = ctx.encoder("gemm test");
            gemm.record(ctx, &mut enc, &plan, &ab, &bb, Some(&biasb), &cb);
            ctx.submit(enc);
            let got: Vec<f32> = ctx.read(&cb).expect("read back");
            let want = reference(spec, &a, &b, &bias, &c0);
            let worst = got.iter().zip(&want).map(|(g, w)| (g - w).abs()).fold(0f32, f32::max);
            if worst >= 1e-4 {
                failures.push(format!("{tile:?} {m}×{n}×{k} {name}: largest difference {worst}"));
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n"));
    }
}
