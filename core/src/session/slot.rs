//! A latest-value slot: the worker puts heavy snapshots here, the UI reads the
//! newest one when it repaints. Nothing is ever queued, so a slow reader costs
//! the worker nothing and never sees stale frames pile up.

use std::sync::{Arc, Mutex};

/// Holds at most one value, the newest; readers get it by `Arc` without copying.
#[derive(Debug)]
pub struct Slot<T> {
    inner: Mutex<(u64, Option<Arc<T>>)>,
}

impl<T> Default for Slot<T> {
    fn default() -> Self {
        Self { inner: Mutex::new((0, None)) }
    }
}

impl<T> Slot<T> {
    /// Replaces the value (the previous one is dropped once no reader holds
    /// it); returns the value as readers get it.
    pub fn put(&self, value: T) -> Arc<T> {
        let value = Arc::new(value);
        let mut g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        g.0 += 1;
        g.1 = Some(Arc::clone(&value));
        value
    }

    /// The newest value, if any.
    pub fn latest(&self) -> Option<Arc<T>> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner()).1.clone()
    }

    /// The newest value if it is newer than `seen` (a version number the caller
    /// keeps), with its version.
    pub fn newer_than(&self, seen: u64) -> Option<(u64, Arc<T>)> {
        let g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        match &g.1 {
            Some(v) if g.0 > seen => Some((g.0, v.clone())),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_only_the_newest() {
        let slot = Slot::default();
        assert!(slot.latest().is_none());
        slot.put(1);
        slot.put(2);
        assert_eq!(*slot.latest().expect("value"), 2);
        let (v, x) = slot.newer_than(0).expect("newer");
        assert_eq!((v, *x), (2, 2));
        assert!(slot.newer_than(v).is_none());
        slot.put(3);
        assert_eq!(slot.newer_than(v).map(|(_, x)| *x), Some(3));
    }
}
