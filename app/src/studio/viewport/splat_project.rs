//! The projection compute pass (shaders/splat_project.wgsl): every Gaussian to
//! a screen-space conic, extent, opacity and SH colour, once per frame.

use super::gpu_types::{ProjectedSplat, ViewUniform};

/// Workgroup size of `project` in the shader.
const WORKGROUP: u32 = 256;

/// The compute pipeline and its bind-group layout.
pub struct ProjectPipeline {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

impl ProjectPipeline {
    /// Compiles the shader and builds the pipeline.
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::include_wgsl!("../../../../shaders/splat_project.wgsl"));
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat_project"),
            entries: &[
                super::uniform_entry::<ViewUniform>(0, wgpu::ShaderStages::COMPUTE),
                storage(1, true),
                storage(2, true),
                storage(3, true),
                storage(4, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("splat_project"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("splat_project"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("project"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { pipeline, layout }
    }

    /// The bind group for one scene's buffers.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        view: &wgpu::Buffer,
        geom: &wgpu::Buffer,
        sh_a: &wgpu::Buffer,
        sh_b: &wgpu::Buffer,
        projected: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        debug_assert_eq!(projected.size() % std::mem::size_of::<ProjectedSplat>() as u64, 0);
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splat_project"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: view.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: geom.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: sh_a.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: sh_b.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: projected.as_entire_binding() },
            ],
        })
    }

    /// Records the dispatch for `count` Gaussians.
    pub fn dispatch(&self, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, count: u32) {
        if count == 0 {
            return;
        }
        let groups = count.div_ceil(WORKGROUP);
        let x = groups.min(65_535);
        let y = groups.div_ceil(x);
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("splat_project"), timestamp_writes: None });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
}
