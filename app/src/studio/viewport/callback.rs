//! The viewport inside egui's frame: the paint callback that hands the
//! scenes of the frame (the loaded one, the run's snapshot or its GPU buffers)
//! to the [`SplatRenderer`], renders both sides and blits them split.

use std::sync::{Arc, Mutex};

use gast_core::Camera;
use gast_core::gpu::{GpuContext, LiveGaussians};

use super::gpu_types::BlitUniform;
use super::{FrameStats, SharedGaussians, Side, SplatRenderer, ViewportNotes, blit};

/// What lives in egui-wgpu's callback resources for the viewport.
pub struct ViewportResources {
    renderer: SplatRenderer,
    blit: blit::BlitPipeline,
    blit_bind: Option<wgpu::BindGroup>,
}

impl ViewportResources {
    /// Pipelines for a device and egui's output format.
    pub fn new(device: &wgpu::Device, target_format: wgpu::TextureFormat) -> Self {
        Self {
            renderer: SplatRenderer::new(device),
            blit: blit::BlitPipeline::new(device, target_format),
            blit_bind: None,
        }
    }

    /// Sorts by depth on the GPU (`ctx` wraps the same device).
    pub fn use_gpu_sort(&mut self, ctx: GpuContext) {
        self.renderer.use_gpu_sort(ctx);
    }
}

/// A scene handed to the viewport: a version number (changes when the
/// Gaussians change) and the Gaussians.
#[derive(Clone)]
pub struct SceneRef {
    /// Bumped by the owner on every change.
    pub version: u64,
    /// The Gaussians.
    pub gaussians: SharedGaussians,
}

/// A running optimisation's GPU buffers handed to the viewport, with a
/// version number the owner gives each run's handle.
#[derive(Clone)]
pub struct LiveRef {
    /// Unique among the versions of [`SceneRef`]s given to the same side.
    pub version: u64,
    /// The engine's buffers.
    pub live: LiveGaussians,
}

/// One frame of the viewport, as an egui-wgpu paint callback.
pub struct ViewportCallback {
    /// The camera (its size is the viewport's size in physical pixels).
    pub camera: Camera,
    /// The original scene.
    pub before: Option<SceneRef>,
    /// The current snapshot, when there is one.
    pub after: Option<SceneRef>,
    /// The running optimisation's buffers: drawn as "after" instead of the
    /// snapshot when the viewport can (same device, GPU sort).
    pub live: Option<LiveRef>,
    /// Split position in [0, 1]: left of it shows `before`.
    pub split: f32,
    /// Where egui paints the callback, in points (the blit places the split
    /// line by the framebuffer's pixel columns within it).
    pub rect: egui::Rect,
    /// Background colour.
    pub background: [f32; 3],
    /// Where the frame's statistics go.
    pub stats: Arc<Mutex<FrameStats>>,
    /// Where problems with the scenes go.
    pub notes: Arc<Mutex<ViewportNotes>>,
}

impl egui_wgpu::CallbackTrait for ViewportCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        screen: &egui_wgpu::ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(res) = resources.get_mut::<ViewportResources>() else { return Vec::new() };
        let r = &mut res.renderer;
        r.begin_frame();
        for (side, scene) in [(Side::Before, &self.before), (Side::After, &self.after)] {
            let live = if side == Side::After { self.live.as_ref() } else { None };
            let drawn_live = live.is_some_and(|l| {
                let result = r.set_live_scene(device, side, l.version, &l.live);
                if let Ok(mut notes) = self.notes.lock()
                    && notes.live_version != l.version
                {
                    notes.live_version = l.version;
                    match &result {
                        Ok(Some(w)) => notes.warnings.push(w.clone()),
                        Ok(None) => {}
                        Err(e) => notes.warnings.push(format!("the viewport draws CPU snapshots of the run: {e}")),
                    }
                }
                result.is_ok()
            });
            match scene {
                _ if drawn_live => {}
                Some(s) => {
                    let result = r.set_scene(device, side, s.version, &s.gaussians);
                    if let Ok(mut notes) = self.notes.lock()
                        && notes.versions[side as usize] != s.version
                    {
                        notes.versions[side as usize] = s.version;
                        match result {
                            Ok(Some(w)) => notes.warnings.push(w),
                            Ok(None) => {}
                            Err(e) => notes.errors.push(e),
                        }
                    }
                }
                None => r.clear_scene(side),
            }
        }
        // Draw the "before" side even without a scene so that the target exists (and is clear).
        r.render(device, queue, encoder, Side::Before, &self.camera);
        let has_after = (self.after.is_some() || self.live.is_some()) && self.split < 1.0;
        if has_after {
            r.render(device, queue, encoder, Side::After, &self.camera);
        }
        if let Ok(mut s) = self.stats.lock() {
            *s = r.stats;
        }
        let Some((_, before)) = r.target(Side::Before) else { return Vec::new() };
        let after = if has_after { r.target(Side::After).map(|t| t.1).unwrap_or(before) } else { before };
        let split = if has_after { self.split } else { 1.0 };
        let bg = self.background;
        // The viewport egui sets for `paint`, in framebuffer pixels.
        let px = egui::PaintCallbackInfo {
            viewport: self.rect,
            clip_rect: self.rect,
            pixels_per_point: screen.pixels_per_point,
            screen_size_px: screen.size_in_pixels,
        }
        .viewport_in_pixels();
        let params = BlitUniform {
            background: [bg[0], bg[1], bg[2], 1.0],
            split: [split, px.left_px as f32, px.width_px.max(1) as f32, 0.0],
        };
        res.blit_bind = Some(res.blit.prepare(device, queue, params, before, after));
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(res) = resources.get::<ViewportResources>()
            && let Some(bind) = &res.blit_bind
        {
            res.blit.draw(pass, bind);
        }
    }
}
