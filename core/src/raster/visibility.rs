//! Which Gaussians a camera actually shows: those composited into at least
//! one pixel with α ≥ 1/255 before the pixel's transmittance ran out. The
//! optimiser leaves the others out (a Gaussian no camera shows gets no
//! gradient and only costs time and memory); the export keeps them.

use super::forward::forward_shown;
use super::{Render, RenderOptions};
use crate::camera::Camera;
use crate::scene::Gaussians;

/// For each Gaussian of `g`, whether `cam` composites it into some pixel.
pub fn contributing(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Vec<bool> {
    render_and_contributing(g, cam, opts).1
}

/// The render of `g` from `cam` and, for each Gaussian, whether it was
/// composited into some pixel: one forward pass for both, the tiles noting
/// the splats they composite (before, a second pass over every tile's list
/// asked each splat again: two fifths of the survey's time on a scene of
/// two million Gaussians).
pub fn render_and_contributing(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> (Render, Vec<bool>) {
    let (img, _, shown) = forward_shown(g, cam, opts);
    (img, shown)
}

#[cfg(test)]
mod tests {
    use super::super::{TILE, forward};
    use super::*;
    use glam::{Mat3, Vec3};
    use rayon::prelude::*;

    /// The marks as a second pass over every tile's list found them (the
    /// code before the tiles noted them as they composite): the oracle.
    fn shown_by_a_second_pass(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Vec<bool> {
        let (_, st) = forward(g, cam, opts);
        let (w, h) = (st.width, st.height);
        let n_tiles = st.tile_starts.len().saturating_sub(1);
        let shown: Vec<Vec<u32>> = (0..n_tiles)
            .into_par_iter()
            .map(|t| {
                let (x0, y0) = ((t as u32 % st.tiles_x) * TILE, (t as u32 / st.tiles_x) * TILE);
                let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
                let list = &st.tile_list[st.tile_range(t)];
                let mut out = Vec::new();
                let mut falloff = [0.0f32; TILE as usize];
                for (k, &si) in list.iter().enumerate() {
                    let s = &st.splats[si as usize];
                    let (_, _, ia, ib) = s.pixel_rect(x0, x1, y0, y1);
                    let mut seen = false;
                    for i in ia..=ib {
                        let (ja, jb) = s.row_span(i, x0, x1);
                        if ja > jb {
                            continue;
                        }
                        let (la, lb) = ((ja as u32 - x0) as usize, (jb as u32 - x0) as usize);
                        s.falloff_row(x0 as f32 + 0.5, i as f32 + 0.5, la, lb, &mut falloff);
                        let row = i as usize * w as usize + x0 as usize;
                        seen = (la..=lb).any(|l| (k as u32) < st.n_contrib[row + l] && s.alpha(falloff[l]).is_some());
                        if seen {
                            break;
                        }
                    }
                    if seen {
                        out.push(st.ids[si as usize]);
                    }
                }
                out
            })
            .collect();
        let mut mask = vec![false; g.len()];
        for id in shown.into_iter().flatten() {
            mask[id as usize] = true;
        }
        mask
    }

    fn cam() -> Camera {
        Camera {
            name: "test".into(),
            width: 40,
            height: 32,
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 16.0,
            rotation: Mat3::IDENTITY,
            translation: Vec3::ZERO,
        }
    }

    fn push(g: &mut Gaussians, mean: [f32; 3], log_scale: f32, opacity_logit: f32) {
        g.means.push(mean);
        g.log_scales.push([log_scale; 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(opacity_logit);
        g.sh.extend_from_slice(&[0.5, 0.2, 0.1]);
    }

    #[test]
    fn hidden_transparent_and_outside_gaussians_are_not_shown() {
        let mut g = Gaussians::with_capacity(6, 0);
        push(&mut g, [0.0, 0.0, 2.0], 0.5, 9.0); // 0: large, opaque, in front: shown
        push(&mut g, [0.0, 0.0, 4.0], -2.0, 3.0); // 1: small, behind 0, 6 and 7: hidden (T < 1e-4)
        push(&mut g, [0.3, 0.2, 3.0], -2.5, -12.0); // 2: opacity ~6e-6 < 1/255: never shown
        push(&mut g, [50.0, 0.0, 2.0], -2.0, 3.0); // 3: far outside the frustum
        push(&mut g, [0.0, 0.0, -2.0], -2.0, 3.0); // 4: behind the camera
        push(&mut g, [0.9, 0.7, 3.0], -3.0, 2.0); // 5: in the corner, clear of the others: shown
        // α is clamped to 0.99, so one opaque layer leaves T = 0.01: two more
        // (6, 7) bring T to 1e-6 < 1e-4 in front of Gaussian 1.
        push(&mut g, [0.0, 0.0, 2.3], 0.5, 9.0);
        push(&mut g, [0.0, 0.0, 2.6], 0.5, 9.0);
        let shown = contributing(&g, &cam(), &RenderOptions::default());
        assert_eq!(shown, vec![true, false, false, false, false, true, true, true]);
    }

    /// `n` overlapping Gaussians in front of the test camera, from `seed`:
    /// log scales `lo + rnd·span` with `(lo, span)` = `scales`, opacity logits
    /// likewise from `opacities`.
    fn overlapping(n: usize, seed: u32, scales: (f32, f32), opacities: (f32, f32)) -> Gaussians {
        let mut g = Gaussians::with_capacity(n, 0);
        let mut s = seed;
        let mut rnd = || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..n {
            let m = [rnd() * 2.4 - 1.2, rnd() * 2.0 - 1.0, 1.5 + rnd() * 3.0];
            push(&mut g, m, scales.0 + rnd() * scales.1, opacities.0 + rnd() * opacities.1);
        }
        g
    }

    #[test]
    fn every_gaussian_with_a_gradient_is_shown() {
        // A Gaussian that receives any gradient must be marked: compare with
        // the backward pass on a random scene with overlap.
        let g = overlapping(200, 1, (-3.0, 2.0), (-5.0, 8.0));
        let c = cam();
        let opts = RenderOptions::default();
        let shown = contributing(&g, &c, &opts);
        let (img, st) = forward(&g, &c, &opts);
        let ones = vec![1.0f32; img.rgb.len()];
        let grads = super::super::backward(&g, &c, &opts, &st, &ones, &vec![0.0; img.inv_depth.len()]);
        for (i, &s) in shown.iter().enumerate() {
            let has_grad = grads.v_sh[3 * i] != 0.0;
            assert!(!has_grad || s, "Gaussian {i} has a colour gradient but is not marked shown");
        }
        let n = shown.iter().filter(|&&x| x).count();
        assert!(n > 20 && n < 200, "{n} of 200 shown");
    }

    /// The marks the tiles note as they composite are the second pass's, on
    /// the random scene of overlapping Gaussians and on guitar's orbit (the
    /// render the same to the bit as `forward`'s).
    #[test]
    fn the_tiles_marks_are_the_second_passs() {
        let g = overlapping(300, 7, (-3.5, 3.0), (-5.0, 10.0));
        let opts = RenderOptions::default();
        assert_eq!(contributing(&g, &cam(), &opts), shown_by_a_second_pass(&g, &cam(), &opts));
        let Some(path) = crate::vision::weights::tests::shared("data/scenes/guitar.compressed.ply") else { return };
        let guitar = crate::scene::load(&path).expect("guitar");
        let orbit = crate::camera::OrbitOptions { count: 4, width: 160, height: 120, ..Default::default() };
        for c in crate::camera::orbit_cameras(&guitar.means, &orbit) {
            let (img, shown) = render_and_contributing(&guitar, &c, &opts);
            assert_eq!(shown, shown_by_a_second_pass(&guitar, &c, &opts));
            assert_eq!(img.rgb, forward(&guitar, &c, &opts).0.rgb);
            let n = shown.iter().filter(|&&x| x).count();
            assert!(n > 1_000 && n < guitar.len(), "{n} of {} shown", guitar.len());
        }
    }
}
