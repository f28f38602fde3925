// The uniform block of the raster shaders (raster_project, raster_forward,
// raster_backward): declared once here and prepended to each by the Rust
// side (`with_camera` in core/src/gpu/raster/raster_project.rs), whose
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
    // Workgroups per tile in the backward pass, each a slice of its list
    // (raster_forward.rs: GpuRaster::splits; the forward pass records where each slice starts).
    splits: u32,
    // SH coefficients per Gaussian whose gradient the backward pass writes
    // into `v_sh` (the first ones, at this stride): all `sh_coeffs` (fitting,
    // the checks) or the DC alone (a stylization steps no other).
    grad_sh_coeffs: u32,
}

// The backward pass's slices of a tile's list (raster_forward.wgsl records
// them, raster_backward.wgsl walks them).

// List positions per slice of a tile's list of `len` (`splits`: the
// uniform's): whole batches of 256, as few per slice as make at most
// `splits` slices.
fn slice_len(len: u32, splits: u32) -> u32 {
    let batches = (len + 255u) / 256u;
    return max((batches + splits - 1u) / splits, 1u) * 256u;
}

// Where pixel q's record of slice c starts in px_state, for `npx` pixels.
fn slice_at(q: u32, c: u32, npx: u32) -> u32 {
    return 2u * npx + 5u * (c * npx + q);
}
