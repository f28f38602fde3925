//! The reference's gradient leak between phases on the GPU
//! (`shaders/leak.wgsl`), when [`StyleConfig::phase_leak`] is on: the
//! gradients a colour step's backward leaves on the geometry, and a geometry
//! step's on the colour, summed on the device until the other phase's next
//! step adds them to its own, as the CPU session's `Leak` does
//! (`core/src/session/run_step.rs`).
//!
//! [`StyleConfig::phase_leak`]: crate::style::StyleConfig::phase_leak

use super::Commands;
use super::{Bind, GpuContext, GpuError, GpuGrads, Kernel};

/// Threads per workgroup in `leak.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `leak.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct LeakParams {
    len: u32,
    group: u32,
    stride: u32,
    _pad: u32,
}

/// One parameter group's sum: `len` elements paired with a gradient array.
#[derive(Debug)]
struct Sum {
    len: usize,
    acc: wgpu::Buffer,
    uniform: wgpu::Buffer,
    groups: [u32; 3],
}

impl Sum {
    fn new(ctx: &GpuContext, label: &str, len: usize, group: u32, stride: u32) -> Self {
        let params = LeakParams { len: len as u32, group, stride, _pad: 0 };
        Self {
            len,
            acc: ctx.zeros(label, len.max(1)),
            uniform: ctx.uniform(label, &params),
            groups: Kernel::groups_1d(len, WORKGROUP),
        }
    }
}

/// The leaked sums of one run's Gaussians (11 floats each), and the two kernels.
#[derive(Debug)]
pub struct GpuLeak {
    take: Kernel,
    add: Kernel,
    color: Sum,
    /// Means, log-scales, quaternions, opacity logits.
    geometry: [Sum; 4],
}

impl GpuLeak {
    /// Empty sums for the Gaussians whose gradients `grads` holds.
    pub fn new(ctx: &GpuContext, grads: &GpuGrads) -> Self {
        let src = include_str!("../../../../shaders/leak.wgsl");
        let binds = [Bind::Uniform, Bind::ReadWrite, Bind::ReadWrite];
        let n = grads.len;
        let sh_stride = (grads.sh_coeffs * 3) as u32;
        Self {
            take: Kernel::new(ctx, "leak.take", src, "take", &binds),
            add: Kernel::new(ctx, "leak.add", src, "add", &binds),
            color: Sum::new(ctx, "leak.color", 3 * n, 3, sh_stride),
            geometry: [
                Sum::new(ctx, "leak.means", 3 * n, 1, 1),
                Sum::new(ctx, "leak.scales", 3 * n, 1, 1),
                Sum::new(ctx, "leak.quats", 4 * n, 1, 1),
                Sum::new(ctx, "leak.opacity", n, 1, 1),
            ],
        }
    }

    /// The sums in the order of the optimiser's groups (colour, means,
    /// scales, quaternions, opacity).
    fn sums(&self) -> [&Sum; 5] {
        let [m, s, q, o] = &self.geometry;
        [&self.color, m, s, q, o]
    }

    /// The sums read back, in the order of the optimiser's groups (a
    /// checkpoint keeps them, so that a resumed run leaks as the whole run).
    pub fn read(&self, ctx: &GpuContext) -> Result<Vec<Vec<f32>>, GpuError> {
        self.sums()
            .into_iter()
            .map(|s| {
                let mut x: Vec<f32> = ctx.read(&s.acc)?;
                x.truncate(s.len);
                Ok(x)
            })
            .collect()
    }

    /// Goes on from `sums` (as [`GpuLeak::read`] gives them); an error that
    /// says which does not fit.
    pub fn write(&self, ctx: &GpuContext, sums: &[Vec<f32>]) -> Result<(), String> {
        let lens: Vec<usize> = self.sums().iter().map(|s| s.len).collect();
        if sums.len() != lens.len() || sums.iter().zip(&lens).any(|(x, &len)| x.len() != len) {
            let found: Vec<usize> = sums.iter().map(Vec::len).collect();
            return Err(format!("expected the phase leak's sums of {lens:?} values, found {found:?}"));
        }
        for (s, x) in self.sums().into_iter().zip(sums) {
            if s.len > 0 {
                ctx.write(&s.acc, x);
            }
        }
        Ok(())
    }

    fn geometry_grads(grads: &GpuGrads) -> [&wgpu::Buffer; 4] {
        [&grads.v_means, &grads.v_log_scales, &grads.v_quats, &grads.v_opacity_logits]
    }

    /// A colour step, before its update: the DC colour's gradient takes the
    /// colour sum (what the geometry steps since the last colour step left), which empties.
    pub fn take_color(&self, ctx: &GpuContext, enc: &mut dyn Commands, grads: &GpuGrads) {
        let s = &self.color;
        self.take.dispatch(ctx, enc, &[&s.uniform, &grads.v_sh, &s.acc], s.groups);
    }

    /// A geometry step, before its update (after the regularisers): each
    /// geometry gradient takes its sum, which empties.
    pub fn take_geometry(&self, ctx: &GpuContext, enc: &mut dyn Commands, grads: &GpuGrads) {
        for (s, v) in self.geometry.iter().zip(Self::geometry_grads(grads)) {
            self.take.dispatch(ctx, enc, &[&s.uniform, v, &s.acc], s.groups);
        }
    }

    /// After a colour step's backward: its geometry gradients join their sums.
    pub fn add_geometry(&self, ctx: &GpuContext, enc: &mut dyn Commands, grads: &GpuGrads) {
        for (s, v) in self.geometry.iter().zip(Self::geometry_grads(grads)) {
            self.add.dispatch(ctx, enc, &[&s.uniform, v, &s.acc], s.groups);
        }
    }

    /// After a geometry step's backward: its DC colour gradient joins the colour sum.
    pub fn add_color(&self, ctx: &GpuContext, enc: &mut dyn Commands, grads: &GpuGrads) {
        let s = &self.color;
        self.add.dispatch(ctx, enc, &[&s.uniform, &grads.v_sh, &s.acc], s.groups);
    }
}
