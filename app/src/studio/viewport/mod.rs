//! The wgpu splat viewport: the scene's Gaussians on the GPU, projected by a
//! compute pass, sorted back to front on the CPU, drawn as instanced quads into
//! an offscreen float target, and blitted into egui's frame by a paint callback.
//!
//! The same [`SplatRenderer`] renders headless (tests, benchmarks) and inside the
//! window, so what the tests compare is what the user sees.

pub mod bench;
pub mod blit;
pub mod gpu_types;
pub mod sort;
pub mod splat_draw;
pub mod splat_project;
pub mod splat_sort;

use std::sync::{Arc, Mutex};
use std::time::Instant;

use gast_core::gpu::GpuContext;
use gast_core::{Camera, Gaussians};
use glam::Vec3;
use wgpu::util::DeviceExt as _;

use gpu_types::{BlitUniform, ProjectedSplat, ViewUniform};

/// Gaussians shared without copying: a loaded scene, or a session snapshot as
/// it came out of the slot (snapshots are large and arrive often).
#[derive(Clone, Debug)]
pub enum SharedGaussians {
    /// Gaussians the studio owns (a loaded scene).
    Owned(Arc<Gaussians>),
    /// The Gaussians inside a session snapshot.
    Snapshot(Arc<gast_core::session::Snapshot>),
}

impl std::ops::Deref for SharedGaussians {
    type Target = Gaussians;
    fn deref(&self) -> &Gaussians {
        match self {
            SharedGaussians::Owned(g) => g,
            SharedGaussians::Snapshot(s) => &s.gaussians,
        }
    }
}

impl From<Arc<Gaussians>> for SharedGaussians {
    fn from(g: Arc<Gaussians>) -> Self {
        SharedGaussians::Owned(g)
    }
}

impl SharedGaussians {
    /// The Gaussians behind an `Arc` of their own (a copy only for snapshots).
    pub fn to_arc(&self) -> Arc<Gaussians> {
        match self {
            SharedGaussians::Owned(g) => g.clone(),
            SharedGaussians::Snapshot(s) => Arc::new(s.gaussians.clone()),
        }
    }
}

/// A scene's Gaussians in GPU buffers, with the buffers its passes write.
struct GpuScene {
    version: u64,
    gaussians: SharedGaussians,
    view: wgpu::Buffer,
    order: wgpu::Buffer,
    project_bind: wgpu::BindGroup,
    draw_bind: wgpu::BindGroup,
    sh_words: u32,
    sh_split: u32,
    /// The SH degree drawn (lower than the scene's when the coefficients do not fit).
    sh_degree: u32,
    /// The depth axis (row z of R, t.z) the order buffer was sorted for, and how many are in front.
    sorted_for: Option<([f32; 4], u32)>,
    /// The GPU sort's workspace, when the renderer sorts on the GPU.
    gpu_sort: Option<splat_sort::SceneSort>,
    /// Kept alive for the bind groups.
    _buffers: Vec<wgpu::Buffer>,
    /// The projection pass's output (the GPU sort reads the depths there).
    projected: wgpu::Buffer,
}

/// An offscreen render target.
struct Target {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
}

/// Timings of the last frame, for the status bar and the benchmark.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameStats {
    /// Gaussians drawn (in front of the camera), summed over the renders of the frame.
    pub drawn: usize,
    /// Milliseconds spent in the CPU depth sort.
    pub sort_ms: f32,
    /// Milliseconds spent recording and uploading (sort included).
    pub prepare_ms: f32,
}

/// What the viewport has to tell the user about the scenes it was given
/// (a scene it cannot draw, a lowered SH degree); the UI shows it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewportNotes {
    /// Scene versions the notes are about.
    pub versions: [u64; 2],
    /// Errors (the scene is not drawn).
    pub errors: Vec<String>,
    /// Warnings (drawn with a limitation).
    pub warnings: Vec<String>,
}

/// Packs the SH coefficients of `g` up to `degree` (≤ the scene's) as f16 pairs,
/// `words` u32 per Gaussian.
pub fn pack_sh_f16(g: &Gaussians, degree: u32) -> (Vec<u32>, u32) {
    let per = gast_core::scene::sh_coeffs_for_degree(degree.min(g.sh_degree)) * 3;
    let words = per.div_ceil(2);
    let mut out = vec![0u32; g.len() * words];
    for i in 0..g.len() {
        let sh = &g.sh_of(i)[..per];
        for (k, pair) in sh.chunks(2).enumerate() {
            let lo = half::f16::from_f32(pair[0]).to_bits() as u32;
            let hi = pair.get(1).map(|&v| half::f16::from_f32(v).to_bits() as u32).unwrap_or(0);
            out[i * words + k] = lo | (hi << 16);
        }
    }
    (out, words as u32)
}

/// The per-Gaussian geometry as three vec4 (mean + opacity logit, log-scale, quaternion).
pub fn pack_geometry(g: &Gaussians) -> Vec<[f32; 4]> {
    let mut out = Vec::with_capacity(g.len() * 3);
    for i in 0..g.len() {
        let m = g.means[i];
        let s = g.log_scales[i];
        out.push([m[0], m[1], m[2], g.opacity_logits[i]]);
        out.push([s[0], s[1], s[2], 0.0]);
        out.push(g.quats[i]);
    }
    out
}

/// A bind-group layout entry for a uniform buffer holding one `T`.
fn uniform_entry<T>(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64),
        },
        count: None,
    }
}

fn storage_init(device: &wgpu::Device, label: &str, bytes: &[u8]) -> wgpu::Buffer {
    // Bindings may not be empty: pad to at least one vec4.
    let mut padded;
    let contents = if bytes.len() < 16 {
        padded = bytes.to_vec();
        padded.resize(16, 0);
        &padded[..]
    } else {
        bytes
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
    })
}

/// The splat renderer: pipelines, up to two scenes ("before" and "after") and their targets.
pub struct SplatRenderer {
    project: splat_project::ProjectPipeline,
    draw: splat_draw::DrawPipeline,
    scenes: [Option<GpuScene>; 2],
    targets: [Option<Target>; 2],
    /// Statistics of the last [`SplatRenderer::render`] calls since [`SplatRenderer::begin_frame`].
    pub stats: FrameStats,
    /// Bytes one SH binding may hold; the device's limit unless a test lowers it.
    pub sh_binding_limit: Option<usize>,
    /// Sorts on the GPU when set ([`SplatRenderer::use_gpu_sort`]); on the CPU otherwise.
    gpu_sort: Option<splat_sort::DepthSortKernels>,
}

/// Which scene slot: the original Gaussians or the current (optimised) ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The scene as loaded.
    Before = 0,
    /// The newest snapshot of a running optimisation.
    After = 1,
}

impl SplatRenderer {
    /// Builds the pipelines.
    pub fn new(device: &wgpu::Device) -> Self {
        Self {
            project: splat_project::ProjectPipeline::new(device),
            draw: splat_draw::DrawPipeline::new(device),
            scenes: [None, None],
            targets: [None, None],
            stats: FrameStats::default(),
            sh_binding_limit: None,
            gpu_sort: None,
        }
    }

    /// Sorts by depth on the GPU from now on (scenes set afterwards), on
    /// `ctx`, which must wrap the device the renderer draws with.
    pub fn use_gpu_sort(&mut self, ctx: GpuContext) {
        self.gpu_sort = Some(splat_sort::DepthSortKernels::new(ctx));
    }

    /// The back-to-front order buffer of `side` (after a render), for tests.
    #[cfg(test)]
    pub fn order_buffer(&self, side: Side) -> Option<&wgpu::Buffer> {
        self.scenes[side as usize].as_ref().map(|s| &s.order)
    }

    /// Uploads `g` into `side` unless that version is already there. A scene whose
    /// geometry does not fit one storage binding is refused; SH coefficients that
    /// do not fit two bindings are drawn at a lower degree (both said in the result).
    pub fn set_scene(
        &mut self,
        device: &wgpu::Device,
        side: Side,
        version: u64,
        g: &SharedGaussians,
    ) -> Result<Option<String>, String> {
        if self.scenes[side as usize].as_ref().is_some_and(|s| s.version == version) {
            return Ok(None);
        }
        self.scenes[side as usize] = None;
        let n = g.len();
        let device_limit = device.limits().max_storage_buffer_binding_size as usize;
        if n * std::mem::size_of::<ProjectedSplat>() > device_limit {
            return Err(format!(
                "{n} Gaussians need {} MB per storage binding, this GPU allows {} MB; the viewport cannot draw the scene",
                (n * std::mem::size_of::<ProjectedSplat>()) >> 20,
                device_limit >> 20
            ));
        }
        // One binding holds at most max_storage_buffer_binding_size bytes: the SH go in two.
        let limit = self.sh_binding_limit.unwrap_or(device_limit);
        let mut degree = g.sh_degree;
        let bytes_per = |d: u32| (gast_core::scene::sh_coeffs_for_degree(d) * 3).div_ceil(2) * 4;
        while degree > 0 && n * bytes_per(degree) > 2 * (limit / bytes_per(degree)) * bytes_per(degree) {
            degree -= 1;
        }
        let note = (degree < g.sh_degree).then(|| format!("the viewport draws SH degree {degree} of {}: the coefficients of {n} Gaussians do not fit the GPU's storage bindings", g.sh_degree));
        let geom = storage_init(device, "splat geometry", bytemuck::cast_slice(&pack_geometry(g)));
        let (sh, words) = pack_sh_f16(g, degree);
        let bytes_per = words as usize * 4;
        let split = if n * bytes_per <= limit { n } else { (limit / bytes_per).min(n) };
        let sh_a = storage_init(device, "splat sh a", bytemuck::cast_slice(&sh[..split * words as usize]));
        let sh_b = storage_init(device, "splat sh b", bytemuck::cast_slice(&sh[split * words as usize..]));
        let projected = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat projected"),
            size: (n.max(1) * std::mem::size_of::<ProjectedSplat>()) as u64,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let order = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat order"),
            size: (n.max(4) * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let view = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat view"),
            size: std::mem::size_of::<ViewUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let project_bind = self.project.bind_group(device, &view, &geom, &sh_a, &sh_b, &projected);
        let draw_bind = self.draw.bind_group(device, &view, &projected, &order);
        self.scenes[side as usize] = Some(GpuScene {
            version,
            gaussians: g.clone(),
            view,
            order,
            project_bind,
            draw_bind,
            sh_words: words,
            sh_split: split as u32,
            sh_degree: degree,
            sorted_for: None,
            gpu_sort: self.gpu_sort.as_ref().map(|k| k.scene(n)),
            _buffers: vec![geom, sh_a, sh_b],
            projected,
        });
        Ok(note)
    }

    /// Forgets the scene of `side`.
    pub fn clear_scene(&mut self, side: Side) {
        self.scenes[side as usize] = None;
    }

    /// Resets the per-frame statistics.
    pub fn begin_frame(&mut self) {
        self.stats = FrameStats::default();
    }

    fn ensure_target(&mut self, device: &wgpu::Device, side: Side, width: u32, height: u32) {
        let slot = &mut self.targets[side as usize];
        if slot.as_ref().is_some_and(|t| t.texture.width() == width && t.texture.height() == height) {
            return;
        }
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("splat target"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: splat_draw::TARGET_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        *slot = Some(Target { texture, view });
    }

    /// Records the render of `side` from `cam` into its target (premultiplied
    /// RGBA, transparent where nothing was drawn). Returns false when `side` has no scene.
    pub fn render(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        side: Side,
        cam: &Camera,
    ) -> bool {
        let started = Instant::now();
        let (w, h) = (cam.width.max(1), cam.height.max(1));
        self.ensure_target(device, side, w, h);
        let Some(scene) = &mut self.scenes[side as usize] else { return false };
        if let (Some(kernels), Some(sort)) = (&self.gpu_sort, &scene.gpu_sort) {
            // Project, then sort every splat on the device (culled ones last, drawn degenerate).
            let n = scene.gaussians.len() as u32;
            let uniform = ViewUniform::new(cam, n, scene.sh_degree, scene.sh_words, scene.sh_split, [0.0; 3]);
            queue.write_buffer(&scene.view, 0, bytemuck::bytes_of(&uniform));
            self.project.dispatch(encoder, &scene.project_bind, n);
            kernels.record(encoder, sort, &scene.projected, &scene.order);
            let Some(target) = &self.targets[side as usize] else { return false };
            self.draw.draw(encoder, &target.view, &scene.draw_bind, n);
            self.stats.drawn += n as usize;
            self.stats.prepare_ms += started.elapsed().as_secs_f32() * 1e3;
            return true;
        }
        let g = &scene.gaussians;
        let row_z = cam.rotation.row(2);
        let axis = [row_z.x, row_z.y, row_z.z, cam.translation.z];
        // A still camera (most repaints) keeps the previous order.
        let visible = match scene.sorted_for {
            Some((a, n)) if a == axis => n,
            _ => {
                let sort_start = Instant::now();
                let order = sort::back_to_front(&g.means, Vec3::new(row_z.x, row_z.y, row_z.z), cam.translation.z);
                self.stats.sort_ms += sort_start.elapsed().as_secs_f32() * 1e3;
                if !order.is_empty() {
                    queue.write_buffer(&scene.order, 0, bytemuck::cast_slice(&order));
                }
                scene.sorted_for = Some((axis, order.len() as u32));
                order.len() as u32
            }
        };
        let scene = &self.scenes[side as usize].as_ref().expect("scene checked above");
        let g = &scene.gaussians;
        let uniform = ViewUniform::new(cam, g.len() as u32, scene.sh_degree, scene.sh_words, scene.sh_split, [0.0; 3]);
        queue.write_buffer(&scene.view, 0, bytemuck::bytes_of(&uniform));
        self.project.dispatch(encoder, &scene.project_bind, g.len() as u32);
        let Some(target) = &self.targets[side as usize] else { return false };
        self.draw.draw(encoder, &target.view, &scene.draw_bind, visible);
        self.stats.drawn += visible as usize;
        self.stats.prepare_ms += started.elapsed().as_secs_f32() * 1e3;
        true
    }

    /// The target of `side` (after a render).
    pub fn target(&self, side: Side) -> Option<(&wgpu::Texture, &wgpu::TextureView)> {
        self.targets[side as usize].as_ref().map(|t| (&t.texture, &t.view))
    }
}

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

/// One frame of the viewport, as an egui-wgpu paint callback.
pub struct ViewportCallback {
    /// The camera (its size is the viewport's size in physical pixels).
    pub camera: Camera,
    /// The original scene.
    pub before: Option<SceneRef>,
    /// The current snapshot, when there is one.
    pub after: Option<SceneRef>,
    /// Split position in [0, 1]: left of it shows `before`.
    pub split: f32,
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
        _screen: &egui_wgpu::ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(res) = resources.get_mut::<ViewportResources>() else { return Vec::new() };
        let r = &mut res.renderer;
        r.begin_frame();
        for (side, scene) in [(Side::Before, &self.before), (Side::After, &self.after)] {
            match scene {
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
        let has_after = self.after.is_some() && self.split < 1.0;
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
        let params = BlitUniform { background: [bg[0], bg[1], bg[2], 1.0], split: [split, 0.0, 0.0, 0.0] };
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

/// Converts an IEEE half float to f32.
#[cfg_attr(not(test), allow(dead_code))] // tests and read-back
pub fn f16_to_f32(bits: u16) -> f32 {
    half::f16::from_bits(bits).to_f32()
}

/// Reads back a [`splat_draw::TARGET_FORMAT`] texture as premultiplied RGBA f32
/// (blocking; for tests, benchmarks and exports).
#[cfg_attr(not(test), allow(dead_code))] // tests; GPU exports will use it
pub fn read_target(device: &wgpu::Device, queue: &wgpu::Queue, texture: &wgpu::Texture) -> Vec<[f32; 4]> {
    let (w, h) = (texture.width(), texture.height());
    let row = (w * 8).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: (row * h) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(h) },
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    queue.submit([encoder.finish()]);
    let slice = buffer.slice(..);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    let Ok(data) = slice.get_mapped_range() else {
        return vec![[0.0; 4]; (w * h) as usize];
    };
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h as usize {
        let line = &data[y * row as usize..y * row as usize + w as usize * 8];
        for px in line.chunks_exact(8) {
            let c = |k: usize| f16_to_f32(u16::from_le_bytes([px[2 * k], px[2 * k + 1]]));
            out.push([c(0), c(1), c(2), c(3)]);
        }
    }
    out
}
