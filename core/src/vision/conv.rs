//! The kernels VGG is made of: 3×3 convolution as im2col + gemm (and its
//! input-gradient as gemm + col2im), and 2×2 max pooling.
//!
//! Layouts are CHW, weights OIHW flattened to `c_out × (c_in·9)`. The im2col
//! matrix is built for a band of output rows at a time, so its size stays
//! bounded (a 512-pixel-high style image at conv1_2 would otherwise need
//! gigabytes) and one scratch buffer is reused for every layer.
//!
//! [`ConvAlgo`] picks between this reference and Winograd (`winograd.rs`),
//! which does the same convolutions with a quarter of the multiplies.

use rayon::prelude::*;

/// How VGG's 3×3 convolutions are computed (both exact up to rounding).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ConvAlgo {
    /// im2col + one gemm per layer: the reference.
    #[default]
    Im2col,
    /// Winograd F(4×4, 3×3): 36 batched gemms on transformed tiles, 4× fewer multiplies.
    Winograd,
}

impl ConvAlgo {
    /// Every choice, in the order the CLI lists them.
    pub const ALL: [ConvAlgo; 2] = [ConvAlgo::Im2col, ConvAlgo::Winograd];

    /// The name used by flags and preset files.
    pub fn name(self) -> &'static str {
        match self {
            ConvAlgo::Im2col => "im2col",
            ConvAlgo::Winograd => "winograd",
        }
    }
}

impl std::fmt::Display for ConvAlgo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ConvAlgo {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL.into_iter().find(|a| a.name() == s).ok_or_else(|| {
            format!("unknown convolution '{s}': expected one of {}", Self::ALL.map(|a| a.name()).join(", "))
        })
    }
}

/// Largest im2col band, in f32 elements (32 MB).
const BAND_ELEMS: usize = 1 << 23;

/// Output rows per im2col band for a layer with `k` rows in its column matrix.
fn band_rows(k: usize, h: usize, w: usize, band_elems: usize) -> usize {
    (band_elems / (k * w).max(1)).clamp(1, h.max(1))
}

/// `dst[i·dst_rs + j] (+)= Σ_p lhs[i·lhs_rs + p·lhs_cs] · rhs[p·rhs_rs + j]`
/// for `i < m, j < n, p < k`, on gemm's rayon threads.
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul(
    dst: &mut [f32],
    dst_rs: usize,
    lhs: (&[f32], usize, usize),
    rhs: (&[f32], usize),
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
) {
    let threads = rayon::current_num_threads();
    let par =
        if threads > 1 && m * n * k > 1 << 16 { gemm::Parallelism::Rayon(threads) } else { gemm::Parallelism::None };
    gemm_strided(dst, dst_rs, lhs, rhs, (m, n, k), accumulate, par);
}

/// [`matmul`] on the calling thread only: for products that are themselves
/// tasks of a rayon loop (the depth network's attention blocks).
pub(crate) fn matmul_serial(
    dst: &mut [f32],
    dst_rs: usize,
    lhs: (&[f32], usize, usize),
    rhs: (&[f32], usize),
    mnk: (usize, usize, usize),
    accumulate: bool,
) {
    gemm_strided(dst, dst_rs, lhs, rhs, mnk, accumulate, gemm::Parallelism::None);
}

fn gemm_strided(
    dst: &mut [f32],
    dst_rs: usize,
    (lhs, lhs_rs, lhs_cs): (&[f32], usize, usize),
    (rhs, rhs_rs): (&[f32], usize),
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
    par: gemm::Parallelism,
) {
    if m == 0 || n == 0 || k == 0 {
        return;
    }
    assert!((m - 1) * dst_rs + n <= dst.len(), "matmul: dst too small");
    assert!((m - 1) * lhs_rs + (k - 1) * lhs_cs < lhs.len(), "matmul: lhs too small");
    assert!((k - 1) * rhs_rs + n <= rhs.len(), "matmul: rhs too small");
    // SAFETY: the asserts above keep every element gemm touches, at the
    // strides given, inside the three slices; dst is borrowed mutably, so it
    // aliases neither input.
    #[allow(unsafe_code)]
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            dst_rs as isize,
            accumulate,
            lhs.as_ptr(),
            lhs_cs as isize,
            lhs_rs as isize,
            rhs.as_ptr(),
            1,
            rhs_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            par,
        );
    }
}

/// The measured rate of the matrix product every convolution runs on, in
/// GFLOP/s (best of `reps`, `m × k` by `k × n`, all rayon threads): the floor
/// against which the VGG passes are judged.
pub fn gemm_gflops(m: usize, n: usize, k: usize, reps: usize) -> f64 {
    let a: Vec<f32> = (0..m * k).map(|i| ((i % 17) as f32 - 8.0) * 0.01).collect();
    let b: Vec<f32> = (0..k * n).map(|i| ((i % 13) as f32 - 6.0) * 0.01).collect();
    let mut c = vec![0.0f32; m * n];
    matmul(&mut c, n, (&a, k, 1), (&b, n), (m, n, k), false);
    let mut best = f64::INFINITY;
    for _ in 0..reps.max(1) {
        let t = std::time::Instant::now();
        matmul(&mut c, n, (&a, k, 1), (&b, n), (m, n, k), false);
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(&c);
    2.0 * (m * n * k) as f64 / best / 1e9
}

/// Fills `cols` (`c_in·9 × (y1−y0)·w`) with the 3×3 zero-padded neighbourhoods
/// of output rows `y0..y1`.
fn im2col(input: &[f32], c_in: usize, h: usize, w: usize, y0: usize, y1: usize, cols: &mut [f32]) {
    let n = (y1 - y0) * w;
    cols[..c_in * 9 * n].par_chunks_mut(n).enumerate().for_each(|(r, row)| {
        let (ci, ky, kx) = (r / 9, (r / 3) % 3, r % 3);
        let plane = &input[ci * h * w..(ci + 1) * h * w];
        for (y, dst) in (y0..y1).zip(row.chunks_exact_mut(w)) {
            let sy = y as isize + ky as isize - 1;
            if sy < 0 || sy >= h as isize {
                dst.fill(0.0);
                continue;
            }
            let src = &plane[sy as usize * w..(sy as usize + 1) * w];
            match kx {
                0 => {
                    dst[0] = 0.0;
                    dst[1..].copy_from_slice(&src[..w - 1]);
                }
                1 => dst.copy_from_slice(src),
                _ => {
                    dst[..w - 1].copy_from_slice(&src[1..]);
                    dst[w - 1] = 0.0;
                }
            }
        }
    });
}

/// Adds the column-matrix gradient `cols` of output rows `y0..y1` back onto
/// the input planes (the adjoint of [`im2col`]).
fn col2im(cols: &[f32], c_in: usize, h: usize, w: usize, y0: usize, y1: usize, v_input: &mut [f32]) {
    let n = (y1 - y0) * w;
    v_input[..c_in * h * w].par_chunks_mut(h * w).enumerate().for_each(|(ci, plane)| {
        for tap in 0..9 {
            let (ky, kx) = (tap / 3, tap % 3);
            let row = &cols[(ci * 9 + tap) * n..(ci * 9 + tap + 1) * n];
            for (y, src) in (y0..y1).zip(row.chunks_exact(w)) {
                let sy = y as isize + ky as isize - 1;
                if sy < 0 || sy >= h as isize {
                    continue;
                }
                let dst = &mut plane[sy as usize * w..(sy as usize + 1) * w];
                match kx {
                    0 => dst[..w - 1].iter_mut().zip(&src[1..]).for_each(|(d, s)| *d += s),
                    1 => dst.iter_mut().zip(src).for_each(|(d, s)| *d += s),
                    _ => dst[1..].iter_mut().zip(&src[..w - 1]).for_each(|(d, s)| *d += s),
                }
            }
        }
    });
}

/// `out = relu(conv3x3(input) + bias)`; `out` is `c_out × h × w`.
pub(crate) fn conv_relu(
    input: &[f32],
    dims: (usize, usize, usize),
    weight: &[f32],
    bias: &[f32],
    out: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    conv_relu_banded(input, dims, weight, bias, out, scratch, BAND_ELEMS, true);
}

/// `out = conv3x3(input) + bias`, without the ReLU: the reference the
/// Winograd convolutions and the linearised network are tested against.
#[cfg(test)]
pub(crate) fn conv_affine(
    input: &[f32],
    dims: (usize, usize, usize),
    weight: &[f32],
    bias: &[f32],
    out: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    conv_relu_banded(input, dims, weight, bias, out, scratch, BAND_ELEMS, false);
}

#[allow(clippy::too_many_arguments)]
fn conv_relu_banded(
    input: &[f32],
    (c_in, h, w): (usize, usize, usize),
    weight: &[f32],
    bias: &[f32],
    out: &mut [f32],
    scratch: &mut Vec<f32>,
    band_elems: usize,
    relu: bool,
) {
    let (c_out, k) = (bias.len(), c_in * 9);
    let rows = band_rows(k, h, w, band_elems);
    scratch.resize(scratch.len().max(k * rows * w), 0.0);
    let mut y0 = 0;
    while y0 < h {
        let y1 = (y0 + rows).min(h);
        let n = (y1 - y0) * w;
        im2col(input, c_in, h, w, y0, y1, scratch);
        matmul(&mut out[y0 * w..], h * w, (weight, k, 1), (scratch, n), (c_out, n, k), false);
        y0 = y1;
    }
    add_bias(&mut out[..c_out * h * w], h * w, bias, relu);
}

/// `plane += bias` per channel plane of `out` (`bias.len() × n`), then the ReLU when `relu`.
pub(crate) fn add_bias(out: &mut [f32], n: usize, bias: &[f32], relu: bool) {
    out[..bias.len() * n].par_chunks_mut(n).zip(bias).for_each(|(plane, &b)| {
        if relu {
            plane.iter_mut().for_each(|v| *v = (*v + b).max(0.0));
        } else {
            plane.iter_mut().for_each(|v| *v += b);
        }
    });
}

/// Input gradient of a 3×3 convolution: `v_input = convᵀ(v_out)` (overwrites `v_input`).
pub(crate) fn conv_backward(
    v_out: &[f32],
    dims: (usize, usize, usize),
    weight: &[f32],
    c_out: usize,
    v_input: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    conv_backward_banded(v_out, dims, weight, c_out, v_input, scratch, BAND_ELEMS);
}

#[allow(clippy::too_many_arguments)]
fn conv_backward_banded(
    v_out: &[f32],
    (c_in, h, w): (usize, usize, usize),
    weight: &[f32],
    c_out: usize,
    v_input: &mut [f32],
    scratch: &mut Vec<f32>,
    band_elems: usize,
) {
    let k = c_in * 9;
    let rows = band_rows(k, h, w, band_elems);
    scratch.resize(scratch.len().max(k * rows * w), 0.0);
    v_input[..c_in * h * w].fill(0.0);
    let mut y0 = 0;
    while y0 < h {
        let y1 = (y0 + rows).min(h);
        let n = (y1 - y0) * w;
        // Wᵀ is `k × c_out`: element (p, o) at o·k + p.
        matmul(scratch, n, (weight, 1, k), (&v_out[y0 * w..], h * w), (k, n, c_out), false);
        col2im(scratch, c_in, h, w, y0, y1, v_input);
        y0 = y1;
    }
}

/// 2×2 stride-2 max pooling with torch's floor semantics (odd last rows and
/// columns are dropped). With `argmax`, records for each output the flat
/// in-plane index of its maximum (the first one on ties, as torch does).
pub(crate) fn max_pool(
    input: &[f32],
    (c, h, w): (usize, usize, usize),
    out: &mut [f32],
    argmax: Option<&mut Vec<u32>>,
) {
    let (ho, wo) = (h / 2, w / 2);
    let pool_plane = |ci: usize, o: &mut [f32], mut a: Option<&mut [u32]>| {
        let plane = &input[ci * h * w..(ci + 1) * h * w];
        for y in 0..ho {
            for x in 0..wo {
                let i0 = 2 * y * w + 2 * x;
                let mut best = i0;
                for i in [i0 + 1, i0 + w, i0 + w + 1] {
                    if plane[i] > plane[best] {
                        best = i;
                    }
                }
                o[y * wo + x] = plane[best];
                if let Some(a) = a.as_deref_mut() {
                    a[y * wo + x] = best as u32;
                }
            }
        }
    };
    let out = &mut out[..c * ho * wo];
    match argmax {
        Some(arg) => {
            arg.clear();
            arg.resize(c * ho * wo, 0);
            out.par_chunks_mut(ho * wo)
                .zip(arg.par_chunks_mut(ho * wo))
                .enumerate()
                .for_each(|(ci, (o, a))| pool_plane(ci, o, Some(a)));
        }
        None => out.par_chunks_mut(ho * wo).enumerate().for_each(|(ci, o)| pool_plane(ci, o, None)),
    }
}

/// Routes each pooled gradient to the input position that won the max.
pub(crate) fn max_pool_backward(v_out: &[f32], argmax: &[u32], (c, h, w): (usize, usize, usize), v_input: &mut [f32]) {
    let no = (h / 2) * (w / 2);
    v_input[..c * h * w].par_chunks_mut(h * w).enumerate().for_each(|(ci, plane)| {
        plane.fill(0.0);
        for (v, &a) in v_out[ci * no..(ci + 1) * no].iter().zip(&argmax[ci * no..(ci + 1) * no]) {
            plane[a as usize] += v;
        }
    });
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Deterministic values in [-1, 1) (also the VGG tests' inputs).
    pub(crate) fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    /// The obvious 3×3 zero-padded convolution, in f64, without ReLU.
    fn naive_conv(x: &[f32], (c_in, h, w): (usize, usize, usize), wt: &[f32], bias: &[f32]) -> Vec<f64> {
        let c_out = bias.len();
        let mut out = vec![0.0; c_out * h * w];
        for o in 0..c_out {
            for y in 0..h {
                for xx in 0..w {
                    let mut acc = bias[o] as f64;
                    for i in 0..c_in {
                        for ky in 0..3 {
                            for kx in 0..3 {
                                let (sy, sx) = (y as isize + ky as isize - 1, xx as isize + kx as isize - 1);
                                if sy >= 0 && sx >= 0 && (sy as usize) < h && (sx as usize) < w {
                                    acc += wt[((o * c_in + i) * 3 + ky) * 3 + kx] as f64
                                        * x[(i * h + sy as usize) * w + sx as usize] as f64;
                                }
                            }
                        }
                    }
                    out[(o * h + y) * w + xx] = acc;
                }
            }
        }
        out
    }

    #[test]
    fn conv_matches_naive_and_backward_is_its_adjoint() {
        let mut failures = Vec::new();
        for (c_in, c_out, h, w, band) in [(3, 5, 7, 9, 1 << 23), (4, 6, 9, 5, 4 * 9 * 5 * 2), (2, 3, 1, 6, 1)] {
            let x = noise(c_in * h * w, 1);
            let wt = noise(c_out * c_in * 9, 2);
            let bias = noise(c_out, 3);
            let mut out = vec![0.0; c_out * h * w];
            let mut scratch = Vec::new();
            conv_relu_banded(&x, (c_in, h, w), &wt, &bias, &mut out, &mut scratch, band, true);
            let reference = naive_conv(&x, (c_in, h, w), &wt, &bias);
            for (i, (a, b)) in out.iter().zip(&reference).enumerate() {
                if (*a as f64 - b.max(0.0)).abs() > 1e-5 {
                    failures.push(format!("{c_in}x{h}x{w} forward[{i}]: {a} vs {}", b.max(0.0)));
                }
            }
            // <conv(x) - bias, v> == <x, convᵀ(v)>
            let v = noise(c_out * h * w, 4);
            let mut v_in = vec![0.0; c_in * h * w];
            conv_backward_banded(&v, (c_in, h, w), &wt, c_out, &mut v_in, &mut scratch, band);
            let lhs: f64 =
                reference.iter().enumerate().map(|(i, r)| (r - bias[i / (h * w)] as f64) * v[i] as f64).sum();
            let rhs: f64 = x.iter().zip(&v_in).map(|(a, b)| *a as f64 * *b as f64).sum();
            if (lhs - rhs).abs() > 1e-4 * lhs.abs().max(1.0) {
                failures.push(format!("{c_in}x{h}x{w} adjoint: {lhs} vs {rhs}"));
            }
        }
        assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
    }

    #[test]
    fn max_pool_floors_and_routes_gradients() {
        let (c, h, w) = (2, 5, 7);
        let x = noise(c * h * w, 9);
        let mut out = vec![0.0; c * 2 * 3];
        let mut arg = Vec::new();
        max_pool(&x, (c, h, w), &mut out, Some(&mut arg));
        for ci in 0..c {
            for y in 0..2 {
                for xx in 0..3 {
                    let p = &x[ci * h * w..];
                    let m = [
                        p[2 * y * w + 2 * xx],
                        p[2 * y * w + 2 * xx + 1],
                        p[(2 * y + 1) * w + 2 * xx],
                        p[(2 * y + 1) * w + 2 * xx + 1],
                    ]
                    .into_iter()
                    .fold(f32::MIN, f32::max);
                    assert_eq!(out[(ci * 2 + y) * 3 + xx], m);
                }
            }
        }
        let v = noise(out.len(), 10);
        let mut v_in = vec![1.0; c * h * w];
        max_pool_backward(&v, &arg, (c, h, w), &mut v_in);
        let total: f32 = v_in.iter().sum();
        assert!((total - v.iter().sum::<f32>()).abs() < 1e-5);
        assert_eq!(v_in[h * w - 1], 0.0, "the dropped last row gets no gradient");
    }
}
