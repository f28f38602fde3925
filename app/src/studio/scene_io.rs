//! Scene files for the studio, until `gast_core::scene::{load, save_ply}` (branch
//! `scene`) is merged: the INRIA binary little-endian `.ply` layout only
//! (`x y z`, `nx ny nz`, `f_dc_*`, `f_rest_*` channel-major, `opacity`,
//! `scale_*`, `rot_*`). Other formats are refused with a message that says so.

use std::io::Write as _;
use std::path::Path;

use anyhow::{Context as _, bail};
use gast_core::Gaussians;
use gast_core::scene::sh_coeffs_for_degree;

/// Loads a scene file.
pub fn load(path: &Path) -> anyhow::Result<Gaussians> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read the file", path.display()))?;
    read_ply(&bytes).with_context(|| format!("{}: not a scene this build can read", path.display()))
}

/// Parses an INRIA-layout binary little-endian PLY.
pub fn read_ply(bytes: &[u8]) -> anyhow::Result<Gaussians> {
    let end = bytes.windows(11).position(|w| w == b"end_header\n").context("expected a PLY header ending in `end_header`, found none")?;
    let header = std::str::from_utf8(&bytes[..end]).context("the PLY header is not text")?;
    let mut lines = header.lines();
    if lines.next() != Some("ply") {
        bail!("expected the file to start with `ply`");
    }
    let mut count = None;
    let mut props: Vec<String> = Vec::new();
    let mut in_vertex = false;
    for line in lines {
        let parts: Vec<&str> = line.split_whitespace().collect();
        match parts.as_slice() {
            ["format", fmt, ..] if *fmt != "binary_little_endian" => bail!("expected binary_little_endian PLY, found `{fmt}`"),
            ["element", "vertex", n] => {
                count = Some(n.parse::<usize>().context("vertex count")?);
                in_vertex = true;
            }
            ["element", name, _] => {
                in_vertex = false;
                if *name != "vertex" {
                    bail!("found element `{name}`: compressed or other PLY layouts need the scene branch's reader");
                }
            }
            ["property", ty, name] if in_vertex => {
                if *ty != "float" {
                    bail!("expected float properties, found `{ty} {name}`");
                }
                props.push(name.to_string());
            }
            _ => {}
        }
    }
    let n = count.context("expected an `element vertex N` line")?;
    let idx = |name: &str| props.iter().position(|p| p == name);
    let need = |name: &str| idx(name).with_context(|| format!("expected a `{name}` property"));
    let rest = props.iter().filter(|p| p.starts_with("f_rest_")).count();
    let degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        other => bail!("expected 0, 9, 24 or 45 f_rest properties, found {other}"),
    };
    let stride = props.len() * 4;
    let body = &bytes[end + 11..];
    if body.len() < n * stride {
        bail!("expected {} bytes of vertex data, found {}", n * stride, body.len());
    }
    let cols: Vec<usize> = ["x", "y", "z", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", "opacity", "f_dc_0", "f_dc_1", "f_dc_2"]
        .iter()
        .map(|p| need(p))
        .collect::<anyhow::Result<_>>()?;
    let rest_cols: Vec<usize> = (0..rest).map(|k| need(&format!("f_rest_{k}"))).collect::<anyhow::Result<_>>()?;
    let k = sh_coeffs_for_degree(degree);
    let mut g = Gaussians::with_capacity(n, degree);
    for v in 0..n {
        let row = &body[v * stride..(v + 1) * stride];
        let f = |c: usize| f32::from_le_bytes([row[4 * c], row[4 * c + 1], row[4 * c + 2], row[4 * c + 3]]);
        g.means.push([f(cols[0]), f(cols[1]), f(cols[2])]);
        g.log_scales.push([f(cols[3]), f(cols[4]), f(cols[5])]);
        g.quats.push([f(cols[6]), f(cols[7]), f(cols[8]), f(cols[9])]);
        g.opacity_logits.push(f(cols[10]));
        g.sh.extend_from_slice(&[f(cols[11]), f(cols[12]), f(cols[13])]);
        // f_rest is channel-major: all coefficients of red, then green, then blue.
        for coef in 1..k {
            for ch in 0..3 {
                g.sh.push(f(rest_cols[ch * (k - 1) + coef - 1]));
            }
        }
    }
    g.check_consistent().map_err(anyhow::Error::msg)?;
    Ok(g)
}

/// The INRIA-layout binary PLY bytes of `g` (normals written as zeros).
pub fn ply_bytes(g: &Gaussians) -> Vec<u8> {
    let k = g.sh_coeffs();
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header += &format!("element vertex {}\n", g.len());
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"].iter().map(|s| s.to_string()).collect();
    names.extend((0..3 * (k - 1)).map(|i| format!("f_rest_{i}")));
    names.extend(["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"].iter().map(|s| s.to_string()));
    for n in &names {
        header += &format!("property float {n}\n");
    }
    header += "end_header\n";
    let mut out = header.into_bytes();
    for i in 0..g.len() {
        let sh = g.sh_of(i);
        let mut row: Vec<f32> = Vec::with_capacity(names.len());
        row.extend_from_slice(&g.means[i]);
        row.extend_from_slice(&[0.0; 3]);
        row.extend_from_slice(&sh[..3]);
        for ch in 0..3 {
            for coef in 1..k {
                row.push(sh[coef * 3 + ch]);
            }
        }
        row.push(g.opacity_logits[i]);
        row.extend_from_slice(&g.log_scales[i]);
        row.extend_from_slice(&g.quats[i]);
        for v in row {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Writes `g` as an INRIA `.ply`, atomically.
pub fn save_ply(path: &Path, g: &Gaussians) -> anyhow::Result<()> {
    let bytes = ply_bytes(g);
    gast_core::io::atomic_write(path, |w| w.write_all(&bytes)).with_context(|| format!("{}: cannot write the scene", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ply_round_trip_degree_2() {
        let mut g = Gaussians::with_capacity(2, 2);
        for i in 0..2 {
            g.means.push([i as f32, 1.0, 2.0]);
            g.log_scales.push([-1.0, -2.0, -3.0]);
            g.quats.push([1.0, 0.0, 0.1, 0.0]);
            g.opacity_logits.push(0.5);
            g.sh.extend((0..27).map(|k| k as f32 * 0.01 + i as f32));
        }
        let back = read_ply(&ply_bytes(&g)).expect("read back");
        assert_eq!(back, g);
        assert!(read_ply(b"ply\nformat ascii 1.0\nend_header\n").is_err());
    }
}
