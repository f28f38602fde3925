//! The device, its queue and what the kernels may use of it.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use wgpu::util::DeviceExt as _;

use super::Encoder;

/// Why the GPU engine cannot run.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter matched the policy.
    #[error("no GPU adapter found{0}")]
    NoAdapter(String),
    /// The adapter refused the device.
    #[error("the GPU adapter {adapter} refused a device: {message}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's reason.
        message: String,
    },
    /// A buffer could not be read back.
    #[error("reading a GPU buffer back failed: {0}")]
    Readback(String),
    /// The work does not fit the device.
    #[error("{0}")]
    TooLarge(String),
}

/// Which adapters [`GpuContext::headless`] accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdapterPolicy {
    /// Hardware adapters only (discrete, integrated, virtual): `--device auto`.
    HardwareOnly,
    /// Any adapter, software rasterizers (lavapipe, llvmpipe) included: `--device gpu`, tests.
    AnyAdapter,
}

/// What the device offers beyond WebGPU's baseline, as the kernels use it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuCaps {
    /// `atomic<f32>` add in storage buffers (else a compare-and-swap loop on `u32`).
    pub float_atomics: bool,
    /// Subgroup operations.
    pub subgroups: bool,
    /// Timestamp queries (per-pass timings in benchmarks).
    pub timestamps: bool,
}

impl GpuCaps {
    fn of(features: wgpu::Features) -> Self {
        Self {
            float_atomics: features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC),
            subgroups: features.contains(wgpu::Features::SUBGROUP),
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
        }
    }
}

/// The features the kernels use where the adapter has them; none is required.
fn wanted_features(adapter: &wgpu::Adapter) -> wgpu::Features {
    let wanted = wgpu::Features::SHADER_FLOAT32_ATOMIC | wgpu::Features::SUBGROUP | wgpu::Features::TIMESTAMP_QUERY;
    adapter.features() & wanted
}

/// The device descriptor the engine needs: the adapter's own limits (storage
/// bindings and workgroup sizes far above WebGPU's defaults) and the optional
/// features it has. The studio hands this to eframe so both share one device.
pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
    wgpu::DeviceDescriptor {
        label: Some("gast"),
        required_features: wanted_features(adapter),
        required_limits: adapter.limits(),
        ..Default::default()
    }
}

/// One device and queue, shared by every kernel of a run (and by the studio's viewport).
#[derive(Clone, Debug)]
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter's description (name, backend, type).
    pub info: wgpu::AdapterInfo,
    /// Optional features the device was created with.
    pub caps: GpuCaps,
    /// Bytes of buffers made through this context (and its clones) so far:
    /// what the engine reports as its GPU memory.
    allocated: Arc<AtomicU64>,
    /// Bind groups made through this context (and its clones): one per
    /// dispatch recorded with [`super::Kernel::dispatch`].
    bind_groups: Arc<AtomicU64>,
    /// Compute passes begun by the encoders of [`GpuContext::encoder`].
    passes: Arc<AtomicU64>,
}

impl GpuContext {
    /// A device of its own on the best adapter the policy allows: a discrete GPU
    /// before an integrated one before anything else.
    pub fn headless(policy: AdapterPolicy) -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let rank = |a: &wgpu::Adapter| {
            let info = a.get_info();
            let kind = match info.device_type {
                wgpu::DeviceType::DiscreteGpu => 0,
                wgpu::DeviceType::IntegratedGpu => 1,
                wgpu::DeviceType::VirtualGpu | wgpu::DeviceType::Other => 2,
                wgpu::DeviceType::Cpu => 3,
            };
            // Vulkan/Metal/DX12 before GL: compute shaders and storage limits.
            let backend = if info.backend == wgpu::Backend::Gl { 1 } else { 0 };
            (kind, backend)
        };
        let seen: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
        let adapter = adapters
            .into_iter()
            .filter(|a| policy == AdapterPolicy::AnyAdapter || a.get_info().device_type != wgpu::DeviceType::Cpu)
            .filter(|a| a.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS))
            .min_by_key(rank)
            .ok_or_else(|| {
                GpuError::NoAdapter(match (policy, seen.is_empty()) {
                    (_, true) => String::new(),
                    (AdapterPolicy::HardwareOnly, false) => {
                        format!(" (hardware only; software adapters seen: {})", seen.join(", "))
                    }
                    (AdapterPolicy::AnyAdapter, false) => format!(" with compute shaders (seen: {})", seen.join(", ")),
                })
            })?;
        Self::on_adapter(&adapter)
    }

    /// A device of its own on `adapter`.
    pub fn on_adapter(adapter: &wgpu::Adapter) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let desc = device_descriptor(adapter);
        let (device, queue) = pollster::block_on(adapter.request_device(&desc))
            .map_err(|e| GpuError::Device { adapter: describe(&info), message: e.to_string() })?;
        Ok(Self::from_device(device, queue, info))
    }

    /// Wraps a device someone else created (the studio's, from eframe).
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, info: wgpu::AdapterInfo) -> Self {
        let caps = GpuCaps::of(device.features());
        Self {
            device,
            queue,
            info,
            caps,
            allocated: Arc::default(),
            bind_groups: Arc::default(),
            passes: Arc::default(),
        }
    }

    /// "NVIDIA H100 (Vulkan, discrete)", for reports.
    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    /// Bytes of buffers made through [`GpuContext::upload`], [`GpuContext::zeros`]
    /// and [`GpuContext::uniform`] so far (freed ones included: a high-water mark
    /// for a run that allocates once).
    pub fn allocated_bytes(&self) -> u64 {
        self.allocated.load(Ordering::Relaxed)
    }

    /// Bind groups made so far ([`super::Kernel::bind`]); the difference
    /// over a step is the groups it made (not those kept from an earlier
    /// step, [`super::BindCache`]).
    pub fn bind_groups_made(&self) -> u64 {
        self.bind_groups.load(Ordering::Relaxed)
    }

    /// Compute passes begun so far by [`GpuContext::encoder`]'s encoders:
    /// one per run of dispatches between copies (one per dispatch with
    /// `GAST_GPU_PASSES=each`).
    pub fn passes_begun(&self) -> u64 {
        self.passes.load(Ordering::Relaxed)
    }

    pub(crate) fn count_bind_group(&self) {
        self.bind_groups.fetch_add(1, Ordering::Relaxed);
    }

    fn count(&self, bytes: u64) {
        self.allocated.fetch_add(bytes, Ordering::Relaxed);
    }

    /// Whether the adapter is a software rasterizer (lavapipe, llvmpipe).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// The largest storage-buffer binding, in bytes.
    pub fn max_binding_bytes(&self) -> u64 {
        self.device.limits().max_storage_buffer_binding_size
    }

    /// A storage buffer holding `data` (read and written by kernels, copyable both ways).
    pub fn upload<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> wgpu::Buffer {
        if data.is_empty() {
            return self.zeros(label, 1);
        }
        self.count(std::mem::size_of_val(data) as u64);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(data),
            usage: storage_usage(),
        })
    }

    /// A zero-filled storage buffer of `words` 4-byte elements (at least one).
    pub fn zeros(&self, label: &str, words: usize) -> wgpu::Buffer {
        self.count((words.max(1) * 4) as u64);
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (words.max(1) * 4) as u64,
            usage: storage_usage(),
            mapped_at_creation: false,
        })
    }

    /// A uniform buffer holding `value`.
    pub fn uniform<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.count(std::mem::size_of::<T>() as u64);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// Overwrites the start of `buffer` with `data`.
    pub fn write<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, data: &[T]) {
        self.queue.write_buffer(buffer, 0, bytemuck::cast_slice(data));
    }

    /// A new command encoder, whose consecutive dispatches share a compute pass ([`Encoder`]).
    pub fn encoder(&self, label: &str) -> Encoder {
        let inner = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        Encoder::new(inner, Arc::clone(&self.passes))
    }

    /// Submits `encoder`'s commands.
    pub fn submit(&self, encoder: Encoder) {
        self.queue.submit([encoder.finish()]);
    }

    /// Reads a whole buffer back as `T`s (blocks until the queue is done).
    pub fn read<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>, GpuError> {
        self.read_range(buffer, 0, buffer.size())
    }

    /// Reads `bytes` bytes of `buffer` from `offset` back as `T`s.
    pub fn read_range<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        offset: u64,
        bytes: u64,
    ) -> Result<Vec<T>, GpuError> {
        let staging = self.staging("readback", bytes);
        let mut enc = self.encoder("readback");
        enc.copy_buffer_to_buffer(buffer, offset, &staging, 0, bytes);
        self.submit(enc);
        self.map_read(&staging, bytes, None)
    }

    /// A buffer the host maps to read (`MAP_READ | COPY_DST`), of `bytes` bytes.
    pub fn staging(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Submits `encoder`'s commands and returns their index, for
    /// [`GpuContext::read_staged`] to wait for them alone.
    pub fn submit_indexed(&self, encoder: Encoder) -> wgpu::SubmissionIndex {
        self.queue.submit([encoder.finish()])
    }

    /// Reads the first `bytes` bytes of `staging` (filled by a copy in
    /// submission `after`) as `T`s, waiting for that submission only: work
    /// submitted after it runs on while the host reads.
    pub fn read_staged<T: bytemuck::Pod>(
        &self,
        staging: &wgpu::Buffer,
        bytes: u64,
        after: wgpu::SubmissionIndex,
    ) -> Result<Vec<T>, GpuError> {
        self.map_read(staging, bytes, Some(after))
    }

    /// Maps `bytes` of `staging`, waits for submission `after` (the latest
    /// without one), copies them out and unmaps.
    fn map_read<T: bytemuck::Pod>(
        &self,
        staging: &wgpu::Buffer,
        bytes: u64,
        after: Option<wgpu::SubmissionIndex>,
    ) -> Result<Vec<T>, GpuError> {
        let slice = staging.slice(..bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        let wait = wgpu::PollType::Wait { submission_index: after, timeout: None };
        self.device.poll(wait).map_err(|e| GpuError::Readback(e.to_string()))?;
        match rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(GpuError::Readback(e.to_string())),
            Err(e) => return Err(GpuError::Readback(e.to_string())),
        }
        let view = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = bytemuck::pod_collect_to_vec(&view);
        drop(view);
        staging.unmap();
        Ok(out)
    }

    /// Blocks until every submitted command has finished (benchmarks, timings).
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map(|_| ()).map_err(|e| GpuError::Readback(e.to_string()))
    }
}

/// Storage buffers are read and written by kernels, filled from and read back to the host.
fn storage_usage() -> wgpu::BufferUsages {
    wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    let kind = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => "discrete",
        wgpu::DeviceType::IntegratedGpu => "integrated",
        wgpu::DeviceType::VirtualGpu => "virtual",
        wgpu::DeviceType::Cpu => "software",
        wgpu::DeviceType::Other => "other",
    };
    format!("{} ({:?}, {kind})", info.name, info.backend)
}
