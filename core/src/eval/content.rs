//! Content preservation: how far the stylized render's features moved from
//! those of the colour-matched render of the same view.
//!
//! The absolute measure is the content loss of the optimisation itself
//! (ALGORITHM.md), so a report and the training curve speak the same units;
//! the relative one divides by the reference's feature energy so that scenes
//! and resolutions with stronger activations can be compared.

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
    fn mismatched_or_empty_maps_have_no_distance() {
        assert_eq!(content_distance(&[], &[]), None);
        assert_eq!(content_distance(&[1.0], &[1.0, 2.0]), None);
        assert_eq!(content_distance(&[1.0], &[0.0]), Some(ContentDistance { mse: 1.0, relative: 0.0 }));
    }
}
