// Reverse compositing per tile (core/src/gpu/raster/raster_backward.rs; CPU twin:
// core/src/raster/backward.rs): `cam.splits` workgroups per tile, each
// walking one slice of the tile's list (whole batches of 256, `slice_len`),
// one thread per pixel, splats staged 256 at a time in workgroup memory from
// the back of the slice. Each pixel starts from the transmittance at the
// slice's end and the colour and depth behind it (the later slices' sums the
// forward pass recorded, and the background), walks back to the slice's
// front, recovering T_i = T_{i+1} / (1 − α_i) and the colour and depth behind
// each splat, and adds its share of ∂L/∂(x, y, A, B, C, opacity, r, g, b,
// 1/z) to the splat's Gaussian with atomic adds. With one slice a tile this
// is one walk from the last composited splat; at low resolution, where a few
// hundred tiles hold long lists, the slices keep the GPU's cores busy.
//
// The lines between the add_grad markers are the fallback, a compare-and-swap
// loop on u32 bits; raster_backward.rs swaps them for a native atomic<f32>
// add where the device has SHADER_FLOAT32_ATOMIC. Between the flush markers,
// each thread adds its own share; where the device has subgroups,
// raster_backward.rs swaps in a subgroup sum first, so one atomic add per
// subgroup (not per pixel) reaches memory.

// `struct Cam` (the uniform block): shaders/raster_camera.wgsl, prepended by the Rust side.

@group(0) @binding(0) var<uniform> cam: Cam;
@group(0) @binding(1) var<storage, read> tile_splats: array<u32>;
@group(0) @binding(2) var<storage, read> order: array<u32>;
@group(0) @binding(3) var<storage, read> splats: array<f32>;
@group(0) @binding(4) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(5) var<storage, read> px_state: array<u32>;
@group(0) @binding(6) var<storage, read> v_rgb: array<f32>;
@group(0) @binding(7) var<storage, read> v_inv_depth: array<f32>;

// BEGIN add_grad
@group(0) @binding(8) var<storage, read_write> v_splat: array<atomic<u32>>;

fn add_grad(i: u32, v: f32) {
    var old = atomicLoad(&v_splat[i]);
    loop {
        let r = atomicCompareExchangeWeak(&v_splat[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            break;
        }
        old = r.old_value;
    }
}
// END add_grad

const TILE: u32 = 16u;
const SPLAT: u32 = 16u;
const ALPHA_MIN: f32 = 0.003921569;
const ALPHA_MAX: f32 = 0.99;

fn sp(g: u32, f: u32) -> f32 {
    return splats[g * SPLAT + f];
}

// BEGIN flush
// Adds one pixel's gradient of one splat (every thread calls it for every splat, zeros included).
fn flush(base: u32, gv: array<f32, 10>) {
    for (var c = 0u; c < 10u; c = c + 1u) {
        if gv[c] != 0.0 {
            add_grad(base + c, gv[c]);
        }
    }
}
// END flush

var<workgroup> s_id: array<u32, 256>;
var<workgroup> s_xy: array<vec2<f32>, 256>;
var<workgroup> s_conic: array<vec4<f32>, 256>;
var<workgroup> s_feat: array<vec4<f32>, 256>;
var<workgroup> max_nc: atomic<u32>;

@compute @workgroup_size(16, 16)
fn tile_backward(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let t = lid.y * TILE + lid.x;
    let tile = wid.y * cam.tiles_x + wid.x;
    let px = wid.x * TILE + lid.x;
    let py = wid.y * TILE + lid.y;
    let inside = px < cam.width && py < cam.height;
    let first = tile_ranges[2u * tile];
    let per_slice = slice_len(max(tile_ranges[2u * tile + 1u], first) - first, cam.splits);
    let lo = wid.z * per_slice;
    if t == 0u {
        atomicStore(&max_nc, 0u);
    }
    workgroupBarrier();
    var trans = 0.0;
    var n_contrib = 0u;
    var cot = vec4<f32>(0.0);
    let bg = vec4<f32>(cam.bg.xyz, 0.0);
    var behind = bg;
    if inside {
        let q = py * cam.width + px;
        trans = bitcast<f32>(px_state[2u * q]);
        n_contrib = px_state[2u * q + 1u];
        cot = vec4<f32>(v_rgb[3u * q], v_rgb[3u * q + 1u], v_rgb[3u * q + 2u], v_inv_depth[q]);
        atomicMax(&max_nc, n_contrib);
        if wid.z + 1u < cam.splits {
            // behind·T at the slice's end: what the later slices and the background add.
            var later = trans * bg;
            for (var c = wid.z + 1u; c < cam.splits; c = c + 1u) {
                let at = slice_at(q, c, cam.width * cam.height);
                later += vec4<f32>(
                    bitcast<f32>(px_state[at + 1u]),
                    bitcast<f32>(px_state[at + 2u]),
                    bitcast<f32>(px_state[at + 3u]),
                    bitcast<f32>(px_state[at + 4u])
                );
            }
            trans = bitcast<f32>(px_state[slice_at(q, wid.z + 1u, cam.width * cam.height)]);
            behind = later / trans;
        }
    }
    let count = workgroupUniformLoad(&max_nc);
    let pos = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    // This slice's part of the tile's composited positions (none when every
    // pixel stopped before it).
    var end = min(count, lo + per_slice);
    while end > lo {
        let start = select(lo, end - 256u, end > lo + 256u);
        workgroupBarrier();
        if start + t < end {
            let g = order[tile_splats[first + start + t]];
            s_id[t] = g;
            s_xy[t] = vec2<f32>(sp(g, 0u), sp(g, 1u));
            s_conic[t] = vec4<f32>(sp(g, 2u), sp(g, 3u), sp(g, 4u), sp(g, 5u));
            s_feat[t] = vec4<f32>(sp(g, 6u), sp(g, 7u), sp(g, 8u), sp(g, 9u));
        }
        workgroupBarrier();
        // Every thread visits every splat of the batch (flush may need the
        // whole subgroup); those that do not composite it add zeros.
        for (var j = end - start; j > 0u; j = j - 1u) {
            let k = start + j - 1u;
            let b = j - 1u;
            let d = pos - s_xy[b];
            let co = s_conic[b];
            let power = -0.5 * (co.x * d.x * d.x + co.z * d.y * d.y) - co.y * d.x * d.y;
            let gauss = exp(power);
            let raw_alpha = co.w * gauss;
            var gv: array<f32, 10>;
            if k < n_contrib && power <= 0.0 && raw_alpha >= ALPHA_MIN {
                let alpha = min(raw_alpha, ALPHA_MAX);
                let feat = s_feat[b];
                let t_i = trans / (1.0 - alpha);
                let v_feat = (alpha * t_i) * cot;
                let v_alpha = dot(feat - behind, cot) * t_i;
                behind = alpha * feat + (1.0 - alpha) * behind;
                trans = t_i;
                if raw_alpha <= ALPHA_MAX {
                    let v_power = v_alpha * alpha;
                    gv[0] = v_power * (co.x * d.x + co.y * d.y);
                    gv[1] = v_power * (co.y * d.x + co.z * d.y);
                    gv[2] = -0.5 * v_power * d.x * d.x;
                    gv[3] = -v_power * d.x * d.y;
                    gv[4] = -0.5 * v_power * d.y * d.y;
                    gv[5] = v_alpha * gauss;
                }
                gv[6] = v_feat.x;
                gv[7] = v_feat.y;
                gv[8] = v_feat.z;
                gv[9] = v_feat.w;
            }
            flush(10u * s_id[b], gv);
        }
        end = start;
    }
}
