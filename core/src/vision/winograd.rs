//! Winograd F(4×4, 3×3): VGG's 3×3 convolutions with 4× fewer multiplies.
//!
//! A step spends most of its time in the three VGG forwards and two
//! backwards, and im2col + gemm already runs near the `gemm` crate's rate, so
//! the exact convolution only gets faster by doing fewer operations (issue 10).
//! Winograd's minimal filtering computes a 4×4 output tile from a 6×6 input
//! tile with 36 element-wise products per (input, output) channel pair instead
//! of 144: `Y = Aᵀ [(G g Gᵀ) ⊙ (Bᵀ d B)] A`. Summed over input channels, the
//! element-wise products become 36 independent matrix products
//! `M_ξ (c_out × tiles) = U_ξ (c_out × c_in) · V_ξ (c_in × tiles)`, which run on
//! `gemm` like im2col's single product does.
//!
//! The input gradient of a zero-padded "same" 3×3 convolution is itself one,
//! with the kernel transposed over channels and flipped in space, so the
//! backward pass is the same routine with other transformed weights.
//!
//! im2col (`conv.rs`) stays as the reference; the tests compare the two.
//! Transforms are the usual interpolation points 0, ±1, ±2, ∞ (Lavin & Gray
//! 2015); in `f32` they agree with the direct convolution to about 1e-6 of
//! the output scale.

use rayon::prelude::*;

use super::conv::matmul_serial;

/// Output tile side.
const TILE: usize = 4;
/// Input tile side (`TILE + 2`).
const ALPHA: usize = 6;
/// Points of the transformed domain (`ALPHA²`): one gemm each.
const XI: usize = ALPHA * ALPHA;
/// Largest transformed band (input and output together), in f32 elements (32 MB).
const BAND_ELEMS: usize = 1 << 23;

/// `G`, the kernel transform (6 × 3).
const G: [[f64; 3]; ALPHA] = [
    [1.0 / 4.0, 0.0, 0.0],
    [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
    [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
    [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
    [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
    [0.0, 0.0, 1.0],
];

/// `Bᵀ x` for a 6-vector (the input transform along one axis).
#[inline(always)]
fn bt(x: [f32; ALPHA]) -> [f32; ALPHA] {
    [
        4.0 * x[0] - 5.0 * x[2] + x[4],
        -4.0 * (x[1] + x[2]) + x[3] + x[4],
        4.0 * (x[1] - x[2]) - x[3] + x[4],
        2.0 * (x[3] - x[1]) - x[2] + x[4],
        2.0 * (x[1] - x[3]) - x[2] + x[4],
        4.0 * x[1] - 5.0 * x[3] + x[5],
    ]
}

/// `Aᵀ x` for a 6-vector (the output transform along one axis).
#[inline(always)]
fn at(x: [f32; ALPHA]) -> [f32; TILE] {
    let (p1, m1) = (x[1] + x[2], x[1] - x[2]);
    let (p2, m2) = (x[3] + x[4], x[3] - x[4]);
    [x[0] + p1 + p2, m1 + 2.0 * m2, p1 + 4.0 * p2, m1 + 8.0 * m2 + x[5]]
}

/// A 3×3 convolution's kernel in the Winograd domain: for each of the 36
/// points ξ, the `c_out × c_in` matrix `U_ξ` (layout `[ξ][o][i]`).
#[derive(Clone, Debug, PartialEq)]
pub struct WinogradKernel {
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
    u: Vec<f32>,
}

impl WinogradKernel {
    /// Transforms OIHW weights (`c_out × c_in × 3 × 3`) for the forward convolution.
    pub fn forward(weight: &[f32], c_out: usize, c_in: usize) -> Self {
        Self::transform(c_out, c_in, |o, i, ky, kx| weight[((o * c_in + i) * 3 + ky) * 3 + kx])
    }

    /// Transforms the same weights for the input gradient: the convolution
    /// from `c_out` to `c_in` channels with the kernel flipped in space.
    pub fn input_gradient(weight: &[f32], c_out: usize, c_in: usize) -> Self {
        Self::transform(c_in, c_out, |i, o, ky, kx| weight[((o * c_in + i) * 3 + 2 - ky) * 3 + 2 - kx])
    }

    /// `U = G g Gᵀ` (in f64) for every channel pair of the kernel `g(o, i, ky, kx)`.
    fn transform(c_out: usize, c_in: usize, g: impl Fn(usize, usize, usize, usize) -> f32 + Sync) -> Self {
        let mut u = vec![0f32; XI * c_out * c_in];
        let per_pair: Vec<[f32; XI]> = (0..c_out * c_in)
            .into_par_iter()
            .map(|p| {
                let (o, i) = (p / c_in, p % c_in);
                // t = G g (6 × 3), then U = t Gᵀ (6 × 6).
                let mut t = [[0f64; 3]; ALPHA];
                for (r, row) in t.iter_mut().enumerate() {
                    for (kx, v) in row.iter_mut().enumerate() {
                        *v = (0..3).map(|ky| G[r][ky] * f64::from(g(o, i, ky, kx))).sum();
                    }
                }
                let mut out = [0f32; XI];
                for r in 0..ALPHA {
                    for c in 0..ALPHA {
                        out[r * ALPHA + c] = (0..3).map(|k| t[r][k] * G[c][k]).sum::<f64>() as f32;
                    }
                }
                out
            })
            .collect();
        for (p, vals) in per_pair.iter().enumerate() {
            for (xi, &v) in vals.iter().enumerate() {
                u[xi * c_out * c_in + p] = v;
            }
        }
        Self { c_in, c_out, u }
    }
}

/// `out = conv3x3(input)` (zero padding 1, no bias), `input` `c_in × h × w`,
/// `out` `c_out × h × w`, both CHW; overwrites `out`.
pub(crate) fn winograd_conv(
    input: &[f32],
    (c_in, h, w): (usize, usize, usize),
    kernel: &WinogradKernel,
    out: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    winograd_conv_banded(input, (c_in, h, w), kernel, out, scratch, BAND_ELEMS);
}

/// [`winograd_conv`] over bands of tile rows, each holding at most `band_elems`
/// transformed values.
pub(crate) fn winograd_conv_banded(
    input: &[f32],
    (c_in, h, w): (usize, usize, usize),
    kernel: &WinogradKernel,
    out: &mut [f32],
    scratch: &mut Vec<f32>,
    band_elems: usize,
) {
    assert_eq!(kernel.c_in, c_in, "winograd_conv: the kernel's input channels");
    let c_out = kernel.c_out;
    assert!(input.len() >= c_in * h * w && out.len() >= c_out * h * w, "winograd_conv: buffer sizes");
    if h == 0 || w == 0 || c_out == 0 {
        return;
    }
    let (tiles_y, tiles_x) = (h.div_ceil(TILE), w.div_ceil(TILE));
    let per_row = XI * (c_in + c_out) * tiles_x;
    let band_rows = (band_elems / per_row.max(1)).clamp(1, tiles_y);
    // Each ξ's row of tiles starts `stride` floats after the previous one: a
    // multiple of 16 plus 16, so the 36 rows never sit 4 KiB apart (which
    // would map them onto the same cache sets).
    let stride = (band_rows * tiles_x).next_multiple_of(16) + 16;
    // M's ξ blocks, `c_out` rows each, start 16 floats further apart than
    // their rows: the output transform reads one value from each of the 36
    // blocks per tile, and `c_out · stride` floats is a multiple of 4 KiB,
    // so unpadded those 36 reads all fell in one cache set (one source line
    // took 11 % of a CPU step's samples).
    let m_block = c_out * stride + 16;
    scratch.resize(scratch.len().max(XI * (c_in * stride + m_block)), 0.0);
    let (v_buf, m_buf) = scratch.split_at_mut(XI * c_in * stride);
    let mut ty0 = 0;
    while ty0 < tiles_y {
        let ty1 = (ty0 + band_rows).min(tiles_y);
        let nt = (ty1 - ty0) * tiles_x;
        // V: [ci][ξ][tile], [`LANES`] tiles of a row at once (each ξ's values
        // of them one contiguous run), the row's last few one by one.
        v_buf.par_chunks_mut(XI * stride).take(c_in).enumerate().for_each(|(ci, vc)| {
            let plane = &input[ci * h * w..(ci + 1) * h * w];
            for ty in ty0..ty1 {
                let t = (ty - ty0) * tiles_x;
                let mut tx = 0;
                while tx + LANES <= tiles_x {
                    let v = input_transform_lanes(&gather_lanes(plane, h, w, ty * TILE, tx * TILE));
                    for (xi, lanes) in v.iter().enumerate() {
                        vc[xi * stride + t + tx..xi * stride + t + tx + LANES].copy_from_slice(lanes);
                    }
                    tx += LANES;
                }
                for tx in tx..tiles_x {
                    let d = gather(plane, h, w, ty * TILE, tx * TILE);
                    for (xi, val) in input_transform(&d).into_iter().enumerate() {
                        vc[xi * stride + t + tx] = val;
                    }
                }
            }
        });
        // M_ξ = U_ξ · V_ξ, M: [ξ][co][tile]. The 36 products are independent and
        // small (a few MFLOP at relu3), so the threads share them out rather
        // than splitting each one: one rayon hand-off per band, not per ξ.
        m_buf[..XI * m_block].par_chunks_mut(m_block).enumerate().for_each(|(xi, dst)| {
            let u = &kernel.u[xi * c_out * c_in..(xi + 1) * c_out * c_in];
            let rhs = &v_buf[xi * stride..];
            matmul_serial(
                &mut dst[..c_out * stride],
                stride,
                (u, c_in, 1),
                (rhs, XI * stride),
                (c_out, nt, c_in),
                false,
            );
        });
        // Y = Aᵀ M A per output channel and tile.
        let (m, y_hi) = (&*m_buf, (ty1 * TILE).min(h));
        out[..c_out * h * w].par_chunks_mut(h * w).enumerate().for_each(|(co, plane)| {
            let mut tile = [0f32; XI];
            for ty in ty0..ty1 {
                let t0 = (ty - ty0) * tiles_x;
                let oy = ty * TILE;
                let rows = y_hi.min(oy + TILE) - oy;
                let mut tx = 0;
                while tx + LANES <= tiles_x {
                    let at = co * stride + t0 + tx;
                    let y = output_transform_lanes(&std::array::from_fn(|xi| {
                        let run = &m[xi * m_block + at..xi * m_block + at + LANES];
                        std::array::from_fn(|l| run[l])
                    }));
                    for lane in 0..LANES {
                        let ox = (tx + lane) * TILE;
                        let n = TILE.min(w - ox);
                        for (r, row) in y.iter().enumerate().take(rows) {
                            let dst = &mut plane[(oy + r) * w + ox..(oy + r) * w + ox + n];
                            dst.iter_mut().zip(row).for_each(|(d, v)| *d = v[lane]);
                        }
                    }
                    tx += LANES;
                }
                for tx in tx..tiles_x {
                    for (xi, v) in tile.iter_mut().enumerate() {
                        *v = m[xi * m_block + co * stride + t0 + tx];
                    }
                    let y = output_transform(&tile);
                    let ox = tx * TILE;
                    let n = TILE.min(w - ox);
                    for (r, row) in y.iter().enumerate().take(rows) {
                        plane[(oy + r) * w + ox..(oy + r) * w + ox + n].copy_from_slice(&row[..n]);
                    }
                }
            }
        });
        ty0 = ty1;
    }
}

/// The 6×6 input tile whose top-left output pixel is `(oy, ox)`: rows
/// `oy−1 .. oy+5`, columns `ox−1 .. ox+5`, zero outside the plane.
#[inline(always)]
fn gather(plane: &[f32], h: usize, w: usize, oy: usize, ox: usize) -> [f32; XI] {
    let mut d = [0f32; XI];
    let interior = oy >= 1 && ox >= 1 && oy + 5 <= h && ox + 5 <= w;
    for r in 0..ALPHA {
        let sy = oy + r;
        if sy == 0 || sy > h {
            continue;
        }
        let row = &plane[(sy - 1) * w..sy * w];
        if interior {
            d[r * ALPHA..(r + 1) * ALPHA].copy_from_slice(&row[ox - 1..ox + 5]);
        } else {
            for c in 0..ALPHA {
                let sx = ox + c;
                if sx >= 1 && sx <= w {
                    d[r * ALPHA + c] = row[sx - 1];
                }
            }
        }
    }
    d
}

/// `Bᵀ d B` of a 6×6 tile (row-major).
#[inline(always)]
fn input_transform(d: &[f32; XI]) -> [f32; XI] {
    let mut cols = [[0f32; ALPHA]; ALPHA];
    for c in 0..ALPHA {
        let col = bt(std::array::from_fn(|r| d[r * ALPHA + c]));
        for r in 0..ALPHA {
            cols[r][c] = col[r];
        }
    }
    let mut out = [0f32; XI];
    for r in 0..ALPHA {
        out[r * ALPHA..(r + 1) * ALPHA].copy_from_slice(&bt(cols[r]));
    }
    out
}

/// `Aᵀ M A` of a 6×6 tile: the 4×4 outputs.
#[inline(always)]
fn output_transform(m: &[f32; XI]) -> [[f32; TILE]; TILE] {
    let mut rows = [[0f32; ALPHA]; TILE];
    for c in 0..ALPHA {
        let col = at(std::array::from_fn(|r| m[r * ALPHA + c]));
        for r in 0..TILE {
            rows[r][c] = col[r];
        }
    }
    rows.map(at)
}

/// Tiles of a row the transforms take at once: the same operations as one
/// tile's ([`input_transform`], [`output_transform`]), each on `LANES`
/// values, which the compiler runs as vector instructions (the results are
/// the one-tile path's to the bit).
const LANES: usize = 8;

/// One value for each of [`LANES`] tiles.
type Lanes = [f32; LANES];

/// [`gather`] of the `LANES` tiles side by side from `(oy, ox)` on.
#[inline(always)]
fn gather_lanes(plane: &[f32], h: usize, w: usize, oy: usize, ox: usize) -> [Lanes; XI] {
    let interior = oy >= 1 && ox >= 1 && oy + 5 <= h && ox + TILE * (LANES - 1) + 5 <= w;
    if !interior {
        let tiles: [[f32; XI]; LANES] = std::array::from_fn(|l| gather(plane, h, w, oy, ox + l * TILE));
        return std::array::from_fn(|i| std::array::from_fn(|l| tiles[l][i]));
    }
    let mut d = [[0f32; LANES]; XI];
    for r in 0..ALPHA {
        let row = &plane[(oy + r - 1) * w + ox - 1..];
        for c in 0..ALPHA {
            d[r * ALPHA + c] = std::array::from_fn(|l| row[l * TILE + c]);
        }
    }
    d
}

/// `f` (a transform of `N` values into `M`) lane by lane.
#[inline(always)]
fn per_lane<const N: usize, const M: usize>(x: [Lanes; N], f: impl Fn([f32; N]) -> [f32; M]) -> [Lanes; M] {
    let mut out = [[0f32; LANES]; M];
    for l in 0..LANES {
        let y = f(std::array::from_fn(|i| x[i][l]));
        for i in 0..M {
            out[i][l] = y[i];
        }
    }
    out
}

/// [`bt`] lane by lane.
#[inline(always)]
fn bt_lanes(x: [Lanes; ALPHA]) -> [Lanes; ALPHA] {
    per_lane(x, bt)
}

/// [`at`] lane by lane.
#[inline(always)]
fn at_lanes(x: [Lanes; ALPHA]) -> [Lanes; TILE] {
    per_lane(x, at)
}

/// [`input_transform`] of `LANES` tiles.
#[inline(always)]
fn input_transform_lanes(d: &[Lanes; XI]) -> [Lanes; XI] {
    let mut cols = [[[0f32; LANES]; ALPHA]; ALPHA];
    for c in 0..ALPHA {
        let col = bt_lanes(std::array::from_fn(|r| d[r * ALPHA + c]));
        for r in 0..ALPHA {
            cols[r][c] = col[r];
        }
    }
    let mut out = [[0f32; LANES]; XI];
    for r in 0..ALPHA {
        out[r * ALPHA..(r + 1) * ALPHA].copy_from_slice(&bt_lanes(cols[r]));
    }
    out
}

/// [`output_transform`] of `LANES` tiles.
#[inline(always)]
fn output_transform_lanes(m: &[Lanes; XI]) -> [[Lanes; TILE]; TILE] {
    let mut rows = [[[0f32; LANES]; ALPHA]; TILE];
    for c in 0..ALPHA {
        let col = at_lanes(std::array::from_fn(|r| m[r * ALPHA + c]));
        for r in 0..TILE {
            rows[r][c] = col[r];
        }
    }
    rows.map(at_lanes)
}

/// Multiplies of one 3×3 convolution at `h × w` (multiply and add counted apart)
/// in its three parts: input transform, the batched products, output transform.
pub fn winograd_flops(c_in: usize, c_out: usize, h: usize, w: usize) -> [f64; 3] {
    let tiles = (h.div_ceil(TILE) * w.div_ceil(TILE)) as f64;
    // Bᵀ d B: 12 six-point transforms of ~12 operations; Aᵀ M A: 10 of ~14.
    [
        tiles * c_in as f64 * 12.0 * 12.0,
        2.0 * XI as f64 * tiles * (c_in * c_out) as f64,
        tiles * c_out as f64 * 10.0 * 14.0,
    ]
}

#[cfg(test)]
#[path = "winograd_tests.rs"]
mod tests;
