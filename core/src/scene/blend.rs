//! Strength after the run: a scene between the colour-matched one and the
//! stylized one, colour and shape apart, with no new optimisation.
//!
//! Stylization never adds, removes or reorders Gaussians, so the two scenes
//! pair Gaussian by Gaussian. Every stored parameter is blended linearly
//! (SH coefficients for colour; means, log-scales, opacity logits and
//! quaternions for shape), `a + s·(b − a)`, written as `(1 − s)·a + s·b`
//! only where it is exact at the ends: `s = 0` gives `a` and `s = 1` gives
//! `b` to the bit. Quaternions are blended on the same hemisphere (the
//! stylized one's sign flipped where the two disagree) and left
//! unnormalised, as the renderer normalises them.

use super::Gaussians;

/// How much of the stylization to keep, each in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Strength {
    /// Share of the colour change (SH coefficients).
    pub colour: f32,
    /// Share of the shape change (means, scales, rotations, opacities).
    pub shape: f32,
}

impl Strength {
    /// The stylized scene as it is.
    pub const FULL: Strength = Strength { colour: 1.0, shape: 1.0 };

    /// Both strengths the same.
    pub fn both(s: f32) -> Self {
        Self { colour: s, shape: s }
    }

    /// Whether this is the stylized scene as it is.
    pub fn is_full(self) -> bool {
        self.colour == 1.0 && self.shape == 1.0
    }
}

/// Why two scenes cannot be blended.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BlendError {
    /// Different numbers of Gaussians.
    #[error("expected the same number of Gaussians as the stylized scene ({expected}), found {found}")]
    Count {
        /// The stylized scene's count.
        expected: usize,
        /// The other scene's.
        found: usize,
    },
    /// Different SH degrees.
    #[error("expected SH degree {expected} as the stylized scene, found {found}")]
    ShDegree {
        /// The stylized scene's degree.
        expected: u32,
        /// The other scene's.
        found: u32,
    },
    /// A strength outside [0, 1].
    #[error("expected a strength between 0 and 1 (0% and 100%), found {0}")]
    Range(f32),
}

/// `a + s·(b − a)`, exactly `a` at 0 and exactly `b` at 1.
fn lerp(a: f32, b: f32, s: f32) -> f32 {
    if s == 0.0 {
        a
    } else if s == 1.0 {
        b
    } else {
        a + s * (b - a)
    }
}

/// The scene `strength` of the way from `matched` (the colour-matched scene,
/// or the input) to `stylized`.
pub fn blend(matched: &Gaussians, stylized: &Gaussians, strength: Strength) -> Result<Gaussians, BlendError> {
    for s in [strength.colour, strength.shape] {
        if !(0.0..=1.0).contains(&s) {
            return Err(BlendError::Range(s));
        }
    }
    if matched.len() != stylized.len() {
        return Err(BlendError::Count { expected: stylized.len(), found: matched.len() });
    }
    if matched.sh_degree != stylized.sh_degree {
        return Err(BlendError::ShDegree { expected: stylized.sh_degree, found: matched.sh_degree });
    }
    let (c, g) = (strength.colour, strength.shape);
    let v3 = |a: &[[f32; 3]], b: &[[f32; 3]]| -> Vec<[f32; 3]> {
        a.iter().zip(b).map(|(a, b)| [lerp(a[0], b[0], g), lerp(a[1], b[1], g), lerp(a[2], b[2], g)]).collect()
    };
    let quats = matched
        .quats
        .iter()
        .zip(&stylized.quats)
        .map(|(a, b)| {
            let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
            // s = 1 keeps `b` exactly, sign and all.
            let sign = if dot < 0.0 && g != 1.0 { -1.0 } else { 1.0 };
            [0, 1, 2, 3].map(|k| lerp(a[k], sign * b[k], g))
        })
        .collect();
    Ok(Gaussians {
        means: v3(&matched.means, &stylized.means),
        log_scales: v3(&matched.log_scales, &stylized.log_scales),
        quats,
        opacity_logits: matched
            .opacity_logits
            .iter()
            .zip(&stylized.opacity_logits)
            .map(|(&a, &b)| lerp(a, b, g))
            .collect(),
        sh_degree: stylized.sh_degree,
        sh: matched.sh.iter().zip(&stylized.sh).map(|(&a, &b)| lerp(a, b, c)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(seed: u32) -> Gaussians {
        let n = 5;
        let f = |i: usize, k: u32| ((i as u32 * 31 + k * 7 + seed * 13) % 17) as f32 / 7.0 - 1.1;
        Gaussians {
            means: (0..n).map(|i| [f(i, 0), f(i, 1), f(i, 2)]).collect(),
            log_scales: (0..n).map(|i| [f(i, 3), f(i, 4), f(i, 5)]).collect(),
            quats: (0..n).map(|i| [f(i, 6), f(i, 7), f(i, 8), f(i, 9)]).collect(),
            opacity_logits: (0..n).map(|i| f(i, 10)).collect(),
            sh_degree: 1,
            sh: (0..n * 12).map(|i| f(i, 11)).collect(),
        }
    }

    #[test]
    fn the_ends_reproduce_their_scenes_to_the_bit() {
        let (a, b) = (scene(1), scene(2));
        assert_eq!(blend(&a, &b, Strength::both(0.0)).expect("a blend"), a);
        assert_eq!(blend(&a, &b, Strength::FULL).expect("a blend"), b);
        // Colour and shape apart: colour from b, shape from a.
        let mixed = blend(&a, &b, Strength { colour: 1.0, shape: 0.0 }).expect("a blend");
        assert_eq!((mixed.sh.clone(), mixed.means.clone()), (b.sh.clone(), a.means.clone()));
        assert_eq!((mixed.quats, mixed.opacity_logits), (a.quats, a.opacity_logits));
    }

    #[test]
    fn half_way_is_the_midpoint_on_the_same_hemisphere() {
        let a = scene(1);
        let mut b = a.clone();
        b.means[0][0] += 2.0;
        b.sh[3] -= 1.0;
        b.quats[0] = a.quats[0].map(|v| -v); // the same rotation, the other sign
        let h = blend(&a, &b, Strength::both(0.5)).expect("a blend");
        assert!((h.means[0][0] - (a.means[0][0] + 1.0)).abs() < 1e-6);
        assert!((h.sh[3] - (a.sh[3] - 0.5)).abs() < 1e-6);
        assert_eq!(h.quats[0], a.quats[0], "q and −q are one rotation: no shrink through zero");
    }

    #[test]
    fn mismatched_scenes_and_strengths_are_refused() {
        let (a, mut b) = (scene(1), scene(2));
        assert_eq!(blend(&a, &b, Strength::both(1.5)), Err(BlendError::Range(1.5)));
        b.sh_degree = 0;
        b.sh.truncate(5 * 3);
        assert_eq!(blend(&a, &b, Strength::FULL), Err(BlendError::ShDegree { expected: 0, found: 1 }));
        let c = Gaussians { means: vec![[0.0; 3]], ..scene(1) };
        assert!(matches!(blend(&c, &a, Strength::FULL), Err(BlendError::Count { expected: 5, found: 1 })));
    }
}
