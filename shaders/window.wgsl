// A rectangle of planes copied between two buffers (core/src/gpu/networks/vgg_window.rs):
// VGG's window cut out of the frame and put back. CPU twin: style/window.rs's
// crop_image, uncrop_image, crop_features and embed_features.
//
// dst[dst_off + p·dst_plane + r·dst_w + x] = src[src_off + p·src_plane + r·src_w + x]
// for p < planes, r < rows, x < cols. An HWC image is one plane whose rows are w·c
// values wide; CHW features are one plane per channel.

struct RectParams {
    planes: u32,
    rows: u32,
    cols: u32,
    src_w: u32,
    src_plane: u32,
    src_off: u32,
    dst_w: u32,
    dst_plane: u32,
    dst_off: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> u: RectParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(256)
fn copy_rect(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    let per_plane = u.rows * u.cols;
    if i >= u.planes * per_plane {
        return;
    }
    let p = i / per_plane;
    let k = i - p * per_plane;
    let r = k / u.cols;
    let x = k - r * u.cols;
    dst[u.dst_off + p * u.dst_plane + r * u.dst_w + x] = src[u.src_off + p * u.src_plane + r * u.src_w + x];
}
