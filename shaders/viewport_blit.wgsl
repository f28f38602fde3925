// Puts the splat renders into egui's frame: the "before" render left of the
// split line, the "after" render right of it, each composited over the
// background. Launched by app/src/studio/viewport/blit.rs.

struct Blit {
    background: vec4<f32>, // rgb, unused
    split: vec4<f32>,      // x: split position in [0, 1] (1 = all "before"); y, z: the viewport's left edge and width in framebuffer pixels; w unused
};

@group(0) @binding(0) var<uniform> params: Blit;
@group(0) @binding(1) var before_tex: texture_2d<f32>;
@group(0) @binding(2) var after_tex: texture_2d<f32>;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) vi: u32) -> VsOut {
    // One triangle covering the viewport.
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    var out: VsOut;
    out.position = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let dims = textureDimensions(before_tex);
    // The column from the fragment's own pixel centre (exactly k + 0.5), not
    // the interpolated uv: its rounding drifts down the frame, and a line
    // decided by it stepped a pixel sideways part of the way down.
    let col = in.position.x - params.split.y;
    let width = params.split.z;
    let u = col / width;
    let texel = vec2<i32>(clamp(vec2<f32>(u, in.uv.y) * vec2<f32>(dims), vec2<f32>(0.0), vec2<f32>(dims) - vec2<f32>(1.0)));
    let split_px = params.split.x * width;
    var s: vec4<f32>;
    if (col < split_px) {
        s = textureLoad(before_tex, texel, 0);
    } else {
        s = textureLoad(after_tex, texel, 0);
    }
    var rgb = s.rgb + params.background.rgb * (1.0 - s.a);
    // A thin line marks the split when it is inside the view: the two columns
    // whose centres lie in [split - 1, split + 1), wherever the split falls.
    let d = col - split_px;
    if (params.split.x > 0.0 && params.split.x < 1.0 && d >= -1.0 && d < 1.0) {
        rgb = vec3<f32>(1.0, 0.85, 0.2);
    }
    return vec4<f32>(min(rgb, vec3<f32>(1.0)), 1.0);
}
