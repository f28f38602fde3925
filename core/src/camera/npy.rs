//! The NumPy `.npy` container, as far as camera files need it: one
//! little-endian float64 matrix in C order (what `np.save` writes for LLFF's
//! `poses_bounds.npy`).
//!
//! The header is a Python dict literal (`{'descr': '<f8', 'fortran_order':
//! False, 'shape': (20, 17), }`); only its three keys are read, with a few
//! lines of string matching rather than a Python parser. Anything else (other
//! dtypes, Fortran order, other ranks) is refused with what was found, so a
//! file saved another way fails loudly instead of being read as noise.

use std::path::Path;

use super::CameraError;

const MAGIC: &[u8] = b"\x93NUMPY";

/// Reads a `(rows, cols)` float64 little-endian C-order array; returns the
/// number of rows and the values row by row. `cols` is what the caller's
/// format requires; at least one row is required.
pub(crate) fn read_f64_matrix(path: &Path, cols: usize) -> Result<(usize, Vec<f64>), CameraError> {
    let bytes = std::fs::read(path).map_err(|e| CameraError::io(path, e))?;
    let truncated = |record: &str, offset: usize, needed: usize| CameraError::Truncated {
        path: path.to_path_buf(),
        record: record.into(),
        offset: offset as u64,
        needed: needed as u64,
        available: bytes.len().saturating_sub(offset) as u64,
    };
    if bytes.len() < 8 {
        return Err(truncated("magic and version", 0, 8));
    }
    if &bytes[..6] != MAGIC {
        return Err(CameraError::format(
            path,
            "magic",
            "a NumPy .npy file (starting with \\x93NUMPY)",
            format!("{:?}", String::from_utf8_lossy(&bytes[..6])),
        ));
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (len_bytes, start) = match major {
        1 => (2, 10),
        2 | 3 => (4, 12),
        _ => {
            return Err(CameraError::format(path, "version", "npy format 1.0, 2.0 or 3.0", format!("{major}.{minor}")));
        }
    };
    if bytes.len() < start {
        return Err(truncated("header length", 8, len_bytes));
    }
    let header_len = if len_bytes == 2 {
        usize::from(u16::from_le_bytes([bytes[8], bytes[9]]))
    } else {
        u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize
    };
    let data_start = start.saturating_add(header_len);
    if bytes.len() < data_start {
        return Err(truncated("header", start, header_len));
    }
    let header = String::from_utf8_lossy(&bytes[start..data_start]);

    let descr = field(&header, "descr").and_then(quoted).unwrap_or("no descr");
    if descr != "<f8" {
        return Err(CameraError::format(path, "header.descr", "'<f8' (little-endian float64)", format!("{descr:?}")));
    }
    let fortran = field(&header, "fortran_order").unwrap_or("");
    if !fortran.starts_with("False") {
        let found = if fortran.starts_with("True") { "True" } else { "no fortran_order" };
        return Err(CameraError::format(path, "header.fortran_order", "False (C order)", found));
    }
    let shape_text = field(&header, "shape").unwrap_or("");
    let shape = shape(shape_text).filter(|s| s.len() == 2 && s[0] >= 1 && s[1] == cols).ok_or_else(|| {
        let found = shape_text.split_inclusive(')').next().unwrap_or("no shape").trim();
        CameraError::format(path, "header.shape", format!("(N, {cols}) with N ≥ 1"), found)
    })?;
    let rows = shape[0];
    let needed = rows.checked_mul(cols).and_then(|n| n.checked_mul(8)).ok_or_else(|| {
        CameraError::format(path, "header.shape", "a shape whose data fits in memory", format!("({rows}, {cols})"))
    })?;
    let available = bytes.len() - data_start;
    if available < needed {
        return Err(truncated(&format!("data of shape ({rows}, {cols})"), data_start, needed));
    }
    if available > needed {
        return Err(CameraError::format(
            path,
            "end of file",
            format!("the file to end after the {needed} data bytes of shape ({rows}, {cols})"),
            format!("{} more bytes", available - needed),
        ));
    }
    let values =
        bytes[data_start..].chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8]))).collect();
    Ok((rows, values))
}

/// The text after `'key':` in the header dict, trimmed at the start.
fn field<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let at = header.find(&format!("'{key}'")).or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = &header[at + key.len() + 2..];
    Some(rest.trim_start().strip_prefix(':')?.trim_start())
}

/// The contents of a quoted string at the start of `s`.
fn quoted(s: &str) -> Option<&str> {
    let q = s.chars().next().filter(|c| *c == '\'' || *c == '"')?;
    let rest = &s[1..];
    rest.find(q).map(|end| &rest[..end])
}

/// The integers of a tuple at the start of `s` (`(20, 17)`, `(5,)`).
fn shape(s: &str) -> Option<Vec<usize>> {
    let inner = s.strip_prefix('(')?;
    let inner = &inner[..inner.find(')')?];
    inner.split(',').map(str::trim).filter(|t| !t.is_empty()).map(|t| t.parse().ok()).collect()
}
