// Exclusive prefix sum of u32 in place (core/src/gpu/ops/scan.rs; CPU twin: a running sum).
// A fixed grid of `groups` workgroups, each owning one contiguous range of
// `per_group` elements: `reduce` sums each range, `scan_sums` scans the range
// sums in one workgroup (and stores the total), `apply` scans each range from
// its offset. No subgroups: workgroup-memory Hillis–Steele scans.
//
// sums layout: sums[0] = total of all elements, sums[1 + g] = offset of range g.

struct ScanParams {
    len: u32,
    groups: u32,
    per_group: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> u: ScanParams;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;

const WG: u32 = 256u;
// Elements per thread in one block.
const ITEMS: u32 = 4u;
const BLOCK: u32 = 1024u;

var<workgroup> buf: array<u32, 256>;
var<workgroup> carry: u32;

// Inclusive scan of one value per thread across the workgroup.
fn wg_inclusive(t: u32, v: u32) -> u32 {
    buf[t] = v;
    workgroupBarrier();
    var x = v;
    for (var off = 1u; off < WG; off = off << 1u) {
        if t >= off {
            x = x + buf[t - off];
        }
        workgroupBarrier();
        buf[t] = x;
        workgroupBarrier();
    }
    return x;
}

fn range_of(g: u32) -> vec2<u32> {
    let a = min(g * u.per_group, u.len);
    let b = min(a + u.per_group, u.len);
    return vec2<u32>(a, b);
}

@compute @workgroup_size(256)
fn reduce(@builtin(local_invocation_index) t: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = range_of(wid.x);
    var s = 0u;
    for (var i = r.x + t; i < r.y; i = i + WG) {
        s = s + data[i];
    }
    let total = wg_inclusive(t, s);
    if t == WG - 1u {
        sums[1u + wid.x] = total;
    }
}

@compute @workgroup_size(256)
fn scan_sums(@builtin(local_invocation_index) t: u32) {
    // groups <= 256: one range sum per thread.
    var v = 0u;
    if t < u.groups {
        v = sums[1u + t];
    }
    let inc = wg_inclusive(t, v);
    if t < u.groups {
        sums[1u + t] = inc - v;
    }
    if t == WG - 1u {
        sums[0] = inc;
    }
}

@compute @workgroup_size(256)
fn apply(@builtin(local_invocation_index) t: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = range_of(wid.x);
    if t == 0u {
        carry = sums[1u + wid.x];
    }
    workgroupBarrier();
    for (var b = r.x; b < r.y; b = b + BLOCK) {
        var v: array<u32, 4>;
        var own = 0u;
        for (var j = 0u; j < ITEMS; j = j + 1u) {
            let i = b + t * ITEMS + j;
            v[j] = select(0u, data[min(i, u.len - 1u)], i < r.y);
            own = own + v[j];
        }
        let inc = wg_inclusive(t, own);
        var run = carry + inc - own;
        for (var j = 0u; j < ITEMS; j = j + 1u) {
            let i = b + t * ITEMS + j;
            if i < r.y {
                data[i] = run;
            }
            run = run + v[j];
        }
        workgroupBarrier();
        if t == WG - 1u {
            carry = run;
        }
        workgroupBarrier();
    }
}
