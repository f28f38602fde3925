//! The command encoder the engine records into: consecutive dispatches share
//! one compute pass.
//!
//! wgpu closes a Vulkan command buffer at every compute pass and opens
//! another for the barriers it places before the next one, so a dispatch in
//! a pass of its own costs two command buffers; a step records about 190
//! dispatches. [`Encoder`] keeps one pass open across dispatches and ends it
//! only for a copy or a clear (anything that reaches the inner
//! `wgpu::CommandEncoder` through `DerefMut`) or at `finish`. Within a pass
//! wgpu still tracks each dispatch's buffers and places the barriers between
//! dispatches that one's writes and the next one's reads need, so the
//! results do not change (every GPU test runs through it).
//!
//! `GAST_GPU_PASSES=each` restores a pass per dispatch, for measuring one
//! against the other (`tools/gpu-check`'s `pass_*` arms).

use std::ops::{Deref, DerefMut};
use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};

/// Where a kernel's dispatch is recorded: the engine's [`Encoder`], or a
/// plain `wgpu::CommandEncoder` (the studio's, inside egui's callback), which
/// gives each dispatch a pass of its own.
pub trait Commands {
    /// Runs `record` on an open compute pass (labelled `label` when it opens one).
    fn compute(&mut self, label: &str, record: &mut dyn FnMut(&mut wgpu::ComputePass<'_>));

    /// The encoder itself, for copies and clears (ending an open pass first).
    fn encoder(&mut self) -> &mut wgpu::CommandEncoder;
}

impl Commands for wgpu::CommandEncoder {
    fn compute(&mut self, label: &str, record: &mut dyn FnMut(&mut wgpu::ComputePass<'_>)) {
        let mut pass =
            self.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: None });
        record(&mut pass);
    }

    fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        self
    }
}

/// Whether every dispatch gets a pass of its own (`GAST_GPU_PASSES=each`).
fn pass_per_dispatch() -> bool {
    static EACH: OnceLock<bool> = OnceLock::new();
    *EACH.get_or_init(|| std::env::var("GAST_GPU_PASSES").is_ok_and(|v| v.trim() == "each"))
}

/// A `wgpu::CommandEncoder` that keeps a compute pass open across
/// dispatches ([`crate::gpu::GpuContext::encoder`] makes one).
pub struct Encoder {
    // Declared first, so that it is dropped before the encoder it locks.
    pass: Option<wgpu::ComputePass<'static>>,
    inner: wgpu::CommandEncoder,
    /// Compute passes begun on the context ([`crate::gpu::GpuContext::passes_begun`]).
    passes: Arc<AtomicU64>,
    each: bool,
}

impl std::fmt::Debug for Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Encoder").field("pass_open", &self.pass.is_some()).field("each", &self.each).finish()
    }
}

impl Encoder {
    pub(crate) fn new(inner: wgpu::CommandEncoder, passes: Arc<AtomicU64>) -> Self {
        Self { pass: None, inner, passes, each: pass_per_dispatch() }
    }

    /// Ends the open pass, if any.
    fn end_pass(&mut self) {
        self.pass = None;
    }

    /// The commands recorded, the open pass ended.
    pub fn finish(mut self) -> wgpu::CommandBuffer {
        self.end_pass();
        self.inner.finish()
    }
}

impl Commands for Encoder {
    fn compute(&mut self, label: &str, record: &mut dyn FnMut(&mut wgpu::ComputePass<'_>)) {
        if self.each {
            self.end_pass();
        }
        let pass = match &mut self.pass {
            Some(pass) => pass,
            open @ None => {
                self.passes.fetch_add(1, Ordering::Relaxed);
                let desc = wgpu::ComputePassDescriptor {
                    label: Some(if self.each { label } else { "gast.dispatches" }),
                    timestamp_writes: None,
                };
                open.insert(self.inner.begin_compute_pass(&desc).forget_lifetime())
            }
        };
        record(pass);
    }

    fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        self.end_pass();
        &mut self.inner
    }
}

impl Deref for Encoder {
    type Target = wgpu::CommandEncoder;

    fn deref(&self) -> &wgpu::CommandEncoder {
        &self.inner
    }
}

/// Copies, clears and the rest of the encoder's own commands: the open pass
/// ends first, so they run after the dispatches recorded before them.
impl DerefMut for Encoder {
    fn deref_mut(&mut self) -> &mut wgpu::CommandEncoder {
        self.encoder()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::ctx;
    use crate::gpu::{Bind, Kernel};

    /// Dispatches that read what the one before wrote, a copy between them,
    /// and a second encoder that gives each dispatch its own pass: the same
    /// values, in two passes against five.
    #[test]
    fn dependent_dispatches_share_a_pass_until_a_copy() {
        let ctx = ctx();
        let src = "@group(0) @binding(0) var<storage, read_write> v: array<f32>;
@compute @workgroup_size(64) fn twice_plus_one(@builtin(global_invocation_id) g: vec3<u32>) {
    if g.x < arrayLength(&v) { v[g.x] = v[g.x] * 2.0 + 1.0; }
}";
        let k = Kernel::new(ctx, "encoder test", src, "twice_plus_one", &[Bind::ReadWrite]);
        // A counter of its own: other tests record on the shared context meanwhile.
        let run = |each: bool| {
            let passes = Arc::new(AtomicU64::new(0));
            let inner = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
            let mut enc = Encoder { each, ..Encoder::new(inner, Arc::clone(&passes)) };
            let (v, copy) = (ctx.zeros("v", 1000), ctx.zeros("copy", 1000));
            for _ in 0..3 {
                k.dispatch(ctx, &mut enc, &[&v], Kernel::groups_1d(1000, 64));
            }
            enc.copy_buffer_to_buffer(&v, 0, &copy, 0, 4000);
            for _ in 0..2 {
                k.dispatch(ctx, &mut enc, &[&v], Kernel::groups_1d(1000, 64));
            }
            ctx.submit(enc);
            let (v, copy): (Vec<f32>, Vec<f32>) = (ctx.read(&v).expect("v"), ctx.read(&copy).expect("copy"));
            (v, copy, passes.load(Ordering::Relaxed))
        };
        let (v, copy, passes) = run(false);
        // 0 → 1 → 3 → 7 (the copy) → 15 → 31: each dispatch saw the one before.
        assert!(copy.iter().all(|&x| x == 7.0) && v.iter().all(|&x| x == 31.0), "{} {}", copy[0], v[0]);
        assert_eq!(passes, 2);
        assert_eq!(run(true), (v, copy, 5));
    }
}
