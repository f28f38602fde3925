//! The GCFM loss on the GPU (`shaders/gcfm.wgsl` and the GEMM), repeating
//! [`crate::style::gcfm`]: the joint nearest (`y+`) and farthest (`y−`) style
//! position of every rendered feature position, the per-modality loss terms
//! and the gradients w.r.t. the rendered RGB and depth features (the edge
//! features are a constant: their term is reported, their gradient is not).
//!
//! The search is one GEMM per modality accumulating the joint scores
//! `⟨r(x), s(y)⟩` of a chunk of rendered positions against every style
//! position, then one workgroup per row taking the arg-extrema of the scores
//! scaled by the style's joint `1/‖s(y)‖` (the rendered norm does not change
//! them). Chunks keep the score matrix under the storage-binding limit. The
//! CPU re-decides near-ties in `f64`; the GPU keeps the `f32` winner (the
//! first index on exact ties), so the two may differ where two style positions
//! score within rounding of each other: the tests count those.
//!
//! With the object focus ([`super::GpuFocus`]), the loss and gradients count
//! only the covered rendered positions and average over their number (read on
//! the device). The search runs over every row, or, given a [`GcfmSubset`] of
//! the covered positions (the engine makes one per view), gathers their
//! columns and searches only those rows: its cost follows the object, not
//! the frame.
//!
//! The style side ([`GpuStyle`]) is uploaded once per style image with the
//! norms [`StyleFeatures`] computed; a [`GcfmWorkspace`] holds the scratch and
//! every launch's uniform for one rendered size, made once.

use super::Commands;
use super::gemm::{Gemm, GemmPlan, GemmSpec, Strided};
use super::kernel::Launch;
use super::{Bind, GpuContext, GpuFocus, GpuSlicedTarget, Kernel};
use crate::style::config::LossWeights;
use crate::style::gcfm::StyleFeatures;

/// Threads per workgroup of the `gcfm.wgsl` kernels.
const WORKGROUP: u32 = 256;
/// Largest score chunk, in f32 elements (64 MiB).
const SCORE_ELEMS: usize = 1 << 24;
/// Most rows per chunk (one workgroup per row, one dispatch dimension).
const MAX_ROWS: usize = 65_535;

/// The uniform block of `gcfm.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct GcfmParams {
    n: u32,
    m: u32,
    c: u32,
    x0: u32,
    len: u32,
    modality: u32,
    out_off: u32,
    _pad0: u32,
    scale: f32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<GcfmParams>() == 48);

/// The style's features and norms on the device, uploaded once per style image.
#[derive(Debug)]
pub struct GpuStyle {
    channels: usize,
    positions: usize,
    feats: Vec<wgpu::Buffer>,
    joint_inv_norm: wgpu::Buffer,
    modal_inv_norm: Vec<wgpu::Buffer>,
    /// The RGB features' per-channel means (λ_mean's target), on the host.
    rgb_mean: Vec<f32>,
    /// The sliced Wasserstein targets of the RGB and depth features (λ_sw,
    /// λ_swd), uploaded only once their term is on ([`GpuStyle::upload_sliced`]).
    sliced: [Option<GpuSlicedTarget>; 2],
}

impl GpuStyle {
    /// Uploads the three modalities' features and their norms; the sliced
    /// targets wait for [`GpuStyle::upload_sliced`].
    pub fn new(ctx: &GpuContext, style: &StyleFeatures) -> Self {
        Self {
            channels: style.channels,
            positions: style.positions(),
            feats: (0..3).map(|k| ctx.upload("gcfm.style", style.modality(k))).collect(),
            joint_inv_norm: ctx.upload("gcfm.joint_inv_norm", style.joint_inv_norm()),
            modal_inv_norm: (0..3)
                .map(|k| {
                    let v: Vec<f32> = style.modal_inv_norm(k).iter().map(|&x| x as f32).collect();
                    ctx.upload("gcfm.modal_inv_norm", &v)
                })
                .collect(),
            rgb_mean: style.rgb_mean().to_vec(),
            sliced: [None, None],
        }
    }

    /// Uploads the sliced Wasserstein target of each sliced term `weights`
    /// turns on (λ_sw: RGB, λ_swd: depth) that has none yet: a style whose
    /// terms stay off never projects and sorts its features for them.
    pub fn upload_sliced(&mut self, ctx: &GpuContext, style: &StyleFeatures, weights: &LossWeights) {
        for (m, weight) in [weights.sliced, weights.sliced_depth].into_iter().enumerate() {
            if weight > 0.0 && self.sliced[m].is_none() {
                self.sliced[m] = Some(GpuSlicedTarget::new(ctx, style.sliced(m)));
            }
        }
    }

    /// The sliced Wasserstein target of modality `m` (0 RGB, 1 depth), if uploaded.
    pub fn sliced(&self, m: usize) -> Option<&GpuSlicedTarget> {
        self.sliced[m].as_ref()
    }

    /// The RGB features' per-channel means ([`StyleFeatures::rgb_mean`]).
    pub fn rgb_mean(&self) -> &[f32] {
        &self.rgb_mean
    }

    /// Number of style positions.
    pub fn positions(&self) -> usize {
        self.positions
    }

    /// Channels per modality.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// One modality's features (0 RGB, 1 depth, 2 edge), `channels × positions`.
    pub fn modality(&self, k: usize) -> &wgpu::Buffer {
        &self.feats[k]
    }
}

/// One chunk of rendered rows: three accumulating GEMMs and the arg-extrema.
#[derive(Debug)]
struct Chunk {
    gemms: Vec<GemmPlan>,
    argext: Launch,
}

/// Scratch and launch uniforms for one rendered size against one style.
#[derive(Debug)]
pub struct GcfmWorkspace {
    n: usize,
    m: usize,
    /// Most rendered rows in one chunk of scores.
    rows: usize,
    scores: wgpu::Buffer,
    matches: wgpu::Buffer,
    stats: wgpu::Buffer,
    chunks: Vec<Chunk>,
    stats_launch: Vec<Launch>,
    grad_launch: Vec<Launch>,
    reduce: Launch,
}

impl GcfmWorkspace {
    /// The matches of the last run: `y+` of every rendered position, then `y−`
    /// (`2n` `u32`s, flat row-major indices into the style feature map, as
    /// [`crate::style::gcfm::Matches`]).
    pub fn matches(&self) -> &wgpu::Buffer {
        &self.matches
    }

    /// Rendered positions.
    pub fn positions(&self) -> usize {
        self.n
    }
}

/// The search over a subset of one view's rendered positions (the object
/// focus's covered ones), made once per view: their indices, the gather of
/// each modality's columns into a scratch of `c × len`, and the GEMM chunks
/// and arg-extrema over those rows only, which write the matches of the
/// subset's positions (the others keep what they held; the masked loss does
/// not read them).
#[derive(Debug)]
pub struct GcfmSubset {
    len: usize,
    m: usize,
    positions: wgpu::Buffer,
    gather: Launch,
    chunks: Vec<Chunk>,
}

impl GcfmSubset {
    /// Positions searched.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it searches no position.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// `f32`s of the scratch [`Search::Subset`] needs.
    pub fn scratch_len(&self, channels: usize) -> usize {
        channels * self.len
    }
}

/// Where a GCFM run takes its matches from.
#[derive(Clone, Copy, Debug)]
pub enum Search<'a> {
    /// Searched for every rendered position.
    Every,
    /// Searched for the subset's positions only; `scratch` holds at least
    /// [`GcfmSubset::scratch_len`] `f32`s.
    Subset {
        /// The positions and their launches.
        subset: &'a GcfmSubset,
        /// One modality's gathered columns.
        scratch: &'a wgpu::Buffer,
    },
    /// Not searched: [`GcfmWorkspace::matches`] already holds them (a view's
    /// kept matches, copied in by the caller).
    Kept,
}

/// The compiled kernels.
#[derive(Debug)]
pub struct GpuGcfm {
    gemm: Gemm,
    argext: Kernel,
    argext_at: Kernel,
    gather: Kernel,
    stats: Kernel,
    grad: Kernel,
    reduce: Kernel,
    dummy: wgpu::Buffer,
    dummy_rw: wgpu::Buffer,
}

fn u32_of(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

impl GpuGcfm {
    /// Compiles `gcfm.wgsl` and the GEMM.
    pub fn new(ctx: &GpuContext) -> Self {
        let src = include_str!("../../../../shaders/gcfm.wgsl");
        use Bind::{Read, ReadWrite, Uniform};
        let all = [Uniform, Read, Read, ReadWrite, Read, ReadWrite, Read, Read];
        Self {
            gemm: Gemm::new(ctx),
            argext: Kernel::new(ctx, "gcfm.argext", src, "argext", &all[..4]),
            argext_at: Kernel::new(ctx, "gcfm.argext_at", src, "argext_at", &all[..5]),
            gather: Kernel::new(ctx, "gcfm.gather", src, "gather", &all[..6]),
            stats: Kernel::new(ctx, "gcfm.stats", src, "stats", &all),
            grad: Kernel::new(ctx, "gcfm.grad", src, "grad", &all[..6]),
            reduce: Kernel::new(ctx, "gcfm.reduce", src, "reduce", &all),
            dummy: ctx.zeros("gcfm.dummy", 1),
            dummy_rw: ctx.zeros("gcfm.dummy_rw", 1),
        }
    }

    /// Scratch and uniforms for `n` rendered positions against `style`. The
    /// run writes the loss of each modality (RGB, depth, edge) and their sum,
    /// four `f32`s, at `scalars_offset` (in `f32`s) of the scalars buffer, and
    /// the gradients multiplied by `scale` (the loss weight).
    pub fn workspace(
        &self,
        ctx: &GpuContext,
        style: &GpuStyle,
        n: usize,
        scalars_offset: usize,
        scale: f32,
    ) -> GcfmWorkspace {
        self.workspace_chunked(ctx, style, n, scalars_offset, scale, Self::score_limit(ctx))
    }

    /// [`GpuGcfm::workspace`] with score chunks of at most `limit` elements.
    fn workspace_chunked(
        &self,
        ctx: &GpuContext,
        style: &GpuStyle,
        n: usize,
        scalars_offset: usize,
        scale: f32,
        limit: usize,
    ) -> GcfmWorkspace {
        let (c, m) = (style.channels, style.positions);
        let rows = (limit / m.max(1)).clamp(1, MAX_ROWS).min(n.max(1));
        let base = GcfmParams {
            n: u32_of(n),
            m: u32_of(m),
            c: u32_of(c),
            out_off: u32_of(scalars_offset),
            scale,
            ..Default::default()
        };
        let chunks = self.chunks(ctx, &base, n, rows, "gcfm.argext");
        let per = |k: usize, len: usize| GcfmParams { modality: u32_of(k), len: u32_of(len), ..base };
        GcfmWorkspace {
            n,
            m,
            rows,
            scores: ctx.zeros("gcfm.scores", rows * m),
            matches: ctx.zeros("gcfm.matches", 2 * n),
            stats: ctx.zeros("gcfm.stats", 3 * 4 * n),
            chunks,
            stats_launch: (0..3).map(|k| Launch::new(ctx, "gcfm.stats", &per(k, n), n, WORKGROUP)).collect(),
            grad_launch: (0..2).map(|k| Launch::new(ctx, "gcfm.grad", &per(k, c * n), c * n, WORKGROUP)).collect(),
            reduce: Launch { uniform: ctx.uniform("gcfm.reduce", &base), groups: [1, 1, 1] },
        }
    }

    /// The search's chunks over `len` rows (`c × len` CHW features, `base`'s
    /// `m` style positions and `c` channels), at most `rows` rows each: three
    /// accumulating GEMMs and the arg-extrema launch (`label`) per chunk.
    fn chunks(&self, ctx: &GpuContext, base: &GcfmParams, len: usize, rows: usize, label: &str) -> Vec<Chunk> {
        let (m, c) = (base.m as usize, base.c as usize);
        let mut chunks = Vec::new();
        let mut x0 = 0;
        while x0 < len {
            let t = rows.min(len - x0);
            let gemms = (0..3)
                .map(|k| {
                    let spec = GemmSpec {
                        a: Strided { offset: x0, row_stride: 1, col_stride: len, batch_stride: 0 },
                        b: Strided::rows(0, m),
                        c: Strided::rows(0, m),
                        accumulate: k > 0,
                        ..GemmSpec::plain(t, m, c)
                    };
                    self.gemm.plan(ctx, &spec)
                })
                .collect();
            let p = GcfmParams { x0: u32_of(x0), len: u32_of(t), ..*base };
            chunks.push(Chunk { gemms, argext: Launch { uniform: ctx.uniform(label, &p), groups: [u32_of(t), 1, 1] } });
            x0 += t;
        }
        chunks
    }

    /// The search of `ws`'s rendered positions at `positions` only (each
    /// `< n`, for the style `ws` was made with).
    pub fn subset(&self, ctx: &GpuContext, ws: &GcfmWorkspace, style: &GpuStyle, positions: &[u32]) -> GcfmSubset {
        let (c, m, len) = (style.channels, style.positions, positions.len());
        let base = GcfmParams { n: u32_of(ws.n), m: u32_of(m), c: u32_of(c), len: u32_of(len), ..Default::default() };
        let chunks = self.chunks(ctx, &base, len, ws.rows, "gcfm.argext_at");
        GcfmSubset {
            len,
            m,
            positions: ctx.upload("gcfm.subset", if positions.is_empty() { &[0u32][..] } else { positions }),
            gather: Launch::new(ctx, "gcfm.gather", &base, c * len, WORKGROUP),
            chunks,
        }
    }

    /// Records the matching, the loss terms (into `scalars`) and the
    /// gradients w.r.t. the rendered RGB and depth features (`v_rgb`,
    /// `v_depth`, each `c × n` CHW like `rendered`, overwritten; 0 at the
    /// positions `focus` does not cover). `rendered` are the RGB, depth and
    /// edge features (`c × n` CHW each); `search` says where the matches
    /// come from ([`Search`]).
    ///
    /// # Panics
    /// When the workspace was made for another style (a caller bug).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        enc: &mut dyn Commands,
        ws: &GcfmWorkspace,
        style: &GpuStyle,
        rendered: [&wgpu::Buffer; 3],
        focus: &GpuFocus,
        v_rgb: &wgpu::Buffer,
        v_depth: &wgpu::Buffer,
        scalars: &wgpu::Buffer,
        search: Search<'_>,
    ) {
        assert_eq!(ws.m, style.positions, "GpuGcfm::record: workspace made for another style");
        if ws.n == 0 || ws.m == 0 {
            return;
        }
        match search {
            Search::Every => {
                for chunk in &ws.chunks {
                    for (k, plan) in chunk.gemms.iter().enumerate() {
                        self.gemm.record(ctx, enc, plan, rendered[k], &style.feats[k], None, &ws.scores);
                    }
                    let l = &chunk.argext;
                    let b = [&l.uniform, &ws.scores, &style.joint_inv_norm, &ws.matches];
                    self.argext.dispatch(ctx, enc, &b, l.groups);
                }
            }
            Search::Subset { subset: sub, scratch } => {
                assert_eq!(sub.m, style.positions, "GpuGcfm::record: subset made for another style");
                for chunk in &sub.chunks {
                    for (k, plan) in chunk.gemms.iter().enumerate() {
                        let g = &sub.gather;
                        let b = [&g.uniform, rendered[k], &self.dummy, &self.dummy_rw, &sub.positions, scratch];
                        self.gather.dispatch(ctx, enc, &b, g.groups);
                        self.gemm.record(ctx, enc, plan, scratch, &style.feats[k], None, &ws.scores);
                    }
                    let l = &chunk.argext;
                    let b = [&l.uniform, &ws.scores, &style.joint_inv_norm, &ws.matches, &sub.positions];
                    self.argext_at.dispatch(ctx, enc, &b, l.groups);
                }
            }
            Search::Kept => {}
        }
        for (k, l) in ws.stats_launch.iter().enumerate() {
            let (m, c) = (focus.cells(), focus.counts());
            let b = [&l.uniform, rendered[k], &style.feats[k], &ws.matches, &style.modal_inv_norm[k], &ws.stats, m, c];
            self.stats.dispatch(ctx, enc, &b, l.groups);
        }
        for (k, (l, out)) in ws.grad_launch.iter().zip([v_rgb, v_depth]).enumerate() {
            let b = [&l.uniform, rendered[k], &style.feats[k], &ws.matches, &ws.stats, out];
            self.grad.dispatch(ctx, enc, &b, l.groups);
        }
        let l = &ws.reduce;
        self.reduce.dispatch(
            ctx,
            enc,
            &[&l.uniform, &ws.stats, &self.dummy, &ws.matches, &self.dummy, scalars, focus.cells(), focus.counts()],
            l.groups,
        );
    }
}

impl GpuGcfm {
    /// The largest score chunk on `ctx`'s device, in `f32` elements: the
    /// storage-binding limit, at most [`SCORE_ELEMS`].
    pub fn score_limit(ctx: &GpuContext) -> usize {
        SCORE_ELEMS.min((ctx.max_binding_bytes() / 4) as usize)
    }

    /// The search alone, outside a step: for each of the `n` rendered
    /// positions of `rendered` (`c × n` CHW) the style position `y` (of the
    /// `m` in `style`, `c × m` CHW) with the largest `⟨r(x), s(y)⟩ · scale(y)`
    /// (`scale`: `m` floats), the first on ties, in score chunks of at most
    /// `limit` elements ([`GpuGcfm::score_limit`]). With unit style columns
    /// and unit scales, the largest cosine: what [`crate::eval::NearestStyle`]
    /// measures (`gast stylize`'s preview distances).
    #[allow(clippy::too_many_arguments)]
    pub fn nearest(
        &self,
        ctx: &GpuContext,
        rendered: &wgpu::Buffer,
        n: usize,
        style: &wgpu::Buffer,
        scale: &wgpu::Buffer,
        m: usize,
        c: usize,
        limit: usize,
    ) -> Result<Vec<u32>, super::GpuError> {
        if n == 0 || m == 0 {
            return Ok(vec![0; n]);
        }
        let rows = (limit / m).clamp(1, MAX_ROWS).min(n);
        let base = GcfmParams { n: u32_of(n), m: u32_of(m), c: u32_of(c), ..Default::default() };
        let scores = ctx.zeros("gcfm.nearest.scores", rows * m);
        let matches = ctx.zeros("gcfm.nearest.matches", 2 * n);
        let mut enc = ctx.encoder("gcfm.nearest");
        // One modality: each chunk's first (non-accumulating) GEMM.
        for chunk in self.chunks(ctx, &base, n, rows, "gcfm.nearest") {
            self.gemm.record(ctx, &mut enc, &chunk.gemms[0], rendered, style, None, &scores);
            let l = &chunk.argext;
            self.argext.dispatch(ctx, &mut enc, &[&l.uniform, &scores, scale, &matches], l.groups);
        }
        ctx.submit(enc);
        ctx.read_range::<u32>(&matches, 0, (n * 4) as u64)
    }
}

/// Milliseconds of one GCFM run (search, loss, gradients) for `n` rendered
/// positions against `m` style positions of `c` channels per modality (best of
/// `reps` after a warm-up), for `gast bench`.
pub fn bench_gcfm(ctx: &GpuContext, c: usize, n: usize, m: usize, reps: usize) -> Vec<(String, f64)> {
    let wave = |len: usize, f: f32| -> Vec<f32> { (0..len).map(|i| ((i as f32) * f).sin().max(0.0)).collect() };
    let style = StyleFeatures::new([wave(c * m, 0.37), wave(c * m, 0.11), wave(c * m, 0.23)], c, 1, m);
    let style = GpuStyle::new(ctx, &style);
    let gcfm = GpuGcfm::new(ctx);
    let ws = gcfm.workspace(ctx, &style, n, 0, 1.0);
    let r: Vec<wgpu::Buffer> = [0.31f32, 0.17, 0.05].iter().map(|&f| ctx.upload("bench.r", &wave(c * n, f))).collect();
    let (v_rgb, v_depth, scalars) = (ctx.zeros("bench.v", c * n), ctx.zeros("bench.v", c * n), ctx.zeros("bench.s", 4));
    let frame = GpuFocus::frame(ctx, 1, 1, n, 1);
    let mut best = f64::INFINITY;
    for _ in 0..reps.max(1) + 1 {
        let t = std::time::Instant::now();
        let mut enc = ctx.encoder("bench gcfm");
        gcfm.record(
            ctx,
            &mut enc,
            &ws,
            &style,
            [&r[0], &r[1], &r[2]],
            &frame,
            &v_rgb,
            &v_depth,
            &scalars,
            Search::Every,
        );
        ctx.submit(enc);
        if ctx.wait().is_err() {
            return Vec::new();
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
    }
    vec![(format!("gcfm {n}×{m}×{} ms", 3 * c), best)]
}

#[cfg(test)]
#[path = "gcfm_tests.rs"]
mod tests;
