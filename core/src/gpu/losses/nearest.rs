//! The preview measures' nearest-neighbour cosine distance
//! ([`crate::eval::NearestStyle::nn_cosine`]) with its search on the GPU:
//! the rendered features against the unit style features by the GCFM's
//! chunked GEMM and arg-max ([`GpuGcfm::nearest`]), then the host takes the
//! cosine of each position's pair (`C` products a position, not `C · M`).
//! At 1,008×756 a render has 47,628 relu3 positions against a style's
//! 2,304: the search is ~56 GFLOP, two seconds of a 2-core CPU.

use super::{GpuContext, GpuError, GpuGcfm};
use crate::eval::NearestStyle;

/// The kernels and the device of the search.
#[derive(Debug)]
pub struct GpuNearest {
    ctx: GpuContext,
    gcfm: GpuGcfm,
}

impl GpuNearest {
    /// Compiles the search's kernels on `ctx`'s device.
    pub fn new(ctx: GpuContext) -> Self {
        let gcfm = GpuGcfm::new(&ctx);
        Self { ctx, gcfm }
    }

    /// [`NearestStyle::nn_cosine`] of the CHW features `a` to `style`, the
    /// search on the device (the style's unit features uploaded each call:
    /// a few MiB, against the render's tens).
    pub fn nn_cosine(&self, style: &NearestStyle, a: &[f32]) -> Result<f32, GpuError> {
        let (c, m) = (style.channels(), style.positions());
        if c == 0 || a.len() < c {
            return Ok(0.0);
        }
        let n = a.len() / c;
        let ctx = &self.ctx;
        let rendered = ctx.upload("nearest.rendered", &a[..n * c]);
        let unit = ctx.upload("nearest.style", style.unit());
        let ones = ctx.upload("nearest.scale", &vec![1.0f32; m]);
        let nearest = self.gcfm.nearest(ctx, &rendered, n, &unit, &ones, m, c, GpuGcfm::score_limit(ctx))?;
        Ok(style.nn_cosine_at(a, &nearest))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_util::{ctx, noise};

    /// The GPU's search gives the CPU's distance, on features with zeros (a
    /// ReLU's) and a zero position, over several score chunks.
    #[test]
    fn the_gpu_search_gives_the_cpus_nearest_neighbour_cosine() {
        let (c, n, m) = (24, 700, 90);
        let relu = |v: Vec<f32>| -> Vec<f32> { v.into_iter().map(|x| x.max(0.0)).collect() };
        let style = relu(noise(c * m, 3));
        let mut a = relu(noise(c * n, 4));
        for ch in 0..c {
            a[ch * n + 5] = 0.0;
        }
        let near = NearestStyle::new(&style, c).expect("a style");
        let cpu = near.nn_cosine(&a);
        let gpu = GpuNearest::new(ctx().clone());
        let got = gpu.nn_cosine(&near, &a).expect("the search");
        assert!(cpu > 0.05 && (got - cpu).abs() <= 1e-5 * cpu.max(1.0), "GPU {got}, CPU {cpu}");
        // Several chunks of rows: the same matches.
        let rendered = ctx().upload("a", &a);
        let unit = ctx().upload("s", near.unit());
        let ones = ctx().upload("ones", &vec![1.0f32; m]);
        let search = |limit| gpu.gcfm.nearest(ctx(), &rendered, n, &unit, &ones, m, c, limit);
        let whole = search(GpuGcfm::score_limit(ctx())).expect("one chunk");
        let chunked = search(7 * m).expect("a hundred chunks");
        assert_eq!(whole, chunked);
        assert_eq!(near.nn_cosine_at(&a, &whole), got);
        // Nothing rendered: 0, as on the CPU.
        assert_eq!(gpu.nn_cosine(&near, &[]).expect("empty"), 0.0);
    }
}
