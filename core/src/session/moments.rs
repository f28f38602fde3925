//! The optimiser's state of a run ([`OptimiserState`]): each parameter
//! group's Adam steps and moments, and the phase leak's sums where the leak
//! is on, which a checkpoint keeps beside its scene so that a resumed run
//! updates as the whole run would have. Stored as safetensors: `{group}.m`
//! and `{group}.v` (f32), `leak.{group}` (f32) when there are sums, the
//! steps in the metadata ([`StateFile`], which a fit's state
//! ([`crate::fit::FitState`]) shares).

use std::collections::HashMap;

use safetensors::tensor::{Dtype, Metadata, TensorInfo};

use crate::style::adam::AdamState;

/// The parameter groups, in the order of [`OptimiserState::groups`].
pub const GROUPS: [&str; 5] = ["color", "means", "scales", "quats", "opacity"];

/// Every parameter group's optimiser state, in the order of [`GROUPS`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OptimiserState {
    /// The run's steps when the state was taken.
    pub step: u32,
    /// One per group of [`GROUPS`].
    pub groups: Vec<AdamState>,
    /// The phase leak's sums ([`crate::style::StyleConfig::phase_leak`]),
    /// one per group of [`GROUPS`] (what one phase's steps left on the other
    /// phase's parameters, not yet applied); empty when the leak is off (and
    /// in files written before the sums were kept).
    pub leak: Vec<Vec<f32>>,
}

/// The tensor of the leak's sum of group `name`.
fn leak_tensor(name: &str) -> String {
    format!("leak.{name}")
}

impl OptimiserState {
    /// The state as a safetensors file's bytes.
    pub fn to_safetensors(&self) -> Result<Vec<u8>, String> {
        let mut bytes = Vec::new();
        self.write_to(&mut bytes).map_err(|e| e.to_string())?;
        Ok(bytes)
    }

    /// Writes [`OptimiserState::to_safetensors`]'s bytes into `w` without
    /// making them in memory first.
    pub fn write_to(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let meta = HashMap::from([("step".to_owned(), self.step.to_string())]);
        let names: Vec<String> = GROUPS.iter().map(|g| leak_tensor(g)).collect();
        let leak: Vec<(&str, Tensor<'_>)> =
            names.iter().zip(&self.leak).map(|(name, sum)| (name.as_str(), Tensor::F32(sum))).collect();
        StateFile::write_into(w, &GROUPS, &self.groups, &leak, meta)
    }

    /// Reads [`OptimiserState::to_safetensors`]'s bytes; an error that says
    /// what is missing or malformed.
    pub fn from_safetensors(bytes: &[u8]) -> Result<Self, String> {
        let file = StateFile::read(bytes)?;
        let leak = if file.has(&leak_tensor(GROUPS[0])) {
            GROUPS.iter().map(|g| file.f32s(&leak_tensor(g))).collect::<Result<_, _>>()?
        } else {
            Vec::new()
        };
        Ok(Self { step: file.number("step")?, groups: file.groups(&GROUPS)?, leak })
    }
}

/// A tensor of a state file beside the groups' moments.
#[derive(Clone)]
pub(crate) enum Tensor<'a> {
    F32(&'a [f32]),
    U32(&'a [u32]),
}

impl Tensor<'_> {
    fn dtype(&self) -> Dtype {
        match self {
            Tensor::F32(_) => Dtype::F32,
            Tensor::U32(_) => Dtype::U32,
        }
    }

    fn len(&self) -> usize {
        match self {
            Tensor::F32(x) => x.len(),
            Tensor::U32(x) => x.len(),
        }
    }
}

/// Writes `values` little-endian through a small buffer (no copy of the whole).
fn write_le<T: Copy, const N: usize, W: std::io::Write + ?Sized>(
    w: &mut W,
    values: &[T],
    le: impl Fn(T) -> [u8; N],
) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(N * 16_384);
    for chunk in values.chunks(16_384) {
        buf.clear();
        buf.extend(chunk.iter().flat_map(|&v| le(v)));
        w.write_all(&buf)?;
    }
    Ok(())
}

/// A safetensors file of optimiser groups (`{group}.m`, `{group}.v` in f32,
/// `{group}.steps` in the metadata), further tensors and metadata: the
/// format of a stylization's and of a fit's optimiser state.
pub(crate) struct StateFile<'a> {
    st: safetensors::SafeTensors<'a>,
    meta: HashMap<String, String>,
}

impl<'a> StateFile<'a> {
    /// Writes the file of `groups` (named by `names`), `extra` tensors and
    /// `meta` into `w` as the moments stand, laid out as `safetensors::serialize`
    /// lays them out (its header, its tensor order), without the copy of every
    /// tensor in bytes and of the whole file in memory that it makes first.
    pub fn write_into<W: std::io::Write + ?Sized>(
        w: &mut W,
        names: &[&str],
        groups: &[AdamState],
        extra: &[(&str, Tensor<'_>)],
        mut meta: HashMap<String, String>,
    ) -> std::io::Result<()> {
        let mut tensors: Vec<(String, Tensor<'_>)> = (names.iter().zip(groups))
            .flat_map(|(name, g)| [(format!("{name}.m"), Tensor::F32(&g.m)), (format!("{name}.v"), Tensor::F32(&g.v))])
            .collect();
        tensors.extend(extra.iter().map(|(name, t)| ((*name).to_owned(), t.clone())));
        // safetensors' order: by descending dtype, then by name.
        tensors.sort_by(|(a, ta), (b, tb)| tb.dtype().cmp(&ta.dtype()).then(a.cmp(b)));
        let mut offset = 0;
        let infos = tensors
            .iter()
            .map(|(name, t)| {
                let (len, at) = (t.len(), offset);
                offset += 4 * len;
                let info = TensorInfo { dtype: t.dtype(), shape: vec![len], data_offsets: (at, offset) };
                (name.clone(), info)
            })
            .collect();
        meta.extend(names.iter().zip(groups).map(|(name, g)| (format!("{name}.steps"), g.step.to_string())));
        let invalid = |e: String| std::io::Error::new(std::io::ErrorKind::InvalidData, e);
        let header = Metadata::new(Some(meta), infos).map_err(|e| invalid(e.to_string()))?;
        let mut header = serde_json::to_vec(&header).map_err(|e| invalid(e.to_string()))?;
        header.resize(header.len().next_multiple_of(8), b' ');
        w.write_all(&(header.len() as u64).to_le_bytes())?;
        w.write_all(&header)?;
        for (_, t) in &tensors {
            match t {
                Tensor::F32(x) => write_le(w, x, |v| v.to_le_bytes())?,
                Tensor::U32(x) => write_le(w, x, |v| v.to_le_bytes())?,
            }
        }
        Ok(())
    }

    /// Opens a file's bytes.
    pub fn read(bytes: &'a [u8]) -> Result<Self, String> {
        let (_, meta) = safetensors::SafeTensors::read_metadata(bytes).map_err(|e| format!("not safetensors: {e}"))?;
        let meta = meta.metadata().clone().unwrap_or_default();
        let st = safetensors::SafeTensors::deserialize(bytes).map_err(|e| format!("not safetensors: {e}"))?;
        Ok(Self { st, meta })
    }

    /// A metadata entry.
    pub fn text(&self, key: &str) -> Result<&str, String> {
        self.meta.get(key).map(String::as_str).ok_or_else(|| format!("no {key:?} in the metadata"))
    }

    /// A metadata entry that is a count.
    pub fn number(&self, key: &str) -> Result<u32, String> {
        let text = self.text(key)?;
        text.parse().map_err(|_| format!("{key:?} is {text:?}, not a step count"))
    }

    fn tensor(&self, name: &str, dtype: Dtype) -> Result<Vec<[u8; 4]>, String> {
        let view = self.st.tensor(name).map_err(|_| format!("no tensor {name:?}"))?;
        if view.dtype() != dtype {
            return Err(format!("{name:?} is {:?}, not {dtype:?}", view.dtype()));
        }
        Ok(view.data().chunks_exact(4).map(|b| [b[0], b[1], b[2], b[3]]).collect())
    }

    /// Whether the file holds a tensor `name`.
    pub fn has(&self, name: &str) -> bool {
        self.st.tensor(name).is_ok()
    }

    /// An f32 tensor.
    pub fn f32s(&self, name: &str) -> Result<Vec<f32>, String> {
        Ok(self.tensor(name, Dtype::F32)?.into_iter().map(f32::from_le_bytes).collect())
    }

    /// A u32 tensor.
    pub fn u32s(&self, name: &str) -> Result<Vec<u32>, String> {
        Ok(self.tensor(name, Dtype::U32)?.into_iter().map(u32::from_le_bytes).collect())
    }

    /// The groups named `names`.
    pub fn groups(&self, names: &[&str]) -> Result<Vec<AdamState>, String> {
        names
            .iter()
            .map(|name| {
                Ok(AdamState {
                    step: self.number(&format!("{name}.steps"))?,
                    m: self.f32s(&format!("{name}.m"))?,
                    v: self.f32s(&format!("{name}.v"))?,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_state_goes_through_its_file_to_the_bit() {
        let group = |k: usize| AdamState {
            step: k as u32 * 7,
            m: (0..k * 3).map(|i| i as f32 * -0.25 + 1e-30).collect(),
            v: (0..k * 3).map(|i| (i as f32).sqrt()).collect(),
        };
        let state = OptimiserState { step: 123, groups: (1..=5).map(group).collect(), leak: Vec::new() };
        let bytes = state.to_safetensors().expect("written");
        assert_eq!(OptimiserState::from_safetensors(&bytes).expect("read"), state);
        // With the phase leak's sums, one per group.
        let leak = (1..=5).map(|k| (0..k * 3).map(|i| i as f32 * 0.5 - 1.0).collect()).collect();
        let state = OptimiserState { leak, ..state };
        let bytes = state.to_safetensors().expect("written");
        assert_eq!(OptimiserState::from_safetensors(&bytes).expect("read"), state);
        // The bytes safetensors' own serializer makes of the same tensors.
        let le = |x: &[f32]| -> Vec<u8> { x.iter().flat_map(|f| f.to_le_bytes()).collect() };
        let mut tensors: Vec<(String, Vec<u8>)> = (GROUPS.iter().zip(&state.groups))
            .flat_map(|(name, g)| [(format!("{name}.m"), le(&g.m)), (format!("{name}.v"), le(&g.v))])
            .collect();
        tensors.extend(GROUPS.iter().zip(&state.leak).map(|(name, sum)| (leak_tensor(name), le(sum))));
        let views = tensors.iter().map(|(name, b)| {
            (name.clone(), safetensors::tensor::TensorView::new(Dtype::F32, vec![b.len() / 4], b).expect("view"))
        });
        let mut meta = HashMap::from([("step".to_owned(), "123".to_owned())]);
        meta.extend(GROUPS.iter().zip(&state.groups).map(|(name, g)| (format!("{name}.steps"), g.step.to_string())));
        let theirs = safetensors::serialize(views, Some(meta)).expect("serialized");
        // The same header (its metadata map in a HashMap's order, in theirs
        // too) and the same tensors' bytes after it.
        let split = |b: &[u8]| {
            let n = 8 + u64::from_le_bytes(b[..8].try_into().expect("8 bytes")) as usize;
            let header: serde_json::Value = serde_json::from_slice(&b[8..n]).expect("a JSON header");
            (n, header, b[n..].to_vec())
        };
        assert!(split(&bytes) == split(&theirs), "the file differs from safetensors::serialize's");
        let bad = OptimiserState::from_safetensors(b"not a file").expect_err("refused");
        assert!(bad.starts_with("not safetensors"), "{bad}");
    }
}
