//! The GPU VGG behind the CPU's [`FeatureNet`] interface: upload, run, read
//! back. Not the optimisation step's path (that keeps everything on the
//! device), but what lets anything written against a `FeatureNet` (Stage 1's
//! style features, `step_loss`, the golden checks, tests) run its network on
//! the GPU unchanged.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::GpuContext;
use super::vgg::{GpuVgg, GpuVggState, GpuVggWorkspace};
use crate::style::step::{FeatureMap, FeatureNet};
use crate::vision::Vgg;
use crate::vision::vgg::FEATURE_CHANNELS;

/// VGG relu3 on a GPU, as a [`FeatureNet`].
#[derive(Debug)]
pub struct GpuFeatureNet {
    ctx: GpuContext,
    vgg: GpuVgg,
    /// One workspace per input size met so far (submissions on one queue run
    /// in order, so concurrent calls can share one).
    workspaces: Mutex<HashMap<(usize, usize), Arc<GpuVggWorkspace>>>,
}

/// What [`GpuFeatureNet`]'s backward pass needs: the forward pass's device buffers.
#[derive(Debug)]
pub struct GpuFeatureState {
    size: (usize, usize),
    state: GpuVggState,
}

impl GpuFeatureNet {
    /// Uploads `vgg`'s weights to `ctx`'s device.
    pub fn new(ctx: GpuContext, vgg: &Vgg) -> Self {
        let net = GpuVgg::new(&ctx, vgg);
        Self { ctx, vgg: net, workspaces: Mutex::new(HashMap::new()) }
    }

    fn workspace(&self, h: usize, w: usize) -> Arc<GpuVggWorkspace> {
        let mut map = self.workspaces.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        map.entry((h, w)).or_insert_with(|| Arc::new(self.vgg.workspace(&self.ctx, h, w))).clone()
    }

    fn run(&self, rgb: &[f32], h: usize, w: usize) -> (FeatureMap, GpuFeatureState) {
        assert_eq!(rgb.len(), h * w * 3, "VGG input must be h·w·3 RGB values");
        let ctx = &self.ctx;
        let state = GpuVggState::new(ctx, h, w);
        let (fh, fw) = state.feature_size();
        let mut map = FeatureMap { channels: FEATURE_CHANNELS, height: fh, width: fw, data: Vec::new() };
        if fh * fw > 0 {
            let ws = self.workspace(h, w);
            let input = ctx.upload("vgg.input", rgb);
            let mut enc = ctx.encoder("vgg forward");
            self.vgg.forward(ctx, &mut enc, &ws, &input, &state);
            ctx.submit(enc);
            map.data = read(ctx, state.features(), FEATURE_CHANNELS * fh * fw);
        }
        (map, GpuFeatureState { size: (h, w), state })
    }
}

/// Reads `len` floats of `buffer`.
///
/// # Panics
/// When the device cannot hand the buffer back (device lost): `FeatureNet`
/// has no error path, and the CPU engine is the fallback for a missing GPU.
fn read(ctx: &GpuContext, buffer: &wgpu::Buffer, len: usize) -> Vec<f32> {
    match ctx.read_range::<f32>(buffer, 0, (len * 4) as u64) {
        Ok(v) => v,
        Err(e) => panic!("GPU VGG: {e}"),
    }
}

impl FeatureNet for GpuFeatureNet {
    type State = GpuFeatureState;

    fn features(&self, rgb: &[f32], h: usize, w: usize) -> FeatureMap {
        self.run(rgb, h, w).0
    }

    fn forward(&self, rgb: &[f32], h: usize, w: usize) -> (FeatureMap, GpuFeatureState) {
        self.run(rgb, h, w)
    }

    fn backward(&self, state: &GpuFeatureState, v_features: &[f32]) -> Vec<f32> {
        let ctx = &self.ctx;
        let (h, w) = state.size;
        let (fh, fw) = state.state.feature_size();
        assert_eq!(v_features.len(), FEATURE_CHANNELS * fh * fw, "backward: v_features has the wrong size");
        if fh * fw == 0 {
            return vec![0.0; h * w * 3];
        }
        let ws = self.workspace(h, w);
        let v = ctx.upload("vgg.v_features", v_features);
        let v_input = ctx.zeros("vgg.v_input", h * w * 3);
        let mut enc = ctx.encoder("vgg backward");
        self.vgg.backward(ctx, &mut enc, &ws, &state.state, &v, &v_input);
        ctx.submit(enc);
        read(ctx, &v_input, h * w * 3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};
    use crate::vision::vgg::tests::random_vgg;

    #[test]
    fn runs_behind_the_feature_net_interface_like_the_cpu_vgg() {
        let cpu = random_vgg(5);
        let gpu = GpuFeatureNet::new(ctx().clone(), &cpu);
        let (h, w) = (16, 20);
        let rgb: Vec<f32> = noise(h * w * 3, 8).iter().map(|v| 0.5 + 0.4 * v).collect();
        let (fc, sc) = FeatureNet::forward(&cpu, &rgb, h, w);
        let (fg, sg) = gpu.forward(&rgb, h, w);
        assert_eq!((fg.channels, fg.height, fg.width), (fc.channels, fc.height, fc.width));
        let largest = fc.data.iter().fold(1f32, |a, v| a.max(v.abs()));
        let err = fc.data.iter().zip(&fg.data).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        assert!(err < 1e-4 * largest, "features differ by {err} (largest {largest})");
        let v = noise(fc.data.len(), 9);
        let (gc, gg) = (FeatureNet::backward(&cpu, &sc, &v), gpu.backward(&sg, &v));
        let largest = gc.iter().fold(0f32, |a, v| a.max(v.abs()));
        let err = gc.iter().zip(&gg).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        assert!(err < 1e-3 * largest, "input gradients differ by {err} (largest {largest})");
        // Too small for relu3: empty features, zero gradient, as on the CPU.
        let (tiny, st) = gpu.forward(&[0.5; 3 * 3 * 3], 3, 3);
        assert!(tiny.data.is_empty() && gpu.backward(&st, &[]).iter().all(|&g| g == 0.0));
    }
}
