//! Helpers for the scene unit tests: scratch directories and small
//! deterministic scenes.

use std::path::{Path, PathBuf};

use super::{Gaussians, sh_coeffs_for_degree};

/// A fresh, empty directory for one test, removed when dropped.
pub(crate) struct Scratch(PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A fresh, empty directory for one test.
pub(crate) fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("gast-scene-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    Scratch(dir)
}

/// `n` Gaussians of SH degree `degree` with varied, awkward float values.
pub(crate) fn sample(n: usize, degree: u32) -> Gaussians {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64 ^ (n as u64) ^ ((degree as u64) << 32);
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 11) as f64 / (1u64 << 53) as f64) as f32 * 2.0 - 1.0
    };
    let mut g = Gaussians::with_capacity(n, degree);
    for _ in 0..n {
        g.means.push([next() * 10.0, next() * 1e-3, next() * 1e5]);
        g.log_scales.push([next() * 5.0, next() - 4.0, next() * 0.1]);
        g.quats.push([next() + 2.0, next(), next(), next()]);
        g.opacity_logits.push(next() * 8.0);
        for _ in 0..sh_coeffs_for_degree(degree) * 3 {
            g.sh.push(next() * 1.7);
        }
    }
    g
}
