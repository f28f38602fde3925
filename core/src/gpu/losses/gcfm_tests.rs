//! The GPU GCFM against the CPU one: matches (near-ties counted), loss terms
//! and gradients, with the score matrix in one chunk or several, over every
//! position or a mask of them.

use super::*;
use crate::gpu::test_util::{ctx, noise};
use crate::style::focus::{gather_positions, scatter_positions};
use crate::style::gcfm::{gcfm_loss, gcfm_loss_with_matches};

/// ReLU-like features: non-negative, some zeros.
fn feats(c: usize, n: usize, seed: u64) -> Vec<f32> {
    noise(c * n, seed).iter().map(|v| (v + 0.4).max(0.0)).collect()
}

/// The joint score `⟨r(x), s(y)⟩ / ‖s(y)‖` in f64, as the CPU decides near-ties.
fn joint_score(st: &StyleFeatures, r: &[Vec<f32>; 3], n: usize, x: usize, y: usize) -> f64 {
    let (c, m) = (st.channels, st.positions());
    let (mut dot, mut sq) = (0f64, 0f64);
    for (k, rk) in r.iter().enumerate() {
        for ch in 0..c {
            let s = f64::from(st.modality(k)[ch * m + y]);
            dot += f64::from(rk[ch * n + x]) * s;
            sq += s * s;
        }
    }
    dot / sq.sqrt().max(1e-30)
}

#[test]
fn search_loss_and_gradients_match_the_cpu_gcfm() {
    let ctx = ctx();
    let gcfm = GpuGcfm::new(ctx);
    let (c, hs, ws_) = (96, 9, 13);
    let m = hs * ws_;
    let st = StyleFeatures::new([feats(c, m, 1), feats(c, m, 2), feats(c, m, 3)], c, hs, ws_);
    let style = GpuStyle::new(ctx, &st);
    let mut failures = Vec::new();
    let mut report = Vec::new();
    for (n, limit, masked) in
        [(300usize, SCORE_ELEMS, false), (211, 37 * m, false), (300, SCORE_ELEMS, true), (211, 37 * m, true)]
    {
        let r: [Vec<f32>; 3] = std::array::from_fn(|k| feats(c, n, 10 + k as u64 + n as u64));
        // About 60% of the positions covered with the mask.
        let idx: Vec<usize> =
            noise(n, 70).iter().enumerate().filter(|(_, v)| !masked || **v > -0.2).map(|(x, _)| x).collect();
        let focus = GpuFocus::frame(ctx, 1, 1, n, 1);
        let mut on = vec![0.0f32; n];
        idx.iter().for_each(|&x| on[x] = 1.0);
        ctx.write(focus.cells(), &on);
        ctx.write(focus.counts(), &[idx.len() as f32, 0.0, 0.0, 0.0]);
        let ws = gcfm.workspace_chunked(ctx, &style, n, 2, 2.0, limit);
        for (i, b) in [&ws.scores, &ws.matches, &ws.stats].into_iter().enumerate() {
            ctx.write(
                b,
                &noise((b.size() / 4) as usize, 50 + i as u64).iter().map(|v| v.to_bits()).collect::<Vec<u32>>(),
            );
        }
        let rb: Vec<wgpu::Buffer> = r.iter().map(|v| ctx.upload("r", v)).collect();
        let v_rgb = ctx.upload("v_rgb", &noise(c * n, 60));
        let v_depth = ctx.upload("v_depth", &noise(c * n, 61));
        let scalars = ctx.upload("scalars", &noise(8, 62));
        let mut enc = ctx.encoder("gcfm test");
        gcfm.record(
            ctx,
            &mut enc,
            &ws,
            &style,
            [&rb[0], &rb[1], &rb[2]],
            &focus,
            &v_rgb,
            &v_depth,
            &scalars,
            Search::Every,
        );
        ctx.submit(enc);
        let mt: Vec<u32> = ctx.read(&ws.matches).expect("matches");
        let s: Vec<f32> = ctx.read(&scalars).expect("scalars");
        let g = [ctx.read::<f32>(&v_rgb).expect("v_rgb"), ctx.read::<f32>(&v_depth).expect("v_depth")];

        // Matches: identical to the CPU's except near-ties of the joint score.
        let cpu = gcfm_loss(&st, [&r[0], &r[1], &r[2]], n);
        let gpu_matches = crate::style::gcfm::Matches { best: mt[..n].to_vec(), worst: mt[n..].to_vec() };
        let mut ties = 0;
        for x in 0..n {
            for (a, b) in [(cpu.matches.best[x], gpu_matches.best[x]), (cpu.matches.worst[x], gpu_matches.worst[x])] {
                if a != b {
                    let (sa, sb) = (joint_score(&st, &r, n, x, a as usize), joint_score(&st, &r, n, x, b as usize));
                    if (sa - sb).abs() > 1e-5 * sa.abs().max(1.0) {
                        failures.push(format!("n {n} x {x}: CPU picks {a} ({sa}), GPU {b} ({sb})"));
                    }
                    ties += 1;
                }
            }
        }
        if ties * 50 > n {
            failures.push(format!("n {n}: {ties} near-tie differences of {} matches", 2 * n));
        }

        // Loss and gradients: against the CPU with the GPU's matches, on the
        // covered positions (as the CPU's masked step), zero elsewhere.
        let parts = r.each_ref().map(|f| gather_positions(f, c, n, &idx));
        let kept = crate::style::gcfm::Matches {
            best: idx.iter().map(|&x| gpu_matches.best[x]).collect(),
            worst: idx.iter().map(|&x| gpu_matches.worst[x]).collect(),
        };
        let mut want = gcfm_loss_with_matches(&st, [&parts[0], &parts[1], &parts[2]], idx.len(), kept);
        want.v_rendered = want.v_rendered.map(|v| scatter_positions(&v, c, n, &idx));
        for k in 0..3 {
            let rel = (s[2 + k] - want.terms[k]).abs() / want.terms[k].abs().max(1e-6);
            if rel > 1e-4 {
                failures.push(format!("n {n} modality {k}: loss {} vs CPU {}", s[2 + k], want.terms[k]));
            }
        }
        if (s[5] - want.loss).abs() > 1e-4 * want.loss.abs() {
            failures.push(format!("n {n}: total {} vs CPU {}", s[5], want.loss));
        }
        let mut worst_rel = 0f32;
        for (k, gk) in g.iter().enumerate() {
            let largest = want.v_rendered[k].iter().fold(0f32, |a, v| a.max(2.0 * v.abs()));
            let err = gk.iter().zip(&want.v_rendered[k]).map(|(a, b)| (a - 2.0 * b).abs()).fold(0f32, f32::max);
            worst_rel = worst_rel.max(err / largest);
            if err > 1e-3 * largest {
                failures.push(format!("n {n} modality {k}: gradient differs by {err} (largest {largest})"));
            }
        }
        for (k, gk) in g.iter().enumerate() {
            let outside = (0..c * n).filter(|&i| on[i % n] == 0.0 && gk[i] != 0.0).count();
            if outside > 0 {
                failures.push(format!("n {n} modality {k}: {outside} gradients outside the mask are not 0"));
            }
        }
        report.push(format!(
            "n {n} (covered {}), m {m}, {} chunks: {ties} near-tie differences; loss {} vs CPU {}; gradient error {worst_rel:.1e} of the largest",
            idx.len(),
            ws.chunks.len(),
            s[5],
            want.loss
        ));
    }
    println!("{}", report.join("\n"));
    assert!(failures.is_empty(), "{}\n{}", failures.join("\n"), report.join("\n"));
}

/// The search of a subset of the positions (the object focus's covered ones)
/// gives those positions the matches the search of every position gives them,
/// in one chunk of scores and in several, and the same loss and gradients.
#[test]
fn a_subset_search_matches_the_full_search_at_its_positions() {
    let ctx = ctx();
    let gcfm = GpuGcfm::new(ctx);
    let (c, hs, ws_) = (64, 7, 11);
    let m = hs * ws_;
    let st = StyleFeatures::new([feats(c, m, 21), feats(c, m, 22), feats(c, m, 23)], c, hs, ws_);
    let style = GpuStyle::new(ctx, &st);
    for (n, limit) in [(257usize, SCORE_ELEMS), (190, 23 * m)] {
        let r: [Vec<f32>; 3] = std::array::from_fn(|k| feats(c, n, 30 + k as u64 + n as u64));
        let rb: Vec<wgpu::Buffer> = r.iter().map(|v| ctx.upload("r", v)).collect();
        // About a third of the positions, ragged.
        let at: Vec<u32> = noise(n, 80).iter().enumerate().filter(|(_, v)| **v > 0.3).map(|(x, _)| x as u32).collect();
        let focus = GpuFocus::frame(ctx, 1, 1, n, 1);
        let mut on = vec![0.0f32; n];
        at.iter().for_each(|&x| on[x as usize] = 1.0);
        ctx.write(focus.cells(), &on);
        ctx.write(focus.counts(), &[at.len() as f32, 0.0, 0.0, 0.0]);
        let run = |subset: Option<&GcfmSubset>| {
            let ws = gcfm.workspace_chunked(ctx, &style, n, 0, 1.0, limit);
            let scratch = ctx.upload("scratch", &noise(c * n, 81));
            let search = match subset {
                Some(subset) => Search::Subset { subset, scratch: &scratch },
                None => Search::Every,
            };
            let (v_rgb, v_depth, scalars) = (ctx.zeros("v", c * n), ctx.zeros("v", c * n), ctx.zeros("s", 4));
            let mut enc = ctx.encoder("gcfm subset test");
            gcfm.record(
                ctx,
                &mut enc,
                &ws,
                &style,
                [&rb[0], &rb[1], &rb[2]],
                &focus,
                &v_rgb,
                &v_depth,
                &scalars,
                search,
            );
            ctx.submit(enc);
            let mt: Vec<u32> = ctx.read(&ws.matches).expect("matches");
            let (s, g): (Vec<f32>, Vec<f32>) = (ctx.read(&scalars).expect("s"), ctx.read(&v_rgb).expect("v"));
            (mt, s, g, ws.chunks.len())
        };
        let (full, full_s, full_g, chunks) = run(None);
        let ws = gcfm.workspace_chunked(ctx, &style, n, 0, 1.0, limit);
        let subset = gcfm.subset(ctx, &ws, &style, &at);
        assert_eq!(subset.len(), at.len());
        let (part, part_s, part_g, _) = run(Some(&subset));
        for &x in &at {
            let x = x as usize;
            assert_eq!((part[x], part[n + x]), (full[x], full[n + x]), "n {n} position {x}");
        }
        assert_eq!(part_s, full_s, "n {n}: loss terms");
        assert_eq!(part_g, full_g, "n {n}: gradients");
        println!(
            "n {n}: {} of {n} positions searched, {chunks} chunk(s) of the full search, {} of the subset's",
            at.len(),
            subset.chunks.len()
        );
    }
}
