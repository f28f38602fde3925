// Projects every Gaussian into screen space once per frame, with the rules of
// the CPU rasterizer (core/src/raster/project.rs): near plane z > 0.2, EWA 2D
// covariance with the 0.3 px low-pass and the 1.3·tan(half-fov) Jacobian clamp,
// sigmoid opacity (skipped below 1/255), the screen extent of the α ≥ 1/255
// ellipse (half-widths sqrt(2·ln(255·o)·Σ_xx), sqrt(2·ln(255·o)·Σ_yy)) and
// view-dependent SH colour (degree ≤ 3).
// Launched by app/src/studio/viewport/splat_project.rs.

struct View {
    rot0: vec4<f32>,        // rows of the world-to-camera rotation R
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    translation: vec4<f32>, // t (xyz)
    cam_pos: vec4<f32>,     // camera centre in world space (xyz)
    focal_principal: vec4<f32>, // fx, fy, cx, cy
    size_tan: vec4<f32>,    // width, height, tan_half_fov_x, tan_half_fov_y
    counts: vec4<u32>,      // num gaussians, sh degree, u32 words of SH per gaussian, split index
    background: vec4<f32>,
};

struct Projected {
    center_extent: vec4<f32>, // u, v (pixels), half-extents x, y (pixels; 0 = culled)
    conic_opacity: vec4<f32>, // conic xx, xy, yy, opacity
    color_depth: vec4<f32>,   // rgb, view depth
};

const NEAR_Z: f32 = 0.2;
const ALPHA_MIN: f32 = 0.00392156862745098; // 1/255
const EXTENT_REL: f32 = 1e-3;
const EXTENT_ABS: f32 = 1e-2;

@group(0) @binding(0) var<uniform> view: View;
// Per Gaussian three vec4: (mean, opacity logit), (log scale, 0), quaternion (w, x, y, z).
@group(0) @binding(1) var<storage, read> geom: array<vec4<f32>>;
// SH coefficients as packed f16 pairs, [gaussian][coef][channel]; Gaussians below
// the split index live in sh_a, the rest in sh_b (one binding holds at most 128 MiB).
@group(0) @binding(2) var<storage, read> sh_a: array<u32>;
@group(0) @binding(3) var<storage, read> sh_b: array<u32>;
@group(0) @binding(4) var<storage, read_write> projected: array<Projected>;

const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;

fn sh_half(i: u32, k: u32) -> f32 {
    // k: index of the half-float inside Gaussian i's block.
    let words = view.counts.z;
    let split = view.counts.w;
    var w: u32;
    if (i < split) {
        w = sh_a[i * words + k / 2u];
    } else {
        w = sh_b[(i - split) * words + k / 2u];
    }
    let pair = unpack2x16float(w);
    return select(pair.x, pair.y, (k & 1u) == 1u);
}

fn sh_coef(i: u32, c: u32) -> vec3<f32> {
    return vec3<f32>(sh_half(i, c * 3u), sh_half(i, c * 3u + 1u), sh_half(i, c * 3u + 2u));
}

fn sh_color(i: u32, deg: u32, d: vec3<f32>) -> vec3<f32> {
    var c = SH_C0 * sh_coef(i, 0u);
    if (deg >= 1u) {
        let x = d.x; let y = d.y; let z = d.z;
        c += -SH_C1 * y * sh_coef(i, 1u) + SH_C1 * z * sh_coef(i, 2u) - SH_C1 * x * sh_coef(i, 3u);
        if (deg >= 2u) {
            let xx = x * x; let yy = y * y; let zz = z * z;
            let xy = x * y; let yz = y * z; let xz = x * z;
            c += 1.0925484305920792 * xy * sh_coef(i, 4u)
                - 1.0925484305920792 * yz * sh_coef(i, 5u)
                + 0.31539156525252005 * (2.0 * zz - xx - yy) * sh_coef(i, 6u)
                - 1.0925484305920792 * xz * sh_coef(i, 7u)
                + 0.5462742152960396 * (xx - yy) * sh_coef(i, 8u);
            if (deg >= 3u) {
                c += -0.5900435899266435 * y * (3.0 * xx - yy) * sh_coef(i, 9u)
                    + 2.890611442640554 * xy * z * sh_coef(i, 10u)
                    - 0.4570457994644658 * y * (4.0 * zz - xx - yy) * sh_coef(i, 11u)
                    + 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh_coef(i, 12u)
                    - 0.4570457994644658 * x * (4.0 * zz - xx - yy) * sh_coef(i, 13u)
                    + 1.445305721320277 * z * (xx - yy) * sh_coef(i, 14u)
                    - 0.5900435899266435 * x * (xx - 3.0 * yy) * sh_coef(i, 15u);
            }
        }
    }
    return max(c + vec3<f32>(0.5), vec3<f32>(0.0));
}

fn culled() -> Projected {
    var p: Projected;
    p.center_extent = vec4<f32>(0.0);
    p.conic_opacity = vec4<f32>(0.0);
    p.color_depth = vec4<f32>(0.0);
    return p;
}

@compute @workgroup_size(256)
fn project(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    // 2D dispatch so that more than 65535 workgroups' worth of Gaussians fit.
    let i = gid.x + gid.y * nwg.x * 256u;
    if (i >= view.counts.x) {
        return;
    }
    let g0 = geom[i * 3u];
    let g1 = geom[i * 3u + 1u];
    let q = normalize(geom[i * 3u + 2u]);
    let mean = g0.xyz;

    let r0 = view.rot0.xyz;
    let r1 = view.rot1.xyz;
    let r2 = view.rot2.xyz;
    let tc = vec3<f32>(dot(r0, mean), dot(r1, mean), dot(r2, mean)) + view.translation.xyz;
    let opacity = 1.0 / (1.0 + exp(-g0.w));
    if (tc.z <= NEAR_Z || opacity < ALPHA_MIN) {
        projected[i] = culled();
        return;
    }

    let fx = view.focal_principal.x;
    let fy = view.focal_principal.y;
    let cx = view.focal_principal.z;
    let cy = view.focal_principal.w;

    // Rotation of the Gaussian from its quaternion (w, x, y, z).
    let w = q.x; let x = q.y; let y = q.z; let z = q.w;
    // Columns of the rotation matrix.
    let rg = mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
    let s = exp(g1.xyz);
    let m = mat3x3<f32>(rg[0] * s.x, rg[1] * s.y, rg[2] * s.z);
    let sigma3 = m * transpose(m);

    let limx = 1.3 * view.size_tan.z;
    let limy = 1.3 * view.size_tan.w;
    let txz = clamp(tc.x / tc.z, -limx, limx) * tc.z;
    let tyz = clamp(tc.y / tc.z, -limy, limy) * tc.z;
    let iz = 1.0 / tc.z;
    // J·W with W = R (rows r0, r1, r2): rows of the 2×3 matrix T.
    let j0 = vec3<f32>(fx * iz, 0.0, -fx * txz * iz * iz);
    let j1 = vec3<f32>(0.0, fy * iz, -fy * tyz * iz * iz);
    let t0 = j0.x * r0 + j0.y * r1 + j0.z * r2;
    let t1 = j1.x * r0 + j1.y * r1 + j1.z * r2;
    let st0 = sigma3 * t0;
    let st1 = sigma3 * t1;
    let a = dot(t0, st0) + 0.3;
    let b = dot(t0, st1);
    let c = dot(t1, st1) + 0.3;
    let det = a * c - b * b;
    if (det <= 0.0) {
        projected[i] = culled();
        return;
    }
    let inv_det = 1.0 / det;
    let cut = max(log(255.0 * opacity), 0.0);
    let ext = vec2<f32>(sqrt(2.0 * cut * a), sqrt(2.0 * cut * c)) * (1.0 + EXTENT_REL) + vec2<f32>(EXTENT_ABS);
    let u = fx * tc.x * iz + cx;
    let v = fy * tc.y * iz + cy;
    // The pixel centres (j + 0.5, i + 0.5) inside the box, clamped to the screen: none
    // means nothing to draw (the CPU rasterizer evaluates pixel centres only), which
    // also drops the many sub-pixel splats of big scenes before the rasterizer sees them.
    let first = max(ceil(vec2<f32>(u, v) - ext - vec2<f32>(0.5)), vec2<f32>(0.0));
    let last = min(floor(vec2<f32>(u, v) + ext - vec2<f32>(0.5)), view.size_tan.xy - vec2<f32>(1.0));
    if (any(last < first)) {
        projected[i] = culled();
        return;
    }

    let dir = normalize(mean - view.cam_pos.xyz);
    var p: Projected;
    p.center_extent = vec4<f32>(u, v, ext);
    p.conic_opacity = vec4<f32>(c * inv_det, -b * inv_det, a * inv_det, opacity);
    p.color_depth = vec4<f32>(sh_color(i, view.counts.y, dir), tc.z);
    projected[i] = p;
}
