//! The optimiser's state of a run ([`OptimiserState`]): each parameter
//! group's Adam steps and moments, and the phase leak's sums where the leak
//! is on, which a checkpoint keeps beside its scene so that a resumed run
//! updates as the whole run would have. Stored as safetensors: `{group}.m`
//! and `{group}.v` (f32), `leak.{group}` (f32) when there are sums, the
//! steps in the metadata ([`StateFile`], which a fit's state
//! ([`crate::fit::FitState`]) shares).

use std::collections::HashMap;

use safetensors::tensor::{Dtype, TensorView};

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
        let meta = HashMap::from([("step".to_owned(), self.step.to_string())]);
        let names: Vec<String> = GROUPS.iter().map(|g| leak_tensor(g)).collect();
        let leak: Vec<(&str, Tensor<'_>)> =
            names.iter().zip(&self.leak).map(|(name, sum)| (name.as_str(), Tensor::F32(sum))).collect();
        StateFile::write(&GROUPS, &self.groups, &leak, meta)
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
pub(crate) enum Tensor<'a> {
    F32(&'a [f32]),
    U32(&'a [u32]),
}

/// A safetensors file of optimiser groups (`{group}.m`, `{group}.v` in f32,
/// `{group}.steps` in the metadata), further tensors and metadata: the
/// format of a stylization's and of a fit's optimiser state.
pub(crate) struct StateFile<'a> {
    st: safetensors::SafeTensors<'a>,
    meta: HashMap<String, String>,
}

impl<'a> StateFile<'a> {
    /// The bytes of a file of `groups` (named by `names`), `extra` tensors and `meta`.
    pub fn write(
        names: &[&str],
        groups: &[AdamState],
        extra: &[(&str, Tensor<'_>)],
        mut meta: HashMap<String, String>,
    ) -> Result<Vec<u8>, String> {
        let le = |x: &[f32]| -> Vec<u8> { x.iter().flat_map(|f| f.to_le_bytes()).collect() };
        let mut bytes: Vec<(String, Dtype, Vec<u8>)> = (names.iter().zip(groups))
            .flat_map(|(name, g)| [(format!("{name}.m"), &g.m), (format!("{name}.v"), &g.v)])
            .map(|(name, x)| (name, Dtype::F32, le(x)))
            .collect();
        for (name, t) in extra {
            bytes.push(match t {
                Tensor::F32(x) => ((*name).to_owned(), Dtype::F32, le(x)),
                Tensor::U32(x) => ((*name).to_owned(), Dtype::U32, x.iter().flat_map(|u| u.to_le_bytes()).collect()),
            });
        }
        let views = bytes
            .iter()
            .map(|(name, dtype, b)| Ok((name.clone(), TensorView::new(*dtype, vec![b.len() / 4], b)?)))
            .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
            .map_err(|e| e.to_string())?;
        meta.extend(names.iter().zip(groups).map(|(name, g)| (format!("{name}.steps"), g.step.to_string())));
        safetensors::serialize(views, Some(meta)).map_err(|e| e.to_string())
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
        let bad = OptimiserState::from_safetensors(b"not a file").expect_err("refused");
        assert!(bad.starts_with("not safetensors"), "{bad}");
    }
}
