//! Reading a Depth Anything V2 checkpoint (`model.safetensors` with the
//! `transformers` tensor names) into the network's layers.
//!
//! The header is parsed here rather than by `safetensors::SafeTensors`, so
//! that every failure can name the tensor it concerns: a truncated download
//! says which tensor's bytes are missing, a misnamed tensor says which name
//! was expected and what the file has beside it, a shape that disagrees with
//! `config.json` names both. Element types F32, F64, F16 and BF16 are read
//! (the published checkpoints are F32, the golden file F64) and kept as f32.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::DepthModelError;

/// One tensor's entry in the safetensors header.
#[derive(serde::Deserialize)]
struct Entry {
    dtype: String,
    shape: Vec<usize>,
    data_offsets: (usize, usize),
}

/// A checkpoint file's bytes and header, from which tensors are taken by name.
pub(crate) struct Checkpoint {
    path: PathBuf,
    bytes: Vec<u8>,
    data_start: usize,
    entries: HashMap<String, Entry>,
    /// The header's `__metadata__` strings (the golden file keeps its config there).
    pub metadata: HashMap<String, String>,
    /// When set, every tensor asked for is made up from this seed instead (for benchmarks).
    random: Option<u64>,
}

impl Checkpoint {
    /// Reads and parses `path`.
    pub(crate) fn read(path: &Path) -> Result<Self, DepthModelError> {
        let bytes = std::fs::read(path).map_err(|source| DepthModelError::Io { path: path.to_path_buf(), source })?;
        Self::parse(path, bytes)
    }

    fn parse(path: &Path, bytes: Vec<u8>) -> Result<Self, DepthModelError> {
        let format = |found: String| DepthModelError::Format {
            path: path.to_path_buf(),
            expected: "a safetensors file (8-byte header length, JSON header, tensor data)".into(),
            found,
        };
        let Some(len) = bytes.get(..8) else {
            return Err(format(format!("{} bytes", bytes.len())));
        };
        let n = u64::from_le_bytes(len.try_into().unwrap_or([0; 8])) as usize;
        let Some(header) = bytes.get(8..8usize.saturating_add(n)) else {
            return Err(format(format!("a header of {n} bytes in a file of {} bytes (truncated?)", bytes.len())));
        };
        let mut raw: HashMap<String, serde_json::Value> =
            serde_json::from_slice(header).map_err(|e| format(format!("an unreadable header ({e})")))?;
        let metadata = match raw.remove("__metadata__") {
            Some(m) => serde_json::from_value(m).map_err(|e| format(format!("unreadable __metadata__ ({e})")))?,
            None => HashMap::new(),
        };
        let mut entries = HashMap::with_capacity(raw.len());
        for (name, v) in raw {
            let e: Entry = serde_json::from_value(v)
                .map_err(|e| format(format!("an unreadable header entry for tensor `{name}` ({e})")))?;
            entries.insert(name, e);
        }
        Ok(Self { path: path.to_path_buf(), bytes, data_start: 8 + n, entries, metadata, random: None })
    }

    /// A checkpoint that has every tensor with the shape asked for, filled
    /// with small pseudo-random values (±0.05), like a freshly initialised
    /// network: the real sizes' cost without the real weights.
    pub(crate) fn random(seed: u64) -> Self {
        let path = PathBuf::from(format!("<random weights, seed {seed}>"));
        Self {
            path,
            bytes: Vec::new(),
            data_start: 0,
            entries: HashMap::new(),
            metadata: HashMap::new(),
            random: Some(seed),
        }
    }

    /// The path the checkpoint was read from.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// The tensor `name` as f32, checked to have `shape`.
    pub(crate) fn take(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, DepthModelError> {
        if let Some(seed) = self.random {
            let mut state = name
                .bytes()
                .fold(seed ^ 0x9e37_79b9_7f4a_7c15, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3));
            let count: usize = shape.iter().product();
            return Ok((0..count)
                .map(|_| {
                    state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                    ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.1
                })
                .collect());
        }
        let Some(e) = self.entries.get(name) else {
            return Err(DepthModelError::MissingTensor {
                path: self.path.clone(),
                name: name.into(),
                nearby: self.nearby(name),
            });
        };
        let bad = |found: String| DepthModelError::BadTensor {
            path: self.path.clone(),
            name: name.into(),
            expected: format!("shape {shape:?} (from config.json)"),
            found,
        };
        if e.shape != shape {
            return Err(bad(format!("shape {:?}", e.shape)));
        }
        let width = match e.dtype.as_str() {
            "F32" => 4,
            "F64" => 8,
            "F16" | "BF16" => 2,
            other => return Err(bad(format!("element type {other} (expected F32, F64, F16 or BF16)"))),
        };
        let count: usize = shape.iter().product();
        let (a, b) = e.data_offsets;
        if b < a || b - a != count * width {
            return Err(bad(format!("{} data bytes for {count} {} values", b.wrapping_sub(a), e.dtype)));
        }
        let Some(data) = self.bytes.get(self.data_start + a..self.data_start + b) else {
            return Err(DepthModelError::Truncated {
                path: self.path.clone(),
                name: name.into(),
                needed: (self.data_start + b) as u64,
                found: self.bytes.len() as u64,
            });
        };
        Ok(match e.dtype.as_str() {
            "F32" => data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
            "F64" => data
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]) as f32)
                .collect(),
            "BF16" => data
                .chunks_exact(2)
                .map(|c| f32::from_bits(u32::from(u16::from_le_bytes([c[0], c[1]])) << 16))
                .collect(),
            _ => data.chunks_exact(2).map(|c| f16_to_f32(u16::from_le_bytes([c[0], c[1]]))).collect(),
        })
    }

    /// Up to four names in the file that could be `name` misspelt: same last
    /// segment (`weight`, `bias`, …) under the same grandparent module.
    fn nearby(&self, name: &str) -> Vec<String> {
        let (head, last) = name.rsplit_once('.').unwrap_or(("", name));
        let module = head.rsplit_once('.').map_or("", |(m, _)| m);
        let mut v: Vec<String> = self
            .entries
            .keys()
            .filter(|k| k.starts_with(module) && k.ends_with(&format!(".{last}")) && *k != name)
            .cloned()
            .collect();
        v.sort();
        v.truncate(4);
        v
    }
}

/// IEEE half to single precision.
fn f16_to_f32(h: u16) -> f32 {
    let sign = u32::from(h >> 15) << 31;
    let exp = u32::from((h >> 10) & 0x1f);
    let man = u32::from(h & 0x3ff);
    let bits = match (exp, man) {
        (0, 0) => sign,
        (0, m) => {
            // Subnormal: renormalise.
            let shift = m.leading_zeros() - 21;
            sign | ((113 - shift) << 23) | (((m << shift) & 0x3ff) << 13)
        }
        (0x1f, m) => sign | 0x7f80_0000 | (m << 13),
        (e, m) => sign | ((e + 112) << 23) | (m << 13),
    };
    f32::from_bits(bits)
}

#[cfg(test)]
mod tests {
    use super::f16_to_f32;

    #[test]
    fn half_precision_values() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(f16_to_f32(0x3555), 0.333_251_95);
    }
}
