//! The Rust twins of the structs the viewport shaders read and write.
//!
//! Each is `#[repr(C)]` and `bytemuck::Pod`, with its size asserted at compile
//! time against the WGSL layout (vec4-only members, so no hidden padding).

use bytemuck::{Pod, Zeroable};
use gast_core::Camera;

/// `View` in splat_project.wgsl and splat_draw.wgsl: one camera and the scene's counts.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ViewUniform {
    /// Rows of the world-to-camera rotation, w unused.
    pub rot: [[f32; 4]; 3],
    /// World-to-camera translation, w unused.
    pub translation: [f32; 4],
    /// Camera centre in world space, w unused.
    pub cam_pos: [f32; 4],
    /// fx, fy, cx, cy.
    pub focal_principal: [f32; 4],
    /// width, height, tan(half fov x), tan(half fov y).
    pub size_tan: [f32; 4],
    /// Gaussian count, SH degree, u32 words of SH per Gaussian, split index of the SH bindings.
    pub counts: [u32; 4],
    /// Background colour, w unused.
    pub background: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<ViewUniform>() == 144);

impl ViewUniform {
    /// The uniform for a camera and a scene layout.
    pub fn new(cam: &Camera, num: u32, sh_degree: u32, sh_words: u32, sh_split: u32, background: [f32; 3]) -> Self {
        let r = cam.rotation.transpose(); // columns of Rᵀ are the rows of R
        let row = |i: usize| {
            let c = r.col(i);
            [c.x, c.y, c.z, 0.0]
        };
        let (tx, ty) = cam.tan_half_fov();
        let t = cam.translation;
        let c = cam.center();
        Self {
            rot: [row(0), row(1), row(2)],
            translation: [t.x, t.y, t.z, 0.0],
            cam_pos: [c.x, c.y, c.z, 0.0],
            focal_principal: [cam.fx, cam.fy, cam.cx, cam.cy],
            size_tan: [cam.width as f32, cam.height as f32, tx, ty],
            counts: [num, sh_degree, sh_words, sh_split],
            background: [background[0], background[1], background[2], 1.0],
        }
    }
}

/// `Projected` in the shaders: one Gaussian in screen space.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ProjectedSplat {
    /// u, v (pixels), half-extents x, y (pixels, 0 when culled).
    pub center_extent: [f32; 4],
    /// Conic (inverse 2D covariance) xx, xy, yy and opacity.
    pub conic_opacity: [f32; 4],
    /// RGB and view depth.
    pub color_depth: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<ProjectedSplat>() == 48);

/// `Blit` in viewport_blit.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BlitUniform {
    /// Background colour, w unused.
    pub background: [f32; 4],
    /// x: split position in [0, 1] (1 = all "before"); y: the viewport's
    /// left edge and z its width, in framebuffer pixels; w unused.
    pub split: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<BlitUniform>() == 32);

/// `Params` in splat_from_engine.wgsl: the shapes of one engine-to-viewport copy.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct FromEngineParams {
    /// Optimised Gaussians, SH floats drawn per Gaussian, the engine's SH floats
    /// per Gaussian, u32 words of packed SH per Gaussian in the viewport.
    pub counts: [u32; 4],
    /// x: the Gaussian index where the viewport's second SH binding starts; yzw unused.
    pub split: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<FromEngineParams>() == 32);
