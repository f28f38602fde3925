//! Niantic's `.spz`: fixed-point, byte-quantised Gaussians, compressed.
//!
//! Two containers share one payload:
//! - v2/v3 (legacy): the whole file is one gzip stream holding a 16-byte
//!   header (`NGSP`, version, count, SH degree, fractional bits, flags,
//!   reserved) followed by the attribute arrays;
//! - v4 (current, what the shared `biker.spz` is): a plain 32-byte header
//!   (… flags, stream count, TOC offset, 12 reserved bytes), a table of
//!   `(compressed, uncompressed)` u64 sizes, then one zstd frame per attribute.
//!
//! Attributes, in order, for N Gaussians: positions (N×3 signed 24-bit fixed
//! point, `fractional_bits` fraction bits), alphas (N bytes, `sigmoid·255`),
//! colours (N×3 bytes, `f_dc·0.15·255 + 127.5`), scales (N×3 bytes,
//! `(log_scale + 10)·16`), rotations (v3+: 4 bytes smallest-three, 2-bit
//! largest index over (x, y, z, w) and 3×(sign + 9-bit magnitude/√½); v2: 3
//! bytes x, y, z as `(q + 1)·127.5`, w ≥ 0), SH (N×dim×3 bytes, channel
//! innermost, `(v − 128)/128`). The quantisation steps are therefore: position
//! 2^−fractional_bits, log-scale 1/16, alpha 1/255, f_dc 1/(0.15·255) ≈ 0.026,
//! quaternion components √½/511, SH 1/128.
//!
//! SPZ stores coordinates in a right-up-back (OpenGL) frame, while INRIA PLY
//! files, and so our layout, use the trainer's right-down-forward (COLMAP)
//! frame; Niantic's converter flips y and z when it writes. The reader
//! converts back: y and z of positions negated, the quaternion's y and z
//! negated (`S R S` with `S = diag(1, −1, −1)`), and each SH coefficient whose
//! basis function is odd under (y, z) → (−y, −z) negated. The shared
//! `biker.spz` then matches `biker.compressed.ply` Gaussian for Gaussian.
//! The writer applies the same flip and rounds every field to its nearest step.

use std::io::Read;
use std::path::Path;

use super::{Gaussians, SceneError, alpha_to_logit, sh_coeffs_for_degree, validate};

const MAGIC: &[u8; 4] = b"NGSP";
/// Largest decompressed/compressed ratio accepted (the reference library's bound).
const MAX_RATIO: usize = 1024;
/// DC colour scale of the format.
const COLOR_SCALE: f32 = 0.15;

struct Layout {
    version: u32,
    n: usize,
    degree: u32,
    fractional_bits: u8,
    /// Byte sizes of positions, alphas, colours, scales, rotations, SH.
    sizes: [usize; 6],
}

fn fmt(path: &Path, what: &str, expected: impl Into<String>, found: impl Into<String>) -> SceneError {
    SceneError::format(path, what, expected, found)
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut a = [0u8; 4];
    if let Some(s) = b.get(at..at + 4) {
        a.copy_from_slice(s);
    }
    u32::from_le_bytes(a)
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    if let Some(s) = b.get(at..at + 8) {
        a.copy_from_slice(s);
    }
    u64::from_le_bytes(a)
}

/// Validates the fields shared by every version and works out the sizes.
fn layout(path: &Path, head: &[u8], compressed_len: usize) -> Result<Layout, SceneError> {
    if head.get(..4) != Some(MAGIC.as_slice()) {
        let shown: Vec<String> = head.iter().take(4).map(|b| format!("{b:02x}")).collect();
        return Err(fmt(path, "header.magic", "NGSP", format!("[{}]", shown.join(" "))));
    }
    let version = u32_at(head, 4);
    let n = u32_at(head, 8) as usize;
    let degree = head.get(12).copied().unwrap_or(0) as u32;
    let fractional_bits = head.get(13).copied().unwrap_or(0);
    if !(2..=4).contains(&version) {
        return Err(fmt(path, "header.version", "2, 3 or 4", version.to_string()));
    }
    if degree > 3 {
        return Err(fmt(path, "header.sh_degree", "0 to 3", degree.to_string()));
    }
    if fractional_bits > 23 {
        return Err(fmt(path, "header.fractional_bits", "0 to 23", fractional_bits.to_string()));
    }
    let dim = sh_coeffs_for_degree(degree) - 1;
    let rot = if version == 2 { 3 } else { 4 };
    let sizes = [9, 1, 3, 3, rot, dim * 3].map(|b| n.saturating_mul(b));
    let total: usize = sizes.iter().fold(0usize, |a, &b| a.saturating_add(b));
    if total > compressed_len.saturating_mul(MAX_RATIO) {
        return Err(fmt(
            path,
            "header.num_points",
            format!("a count whose {total} bytes of data fit {compressed_len} compressed bytes (ratio ≤ {MAX_RATIO})"),
            format!("{n} points"),
        ));
    }
    Ok(Layout { version, n, degree, fractional_bits, sizes })
}

/// Reads exactly `want` bytes from `r` without trusting `want` for allocation.
fn read_exact_grow(path: &Path, what: &str, r: impl Read, want: usize) -> Result<Vec<u8>, SceneError> {
    let mut out = Vec::new();
    r.take(want as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| fmt(path, what, "a valid compressed stream", format!("a decoding error: {e}")))?;
    if out.len() != want {
        return Err(fmt(
            path,
            what,
            format!("{want} decompressed bytes"),
            if out.len() > want { "more (trailing data)".to_string() } else { format!("{} (truncated)", out.len()) },
        ));
    }
    Ok(out)
}

/// Reads a `.spz` held in `bytes` (gzip v2/v3 or zstd v4).
pub(crate) fn read_spz_bytes(path: &Path, bytes: &[u8]) -> Result<Gaussians, SceneError> {
    if bytes.starts_with(MAGIC) {
        return read_v4(path, bytes);
    }
    let mut gz = flate2::read::GzDecoder::new(bytes);
    let mut head = [0u8; 16];
    gz.read_exact(&mut head)
        .map_err(|e| fmt(path, "gzip stream", "a gzip stream holding a 16-byte SPZ header", format!("{e}")))?;
    let lay = layout(path, &head, bytes.len())?;
    if lay.version == 4 {
        return Err(fmt(path, "header.version", "2 or 3 inside gzip", "4"));
    }
    let total: usize = lay.sizes.iter().sum();
    // Anything after the arrays (v3 extensions) is ignored: read exactly `total`.
    let mut data = Vec::new();
    (&mut gz)
        .take(total as u64)
        .read_to_end(&mut data)
        .map_err(|e| fmt(path, "gzip payload", "a valid gzip stream", format!("a decoding error: {e}")))?;
    if data.len() != total {
        return Err(fmt(
            path,
            "gzip payload",
            format!("{total} bytes of attributes for {} points", lay.n),
            format!("{} bytes (truncated)", data.len()),
        ));
    }
    let mut parts = Vec::with_capacity(6);
    let mut at = 0;
    for s in lay.sizes {
        parts.push(data.get(at..at + s).unwrap_or(&[]).to_vec());
        at += s;
    }
    decode(path, &lay, &parts)
}

fn read_v4(path: &Path, bytes: &[u8]) -> Result<Gaussians, SceneError> {
    if bytes.len() < 32 {
        return Err(fmt(path, "header", "a 32-byte v4 header", format!("{} bytes (truncated)", bytes.len())));
    }
    let lay = layout(path, bytes, bytes.len())?;
    if lay.version != 4 {
        return Err(fmt(path, "header.version", "4 for an uncompressed NGSP header", lay.version.to_string()));
    }
    let num_streams = bytes[15] as usize;
    let toc = u32_at(bytes, 16) as usize;
    let want_streams = if lay.sizes[5] == 0 { 5 } else { 6 };
    if num_streams != want_streams {
        return Err(fmt(
            path,
            "header.num_streams",
            format!(
                "{want_streams} (positions, alphas, colours, scales, rotations{})",
                if want_streams == 6 { ", SH" } else { "" }
            ),
            num_streams.to_string(),
        ));
    }
    let toc_end = toc.checked_add(16 * num_streams).filter(|&e| toc >= 32 && e <= bytes.len()).ok_or_else(|| {
        fmt(path, "header.toc_offset", format!("a table inside the {}-byte file", bytes.len()), toc.to_string())
    })?;
    let names = ["positions", "alphas", "colours", "scales", "rotations", "sh"];
    let mut at = toc_end;
    let mut parts = vec![Vec::new(); 6];
    for s in 0..num_streams {
        let compressed = u64_at(bytes, toc + 16 * s);
        let uncompressed = u64_at(bytes, toc + 16 * s + 8);
        let what = format!("stream {s} ({})", names[s]);
        if uncompressed != lay.sizes[s] as u64 {
            return Err(fmt(path, &what, format!("{} uncompressed bytes", lay.sizes[s]), uncompressed.to_string()));
        }
        let end = usize::try_from(compressed).ok().and_then(|c| at.checked_add(c)).filter(|&e| e <= bytes.len());
        let Some(end) = end else {
            return Err(fmt(
                path,
                &what,
                format!("at most {} compressed bytes left in the file", bytes.len() - at),
                format!("{compressed} (truncated)"),
            ));
        };
        let src = &bytes[at..end];
        let dec = ruzstd::decoding::StreamingDecoder::new(src)
            .map_err(|e| fmt(path, &what, "a zstd frame", format!("a bad frame header: {e}")))?;
        parts[s] = read_exact_grow(path, &what, dec, lay.sizes[s])?;
        at = end;
    }
    decode(path, &lay, &parts)
}

/// Smallest-three quaternion (v3+), returned as (w, x, y, z).
fn unpack_rotation_v3(b: &[u8]) -> [f32; 4] {
    let mut comp = u32_at(b, 0);
    let mask = (1u32 << 9) - 1;
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4]; // x, y, z, w
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i != largest {
            let mag = comp & mask;
            let neg = (comp >> 9) & 1 == 1;
            comp >>= 10;
            let v = std::f32::consts::FRAC_1_SQRT_2 * mag as f32 / mask as f32;
            q[i] = if neg { -v } else { v };
            sum += q[i] * q[i];
        }
    }
    q[largest] = (1.0f32 - sum).max(0.0).sqrt();
    [q[3], q[0], q[1], q[2]]
}

/// Sign of each SH coefficient (band-major, bands 1 to 3, coefficient 1
/// first) under the RUB → RDF flip (y, z) → (−y, −z).
const SH_FLIP: [f32; 15] = [
    -1.0, -1.0, 1.0, // y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // xy, yz, 3z²−1, xz, x²−y²
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0,
    1.0, // y(3x²−y²), xyz, y(5z²−1), z(5z²−3), x(5z²−1), z(x²−y²), x(x²−3y²)
];

fn decode(path: &Path, lay: &Layout, parts: &[Vec<u8>]) -> Result<Gaussians, SceneError> {
    let [pos, alpha, colour, scale, rot, sh] = parts else {
        return Err(fmt(path, "payload", "six attribute arrays", format!("{}", parts.len())));
    };
    let n = lay.n;
    let k = sh_coeffs_for_degree(lay.degree);
    let dim = k - 1;
    let step = 1.0 / (1u32 << lay.fractional_bits) as f32;
    let rot_size = if lay.version == 2 { 3 } else { 4 };
    let mut g = Gaussians::with_capacity(n, lay.degree);
    g.sh.resize(n * k * 3, 0.0);
    let byte = |v: &Vec<u8>, i: usize| v.get(i).copied().unwrap_or(0);
    for i in 0..n {
        let mut p = [0.0f32; 3];
        for (a, pa) in p.iter_mut().enumerate() {
            let o = i * 9 + a * 3;
            let raw = byte(pos, o) as u32 | (byte(pos, o + 1) as u32) << 8 | (byte(pos, o + 2) as u32) << 16;
            let signed = ((raw << 8) as i32) >> 8;
            *pa = signed as f32 * step;
        }
        p[1] = -p[1];
        p[2] = -p[2];
        g.means.push(p);
        g.opacity_logits.push(alpha_to_logit(byte(alpha, i) as f64 / 255.0));
        g.log_scales.push([0, 1, 2].map(|a| byte(scale, i * 3 + a) as f32 / 16.0 - 10.0));
        let rb = rot.get(i * rot_size..(i + 1) * rot_size).unwrap_or(&[]);
        let [w, x, y, z] = if lay.version == 2 {
            let xyz = [0, 1, 2].map(|a| rb.get(a).copied().unwrap_or(0) as f32 / 127.5 - 1.0);
            let w = (1.0 - xyz.iter().map(|v| v * v).sum::<f32>()).max(0.0).sqrt();
            [w, xyz[0], xyz[1], xyz[2]]
        } else {
            unpack_rotation_v3(rb)
        };
        g.quats.push([w, x, -y, -z]);
        let out = &mut g.sh[i * k * 3..(i + 1) * k * 3];
        for (ch, o) in out[..3].iter_mut().enumerate() {
            *o = (byte(colour, i * 3 + ch) as f32 / 255.0 - 0.5) / COLOR_SCALE;
        }
        for j in 0..dim {
            for ch in 0..3 {
                out[(j + 1) * 3 + ch] = SH_FLIP[j] * (byte(sh, (i * dim + j) * 3 + ch) as f32 - 128.0) / 128.0;
            }
        }
    }
    validate(path, &g)?;
    Ok(g)
}

/// Builds `.spz` bytes for tests: `version` 3 (gzip) or 4 (zstd), from raw
/// attribute arrays (positions, alphas, colours, scales, rotations, SH), with
/// Niantic's 12 fractional bits.
#[cfg(test)]
pub(crate) fn encode_for_test(version: u32, n: u32, degree: u8, parts: &[Vec<u8>; 6]) -> Vec<u8> {
    container(version, n, degree, 12, parts).expect("encode to memory")
}

/// Wraps the attribute arrays in a version 3 (one gzip stream) or version 4
/// (plain header, table of sizes, one zstd frame per non-empty array) file.
fn container(version: u32, n: u32, degree: u8, fractional_bits: u8, parts: &[Vec<u8>; 6]) -> std::io::Result<Vec<u8>> {
    use std::io::Write;
    let mut head = Vec::new();
    head.extend_from_slice(MAGIC);
    head.extend_from_slice(&version.to_le_bytes());
    head.extend_from_slice(&n.to_le_bytes());
    if version == 4 {
        let count = if parts[5].is_empty() { 5 } else { 6 };
        head.extend_from_slice(&[degree, fractional_bits, 0, count]);
        head.extend_from_slice(&32u32.to_le_bytes());
        head.extend_from_slice(&[0; 12]);
        let frames: Vec<Vec<u8>> = parts[..count as usize]
            .iter()
            .map(|s| ruzstd::encoding::compress_to_vec(s.as_slice(), ruzstd::encoding::CompressionLevel::Fastest))
            .collect();
        for (f, s) in frames.iter().zip(&parts[..count as usize]) {
            head.extend_from_slice(&(f.len() as u64).to_le_bytes());
            head.extend_from_slice(&(s.len() as u64).to_le_bytes());
        }
        for f in frames {
            head.extend_from_slice(&f);
        }
        Ok(head)
    } else {
        head.extend_from_slice(&[degree, fractional_bits, 0, 0]);
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(&head)?;
        for p in parts {
            enc.write_all(p)?;
        }
        enc.finish()
    }
}

/// The most fraction bits (at most 23, of a signed 24-bit fixed point) that
/// still hold the largest coordinate of `g`; `None` when even 0 does not.
fn fraction_bits_for(g: &Gaussians) -> Option<u8> {
    let largest = g.means.iter().flatten().fold(0.0f64, |m, &v| m.max((v as f64).abs()));
    (0..=23u8).rev().find(|&b| (largest * (1u64 << b) as f64).round() <= ((1 << 23) - 1) as f64)
}

/// A byte from a value already scaled to 0..255 (rounded, clamped).
fn byte_of(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// Smallest-three packing (v3+) of an (x, y, z, w) quaternion, the inverse of
/// [`unpack_rotation_v3`].
fn pack_rotation_v3(q: [f32; 4]) -> [u8; 4] {
    let q = super::normalised_largest_positive(q);
    let largest = super::largest_abs(&q);
    let mask = (1u32 << 9) - 1;
    let mut comp = largest as u32;
    for (i, v) in q.iter().enumerate() {
        if i != largest {
            let mag = (v.abs() / std::f32::consts::FRAC_1_SQRT_2 * mask as f32).round().min(mask as f32) as u32;
            comp = comp << 10 | u32::from(*v < 0.0) << 9 | mag;
        }
    }
    comp.to_le_bytes()
}

/// Encodes `g` as a `.spz` of `version` 3 or 4, converting to the format's
/// right-up-back frame (the inverse of the reader's flip). Positions use the
/// most fraction bits the scene's extent allows (Niantic's writer always uses
/// 12, which overflows beyond ±2048 units); a scene beyond ±2^23 is refused.
pub(crate) fn encode(path: &Path, g: &Gaussians, version: u32) -> Result<Vec<u8>, SceneError> {
    let n = g.len();
    let count = u32::try_from(n).map_err(|_| fmt(path, "count", "at most 2^32 − 1 Gaussians", n.to_string()))?;
    let bits = fraction_bits_for(g).ok_or_else(|| {
        fmt(path, "positions", "coordinates within ±8388607 (24-bit fixed point)", "a larger coordinate")
    })?;
    let k = g.sh_coeffs();
    let scale = (1u64 << bits) as f64;
    let mut parts: [Vec<u8>; 6] = Default::default();
    for i in 0..n {
        let [x, y, z] = g.means[i];
        for v in [x, -y, -z] {
            let fixed = ((v as f64) * scale).round() as i32;
            parts[0].extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
        let alpha = 1.0 / (1.0 + (-g.opacity_logits[i]).exp());
        parts[1].push(byte_of(alpha * 255.0));
        let sh = g.sh_of(i);
        for &c in &sh[..3] {
            parts[2].push(byte_of((c * COLOR_SCALE + 0.5) * 255.0));
        }
        for s in g.log_scales[i] {
            parts[3].push(byte_of((s + 10.0) * 16.0));
        }
        let [w, qx, qy, qz] = g.quats[i];
        parts[4].extend_from_slice(&pack_rotation_v3([qx, -qy, -qz, w]));
        for j in 0..k - 1 {
            for ch in 0..3 {
                parts[5].push(byte_of(SH_FLIP[j] * sh[(j + 1) * 3 + ch] * 128.0 + 128.0));
            }
        }
    }
    container(version, count, g.sh_degree as u8, bits, &parts).map_err(|e| SceneError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_smallest_three_round_values() {
        // largest = w (index 3), others zero → identity.
        let q = unpack_rotation_v3(&(3u32 << 30).to_le_bytes());
        assert_eq!(q, [1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn rotation_packs_back_to_itself() {
        for q in [[0.0, 0.0, 0.0, 1.0], [0.1, -0.7, 0.2, 0.3], [-0.5, 0.5, -0.5, 0.5], [0.0, -2.0, 0.0, 0.0]] {
            let n = q.iter().map(|v: &f32| v * v).sum::<f32>().sqrt();
            let b = unpack_rotation_v3(&pack_rotation_v3(q)); // (w, x, y, z)
            let back = [b[1], b[2], b[3], b[0]];
            let dot: f32 = (0..4).map(|c| back[c] * q[c] / n).sum();
            assert!(dot.abs() > 1.0 - 1e-5, "{q:?} came back as {back:?}");
        }
    }

    #[test]
    fn fraction_bits_fit_the_extent() {
        let mut g = crate::scene::test_util::sample(3, 0);
        g.means = vec![[0.0; 3], [2047.9, 0.0, 0.0], [0.0, -1.0, 0.0]];
        assert_eq!(fraction_bits_for(&g), Some(12));
        g.means[1][0] = 0.5;
        assert_eq!(fraction_bits_for(&g), Some(22));
        g.means[1][0] = 1e7;
        assert_eq!(fraction_bits_for(&g), None);
    }
}
