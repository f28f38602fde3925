//! The Stage-1 cache with the real (golden, random-weight) depth network:
//! hits, misses and damaged files, counted in forward passes.

use std::cell::Cell;

use super::*;
use crate::session::StyleDepthSource;
use crate::vision::depth::{DepthAnything, DepthModelError, INPUT_SIZE, checkpoint_digest};
use crate::vision::style_depth::DepthProvider;

fn style(seed: usize) -> StyleImage {
    StyleImage { width: 40, height: 28, rgb: (0..40 * 28 * 3).map(|i| ((i * 7 + seed * 13) % 251) as u8).collect() }
}

/// The golden checkpoint, or `None` where the shared data is absent.
fn golden() -> Option<PathBuf> {
    crate::vision::weights::tests::shared("golden/depth/depth_seed1.safetensors")
}

/// A cache in a fresh temporary folder.
fn temp_cache(tag: &str) -> Stage1Cache {
    let dir = crate::vision::download::tests::temp_dir(&format!("stage1-{tag}"));
    let _ = std::fs::remove_dir_all(&dir);
    Stage1Cache::new(dir)
}

#[test]
fn second_call_hits_the_cache_and_other_images_miss() -> Result<(), DepthModelError> {
    let Some(p) = golden() else { return Ok(()) };
    let net = DepthAnything::load_path(&p)?;
    let id = checkpoint_digest(&p)?;
    let cache = temp_cache("hits");
    let forwards = Cell::new(0);
    let run = |s: &StyleImage, warnings: &mut Vec<String>| {
        cache.depth_or_compute(
            &depth_key(s, &id, INPUT_SIZE),
            || {
                forwards.set(forwards.get() + 1);
                Ok::<_, DepthModelError>(net.depth_image(&s.rgb[..], s.height, s.width))
            },
            warnings,
        )
    };
    let mut warnings = Vec::new();
    let (first, o1) = run(&style(0), &mut warnings)?;
    let (second, o2) = run(&style(0), &mut warnings)?;
    assert_eq!((forwards.get(), &o1), (1, &CacheOutcome::Computed));
    assert!(matches!(o2, CacheOutcome::Hit(ref f) if f.starts_with(cache.dir())), "{o2:?}");
    assert_eq!(first, second, "the cached depth is the computed one, bit for bit");
    // Another image, and the same image under another checkpoint, miss.
    let (_, o3) = run(&style(1), &mut warnings)?;
    assert_eq!((forwards.get(), o3), (2, CacheOutcome::Computed));
    assert_ne!(depth_key(&style(0), &id, INPUT_SIZE), depth_key(&style(0), "another model", INPUT_SIZE));
    assert_ne!(depth_key(&style(0), &id, INPUT_SIZE), depth_key(&style(0), &id, 392));
    assert!(warnings.is_empty(), "{warnings:?}");
    let _ = std::fs::remove_dir_all(cache.dir());
    Ok(())
}

#[test]
fn damaged_files_are_recomputed_with_a_warning() -> Result<(), String> {
    let cache = temp_cache("damaged");
    let depth = DepthImage {
        values: (0..6 * 5).map(|i| i as f32 * 0.25 - 1.0).collect(),
        height: 6,
        width: 5,
        near_is_larger: true,
    };
    let key = "k";
    let sound = cache.write_depth(key, &depth)?;
    assert_eq!(cache.read_depth(key)?, Some(depth.clone()));
    let bytes = std::fs::read(&sound).map_err(|e| e.to_string())?;
    let mut flipped = bytes.clone();
    flipped[30] ^= 0x10;
    let damaged: [(&str, Vec<u8>, &str); 4] = [
        ("truncated", bytes[..bytes.len() - 7].to_vec(), "truncated"),
        ("a flipped bit", flipped, "checksum"),
        ("another file", b"P6\n5 6\n255\n".to_vec(), "expected a gast depth cache file"),
        ("empty", Vec::new(), "found 0 bytes"),
    ];
    for (what, content, says) in damaged {
        std::fs::write(cache.depth_path(key), &content).map_err(|e| e.to_string())?;
        let err = cache.read_depth(key).err().unwrap_or_default();
        assert!(err.contains("depth-k.bin") && err.contains(says), "{what}: {err}");
        let (mut warnings, mut computed) = (Vec::new(), 0);
        let (got, outcome) = cache.depth_or_compute(
            key,
            || {
                computed += 1;
                Ok::<_, String>(depth.clone())
            },
            &mut warnings,
        )?;
        assert_eq!((got, outcome, computed), (depth.clone(), CacheOutcome::Computed, 1), "{what}");
        assert!(warnings.len() == 1 && warnings[0].contains("computing it again"), "{what}: {warnings:?}");
        // The recomputed value replaced the damaged file.
        assert_eq!(cache.read_depth(key)?, Some(depth.clone()), "{what}");
    }
    // No temporary files are left behind.
    let names: Vec<String> = std::fs::read_dir(cache.dir())
        .map_err(|e| e.to_string())?
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect();
    assert_eq!(names, ["depth-k.bin"]);
    let _ = std::fs::remove_dir_all(cache.dir());
    Ok(())
}

#[test]
fn resolve_reads_the_learned_depth_from_the_cache() {
    let Some(p) = golden() else { return };
    let cache = temp_cache("resolve");
    let none = &mut |_: u64, _: Option<u64>| {};
    let first = StyleDepthSource::resolve(DepthProvider::Learned, None, Some(&p), Some(&cache), &style(2), none);
    let second = StyleDepthSource::resolve(DepthProvider::Learned, None, Some(&p), Some(&cache), &style(2), none);
    assert!(first.warning.is_none() && first.cached.is_none(), "{:?}", first.warning);
    assert!(second.warning.is_none() && second.cached.is_some(), "{:?}", second.warning);
    let (StyleDepthSource::Image(a), StyleDepthSource::Image(b)) = (&first.source, &second.source) else {
        panic!("expected the learned depth twice")
    };
    assert_eq!(a, b);
    let _ = std::fs::remove_dir_all(cache.dir());
}

#[test]
fn the_gpu_depth_matches_the_cpu_one_and_shares_its_cache_entry() {
    let Some(p) = golden() else { return };
    let cache = temp_cache("gpu");
    let none = &mut |_: u64, _: Option<u64>| {};
    let gpu = crate::gpu::test_util::ctx();
    let learned = DepthProvider::Learned;
    let on_gpu = StyleDepthSource::resolve_on(learned, None, Some(&p), Some(&cache), &style(3), Some(gpu), none);
    let on_cpu = StyleDepthSource::resolve(learned, None, Some(&p), None, &style(3), none);
    let again = StyleDepthSource::resolve(learned, None, Some(&p), Some(&cache), &style(3), none);
    assert!(on_gpu.warning.is_none() && on_gpu.cached.is_none(), "{:?}", on_gpu.warning);
    assert!(again.warning.is_none() && again.cached.is_some(), "the CPU run missed the GPU run's entry");
    let (StyleDepthSource::Image(g), StyleDepthSource::Image(c), StyleDepthSource::Image(a)) =
        (&on_gpu.source, &on_cpu.source, &again.source)
    else {
        panic!("expected the learned depth three times")
    };
    assert_eq!(g, a);
    assert_eq!((g.height, g.width), (c.height, c.width));
    let largest = c.values.iter().fold(0f32, |m, v| m.max(v.abs()));
    let err = g.values.iter().zip(&c.values).fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(largest > 0.0 && err <= 1e-4 * largest, "GPU against CPU: {err} (largest {largest})");
    let _ = std::fs::remove_dir_all(cache.dir());
}
