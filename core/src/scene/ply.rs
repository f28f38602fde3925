//! The INRIA 3DGS `.ply` layout: read in any PLY encoding, write exactly as
//! the original trainer does.
//!
//! This is the lossless interchange format every Gaussian-splatting tool
//! reads, so the writer emits the trainer's property names and order
//! (`x y z nx ny nz f_dc_* f_rest_* opacity scale_* rot_*`, all float,
//! binary little-endian) and a write followed by a read is bit-exact. The
//! file stores `f_rest_*` channel-major (`c·(K−1) + (k−1)`); our layout is
//! band-major, so both directions transpose.

use std::io::Write;
use std::path::Path;

use super::ply_header::{Body, Header, Scalar};
use super::{Gaussians, SceneError, sh_coeffs_for_degree, validate};

/// Properties every INRIA file must have, in the groups we read them.
const REQUIRED: [&str; 14] = [
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2",
    "rot_3",
];

/// SH degree for a number of `f_rest_*` properties (0, 9, 24, 45).
fn degree_for_rest(count: usize) -> Option<u32> {
    match count {
        0 => Some(0),
        9 => Some(1),
        24 => Some(2),
        45 => Some(3),
        _ => None,
    }
}

/// Finite stand-in for an opacity logit of +inf: the smallest round value
/// whose sigmoid is exactly 1 in f32 both as `1/(1 + e^−x)` (needs
/// `e^−x ≤ 2^−24`, x ≥ 16.7) and as `e^x/(1 + e^x)` (needs `e^x ≥ 2^25`,
/// x ≥ 17.4), while `e^x` stays far from overflow.
pub const OPACITY_LOGIT_INF: f32 = 20.0;
/// Finite stand-in for an opacity logit of −inf: `1/(1 + e^110)` is 0 in f32
/// because `e^110` overflows to inf, and `e^−110` underflows to 0, so the
/// sigmoid is exactly 0 whichever way it is computed.
pub const OPACITY_LOGIT_NEG_INF: f32 = -110.0;
/// Finite stand-in for a log-scale of +inf: a standard deviation of e^10 ≈
/// 22,000 units, far beyond any captured scene, so the Gaussian covers the
/// whole view at near-constant alpha as an infinite one would, while its
/// projected 2D covariance and that covariance's determinant stay finite in
/// f32 (about f²·e^20/z² ≤ 10^17 px² for f = 2000 px and depth 0.1).
pub const LOG_SCALE_INF: f32 = 10.0;
/// Finite stand-in for a log-scale of −inf: a standard deviation of e^−30
/// (variance ~10^−26), whose projected footprint is some 10^−20 px², far under
/// the 0.3 px² screen-space dilation, so it renders as a zero-size Gaussian.
pub const LOG_SCALE_NEG_INF: f32 = -30.0;

/// Replaces infinite opacity logits and log-scales (which some tools write,
/// e.g. splat-transform for an opacity of exactly 1) by the finite values
/// above; returns how many of each were replaced. NaN is left for
/// [`validate`] to refuse.
fn clamp_infinities(g: &mut Gaussians) -> (usize, usize) {
    let fix = |v: &mut f32, hi: f32, lo: f32| {
        if v.is_infinite() {
            *v = if *v > 0.0 { hi } else { lo };
            1
        } else {
            0
        }
    };
    let opacity = g.opacity_logits.iter_mut().map(|o| fix(o, OPACITY_LOGIT_INF, OPACITY_LOGIT_NEG_INF)).sum();
    let scales = g.log_scales.iter_mut().flatten().map(|s| fix(s, LOG_SCALE_INF, LOG_SCALE_NEG_INF)).sum();
    (opacity, scales)
}

/// Reads an INRIA `.ply` held in `bytes` (already known to start with `ply`).
/// Infinite opacity logits and log-scales are clamped (see [`OPACITY_LOGIT_INF`]
/// and the others) and counted in one message pushed to `warnings`.
pub(crate) fn read_ply_bytes(
    path: &Path,
    bytes: &[u8],
    header: &Header,
    warnings: &mut Vec<String>,
) -> Result<Gaussians, SceneError> {
    let (vi, vertex) = header.element("vertex").ok_or_else(|| {
        let names: Vec<&str> = header.elements.iter().map(|e| e.name.as_str()).collect();
        SceneError::format(path, "element vertex", "a `vertex` element", format!("elements [{}]", names.join(", ")))
    })?;
    let mut cols = Vec::with_capacity(REQUIRED.len());
    for name in REQUIRED {
        let idx = vertex.find(name).ok_or_else(|| {
            SceneError::format(
                path,
                format!("vertex.{name}"),
                format!("property {name}"),
                format!("no such property (vertex has: {})", vertex.prop_list()),
            )
        })?;
        check_float(path, name, vertex.props[idx].ty)?;
        cols.push(idx);
    }
    let rest_count = vertex.props.iter().filter(|p| p.name.starts_with("f_rest_")).count();
    let degree = degree_for_rest(rest_count).ok_or_else(|| {
        SceneError::format(
            path,
            "vertex.f_rest_*",
            "0, 9, 24 or 45 f_rest properties (SH degree 0 to 3)",
            format!("{rest_count} f_rest properties"),
        )
    })?;
    let mut rest = Vec::with_capacity(rest_count);
    for j in 0..rest_count {
        let name = format!("f_rest_{j}");
        let idx = vertex.find(&name).ok_or_else(|| {
            SceneError::format(
                path,
                format!("vertex.{name}"),
                format!("f_rest_0 … f_rest_{}", rest_count - 1),
                format!("no {name} (vertex has: {})", vertex.prop_list()),
            )
        })?;
        check_float(path, &name, vertex.props[idx].ty)?;
        rest.push(idx);
    }

    let body = Body::new(path, header, bytes)?;
    let n = vertex.count;
    let k = sh_coeffs_for_degree(degree);
    let mut g = Gaussians::with_capacity(n, degree);
    let c: Vec<_> = cols.iter().map(|&p| body.column(vi, p)).collect();
    let r: Vec<_> = rest.iter().map(|&p| body.column(vi, p)).collect();
    let f = |col: &super::ply_header::Column<'_>, i: usize| col.get(i) as f32;
    g.sh.resize(n * k * 3, 0.0);
    for i in 0..n {
        g.means.push([f(&c[0], i), f(&c[1], i), f(&c[2], i)]);
        g.opacity_logits.push(f(&c[6], i));
        g.log_scales.push([f(&c[7], i), f(&c[8], i), f(&c[9], i)]);
        g.quats.push([f(&c[10], i), f(&c[11], i), f(&c[12], i), f(&c[13], i)]);
        let sh = &mut g.sh[i * k * 3..(i + 1) * k * 3];
        sh[..3].copy_from_slice(&[f(&c[3], i), f(&c[4], i), f(&c[5], i)]);
        for ch in 0..3 {
            for kk in 1..k {
                sh[kk * 3 + ch] = f(&r[ch * (k - 1) + (kk - 1)], i);
            }
        }
    }
    let (opacity, scales) = clamp_infinities(&mut g);
    if opacity + scales > 0 {
        warnings.push(format!(
            "{}: {opacity} infinite opacity logits replaced by {OPACITY_LOGIT_INF} or {OPACITY_LOGIT_NEG_INF} \
             (sigmoid exactly 1 or 0, as infinity gives) and {scales} infinite log-scales by {LOG_SCALE_INF} \
             or {LOG_SCALE_NEG_INF}, among {n} Gaussians",
            path.display()
        ));
    }
    validate(path, &g)?;
    Ok(g)
}

/// INRIA fields are logits, logs and fractional coefficients: only float and
/// double make sense; integers mean the file is something else.
fn check_float(path: &Path, name: &str, ty: Scalar) -> Result<(), SceneError> {
    match ty {
        Scalar::F32 | Scalar::F64 => Ok(()),
        other => Err(SceneError::format(
            path,
            format!("vertex.{name}"),
            "type float or double",
            format!("type {}", other.name()),
        )),
    }
}

/// The INRIA header for `n` Gaussians of SH degree `degree`.
fn header_text(n: usize, degree: u32) -> String {
    let rest = (sh_coeffs_for_degree(degree) - 1) * 3;
    let mut h = format!("ply\nformat binary_little_endian 1.0\nelement vertex {n}\n");
    let mut names: Vec<String> =
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"].iter().map(|s| s.to_string()).collect();
    names.extend((0..rest).map(|j| format!("f_rest_{j}")));
    names.extend(
        ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"].iter().map(|s| s.to_string()),
    );
    for name in names {
        h.push_str("property float ");
        h.push_str(&name);
        h.push('\n');
    }
    h.push_str("end_header\n");
    h
}

/// Writes `g` as an INRIA binary little-endian `.ply` to `out`.
pub(crate) fn write_ply_to(out: &mut impl Write, g: &Gaussians) -> std::io::Result<()> {
    g.check_consistent().map_err(std::io::Error::other)?;
    let n = g.len();
    let k = g.sh_coeffs();
    out.write_all(header_text(n, g.sh_degree).as_bytes())?;
    let floats_per_row = 3 + 3 + 3 * k + 1 + 3 + 4;
    let mut row: Vec<f32> = Vec::with_capacity(floats_per_row);
    let mut buf: Vec<u8> = Vec::with_capacity(floats_per_row * 4 * 1024);
    for i in 0..n {
        row.clear();
        row.extend_from_slice(&g.means[i]);
        row.extend_from_slice(&[0.0, 0.0, 0.0]);
        let sh = g.sh_of(i);
        row.extend_from_slice(&sh[..3]);
        for ch in 0..3 {
            for kk in 1..k {
                row.push(sh[kk * 3 + ch]);
            }
        }
        row.push(g.opacity_logits[i]);
        row.extend_from_slice(&g.log_scales[i]);
        row.extend_from_slice(&g.quats[i]);
        for v in &row {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        if buf.len() >= floats_per_row * 4 * 1023 {
            out.write_all(&buf)?;
            buf.clear();
        }
    }
    out.write_all(&buf)?;
    Ok(())
}

/// Writes `g` to `path` as an INRIA `.ply`, atomically (temporary file in the
/// same directory, then rename).
pub(crate) fn save_ply(path: &Path, g: &Gaussians) -> Result<(), SceneError> {
    validate(path, g)?;
    super::atomic_write(path, |w| write_ply_to(w, g))
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{sample, scratch};
    use super::super::{load, save_ply};
    use super::*;

    #[test]
    fn write_then_read_is_bit_exact_for_every_degree() {
        let dir = scratch("ply_roundtrip");
        for degree in 0..=3 {
            let g = sample(37, degree);
            let p = dir.join(format!("deg{degree}.ply"));
            save_ply(&p, &g).expect("save");
            let back = load(&p).expect("load");
            assert_eq!(back.sh_degree, degree);
            assert_eq!(back.len(), g.len());
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&back.sh), bits(&g.sh), "degree {degree} sh");
            assert_eq!(bits(&back.opacity_logits), bits(&g.opacity_logits));
            assert_eq!(back.means, g.means);
            assert_eq!(back.log_scales, g.log_scales);
            assert_eq!(back.quats, g.quats);
        }
    }

    #[test]
    fn header_has_the_trainer_property_order() {
        let h = header_text(1, 1);
        let props: Vec<&str> = h.lines().filter_map(|l| l.strip_prefix("property float ")).collect();
        assert_eq!(&props[..9], &["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]);
        assert_eq!(props[9], "f_rest_0");
        assert_eq!(props[17], "f_rest_8");
        assert_eq!(&props[18..], &["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]);
    }

    /// f_rest is channel-major in the file: f_rest_(c·(K−1)+k−1) holds
    /// coefficient k of channel c.
    #[test]
    fn f_rest_is_transposed() {
        let dir = scratch("ply_transpose");
        let mut g = sample(1, 1);
        for (j, v) in g.sh.iter_mut().enumerate() {
            *v = j as f32; // sh[k*3+c] = 3k+c
        }
        let p = dir.join("t.ply");
        save_ply(&p, &g).expect("save");
        let bytes = std::fs::read(&p).expect("read");
        let h = crate::scene::ply_header::parse_header(&p, &bytes).expect("header");
        let body = Body::new(&p, &h, &bytes).expect("body");
        let (_, v) = h.element("vertex").expect("vertex");
        for c in 0..3 {
            for k in 1..4 {
                let idx = v.find(&format!("f_rest_{}", c * 3 + (k - 1))).expect("prop");
                assert_eq!(body.get(0, 0, idx), (3 * k + c) as f64);
            }
        }
    }
}
