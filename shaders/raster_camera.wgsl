// The uniform block of the raster shaders (raster_project, raster_forward,
// raster_backward): declared once here and prepended to each by the Rust
// side (`with_camera` in core/src/gpu/raster_project.rs), whose
// `RasterUniform` is its twin, field for field.

struct Cam {
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    trans: vec4<f32>,
    center: vec4<f32>,
    bg: vec4<f32>,
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
    _p0: u32,
    _p1: u32,
}
