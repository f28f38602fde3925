//! The viewport's side of drawing a running optimisation straight from the GPU
//! engine's buffers (shaders/splat_from_engine.wgsl): when the engine has taken
//! steps since the last frame, two compute passes copy its optimised Gaussians
//! into the viewport's own buffers of the whole scene, on the device. No
//! snapshot goes through the CPU per step.
//!
//! Ordering: [`LiveScatter::record`] reads the engine's step count (acquire)
//! before it records the copy into the frame's encoder, which egui submits on
//! the queue the engine's steps use; wgpu runs one queue's submissions in order
//! and inserts the barriers between them. So the copy sees at least the steps
//! it counted, and since a whole step is one submission, never part of one
//! (see [`gast_core::gpu::LiveGaussians`]).

use gast_core::gpu::LiveGaussians;
use wgpu::util::DeviceExt as _;

use super::gpu_types::FromEngineParams;

/// Workgroup size of both entry points in the shader.
const WORKGROUP: u32 = 256;

/// Bindings of `scatter_geometry`, then of `scatter_sh` (the uniform is binding 0 of both).
const GEOMETRY_BINDINGS: [(u32, bool); 6] = [(1, true), (2, true), (3, true), (4, true), (5, true), (6, false)];
const SH_BINDINGS: [(u32, bool); 4] = [(1, true), (7, true), (8, false), (9, false)];

/// The two compute pipelines and their bind-group layouts.
pub struct FromEnginePipeline {
    geometry: (wgpu::ComputePipeline, wgpu::BindGroupLayout),
    sh: (wgpu::ComputePipeline, wgpu::BindGroupLayout),
}

fn pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    entry: &str,
    bindings: &[(u32, bool)],
) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let mut entries = vec![super::uniform_entry::<FromEngineParams>(0, wgpu::ShaderStages::COMPUTE)];
    entries.extend(bindings.iter().map(|&(binding, read_only)| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }));
    let layout =
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(entry), entries: &entries });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(entry),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(&pipeline_layout),
        module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    (pipeline, layout)
}

impl FromEnginePipeline {
    /// Compiles the shader and builds both pipelines.
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::include_wgsl!("../../../../shaders/splat_from_engine.wgsl"));
        Self {
            geometry: pipeline(device, &module, "scatter_geometry", &GEOMETRY_BINDINGS),
            sh: pipeline(device, &module, "scatter_sh", &SH_BINDINGS),
        }
    }
}

/// The viewport's buffers of one scene that the copy writes.
pub struct Targets<'a> {
    /// Three vec4 per Gaussian (see [`super::pack_geometry`]).
    pub geom: &'a wgpu::Buffer,
    /// Packed f16 SH of the Gaussians below `split`.
    pub sh_a: &'a wgpu::Buffer,
    /// Packed f16 SH of the rest.
    pub sh_b: &'a wgpu::Buffer,
    /// SH degree drawn (at most the scene's).
    pub sh_degree: u32,
    /// u32 words of packed SH per Gaussian.
    pub sh_words: u32,
    /// First Gaussian in `sh_b`.
    pub sh_split: u32,
}

/// One run's engine buffers bound to one viewport scene, and the step count last copied.
pub struct LiveScatter {
    live: LiveGaussians,
    count: u32,
    geometry: wgpu::BindGroup,
    sh: wgpu::BindGroup,
    /// Kept alive for the bind groups.
    _buffers: [wgpu::Buffer; 2],
    copied: Option<u64>,
}

impl LiveScatter {
    /// Binds `live`'s buffers to `to`; an error says why the viewport cannot
    /// draw from them (it then draws snapshots).
    pub fn new(
        device: &wgpu::Device,
        k: &FromEnginePipeline,
        live: &LiveGaussians,
        to: Targets<'_>,
    ) -> Result<Self, String> {
        if !live.is_on(device) {
            return Err("the optimiser runs on another device".into());
        }
        if let Some(p) = live.problem() {
            return Err(format!("the optimiser's buffers do not match the scene: {p}"));
        }
        let g = live.gaussians();
        let limit = device.limits().max_storage_buffer_binding_size;
        let widest = [&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh].iter().map(|b| b.size()).max();
        if widest.unwrap_or(0) > limit || (live.keep().len() * 4) as u64 > limit {
            return Err(format!("the optimiser's buffers exceed this GPU's storage binding ({} MB)", limit >> 20));
        }
        let count = live.keep().len() as u32;
        let coeffs = |d| gast_core::scene::sh_coeffs_for_degree(d) as u32 * 3;
        let params = FromEngineParams {
            counts: [count, coeffs(to.sh_degree), coeffs(g.sh_degree), to.sh_words],
            split: [to.sh_split, 0, 0, 0],
        };
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("splat_from_engine params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let keep = super::storage_init(device, "splat_from_engine keep", bytemuck::cast_slice(live.keep()));
        let bind = |layout: &wgpu::BindGroupLayout, label: &str, buffers: &[(u32, &wgpu::Buffer)]| {
            let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() }];
            entries.extend(
                buffers.iter().map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }),
            );
            device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
        };
        let geometry = bind(
            &k.geometry.1,
            "scatter_geometry",
            &[(1, &keep), (2, &g.means), (3, &g.log_scales), (4, &g.quats), (5, &g.opacity_logits), (6, to.geom)],
        );
        let sh = bind(&k.sh.1, "scatter_sh", &[(1, &keep), (7, &g.sh), (8, to.sh_a), (9, to.sh_b)]);
        Ok(Self { live: live.clone(), count, geometry, sh, _buffers: [uniform, keep], copied: None })
    }

    /// Records the copy into `encoder` when the engine has stepped since the
    /// last one; returns whether it did.
    pub fn record(&mut self, encoder: &mut wgpu::CommandEncoder, k: &FromEnginePipeline) -> bool {
        let steps = self.live.steps();
        if self.copied == Some(steps) || self.count == 0 {
            return false;
        }
        let groups = self.count.div_ceil(WORKGROUP);
        let x = groups.min(65_535);
        let y = groups.div_ceil(x);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("splat_from_engine"),
            timestamp_writes: None,
        });
        for (pipeline, bind) in [(&k.geometry.0, &self.geometry), (&k.sh.0, &self.sh)] {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.copied = Some(steps);
        true
    }

    /// The engine's step count the last copy was recorded for.
    pub fn copied_steps(&self) -> Option<u64> {
        self.copied
    }
}
