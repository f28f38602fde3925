//! Bind groups kept from one step to the next.
//!
//! A step records about 250 dispatches, each with a bind group of the same
//! buffers as at the step before (the engine allocates its workspaces once).
//! Making them is most of the host's recording time (on lavapipe 0.7–1.0 ms
//! of a step's 0.9–1.5 ms). [`BindCache`] keeps them: the engine lends it to
//! its thread for the length of a step ([`BindCache::lend`]), and
//! [`super::Kernel::bind`] takes a kept group of the same layout and buffers,
//! or makes one and keeps it.
//!
//! A kept group holds its buffers alive, so the cache is emptied whenever
//! the context allocated since the last lend (a buffer replaced is a buffer
//! allocated: a grown window, a new plan, a view's first target), and the
//! engine empties it when it drops buffers without allocating
//! ([`BindCache::clear`]). Outside a lend (the studio's viewport, the
//! per-view targets, tests) every bind group is made fresh, as before.
//!
//! `GAST_BIND_CACHE=0` makes every group fresh in the steps too, for
//! measuring one against the other (`tools/gpu-check`'s `bind_*` arms).

use std::cell::RefCell;
use std::collections::HashMap;

use super::GpuContext;

/// Whether the steps keep their bind groups (not `GAST_BIND_CACHE=0`).
pub fn enabled() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| !std::env::var("GAST_BIND_CACHE").is_ok_and(|v| v.trim() == "0"))
}

/// More kept groups than this empties the cache (a bound on what it holds
/// alive should a step make new groups every time).
const MAX_KEPT: usize = 16_384;

#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct Key {
    layout: wgpu::BindGroupLayout,
    buffers: Vec<wgpu::Buffer>,
}

/// Bind groups by layout and buffers, kept across an engine's steps (the
/// groups it makes are counted where every group is, in
/// [`GpuContext::bind_groups_made`]).
#[derive(Debug, Default)]
pub struct BindCache {
    groups: HashMap<Key, wgpu::BindGroup>,
    /// The context's allocated bytes when the last lend began.
    allocated_at: u64,
}

thread_local! {
    /// The cache lent to this thread, if any.
    static LENT: RefCell<Option<BindCache>> = const { RefCell::new(None) };
}

/// A lent cache: [`Lent::finish`] gives it back; dropped early (an error
/// return), the cache goes with it and the next step starts an empty one.
pub struct Lent {
    /// Whether this lend put the cache in (a nested lend leaves the outer one).
    installed: bool,
}

impl Lent {
    /// The cache back, the thread's slot emptied.
    pub fn finish(mut self) -> BindCache {
        let installed = std::mem::replace(&mut self.installed, false);
        if !installed {
            return BindCache::default();
        }
        LENT.with(|l| l.borrow_mut().take()).unwrap_or_default()
    }
}

impl Drop for Lent {
    fn drop(&mut self) {
        if self.installed {
            LENT.with(|l| l.borrow_mut().take());
        }
    }
}

impl BindCache {
    /// Lends the cache to this thread until [`Lent::finish`]: the bind
    /// groups made meanwhile are kept or taken from it. Empties it first
    /// when `ctx` allocated since the last lend began. With
    /// `GAST_BIND_CACHE=0` ([`enabled`]) it lends nothing.
    pub fn lend(mut self, ctx: &GpuContext) -> Lent {
        if !enabled() {
            return Lent { installed: false };
        }
        let allocated = ctx.allocated_bytes();
        if allocated != self.allocated_at || self.groups.len() > MAX_KEPT {
            self.groups.clear();
        }
        self.allocated_at = allocated;
        LENT.with(|l| {
            let mut slot = l.borrow_mut();
            if slot.is_some() {
                return Lent { installed: false };
            }
            *slot = Some(self);
            Lent { installed: true }
        })
    }

    /// Forgets every kept group (the engine dropped buffers).
    pub fn clear(&mut self) {
        self.groups.clear();
    }

    /// `make`'s group for `layout` and `buffers`: from the lent cache when
    /// this thread has one (kept there if new), else made fresh. The second
    /// value says whether it was made.
    pub(crate) fn group(
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
        make: impl FnOnce() -> wgpu::BindGroup,
    ) -> (wgpu::BindGroup, bool) {
        LENT.with(|l| {
            let mut slot = l.borrow_mut();
            let Some(cache) = slot.as_mut() else {
                return (make(), true);
            };
            let key = Key { layout: layout.clone(), buffers: buffers.iter().map(|&b| b.clone()).collect() };
            if let Some(group) = cache.groups.get(&key) {
                return (group.clone(), false);
            }
            let group = make();
            cache.groups.insert(key, group.clone());
            (group, true)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::{AdapterPolicy, Bind, Kernel};

    /// `a[0] += 1` on its one buffer.
    const ADD_ONE: &str = "@group(0) @binding(0) var<storage, read_write> a: array<f32>;
@compute @workgroup_size(1) fn main() { a[0] = a[0] + 1.0; }";

    /// A context of its own: the shared test context's allocations and bind
    /// groups are other tests' too, which run beside this one.
    fn own_ctx() -> GpuContext {
        GpuContext::headless(AdapterPolicy::AnyAdapter).expect("a GPU adapter (lavapipe in CI)")
    }

    #[test]
    fn a_lent_cache_keeps_a_group_from_step_to_step_and_forgets_it_when_buffers_may_have_gone() {
        let ctx = own_ctx();
        let k = Kernel::new(&ctx, "add_one", ADD_ONE, "main", &[Bind::ReadWrite]);
        let (a, b) = (ctx.zeros("a", 1), ctx.zeros("b", 1));
        // Groups made since `from` (the context counts every group made).
        let made = |from: u64| ctx.bind_groups_made() - from;
        // Not lent: a new group at every bind.
        assert_ne!(k.bind(&ctx, &[&a]), k.bind(&ctx, &[&a]));

        // Lent: one group per kernel and buffers, kept into the next lend.
        let at = ctx.bind_groups_made();
        let lent = BindCache::default().lend(&ctx);
        let first = k.bind(&ctx, &[&a]);
        assert_eq!(k.bind(&ctx, &[&a]), first);
        assert_ne!(k.bind(&ctx, &[&b]), first);
        let mut cache = lent.finish();
        assert_eq!(made(at), 2, "three binds, one of them kept");
        assert_ne!(k.bind(&ctx, &[&a]), first, "given back, the thread makes groups afresh");
        let at = ctx.bind_groups_made();
        let lent = cache.lend(&ctx);
        assert_eq!(k.bind(&ctx, &[&a]), first);
        cache = lent.finish();
        assert_eq!(made(at), 0, "kept from the last lend");

        // The context allocated since: the next lend starts empty.
        let _c = ctx.zeros("c", 1);
        let lent = cache.lend(&ctx);
        assert_ne!(k.bind(&ctx, &[&a]), first);
        cache = lent.finish();
        assert_eq!(made(at), 1);

        // Cleared by its engine: empty too.
        let kept = {
            let lent = cache.lend(&ctx);
            let g = k.bind(&ctx, &[&a]);
            cache = lent.finish();
            g
        };
        cache.clear();
        let lent = cache.lend(&ctx);
        assert_ne!(k.bind(&ctx, &[&a]), kept);
        // Dropped without being given back (an error return): the thread's slot is emptied.
        drop(lent);
        assert_ne!(k.bind(&ctx, &[&a]), k.bind(&ctx, &[&a]));
    }

    #[test]
    fn dispatches_of_one_kept_group_each_see_the_last_ones_writes() {
        let ctx = own_ctx();
        let k = Kernel::new(&ctx, "add_one", ADD_ONE, "main", &[Bind::ReadWrite]);
        let a = ctx.zeros("a", 1);
        let mut cache = BindCache::default();
        let at = ctx.bind_groups_made();
        for step in 1..=3 {
            let lent = cache.lend(&ctx);
            let mut enc = ctx.encoder("kept group test");
            for _ in 0..4 {
                k.dispatch(&ctx, &mut enc, &[&a], [1, 1, 1]);
            }
            ctx.submit(enc);
            cache = lent.finish();
            let got: Vec<f32> = ctx.read(&a).expect("read back");
            assert_eq!(got[0], (4 * step) as f32, "step {step}");
        }
        assert_eq!(ctx.bind_groups_made() - at, 1, "one group made, the other eleven dispatches kept it");
    }
}
