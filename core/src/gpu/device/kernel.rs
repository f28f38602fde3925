//! One compute entry point with its bindings, and its dispatch.

use super::{BindCache, Commands, GpuContext};

/// How a kernel binds one buffer, in binding order (group 0, bindings 0, 1, …).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bind {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>`.
    Read,
    /// `var<storage, read_write>`.
    ReadWrite,
}

/// Largest workgroup count along one dimension (WebGPU's limit).
const MAX_GROUPS_PER_DIM: u32 = 65_535;

/// A compute pipeline for one entry point of one WGSL module.
#[derive(Debug)]
pub struct Kernel {
    label: String,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    binds: Vec<Bind>,
}

impl Kernel {
    /// Compiles `entry` of `source` (a file of `shaders/`, by `include_str!`).
    pub fn new(ctx: &GpuContext, label: &str, source: &str, entry: &str, binds: &[Bind]) -> Self {
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let entries: Vec<wgpu::BindGroupLayoutEntry> = binds
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: match b {
                        Bind::Uniform => wgpu::BufferBindingType::Uniform,
                        Bind::Read => wgpu::BufferBindingType::Storage { read_only: true },
                        Bind::ReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
        let pipeline_layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { label: label.to_owned(), pipeline, layout, binds: binds.to_vec() }
    }

    /// A bind group of `buffers`, one per declared binding, in order: the
    /// kept one while an engine's step has lent its [`BindCache`] to this
    /// thread, else a new one.
    ///
    /// # Panics
    /// When the number of buffers differs from the declared bindings (a bug in the caller).
    pub fn bind(&self, ctx: &GpuContext, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        assert_eq!(buffers.len(), self.binds.len(), "kernel {}: buffers and bindings differ in number", self.label);
        let (group, made) = BindCache::group(&self.layout, buffers, || {
            let entries: Vec<wgpu::BindGroupEntry> = buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
                .collect();
            ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(&self.label),
                layout: &self.layout,
                entries: &entries,
            })
        });
        if made {
            ctx.count_bind_group();
        }
        group
    }

    /// Records a dispatch of `groups` workgroups (x, y, z) with a bind group of `buffers` ([`Kernel::bind`]).
    pub fn dispatch(&self, ctx: &GpuContext, encoder: &mut dyn Commands, buffers: &[&wgpu::Buffer], groups: [u32; 3]) {
        let bind = self.bind(ctx, buffers);
        self.dispatch_bound(encoder, &bind, groups);
    }

    /// Records a dispatch with a bind group made earlier by [`Kernel::bind`].
    pub fn dispatch_bound(&self, encoder: &mut dyn Commands, bind: &wgpu::BindGroup, groups: [u32; 3]) {
        if groups.contains(&0) {
            return;
        }
        encoder.compute(&self.label, &mut |pass| {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        });
    }

    /// Records a dispatch whose workgroup counts a kernel wrote earlier into
    /// `indirect` at byte `offset` (three `u32`s; zero workgroups skip it).
    pub fn dispatch_indirect(
        &self,
        ctx: &GpuContext,
        encoder: &mut dyn Commands,
        buffers: &[&wgpu::Buffer],
        indirect: &wgpu::Buffer,
        offset: u64,
    ) {
        let bind = self.bind(ctx, buffers);
        encoder.compute(&self.label, &mut |pass| {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups_indirect(indirect, offset);
        });
    }

    /// Workgroup counts covering `items` invocations of a 1-D kernel with
    /// `workgroup` threads: x up to 65,535, the rest in y. The shader computes
    /// its flat index as `gid.x + gid.y * nwg.x * workgroup` and checks bounds.
    pub fn groups_1d(items: usize, workgroup: u32) -> [u32; 3] {
        let groups = (items as u64).div_ceil(u64::from(workgroup)) as u32;
        if groups <= MAX_GROUPS_PER_DIM {
            return [groups, 1, 1];
        }
        let y = groups.div_ceil(MAX_GROUPS_PER_DIM);
        [groups.div_ceil(y), y, 1]
    }
}

/// A 1-D launch planned once: its uniform (made when a workspace is, never
/// rewritten between dispatches of one encoder) and its workgroup counts.
#[derive(Debug)]
pub(crate) struct Launch {
    /// The uniform block.
    pub uniform: wgpu::Buffer,
    /// Workgroups covering the launch's items.
    pub groups: [u32; 3],
}

impl Launch {
    /// A uniform holding `params` and the workgroups for `items` threads of `workgroup`.
    pub fn new<T: bytemuck::Pod>(ctx: &GpuContext, label: &str, params: &T, items: usize, workgroup: u32) -> Self {
        Self { uniform: ctx.uniform(label, params), groups: Kernel::groups_1d(items, workgroup) }
    }
}
