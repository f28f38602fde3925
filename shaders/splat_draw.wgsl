// Draws the projected Gaussians as instanced screen-space quads (the α ≥ 1/255
// box of each), back to front
// in the order the CPU depth sort produced, with premultiplied alpha "over"
// blending into a transparent target (the background is composited by the
// viewport blit). Launched by app/src/studio/viewport/splat_draw.rs.

struct View {
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    translation: vec4<f32>,
    cam_pos: vec4<f32>,
    focal_principal: vec4<f32>,
    size_tan: vec4<f32>,
    counts: vec4<u32>,
    background: vec4<f32>,
};

struct Projected {
    center_extent: vec4<f32>,
    conic_opacity: vec4<f32>,
    color_depth: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> projected: array<Projected>;
@group(0) @binding(2) var<storage, read> order: array<u32>;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) offset: vec2<f32>,
    @location(1) @interpolate(flat) conic_opacity: vec4<f32>,
    @location(2) @interpolate(flat) color: vec3<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VsOut {
    var out: VsOut;
    let p = projected[order[ii]];
    let ext = p.center_extent.zw;
    let corner = vec2<f32>(f32(vi & 1u), f32((vi >> 1u) & 1u)) * 2.0 - vec2<f32>(1.0);
    let offset = corner * ext;
    let pixel = p.center_extent.xy + offset;
    let size = view.size_tan.xy;
    if (ext.x <= 0.0) {
        out.position = vec4<f32>(2.0, 2.0, 2.0, 1.0); // outside the clip volume
    } else {
        out.position = vec4<f32>(pixel.x / size.x * 2.0 - 1.0, 1.0 - pixel.y / size.y * 2.0, 0.0, 1.0);
    }
    out.offset = offset;
    out.conic_opacity = p.conic_opacity;
    out.color = p.color_depth.rgb;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let d = in.offset;
    let co = in.conic_opacity;
    let power = -0.5 * (co.x * d.x * d.x + co.z * d.y * d.y) - co.y * d.x * d.y;
    if (power > 0.0) {
        discard;
    }
    let alpha = min(0.99, co.w * exp(power));
    if (alpha < 1.0 / 255.0) {
        discard;
    }
    return vec4<f32>(in.color * alpha, alpha);
}
