//! The optimiser's state of a run ([`OptimiserState`]): each parameter
//! group's Adam steps and moments, which a checkpoint keeps beside its scene
//! so that a resumed run updates as the whole run would have. Stored as
//! safetensors: `{group}.m` and `{group}.v` (f32), the steps in the metadata.

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
}

impl OptimiserState {
    /// The state as a safetensors file's bytes.
    pub fn to_safetensors(&self) -> Result<Vec<u8>, String> {
        let bytes: Vec<(String, Vec<u8>)> = (GROUPS.iter().zip(&self.groups))
            .flat_map(|(name, g)| [(format!("{name}.m"), &g.m), (format!("{name}.v"), &g.v)])
            .map(|(name, x)| (name, x.iter().flat_map(|f| f.to_le_bytes()).collect()))
            .collect();
        let views = bytes
            .iter()
            .map(|(name, b)| Ok((name.clone(), TensorView::new(Dtype::F32, vec![b.len() / 4], b)?)))
            .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
            .map_err(|e| e.to_string())?;
        let mut meta: HashMap<String, String> =
            GROUPS.iter().zip(&self.groups).map(|(name, g)| (format!("{name}.steps"), g.step.to_string())).collect();
        meta.insert("step".into(), self.step.to_string());
        safetensors::serialize(views, Some(meta)).map_err(|e| e.to_string())
    }

    /// Reads [`OptimiserState::to_safetensors`]'s bytes; an error that says
    /// what is missing or malformed.
    pub fn from_safetensors(bytes: &[u8]) -> Result<Self, String> {
        let (_, meta) = safetensors::SafeTensors::read_metadata(bytes).map_err(|e| format!("not safetensors: {e}"))?;
        let meta = meta.metadata().clone().unwrap_or_default();
        let number = |key: &str| -> Result<u32, String> {
            let text = meta.get(key).ok_or_else(|| format!("no {key:?} in the metadata"))?;
            text.parse().map_err(|_| format!("{key:?} is {text:?}, not a step count"))
        };
        let st = safetensors::SafeTensors::deserialize(bytes).map_err(|e| format!("not safetensors: {e}"))?;
        let tensor = |name: String| -> Result<Vec<f32>, String> {
            let view = st.tensor(&name).map_err(|_| format!("no tensor {name:?}"))?;
            if view.dtype() != Dtype::F32 {
                return Err(format!("{name:?} is {:?}, not F32", view.dtype()));
            }
            Ok(view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
        };
        let groups = GROUPS
            .iter()
            .map(|name| {
                Ok(AdamState {
                    step: number(&format!("{name}.steps"))?,
                    m: tensor(format!("{name}.m"))?,
                    v: tensor(format!("{name}.v"))?,
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(Self { step: number("step")?, groups })
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
        let state = OptimiserState { step: 123, groups: (1..=5).map(group).collect() };
        let bytes = state.to_safetensors().expect("written");
        assert_eq!(OptimiserState::from_safetensors(&bytes).expect("read"), state);
        let bad = OptimiserState::from_safetensors(b"not a file").expect_err("refused");
        assert!(bad.starts_with("not safetensors"), "{bad}");
    }
}
