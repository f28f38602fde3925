//! The wgpu splat viewport: the scene's Gaussians on the GPU, projected by a
//! compute pass, sorted back to front (on the GPU in the studio), drawn as
//! instanced quads into an offscreen float target, and blitted into egui's
//! frame by a paint callback. A run whose GPU engine shares the viewport's
//! device is drawn from the engine's buffers ([`splat_from_engine`]); other
//! runs from their CPU snapshots.
//!
//! The same [`SplatRenderer`] renders headless (tests, benchmarks) and inside the
//! window, so what the tests compare is what the user sees.

pub mod bench;
pub mod bench_live;
pub mod blit;
mod callback;
pub mod gpu_types;
pub mod sort;
pub mod splat_draw;
pub mod splat_from_engine;
#[cfg(test)]
mod splat_from_engine_tests;
pub mod splat_project;
pub mod splat_sort;
#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::time::Instant;

use gast_core::gpu::{GpuContext, LiveGaussians};
use gast_core::{Camera, Gaussians};
use glam::Vec3;
use wgpu::util::DeviceExt as _;

pub use callback::{LiveRef, SceneRef, ViewportCallback, ViewportResources};
use gpu_types::{ProjectedSplat, ViewUniform};

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
    /// The scene's geometry and SH (the projection reads them; a live scene's copy writes them).
    geom: wgpu::Buffer,
    sh_a: wgpu::Buffer,
    sh_b: wgpu::Buffer,
    /// The projection pass's output (the GPU sort reads the depths there).
    projected: wgpu::Buffer,
    /// The GPU engine's buffers this scene follows, when it is drawn from them.
    live: Option<splat_from_engine::LiveScatter>,
    /// The camera this scene's target was last drawn from and the splats
    /// drawn: a repaint that changes neither (a progress line, a slider, a
    /// tooltip) keeps that image rather than drawing every splat again, which
    /// on a software renderer took the CPU from the run.
    drawn_for: Option<(Camera, u32)>,
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
    /// The optimiser's step drawn from its GPU buffers, when a side is drawn from them.
    pub live_step: Option<u64>,
    /// Renders that kept the image drawn before (same scene, same camera).
    pub kept: u32,
}

/// What the viewport has to tell the user about the scenes it was given
/// (a scene it cannot draw, a lowered SH degree); the UI shows it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewportNotes {
    /// Scene versions the notes are about.
    pub versions: [u64; 2],
    /// The version of the live run the notes are about.
    pub live_version: u64,
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
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
    })
}

/// The splat renderer: pipelines, up to two scenes ("before" and "after") and their targets.
pub struct SplatRenderer {
    project: splat_project::ProjectPipeline,
    draw: splat_draw::DrawPipeline,
    from_engine: splat_from_engine::FromEnginePipeline,
    scenes: [Option<GpuScene>; 2],
    targets: [Option<Target>; 2],
    /// Statistics of the last [`SplatRenderer::render`] calls since [`SplatRenderer::begin_frame`].
    pub stats: FrameStats,
    /// Bytes one SH binding may hold; the device's limit unless a test lowers it.
    pub sh_binding_limit: Option<usize>,
    /// Sorts on the GPU when set ([`SplatRenderer::use_gpu_sort`]); on the CPU otherwise.
    gpu_sort: Option<splat_sort::DepthSortKernels>,
    /// The live run version [`SplatRenderer::set_live_scene`] last refused, and why.
    refused_live: Option<(u64, String)>,
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
            from_engine: splat_from_engine::FromEnginePipeline::new(device),
            scenes: [None, None],
            targets: [None, None],
            stats: FrameStats::default(),
            sh_binding_limit: None,
            gpu_sort: None,
            refused_live: None,
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
        let (scene, note) = self.build_scene(device, version, g)?;
        self.scenes[side as usize] = Some(scene);
        Ok(note)
    }

    /// Draws in `side` the run whose GPU engine owns `live`, from the engine's
    /// buffers: the whole scene is uploaded once, then every frame after a step
    /// copies the optimised Gaussians on the device ([`splat_from_engine`]).
    /// An error says why this cannot be (the engine is on another device, the
    /// viewport sorts on the CPU, …); the caller then draws snapshots.
    pub fn set_live_scene(
        &mut self,
        device: &wgpu::Device,
        side: Side,
        version: u64,
        live: &LiveGaussians,
    ) -> Result<Option<String>, String> {
        if self.scenes[side as usize].as_ref().is_some_and(|s| s.version == version && s.live.is_some()) {
            return Ok(None);
        }
        if let Some((v, why)) = &self.refused_live
            && *v == version
        {
            return Err(why.clone());
        }
        let result = self.build_live_scene(device, version, live);
        match result {
            Ok((scene, note)) => {
                self.scenes[side as usize] = Some(scene);
                Ok(note)
            }
            Err(why) => {
                self.refused_live = Some((version, why.clone()));
                Err(why)
            }
        }
    }

    fn build_live_scene(
        &self,
        device: &wgpu::Device,
        version: u64,
        live: &LiveGaussians,
    ) -> Result<(GpuScene, Option<String>), String> {
        if self.gpu_sort.is_none() {
            // The CPU sort reads the means on the host, which a live scene does not have.
            return Err("the viewport sorts on the CPU, which needs the Gaussians on the host".into());
        }
        if !live.is_on(device) {
            return Err("the optimiser runs on another device".into());
        }
        let (mut scene, note) = self.build_scene(device, version, &SharedGaussians::Owned(live.base().clone()))?;
        let targets = splat_from_engine::Targets {
            geom: &scene.geom,
            sh_a: &scene.sh_a,
            sh_b: &scene.sh_b,
            sh_degree: scene.sh_degree,
            sh_words: scene.sh_words,
            sh_split: scene.sh_split,
        };
        scene.live = Some(splat_from_engine::LiveScatter::new(device, &self.from_engine, live, targets)?);
        Ok((scene, note))
    }

    /// Copies a live scene's optimised Gaussians into its buffers now if the
    /// engine stepped since the last copy (rendering does this by itself).
    pub fn sync_live(&mut self, encoder: &mut wgpu::CommandEncoder, side: Side) -> bool {
        let k = &self.from_engine;
        self.scenes[side as usize].as_mut().and_then(|s| s.live.as_mut()).is_some_and(|l| l.record(encoder, k))
    }

    /// The buffers of `side` in the layout the projection reads (geometry, SH
    /// below and from the split), for tests that compare them.
    #[cfg(test)]
    pub fn scene_buffers(&self, side: Side) -> Option<[&wgpu::Buffer; 3]> {
        self.scenes[side as usize].as_ref().map(|s| [&s.geom, &s.sh_a, &s.sh_b])
    }

    /// Uploads `g` into a new scene's buffers.
    fn build_scene(
        &self,
        device: &wgpu::Device,
        version: u64,
        g: &SharedGaussians,
    ) -> Result<(GpuScene, Option<String>), String> {
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
        let scene = GpuScene {
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
            drawn_for: None,
            gpu_sort: self.gpu_sort.as_ref().map(|k| k.scene(n)),
            geom,
            sh_a,
            sh_b,
            projected,
            live: None,
        };
        Ok((scene, note))
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
    /// RGBA, transparent where nothing was drawn), unless the target already
    /// holds that scene from that camera (a scene drawn from a running GPU
    /// engine's buffers is drawn every time). Returns false when `side` has no scene.
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
        if scene.live.is_none()
            && let Some((drawn_cam, drawn)) = &scene.drawn_for
            && drawn_cam == cam
        {
            self.stats.drawn += *drawn as usize;
            self.stats.kept += 1;
            return true;
        }
        if let Some(live) = &mut scene.live {
            live.record(encoder, &self.from_engine);
            self.stats.live_step = live.copied_steps();
        }
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
            if let Some(scene) = &mut self.scenes[side as usize] {
                scene.drawn_for = Some((cam.clone(), n));
            }
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
        if let Some(scene) = &mut self.scenes[side as usize] {
            scene.drawn_for = Some((cam.clone(), visible));
        }
        self.stats.prepare_ms += started.elapsed().as_secs_f32() * 1e3;
        true
    }

    /// The target of `side` (after a render).
    pub fn target(&self, side: Side) -> Option<(&wgpu::Texture, &wgpu::TextureView)> {
        self.targets[side as usize].as_ref().map(|t| (&t.texture, &t.view))
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
    let (w, h) = (texture.width() as usize, texture.height() as usize);
    let Some(rows) = read_texture_rows(device, queue, texture, 8) else {
        return vec![[0.0; 4]; w * h];
    };
    let mut out = Vec::with_capacity(w * h);
    for line in &rows {
        for px in line.chunks_exact(8) {
            let c = |k: usize| f16_to_f32(u16::from_le_bytes([px[2 * k], px[2 * k + 1]]));
            out.push([c(0), c(1), c(2), c(3)]);
        }
    }
    out
}

/// The rows of a 2-D texture of `texel` bytes a texel, read back (blocking)
/// through a buffer whose rows are padded to the copy alignment; `None` when
/// the read-back fails.
pub fn read_texture_rows(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    texel: u32,
) -> Option<Vec<Vec<u8>>> {
    let (w, h) = (texture.width(), texture.height());
    let row = (w * texel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: u64::from(row) * u64::from(h),
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
    device.poll(wgpu::PollType::wait_indefinitely()).ok()?;
    let data = slice.get_mapped_range().ok()?;
    let (row, line) = (row as usize, (w * texel) as usize);
    Some((0..h as usize).map(|y| data[y * row..y * row + line].to_vec()).collect())
}
