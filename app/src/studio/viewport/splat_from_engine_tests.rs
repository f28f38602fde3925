//! The engine-buffer path against the snapshot path: after real GPU steps on
//! the guitar, the viewport's buffers filled on the device from the engine's
//! must equal those a CPU snapshot upload fills (lavapipe, no window).

use std::sync::Arc;

use gast_core::gpu::{AdapterPolicy, GpuContext};
use gast_core::session::{Session, SessionInputs, StyleDepthSource, StyleImage};
use gast_core::style::{Focus, Mode, StyleConfig};
use gast_tests::shared_file;

use super::{SharedGaussians, Side, SplatRenderer, pack_geometry};

/// A GPU session on the guitar at 48 px, joint mode (colour and geometry move every step).
fn gpu_session(ctx: &GpuContext) -> Option<Session> {
    let scene = gast_core::scene::load(shared_file("data/scenes/guitar.compressed.ply")?).expect("scene");
    let style = StyleImage::open(&shared_file("data/styles/mosaic.jpg")?).expect("style");
    let weights = shared_file("data/weights/vgg19-conv3.safetensors")?;
    let vgg = Arc::new(gast_core::vision::Vgg::load(&weights).expect("weights"));
    let opts = gast_core::camera::OrbitOptions { count: 6, width: 48, height: 48, ..Default::default() };
    let cameras = gast_core::camera::orbit_cameras(&scene.means, &opts);
    let config = StyleConfig {
        cycles: 1,
        steps_per_cycle: 8,
        resolution: 48,
        texture_scale: 48,
        mode: Mode::Joint,
        focus: Focus::Frame,
        ..Default::default()
    };
    let style_depth = StyleDepthSource::Heuristic;
    let inputs = SessionInputs {
        scene: std::sync::Arc::new(scene),
        cameras,
        style,
        style_depth,
        vgg,
        config,
        gpu: Some(ctx.clone()),
    };
    Some(Session::prepare(inputs, &mut |_| {}).expect("GPU session"))
}

/// The f16 values of packed SH words.
fn halves(words: &[u32]) -> Vec<f32> {
    words.iter().flat_map(|w| [(w & 0xffff) as u16, (w >> 16) as u16]).map(super::f16_to_f32).collect()
}

/// Largest difference between two float arrays of the same length, and how many differ.
fn worst(a: &[f32], b: &[f32]) -> (f32, usize) {
    assert_eq!(a.len(), b.len());
    let d = a.iter().zip(b).map(|(x, y)| if x == y { 0.0 } else { (x - y).abs().max(f32::MIN_POSITIVE) });
    d.fold((0.0f32, 0), |(m, n), v| (m.max(v), n + usize::from(v > 0.0)))
}

#[test]
fn engine_buffers_reach_the_viewport_as_a_snapshot_would() {
    let ctx = GpuContext::headless(AdapterPolicy::AnyAdapter).expect("a wgpu adapter (lavapipe)");
    let Some(mut session) = gpu_session(&ctx) else { return };
    let live = session.live().expect("a GPU session shares its buffers");
    assert_eq!(live.steps(), 0);
    let device = &ctx.device;
    let n = live.base().len();
    let sh_words = (gast_core::scene::sh_coeffs_for_degree(live.base().sh_degree) * 3).div_ceil(2);
    // The device's own bindings, then the SH forced across two bindings.
    for limit in [None, Some(n / 3 * sh_words * 4)] {
        let mut r = SplatRenderer::new(device);
        r.use_gpu_sort(ctx.clone());
        r.sh_binding_limit = limit;
        r.set_live_scene(device, Side::After, 1, &live).expect("the engine's device is the viewport's");
        let mut enc = ctx.encoder("test");
        assert!(r.sync_live(&mut enc, Side::After), "the first frame copies");
        assert!(!r.sync_live(&mut enc, Side::After), "no step since: no copy");
        ctx.submit(enc);
        for _ in 0..3 {
            session.step().unwrap_or_else(|| panic!("GPU step failed: {:?}", session.failure()));
        }
        assert_eq!(live.steps(), u64::from(session.steps_done()));
        let mut enc = ctx.encoder("test");
        assert!(r.sync_live(&mut enc, Side::After), "new steps: a copy");
        ctx.submit(enc);

        // The snapshot path: the whole scene read back to the CPU and uploaded.
        let snapshot: SharedGaussians = Arc::new(session.result()).into();
        r.set_scene(device, Side::Before, 2, &snapshot).expect("upload");
        let read = |side| -> Vec<Vec<u32>> {
            let b = r.scene_buffers(side).expect("scene");
            b.iter().map(|b| ctx.read::<u32>(b).expect("read back")).collect()
        };
        let (from_engine, from_snapshot) = (read(Side::After), read(Side::Before));
        let geometry = |w: &[u32]| -> Vec<f32> { w.iter().map(|&b| f32::from_bits(b)).collect() };
        let (geom_err, geom_off) = worst(&geometry(&from_engine[0]), &geometry(&from_snapshot[0]));
        let sh = |w: &[Vec<u32>]| [halves(&w[1]), halves(&w[2])].concat();
        let (sh_err, sh_off) = worst(&sh(&from_engine), &sh(&from_snapshot));
        // The copy did something: the optimised geometry left the colour-matched start.
        let start: Vec<f32> = pack_geometry(live.base()).into_iter().flatten().collect();
        let (_, moved) = worst(&geometry(&from_engine[0])[..start.len()], &start);
        println!(
            "SH binding limit {limit:?}: {n} Gaussians ({} optimised) after {} steps: geometry max |diff| {geom_err:e} \
             ({geom_off} values differ), SH {sh_err:e} ({sh_off} differ); {moved} geometry values moved from the start",
            live.keep().len(),
            session.steps_done()
        );
        assert!(moved > 1000, "the engine moved only {moved} geometry values");
        assert!(geom_err <= 1e-6 && sh_err <= 1e-6, "geometry {geom_err}, SH {sh_err}");
        assert!(!from_engine[2].is_empty());
    }
}

/// The copy without a session: a synthetic SH-3 scene, every third Gaussian
/// "optimised" to values that stress the f16 rounding (ties, subnormals,
/// overflow, signed zero); the words must equal the CPU packer's bit for bit,
/// at the full SH degree and at a lowered one, across two SH bindings.
#[test]
fn the_copy_packs_sh_exactly_as_the_cpu_does() {
    use gast_core::gpu::{GpuGaussians, LiveGaussians};
    let ctx = GpuContext::headless(AdapterPolicy::AnyAdapter).expect("a wgpu adapter (lavapipe)");
    let base = super::bench::synthetic_scene(3000);
    let keep: Vec<u32> = (0..base.len() as u32).step_by(3).collect();
    let mut g = gast_core::session::subset(&base, &keep);
    let special = [1.0 + 1.0 / 2048.0, 1.0 + 3.0 / 2048.0, 3e-6, -7e-8, 7e4, -0.0, 65520.0, 0.33333334];
    for (k, v) in g.sh.iter_mut().enumerate() {
        *v = if k % 5 == 0 { special[(k / 5) % special.len()] } else { *v * 1.7 - 0.01 };
    }
    g.means.iter_mut().for_each(|m| m[1] += 0.25);
    g.opacity_logits.iter_mut().for_each(|o| *o = -*o);
    let mut whole = base.clone();
    gast_core::session::scatter(&mut whole, &keep, &g);
    let live = LiveGaussians::new(&ctx, &GpuGaussians::upload(&ctx, &g), Arc::new(base), Arc::new(keep));
    assert!(live.problem().is_none());
    let device = &ctx.device;
    let n = whole.len();
    // Degree 3 in two bindings; then a limit so low that only degree 1 fits (two words per binding row).
    for (limit, degree) in [(n / 2 * 24 * 4, 3), (n / 2 * 6 * 4, 1)] {
        let mut r = SplatRenderer::new(device);
        r.use_gpu_sort(ctx.clone());
        r.sh_binding_limit = Some(limit);
        let note = r.set_live_scene(device, Side::After, 1, &live).expect("live scene");
        assert_eq!(note.is_some(), degree < 3, "{note:?}");
        r.set_scene(device, Side::Before, 2, &SharedGaussians::Owned(Arc::new(whole.clone()))).expect("upload");
        let mut enc = ctx.encoder("test");
        assert!(r.sync_live(&mut enc, Side::After));
        ctx.submit(enc);
        let read = |side| -> Vec<Vec<u32>> {
            let b = r.scene_buffers(side).expect("scene");
            b.iter().map(|b| ctx.read::<u32>(b).expect("read back")).collect()
        };
        let (a, b) = (read(Side::After), read(Side::Before));
        for (k, name) in ["geometry", "SH a", "SH b"].iter().enumerate() {
            let off = a[k].iter().zip(&b[k]).filter(|(x, y)| x != y).count();
            println!("degree {degree}: {name}: {} words, {off} differ", a[k].len());
            assert_eq!(off, 0, "degree {degree}: {name} differs in {off} words");
        }
        assert!(b[2].len() > 16, "the SH are split across two bindings");
    }
}
