// Stable LSD radix sort of u32 keys with u32 values, 4 bits a pass
// (core/src/gpu/ops/sort.rs; CPU twin: a stable sort by key). No subgroups.
//
// A fixed grid of `groups` workgroups, each owning one contiguous range of
// whole 1,024-element blocks (the element count is read from `count[0]`, so
// a kernel earlier in the same submission may have written it):
// `histogram` counts each range's digits into hist[digit * groups + group];
// scan.wgsl turns that into exclusive offsets (digit-major, so equal digits
// keep their range order); `scatter` ranks each block's elements stably in
// workgroup memory (per-thread counters, 16 bits a digit packed two to a
// word, scanned across the workgroup) and writes them to their offsets.

struct SortParams {
    shift: u32,
    groups: u32,
    capacity: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> u: SortParams;
@group(0) @binding(1) var<storage, read> count: array<u32>;
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> values_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> hist: array<u32>;
@group(0) @binding(5) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> values_out: array<u32>;

const WG: u32 = 256u;
const ITEMS: u32 = 4u;
const BLOCK: u32 = 1024u;
const DIGITS: u32 = 16u;
// Words of packed 16-bit counters per thread (16 digits, two a word).
const WORDS: u32 = 8u;

var<workgroup> counts: array<atomic<u32>, 16>;
// Packed counters, [word][thread].
var<workgroup> packed: array<u32, 2048>;
var<workgroup> base: array<u32, 16>;

fn n_elems() -> u32 {
    return min(count[0], u.capacity);
}

// [first, end) of the elements owned by workgroup g.
fn range_of(g: u32, n: u32) -> vec2<u32> {
    let blocks = (n + BLOCK - 1u) / BLOCK;
    let per = ((blocks + u.groups - 1u) / u.groups) * BLOCK;
    let a = min(g * per, n);
    return vec2<u32>(a, min(a + per, n));
}

fn digit_of(key: u32) -> u32 {
    return (key >> u.shift) & 15u;
}

@compute @workgroup_size(256)
fn histogram(@builtin(local_invocation_index) t: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    if t < DIGITS {
        atomicStore(&counts[t], 0u);
    }
    workgroupBarrier();
    let r = range_of(wid.x, n_elems());
    for (var i = r.x + t; i < r.y; i = i + WG) {
        atomicAdd(&counts[digit_of(keys_in[i])], 1u);
    }
    workgroupBarrier();
    if t < DIGITS {
        hist[t * u.groups + wid.x] = atomicLoad(&counts[t]);
    }
}

@compute @workgroup_size(256)
fn scatter(@builtin(local_invocation_index) t: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    if t < DIGITS {
        base[t] = hist[t * u.groups + wid.x];
    }
    workgroupBarrier();
    let r = range_of(wid.x, n_elems());
    for (var b = r.x; b < r.y; b = b + BLOCK) {
        // This thread's four consecutive elements; 16 marks "none".
        var key: array<u32, 4>;
        var val: array<u32, 4>;
        var dig: array<u32, 4>;
        var local_rank: array<u32, 4>;
        var mine: array<u32, 8>;
        for (var w = 0u; w < WORDS; w = w + 1u) {
            mine[w] = 0u;
        }
        for (var j = 0u; j < ITEMS; j = j + 1u) {
            let i = b + t * ITEMS + j;
            dig[j] = DIGITS;
            if i < r.y {
                key[j] = keys_in[i];
                val[j] = values_in[i];
                let d = digit_of(key[j]);
                dig[j] = d;
                let sh = 16u * (d & 1u);
                local_rank[j] = (mine[d >> 1u] >> sh) & 0xffffu;
                mine[d >> 1u] = mine[d >> 1u] + (1u << sh);
            }
        }
        // Inclusive Hillis–Steele scan of the packed counters across threads.
        var acc: array<u32, 8>;
        for (var w = 0u; w < WORDS; w = w + 1u) {
            acc[w] = mine[w];
            packed[w * WG + t] = mine[w];
        }
        workgroupBarrier();
        for (var off = 1u; off < WG; off = off << 1u) {
            if t >= off {
                for (var w = 0u; w < WORDS; w = w + 1u) {
                    acc[w] = acc[w] + packed[w * WG + t - off];
                }
            }
            workgroupBarrier();
            for (var w = 0u; w < WORDS; w = w + 1u) {
                packed[w * WG + t] = acc[w];
            }
            workgroupBarrier();
        }
        for (var j = 0u; j < ITEMS; j = j + 1u) {
            let d = dig[j];
            if d < DIGITS {
                let sh = 16u * (d & 1u);
                let before = ((acc[d >> 1u] - mine[d >> 1u]) >> sh) & 0xffffu;
                let at = base[d] + before + local_rank[j];
                keys_out[at] = key[j];
                values_out[at] = val[j];
            }
        }
        workgroupBarrier();
        // The block's totals (the last thread's inclusive counts) advance the bases.
        if t < DIGITS {
            base[t] = base[t] + ((packed[(t >> 1u) * WG + WG - 1u] >> (16u * (t & 1u))) & 0xffffu);
        }
        workgroupBarrier();
    }
}
