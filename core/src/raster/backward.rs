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

use super::forward::{TILE_PX, gaussian_ref, span_mask};
use super::project::{CamConsts, GaussianGrad, SplatGrad, project_backward};
use super::splat::{ALPHA_MAX, LANE};
use super::state::{ForwardState, split_by_tile};
use super::{Grads, RenderOptions, ShGrads, TILE};
use crate::camera::Camera;
use crate::scene::Gaussians;

/// Gradients of a loss `L(rgb, inv_depth)` w.r.t. every Gaussian parameter,
/// given `v_rgb = ∂L/∂rgb` (`H·W·3`) and `v_inv_depth = ∂L/∂inv_depth` (`H·W`),
/// and the state of the [`super::forward()`] call with the same inputs.
///
/// # Panics
/// When the arrays of `g` are inconsistent, or the cotangents or the state do
/// not match the camera's image size and the Gaussians (caller bugs).
pub fn backward(
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    state: &ForwardState,
    v_rgb: &[f32],
    v_inv_depth: &[f32],
) -> Grads {
    backward_sh(g, cam, opts, state, v_rgb, v_inv_depth, ShGrads::All)
}

/// [`backward`] with the gradients of the SH coefficients `sh` only (the
/// others' are the same as [`backward`]'s, to the bit).
///
/// # Panics
/// As [`backward`].
pub fn backward_sh(
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    state: &ForwardState,
    v_rgb: &[f32],
    v_inv_depth: &[f32],
    sh: ShGrads,
) -> Grads {
    if let Err(e) = g.check_consistent() {
        panic!("raster::backward: {e}");
    }
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
    let ctx = TileCtx { state, v_rgb, v_inv_depth, bg: opts.background };
    split_by_tile(&mut pair_grads, &state.tile_starts)
        .into_par_iter()
        .enumerate()
        .for_each(|(t, dst)| ctx.tile(t, dst));

    // 2. Sum per splat.
    let mut splat_grads: Vec<SplatGrad> = vec![[0.0; 10]; state.splats.len()];
    for (pg, &si) in pair_grads.iter().zip(&state.tile_list) {
        let sg = &mut splat_grads[si as usize];
        for k in 0..10 {
            sg[k] += pg[k];
        }
    }
    drop(pair_grads);

    // 3. Per Gaussian, for the splats that received a gradient (the others
    // are hidden behind others), in Gaussian order.
    if let Some(&i) = state.ids.iter().find(|&&i| i as usize >= g.len()) {
        panic!("raster::backward: the state holds Gaussian {i}, only {} are given", g.len());
    }
    let cc = CamConsts::new(cam);
    let ksh = sh.coefficients(g) * 3;
    let mut contributing: Vec<(u32, u32)> = (0..state.splats.len())
        .into_par_iter()
        .with_min_len(1024)
        .filter(|&k| splat_grads[k] != [0.0; 10])
        .map(|k| (state.ids[k], k as u32))
        .collect();
    contributing.par_sort_unstable();
    let mut out = Grads::zeros_for(g, sh);
    // Chunks of Gaussians in parallel, each writing its own slices (empty
    // SH slices where no coefficient is asked).
    const CHUNK: usize = 4096;
    let v_sh: Vec<&mut [f32]> = if ksh == 0 {
        (0..g.len().div_ceil(CHUNK)).map(|_| &mut [][..]).collect()
    } else {
        out.v_sh.chunks_mut(CHUNK * ksh).collect()
    };
    (
        out.v_means.par_chunks_mut(CHUNK),
        out.v_log_scales.par_chunks_mut(CHUNK),
        out.v_quats.par_chunks_mut(CHUNK),
        out.v_opacity_logits.par_chunks_mut(CHUNK),
        v_sh,
    )
        .into_par_iter()
        .enumerate()
        .for_each(|(c, (v_means, v_log_scales, v_quats, v_opacity_logits, v_sh))| {
            let (lo, hi) = (c * CHUNK, c * CHUNK + v_means.len());
            let first = contributing.partition_point(|&(i, _)| (i as usize) < lo);
            for &(i, k) in contributing[first..].iter().take_while(|&&(i, _)| (i as usize) < hi) {
                let j = i as usize - lo;
                let grad = GaussianGrad {
                    v_mean: &mut v_means[j],
                    v_log_scale: &mut v_log_scales[j],
                    v_quat: &mut v_quats[j],
                    v_opacity_logit: &mut v_opacity_logits[j],
                    v_sh: &mut v_sh[j * ksh..(j + 1) * ksh],
                };
                project_backward(&gaussian_ref(g, i as usize), &cc, &splat_grads[k as usize], grad);
            }
        });
    out
}

/// One pixel's state walking back to front.
#[derive(Clone, Copy)]
struct Px {
    /// Transmittance in front of the current splat once it is divided out.
    t: f32,
    /// Colour and inverse depth seen behind the current splat, per unit transmittance.
    behind: [f32; 4],
    /// `∂L/∂rgb` and `∂L/∂inv_depth` of the pixel.
    cot: [f32; 4],
    /// The pixel's list length from the forward pass.
    n_contrib: u32,
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
    #[inline(never)]
    fn tile(&self, t: usize, dst: &mut [SplatGrad]) {
        let st = self.state;
        let (w, h) = (st.width, st.height);
        let (x0, y0) = ((t as u32 % st.tiles_x) * TILE, (t as u32 / st.tiles_x) * TILE);
        let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
        let list = &st.tile_list[st.tile_range(t)];

        // Per pixel: transmittance, colour and depth behind the current splat,
        // the pixel's cotangents and its list length.
        let mut px = [Px { t: 0.0, behind: [0.0; 4], cot: [0.0; 4], n_contrib: 0 }; TILE_PX];
        let mut max_nc = 0;
        for y in y0..y1 {
            for x in x0..x1 {
                let q = y as usize * w as usize + x as usize;
                let p = &mut px[((y - y0) * TILE + (x - x0)) as usize];
                p.t = st.final_t[q];
                p.behind = [self.bg[0], self.bg[1], self.bg[2], 0.0];
                p.cot = [self.v_rgb[3 * q], self.v_rgb[3 * q + 1], self.v_rgb[3 * q + 2], self.v_inv_depth[q]];
                p.n_contrib = st.n_contrib[q];
                max_nc = max_nc.max(p.n_contrib);
            }
        }

        // Pixels by decreasing list length: walking back, pixel p joins when
        // k drops below its n_contrib. Bit j of active[ly] marks the joined ones.
        let mut order = [(0u32, 0u16); TILE_PX];
        let mut n_px = 0;
        for (p, q) in px.iter().enumerate() {
            if q.n_contrib > 0 {
                order[n_px] = (q.n_contrib, p as u16);
                n_px += 1;
            }
        }
        let order = &mut order[..n_px];
        order.sort_unstable_by_key(|&(nc, _)| std::cmp::Reverse(nc));
        let mut joined = 0;
        let mut active = [0u32; TILE as usize];

        let mut falloff = [0.0f32; TILE as usize];
        for k in (0..max_nc as usize).rev() {
            while joined < order.len() && order[joined].0 as usize > k {
                let p = order[joined].1 as usize;
                active[p / TILE as usize] |= 1 << (p % TILE as usize);
                joined += 1;
            }
            let s = &st.splats[list[k] as usize];
            let feat = [s.color[0], s.color[1], s.color[2], s.inv_z];
            let [ca, cb, cc] = s.conic;
            // ∂L/∂(x, y), ∂L/∂(A, B, C), ∂L/∂opacity, ∂L/∂(r, g, b, inv_z).
            let (mut v_xy, mut v_conic, mut v_op, mut v_feat) = ([0.0f32; 2], [0.0f32; 3], 0.0f32, [0.0f32; 4]);
            let (bja, bjb, ia, ib) = s.pixel_rect(x0, x1, y0, y1);
            let box_mask =
                if bja > bjb { 0 } else { span_mask((bja as u32 - x0) as usize, (bjb as u32 - x0) as usize) };
            for i in ia..=ib {
                let ly = (i as u32 - y0) as usize;
                if active[ly] & box_mask == 0 {
                    continue;
                }
                let (ja, jb) = s.row_span(i, x0, x1);
                if ja > jb {
                    continue;
                }
                let (ja, jb) = ((ja as u32 - x0) as usize, (jb as u32 - x0) as usize);
                let mut live = span_mask(ja, jb) & active[ly];
                if live == 0 {
                    continue;
                }
                let py = i as f32 + 0.5;
                s.falloff_row(x0 as f32 + 0.5, py, ja, jb, &mut falloff);
                let dy = py - s.xy[1];
                let dx0 = x0 as f32 + 0.5 - s.xy[0];
                let row = ly * TILE as usize;
                while live != 0 {
                    let j = live.trailing_zeros() as usize;
                    live &= live - 1;
                    let gauss = falloff[j];
                    let Some(alpha) = s.alpha(gauss) else { continue };
                    let dx = dx0 + LANE[j];
                    let p = &mut px[row + j];
                    let t_i = p.t / (1.0 - alpha);
                    let wgt = alpha * t_i;
                    let mut v_alpha = 0.0;
                    for (((vf, &f), b), &ct) in v_feat.iter_mut().zip(&feat).zip(p.behind.iter_mut()).zip(&p.cot) {
                        *vf += wgt * ct;
                        v_alpha += (f - *b) * ct;
                        *b = alpha * f + (1.0 - alpha) * *b;
                    }
                    v_alpha *= t_i;
                    p.t = t_i;
                    if s.opacity * gauss <= ALPHA_MAX {
                        v_op += v_alpha * gauss;
                        let v_power = v_alpha * alpha;
                        v_conic[0] += -0.5 * v_power * dx * dx;
                        v_conic[1] += -v_power * dx * dy;
                        v_conic[2] += -0.5 * v_power * dy * dy;
                        v_xy[0] += v_power * (ca * dx + cb * dy);
                        v_xy[1] += v_power * (cb * dx + cc * dy);
                    }
                }
            }
            let [x, y] = v_xy;
            let [a, b, c] = v_conic;
            let [r, g, bl, d] = v_feat;
            dst[k] = [x, y, a, b, c, v_op, r, g, bl, d];
        }
    }
}
