//! The optimiser's Gaussians as a viewer on the same device may read them:
//! handles to the engine's parameter buffers, where each optimised Gaussian
//! sits in the whole scene, and how many steps the buffers hold.
//!
//! A viewer that shares the engine's device draws the run from these buffers
//! with device-side copies only, instead of a CPU snapshot per repaint.
//!
//! What a reader may rely on: the engine updates the buffers in place, one
//! step per queue submission ([`super::GpuEngine::step`] records a whole step
//! in one command encoder). [`LiveGaussians::publish`] is called after that
//! submission (release), and a reader that sees the new count (acquire) and
//! then submits its copy on the same queue is ordered after the step: wgpu runs
//! one queue's submissions in order and puts the barriers between a step's
//! writes and a later submission's reads. A step submitted meanwhile by the
//! worker may land before the copy; the copy then holds that newer whole step,
//! never a half-updated one, and the reader copies again when it sees the count.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::{GpuContext, GpuGaussians};
use crate::scene::Gaussians;

/// The engine's parameter buffers (shared handles, not copies), the whole
/// scene they are scattered into, and the number of steps they hold. Cheap to
/// clone; every clone sees the same step count.
#[derive(Clone, Debug)]
pub struct LiveGaussians {
    device: wgpu::Device,
    gaussians: Arc<GpuGaussians>,
    base: Arc<Gaussians>,
    keep: Arc<Vec<u32>>,
    steps: Arc<AtomicU64>,
}

impl LiveGaussians {
    /// Handles to `g`'s buffers on `ctx`'s device; `base` is the whole scene
    /// (the Gaussians nobody optimises included) and `keep[j]` the index in
    /// `base` of the `j`-th Gaussian of `g` ([`LiveGaussians::problem`] says
    /// whether they fit together).
    pub fn new(ctx: &GpuContext, g: &GpuGaussians, base: Arc<Gaussians>, keep: Arc<Vec<u32>>) -> Self {
        let gaussians = GpuGaussians {
            len: g.len,
            sh_degree: g.sh_degree,
            means: g.means.clone(),
            log_scales: g.log_scales.clone(),
            quats: g.quats.clone(),
            opacity_logits: g.opacity_logits.clone(),
            sh: g.sh.clone(),
        };
        Self { device: ctx.device.clone(), gaussians: Arc::new(gaussians), base, keep, steps: Arc::default() }
    }

    /// Why a viewer cannot use these buffers as described, if it cannot: the
    /// index map and the buffers disagree, or the SH degrees differ.
    pub fn problem(&self) -> Option<String> {
        let (n, m) = (self.base.len(), self.keep.len());
        if m != self.gaussians.len {
            return Some(format!("{m} indices for {} optimised Gaussians", self.gaussians.len));
        }
        if let Some(&i) = self.keep.iter().find(|&&i| i as usize >= n) {
            return Some(format!("index {i} outside the scene of {n} Gaussians"));
        }
        if self.base.sh_degree != self.gaussians.sh_degree {
            return Some(format!(
                "the scene has SH degree {}, the optimised Gaussians {}",
                self.base.sh_degree, self.gaussians.sh_degree
            ));
        }
        None
    }

    /// Whether the buffers live on `device` (a viewer on another device needs snapshots).
    pub fn is_on(&self, device: &wgpu::Device) -> bool {
        self.device == *device
    }

    /// Whether `self` and `other` are handles to the same run's buffers.
    pub fn same_run(&self, other: &LiveGaussians) -> bool {
        Arc::ptr_eq(&self.steps, &other.steps)
    }

    /// The engine's parameter buffers.
    pub fn gaussians(&self) -> &GpuGaussians {
        &self.gaussians
    }

    /// The whole scene the optimised Gaussians are scattered into (colour-matched).
    pub fn base(&self) -> &Arc<Gaussians> {
        &self.base
    }

    /// Index in [`LiveGaussians::base`] of each optimised Gaussian.
    pub fn keep(&self) -> &[u32] {
        &self.keep
    }

    /// Steps whose results the buffers hold (read with acquire ordering: work
    /// submitted afterwards on the device's queue runs after those steps).
    pub fn steps(&self) -> u64 {
        self.steps.load(Ordering::Acquire)
    }

    /// Records that `steps` steps have been submitted (release ordering); the
    /// engine's owner calls this after each step.
    pub fn publish(&self, steps: u64) {
        self.steps.store(steps, Ordering::Release);
    }
}
