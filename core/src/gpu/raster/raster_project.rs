//! The per-Gaussian stages of the GPU rasterizer (`shaders/raster_project.wgsl`):
//! projection to 16-float splats with depth sort keys, and its backward pass
//! to the parameter gradients. The CPU twin is `raster/project.rs`, whose
//! formulas the shader repeats; both directions recompute the intermediates
//! from the parameters, as there.

use super::{Bind, GpuContext, Kernel};
use crate::camera::Camera;
use crate::raster::{RenderOptions, ShGrads, TILE};

/// The Jacobian clamps `x/z`, `y/z` to this multiple of `tan(half-fov)` (`raster/project.rs`).
const FOV_CLAMP: f32 = 1.3;

/// Threads per workgroup of the 1-D raster kernels.
pub(crate) const WORKGROUP: u32 = 256;

/// `struct Cam`, the raster shaders' uniform block, declared once.
pub(crate) const RASTER_CAMERA_WGSL: &str = include_str!("../../../../shaders/raster_camera.wgsl");

/// A raster shader's source with the camera block it uses in front.
pub(crate) fn with_camera(src: &str) -> String {
    format!("{RASTER_CAMERA_WGSL}\n{src}")
}

/// The uniform block every raster shader declares as `Cam` (`shaders/raster_camera.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct RasterUniform {
    /// Rows of the world-to-camera rotation (w unused).
    rows: [[f32; 4]; 3],
    trans: [f32; 4],
    center: [f32; 4],
    bg: [f32; 4],
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    lim_x: f32,
    lim_y: f32,
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    n: u32,
    sh_coeffs: u32,
    capacity: u32,
    sh_degree: u32,
    splits: u32,
    grad_sh_coeffs: u32,
}
const _: () = assert!(std::mem::size_of::<RasterUniform>() == 160);

impl RasterUniform {
    /// The uniform for `n` Gaussians of SH degree `sh_degree` seen by `cam`,
    /// the backward pass splitting each tile's list into `splits` slices and
    /// writing the gradient of the SH coefficients `grad_sh`.
    pub fn new(
        cam: &Camera,
        opts: &RenderOptions,
        n: usize,
        sh_degree: u32,
        capacity: usize,
        splits: u32,
        grad_sh: ShGrads,
    ) -> Self {
        let (tx, ty) = cam.tan_half_fov();
        let r = cam.rotation;
        let row = |i: usize| {
            let v = r.row(i);
            [v.x, v.y, v.z, 0.0]
        };
        let c = cam.center();
        let t = cam.translation;
        let [br, bgc, bb] = opts.background;
        Self {
            rows: [row(0), row(1), row(2)],
            trans: [t.x, t.y, t.z, 0.0],
            center: [c.x, c.y, c.z, 0.0],
            bg: [br, bgc, bb, 0.0],
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            lim_x: FOV_CLAMP * tx,
            lim_y: FOV_CLAMP * ty,
            width: cam.width,
            height: cam.height,
            tiles_x: cam.width.div_ceil(TILE),
            tiles_y: cam.height.div_ceil(TILE),
            n: n as u32,
            sh_coeffs: crate::scene::sh_coeffs_for_degree(sh_degree) as u32,
            capacity: capacity as u32,
            sh_degree,
            splits,
            grad_sh_coeffs: grad_sh.for_degree(sh_degree) as u32,
        }
    }
}

/// The two entry points of `raster_project.wgsl`.
#[derive(Debug)]
pub(crate) struct ProjectKernels {
    /// Parameters → splats, depth keys, identity order.
    pub project: Kernel,
    /// Screen-space gradients → parameter gradients.
    pub backward: Kernel,
}

impl ProjectKernels {
    pub fn new(ctx: &GpuContext) -> Self {
        let src = &with_camera(include_str!("../../../../shaders/raster_project.wgsl"));
        use Bind::{Read, ReadWrite, Uniform};
        Self {
            project: Kernel::new(
                ctx,
                "raster_project.project",
                src,
                "project",
                &[Uniform, Read, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite],
            ),
            backward: Kernel::new(
                ctx,
                "raster_project.project_backward",
                src,
                "project_backward",
                &[Uniform, Read, Read, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite, ReadWrite, ReadWrite],
            ),
        }
    }
}
