//! Stage 0: linear colour transfer (as in ARF), applied exactly to SH colours.
//!
//! The reference recolours the training photos and fine-tunes the scene for a
//! thousand steps to follow them. Rendered colour is affine in the SH
//! coefficients (`0.5 + Σ_l Y_l(d)·c_l`), so the affine map `x ↦ A x + b` can be
//! pushed into the coefficients instead: `c_l ← A c_l` for every band and an
//! extra constant on the DC term. That is instant and exact up to the `[0, 1]`
//! clamp of the renderer.

use crate::scene::{Gaussians, SH_C0};
use crate::vision::resize::Unit;

/// The affine colour map `x ↦ A x + b` (RGB, values in [0, 1]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColorTransfer {
    /// Linear part, row-major: `y[i] = Σ_j a[i][j]·x[j] + b[i]`.
    pub a: [[f32; 3]; 3],
    /// Offset.
    pub b: [f32; 3],
}

/// Eigenvalues are clamped to this range before square roots and inverses.
const EIG_MIN: f64 = 1e-8;
const EIG_MAX: f64 = 1e8;

impl ColorTransfer {
    /// The identity map.
    pub fn identity() -> Self {
        Self { a: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], b: [0.0; 3] }
    }

    /// Fits the transfer from content pixels to style pixels (flat RGB triples):
    /// `A = C_s^{1/2} C_c^{-1/2}` from population covariances (symmetric square
    /// roots by eigen-decomposition, eigenvalues clamped to [1e-8, 1e8]),
    /// `b = μ_s − A μ_c`. Returns the identity when either set is empty. The
    /// style may be the 8-bit image itself ([`Unit`]), read in place.
    pub fn fit<S: Unit>(content: &[f32], style: &[S]) -> Self {
        if content.len() < 3 || style.len() < 3 {
            return Self::identity();
        }
        let (mu_c, cov_c) = mean_cov(content);
        let (mu_s, cov_s) = mean_cov(style);
        let root_s = sym_fn(&cov_s, |s| s.clamp(EIG_MIN, EIG_MAX).sqrt());
        let inv_root_c = sym_fn(&cov_c, |s| 1.0 / s.clamp(EIG_MIN, EIG_MAX).sqrt());
        let a = matmul3(&root_s, &inv_root_c);
        let mut out = Self::identity();
        for i in 0..3 {
            let mut bi = mu_s[i];
            for j in 0..3 {
                out.a[i][j] = a[i][j] as f32;
                bi -= a[i][j] * mu_c[j];
            }
            out.b[i] = bi as f32;
        }
        out
    }

    /// Applies the map to one colour.
    pub fn apply(&self, x: [f32; 3]) -> [f32; 3] {
        let mut y = self.b;
        for (i, yi) in y.iter_mut().enumerate() {
            for (j, xj) in x.iter().enumerate() {
                *yi += self.a[i][j] * xj;
            }
        }
        y
    }

    /// Pushes the map into the SH coefficients of every Gaussian: `c_l ← A c_l`
    /// for every band `l`, and `c_0 += (A·0.5 + b − 0.5)/C0`, so that the
    /// rendered colour `0.5 + Σ_l Y_l c_l` becomes `A·colour + b` (before the
    /// renderer's clamp).
    pub fn apply_to_gaussians(&self, g: &mut Gaussians) {
        self.apply_to_gaussians_except(g, &[]);
    }

    /// As [`Self::apply_to_gaussians`], leaving out the Gaussians at `skip`
    /// (ascending indices): those a caller overwrites next.
    pub fn apply_to_gaussians_except(&self, g: &mut Gaussians, skip: &[u32]) {
        let k = g.sh_coeffs();
        let half = self.apply([0.5; 3]);
        let dc_shift: [f32; 3] = std::array::from_fn(|i| (half[i] - 0.5) / SH_C0);
        let mut skip = skip.iter().peekable();
        for (n, coeffs) in g.sh.chunks_exact_mut(k * 3).enumerate() {
            if skip.next_if(|&&s| s as usize == n).is_some() {
                continue;
            }
            for (band, c) in coeffs.chunks_exact_mut(3).enumerate() {
                let mut y = [0.0f32; 3];
                for (i, yi) in y.iter_mut().enumerate() {
                    *yi = self.a[i][0] * c[0] + self.a[i][1] * c[1] + self.a[i][2] * c[2];
                }
                if band == 0 {
                    for i in 0..3 {
                        y[i] += dc_shift[i];
                    }
                }
                c.copy_from_slice(&y);
            }
        }
    }
}

/// Mean and population covariance of RGB triples, in f64.
fn mean_cov<T: Unit>(px: &[T]) -> ([f64; 3], [[f64; 3]; 3]) {
    let n = (px.len() / 3) as f64;
    let mut mu = [0f64; 3];
    for p in px.chunks_exact(3) {
        for i in 0..3 {
            mu[i] += f64::from(p[i].unit());
        }
    }
    mu.iter_mut().for_each(|m| *m /= n);
    let mut cov = [[0f64; 3]; 3];
    for p in px.chunks_exact(3) {
        let d: [f64; 3] = std::array::from_fn(|i| f64::from(p[i].unit()) - mu[i]);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j];
            }
        }
    }
    cov.iter_mut().flatten().for_each(|c| *c /= n);
    (mu, cov)
}

fn matmul3(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// `U diag(f(s)) Uᵀ` for a symmetric matrix `m = U diag(s) Uᵀ`.
fn sym_fn(m: &[[f64; 3]; 3], f: impl Fn(f64) -> f64) -> [[f64; 3]; 3] {
    let (s, u) = jacobi_eigen(m);
    let fs = s.map(f);
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| u[i][k] * fs[k] * u[j][k]).sum()))
}

/// Cyclic Jacobi eigen-decomposition of a symmetric 3×3 matrix: eigenvalues and
/// the eigenvectors as the columns of `U`.
pub(crate) fn jacobi_eigen(m: &[[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = *m;
    let mut u = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..64 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-300 || off <= 1e-17 * scale {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J with the rotation J in the (p, q) plane.
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * rp[k] - s * rq[k];
                a[q][k] = s * rp[k] + c * rq[k];
            }
            for row in u.iter_mut() {
                let (ukp, ukq) = (row[p], row[q]);
                row[p] = c * ukp - s * ukq;
                row[q] = s * ukp + c * ukq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], u)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_reconstructs() {
        let m = [[2.0, 0.3, -0.1], [0.3, 1.0, 0.25], [-0.1, 0.25, 0.5]];
        let (s, u) = jacobi_eigen(&m);
        for i in 0..3 {
            for j in 0..3 {
                let r: f64 = (0..3).map(|k| u[i][k] * s[k] * u[j][k]).sum();
                assert!((r - m[i][j]).abs() < 1e-12);
            }
        }
    }

    fn pixels(n: usize, seed: u32, f: impl Fn([f32; 3]) -> [f32; 3]) -> Vec<f32> {
        let mut x = seed;
        let mut next = || {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (x >> 8) as f32 / (1u32 << 24) as f32
        };
        (0..n).flat_map(|_| f([next(), next(), next()])).collect()
    }

    #[test]
    fn fit_maps_statistics() {
        let content = pixels(4000, 1, |p| [p[0], 0.5 * p[1] + 0.2 * p[0], 0.3 * p[2]]);
        let style: Vec<f32> = content
            .chunks_exact(3)
            .flat_map(|p| [0.8 * p[0] + 0.1, 0.2 * p[1] + 0.5 * p[2] + 0.3, 0.9 * p[2]])
            .collect();
        let t = ColorTransfer::fit(&content, &style);
        let mapped: Vec<f32> = content.chunks_exact(3).flat_map(|p| t.apply([p[0], p[1], p[2]])).collect();
        let (mu_m, cov_m) = mean_cov(&mapped);
        let (mu_s, cov_s) = mean_cov(&style);
        for i in 0..3 {
            assert!((mu_m[i] - mu_s[i]).abs() < 1e-5);
            for j in 0..3 {
                assert!((cov_m[i][j] - cov_s[i][j]).abs() < 1e-5, "{i}{j}");
            }
        }
    }

    #[test]
    fn an_8bit_style_fits_as_its_f32_copy_does() {
        let content = pixels(500, 3, |p| p);
        let style: Vec<u8> = (0..900).map(|i| (i * 37 % 256) as u8).collect();
        let copy: Vec<f32> = style.iter().map(|&v| f32::from(v) / 255.0).collect();
        assert_eq!(ColorTransfer::fit(&content, &style), ColorTransfer::fit(&content, &copy));
    }

    #[test]
    fn sh_application_matches_colour_map() {
        let t = ColorTransfer { a: [[0.9, 0.1, -0.2], [0.05, 1.1, 0.0], [0.3, -0.1, 0.7]], b: [0.05, -0.1, 0.2] };
        let mut g = Gaussians::with_capacity(2, 0);
        for i in 0..2 {
            g.means.push([0.0; 3]);
            g.log_scales.push([0.0; 3]);
            g.quats.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity_logits.push(0.0);
            g.sh.extend_from_slice(&[0.3 * i as f32 - 0.2, 0.1, 0.4]);
        }
        let before = g.clone();
        t.apply_to_gaussians(&mut g);
        for i in 0..2 {
            let c0 = before.sh_of(i);
            let col: [f32; 3] = std::array::from_fn(|k| 0.5 + SH_C0 * c0[k]);
            let want = t.apply(col);
            let c1 = g.sh_of(i);
            for k in 0..3 {
                let got = 0.5 + SH_C0 * c1[k];
                assert!((got - want[k]).abs() < 1e-6, "{got} vs {}", want[k]);
            }
        }
    }

    #[test]
    fn higher_bands_are_multiplied_by_a() {
        let t = ColorTransfer { a: [[2.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.5]], b: [0.1, 0.0, 0.0] };
        let mut g = Gaussians::with_capacity(1, 1);
        g.means.push([0.0; 3]);
        g.log_scales.push([0.0; 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(0.0);
        g.sh.extend_from_slice(&[0.0; 3]);
        g.sh.extend_from_slice(&[1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        t.apply_to_gaussians(&mut g);
        assert_eq!(&g.sh[3..6], &[2.0, 5.0, 1.5]);
    }

    #[test]
    fn the_gaussians_left_out_keep_their_coefficients_and_the_rest_are_mapped_alike() {
        let t = ColorTransfer { a: [[0.9, 0.1, -0.2], [0.05, 1.1, 0.0], [0.3, -0.1, 0.7]], b: [0.05, -0.1, 0.2] };
        let g = crate::scene::test_util::sample(6, 1);
        let (mut all, mut some) = (g.clone(), g.clone());
        t.apply_to_gaussians(&mut all);
        t.apply_to_gaussians_except(&mut some, &[0, 2, 3]);
        for i in 0..6 {
            let want = if [0, 2, 3].contains(&i) { g.sh_of(i) } else { all.sh_of(i) };
            assert_eq!(some.sh_of(i), want, "Gaussian {i}");
        }
        assert_ne!(all.sh, g.sh);
    }
}
