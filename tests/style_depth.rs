//! The built-in style depth keeps the style's structure: on the nine reference
//! styles and the demo styles, the Canny edges of its JET colouring (the edge
//! modality GCFM matches) are not empty, where the old layout heuristic's were.

use gast_core::session::StyleImage;
use gast_core::style::stage1::style_maps;
use gast_core::vision::relief_depth::ReliefDepth;
use gast_core::vision::style_depth::{DepthPolarity, HeuristicDepth, StyleDepthProvider};
use gast_tests::shared_file;

const STYLES: [&str; 9] = ["block2", "fire", "galaxy", "hydrangea", "mosaic", "particle", "starry", "stone", "wave"];

/// Share of edge pixels in the style's edge map at texture scale 256.
fn edge_share(style: &StyleImage, depth: &dyn StyleDepthProvider) -> f32 {
    let m = style_maps(&style.rgb, style.height, style.width, 256, depth, DepthPolarity::NearBright);
    m.edge.iter().sum::<f32>() / m.edge.len() as f32
}

#[test]
fn relief_depth_has_edges_on_every_style() {
    let mut paths: Vec<(String, std::path::PathBuf)> = Vec::new();
    for s in STYLES {
        let Some(p) = shared_file(&format!("data/styles/{s}.jpg")) else { return };
        paths.push((s.to_string(), p));
    }
    let assets = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    for demo in ["style_blocks", "style_particles", "style_waves"] {
        paths.push((demo.to_string(), assets.join(format!("{demo}.png"))));
    }
    let mut failures = Vec::new();
    for (name, path) in &paths {
        let style = StyleImage::open(path).expect("style image");
        let relief = edge_share(&style, &ReliefDepth::default());
        let old = edge_share(&style, &HeuristicDepth::default());
        eprintln!("{name:<16} edge pixels: relief {:.2}%, layout heuristic {:.2}%", relief * 100.0, old * 100.0);
        if relief < 0.005 {
            failures.push(format!("{name}: {:.3}% edge pixels", relief * 100.0));
        }
    }
    assert!(failures.is_empty(), "styles whose relief depth has (almost) no edges: {failures:?}");
}

/// Pearson correlation of two equally long maps.
fn correlation(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len() as f32;
    let (ma, mb) = (a.iter().sum::<f32>() / n, b.iter().sum::<f32>() / n);
    let (mut sab, mut saa, mut sbb) = (0f32, 0f32, 0f32);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt().max(1e-12)
}

/// F1 of `found` edges against `truth` edges, a match within one pixel.
fn edge_f1(found: &[f32], truth: &[f32], h: usize, w: usize) -> f32 {
    let near = |map: &[f32], i: usize, j: usize| {
        (i.saturating_sub(1)..=(i + 1).min(h - 1))
            .any(|y| (j.saturating_sub(1)..=(j + 1).min(w - 1)).any(|x| map[y * w + x] > 0.5))
    };
    let (mut tp_f, mut n_f, mut tp_t, mut n_t) = (0f32, 0f32, 0f32, 0f32);
    for i in 0..h {
        for j in 0..w {
            if found[i * w + j] > 0.5 {
                n_f += 1.0;
                tp_f += f32::from(u8::from(near(truth, i, j)));
            }
            if truth[i * w + j] > 0.5 {
                n_t += 1.0;
                tp_t += f32::from(u8::from(near(found, i, j)));
            }
        }
    }
    let (p, r) = (tp_f / n_f.max(1.0), tp_t / n_t.max(1.0));
    2.0 * p * r / (p + r).max(1e-12)
}

/// On styles whose depth is known, the relief estimate follows it better than the
/// layout heuristic: correlation of the depths and F1 of their edge maps.
#[test]
fn relief_depth_follows_known_relief() {
    use gast_core::vision::relief_styles::{ReliefKind, relief_style};
    use gast_core::vision::style_depth::DepthImage;
    for kind in ReliefKind::ALL {
        let r = relief_style(kind, 256);
        let truth = DepthImage { values: r.depth.clone(), height: r.height, width: r.width, near_is_larger: true };
        let maps =
            |d: &dyn StyleDepthProvider| style_maps(&r.rgb, r.height, r.width, 256, d, DepthPolarity::NearBright);
        let (t, relief, old) = (maps(&truth), maps(&ReliefDepth::default()), maps(&HeuristicDepth::default()));
        let (h, w) = (t.height, t.width);
        let (c_relief, c_old) = (correlation(&relief.depth, &t.depth), correlation(&old.depth, &t.depth));
        let (f_relief, f_old) = (edge_f1(&relief.edge, &t.edge, h, w), edge_f1(&old.edge, &t.edge, h, w));
        eprintln!(
            "{:<14} depth correlation: relief {c_relief:.3}, layout heuristic {c_old:.3}; edge F1: relief {f_relief:.3}, heuristic {f_old:.3}",
            kind.name()
        );
        assert!(c_relief > c_old, "{kind:?}: relief {c_relief} against the heuristic's {c_old}");
        assert!(f_relief > f_old, "{kind:?}: edge F1 {f_relief} against the heuristic's {f_old}");
    }
}
