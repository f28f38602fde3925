//! A fit's whole state after an iteration, beside its scene: each parameter
//! group's Adam moments, the densification's gradient statistics, the views
//! left in this pass's order and the generator's state. A checkpoint keeps
//! it (`fern.checkpoint.adam.safetensors`), so that a fit resumed from one
//! is the fit run through, to the bit.

use std::collections::HashMap;

use crate::scene::Gaussians;
use crate::session::moments::{StateFile, Tensor};
use crate::style::adam::AdamState;

/// The parameter groups, in the order of [`FitState::groups`].
pub const GROUPS: [&str; 6] = ["means", "scales", "quats", "opacity", "sh_dc", "sh_rest"];

/// A fit's state after `iteration` iterations, apart from its scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitState {
    /// Iterations done.
    pub iteration: u32,
    /// One optimiser per group of [`GROUPS`].
    pub groups: Vec<AdamState>,
    /// The view-space gradient norms summed per Gaussian since the last
    /// densification.
    pub grad_sum: Vec<f32>,
    /// How many views gave each Gaussian one.
    pub grad_count: Vec<u32>,
    /// The views left in this pass's order (the next one last).
    pub order: Vec<u32>,
    /// The generator's state (the view order, densification's splits).
    pub rng: u64,
}

impl FitState {
    /// The state as a safetensors file's bytes.
    pub fn to_safetensors(&self) -> Result<Vec<u8>, String> {
        let mut bytes = Vec::new();
        self.write_to(&mut bytes).map_err(|e| e.to_string())?;
        Ok(bytes)
    }

    /// Writes [`FitState::to_safetensors`]'s bytes into `w` without making
    /// them in memory first.
    pub fn write_to(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let meta = HashMap::from([
            ("iteration".to_owned(), self.iteration.to_string()),
            ("rng".to_owned(), self.rng.to_string()),
        ]);
        let extra = [
            ("grad_sum", Tensor::F32(&self.grad_sum)),
            ("grad_count", Tensor::U32(&self.grad_count)),
            ("order", Tensor::U32(&self.order)),
        ];
        StateFile::write_into(w, &GROUPS, &self.groups, &extra, meta)
    }

    /// Reads [`FitState::to_safetensors`]'s bytes; an error that says what
    /// is missing or malformed.
    pub fn from_safetensors(bytes: &[u8]) -> Result<Self, String> {
        let file = StateFile::read(bytes)?;
        let rng = file.text("rng")?;
        Ok(Self {
            iteration: file.number("iteration")?,
            groups: file.groups(&GROUPS)?,
            grad_sum: file.f32s("grad_sum")?,
            grad_count: file.u32s("grad_count")?,
            order: file.u32s("order")?,
            rng: rng.parse().map_err(|_| format!("\"rng\" is {rng:?}, not a generator's state"))?,
        })
    }

    /// Whether the state is that of the scene `g` after `iteration`
    /// iterations over `views` views; else what does not fit.
    pub fn check(&self, g: &Gaussians, iteration: u32, views: usize) -> Result<(), String> {
        if self.iteration != iteration {
            return Err(format!("it holds iteration {}'s state, not {iteration}'s", self.iteration));
        }
        let n = g.len();
        let sizes = [3 * n, 3 * n, 4 * n, n, 3 * n, (g.sh_coeffs() - 1) * 3 * n];
        let fits = self.groups.len() == sizes.len()
            && self.groups.iter().zip(sizes).all(|(s, len)| s.m.len() == len && s.v.len() == len);
        if !fits {
            let found: Vec<String> = self.groups.iter().map(|s| format!("{}/{}", s.m.len(), s.v.len())).collect();
            return Err(format!(
                "expected moments of {sizes:?} parameters (the groups {}) for {n} Gaussians, found {}",
                GROUPS.join(", "),
                found.join(", ")
            ));
        }
        if self.grad_sum.len() != n || self.grad_count.len() != n {
            return Err(format!(
                "expected gradient statistics of {n} Gaussians, found {} and {}",
                self.grad_sum.len(),
                self.grad_count.len()
            ));
        }
        if let Some(v) = self.order.iter().find(|&&v| v as usize >= views) {
            return Err(format!("its view order names view {v} of {views}"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_state_goes_through_its_file_to_the_bit() {
        let group = |k: usize| AdamState {
            step: k as u32 * 3,
            m: (0..k * 2).map(|i| i as f32 * -0.5 + 1e-30).collect(),
            v: (0..k * 2).map(|i| (i as f32).sqrt()).collect(),
        };
        let state = FitState {
            iteration: 1234,
            groups: (0..6).map(group).collect(),
            grad_sum: vec![0.25, 1e-20, 3.0],
            grad_count: vec![0, 7, u32::MAX],
            order: vec![4, 0, 2],
            rng: u64::MAX - 5,
        };
        let bytes = state.to_safetensors().expect("written");
        assert_eq!(FitState::from_safetensors(&bytes).expect("read"), state);
        let bad = FitState::from_safetensors(b"not a file").expect_err("refused");
        assert!(bad.starts_with("not safetensors"), "{bad}");
    }
}
