// The object focus's masks (core/src/gpu/losses/focus.rs; CPU twins: coverage_mask
// and feature_mask in style/focus.rs). Masks are f32 0/1 so the losses can
// multiply by them. Runs once per view, on the colour-matched render's alpha.

struct FocusParams {
    // Render height and width.
    h: u32,
    w: u32,
    // Feature-map height and width (cells).
    fh: u32,
    fw: u32,
    // Erosion radius (Chebyshev, clipped to the image).
    radius: u32,
    // Alpha above which a pixel counts as covered.
    threshold: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: FocusParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// src = alpha (h × w), dst = pixel mask: 1 where every pixel within the
// radius (inside the image) has alpha above the threshold.
@compute @workgroup_size(256)
fn coverage(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    if p >= u.h * u.w {
        return;
    }
    let i = p / u.w;
    let j = p % u.w;
    let i0 = i - min(i, u.radius);
    let i1 = min(i + u.radius, u.h - 1u);
    let j0 = j - min(j, u.radius);
    let j1 = min(j + u.radius, u.w - 1u);
    var covered = 1.0;
    for (var y = i0; y <= i1; y++) {
        for (var x = j0; x <= j1; x++) {
            if !(src[y * u.w + x] > u.threshold) {
                covered = 0.0;
            }
        }
    }
    dst[p] = covered;
}

// src = pixel mask, dst = cell mask (fh × fw): 1 where at least half of the
// cell's pixels (rows i·h/fh .. (i+1)·h/fh, at least one) are covered.
@compute @workgroup_size(256)
fn cells(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = flat_index(gid, nwg);
    if k >= u.fh * u.fw {
        return;
    }
    let i = k / u.fw;
    let j = k % u.fw;
    let r0 = i * u.h / u.fh;
    let r1 = min(max((i + 1u) * u.h / u.fh, r0 + 1u), u.h);
    let c0 = j * u.w / u.fw;
    let c1 = min(max((j + 1u) * u.w / u.fw, c0 + 1u), u.w);
    var covered = 0u;
    for (var y = r0; y < r1; y++) {
        for (var x = c0; x < c1; x++) {
            covered += u32(src[y * u.w + x] > 0.5);
        }
    }
    dst[k] = select(0.0, 1.0, 2u * covered >= (r1 - r0) * (c1 - c0));
}

// src = pixel mask, dst (2 · h · w) = [pixel and its right neighbour both
// covered | pixel and the one below both covered]: summed, TV's difference counts.
@compute @workgroup_size(256)
fn pairs(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = flat_index(gid, nwg);
    let n = u.h * u.w;
    if p >= n {
        return;
    }
    let i = p / u.w;
    let j = p % u.w;
    var right = 0.0;
    var below = 0.0;
    if j + 1u < u.w {
        right = src[p] * src[p + 1u];
    }
    if i + 1u < u.h {
        below = src[p] * src[p + u.w];
    }
    dst[p] = right;
    dst[n + p] = below;
}
