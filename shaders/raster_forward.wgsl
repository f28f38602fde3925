// Tile binning and compositing (core/src/gpu/raster/raster_forward.rs; CPU twin:
// core/src/raster/forward.rs). After raster_project.wgsl and the depth sort:
// `count_tiles` counts, per splat in depth order, the 16×16 tiles its
// α ≥ 1/255 ellipse reaches (the CPU's box-then-ellipse test); scan.wgsl
// turns the counts into offsets; `emit` writes (tile, depth rank) pairs; the
// stable tile sort groups them by tile keeping depth order; `ranges` finds
// each tile's range; `composite` blends each tile front to back in one
// workgroup, splats staged 256 at a time in workgroup memory, and records
// for each pixel where each of the backward pass's `cam.splits` slices of
// the list starts (the transmittance there) and what the slice adds (its
// colour and inverse depth, premultiplied), so that raster_backward.wgsl can
// walk the slices in separate workgroups.

// `struct Cam` (the uniform block): shaders/raster_camera.wgsl, prepended by the Rust side.

@group(0) @binding(0) var<uniform> cam: Cam;
// count_tiles, emit.
@group(0) @binding(1) var<storage, read> depth_keys: array<u32>;
@group(0) @binding(2) var<storage, read> order: array<u32>;
@group(0) @binding(3) var<storage, read> splats: array<f32>;
@group(0) @binding(4) var<storage, read_write> counts: array<u32>;
@group(0) @binding(5) var<storage, read_write> pair_keys: array<u32>;
@group(0) @binding(6) var<storage, read_write> pair_values: array<u32>;
// ranges.
@group(0) @binding(1) var<storage, read> total: array<u32>;
@group(0) @binding(2) var<storage, read> sorted_keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> ranges: array<u32>;
// composite (order at 2, splats at 3 as above).
@group(0) @binding(1) var<storage, read> tile_splats: array<u32>;
@group(0) @binding(4) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(5) var<storage, read_write> rgb: array<f32>;
@group(0) @binding(6) var<storage, read_write> inv_depth: array<f32>;
@group(0) @binding(7) var<storage, read_write> alpha_out: array<f32>;
// Per pixel: final transmittance (bits), then one past the last composited
// list position; after those 2·H·W words, with more than one slice, per
// slice and pixel (`slice_at`):
// the transmittance at the slice's start, then its premultiplied colour and
// inverse depth (f32 bits).
@group(0) @binding(8) var<storage, read_write> px_state: array<u32>;

const TILE: u32 = 16u;
const SPLAT: u32 = 16u;
const NO_KEY: u32 = 0xffffffffu;
const ALPHA_MIN: f32 = 0.003921569;
const ALPHA_MAX: f32 = 0.99;
const T_MIN: f32 = 1e-4;
const EXTENT_REL: f32 = 1e-3;
const POWER_SLACK: f32 = 1e-3;

fn index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

fn sp(g: u32, f: u32) -> f32 {
    return splats[g * SPLAT + f];
}

// Pixels k in [lo, hi) with centre k + 0.5 in [a, b]: (first, last), empty when first > last.
fn centre_span(a: f32, b: f32, lo: u32, hi: u32) -> vec2<i32> {
    let first = max(i32(clamp(ceil(a - 0.5), -1e9, 1e9)), i32(lo));
    let last = min(i32(clamp(floor(b - 0.5), -1e9, 1e9)), i32(hi) - 1);
    return vec2<i32>(first, last);
}

// Whether splat g's ellipse power ≥ −cut − slack contains a pixel centre of [x0, x1) × [y0, y1).
fn touches_rect(g: u32, x0: u32, x1: u32, y0: u32, y1: u32) -> bool {
    let mx = sp(g, 0u);
    let my = sp(g, 1u);
    let xa = f32(x0) + 0.5 - mx;
    let xb = f32(x1) - 0.5 - mx;
    let ya = f32(y0) + 0.5 - my;
    let yb = f32(y1) - 0.5 - my;
    if xa <= 0.0 && xb >= 0.0 && ya <= 0.0 && yb >= 0.0 {
        return true;
    }
    let a = sp(g, 2u);
    let b = sp(g, 3u);
    let c = sp(g, 4u);
    var m = 3.4e38;
    for (var e = 0u; e < 2u; e = e + 1u) {
        let dx = select(xa, xb, e == 1u);
        let dyc = clamp(-b * dx / c, ya, yb);
        m = min(m, a * dx * dx + 2.0 * b * dx * dyc + c * dyc * dyc);
        let dy = select(ya, yb, e == 1u);
        let dxc = clamp(-b * dy / a, xa, xb);
        m = min(m, a * dxc * dxc + 2.0 * b * dxc * dy + c * dy * dy);
    }
    return m <= 2.0 * (sp(g, 11u) + POWER_SLACK) * (1.0 + EXTENT_REL);
}

// Counts the tiles the k-th splat in depth order reaches; with `emit`, writes
// its (tile, k) pairs from `at` on (up to the capacity).
fn visit_tiles(k: u32, emit: bool, at: u32) -> u32 {
    if depth_keys[k] == NO_KEY {
        return 0u;
    }
    let g = order[k];
    let sx = centre_span(sp(g, 0u) - sp(g, 12u), sp(g, 0u) + sp(g, 12u), 0u, cam.width);
    let sy = centre_span(sp(g, 1u) - sp(g, 13u), sp(g, 1u) + sp(g, 13u), 0u, cam.height);
    if sx.x > sx.y || sy.x > sy.y {
        return 0u;
    }
    let tx0 = u32(sx.x) / TILE;
    let tx1 = u32(sx.y) / TILE;
    let ty0 = u32(sy.x) / TILE;
    let ty1 = u32(sy.y) / TILE;
    let single = tx0 == tx1 && ty0 == ty1;
    var n = 0u;
    for (var ty = ty0; ty <= ty1; ty = ty + 1u) {
        for (var tx = tx0; tx <= tx1; tx = tx + 1u) {
            let x0 = tx * TILE;
            let y0 = ty * TILE;
            if single || touches_rect(g, x0, min(x0 + TILE, cam.width), y0, min(y0 + TILE, cam.height)) {
                if emit && at + n < cam.capacity {
                    pair_keys[at + n] = ty * cam.tiles_x + tx;
                    pair_values[at + n] = k;
                }
                n = n + 1u;
            }
        }
    }
    return n;
}

@compute @workgroup_size(256)
fn count_tiles(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = index(gid, nwg);
    if k < cam.n {
        counts[k] = visit_tiles(k, false, 0u);
    }
}

@compute @workgroup_size(256)
fn emit(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = index(gid, nwg);
    if k < cam.n {
        visit_tiles(k, true, counts[k]);
    }
}

@compute @workgroup_size(256)
fn ranges_of_tiles(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = index(gid, nwg);
    let n = min(total[0], cam.capacity);
    if i >= n {
        return;
    }
    let key = sorted_keys[i];
    if i == 0u || sorted_keys[i - 1u] != key {
        ranges[2u * key] = i;
    }
    if i == n - 1u || sorted_keys[i + 1u] != key {
        ranges[2u * key + 1u] = i + 1u;
    }
}

fn put_slice(q: u32, c: u32, t_start: f32, sum: vec4<f32>) {
    let at = slice_at(q, c, cam.width * cam.height);
    px_state[at] = bitcast<u32>(t_start);
    px_state[at + 1u] = bitcast<u32>(sum.x);
    px_state[at + 2u] = bitcast<u32>(sum.y);
    px_state[at + 3u] = bitcast<u32>(sum.z);
    px_state[at + 4u] = bitcast<u32>(sum.w);
}

// A pixel's result: its colour, inverse depth, opacity and state, and the
// slice under way, then those the pixel never reached (with one slice the
// backward pass needs no record: px_state has none).
fn finish(q: u32, cur: u32, slice_t: f32, slice_sum: vec4<f32>, trans: f32, acc: vec4<f32>, n_contrib: u32) {
    if cam.splits > 1u {
        put_slice(q, cur, slice_t, slice_sum);
        for (var c = cur + 1u; c < cam.splits; c = c + 1u) {
            put_slice(q, c, trans, vec4<f32>(0.0));
        }
    }
    rgb[3u * q] = acc.x + trans * cam.bg.x;
    rgb[3u * q + 1u] = acc.y + trans * cam.bg.y;
    rgb[3u * q + 2u] = acc.z + trans * cam.bg.z;
    inv_depth[q] = acc.w;
    alpha_out[q] = 1.0 - trans;
    px_state[2u * q] = bitcast<u32>(trans);
    px_state[2u * q + 1u] = n_contrib;
}

var<workgroup> s_xy: array<vec2<f32>, 256>;
var<workgroup> s_conic: array<vec4<f32>, 256>;
var<workgroup> s_feat: array<vec4<f32>, 256>;
var<workgroup> n_done: atomic<u32>;
var<workgroup> all_done: u32;

@compute @workgroup_size(16, 16)
fn composite(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let t = lid.y * TILE + lid.x;
    let tile = wid.y * cam.tiles_x + wid.x;
    let px = wid.x * TILE + lid.x;
    let py = wid.y * TILE + lid.y;
    let inside = px < cam.width && py < cam.height;
    let first = tile_ranges[2u * tile];
    let end = max(tile_ranges[2u * tile + 1u], first);
    if t == 0u {
        atomicStore(&n_done, 0u);
    }
    workgroupBarrier();
    var done = !inside;
    if done {
        atomicAdd(&n_done, 1u);
    }
    let pos = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    let q = py * cam.width + px;
    var trans = 1.0;
    var acc = vec4<f32>(0.0);
    var n_contrib = 0u;
    let per_slice = slice_len(end - first, cam.splits);
    var cur = 0u;
    var slice_t = 1.0;
    var slice_sum = vec4<f32>(0.0);
    for (var start = first; start < end; start = start + 256u) {
        if inside && !done && cam.splits > 1u && start > first && (start - first) % per_slice == 0u {
            put_slice(q, cur, slice_t, slice_sum);
            cur += 1u;
            slice_t = trans;
            slice_sum = vec4<f32>(0.0);
        }
        workgroupBarrier();
        if start + t < end {
            let g = order[tile_splats[start + t]];
            s_xy[t] = vec2<f32>(sp(g, 0u), sp(g, 1u));
            s_conic[t] = vec4<f32>(sp(g, 2u), sp(g, 3u), sp(g, 4u), sp(g, 5u));
            s_feat[t] = vec4<f32>(sp(g, 6u), sp(g, 7u), sp(g, 8u), sp(g, 9u));
        }
        workgroupBarrier();
        let batch = min(256u, end - start);
        for (var j = 0u; j < batch && !done; j = j + 1u) {
            let d = pos - s_xy[j];
            let co = s_conic[j];
            let power = -0.5 * (co.x * d.x * d.x + co.z * d.y * d.y) - co.y * d.x * d.y;
            if power > 0.0 {
                continue;
            }
            var alpha = co.w * exp(power);
            if !(alpha >= ALPHA_MIN) {
                continue;
            }
            alpha = min(alpha, ALPHA_MAX);
            let test_t = trans * (1.0 - alpha);
            if test_t < T_MIN {
                done = true;
                atomicAdd(&n_done, 1u);
                // Written at once rather than after the remaining batches: on
                // lavapipe, a pixel that stopped early and idled through a long
                // list's barriers came out empty (a tile of 65,025 splats).
                finish(q, cur, slice_t, slice_sum, trans, acc, n_contrib);
                break;
            }
            let add = (alpha * trans) * s_feat[j];
            acc += add;
            slice_sum += add;
            trans = test_t;
            n_contrib = start - first + j + 1u;
        }
        workgroupBarrier();
        if t == 0u {
            all_done = u32(atomicLoad(&n_done) == 256u);
        }
        if workgroupUniformLoad(&all_done) == 1u {
            break;
        }
    }
    // A pixel still compositing at the end of its list writes its result now.
    if inside && !done {
        finish(q, cur, slice_t, slice_sum, trans, acc, n_contrib);
    }
}
