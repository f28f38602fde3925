//! Adam on the GPU (`shaders/adam.wgsl`): one instance per parameter group and
//! phase, as [`crate::style::adam::Adam`] on the CPU, whose numbers it repeats.
//! An optional floor projects the updated parameters (the colour floor,
//! [`crate::style::StyleConfig::color_floor`]) in the same pass.

use super::Commands;
use super::{Bind, GpuContext, GpuError, Kernel};
use crate::style::adam::{AdamConfig, AdamState};

/// Threads per workgroup in `adam.wgsl`.
const WORKGROUP: u32 = 256;

/// The uniform block of `adam.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct AdamParams {
    len: u32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    step_size: f32,
    bc2_sqrt: f32,
    group: u32,
    stride: u32,
    floor: f32,
    grad_stride: u32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<AdamParams>() == 48);

/// The floor that lets every value through.
const NO_FLOOR: f32 = f32::MIN;

/// Adam state for one flat parameter buffer, on the device.
#[derive(Debug)]
pub struct GpuAdam {
    config: AdamConfig,
    len: usize,
    step: u32,
    group: u32,
    stride: u32,
    grad_stride: u32,
    floor: f32,
    m: wgpu::Buffer,
    v: wgpu::Buffer,
    uniform: wgpu::Buffer,
}

/// The compiled kernel, shared by every [`GpuAdam`] of a context.
#[derive(Debug)]
pub struct AdamKernel(Kernel);

impl AdamKernel {
    /// Compiles `adam.wgsl`.
    pub fn new(ctx: &GpuContext) -> Self {
        Self(Kernel::new(
            ctx,
            "adam",
            include_str!("../../../../shaders/adam.wgsl"),
            "step",
            &[Bind::Uniform, Bind::ReadWrite, Bind::Read, Bind::ReadWrite, Bind::ReadWrite],
        ))
    }
}

impl GpuAdam {
    /// Fresh state (zero moments) for `len` parameters, a whole flat array.
    pub fn new(ctx: &GpuContext, len: usize, config: AdamConfig) -> Self {
        Self::strided(ctx, len, 1, 1, config)
    }

    /// Fresh state for `len` parameters taken `group` at a time every `stride`
    /// elements of the parameter array and of the gradient (the DC colour
    /// inside the SH array: group 3, stride 3 × coefficients per Gaussian).
    pub fn strided(ctx: &GpuContext, len: usize, group: u32, stride: u32, config: AdamConfig) -> Self {
        let zeros = vec![0.0f32; len.max(1)];
        Self {
            config,
            len,
            step: 0,
            group: group.max(1),
            stride: stride.max(1),
            grad_stride: stride.max(1),
            floor: NO_FLOOR,
            m: ctx.upload("adam.m", &zeros),
            v: ctx.upload("adam.v", &zeros),
            uniform: ctx.uniform("adam.params", &AdamParams::zeroed()),
        }
    }

    /// The gradient's groups every `grad_stride` elements rather than the
    /// parameters' stride (a gradient of the DC colour alone: 3).
    pub fn with_grad_stride(mut self, grad_stride: u32) -> Self {
        self.grad_stride = grad_stride.max(1);
        self
    }

    /// From the next step on, raises every updated parameter to at least
    /// `floor` after the update (`None`: no floor).
    pub fn set_floor(&mut self, floor: Option<f32>) {
        self.floor = floor.unwrap_or(NO_FLOOR);
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u32 {
        self.step
    }

    /// The steps taken and the moments, read back.
    pub fn state(&self, ctx: &GpuContext) -> Result<AdamState, GpuError> {
        let read = |b: &wgpu::Buffer| -> Result<Vec<f32>, GpuError> {
            let mut x: Vec<f32> = ctx.read(b)?;
            x.truncate(self.len);
            Ok(x)
        };
        Ok(AdamState { step: self.step, m: read(&self.m)?, v: read(&self.v)? })
    }

    /// Goes on from `state`, which must have a moment per parameter; else
    /// an error saying what it has.
    pub fn set_state(&mut self, ctx: &GpuContext, state: &AdamState) -> Result<(), String> {
        if state.m.len() != self.len || state.v.len() != self.len {
            return Err(format!(
                "expected {} moments of each order, found {} and {}",
                self.len,
                state.m.len(),
                state.v.len()
            ));
        }
        if self.len > 0 {
            ctx.write(&self.m, &state.m);
            ctx.write(&self.v, &state.v);
        }
        self.step = state.step;
        Ok(())
    }

    /// Records one update of `params` by `grads` (`len` floats of each, at
    /// their strides) into `encoder`.
    pub fn step(
        &mut self,
        ctx: &GpuContext,
        kernel: &AdamKernel,
        encoder: &mut dyn Commands,
        params: &wgpu::Buffer,
        grads: &wgpu::Buffer,
        lr: f32,
    ) {
        self.step += 1;
        let AdamConfig { beta1, beta2, eps } = self.config;
        let t = self.step as i32;
        let u = AdamParams {
            len: self.len as u32,
            beta1,
            beta2,
            eps,
            step_size: lr / (1.0 - beta1.powi(t)),
            bc2_sqrt: (1.0 - beta2.powi(t)).sqrt(),
            group: self.group,
            stride: self.stride,
            floor: self.floor,
            grad_stride: self.grad_stride,
            _pad: [0; 2],
        };
        // The uniform is written before the encoder is submitted; one buffer per
        // state is enough because each state steps at most once per submission.
        ctx.queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&u));
        kernel.0.dispatch(
            ctx,
            encoder,
            &[&self.uniform, params, grads, &self.m, &self.v],
            Kernel::groups_1d(self.len, WORKGROUP),
        );
    }
}

use bytemuck::Zeroable as _;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::style::adam::Adam;

    #[test]
    fn matches_the_cpu_adam_over_several_steps() {
        let ctx = ctx();
        let kernel = AdamKernel::new(ctx);
        let n = 1000;
        let mut p_cpu = noise(n, 1);
        let params = ctx.upload("p", &p_cpu);
        let mut cpu = Adam::new(n, AdamConfig::default());
        let mut gpu = GpuAdam::new(ctx, n, AdamConfig::default());
        for s in 0..5 {
            let g = noise(n, 10 + s);
            let grads = ctx.upload("g", &g);
            cpu.step(&mut p_cpu, &g, 0.01);
            let mut enc = ctx.encoder("adam test");
            gpu.step(ctx, &kernel, &mut enc, &params, &grads, 0.01);
            ctx.submit(enc);
        }
        let p_gpu: Vec<f32> = ctx.read(&params).expect("read back");
        let worst = p_cpu.iter().zip(&p_gpu).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-6, "largest difference {worst}");
        assert_eq!(gpu.steps(), 5);
    }

    #[test]
    fn strided_state_updates_only_its_elements() {
        // Three Gaussians with 4 SH coefficients × 3 channels: the DC is the first 3 of every 12.
        let ctx = ctx();
        let kernel = AdamKernel::new(ctx);
        let (n, stride) = (3usize, 12u32);
        let sh = noise(n * 12, 3);
        let grads_full = noise(n * 12, 4);
        let params = ctx.upload("sh", &sh);
        let grads = ctx.upload("v_sh", &grads_full);
        let mut gpu = GpuAdam::strided(ctx, n * 3, 3, stride, AdamConfig::default());
        let mut enc = ctx.encoder("adam strided");
        gpu.step(ctx, &kernel, &mut enc, &params, &grads, 0.01);
        ctx.submit(enc);
        let out: Vec<f32> = ctx.read(&params).expect("read back");
        let mut dc: Vec<f32> = (0..n).flat_map(|i| sh[i * 12..i * 12 + 3].to_vec()).collect();
        let v_dc: Vec<f32> = (0..n).flat_map(|i| grads_full[i * 12..i * 12 + 3].to_vec()).collect();
        Adam::new(n * 3, AdamConfig::default()).step(&mut dc, &v_dc, 0.01);
        for i in 0..n {
            for k in 0..12 {
                let want = if k < 3 { dc[i * 3 + k] } else { sh[i * 12 + k] };
                assert!((out[i * 12 + k] - want).abs() < 1e-6, "gaussian {i} coefficient {k}");
            }
        }
    }

    /// The engine's gradient holds the DC alone (3 floats a Gaussian): the
    /// same update as from a gradient laid out like the SH array.
    #[test]
    fn a_gradient_of_the_dc_alone_updates_as_the_whole_layouts() {
        let ctx = ctx();
        let kernel = AdamKernel::new(ctx);
        let (n, stride) = (40usize, 48u32);
        let sh = noise(n * 48, 7);
        let grads_full = noise(n * 48, 8);
        let v_dc: Vec<f32> = (0..n).flat_map(|i| grads_full[i * 48..i * 48 + 3].to_vec()).collect();
        let (whole, dc) = (ctx.upload("sh", &sh), ctx.upload("sh", &sh));
        let (g_whole, g_dc) = (ctx.upload("v_sh", &grads_full), ctx.upload("v_dc", &v_dc));
        let mut a = GpuAdam::strided(ctx, n * 3, 3, stride, AdamConfig::default());
        let mut b = GpuAdam::strided(ctx, n * 3, 3, stride, AdamConfig::default()).with_grad_stride(3);
        for _ in 0..3 {
            let mut enc = ctx.encoder("adam dc");
            a.step(ctx, &kernel, &mut enc, &whole, &g_whole, 0.05);
            b.step(ctx, &kernel, &mut enc, &dc, &g_dc, 0.05);
            ctx.submit(enc);
        }
        let (a, b): (Vec<f32>, Vec<f32>) = (ctx.read(&whole).expect("read"), ctx.read(&dc).expect("read"));
        assert_eq!(a, b);
        assert_ne!(a, sh, "the steps changed nothing");
    }

    #[test]
    fn the_floor_projects_the_updated_dc_only() {
        // The colour floor's setting: DC of 4 coefficients × 3 channels, some pushed below the floor.
        let ctx = ctx();
        let kernel = AdamKernel::new(ctx);
        let (n, stride) = (50usize, 12u32);
        let floor = crate::style::DC_FLOOR;
        let sh: Vec<f32> = noise(n * 12, 5).iter().map(|v| v * 2.0).collect();
        let grads_full: Vec<f32> = noise(n * 12, 6).iter().map(|v| v + 0.5).collect();
        let params = ctx.upload("sh", &sh);
        let grads = ctx.upload("v_sh", &grads_full);
        let mut gpu = GpuAdam::strided(ctx, n * 3, 3, stride, AdamConfig::default());
        let mut cpu = Adam::new(n * 3, AdamConfig::default());
        let mut dc: Vec<f32> = (0..n).flat_map(|i| sh[i * 12..i * 12 + 3].to_vec()).collect();
        let v_dc: Vec<f32> = (0..n).flat_map(|i| grads_full[i * 12..i * 12 + 3].to_vec()).collect();
        for (s, on) in [true, false, true].into_iter().enumerate() {
            gpu.set_floor(on.then_some(floor));
            let mut enc = ctx.encoder("adam floor");
            gpu.step(ctx, &kernel, &mut enc, &params, &grads, 0.5);
            ctx.submit(enc);
            cpu.step(&mut dc, &v_dc, 0.5);
            if on {
                dc.iter_mut().for_each(|v| *v = v.max(floor));
            }
            let out: Vec<f32> = ctx.read(&params).expect("read back");
            let clamped = dc.iter().filter(|&&v| v == floor).count();
            assert!(!on || clamped > 0, "step {s}: the test pushes some DC below the floor");
            for i in 0..n {
                for k in 0..12 {
                    let want = if k < 3 { dc[i * 3 + k] } else { sh[i * 12 + k] };
                    assert!((out[i * 12 + k] - want).abs() < 1e-5, "step {s} gaussian {i} coefficient {k}");
                }
            }
        }
    }

    #[test]
    fn groups_cover_large_dispatches() {
        for items in [1usize, 256, 257, 65_535 * 256, 65_536 * 256 + 1, 40_000_000] {
            let [x, y, z] = Kernel::groups_1d(items, 256);
            assert!(x <= 65_535 && z == 1);
            assert!(u64::from(x) * u64::from(y) * 256 >= items as u64, "{items}");
        }
    }
}
