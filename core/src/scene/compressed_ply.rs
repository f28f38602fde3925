//! PlayCanvas's compressed `.ply` (the format SuperSplat writes): Gaussians
//! quantised to 16 bytes each against per-chunk bounds.
//!
//! Layout: a `chunk` element (one per 256 Gaussians) with float bounds
//! `min_/max_{x,y,z}`, `min_/max_scale_{x,y,z}` and optionally
//! `min_/max_{r,g,b}`; a `vertex` element with four `uint` words; optionally an
//! `sh` element of `uchar f_rest_*` (channel-major, as in INRIA files).
//!
//! - `packed_position`, `packed_scale`: 11/10/11 bits (x high), each a unorm
//!   lerped between the chunk's min and max (scales are natural logs).
//! - `packed_rotation`: 2 bits (top) index of the largest component in
//!   (w, x, y, z) order, then three 10-bit unorms `(v − 0.5)·√2` for the others;
//!   the largest is `√(1 − a² − b² − c²)`.
//! - `packed_color`: r, g, b, a bytes (r high). Colours are lerped between the
//!   chunk's colour bounds when present; `f_dc = (colour − 0.5)/SH_C0`;
//!   opacity logit = inverse sigmoid of `a/255`.
//! - `sh` bytes: `0 → −4`, `255 → 4`, else `((v + 0.5)/256 − 0.5)·8`.
//!
//! Quantisation steps per chunk: position `(max−min)/2047` (x, z) and
//! `/1023` (y), log-scale likewise, colour `(max−min)/255`, alpha `1/255`,
//! quaternion components `√2/1023`, SH `8/256`.
//!
//! The writer computes those bounds per chunk (colour bounds included) and
//! rounds to the nearest step, except SH, which takes the bucket holding the
//! value as PlayCanvas's writer does.

use std::path::Path;

use super::ply_header::{Body, Header, Scalar};
use super::{Gaussians, SH_C0, SceneError, alpha_to_logit, sh_coeffs_for_degree, validate};

/// Gaussians per chunk.
pub(crate) const CHUNK_SIZE: usize = 256;

const CHUNK_BOUNDS: [&str; 12] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
];
const CHUNK_COLOUR: [&str; 6] = ["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"];
const PACKED: [&str; 4] = ["packed_position", "packed_rotation", "packed_scale", "packed_color"];

fn unorm(v: u32, bits: u32) -> f32 {
    let max = (1u32 << bits) - 1;
    (v & max) as f32 / max as f32
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// 11/10/11-bit unorm triple, x in the high bits.
fn unpack_111011(v: u32) -> [f32; 3] {
    [unorm(v >> 21, 11), unorm(v >> 11, 10), unorm(v, 11)]
}

/// Smallest-three quaternion, returned as (w, x, y, z).
pub(crate) fn unpack_rotation(v: u32) -> [f32; 4] {
    let norm = std::f32::consts::SQRT_2;
    let a = (unorm(v >> 20, 10) - 0.5) * norm;
    let b = (unorm(v >> 10, 10) - 0.5) * norm;
    let c = (unorm(v, 10) - 0.5) * norm;
    let m = (1.0 - (a * a + b * b + c * c)).max(0.0).sqrt();
    match v >> 30 {
        0 => [m, a, b, c],
        1 => [a, m, b, c],
        2 => [a, b, m, c],
        _ => [a, b, c, m],
    }
}

fn sh_byte(v: u8) -> f32 {
    let n = match v {
        0 => 0.0,
        255 => 1.0,
        v => (v as f32 + 0.5) / 256.0,
    };
    (n - 0.5) * 8.0
}

/// Finds each named property of `el` and checks its type.
fn props(
    path: &Path,
    header: &Header,
    el_name: &str,
    names: &[&str],
    ty: Scalar,
) -> Result<(usize, Vec<usize>), SceneError> {
    let (ei, el) = header.element(el_name).ok_or_else(|| {
        SceneError::format(path, format!("element {el_name}"), format!("a `{el_name}` element"), "none")
    })?;
    let mut out = Vec::with_capacity(names.len());
    for name in names {
        let idx = el.find(name).ok_or_else(|| {
            SceneError::format(
                path,
                format!("{el_name}.{name}"),
                format!("property {} {name}", ty.name()),
                format!("no such property ({el_name} has: {})", el.prop_list()),
            )
        })?;
        let found = el.props[idx].ty;
        if found != ty {
            return Err(SceneError::format(
                path,
                format!("{el_name}.{name}"),
                format!("type {}", ty.name()),
                format!("type {}", found.name()),
            ));
        }
        out.push(idx);
    }
    Ok((ei, out))
}

/// Decodes a compressed PLY whose header has been parsed.
pub(crate) fn read_compressed_ply(path: &Path, bytes: &[u8], header: &Header) -> Result<Gaussians, SceneError> {
    let (ci, bounds) = props(path, header, "chunk", &CHUNK_BOUNDS, Scalar::F32)?;
    let has_colour = header.element("chunk").is_some_and(|(_, c)| c.find("min_r").is_some());
    let colour = if has_colour { props(path, header, "chunk", &CHUNK_COLOUR, Scalar::F32)?.1 } else { Vec::new() };
    let (vi, packed) = props(path, header, "vertex", &PACKED, Scalar::U32)?;
    let n = header.elements[vi].count;
    let chunks = header.elements[ci].count;
    if chunks != n.div_ceil(CHUNK_SIZE) {
        return Err(SceneError::format(
            path,
            "element chunk",
            format!("{} chunks for {n} vertices (one per {CHUNK_SIZE})", n.div_ceil(CHUNK_SIZE)),
            format!("{chunks} chunks"),
        ));
    }
    let sh = match header.element("sh") {
        None => None,
        Some((si, el)) => {
            let count = el.props.len();
            let degree = match count {
                9 => 1,
                24 => 2,
                45 => 3,
                _ => {
                    return Err(SceneError::format(
                        path,
                        "element sh",
                        "9, 24 or 45 f_rest properties",
                        format!("{count} properties"),
                    ));
                }
            };
            if el.count != n {
                return Err(SceneError::format(
                    path,
                    "element sh",
                    format!("{n} rows (one per vertex)"),
                    format!("{} rows", el.count),
                ));
            }
            let names: Vec<String> = (0..count).map(|j| format!("f_rest_{j}")).collect();
            let refs: Vec<&str> = names.iter().map(String::as_str).collect();
            Some((si, degree, props(path, header, "sh", &refs, Scalar::U8)?.1))
        }
    };
    let degree = sh.as_ref().map_or(0, |s| s.1);
    let body = Body::new(path, header, bytes)?;

    // Chunk table, read once: 12 bounds plus 6 colour bounds (or 0..1).
    let mut table: Vec<[f32; 18]> = Vec::with_capacity(chunks);
    let bcols: Vec<_> = bounds.iter().map(|&p| body.column(ci, p)).collect();
    let ccols: Vec<_> = colour.iter().map(|&p| body.column(ci, p)).collect();
    for c in 0..chunks {
        let mut row = [0.0f32; 18];
        for (j, col) in bcols.iter().enumerate() {
            row[j] = col.get(c) as f32;
        }
        for j in 0..3 {
            row[12 + j] = ccols.get(j).map_or(0.0, |col| col.get(c) as f32);
            row[15 + j] = ccols.get(3 + j).map_or(1.0, |col| col.get(c) as f32);
        }
        if let Some(j) = row.iter().position(|v| !v.is_finite()) {
            let name =
                CHUNK_BOUNDS.get(j).or_else(|| j.checked_sub(12).and_then(|c| CHUNK_COLOUR.get(c))).unwrap_or(&"?");
            return Err(SceneError::format(path, format!("chunk {c}: {name}"), "a finite value", row[j].to_string()));
        }
        table.push(row);
    }

    let k = sh_coeffs_for_degree(degree);
    let mut g = Gaussians::with_capacity(n, degree);
    g.sh.resize(n * k * 3, 0.0);
    let pc: Vec<_> = packed.iter().map(|&p| body.column(vi, p)).collect();
    let shc: Vec<_> =
        sh.as_ref().map(|(si, _, cols)| cols.iter().map(|&p| body.column(*si, p)).collect()).unwrap_or_default();
    for i in 0..n {
        let t = &table[i / CHUNK_SIZE];
        let word = |j: usize| pc[j].get(i) as u32;
        let p = unpack_111011(word(0));
        g.means.push([lerp(t[0], t[3], p[0]), lerp(t[1], t[4], p[1]), lerp(t[2], t[5], p[2])]);
        g.quats.push(unpack_rotation(word(1)));
        let s = unpack_111011(word(2));
        g.log_scales.push([lerp(t[6], t[9], s[0]), lerp(t[7], t[10], s[1]), lerp(t[8], t[11], s[2])]);
        let col = word(3);
        let rgba = [unorm(col >> 24, 8), unorm(col >> 16, 8), unorm(col >> 8, 8), unorm(col, 8)];
        let out = &mut g.sh[i * k * 3..(i + 1) * k * 3];
        for ch in 0..3 {
            out[ch] = (lerp(t[12 + ch], t[15 + ch], rgba[ch]) - 0.5) / SH_C0;
        }
        g.opacity_logits.push(alpha_to_logit(rgba[3] as f64));
        for ch in 0..3 {
            for kk in 1..k {
                if let Some(c) = shc.get(ch * (k - 1) + (kk - 1)) {
                    out[kk * 3 + ch] = sh_byte(c.get(i) as u8);
                }
            }
        }
    }
    validate(path, &g)?;
    Ok(g)
}

/// Quantises `v` between `lo` and `hi` to a `bits`-bit unorm (0 when the range is empty).
fn quantise(v: f32, lo: f32, hi: f32, bits: u32) -> u32 {
    let max = ((1u32 << bits) - 1) as f32;
    let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.0 };
    (t.clamp(0.0, 1.0) * max).round() as u32
}

/// Packs three values as 11/10/11 bits (x high) between per-axis bounds.
fn pack_111011(v: [f32; 3], lo: &[f32], hi: &[f32]) -> u32 {
    quantise(v[0], lo[0], hi[0], 11) << 21 | quantise(v[1], lo[1], hi[1], 10) << 11 | quantise(v[2], lo[2], hi[2], 11)
}

/// Smallest-three packing of a (w, x, y, z) quaternion, the inverse of [`unpack_rotation`].
pub(crate) fn pack_rotation(q: [f32; 4]) -> u32 {
    let q = super::normalised_largest_positive(q);
    let largest = super::largest_abs(&q);
    let mut word = largest as u32;
    for (c, v) in q.iter().enumerate() {
        if c != largest {
            let u = ((v / std::f32::consts::SQRT_2 + 0.5) * 1023.0).round().clamp(0.0, 1023.0) as u32;
            word = word << 10 | u;
        }
    }
    word
}

/// The SH byte whose bucket holds `v` (values beyond ±4 clamp), the inverse of [`sh_byte`].
fn to_sh_byte(v: f32) -> u8 {
    ((v / 8.0 + 0.5) * 256.0).floor().clamp(0.0, 255.0) as u8
}

/// The compressed PLY header for `n` Gaussians with `rest` higher SH bytes each.
fn header_text(n: usize, rest: usize) -> String {
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by gast\nelement chunk {}\n",
        n.div_ceil(CHUNK_SIZE)
    );
    for name in CHUNK_BOUNDS.iter().chain(&CHUNK_COLOUR) {
        h += &format!("property float {name}\n");
    }
    h += &format!("element vertex {n}\n");
    for name in PACKED {
        h += &format!("property uint {name}\n");
    }
    if rest > 0 {
        h += &format!("element sh {n}\n");
        for j in 0..rest {
            h += &format!("property uchar f_rest_{j}\n");
        }
    }
    h + "end_header\n"
}

/// Writes `g` as a PlayCanvas compressed PLY: per chunk of 256 the bounds of
/// positions, log-scales and DC colours, then the packed words, then the SH
/// bytes (channel-major, as in INRIA files). Order is kept.
pub(crate) fn write_compressed_ply(out: &mut impl std::io::Write, g: &Gaussians) -> std::io::Result<()> {
    let n = g.len();
    let k = g.sh_coeffs();
    out.write_all(header_text(n, (k - 1) * 3).as_bytes())?;
    let colour = |i: usize| -> [f32; 3] { [0, 1, 2].map(|ch| g.sh_of(i)[ch] * SH_C0 + 0.5) };
    let mut table: Vec<[f32; 18]> = Vec::with_capacity(n.div_ceil(CHUNK_SIZE));
    let mut buf = Vec::with_capacity(n.div_ceil(CHUNK_SIZE) * 72);
    for c in 0..n.div_ceil(CHUNK_SIZE) {
        let mut row =
            [f32::INFINITY, f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY]
                .repeat(3);
        for i in c * CHUNK_SIZE..((c + 1) * CHUNK_SIZE).min(n) {
            for (group, v) in [g.means[i], g.log_scales[i], colour(i)].iter().enumerate() {
                for a in 0..3 {
                    row[group * 6 + a] = row[group * 6 + a].min(v[a]);
                    row[group * 6 + 3 + a] = row[group * 6 + 3 + a].max(v[a]);
                }
            }
        }
        let mut bounds = [0.0f32; 18];
        bounds.copy_from_slice(&row);
        for v in bounds {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        table.push(bounds);
    }
    out.write_all(&buf)?;
    buf.clear();
    for i in 0..n {
        let t = &table[i / CHUNK_SIZE];
        let col = colour(i);
        let alpha = 1.0 / (1.0 + (-g.opacity_logits[i]).exp());
        let rgba = [
            quantise(col[0], t[12], t[15], 8),
            quantise(col[1], t[13], t[16], 8),
            quantise(col[2], t[14], t[17], 8),
            quantise(alpha, 0.0, 1.0, 8),
        ];
        let words = [
            pack_111011(g.means[i], &t[0..3], &t[3..6]),
            pack_rotation(g.quats[i]),
            pack_111011(g.log_scales[i], &t[6..9], &t[9..12]),
            rgba[0] << 24 | rgba[1] << 16 | rgba[2] << 8 | rgba[3],
        ];
        for w in words {
            buf.extend_from_slice(&w.to_le_bytes());
        }
    }
    out.write_all(&buf)?;
    buf.clear();
    for i in 0..n {
        let sh = g.sh_of(i);
        for ch in 0..3 {
            for kk in 1..k {
                buf.push(to_sh_byte(sh[kk * 3 + ch]));
            }
        }
    }
    out.write_all(&buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_unpacks_to_unit_quaternion_with_largest_in_place() {
        // a = b = c = 0.5 unorm → components 0, largest = 1.
        let mid = 511u32; // (511/1023 − 0.5)·√2 ≈ −0.0007
        for which in 0..4u32 {
            let q = unpack_rotation((which << 30) | (mid << 20) | (mid << 10) | mid);
            assert!((q[which as usize] - 1.0).abs() < 1e-5, "{q:?}");
            let n: f32 = q.iter().map(|v| v * v).sum();
            assert!((n - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn rotation_packs_back_to_itself() {
        for q in [[1.0, 0.0, 0.0, 0.0], [0.1, -0.7, 0.2, 0.3], [-0.5, 0.5, -0.5, 0.5], [0.0, 0.0, 0.0, -2.0]] {
            let n = q.iter().map(|v: &f32| v * v).sum::<f32>().sqrt();
            let back = unpack_rotation(pack_rotation(q));
            let dot: f32 = (0..4).map(|c| back[c] * q[c] / n).sum();
            assert!(dot.abs() > 1.0 - 1e-5, "{q:?} came back as {back:?}");
        }
    }

    #[test]
    fn sh_bytes_invert_within_half_a_bucket() {
        for b in 1..=254u8 {
            assert_eq!(to_sh_byte(sh_byte(b)), b);
        }
        assert_eq!(to_sh_byte(-9.0), 0);
        assert_eq!(to_sh_byte(9.0), 255);
    }

    #[test]
    fn sh_bytes_span_minus_four_to_four() {
        assert_eq!(sh_byte(0), -4.0);
        assert_eq!(sh_byte(255), 4.0);
        assert!((sh_byte(128) - (128.5 / 256.0 - 0.5) * 8.0).abs() < 1e-7);
    }
}
