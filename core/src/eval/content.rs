//! Content preservation: how far the stylized render's features moved from
//! those of the colour-matched render of the same view.
//!
//! The absolute measure is the content loss of the optimisation itself
//! (ALGORITHM.md), so a report and the training curve speak the same units;
//! the relative one divides by the reference's feature energy so that scenes
//! and resolutions with stronger activations can be compared. The masked
//! variant measures the object alone (the positions the colour-matched scene
//! covers), so a small object's change is not diluted by an unchanged background.

/// Content distance between two feature maps of the same view.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContentDistance {
    /// `mean((φ(I) − φ(I^c))²)` over every channel and position, squared feature units.
    pub mse: f32,
    /// `Σ(φ(I) − φ(I^c))² / Σ φ(I^c)²`, unitless (0 when the reference is all zeros).
    pub relative: f32,
}

/// The content distance between the features of a stylized render and those of
/// the colour-matched render `reference` from the same view (VGG relu3, same
/// CHW shape). `None` when the maps are empty or differ in length.
pub fn content_distance(stylized: &[f32], reference: &[f32]) -> Option<ContentDistance> {
    if stylized.is_empty() || stylized.len() != reference.len() {
        return None;
    }
    let (mut sq, mut energy) = (0.0f64, 0.0f64);
    for (&s, &r) in stylized.iter().zip(reference) {
        sq += (f64::from(s) - f64::from(r)).powi(2);
        energy += f64::from(r).powi(2);
    }
    let mse = (sq / stylized.len() as f64) as f32;
    let relative = if energy > 0.0 { (sq / energy) as f32 } else { 0.0 };
    Some(ContentDistance { mse, relative })
}

/// [`content_distance`] over the feature positions `covered` marks (one flag
/// per position of the `channels × positions` CHW maps, e.g. the
/// [`crate::style::focus::feature_mask`] of the colour-matched render's
/// coverage): the content change on the object, whatever happens on the
/// background. Both sums run over the covered positions only, so a mask of all
/// ones gives [`content_distance`]. `None` when the maps are empty, differ in
/// length, do not hold `channels × covered.len()` values, or no position is covered.
pub fn content_distance_masked(
    stylized: &[f32],
    reference: &[f32],
    channels: usize,
    covered: &[bool],
) -> Option<ContentDistance> {
    let n = covered.len();
    if stylized.is_empty() || stylized.len() != reference.len() || stylized.len() != channels * n {
        return None;
    }
    let count = covered.iter().filter(|&&c| c).count();
    if count == 0 {
        return None;
    }
    let (mut sq, mut energy) = (0.0f64, 0.0f64);
    for ch in 0..channels {
        let rows = stylized[ch * n..(ch + 1) * n].iter().zip(&reference[ch * n..(ch + 1) * n]);
        for ((&s, &r), _) in rows.zip(covered).filter(|(_, c)| **c) {
            sq += (f64::from(s) - f64::from(r)).powi(2);
            energy += f64::from(r).powi(2);
        }
    }
    let mse = (sq / (channels * count) as f64) as f32;
    let relative = if energy > 0.0 { (sq / energy) as f32 } else { 0.0 };
    Some(ContentDistance { mse, relative })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_distance_of_known_maps() {
        let r = [1.0f32, 2.0, 0.0, 2.0];
        let same = content_distance(&r, &r).expect("same shape");
        assert_eq!(same, ContentDistance { mse: 0.0, relative: 0.0 });
        // Differences (1, 0, 1, 0): mse = 2/4, energy = 1 + 4 + 0 + 4 = 9.
        let d = content_distance(&[2.0, 2.0, 1.0, 2.0], &r).expect("same shape");
        assert!((d.mse - 0.5).abs() < 1e-7);
        assert!((d.relative - 2.0 / 9.0).abs() < 1e-7);
        // Scaling both maps scales mse by k² but leaves the relative distance alone.
        let k = 3.0f32;
        let scaled = content_distance(&[2.0 * k, 2.0 * k, k, 2.0 * k], &r.map(|v| v * k)).expect("same shape");
        assert!((scaled.mse - 0.5 * k * k).abs() < 1e-5);
        assert!((scaled.relative - d.relative).abs() < 1e-6);
    }

    #[test]
    fn the_masked_distance_ignores_uncovered_positions() {
        // 2 channels × 4 positions, channel-major.
        let r = [1.0f32, 2.0, 0.5, 3.0, 0.0, 1.0, 2.0, 1.0];
        let s = [1.5f32, 2.0, 0.0, 4.0, 1.0, 1.0, 2.5, 0.0];
        let all = content_distance_masked(&s, &r, 2, &[true; 4]).expect("all covered");
        assert_eq!(Some(all), content_distance(&s, &r), "a mask of all ones is the unmasked distance");
        // Positions 1 and 3 uncovered: whatever they hold, the distance is that of positions 0 and 2.
        let covered = [true, false, true, false];
        let d = content_distance_masked(&s, &r, 2, &covered).expect("covered");
        let mut s2 = s;
        for k in [1, 3, 5, 7] {
            s2[k] = 100.0 + k as f32;
        }
        assert_eq!(content_distance_masked(&s2, &r, 2, &covered), Some(d));
        // Differences at positions 0 and 2: (0.5, 0.5) in channel 0, (1, 0.5) in channel 1.
        let sq = 0.25 + 0.25 + 1.0 + 0.25;
        assert!((d.mse - sq / 4.0).abs() < 1e-6, "{d:?}");
        assert!((d.relative - sq / (1.0 + 0.25 + 0.0 + 4.0)).abs() < 1e-6, "{d:?}");
        // Nothing covered, or a mask of the wrong size: no distance.
        assert_eq!(content_distance_masked(&s, &r, 2, &[false; 4]), None);
        assert_eq!(content_distance_masked(&s, &r, 2, &[true; 3]), None);
    }

    #[test]
    fn mismatched_or_empty_maps_have_no_distance() {
        assert_eq!(content_distance(&[], &[]), None);
        assert_eq!(content_distance(&[1.0], &[1.0, 2.0]), None);
        assert_eq!(content_distance(&[1.0], &[0.0]), Some(ContentDistance { mse: 1.0, relative: 0.0 }));
    }
}
