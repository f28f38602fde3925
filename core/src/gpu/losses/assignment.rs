//! The assignment terms on the GPU engine (`shaders/assignment.wgsl`): λ_as
//! and λ_asc, the twin of [`crate::style::assignment::assignment_loss`].
//!
//! The pairing is a least-cost one-to-one assignment of at most
//! [`crate::style::assignment::ASSIGN_MAX`] rendered positions, sequential
//! work that stays on the host. The device gathers only the columns a step
//! pairs (the drawn rendered positions of this step's RGB relu3 features and
//! their drawn style positions, `channels × r` each), the host pairs them and
//! computes both pulls with the CPU step's own
//! [`crate::style::assignment::pull_pairs`], and the device adds the
//! gradient back at those positions before VGG's backward pass. A step moves
//! `2 · channels · r` floats down and `channels · r` up (3 MiB at r = 512),
//! not the feature maps. The columns come down in one copy, and the host
//! waits for the submission that gathered them alone, right after the RGB
//! features, so the device computes the depth and edge maps' features, runs
//! the step's GCFM search, and on geometry steps the depth's backward pass,
//! while the host pairs (`GpuEngine::step`).
//!
//! The draw differs from the CPU step's in its seed only: the CPU seeds from
//! the features' bits (which would need the whole maps here), the engine from
//! the run's seed and the step's index, so a run is reproducible, each step
//! draws anew and a resumed run draws as the whole run did.

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel};
use crate::rng::Rng;
use crate::style::assignment::{ASSIGN_MAX, Assignment, draw_pairs, pull_pairs};

/// Threads per workgroup in `assignment.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `assignment.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct AssignParams {
    channels: u32,
    positions: u32,
    count: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<AssignParams>() == 16);

/// The gathered columns, pairing and gradient of one step's assignment.
#[derive(Debug)]
pub struct GpuAssignment {
    gather: Kernel,
    scatter: Kernel,
    channels: usize,
    /// This step's rendered positions (`u32`, at most `ASSIGN_MAX`).
    rows: wgpu::Buffer,
    /// This step's style positions, one per row.
    targets: wgpu::Buffer,
    /// Gathered rendered features, style features and the gradient, `channels × r`.
    x: wgpu::Buffer,
    s: wgpu::Buffer,
    g: wgpu::Buffer,
    /// `x` then `s`, copied for the host to read (`2 · channels × r`).
    staging: wgpu::Buffer,
    /// The uniforms of the two gathers and the scatter (one each: a uniform
    /// is not rewritten between the dispatches of one encoder).
    u_x: wgpu::Buffer,
    u_s: wgpu::Buffer,
    u_g: wgpu::Buffer,
    rng: Rng,
    /// Rows of the last draw (0: nothing to pull or add).
    drawn: usize,
    /// The last pull's wait for the gathered columns and its pairing, ms.
    pull_ms: (f32, f32),
}

impl GpuAssignment {
    /// The workspace for `channels`-channel features, its draws seeded by
    /// `seed` (until [`GpuAssignment::reseed`]).
    pub fn new(ctx: &GpuContext, channels: usize, seed: u64) -> Self {
        let src = include_str!("../../../../shaders/assignment.wgsl");
        let binds = [Bind::Uniform, Bind::Read, Bind::Read, Bind::ReadWrite];
        let k = |entry: &str| Kernel::new(ctx, &format!("assignment.{entry}"), src, entry, &binds);
        let channels = channels.max(1);
        let cols = channels * ASSIGN_MAX;
        let zero = AssignParams { channels: 0, positions: 0, count: 0, _pad: 0 };
        Self {
            gather: k("gather"),
            scatter: k("scatter_add"),
            channels,
            rows: ctx.zeros("assignment.rows", ASSIGN_MAX),
            targets: ctx.zeros("assignment.targets", ASSIGN_MAX),
            x: ctx.zeros("assignment.x", cols),
            s: ctx.zeros("assignment.s", cols),
            g: ctx.zeros("assignment.g", cols),
            staging: ctx.staging("assignment.staging", (2 * cols * 4) as u64),
            u_x: ctx.uniform("assignment.u_x", &zero),
            u_s: ctx.uniform("assignment.u_s", &zero),
            u_g: ctx.uniform("assignment.u_g", &zero),
            rng: Rng::new(seed),
            drawn: 0,
            pull_ms: (0.0, 0.0),
        }
    }

    /// Seeds the next draws by `seed`.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
    }

    fn params(&self, positions: usize, count: usize) -> AssignParams {
        AssignParams { channels: self.channels as u32, positions: positions as u32, count: count as u32, _pad: 0 }
    }

    /// Draws this step's pairs ([`draw_pairs`]) among the `covered` positions
    /// of the `channels × n` rendered features and the `m` style positions,
    /// and records the gathers of both sides' columns from `features` and
    /// `style` and their copy for the host. Returns the rows drawn (0 when
    /// nothing is covered or the style is empty: then nothing is recorded and
    /// the step pulls nothing).
    #[allow(clippy::too_many_arguments)]
    pub fn record_gather(
        &mut self,
        ctx: &GpuContext,
        enc: &mut dyn Commands,
        features: &wgpu::Buffer,
        n: usize,
        covered: Vec<usize>,
        style: &wgpu::Buffer,
        m: usize,
    ) -> usize {
        self.drawn = 0;
        if covered.is_empty() || m == 0 {
            return 0;
        }
        let (rows, targets) = draw_pairs(&mut self.rng, covered, m);
        self.record_gather_of(ctx, enc, features, n, &rows, style, m, &targets);
        self.drawn
    }

    /// [`GpuAssignment::record_gather`] of given pairs (tests compare it with the CPU's).
    #[allow(clippy::too_many_arguments)]
    fn record_gather_of(
        &mut self,
        ctx: &GpuContext,
        enc: &mut dyn Commands,
        features: &wgpu::Buffer,
        n: usize,
        rows: &[usize],
        style: &wgpu::Buffer,
        m: usize,
        targets: &[usize],
    ) {
        let r = rows.len().min(ASSIGN_MAX);
        let to_u32 = |v: &[usize]| v.iter().take(r).map(|&i| i as u32).collect::<Vec<u32>>();
        ctx.write(&self.rows, &to_u32(rows));
        ctx.write(&self.targets, &to_u32(targets));
        ctx.write(&self.u_x, std::slice::from_ref(&self.params(n, r)));
        ctx.write(&self.u_s, std::slice::from_ref(&self.params(m, r)));
        ctx.write(&self.u_g, std::slice::from_ref(&self.params(n, r)));
        let groups = Kernel::groups_1d(self.channels * r, WORKGROUP);
        self.gather.dispatch(ctx, enc, &[&self.u_x, &self.rows, features, &self.x], groups);
        self.gather.dispatch(ctx, enc, &[&self.u_s, &self.targets, style, &self.s], groups);
        let bytes = (self.channels * r * 4) as u64;
        enc.encoder().copy_buffer_to_buffer(&self.x, 0, &self.staging, 0, bytes);
        enc.encoder().copy_buffer_to_buffer(&self.s, 0, &self.staging, bytes, bytes);
        self.drawn = r;
    }

    /// Once `gathered` (the submission holding the gathers) has run: reads
    /// the gathered columns back, pairs them and computes both pulls on the
    /// host ([`pull_pairs`], by the cosine and squared weights `weights`, in
    /// blocks of at most `block` rows), and uploads the weighted gradient for
    /// [`GpuAssignment::record_scatter`] (recorded before or after: the
    /// upload lands before the next submission). Work submitted after
    /// `gathered` runs on meanwhile. Returns the terms (the gradient stays on the
    /// device; `grad` is empty).
    pub fn pull(
        &mut self,
        ctx: &GpuContext,
        gathered: wgpu::SubmissionIndex,
        (cosine_weight, l2_weight): (f32, f32),
        block: usize,
    ) -> Result<Assignment, GpuError> {
        self.pull_ms = (0.0, 0.0);
        if self.drawn == 0 {
            return Ok(Assignment { cosine: 0.0, l2: 0.0, grad: Vec::new() });
        }
        let half = self.channels * self.drawn;
        let waited = std::time::Instant::now();
        let xs: Vec<f32> = ctx.read_staged(&self.staging, (2 * half * 4) as u64, gathered)?;
        let paired = std::time::Instant::now();
        let (x, s) = xs.split_at(half);
        let pulled = pull_pairs(x, s, self.channels, cosine_weight, l2_weight, block);
        let ms = |d: std::time::Duration| d.as_secs_f32() * 1e3;
        self.pull_ms = (ms(paired - waited), ms(paired.elapsed()));
        ctx.write(&self.g, &pulled.grad);
        Ok(Assignment { grad: Vec::new(), ..pulled })
    }

    /// The last pull's wait for the gathered columns and its pairing on the
    /// host, in ms (zeros when it drew nothing).
    pub fn last_pull_ms(&self) -> (f32, f32) {
        self.pull_ms
    }

    /// Records `v_features += ` the last pull's gradient at the rows drawn
    /// (nothing when none were).
    pub fn record_scatter(&self, ctx: &GpuContext, enc: &mut dyn Commands, v_features: &wgpu::Buffer) {
        if self.drawn == 0 {
            return;
        }
        let groups = Kernel::groups_1d(self.channels * self.drawn, WORKGROUP);
        self.scatter.dispatch(ctx, enc, &[&self.u_g, &self.rows, &self.g, v_features], groups);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::assignment::ASSIGN_BLOCK;
    use crate::style::focus::gather_positions;

    /// The device's gather, the host's pull and the device's scatter give the
    /// CPU step's terms and gradient for the same draw, the gradient added to
    /// what was there and nothing added off the drawn rows, with the scatter
    /// recorded before the pull uploads the gradient (as the engine records it).
    #[test]
    fn gather_pull_and_scatter_match_the_cpu_assignment() {
        let ctx = ctx();
        for (channels, n, m, cover, weights) in [
            (3usize, 7usize, 9usize, 1.0f32, (10.0f32, 0.0f32)),
            (5, 40, 30, 0.5, (10.0, 0.01)),
            (16, 700, 650, 1.0, (0.0, 1.0)),
            (8, 300, 20, 0.7, (1.0, 1.0)),
        ] {
            let label = format!("{channels} × {n} against {m}, cover {cover}, weights {weights:?}");
            let f: Vec<f32> = noise(channels * n, 1).iter().map(|v| v.abs() + 0.1).collect();
            let style: Vec<f32> = noise(channels * m, 2).iter().map(|v| v.abs()).collect();
            let v0 = noise(channels * n, 3);
            let covered: Vec<usize> =
                noise(n, 4).iter().enumerate().filter(|(_, v)| v.abs() < cover).map(|(i, _)| i).collect();
            let mut a = GpuAssignment::new(ctx, channels, 7);
            let (rows, targets) = draw_pairs(&mut Rng::new(11), covered.clone(), m);
            let (fb, sb, vb) = (ctx.upload("f", &f), ctx.upload("s", &style), ctx.upload("v", &v0));
            let mut enc = ctx.encoder("assignment test gather");
            a.record_gather_of(ctx, &mut enc, &fb, n, &rows, &sb, m, &targets);
            let gathered = ctx.submit_indexed(enc);
            // As the engine does: the scatter recorded before the pull,
            // whose upload of the gradient the scatter's submission sees.
            let mut enc = ctx.encoder("assignment test scatter");
            a.record_scatter(ctx, &mut enc, &vb);
            let got = a.pull(ctx, gathered, weights, ASSIGN_BLOCK).expect("pull");
            ctx.submit(enc);
            let v: Vec<f32> = ctx.read(&vb).expect("gradient");

            // The CPU's pulls of the same columns, scattered by hand.
            let x = gather_positions(&f, channels, n, &rows);
            let s = gather_positions(&style, channels, m, &targets);
            let want = pull_pairs(&x, &s, channels, weights.0, weights.1, ASSIGN_BLOCK);
            assert_eq!((got.cosine, got.l2), (want.cosine, want.l2), "{label}");
            let r = rows.len();
            let mut expect = v0.clone();
            for (t, &pos) in rows.iter().enumerate() {
                for c in 0..channels {
                    expect[c * n + pos] += want.grad[c * r + t];
                }
            }
            for (i, (g, e)) in v.iter().zip(&expect).enumerate() {
                assert!((g - e).abs() <= 1e-6 * e.abs().max(1.0), "{label}: element {i}: {g} vs {e}");
            }
        }
    }

    #[test]
    fn nothing_covered_draws_nothing_and_adds_nothing() {
        let ctx = ctx();
        let mut a = GpuAssignment::new(ctx, 4, 1);
        let (fb, sb) = (ctx.upload("f", &noise(40, 1)), ctx.upload("s", &noise(40, 2)));
        let v0 = noise(40, 3);
        let vb = ctx.upload("v", &v0);
        let mut enc = ctx.encoder("empty");
        assert_eq!(a.record_gather(ctx, &mut enc, &fb, 10, Vec::new(), &sb, 10), 0);
        assert_eq!(a.record_gather(ctx, &mut enc, &fb, 10, vec![1, 2], &sb, 0), 0);
        let gathered = ctx.submit_indexed(enc);
        let t = a.pull(ctx, gathered, (10.0, 1.0), ASSIGN_BLOCK).expect("pull");
        assert_eq!((t.cosine, t.l2), (0.0, 0.0));
        let mut enc = ctx.encoder("empty scatter");
        a.record_scatter(ctx, &mut enc, &vb);
        ctx.submit(enc);
        assert_eq!(ctx.read::<f32>(&vb).expect("v"), v0);
    }
}
