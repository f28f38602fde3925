//! Total-variation smoothness of the rendered image.
//!
//! `L = (mean((Δ_h I)²) + mean((Δ_v I)²)) / 2`, with `Δ_h` the difference to the
//! right neighbour and `Δ_v` to the lower one, means over all differences and
//! channels. ALGORITHM.md writes `mean(Δ_h I)²`; the golden `tv_loss` settles it
//! as the mean of squares (the reference code's `mean(pow(.., 2))`). Unlike the
//! reference, which slices a `(1, 3, H, W)` tensor so that its "horizontal"
//! term differences colour channels, both terms here are spatial (the paper's
//! formula, which the golden values also use).

/// TV loss of an HWC image and its gradient.
pub fn tv_loss(img: &[f32], h: usize, w: usize, c: usize) -> (f32, Vec<f32>) {
    tv_loss_masked(img, h, w, c, None)
}

/// [`tv_loss`] over the differences whose two pixels are both in `mask`
/// (`h × w`; all of them without a mask): the means are over those
/// differences, and pixels outside the mask get no gradient.
pub fn tv_loss_masked(img: &[f32], h: usize, w: usize, c: usize, mask: Option<&[bool]>) -> (f32, Vec<f32>) {
    assert_eq!(img.len(), h * w * c, "tv_loss: image size mismatch");
    let inside = |p: usize| mask.is_none_or(|m| m[p]);
    let mut grad = vec![0f32; img.len()];
    let (mut count_h, mut count_v) = (0usize, 0usize);
    for i in 0..h {
        for j in 0..w {
            let p = i * w + j;
            count_h += usize::from(j + 1 < w && inside(p) && inside(p + 1));
            count_v += usize::from(i + 1 < h && inside(p) && inside(p + w));
        }
    }
    let nh = (count_h * c) as f64;
    let nv = (count_v * c) as f64;
    let (mut sh, mut sv) = (0f64, 0f64);
    // d/dx of mean(d²)/2 = d/n per difference, with sign ±.
    let kh = if nh > 0.0 { (1.0 / nh) as f32 } else { 0.0 };
    let kv = if nv > 0.0 { (1.0 / nv) as f32 } else { 0.0 };
    for i in 0..h {
        for j in 0..w {
            for k in 0..c {
                let p = (i * w + j) * c + k;
                let here = inside(i * w + j);
                if j + 1 < w && here && inside(i * w + j + 1) {
                    let q = p + c;
                    let d = img[q] - img[p];
                    sh += f64::from(d) * f64::from(d);
                    grad[q] += kh * d;
                    grad[p] -= kh * d;
                }
                if i + 1 < h && here && inside((i + 1) * w + j) {
                    let q = p + w * c;
                    let d = img[q] - img[p];
                    sv += f64::from(d) * f64::from(d);
                    grad[q] += kv * d;
                    grad[p] -= kv * d;
                }
            }
        }
    }
    let mh = if nh > 0.0 { sh / nh } else { 0.0 };
    let mv = if nv > 0.0 { sv / nv } else { 0.0 };
    (((mh + mv) / 2.0) as f32, grad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finite_difference() {
        let (h, w, c) = (4, 5, 3);
        let img: Vec<f32> = (0..h * w * c).map(|i| ((i * 29) % 31) as f32 / 31.0).collect();
        let (_, g) = tv_loss(&img, h, w, c);
        let mut bad = Vec::new();
        for i in 0..img.len() {
            let mut p = img.clone();
            p[i] += 1e-2;
            let mut m = img.clone();
            m[i] -= 1e-2;
            let fd = (tv_loss(&p, h, w, c).0 - tv_loss(&m, h, w, c).0) / 2e-2;
            if (fd - g[i]).abs() > 1e-4 + 1e-3 * fd.abs() {
                bad.push(format!("{i}: fd {fd} analytic {}", g[i]));
            }
        }
        assert!(bad.is_empty(), "{}", bad.join("\n"));
    }

    #[test]
    fn constant_image_has_zero_tv() {
        let (l, g) = tv_loss(&[0.3; 2 * 3 * 3], 2, 3, 3);
        assert_eq!(l, 0.0);
        assert!(g.iter().all(|&v| v == 0.0));
    }
}
