//! What only the CPU engine steps: the optimised Gaussians, the frozen
//! reference `G^c` and Adam's moments.
//!
//! The colour steps change only the DC coefficients (`ShGrads::Dc`), so the
//! higher SH bands of the optimised set stay those of `G^c` for the whole
//! run. The reference keeps its geometry and DC alone and borrows those bands
//! when a view's targets render it ([`CpuState::with_reference`]): on a scene
//! of 2,000,000 Gaussians of SH degree 2, 216 MB it no longer holds.

use rayon::prelude::*;

use crate::scene::Gaussians;
use crate::style::adam::Adam;

/// Gaussians a rayon task takes at least in the DC swap.
const PER_TASK: usize = 4096;

/// The CPU engine's state. A run on the GPU engine keeps none of it on the
/// host (the engine holds its own copies on the device).
pub(super) struct CpuState {
    /// The optimised Gaussians (current).
    pub(super) g: Gaussians,
    /// `G^c` restricted to the optimised Gaussians, the frozen reference, at
    /// SH degree 0: its DC in `sh`, its higher bands `g`'s
    /// ([`CpuState::with_reference`]). Its geometry is whole.
    pub(super) g_ref: Gaussians,
    pub(super) opt: Optimisers,
}

/// Optimiser state, one Adam per parameter group, per phase (kept across cycles).
pub(super) struct Optimisers {
    pub(super) color: Adam,
    pub(super) means: Adam,
    pub(super) scales: Adam,
    pub(super) quats: Adam,
    pub(super) opacity: Adam,
}

impl Optimisers {
    /// Every group, in the order of [`super::moments::GROUPS`].
    pub(super) fn groups(&self) -> [&Adam; 5] {
        [&self.color, &self.means, &self.scales, &self.quats, &self.opacity]
    }

    /// [`Optimisers::groups`], to set.
    pub(super) fn groups_mut(&mut self) -> [&mut Adam; 5] {
        [&mut self.color, &mut self.means, &mut self.scales, &mut self.quats, &mut self.opacity]
    }
}

impl CpuState {
    /// The state at the run's start: `reference` (`G^c` on the optimised
    /// Gaussians) becomes the optimised set, and the reference keeps its
    /// geometry and DC.
    pub(super) fn new(reference: Gaussians, opt: Optimisers) -> Self {
        let k = reference.sh_coeffs() * 3;
        let mut dc = Vec::with_capacity(3 * reference.len());
        dc.extend(reference.sh.chunks_exact(k).flat_map(|c| &c[..3]));
        let g_ref = Gaussians {
            means: reference.means.clone(),
            log_scales: reference.log_scales.clone(),
            quats: reference.quats.clone(),
            opacity_logits: reference.opacity_logits.clone(),
            sh_degree: 0,
            sh: dc,
        };
        Self { g: reference, g_ref, opt }
    }

    /// Runs `f` on `G^c` whole: the reference's geometry and DC with the
    /// optimised set's higher bands, which no step changes. The bands are
    /// moved, not copied (the DC swapped in place), and back in `g` when `f`
    /// returns.
    pub(super) fn with_reference<R>(&mut self, f: impl FnOnce(&Gaussians) -> R) -> R {
        if self.g.sh_degree == 0 {
            return f(&self.g_ref);
        }
        let degree = self.g.sh_degree;
        let mut sh = std::mem::take(&mut self.g.sh);
        swap_dc(&mut sh, &mut self.g_ref.sh, self.g.sh_coeffs() * 3);
        let dc = std::mem::replace(&mut self.g_ref.sh, sh);
        self.g_ref.sh_degree = degree;
        let out = f(&self.g_ref);
        self.g_ref.sh_degree = 0;
        let mut sh = std::mem::replace(&mut self.g_ref.sh, dc);
        swap_dc(&mut sh, &mut self.g_ref.sh, self.g.sh_coeffs() * 3);
        self.g.sh = sh;
        out
    }

    /// Gives `g` (a resumed state) the higher SH bands of `G^c`
    /// (`reference`, the same Gaussians at `g`'s degree), which
    /// [`CpuState::with_reference`] lends to the reference's renders; a state
    /// a run with the same inputs wrote has them already.
    pub(super) fn take_higher_bands(&mut self, reference: &Gaussians) {
        let k = self.g.sh_coeffs() * 3;
        if k == 3 || reference.sh.len() != self.g.sh.len() {
            return;
        }
        self.g.sh.par_chunks_mut(k).zip(reference.sh.par_chunks(k)).with_min_len(PER_TASK).for_each(|(g, r)| {
            g[3..].copy_from_slice(&r[3..]);
        });
    }
}

/// Swaps the DC (the first three values of each Gaussian's `k` in `sh`) with
/// `dc` (three a Gaussian).
fn swap_dc(sh: &mut [f32], dc: &mut [f32], k: usize) {
    sh.par_chunks_mut(k).zip(dc.par_chunks_mut(3)).with_min_len(PER_TASK).for_each(|(s, d)| {
        s[..3].swap_with_slice(d);
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::style::adam::AdamConfig;

    fn scene(n: usize, degree: u32) -> Gaussians {
        let k = crate::scene::sh_coeffs_for_degree(degree) * 3;
        let mut g = Gaussians::with_capacity(n, degree);
        for i in 0..n {
            let f = i as f32;
            g.means.push([f, -f, 0.5 * f]);
            g.log_scales.push([-1.0, -2.0, -3.0 + 0.01 * f]);
            g.quats.push([1.0, 0.0, 0.1 * f, 0.0]);
            g.opacity_logits.push(0.2 * f);
            g.sh.extend((0..k).map(|c| f + 0.01 * c as f32));
        }
        g
    }

    fn state(reference: Gaussians) -> CpuState {
        let n = reference.len();
        let adam = |len| Adam::new(len, AdamConfig::default());
        let opt = Optimisers {
            color: adam(3 * n),
            means: adam(3 * n),
            scales: adam(3 * n),
            quats: adam(4 * n),
            opacity: adam(n),
        };
        CpuState::new(reference, opt)
    }

    #[test]
    fn the_reference_lends_its_dc_to_the_optimised_sets_higher_bands() {
        for degree in 0..=3 {
            let reference = scene(5, degree);
            let mut cpu = state(reference.clone());
            assert_eq!(cpu.g_ref.sh.len(), 5 * 3, "degree {degree}: the reference holds the DC alone");
            // Steps move the optimised set's DC and geometry, never its higher bands.
            let k = cpu.g.sh_coeffs() * 3;
            for c in cpu.g.sh.chunks_exact_mut(k) {
                c[..3].iter_mut().for_each(|v| *v += 7.0);
            }
            cpu.g.means[2][0] += 1.0;
            let stepped = cpu.g.clone();
            let seen = cpu.with_reference(Gaussians::clone);
            assert_eq!(seen, reference, "degree {degree}: G^c whole");
            assert_eq!(cpu.g, stepped, "degree {degree}: the optimised set as it was");
            assert_eq!(cpu.g_ref.sh_degree, 0);
            assert_eq!(cpu.g_ref.sh.len(), 5 * 3);
        }
    }

    #[test]
    fn a_resumed_state_takes_the_references_higher_bands() {
        let reference = scene(4, 2);
        let mut cpu = state(reference.clone());
        let mut resumed = reference.clone();
        resumed.sh.iter_mut().for_each(|v| *v -= 3.0);
        cpu.g = resumed.clone();
        cpu.take_higher_bands(&reference);
        let k = cpu.g.sh_coeffs() * 3;
        for ((g, r), s) in cpu.g.sh.chunks_exact(k).zip(reference.sh.chunks_exact(k)).zip(resumed.sh.chunks_exact(k)) {
            assert_eq!(g[..3], s[..3], "the DC is the state's");
            assert_eq!(g[3..], r[3..], "the higher bands are G^c's");
        }
        assert_eq!(cpu.with_reference(Gaussians::clone), reference);
    }
}
