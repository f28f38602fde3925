//! The style's depth in the studio, resolved once per style and choice.
//!
//! The learned depth costs a network pass (and, the first time, a download),
//! so the studio keeps each resolved source for the life of the process: the
//! inspection strip and every run of the same style share one pass, and the
//! pass itself is kept in the Stage-1 cache on disk for the next session. The
//! warning that comes with a fallback to the heuristic is kept with it, so the
//! panel can show it next to the selector.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{LazyLock, Mutex};

use gast_core::gpu::GpuContext;
use gast_core::session::{Stage1Cache, StyleDepthSource, StyleImage};
use gast_core::vision::style_depth::{DepthImage, DepthProvider};

/// A resolved source and the warning to show with it, if any.
pub type Resolved = (StyleDepthSource, Option<String>);

type Key = (PathBuf, DepthProvider, Option<PathBuf>);

static CACHE: LazyLock<Mutex<HashMap<Key, Resolved>>> = LazyLock::new(|| Mutex::new(HashMap::new()));

/// The depth source for the style at `style_path` under `provider`, with the
/// user's depth image for that style when the provider is `image`. Computed
/// on first use (holding the cache, so a second caller waits for the same
/// pass instead of running another), then served from the cache. The learned
/// network runs on `gpu` when one is given (a run on a hardware adapter),
/// else on the CPU; the two agree to 3e-7, so one cached source serves both.
pub fn source_for(
    style_path: &Path,
    style: &StyleImage,
    provider: DepthProvider,
    image: Option<&Path>,
    gpu: Option<&GpuContext>,
) -> Resolved {
    let image = if provider == DepthProvider::Image { image.map(Path::to_path_buf) } else { None };
    let key = (style_path.to_path_buf(), provider, image.clone());
    let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(hit) = cache.get(&key) {
        return hit.clone();
    }
    let resolved = match image.as_deref().map(DepthImage::from_file) {
        Some(Err(e)) => {
            let why = format!("depth image unreadable; using the built-in relief estimate (luminance detail): {e}");
            (StyleDepthSource::Heuristic, Some(why))
        }
        read => {
            let cache = Stage1Cache::from_env();
            let r = StyleDepthSource::resolve_on(
                provider,
                read.and_then(Result::ok),
                None,
                cache.as_ref(),
                style,
                gpu,
                &mut |_, _| {},
            );
            (r.source, r.warning)
        }
    };
    cache.insert(key, resolved.clone());
    resolved
}
