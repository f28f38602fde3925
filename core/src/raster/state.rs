//! What [`super::forward()`] saves for [`super::backward()`].

use super::splat::Splat;

/// The forward pass's saved state: the visible splats, the per-tile lists in
/// depth order, and per pixel the final transmittance and how far along its
/// tile's list compositing went. Its size is proportional to the visible
/// Gaussians, the (tile, Gaussian) pairs and the pixels.
#[derive(Clone, Debug, Default)]
pub struct ForwardState {
    /// Image size the state belongs to.
    pub(crate) width: u32,
    /// Image height.
    pub(crate) height: u32,
    /// Tiles per row.
    pub(crate) tiles_x: u32,
    /// Projected Gaussians that can touch a pixel, front to back.
    pub(crate) splats: Vec<Splat>,
    /// For each splat, the index of its Gaussian.
    pub(crate) ids: Vec<u32>,
    /// Per tile, the start of its list in `tile_list`; one extra end entry.
    pub(crate) tile_starts: Vec<u32>,
    /// Splat indices, grouped by tile, each group increasing (front to back).
    pub(crate) tile_list: Vec<u32>,
    /// Transmittance left at each pixel after compositing.
    pub(crate) final_t: Vec<f32>,
    /// Per pixel, one past the position in its tile's list of the last splat composited.
    pub(crate) n_contrib: Vec<u32>,
}

impl ForwardState {
    /// Number of Gaussians that survived projection and culling.
    pub fn visible(&self) -> usize {
        self.splats.len()
    }

    /// Number of (tile, Gaussian) pairs composited.
    pub fn pairs(&self) -> usize {
        self.tile_list.len()
    }

    /// The list range of tile `t`.
    pub(crate) fn tile_range(&self, t: usize) -> std::ops::Range<usize> {
        self.tile_starts[t] as usize..self.tile_starts[t + 1] as usize
    }
}

/// Splits `v` into the consecutive pieces `starts[t]..starts[t + 1]`, one per
/// tile, so that tiles can fill their own pieces in parallel.
pub(crate) fn split_by_tile<'a, T>(v: &'a mut [T], starts: &[u32]) -> Vec<&'a mut [T]> {
    let mut pieces = Vec::with_capacity(starts.len().saturating_sub(1));
    let mut rest = v;
    for w in starts.windows(2) {
        let (a, b) = rest.split_at_mut((w[1] - w[0]) as usize);
        pieces.push(a);
        rest = b;
    }
    pieces
}
