//! The tiled forward pass: project, sort by depth, bin into tiles, composite.

use rayon::prelude::*;

use super::project::{CamConsts, GaussianRef, project};
use super::splat::{Splat, T_MIN};
use super::state::{ForwardState, split_by_tile};
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

/// Renders the Gaussians and returns the state [`super::backward()`] needs.
///
/// # Panics
/// When the arrays of `g` are inconsistent (a caller bug).
pub fn forward(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> (Render, ForwardState) {
    let (render, state, _) = forward_marking::<false>(g, cam, opts);
    (render, state)
}

/// As [`forward`], and for each Gaussian whether it was composited into
/// some pixel (α ≥ 1/255 before the pixel's transmittance ran out), noted
/// as the tiles composite rather than in a second pass over them.
pub(crate) fn forward_shown(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> (Render, ForwardState, Vec<bool>) {
    forward_marking::<true>(g, cam, opts)
}

/// [`forward`]; with `MARK`, also the Gaussians composited (else an empty list).
fn forward_marking<const MARK: bool>(
    g: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
) -> (Render, ForwardState, Vec<bool>) {
    if let Err(e) = g.check_consistent() {
        panic!("raster::forward: {e}");
    }
    let cc = CamConsts::new(cam);
    let (splats, ids) = project_sorted(g, &cc);
    let tiles_x = cam.width.div_ceil(TILE);
    let tiles_y = cam.height.div_ceil(TILE);
    let (tile_starts, tile_list) = bin(&splats, cam.width, cam.height, tiles_x, tiles_y);

    let n_tiles = (tiles_x * tiles_y) as usize;
    let outs: Vec<TileOut> = (0..n_tiles)
        .into_par_iter()
        .map(|t| {
            let list = &tile_list[tile_starts[t] as usize..tile_starts[t + 1] as usize];
            composite_tile::<MARK>(t as u32, tiles_x, cam.width, cam.height, &splats, list)
        })
        .collect();
    let mut shown = Vec::new();
    if MARK {
        shown = vec![false; g.len()];
        for &si in outs.iter().flat_map(|o| &o.shown) {
            shown[ids[si as usize] as usize] = true;
        }
    }

    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut out = Render::zeros(cam.width, cam.height);
    let mut final_t = vec![1.0f32; w * h];
    let mut n_contrib = vec![0u32; w * h];
    let bg = opts.background;
    for (t, o) in outs.iter().enumerate() {
        let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
        for ly in 0..TILE.min(cam.height - y0) {
            for lx in 0..TILE.min(cam.width - x0) {
                let p = &o.px[(ly * TILE + lx) as usize];
                let q = (y0 + ly) as usize * w + (x0 + lx) as usize;
                for ((o, acc), bg) in out.rgb[3 * q..3 * q + 3].iter_mut().zip(p.acc).zip(bg) {
                    *o = acc + p.t * bg;
                }
                out.inv_depth[q] = p.acc[3];
                out.alpha[q] = 1.0 - p.t;
                final_t[q] = p.t;
                n_contrib[q] = p.n_contrib;
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
    (out, state, shown)
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

/// Projects every Gaussian in parallel, keeping those that can touch a pixel,
/// and returns them sorted front to back with their Gaussian indices.
///
/// Sorting the splats themselves (not a list of indices) makes every later
/// pass read them in order: the tile lists become increasing indices.
///
/// Every Gaussian's splat goes to its own slot of one array (a culled one's
/// depth 0, below the near plane), so the only list of unknown length is
/// the visible ones' sort keys: gathering splats of unknown count from the
/// threads grew and appended 64-byte vectors, most of the page faults of a
/// step on millions of Gaussians.
fn project_sorted(g: &Gaussians, cc: &CamConsts) -> (Vec<Splat>, Vec<u32>) {
    let mut all = Vec::new();
    (0..g.len())
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| project(&gaussian_ref(g, i), cc).unwrap_or_default())
        .collect_into_vec(&mut all);
    // Depth is positive, so its bits order like the float; ties go by index.
    let mut keys: Vec<u64> = all
        .par_iter()
        .with_min_len(1024)
        .enumerate()
        .filter(|(_, s)| s.depth > 0.0)
        .map(|(i, s)| (u64::from(s.depth.to_bits()) << 32) | i as u64)
        .collect();
    keys.par_sort_unstable();
    keys.par_iter().map(|&k| (k & 0xffff_ffff) as u32).map(|i| (all[i as usize], i)).unzip()
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
            if single || s.touches_rect(x0, (x0 + TILE).min(w), y0, (y0 + TILE).min(h)) {
                f((ty * tiles_x + tx) as usize);
            }
        }
    }
}

/// Lists, for every tile, the (depth-sorted) splats that reach it, front to
/// back. Returns `(tile_starts, tile_list)`.
fn bin(splats: &[Splat], w: u32, h: u32, tiles_x: u32, tiles_y: u32) -> (Vec<u32>, Vec<u32>) {
    let n_tiles = (tiles_x * tiles_y) as usize;
    // Each chunk of splats makes its own per-tile lists (a counting sort),
    // then every tile concatenates its pieces chunk by chunk.
    let chunk = splats.len().div_ceil(rayon::current_num_threads() * 4).max(4096);
    let pieces: Vec<(Vec<u32>, Vec<u32>)> = splats
        .par_chunks(chunk)
        .enumerate()
        .map(|(c, ss)| {
            let base = (c * chunk) as u32;
            // (tile, splat) pairs in depth order, then a counting sort by tile.
            let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(2 * ss.len());
            for (k, s) in ss.iter().enumerate() {
                for_each_tile(s, w, h, tiles_x, |t| pairs.push((t as u32, base + k as u32)));
            }
            let mut starts = vec![0u32; n_tiles + 1];
            for &(t, _) in &pairs {
                starts[t as usize + 1] += 1;
            }
            for t in 0..n_tiles {
                starts[t + 1] += starts[t];
            }
            let mut fill = starts.clone();
            let mut list = vec![0u32; pairs.len()];
            for &(t, idx) in &pairs {
                list[fill[t as usize] as usize] = idx;
                fill[t as usize] += 1;
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
    split_by_tile(&mut tile_list, &tile_starts).into_par_iter().enumerate().for_each(|(t, dst)| {
        let mut at = 0;
        for (s, l) in &pieces {
            let src = &l[s[t] as usize..s[t + 1] as usize];
            dst[at..at + src.len()].copy_from_slice(src);
            at += src.len();
        }
    });
    (tile_starts, tile_list)
}

/// One pixel's running compositing state.
#[derive(Clone, Copy)]
struct Px {
    /// Transmittance so far.
    t: f32,
    /// Colour and inverse depth accumulated so far.
    acc: [f32; 4],
    /// One past the list position of the last splat composited.
    n_contrib: u32,
}

/// One tile's composited pixels (local row-major, `TILE` wide).
struct TileOut {
    px: [Px; TILE_PX],
    /// The splats composited into some pixel of the tile, when asked (`MARK`).
    shown: Vec<u32>,
}

/// The bits `lo..=hi` of a tile row mask.
#[inline(always)]
pub(crate) fn span_mask(lo: usize, hi: usize) -> u32 {
    ((1u32 << (hi + 1)) - 1) & !((1u32 << lo) - 1)
}

/// Composites one tile front to back, splat-major: each splat visits only the
/// pixels of its ellipse, row by row, that are not finished yet (a bit mask
/// per tile row marks the finished ones, so saturated regions cost nothing).
/// With `MARK` it lists the splats it composited into some pixel.
#[inline(never)]
fn composite_tile<const MARK: bool>(
    tile: u32,
    tiles_x: u32,
    w: u32,
    h: u32,
    splats: &[Splat],
    list: &[u32],
) -> TileOut {
    let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
    let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
    let mut o = TileOut { px: [Px { t: 1.0, acc: [0.0; 4], n_contrib: 0 }; TILE_PX], shown: Vec::new() };
    // Bit j of done[ly]: the transmittance of pixel (ly, j) would have fallen below T_MIN.
    let mut done = [0u32; TILE as usize];
    let mut remaining = (x1 - x0) * (y1 - y0);
    let mut falloff = [0.0f32; TILE as usize];
    for (k, &si) in list.iter().enumerate() {
        let s = &splats[si as usize];
        let feat = [s.color[0], s.color[1], s.color[2], s.inv_z];
        let (bja, bjb, ia, ib) = s.pixel_rect(x0, x1, y0, y1);
        if bja > bjb {
            continue;
        }
        let box_mask = span_mask((bja as u32 - x0) as usize, (bjb as u32 - x0) as usize);
        let mut composited = false;
        for i in ia..=ib {
            let ly = (i as u32 - y0) as usize;
            if done[ly] & box_mask == box_mask {
                continue;
            }
            let (ja, jb) = s.row_span(i, x0, x1);
            if ja > jb {
                continue;
            }
            let (ja, jb) = ((ja as u32 - x0) as usize, (jb as u32 - x0) as usize);
            let mut live = span_mask(ja, jb) & !done[ly];
            if live == 0 {
                continue;
            }
            s.falloff_row(x0 as f32 + 0.5, i as f32 + 0.5, ja, jb, &mut falloff);
            let row = ly * TILE as usize;
            while live != 0 {
                let j = live.trailing_zeros() as usize;
                live &= live - 1;
                let Some(alpha) = s.alpha(falloff[j]) else { continue };
                let p = &mut o.px[row + j];
                let test_t = p.t * (1.0 - alpha);
                if test_t < T_MIN {
                    done[ly] |= 1 << j;
                    remaining -= 1;
                    continue;
                }
                let wgt = alpha * p.t;
                for (a, f) in p.acc.iter_mut().zip(feat) {
                    *a += wgt * f;
                }
                p.t = test_t;
                p.n_contrib = k as u32 + 1;
                composited = true;
            }
        }
        if MARK && composited {
            o.shown.push(si);
        }
        if remaining == 0 {
            break;
        }
    }
    o
}
