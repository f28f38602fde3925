// The render's edge map (core/src/gpu/losses/canny.rs; CPU twin: vision/canny.rs
// render_edges): the clamped render min-max normalised to 8-bit per channel,
// OpenCV's Canny(25, 200) with the L1 gradient on each channel, the three
// maps averaged and replicated to 3 channels. Integer arithmetic throughout,
// so the map is the CPU's exactly.
// state (3 planes of n): 1 nothing, 0 candidate (a local maximum above low),
// 2 edge (above high, or connected to such a pixel through candidates).

struct CannyParams {
    h: u32,
    w: u32,
    n: u32,
    // floor(low), floor(high).
    low: i32,
    high: i32,
    // The hysteresis pass this uniform drives (0, 1, …).
    iteration: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: CannyParams;
// The clamped render, h × w × 3.
@group(0) @binding(1) var<storage, read> rgb: array<f32>;
// [min, max] of rgb.
@group(0) @binding(2) var<storage, read> stats: array<f32>;
@group(0) @binding(3) var<storage, read_write> state: array<atomic<u32>>;
// The indirect dispatch arguments of every hysteresis pass, three words
// each, zeroed before the first: pass k writes pass k + 1's (its own
// workgroup counts) when it changed a pixel on a tile's border.
@group(0) @binding(4) var<storage, read_write> next: array<atomic<u32>>;
// The edge map, h × w × 3.
@group(0) @binding(5) var<storage, read_write> edge: array<f32>;

const NONE: u32 = 1u;
const CANDIDATE: u32 = 0u;
const EDGE: u32 = 2u;
// tan(22.5°) in Q15, as OpenCV rounds it.
const TG22: i32 = 13573;

// The 8-bit value of channel ch at (i, j), borders replicated:
// (v − min)/(max − min)·255 truncated (0 for a flat image).
fn q(i: i32, j: i32, ch: u32) -> i32 {
    let ii = u32(clamp(i, 0, i32(u.h) - 1));
    let jj = u32(clamp(j, 0, i32(u.w) - 1));
    let v = rgb[(ii * u.w + jj) * 3u + ch];
    let lo = stats[0];
    let range = stats[1] - lo;
    if range > 0.0 {
        return i32(clamp((v - lo) / range * 255.0, 0.0, 255.0));
    }
    return 0;
}

// 3×3 Sobel: (gx, gy, |gx| + |gy|).
fn sobel(i: i32, j: i32, ch: u32) -> vec3<i32> {
    let gx = (q(i - 1, j + 1, ch) - q(i - 1, j - 1, ch)) + 2 * (q(i, j + 1, ch) - q(i, j - 1, ch))
        + (q(i + 1, j + 1, ch) - q(i + 1, j - 1, ch));
    let gy = (q(i + 1, j - 1, ch) - q(i - 1, j - 1, ch)) + 2 * (q(i + 1, j, ch) - q(i - 1, j, ch))
        + (q(i + 1, j + 1, ch) - q(i - 1, j + 1, ch));
    return vec3<i32>(gx, gy, abs(gx) + abs(gy));
}

// Magnitude for non-maximum suppression: 0 outside the image.
fn mag_at(i: i32, j: i32, ch: u32) -> i32 {
    if i < 0 || j < 0 || i >= i32(u.h) || j >= i32(u.w) {
        return 0;
    }
    return sobel(i, j, ch).z;
}

// Non-maximum suppression and the two thresholds, one (pixel, channel) each.
@compute @workgroup_size(256)
fn nms(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = gid.x + gid.y * nwg.x * 256u;
    if t >= 3u * u.n {
        return;
    }
    let ch = t / u.n;
    let p = t % u.n;
    let i = i32(p / u.w);
    let j = i32(p % u.w);
    let s = sobel(i, j, ch);
    let m = s.z;
    var out = NONE;
    if m > u.low {
        let x = abs(s.x);
        let y = abs(s.y) << 15u;
        let tg22x = x * TG22;
        var is_max = false;
        if y < tg22x {
            is_max = m > mag_at(i, j - 1, ch) && m >= mag_at(i, j + 1, ch);
        } else {
            let tg67x = tg22x + (x << 16u);
            if y > tg67x {
                is_max = m > mag_at(i - 1, j, ch) && m >= mag_at(i + 1, j, ch);
            } else {
                let sg = select(1, -1, (s.x ^ s.y) < 0);
                is_max = m > mag_at(i - 1, j - sg, ch) && m > mag_at(i + 1, j + sg, ch);
            }
        }
        if is_max {
            out = select(CANDIDATE, EDGE, m > u.high);
        }
    }
    atomicStore(&state[t], out);
}

// A hysteresis tile: TILE × TILE pixels of one channel and a one-pixel
// halo, as bit rows of HALO bits in WORDS words each (bit b of word k is
// column 32k + b of the halo). `cand` holds candidates and edges, `grown`
// the edges; thread t < HALO·WORDS owns word t.
const TILE: u32 = 64u;
const HALO: u32 = 66u;
const WORDS: u32 = 3u;
const ROW_WORDS: u32 = 198u;
var<workgroup> cand: array<atomic<u32>, 198>;
var<workgroup> grown: array<atomic<u32>, 198>;
var<workgroup> wg_changed: atomic<u32>;
var<workgroup> wg_again: u32;

// The interior columns (1 ..= TILE of the halo) in word k.
fn interior(k: u32) -> u32 {
    return select(select(1u, 0xffffffffu, k == 1u), 0xfffffffeu, k == 0u);
}

// Word k of halo row r of `grown`, widened by one column each way
// (its bits, and those of its left and right neighbours).
fn widened(r: u32, k: u32) -> u32 {
    let e = atomicLoad(&grown[r * WORDS + k]);
    var v = e | (e << 1u) | (e >> 1u);
    if k > 0u {
        v = v | (atomicLoad(&grown[r * WORDS + k - 1u]) >> 31u);
    }
    if k + 1u < WORDS {
        v = v | (atomicLoad(&grown[r * WORDS + k + 1u]) << 31u);
    }
    return v;
}

// One hysteresis pass: each workgroup loads a 64×64 tile of one channel with
// a one-pixel halo as bit rows and grows edges through 8-connected
// candidates until the tile is stable (a candidate becomes an edge when its
// row, or the rows above and below, widened by a column, hold an edge), then
// writes its new edges back. Edges cross tile borders from one pass to the
// next; only a pass that changed a tile border launches the next one (an
// indirect dispatch), so a generous bound on passes is free.
@compute @workgroup_size(256)
fn hysteresis(
    @builtin(local_invocation_index) t: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    if t == 0u {
        atomicStore(&wg_changed, 0u);
    }
    if t < ROW_WORDS {
        atomicStore(&cand[t], 0u);
        atomicStore(&grown[t], 0u);
    }
    workgroupBarrier();
    let base = wid.z * u.n;
    let i0 = i32(wid.y * TILE) - 1;
    let j0 = i32(wid.x * TILE) - 1;
    // Neighbouring threads read neighbouring pixels, each setting its bit.
    for (var p = t; p < HALO * HALO; p = p + 256u) {
        let hr = p / HALO;
        let hc = p % HALO;
        let gi = i0 + i32(hr);
        let gj = j0 + i32(hc);
        if gi >= 0 && gj >= 0 && gi < i32(u.h) && gj < i32(u.w) {
            let s = atomicLoad(&state[base + u32(gi) * u.w + u32(gj)]);
            let word = hr * WORDS + hc / 32u;
            let bit = 1u << (hc % 32u);
            if s != NONE {
                atomicOr(&cand[word], bit);
            }
            if s == EDGE {
                atomicOr(&grown[word], bit);
            }
        }
    }
    workgroupBarrier();
    let owner = t < ROW_WORDS;
    let r = t / WORDS;
    let k = t % WORDS;
    var c = 0u;
    var e = 0u;
    if owner {
        c = atomicLoad(&cand[t]);
        e = atomicLoad(&grown[t]);
    }
    let start = e;
    let grows = owner && r >= 1u && r <= TILE && (c & ~e & interior(k)) != 0u;
    loop {
        var next_e = e;
        if grows {
            let near = widened(r - 1u, k) | widened(r, k) | widened(r + 1u, k);
            next_e = e | (c & near & interior(k));
        }
        workgroupBarrier();
        if next_e != e {
            e = next_e;
            atomicStore(&grown[t], e);
            atomicStore(&wg_changed, 1u);
        }
        workgroupBarrier();
        if t == 0u {
            wg_again = atomicExchange(&wg_changed, 0u);
        }
        if workgroupUniformLoad(&wg_again) == 0u {
            break;
        }
    }
    var fresh = e & ~start;
    if fresh != 0u {
        let gi = u32(i0 + i32(r));
        var border = r == 1u || r == TILE;
        loop {
            if fresh == 0u {
                break;
            }
            let b = firstTrailingBit(fresh);
            fresh = fresh & (fresh - 1u);
            let col = 32u * k + b;
            atomicStore(&state[base + gi * u.w + u32(j0 + i32(col))], EDGE);
            border = border || col == 1u || col == TILE;
        }
        if border {
            let a = 3u * (u.iteration + 1u);
            atomicStore(&next[a], nwg.x);
            atomicStore(&next[a + 1u], nwg.y);
            atomicStore(&next[a + 2u], nwg.z);
        }
    }
}

// The average of the three channels' edges, replicated to 3 channels.
@compute @workgroup_size(256)
fn finish(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = gid.x + gid.y * nwg.x * 256u;
    if p >= u.n {
        return;
    }
    var count = 0u;
    for (var ch = 0u; ch < 3u; ch = ch + 1u) {
        if atomicLoad(&state[ch * u.n + p]) == EDGE {
            count = count + 1u;
        }
    }
    // The CPU's f32 count / 3, exactly.
    var values = array<f32, 4>(0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0);
    let v = values[count];
    edge[3u * p] = v;
    edge[3u * p + 1u] = v;
    edge[3u * p + 2u] = v;
}
