//! The tiled backward pass.
//!
//! 1. Per tile, in parallel, each pixel walks its list back to front from its
//!    last composited splat, recovering `T_i = T_{i+1} / (1 − α_i)` and the
//!    colour and depth behind each splat, as the 3DGS CUDA kernel does. The
//!    gradient of each (tile, splat) pair goes to its own slot, so no two
//!    threads write the same memory.
//! 2. The pair slots are summed per splat.
//! 3. Per Gaussian, in parallel, the projection's backward turns the splat
//!    gradient into parameter gradients.

use rayon::prelude::*;

use super::forward::{TILE_PX, gaussian_ref};
use super::project::{ALPHA_MAX, CamConsts, GaussianGrad, SplatGrad, project_backward};
use super::state::ForwardState;
use super::{Grads, RenderOptions, TILE};
use crate::camera::Camera;
use crate::scene::Gaussians;

/// Gradients of a loss `L(rgb, inv_depth)` w.r.t. every Gaussian parameter,
/// given `v_rgb = ∂L/∂rgb` (`H·W·3`) and `v_inv_depth = ∂L/∂inv_depth` (`H·W`),
/// and the state of the [`super::forward`] call with the same inputs.
///
/// # Panics
/// When the cotangents or the state do not match the camera's image size.
pub fn backward(
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    state: &ForwardState,
    v_rgb: &[f32],
    v_inv_depth: &[f32],
) -> Grads {
    let npx = cam.width as usize * cam.height as usize;
    assert!(
        state.width == cam.width && state.height == cam.height,
        "raster::backward: state is for {}×{}, camera is {}×{}",
        state.width,
        state.height,
        cam.width,
        cam.height
    );
    assert_eq!(v_rgb.len(), 3 * npx, "raster::backward: v_rgb length");
    assert_eq!(v_inv_depth.len(), npx, "raster::backward: v_inv_depth length");

    // 1. Per-pair gradients, one disjoint slice per tile.
    let mut pair_grads: Vec<SplatGrad> = vec![[0.0; 10]; state.tile_list.len()];
    let n_tiles = state.tile_starts.len() - 1;
    let mut slices = Vec::with_capacity(n_tiles);
    let mut rest = pair_grads.as_mut_slice();
    for t in 0..n_tiles {
        let (a, b) = rest.split_at_mut(state.tile_range(t).len());
        slices.push(a);
        rest = b;
    }
    let ctx = TileCtx { state, v_rgb, v_inv_depth, bg: opts.background };
    slices.into_par_iter().enumerate().for_each(|(t, dst)| ctx.tile(t, dst));

    // 2. Sum per splat.
    let mut splat_grads: Vec<SplatGrad> = vec![[0.0; 10]; state.splats.len()];
    for (pg, &si) in pair_grads.iter().zip(&state.tile_list) {
        let sg = &mut splat_grads[si as usize];
        for k in 0..10 {
            sg[k] += pg[k];
        }
    }
    drop(pair_grads);

    // 3. Per Gaussian.
    let mut slot = vec![u32::MAX; g.len()];
    for (k, &i) in state.ids.iter().enumerate() {
        slot[i as usize] = k as u32;
    }
    let cc = CamConsts::new(cam);
    let mut out = Grads::zeros_like(g);
    let ksh = g.sh_coeffs() * 3;
    (
        out.v_means.par_iter_mut(),
        out.v_log_scales.par_iter_mut(),
        out.v_quats.par_iter_mut(),
        out.v_opacity_logits.par_iter_mut(),
        out.v_sh.par_chunks_mut(ksh),
    )
        .into_par_iter()
        .with_min_len(1024)
        .enumerate()
        .for_each(|(i, (v_mean, v_log_scale, v_quat, v_opacity_logit, v_sh))| {
            let k = slot[i];
            if k == u32::MAX {
                return;
            }
            let grad = GaussianGrad { v_mean, v_log_scale, v_quat, v_opacity_logit, v_sh };
            project_backward(&gaussian_ref(g, i), &cc, &splat_grads[k as usize], grad);
        });
    out
}

/// What every tile's backward reads.
struct TileCtx<'a> {
    state: &'a ForwardState,
    v_rgb: &'a [f32],
    v_inv_depth: &'a [f32],
    bg: [f32; 3],
}

impl TileCtx<'_> {
    /// Backward of one tile; `dst[k]` receives the gradient of the tile's
    /// `k`-th splat from this tile's pixels.
    fn tile(&self, t: usize, dst: &mut [SplatGrad]) {
        let st = self.state;
        let (w, h) = (st.width, st.height);
        let (x0, y0) = ((t as u32 % st.tiles_x) * TILE, (t as u32 / st.tiles_x) * TILE);
        let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
        let list = &st.tile_list[st.tile_range(t)];

        // Per pixel: transmittance, colour and depth behind the current splat,
        // the pixel's cotangents and its list length.
        let mut tr = [0.0f32; TILE_PX];
        let mut behind = [[0.0f32; 4]; TILE_PX];
        let mut cot = [[0.0f32; 4]; TILE_PX];
        let mut nc = [0u32; TILE_PX];
        let mut max_nc = 0;
        for y in y0..y1 {
            for x in x0..x1 {
                let p = ((y - y0) * TILE + (x - x0)) as usize;
                let q = y as usize * w as usize + x as usize;
                tr[p] = st.final_t[q];
                behind[p] = [self.bg[0], self.bg[1], self.bg[2], 0.0];
                cot[p] = [self.v_rgb[3 * q], self.v_rgb[3 * q + 1], self.v_rgb[3 * q + 2], self.v_inv_depth[q]];
                nc[p] = st.n_contrib[q];
                max_nc = max_nc.max(nc[p]);
            }
        }

        for k in (0..max_nc as usize).rev() {
            let s = &st.splats[list[k] as usize];
            let feat = [s.color[0], s.color[1], s.color[2], s.inv_z];
            let [ca, cb, cc] = s.conic;
            let mut acc: SplatGrad = [0.0; 10];
            let (ja, jb, ia, ib) = s.pixel_rect(x0, x1, y0, y1);
            for i in ia..=ib {
                let row = (i as u32 - y0) * TILE;
                for j in ja..=jb {
                    let p = (row + (j as u32 - x0)) as usize;
                    if k as u32 >= nc[p] {
                        continue;
                    }
                    let Some((alpha, gauss, dx, dy)) = s.eval(j as f32 + 0.5, i as f32 + 0.5) else { continue };
                    let t_i = tr[p] / (1.0 - alpha);
                    let wgt = alpha * t_i;
                    let mut v_alpha = 0.0;
                    for c in 0..4 {
                        acc[6 + c] += wgt * cot[p][c];
                        v_alpha += (feat[c] - behind[p][c]) * cot[p][c];
                        behind[p][c] = alpha * feat[c] + (1.0 - alpha) * behind[p][c];
                    }
                    v_alpha *= t_i;
                    tr[p] = t_i;
                    if s.opacity * gauss <= ALPHA_MAX {
                        acc[5] += v_alpha * gauss;
                        let v_power = v_alpha * alpha;
                        acc[2] += -0.5 * v_power * dx * dx;
                        acc[3] += -v_power * dx * dy;
                        acc[4] += -0.5 * v_power * dy * dy;
                        acc[0] += v_power * (ca * dx + cb * dy);
                        acc[1] += v_power * (cb * dx + cc * dy);
                    }
                }
            }
            dst[k] = acc;
        }
    }
}
