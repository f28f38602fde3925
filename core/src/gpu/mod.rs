//! The GPU engine: the optimisation step on wgpu, beside the CPU engine.
//!
//! Every kernel here has a CPU twin in the rest of `core` (the reference the
//! tests compare against). Kernels are hand-written WGSL in the workspace's
//! `shaders/` folder, one file per launching module, named after it
//! (`gpu/ops/adam.rs` launches `shaders/adam.wgsl`). The files are grouped by
//! what they are: `device/` (the context, kernels, buffers), `ops/` (general
//! kernels), `raster/`, `networks/` (VGG, the depth network) and `losses/`;
//! `engine.rs` ties them into a step. The modules keep flat names
//! (`gpu::gcfm`, not `gpu::losses::gcfm`).
//!
//! The [`GpuContext`] wraps one `wgpu::Device` and its queue: a headless one
//! (CLI, benchmarks, tests on lavapipe) or the studio's own, which eframe
//! creates with [`device_descriptor`] so the kernels' features and limits are
//! there. Buffers hold flat `f32`/`u32` arrays; a [`Kernel`] is one compute
//! entry point with an explicit binding list.

// The device and its buffers (`device/`).
#[path = "device/bind_cache.rs"]
mod bind_cache;
#[path = "device/context.rs"]
mod context;
#[path = "device/encoder.rs"]
mod encoder;
#[path = "device/gaussians.rs"]
mod gaussians;
#[path = "device/kernel.rs"]
mod kernel;
#[path = "device/live.rs"]
mod live;

// General kernels: Adam (and the phase leak's sums), reductions, scans, sorting, GEMM, resizing (`ops/`).
#[path = "ops/adam.rs"]
mod adam;
#[path = "ops/gemm.rs"]
mod gemm;
#[path = "ops/leak.rs"]
mod leak;
#[path = "ops/ops_bench.rs"]
mod ops_bench;
#[cfg(test)]
#[path = "ops/ops_chain_tests.rs"]
mod ops_chain_tests;
#[path = "ops/reduce.rs"]
mod reduce;
#[path = "ops/resize.rs"]
mod resize;
#[path = "ops/scan.rs"]
mod scan;
#[path = "ops/sort.rs"]
mod sort;

// The rasterizer, forward and backward (`raster/`).
#[path = "raster/raster_backward.rs"]
mod raster_backward;
#[path = "raster/raster_forward.rs"]
mod raster_forward;
#[path = "raster/raster_kernels.rs"]
mod raster_kernels;
#[path = "raster/raster_project.rs"]
mod raster_project;
#[path = "raster/raster_run.rs"]
mod raster_run;
#[cfg(test)]
#[path = "raster/raster_tests.rs"]
mod raster_tests;

// The networks: VGG and the depth network (`networks/`).
#[path = "networks/depth_dpt.rs"]
mod depth_dpt;
#[path = "networks/depth_net.rs"]
mod depth_net;
#[path = "networks/depth_rec.rs"]
mod depth_rec;
#[path = "networks/feature_net.rs"]
mod feature_net;
#[path = "networks/vgg.rs"]
mod vgg;
#[path = "networks/vgg_window.rs"]
mod vgg_window;

// The loss terms, their maps and the step that ties them (`losses/`).
#[path = "losses/assignment.rs"]
mod assignment;
#[path = "losses/canny.rs"]
mod canny;
#[path = "losses/content.rs"]
mod content;
#[path = "losses/depth_map.rs"]
mod depth_map;
#[path = "losses/feature_mean.rs"]
mod feature_mean;
#[path = "losses/focus.rs"]
mod focus;
#[path = "losses/gcfm.rs"]
mod gcfm;
#[path = "losses/losses.rs"]
mod losses;
#[path = "losses/nearest.rs"]
mod nearest;
#[path = "losses/palette.rs"]
mod palette;
#[path = "losses/relief.rs"]
mod relief;
#[path = "losses/sliced.rs"]
mod sliced;
#[path = "losses/step_loss.rs"]
mod step_loss;

// The engine: one optimisation step on the device.
mod engine;
pub use adam::GpuAdam;
pub use assignment::GpuAssignment;
pub use bind_cache::{BindCache, Lent};
pub use canny::{CannyKernels, EdgeMap};
pub use content::ContentLoss;
pub use context::{AdapterPolicy, GpuCaps, GpuContext, GpuError, device_descriptor};
pub use depth_map::{DepthMap, DepthMapKernels};
pub use depth_net::GpuDepthNet;
pub use encoder::{Commands, Encoder};
pub use engine::{GpuEngine, HostTimes};
pub use feature_mean::FeatureMeanLoss;
pub use feature_net::{GpuFeatureNet, GpuFeatureState};
pub use focus::{FocusKernels, GpuFocus};
pub use gaussians::{GpuGaussians, GpuGrads};
pub use gcfm::{GcfmSubset, GcfmWorkspace, GpuGcfm, GpuStyle, Search, bench_gcfm};
pub use gemm::{Gemm, GemmPlan, GemmSpec, GemmTile, Strided, WIDE_MIN_GROUPS, bench_gemm};
pub use kernel::{Bind, Kernel};
pub use leak::GpuLeak;
pub use live::LiveGaussians;
pub use losses::{LossKernels, RefLoss, TvLoss};
pub use nearest::GpuNearest;
pub use ops_bench::bench_image_ops;
pub use palette::PaletteLoss;
pub use raster_forward::GpuRaster;
pub use raster_kernels::{Accumulation, RasterKernels};
pub use raster_run::{bench_raster, render_and_backward_gpu, render_gpu};
pub use reduce::{ReduceKernels, ReduceOp, ReduceSpec, Reduction};
pub use relief::{DepthRelief, DepthReliefKernels};
pub use resize::{Clamp01, Downscale, ResizeKernels};
pub use scan::{GpuScan, ScanKernels};
pub use sliced::{GpuSlicedTarget, SlicedKernels, SlicedLoss};
pub use sort::{GpuSort, SortKernels, bits_for};
pub use step_loss::{StepInputs, StepLossKernels, StepLossPlan, step_loss_gpu};
pub use vgg::{GpuVgg, GpuVggState, GpuVggWorkspace, bench_vgg};
pub use vgg_window::{VggWindow, WindowKernel, WindowSize};

use serde::{Deserialize, Serialize};

/// Where a run computes: the user's choice (`--device`, the studio's selector).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceChoice {
    /// A hardware GPU adapter when there is one (never a software one), else the CPU.
    #[default]
    Auto,
    /// The CPU engine (the reference).
    Cpu,
    /// The GPU engine on any adapter, software rasterizers (lavapipe) included.
    Gpu,
}

impl DeviceChoice {
    /// Every choice, in the order a selector lists them.
    pub const ALL: [DeviceChoice; 3] = [DeviceChoice::Auto, DeviceChoice::Cpu, DeviceChoice::Gpu];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DeviceChoice::Auto => "auto",
            DeviceChoice::Cpu => "cpu",
            DeviceChoice::Gpu => "gpu",
        }
    }
}

impl DeviceChoice {
    /// The GPU context this choice runs on, for a front end without a device of
    /// its own (the CLI): `None` for the CPU engine. `auto` takes a hardware
    /// adapter when one answers and falls back to the CPU otherwise; `gpu`
    /// takes any adapter (lavapipe included) and fails without one.
    pub fn resolve(self) -> Result<Option<GpuContext>, GpuError> {
        match self {
            DeviceChoice::Cpu => Ok(None),
            DeviceChoice::Auto => Ok(GpuContext::headless(AdapterPolicy::HardwareOnly).ok()),
            DeviceChoice::Gpu => GpuContext::headless(AdapterPolicy::AnyAdapter).map(Some),
        }
    }

    /// The same choice for a front end that already holds a device (the
    /// studio's, shared with its viewport): `auto` uses it unless it is a
    /// software rasterizer.
    pub fn pick(self, shared: Option<&GpuContext>) -> Option<GpuContext> {
        match self {
            DeviceChoice::Cpu => None,
            DeviceChoice::Auto => shared.filter(|c| !c.is_software()).cloned(),
            DeviceChoice::Gpu => shared.cloned(),
        }
    }
}

impl std::str::FromStr for DeviceChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(DeviceChoice::Auto),
            "cpu" => Ok(DeviceChoice::Cpu),
            "gpu" => Ok(DeviceChoice::Gpu),
            other => Err(format!("expected auto, cpu or gpu, found {other:?}")),
        }
    }
}

impl std::fmt::Display for DeviceChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
pub(crate) mod test_util {
    //! A context for kernel tests: any adapter, lavapipe included (CI has no GPU).
    use super::{AdapterPolicy, Commands, GpuContext, GpuFocus};
    use std::sync::OnceLock;

    /// The focus of a feature-position mask for the feature-space terms: its
    /// cells and their count uploaded, the pixel mask unused (1 × 1).
    pub fn cells_focus(ctx: &GpuContext, cells: &[bool]) -> GpuFocus {
        let f = GpuFocus::frame(ctx, 1, 1, cells.len(), 1);
        let on: Vec<f32> = cells.iter().map(|&v| f32::from(u8::from(v))).collect();
        ctx.write(f.cells(), &on);
        ctx.write(f.counts(), &[on.iter().sum::<f32>(), 0.0, 0.0, 0.0]);
        f
    }

    /// Records a feature-space loss term (weight 0.5, scalar slot 3) on the
    /// features `f` (`c × positions`, `positions = cells.len()`) over the
    /// positions `cells` covers, into a gradient buffer that starts as noise,
    /// and checks it against the CPU's `(value, gradient)`: the value within
    /// `tol` of it, the gradient added at half weight within `tol` of its
    /// largest element (plus the rounding of adding to the noise), nothing
    /// outside the mask touched. `record(encoder, features, focus, gradient,
    /// scalars)` records the term.
    pub fn check_masked_term(
        ctx: &GpuContext,
        label: &str,
        f: &[f32],
        cells: &[bool],
        (want, grad): (f32, Vec<f32>),
        tol: f32,
        record: impl FnOnce(&mut dyn Commands, &wgpu::Buffer, &GpuFocus, &wgpu::Buffer, &wgpu::Buffer),
    ) {
        let (n, positions) = (f.len(), cells.len());
        let g0 = noise(n, 3);
        let (fb, gb) = (ctx.upload("f", f), ctx.upload("g", &g0));
        let focus = cells_focus(ctx, cells);
        let scalars = ctx.upload("scalars", &noise(8, 4));
        let mut enc = ctx.encoder("masked term test");
        record(&mut enc, &fb, &focus, &gb, &scalars);
        ctx.submit(enc);
        let got: Vec<f32> = ctx.read(&scalars).expect("scalars");
        assert!((got[3] - want).abs() <= tol * want.abs().max(1e-6), "{label}: {} vs {want}", got[3]);
        let g: Vec<f32> = ctx.read(&gb).expect("grad");
        let scale = grad.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        let worst = (0..n).map(|i| (g[i] - (g0[i] + 0.5 * grad[i])).abs()).fold(0.0f32, f32::max);
        // Adding to g0 (about 1) rounds at f32's epsilon of it.
        let rounding = 2.0 * f32::EPSILON * g0.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(worst <= tol * scale + rounding, "{label}: gradient off by {worst} of {scale}");
        for i in (0..n).filter(|i| !cells[i % positions]) {
            assert_eq!(g[i], g0[i], "{label}: element {i} is outside the mask");
        }
    }

    /// The shared test context; panics with the reason when no adapter exists
    /// (CI installs Mesa's lavapipe, see `.ci/run`).
    pub fn ctx() -> &'static GpuContext {
        static CTX: OnceLock<GpuContext> = OnceLock::new();
        CTX.get_or_init(|| match GpuContext::headless(AdapterPolicy::AnyAdapter) {
            Ok(c) => c,
            Err(e) => panic!("GPU tests need a wgpu adapter (lavapipe: apt-get install mesa-vulkan-drivers): {e}"),
        })
    }

    /// Deterministic noise in [-1, 1) for inputs and for pre-filling scratch buffers.
    pub fn noise(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 40) as f32 / (1u64 << 23) as f32 - 1.0
            })
            .collect()
    }
}
