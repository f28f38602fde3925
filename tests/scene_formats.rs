//! The scene readers on the real shared scenes: counts, degrees, sanity of
//! values, the biker in two formats agreeing within their quantisation, and a
//! real scene surviving a `save_ply`/`load` round trip bit for bit.

use std::time::Instant;

use gast_core::Gaussians;
use gast_core::scene::{self, SH_C0};
use gast_tests::shared_file;

fn load_timed(rel: &str) -> Option<Gaussians> {
    let path = shared_file(rel)?;
    let t = Instant::now();
    let g = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "loaded {rel}: {} Gaussians, degree {}, in {:.1} ms",
        g.len(),
        g.sh_degree,
        t.elapsed().as_secs_f64() * 1e3
    );
    Some(g)
}

fn summary(name: &str, g: &Gaussians) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for m in &g.means {
        for a in 0..3 {
            lo[a] = lo[a].min(m[a]);
            hi[a] = hi[a].max(m[a]);
        }
    }
    let op: Vec<f32> = g.opacity_logits.iter().map(|&o| 1.0 / (1.0 + (-o).exp())).collect();
    let mean_op = op.iter().sum::<f32>() / op.len() as f32;
    let dc_mean: f32 = (0..g.len()).map(|i| 0.5 + SH_C0 * g.sh_of(i)[0]).sum::<f32>() / g.len() as f32;
    let ls_min = g.log_scales.iter().flatten().fold(f32::INFINITY, |a, &b| a.min(b));
    let ls_max = g.log_scales.iter().flatten().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
    eprintln!(
        "{name}: bounds {lo:?}..{hi:?}, mean opacity {mean_op:.3}, mean red {dc_mean:.3}, log-scales {ls_min:.2}..{ls_max:.2}"
    );
}

/// Plausibility of a decoded real scene: the readers already reject
/// non-finite values and zero quaternions, so this checks magnitudes.
fn check_sane(name: &str, g: &Gaussians, n: usize, degree: u32) {
    assert_eq!(g.len(), n, "{name}: count");
    assert_eq!(g.sh_degree, degree, "{name}: SH degree");
    g.check_consistent().unwrap_or_else(|e| panic!("{name}: {e}"));
    summary(name, g);
    for (i, m) in g.means.iter().enumerate() {
        assert!(m.iter().all(|v| v.is_finite() && v.abs() < 100.0), "{name}: mean {i} = {m:?}");
    }
    for (i, q) in g.quats.iter().enumerate() {
        let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-2, "{name}: quaternion {i} has norm {norm}");
    }
    for (i, s) in g.log_scales.iter().enumerate() {
        assert!(s.iter().all(|v| (-25.0..=5.0).contains(v)), "{name}: log-scale {i} = {s:?}");
    }
    let alphas: Vec<f32> = g.opacity_logits.iter().map(|&o| 1.0 / (1.0 + (-o).exp())).collect();
    assert!(alphas.iter().all(|a| (0.0..=1.0).contains(a)));
    let mean_alpha = alphas.iter().sum::<f32>() / n as f32;
    assert!((0.05..0.95).contains(&mean_alpha), "{name}: mean opacity {mean_alpha}");
    assert!(g.sh.iter().all(|v| v.is_finite() && v.abs() < 50.0), "{name}: SH magnitude");
}

#[test]
fn guitar_compressed_ply() {
    let Some(g) = load_timed("data/scenes/guitar.compressed.ply") else { return };
    check_sane("guitar", &g, 90_854, 0);
}

#[test]
fn biker_compressed_ply() {
    let Some(g) = load_timed("data/scenes/biker.compressed.ply") else { return };
    check_sane("biker.compressed.ply", &g, 152_746, 0);
}

#[test]
fn biker_spz() {
    let Some(g) = load_timed("data/scenes/biker.spz") else { return };
    check_sane("biker.spz", &g, 152_746, 0);
}

#[test]
fn playbot_sog_directory_and_meta_json() {
    let Some(g) = load_timed("data/scenes/playbot-sog") else { return };
    // meta.json: count 500000, shN.bands 2 (palette of 65536 entries).
    check_sane("playbot-sog", &g, 500_000, 2);
    // The higher-order SH really came through the palette.
    let rest_nonzero = (0..g.len()).filter(|&i| g.sh_of(i)[3..].iter().any(|&v| v != 0.0)).count();
    assert!(rest_nonzero > g.len() / 2, "only {rest_nonzero} Gaussians have non-zero higher-order SH");
    let Some(g2) = load_timed("data/scenes/playbot-sog/meta.json") else { return };
    assert_eq!(g, g2, "loading the directory and its meta.json must agree");
}

/// Quantisation of the compressed PLY, per chunk of 256: positions and
/// log-scales are 11/10/11-bit unorms between the chunk's bounds, colours
/// 8-bit between the chunk's colour bounds, alpha 8-bit, quaternion
/// components 10-bit over [−1/√2, 1/√2]. The decoded extremes of a chunk are
/// its bounds (unorm 0 and 1 decode exactly), so the steps are recovered from
/// the decoded values.
///
/// SPZ: positions 2^−12 (fixed point, 12 fraction bits in this file),
/// log-scales 1/16 clamped to [−10, 5.9375], alpha 1/255, f_dc 1/(0.15·255)
/// clamped to [−0.5/0.15, 0.5/0.15], quaternion components √½/511.
///
/// Both quantise the same original, so a field may differ by half a step of
/// each (plus float rounding).
#[test]
fn biker_ply_and_spz_agree_within_quantisation() {
    let (Some(a), Some(b)) = (load_timed("data/scenes/biker.compressed.ply"), load_timed("data/scenes/biker.spz"))
    else {
        return;
    };
    assert_eq!(a.len(), b.len());
    let n = a.len();
    // Same order? (Checked on positions with a generous bound; otherwise the
    // test would have to match by nearest position.)
    let same_order = (0..n).all(|i| (0..3).all(|k| (a.means[i][k] - b.means[i][k]).abs() < 0.01));
    assert!(same_order, "biker.spz is not in the compressed PLY's order");

    let spz_pos = 0.5 / 4096.0;
    let spz_scale = 0.5 / 16.0;
    let spz_dc = 0.5 / (0.15 * 255.0);
    let spz_q = 0.5 * std::f32::consts::FRAC_1_SQRT_2 / 511.0;
    let ply_q = 0.5 * std::f32::consts::SQRT_2 / 1023.0;
    let eps = 1e-5;
    let mut worst = [0.0f32; 5]; // position, log-scale, f_dc, alpha, quaternion: error / tolerance
    for c in 0..n.div_ceil(256) {
        let rows = c * 256..((c + 1) * 256).min(n);
        let range = |f: &dyn Fn(usize) -> f32| {
            let (lo, hi) =
                rows.clone().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), i| (l.min(f(i)), h.max(f(i))));
            hi - lo
        };
        let bits = [2047.0, 1023.0, 2047.0];
        let pos_step: Vec<f32> = (0..3).map(|k| range(&|i| a.means[i][k]) / bits[k]).collect();
        let scale_step: Vec<f32> = (0..3).map(|k| range(&|i| a.log_scales[i][k]) / bits[k]).collect();
        let dc_step: Vec<f32> = (0..3).map(|ch| range(&|i| a.sh_of(i)[ch]) / 255.0).collect();
        for i in rows {
            for k in 0..3 {
                let tol = 0.5 * pos_step[k] + spz_pos + eps;
                let err = (a.means[i][k] - b.means[i][k]).abs();
                worst[0] = worst[0].max(err / tol);
                assert!(
                    err <= tol,
                    "Gaussian {i} position {k}: ply {} spz {} (tolerance {tol})",
                    a.means[i][k],
                    b.means[i][k]
                );

                let expect = a.log_scales[i][k].clamp(-10.0, 5.9375);
                let tol = 0.5 * scale_step[k] + spz_scale + eps;
                let err = (expect - b.log_scales[i][k]).abs();
                worst[1] = worst[1].max(err / tol);
                assert!(
                    err <= tol,
                    "Gaussian {i} log-scale {k}: ply {} spz {} (tolerance {tol})",
                    a.log_scales[i][k],
                    b.log_scales[i][k]
                );

                let limit = 0.5 / 0.15;
                let expect = a.sh_of(i)[k].clamp(-limit, limit);
                let tol = 0.5 * dc_step[k] + spz_dc + eps;
                let err = (expect - b.sh_of(i)[k]).abs();
                worst[2] = worst[2].max(err / tol);
                assert!(
                    err <= tol,
                    "Gaussian {i} f_dc {k}: ply {} spz {} (tolerance {tol})",
                    a.sh_of(i)[k],
                    b.sh_of(i)[k]
                );
            }
            let sig = |o: f32| 1.0 / (1.0 + (-o).exp());
            let tol = 1.0 / 255.0 + eps;
            let err = (sig(a.opacity_logits[i]) - sig(b.opacity_logits[i])).abs();
            worst[3] = worst[3].max(err / tol);
            assert!(err <= tol, "Gaussian {i} alpha: {err} > {tol}");

            // q and −q are the same rotation. Each small component is off by
            // at most half a step; the reconstructed largest one by at most
            // 3× that (Σ|a_i| ≤ 1.5, largest ≥ 1/2).
            let (qa, qb) = (a.quats[i], b.quats[i]);
            let dot: f32 = (0..4).map(|k| qa[k] * qb[k]).sum();
            let s = if dot < 0.0 { -1.0 } else { 1.0 };
            let err = (0..4).map(|k| (qa[k] - s * qb[k]).abs()).fold(0.0f32, f32::max);
            let tol = 3.0 * (ply_q + spz_q) + eps;
            worst[4] = worst[4].max(err / tol);
            assert!(err <= tol, "Gaussian {i} quaternion: ply {qa:?} spz {qb:?} (tolerance {tol})");
        }
    }
    eprintln!(
        "worst error / tolerance: position {:.2}, log-scale {:.2}, f_dc {:.2}, alpha {:.2}, quaternion {:.2}",
        worst[0], worst[1], worst[2], worst[3], worst[4]
    );
}

/// A real scene (the SOG one: degree 2, so the f_rest transpose is exercised)
/// survives `save_ply` then `load` bit for bit.
#[test]
fn real_scene_round_trips_through_save_ply_bit_exactly() {
    let Some(g) = load_timed("data/scenes/playbot-sog") else { return };
    let dir = std::env::temp_dir().join(format!("gast-scene-formats-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("playbot.ply");
    let t = Instant::now();
    scene::save_ply(&path, &g).expect("save_ply");
    eprintln!("save_ply of 500k Gaussians (degree 2): {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    let t = Instant::now();
    let back = scene::load(&path).expect("load");
    eprintln!("load of the INRIA .ply: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(back.sh_degree, g.sh_degree);
    assert_eq!(bits(&back.sh), bits(&g.sh));
    assert_eq!(bits(&back.opacity_logits), bits(&g.opacity_logits));
    assert_eq!(bits(back.means.as_flattened()), bits(g.means.as_flattened()));
    assert_eq!(bits(back.log_scales.as_flattened()), bits(g.log_scales.as_flattened()));
    assert_eq!(bits(back.quats.as_flattened()), bits(g.quats.as_flattened()));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A folder that is no SOG scene is refused saying what it is (it said only
/// "meta.json: No such file or directory"): a posed-photo dataset, which
/// `gast fit` turns into a scene; an INRIA model folder, naming its newest
/// `point_cloud.ply`; else its first names.
#[test]
fn a_folder_that_is_no_scene_says_what_it_holds() {
    for (rel, kind) in [("data/datasets/fern", "LLFF poses_bounds.npy"), ("data/datasets/lego", "NeRF transforms.json")]
    {
        let Some(dir) = shared_file(rel) else { continue };
        let e = scene::load(&dir).expect_err("a photo dataset is no scene").to_string();
        assert!(e.contains(&format!("found a folder of posed photos ({kind})")) && e.contains("gast fit"), "{e}");
    }
    let dir = std::env::temp_dir().join(format!("gast-folder-no-scene-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let e = scene::load(&dir).expect_err("empty").to_string();
    assert!(e.contains("found an empty folder"), "{e}");
    for it in ["7000", "30000"] {
        let folder = dir.join("point_cloud").join(format!("iteration_{it}"));
        std::fs::create_dir_all(&folder).expect("dir");
        gast_tests::write_empty_ply(&folder.join("point_cloud.ply"));
    }
    let e = scene::load(&dir).expect_err("a model folder").to_string();
    let newest = dir.join("point_cloud/iteration_30000/point_cloud.ply");
    assert!(
        e.contains(&format!("INRIA model folder without meta.json; its newest scene is {}", newest.display())),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
