//! The tiled forward pass: project, sort by depth, bin into tiles, composite.

use rayon::prelude::*;

use super::project::{CamConsts, GaussianRef, Splat, T_MIN, project};
use super::state::ForwardState;
use super::{Render, RenderOptions, TILE};
use crate::camera::Camera;
use crate::scene::Gaussians;

/// Pixels per tile.
pub(crate) const TILE_PX: usize = (TILE * TILE) as usize;

/// Renders the Gaussians from a camera, forward only (the viewer and export
/// path). The same image as [`forward`], without keeping the saved state.
pub fn render(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Render {
    forward(g, cam, opts).0
}

/// Renders the Gaussians and returns the state [`super::backward`] needs.
///
/// # Panics
/// When the arrays of `g` are inconsistent (a caller bug).
pub fn forward(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> (Render, ForwardState) {
    if let Err(e) = g.check_consistent() {
        panic!("raster::forward: {e}");
    }
    let cc = CamConsts::new(cam);
    let (splats, ids) = project_all(g, &cc);
    let tiles_x = cam.width.div_ceil(TILE);
    let tiles_y = cam.height.div_ceil(TILE);
    let (tile_starts, tile_list) = bin(&splats, cam.width, cam.height, tiles_x, tiles_y);

    let n_tiles = (tiles_x * tiles_y) as usize;
    let outs: Vec<TileOut> = (0..n_tiles)
        .into_par_iter()
        .map(|t| {
            let list = &tile_list[tile_starts[t] as usize..tile_starts[t + 1] as usize];
            composite_tile(t as u32, tiles_x, cam.width, cam.height, &splats, list)
        })
        .collect();

    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut out = Render::zeros(cam.width, cam.height);
    let mut final_t = vec![1.0f32; w * h];
    let mut n_contrib = vec![0u32; w * h];
    let bg = opts.background;
    for (t, o) in outs.iter().enumerate() {
        let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
        for ly in 0..TILE.min(cam.height - y0) {
            for lx in 0..TILE.min(cam.width - x0) {
                let p = (ly * TILE + lx) as usize;
                let q = (y0 + ly) as usize * w + (x0 + lx) as usize;
                let tf = o.t[p];
                for c in 0..3 {
                    out.rgb[3 * q + c] = o.rgb[3 * p + c] + tf * bg[c];
                }
                out.inv_depth[q] = o.inv_depth[p];
                out.alpha[q] = 1.0 - tf;
                final_t[q] = tf;
                n_contrib[q] = o.n_contrib[p];
            }
        }
    }
    let state = ForwardState {
        width: cam.width,
        height: cam.height,
        tiles_x,
        splats,
        ids,
        tile_starts,
        tile_list,
        final_t,
        n_contrib,
    };
    (out, state)
}

/// One Gaussian's parameters by index.
pub(crate) fn gaussian_ref(g: &Gaussians, i: usize) -> GaussianRef<'_> {
    GaussianRef {
        mean: g.means[i],
        log_scale: g.log_scales[i],
        quat: g.quats[i],
        opacity_logit: g.opacity_logits[i],
        sh: g.sh_of(i),
        deg: g.sh_degree,
    }
}

/// Projects every Gaussian in parallel, keeping those that can touch a pixel.
fn project_all(g: &Gaussians, cc: &CamConsts) -> (Vec<Splat>, Vec<u32>) {
    let kept: Vec<(u32, Splat)> = (0..g.len())
        .into_par_iter()
        .with_min_len(1024)
        .filter_map(|i| project(&gaussian_ref(g, i), cc).map(|s| (i as u32, s)))
        .collect();
    kept.into_iter().map(|(i, s)| (s, i)).unzip()
}

/// Whether the ellipse `power ≥ −cut` of a splat reaches a pixel centre in the
/// pixel rectangle `[x0, x1) × [y0, y1)` (conservatively).
fn touches_rect(s: &Splat, x0: u32, x1: u32, y0: u32, y1: u32) -> bool {
    let (xa, xb) = (x0 as f32 + 0.5 - s.xy[0], x1 as f32 - 0.5 - s.xy[0]);
    let (ya, yb) = (y0 as f32 + 0.5 - s.xy[1], y1 as f32 - 0.5 - s.xy[1]);
    if xa <= 0.0 && xb >= 0.0 && ya <= 0.0 && yb >= 0.0 {
        return true;
    }
    let [a, b, c] = s.conic;
    let q = |dx: f32, dy: f32| a * dx * dx + 2.0 * b * dx * dy + c * dy * dy;
    let on_x_edge = |dx: f32| q(dx, (-b * dx / c).clamp(ya, yb));
    let on_y_edge = |dy: f32| q((-b * dy / a).clamp(xa, xb), dy);
    let m = on_x_edge(xa).min(on_x_edge(xb)).min(on_y_edge(ya)).min(on_y_edge(yb));
    m <= 2.0 * (s.cut + 2e-3) * 1.001
}

/// Calls `f(tile)` for every tile the splat's α ≥ 1/255 region reaches.
#[inline]
fn for_each_tile(s: &Splat, w: u32, h: u32, tiles_x: u32, mut f: impl FnMut(usize)) {
    let (ja, jb, ia, ib) = s.pixel_rect(0, w, 0, h);
    if ja > jb || ia > ib {
        return;
    }
    let (tx0, tx1) = (ja as u32 / TILE, jb as u32 / TILE);
    let (ty0, ty1) = (ia as u32 / TILE, ib as u32 / TILE);
    let single = tx0 == tx1 && ty0 == ty1;
    for ty in ty0..=ty1 {
        for tx in tx0..=tx1 {
            let (x0, y0) = (tx * TILE, ty * TILE);
            if single || touches_rect(s, x0, (x0 + TILE).min(w), y0, (y0 + TILE).min(h)) {
                f((ty * tiles_x + tx) as usize);
            }
        }
    }
}

/// Sorts the splats by depth and lists, for every tile, the splats that reach
/// it, front to back. Returns `(tile_starts, tile_list)`.
fn bin(splats: &[Splat], w: u32, h: u32, tiles_x: u32, tiles_y: u32) -> (Vec<u32>, Vec<u32>) {
    let n_tiles = (tiles_x * tiles_y) as usize;
    // Depth is positive, so its bits order like the float; ties go by index.
    let mut keys: Vec<u64> =
        splats.par_iter().enumerate().map(|(k, s)| (u64::from(s.depth.to_bits()) << 32) | k as u64).collect();
    keys.par_sort_unstable();

    // Each chunk of the depth order makes its own per-tile lists (a counting
    // sort), then every tile concatenates its pieces chunk by chunk.
    let chunk = keys.len().div_ceil(rayon::current_num_threads() * 4).max(4096);
    let pieces: Vec<(Vec<u32>, Vec<u32>)> = keys
        .par_chunks(chunk)
        .map(|ks| {
            let mut starts = vec![0u32; n_tiles + 1];
            for &k in ks {
                for_each_tile(&splats[(k & 0xffff_ffff) as usize], w, h, tiles_x, |t| starts[t + 1] += 1);
            }
            for t in 0..n_tiles {
                starts[t + 1] += starts[t];
            }
            let mut fill = starts.clone();
            let mut list = vec![0u32; starts[n_tiles] as usize];
            for &k in ks {
                let idx = (k & 0xffff_ffff) as u32;
                for_each_tile(&splats[idx as usize], w, h, tiles_x, |t| {
                    list[fill[t] as usize] = idx;
                    fill[t] += 1;
                });
            }
            (starts, list)
        })
        .collect();

    let mut tile_starts = vec![0u32; n_tiles + 1];
    for t in 0..n_tiles {
        let n: u32 = pieces.iter().map(|(s, _)| s[t + 1] - s[t]).sum();
        tile_starts[t + 1] = tile_starts[t] + n;
    }
    let mut tile_list = vec![0u32; tile_starts[n_tiles] as usize];
    let mut slices = Vec::with_capacity(n_tiles);
    let mut rest = tile_list.as_mut_slice();
    for t in 0..n_tiles {
        let (a, b) = rest.split_at_mut((tile_starts[t + 1] - tile_starts[t]) as usize);
        slices.push(a);
        rest = b;
    }
    slices.into_par_iter().enumerate().for_each(|(t, dst)| {
        let mut at = 0;
        for (s, l) in &pieces {
            let src = &l[s[t] as usize..s[t + 1] as usize];
            dst[at..at + src.len()].copy_from_slice(src);
            at += src.len();
        }
    });
    (tile_starts, tile_list)
}

/// One tile's composited pixels (local row-major, `TILE` wide).
struct TileOut {
    rgb: [f32; 3 * TILE_PX],
    inv_depth: [f32; TILE_PX],
    t: [f32; TILE_PX],
    n_contrib: [u32; TILE_PX],
}

/// Composites one tile front to back, splat-major: each splat visits only the
/// pixels of its extent that are not finished yet.
fn composite_tile(tile: u32, tiles_x: u32, w: u32, h: u32, splats: &[Splat], list: &[u32]) -> TileOut {
    let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
    let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
    let mut o = TileOut { rgb: [0.0; 3 * TILE_PX], inv_depth: [0.0; TILE_PX], t: [1.0; TILE_PX], n_contrib: [0; TILE_PX] };
    let mut done = [false; TILE_PX];
    let mut remaining = (x1 - x0) * (y1 - y0);
    for (k, &si) in list.iter().enumerate() {
        let s = &splats[si as usize];
        let (ja, jb, ia, ib) = s.pixel_rect(x0, x1, y0, y1);
        for i in ia..=ib {
            let row = (i as u32 - y0) * TILE;
            for j in ja..=jb {
                let p = (row + (j as u32 - x0)) as usize;
                if done[p] {
                    continue;
                }
                let Some((alpha, ..)) = s.eval(j as f32 + 0.5, i as f32 + 0.5) else { continue };
                let test_t = o.t[p] * (1.0 - alpha);
                if test_t < T_MIN {
                    done[p] = true;
                    remaining -= 1;
                    continue;
                }
                let wgt = alpha * o.t[p];
                for c in 0..3 {
                    o.rgb[3 * p + c] += wgt * s.color[c];
                }
                o.inv_depth[p] += wgt * s.inv_z;
                o.t[p] = test_t;
                o.n_contrib[p] = k as u32 + 1;
            }
        }
        if remaining == 0 {
            break;
        }
    }
    o
}
