//! Studio tests that need no window: UI logic through egui_kittest, runs,
//! exports and files dropped on the window (the viewport's own tests are in
//! `viewport/tests.rs`).

use std::path::PathBuf;

use egui_kittest::kittest::{NodeT as _, Queryable as _};
use std::sync::Arc;

use super::viewport::{SharedGaussians, bench};
use super::*;
use gast_core::session::Command;
use gast_core::session::plan::MODEL_GEMM_GFLOPS;

/// Whether tests that need lavapipe/Xvfb must fail (CI) rather than skip.
pub(super) fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// A headless device, or `None` (loudly) when there is none outside CI.
pub(super) fn device_or_skip(test: &str) -> Option<(wgpu::Device, wgpu::Queue, String)> {
    match bench::headless_device() {
        Ok(d) => Some(d),
        Err(e) if !in_ci() => {
            eprintln!("SKIPPED {test}: {e:#}");
            None
        }
        Err(e) => panic!("{test}: {e:#} (CI=true, so this is a failure)"),
    }
}

pub(super) fn demo_camera(g: &Gaussians, w: u32, h: u32) -> Camera {
    let mut v = ViewState::default();
    v.fit(g);
    v.orbit(0.4, 0.1);
    v.camera(w, h)
}

fn test_app() -> StudioApp {
    let mut app = StudioApp::new(egui::Context::default(), StudioArgs::default());
    app.load_in_background = false;
    assert!(app.scene.is_some(), "the demo scene opens with no arguments: {:?}", app.errors);
    assert!(!app.styles.is_empty(), "a demo style opens with no arguments");
    app
}

#[test]
fn a_bad_scene_file_shows_an_error_and_keeps_the_scene() {
    let dir = std::env::temp_dir().join(format!("gast-studio-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let bad = dir.join("broken.ply");
    std::fs::write(&bad, b"ply\nformat ascii 1.0\nelement vertex 1\nend_header\n1 2 3\n").expect("write");
    let mut app = test_app();
    let before = app.scene.as_ref().map(|s| s.scene.version);
    app.open_any(&bad);
    assert_eq!(app.scene.as_ref().map(|s| s.scene.version), before, "the previous scene stays");
    assert_eq!(app.errors.len(), 1);
    assert!(
        app.errors[0].contains("broken.ply") && app.errors[0].contains("keeping the previous scene"),
        "{}",
        app.errors[0]
    );
    app.open_any(&dir.join("missing.png"));
    assert_eq!(app.errors.len(), 2);
    // A style too long and narrow for a run is refused as it opens, and the
    // one chosen before stays.
    let strip = dir.join("strip.png");
    image::RgbImage::new(400, 8).save(&strip).expect("write a strip");
    let chosen = app.style.map(|i| app.styles[i].path.clone());
    app.open_any(&strip);
    assert_eq!(app.style.map(|i| app.styles[i].path.clone()), chosen);
    assert!(app.errors[2].contains("strip.png: expected a style image at most 8 times"), "{}", app.errors[2]);
    assert!(app.errors[2].contains("keeping the previous style"), "{}", app.errors[2]);
    app.errors.pop();

    // The error is on screen, in the bottom panel.
    let mut harness = harness_of(app, 800.0);
    harness.run_steps(3);
    harness.get_by_label_contains("broken.ply");
    harness.get_by_label("2 error(s)");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn controls_edit_the_config_and_presets_round_trip() {
    let app = test_app();
    let mut harness = harness_of(app, 1400.0);
    settle(&mut harness);
    // Texture scale buttons set the config.
    harness.get_by_label("2×").click();
    settle(&mut harness);
    assert_eq!(harness.state().config.texture_scale, 512);
    // Mode menu.
    harness.get_by_label("mode").click();
    harness.run_steps(2);
    harness.get_by_label("joint").click();
    harness.run_steps(2);
    assert_eq!(harness.state().config.mode, gast_core::style::Mode::Joint);
    // Start is disabled without a session runner.
    assert!(harness.get_by_label("Start").accesskit_node().is_disabled());

    let path = std::env::temp_dir().join(format!("gast-preset-{}.json", std::process::id()));
    let app = harness.state_mut();
    app.config.weights.tv = 0.125;
    app.save_preset(&path);
    app.config = StyleConfig::default();
    app.load_preset(&path);
    assert_eq!(app.config.weights.tv, 0.125);
    assert_eq!(app.config.texture_scale, 512);
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    std::fs::write(&path, r#"{"ratio_geo": 3.0}"#).expect("write");
    app.load_preset(&path);
    assert_eq!(app.errors.len(), 1, "a preset with problems is refused");
    assert_eq!(app.config.weights.tv, 0.125);
    std::fs::remove_file(&path).ok();
}

/// The studio with a fake run attached: `steps` step events and a recoloured
/// snapshot of the demo scene in the slot (standing in for a session worker).
fn app_with_a_run(
    steps: u32,
) -> (StudioApp, crossbeam_channel::Receiver<Command>, crossbeam_channel::Sender<gast_core::session::Event>) {
    use gast_core::session::{Event, LossTerms, Slot, Snapshot, StepReport};
    let mut app = test_app();
    let (ctx, crx) = crossbeam_channel::unbounded();
    let (etx, erx) = crossbeam_channel::unbounded();
    let slot = Arc::new(Slot::default());
    app.run.attach(session_link::SessionLink {
        commands: ctx,
        events: erx,
        snapshots: slot.clone(),
        live: Arc::default(),
        start: Arc::default(),
        worker: None,
    });
    for iter in 0..steps {
        let t = iter as f32 / steps as f32;
        let losses = LossTerms {
            total: 2.0 - 1.2 * t + 0.1 * (iter as f32).sin(),
            gcfm: 1.5 - t + 0.05 * (iter as f32 * 1.7).cos(),
            ..LossTerms::default()
        };
        let report = StepReport {
            iter,
            total: 4 * steps,
            cycle: 0,
            phase: gast_core::style::Phase::Color,
            view: 0,
            losses,
            timings: Default::default(),
            elapsed_s: iter as f64 * 0.5 + 0.5,
            // The object slowly darkening, as the colour watch would read it.
            colour: Some(gast_core::session::ColourReading {
                reference: gast_core::eval::CoveredColour { luminance: 0.4, chroma: 0.3 },
                now: gast_core::eval::CoveredColour {
                    luminance: 0.4 * (1.0 - 0.25 * t),
                    chroma: 0.3 * (1.0 - 0.2 * t),
                },
                views: 36,
            }),
        };
        etx.send(Event::Step(report)).expect("send");
    }
    let mut g = (*app.scene.as_ref().expect("scene").scene.gaussians).clone();
    let k = g.sh_coeffs() * 3;
    for dc in g.sh.chunks_exact_mut(k) {
        dc[0] -= 1.0;
        dc[1] -= 0.3;
    }
    slot.put(Snapshot { step: steps, gaussians: g });
    (app, crx, etx)
}

/// A harness drawing `app` in a window 1280 wide and `height` high.
fn harness_of(app: StudioApp, height: f32) -> egui_kittest::Harness<'static, StudioApp> {
    egui_kittest::Harness::builder()
        .with_size(egui::vec2(1280.0, height))
        .build_ui_state(|ui, app: &mut StudioApp| app.show(ui), app)
}

/// Steps the harness until no background job (style maps and depth,
/// inspection) is running, so a click does not race a late layout change.
fn settle(harness: &mut egui_kittest::Harness<'_, StudioApp>) {
    for _ in 0..600 {
        harness.run_steps(1);
        if harness.state().jobs.running == 0 {
            harness.run_steps(2);
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    panic!("background jobs still running after 600 frames");
}

#[test]
fn session_events_and_snapshots_reach_the_window() {
    use gast_core::session::Event;
    let (app, crx, etx) = app_with_a_run(5);
    let mut harness = harness_of(app, 1400.0);
    settle(&mut harness);
    assert!(
        harness.state().snapshot.as_ref().is_some_and(|s| matches!(s.gaussians, SharedGaussians::Snapshot(_))),
        "the snapshot is shown as the current scene, without a copy"
    );
    assert_eq!(harness.state().run.steps.len(), 5);
    harness.get_by_label_contains("ETA");
    // The colour watch's reading under the progress bar; a collapse adds the warning.
    harness.get_by_label_contains("object colour: luminance");
    assert!(harness.query_by_label_contains("Colour collapse").is_none());
    let mut collapsed = harness.state().run.steps.last().cloned().expect("a step");
    collapsed.iter += 1;
    collapsed.colour = Some(gast_core::session::ColourReading {
        reference: gast_core::eval::CoveredColour { luminance: 0.4, chroma: 0.3 },
        now: gast_core::eval::CoveredColour { luminance: 0.1, chroma: 0.1 },
        views: 36,
    });
    etx.send(Event::Step(collapsed)).expect("send");
    harness.run_steps(2);
    harness.get_by_label_contains("Colour collapse: 75% of the colour is lost");
    harness.get_by_label("Pause").click();
    harness.run_steps(2);
    assert_eq!(crx.try_recv().ok(), Some(Command::Pause));
    etx.send(Event::Paused).expect("send");
    harness.run_steps(2);
    harness.get_by_label("Resume").click();
    harness.run_steps(2);
    assert_eq!(crx.try_recv().ok(), Some(Command::Resume));
    etx.send(Event::Finished { completed: true, steps: 20, seconds: 20.0 }).expect("send");
    harness.run_steps(2);
    assert!(!harness.state().run.is_live());
    assert!(harness.get_by_label("Start").accesskit_node().is_disabled());
}

/// The whole window rendered headless through egui-wgpu with the viewport's
/// paint callback: a run in progress, the before/after split, the loss chart.
#[test]
fn headless_screenshot_of_a_run_in_progress() {
    if device_or_skip("headless_screenshot_of_a_run_in_progress").is_none() {
        return;
    }
    let rs = egui_kittest::wgpu::create_render_state(
        egui_kittest::wgpu::default_wgpu_setup(),
        egui_wgpu::RendererOptions::PREDICTABLE,
    );
    let resources = ViewportResources::new(&rs.device, rs.target_format);
    rs.renderer.write().callback_resources.insert(resources);
    let renderer = egui_kittest::wgpu::WgpuTestRenderer::from_render_state(rs);
    let (app, _crx, _etx) = app_with_a_run(60);
    let mut harness = egui_kittest::Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .renderer(renderer)
        .build_ui_state(|ui, app: &mut StudioApp| app.show(ui), app);
    harness.run_steps(3);
    // Let the inspection job finish, then draw again.
    for _ in 0..100 {
        if harness.state().maps.is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
        harness.step();
    }
    harness.run_steps(2);
    // The viewport's callback fills the status bar's frame figures when it
    // is rendered; render once, lay out again, then take the picture.
    harness.render().expect("render");
    harness.run_steps(1);
    let img = harness.render().expect("render");
    let path = std::env::temp_dir().join("gast-studio-gpu-vs-cpu").join("studio_run.png");
    std::fs::create_dir_all(path.parent().expect("parent")).expect("dir");
    img.save(&path).expect("save");
    println!("wrote {}", path.display());
    // The split line is drawn across the middle of the viewport.
    let app = harness.state();
    assert!(app.snapshot.is_some() && app.maps.is_some());
    let yellow = (0..img.width()).filter(|&x| {
        let p = img.get_pixel(x, 300).0;
        p[0] > 200 && p[1] > 180 && p[2] < 90
    });
    assert!(yellow.count() >= 1, "no split line in the viewport");
}

/// A file "dropped" onto the window in tests.
#[derive(Debug)]
struct TestDrop(PathBuf);

impl egui::DroppedFile for TestDrop {
    fn path(&self) -> &std::path::Path {
        &self.0
    }
    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

#[test]
fn dropped_styles_and_scenes_open() {
    let app = test_app();
    let styles_before = app.styles.len();
    let mut harness = harness_of(app, 900.0);
    harness.run_steps(1);
    let dir = assets::source_assets_dir();
    let dropped: Vec<egui::DroppedFileHandle> = vec![
        Arc::new(TestDrop(dir.join(assets::DEMO_STYLES[1]))),
        Arc::new(TestDrop(dir.join(assets::DEMO_SCENE))),
        Arc::new(TestDrop(dir.join("no-such-file.ply"))),
        Arc::new(TestDrop(dir.join("no-such-style.jpg"))),
    ];
    harness.state_mut().load_in_background = true;
    harness.input_mut().dropped_files = dropped;
    harness.step();
    // Scenes and styles load on worker threads: wait for all four results.
    for _ in 0..200 {
        if harness.state().jobs.running == 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
        harness.step();
    }
    harness.run_steps(2);
    let app = harness.state();
    assert_eq!(app.styles.len(), styles_before + 1, "the dropped style joins the recent strip");
    assert_eq!(app.style, Some(0), "and becomes the current style");
    assert!(app.styles[0].path.ends_with(assets::DEMO_STYLES[1]));
    assert_eq!(app.errors.len(), 2, "{:?}", app.errors);
    let said = app.errors.join("\n");
    assert!(said.contains("no-such-file.ply"), "{said}");
    assert!(said.contains("no-such-style.jpg: not a style image this build can read"), "{said}");
    assert!(said.contains("keeping the previous style"), "{said}");
    assert!(app.scene.as_ref().is_some_and(|s| s.scene.version > 1), "the dropped scene replaced the first one");
}

#[test]
fn recent_styles_hold_the_selected_image_only() {
    let (Some(wave), Some(fire)) = (shared_file("data/styles/wave.jpg"), shared_file("data/styles/fire.jpg")) else {
        panic!("the shared styles wave.jpg and fire.jpg are needed (set GAST_SHARED)");
    };
    let mut app = test_app();
    let generated = PathBuf::from("generated ramp");
    app.add_style(
        generated.clone(),
        image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([x as u8 * 4, y as u8 * 5, 90])),
    );
    app.open_style(&wave);
    app.open_style(&fire);
    let held = |app: &StudioApp, p: &Path| app.styles.iter().find(|s| s.path == p).map(|s| s.image.is_some());
    assert_eq!((app.style, app.styles[0].path.clone()), (Some(0), fire.clone()));
    assert_eq!(held(&app, &fire), Some(true));
    assert_eq!(held(&app, &wave), Some(false), "a file's style not selected lets its image go");
    assert_eq!(held(&app, &generated), Some(true), "a generated style, which cannot be read again, keeps its own");
    // Picking it back reads the file again and puts it at the head.
    let k = app.styles.iter().position(|s| s.path == wave).expect("wave in the strip");
    app.select_style(k);
    assert_eq!((app.style, app.styles[0].path.clone()), (Some(0), wave.clone()));
    assert_eq!(app.styles[0].image.as_ref().map(|i| (i.width, i.height)), Some((4200, 2000)));
    assert_eq!(held(&app, &fire), Some(false));
    // A held one is selected at once, in its place.
    let k = app.styles.iter().position(|s| s.path == generated).expect("the generated style in the strip");
    app.select_style(k);
    assert_eq!((app.style, app.styles[k].path.clone()), (Some(k), generated));
    assert_eq!(held(&app, &wave), Some(false));
    assert!(app.errors.is_empty(), "{:?}", app.errors);
}

#[test]
fn turntable_export_runs_in_the_background_and_shows_its_gif() {
    let mut app = test_app();
    let dir = std::env::temp_dir().join(format!("gast-studio-turntable-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let opts = crate::turntable::TurntableOptions { frames: 5, size: 40, ..Default::default() };
    app.export_turntable(dir.clone(), opts);
    // The call only starts a job; the UI thread keeps going.
    assert_eq!(app.jobs.running, 1);
    for _ in 0..500 {
        app.poll_workers();
        if app.jobs.running == 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    let gif = dir.join(crate::turntable::GIF_NAME);
    assert!(app.notice.contains(&gif.display().to_string()), "the notice does not show the GIF: {}", app.notice);
    let file = std::io::BufReader::new(std::fs::File::open(&gif).expect("the GIF"));
    let decoder = image::codecs::gif::GifDecoder::new(file).expect("a GIF");
    let frames = image::AnimationDecoder::into_frames(decoder).collect_frames().expect("frames");
    assert_eq!(frames.len(), 5);
    assert_eq!(frames[0].buffer().dimensions(), (40, 40), "no snapshot: one panel per frame");
    std::fs::remove_dir_all(&dir).ok();
}

/// A scene with `cameras.json` beside it (as `gast fit` writes it) opens on
/// its cameras, and an export of the scene carries them to its new folder;
/// the demo scene's orbit is not written out.
#[test]
fn a_scenes_cameras_open_with_it_and_travel_with_its_export() {
    let dir = std::env::temp_dir().join(format!("gast-studio-cameras-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    for sub in ["fit", "out"] {
        std::fs::create_dir_all(dir.join(sub)).expect("dir");
    }
    let scene = super::assets::demo_scene();
    let cameras: Vec<Camera> = (0..3).map(|k| demo_camera(&scene, 64 + k, 48)).collect();
    let cameras: Vec<Camera> =
        cameras.into_iter().enumerate().map(|(k, c)| Camera { name: format!("view{k}"), ..c }).collect();
    gast_core::scene::save(dir.join("fit/scene.ply"), &scene, &Default::default()).expect("scene");
    gast_core::camera::write_inria(dir.join("fit/cameras.json"), &cameras).expect("cameras");
    let mut app = test_app();
    // The demo scene's orbit is not a camera file to carry.
    assert!(app.camera_file().is_none());
    app.open_any(&dir.join("fit/scene.ply"));
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    assert_eq!(app.cameras.len(), 3);
    assert_eq!(app.camera_source_name(), dir.join("fit").display().to_string());
    // They all look one way: F (Fit, Reset) returns to the first of them, where the scene opened.
    let opened = app.view.eye();
    assert!(opened.distance(app.cameras[0].center()) < 1e-3, "{opened} against {}", app.cameras[0].center());
    app.view.orbit(1.0, 0.3);
    assert!(app.view.eye().distance(opened) > 1e-2);
    app.frame_scene();
    assert!(app.view.eye().distance(opened) < 1e-3);
    let g = app.current().expect("the scene");
    app.jobs.export_scene(g, dir.join("out/stylized.ply"), app.camera_file());
    poll_until(&mut app, 30, "the export", |a| a.jobs.running == 0);
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    assert!(app.notice.ends_with("stylized.ply and its cameras.json"), "{}", app.notice);
    let set = gast_core::camera::load(dir.join("out")).expect("the exported cameras.json");
    assert_eq!(set.cameras.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["view0", "view1", "view2"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Cameras beside a scene that see none of it in most views are another
/// scene's: the scene opens on its orbit, and the log says why.
#[test]
fn cameras_beside_an_unrelated_scene_are_not_opened() {
    let dir = std::env::temp_dir().join(format!("gast-studio-foreign-cameras-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let scene = super::assets::demo_scene();
    let cameras: Vec<Camera> = (0..3).map(|k| demo_camera(&scene, 64 + k, 48)).collect();
    let mut far = scene.clone();
    for m in &mut far.means {
        m[0] += 1000.0;
    }
    gast_core::scene::save(dir.join("scene.ply"), &far, &Default::default()).expect("scene");
    gast_core::camera::write_inria(dir.join("cameras.json"), &cameras).expect("cameras");
    let mut app = test_app();
    app.open_any(&dir.join("scene.ply"));
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    assert!(app.camera_file().is_none(), "the orbit, not the camera file");
    let said = app.run.log.iter().find(|l| l.contains("are not used")).expect("the log says why");
    assert!(said.contains("3 of their 3 views show none of the scene"), "{said}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A file of the shared data (`$GAST_SHARED`, else `../shared` beside the workspace).
fn shared_file(rel: &str) -> Option<PathBuf> {
    let base = std::env::var_os("GAST_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let p = base.join(rel);
    p.exists().then_some(p)
}

/// A session starter for tests: the core session worker on the CPU with the
/// built-in style depth, on `views` orbit views at the working resolution of
/// the config `plan` makes of the editor's (the worker's own planning, for a
/// test that needs one).
fn cpu_starter(
    vgg: Arc<gast_core::vision::Vgg>,
    views: usize,
    plan: fn(StyleConfig) -> StyleConfig,
) -> session_link::SessionStarter {
    Box::new(move |req: session_link::StartRequest| {
        let scene = req.scene;
        let config = plan(req.config);
        let side = config.resolution;
        let opts = gast_core::camera::OrbitOptions { count: views, width: side, height: side, ..Default::default() };
        let inputs = gast_core::session::SessionInputs {
            cameras: gast_core::camera::framed_orbit(&scene, &opts),
            scene,
            style: (*req.style).clone(),
            style_depth: gast_core::session::StyleDepthSource::Heuristic,
            vgg: vgg.clone(),
            config,
            gpu: None,
        };
        Ok(session_link::SessionLink::of(gast_core::session::spawn(inputs, req.waker)))
    })
}

/// Steps the app's workers until `done` holds (or panics after `seconds`).
fn poll_until(app: &mut StudioApp, seconds: u64, what: &str, done: impl Fn(&StudioApp) -> bool) {
    let end = std::time::Instant::now() + std::time::Duration::from_secs(seconds);
    while !done(app) {
        assert!(std::time::Instant::now() < end, "{what}: not done after {seconds} s; errors {:?}", app.errors);
        app.poll_workers();
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The contact sheet of a real run (the core session worker on the demo scene
/// and style, a few CPU steps): refused with a message before any run, then
/// written with every tile; a path that cannot be written shows its error in
/// the bottom panel.
#[test]
fn the_contact_sheet_of_a_run_is_exported() {
    let Some(weights) = shared_file("data/weights/vgg19-conv3.safetensors") else {
        assert!(!in_ci(), "the shared VGG weights are missing (CI=true, so this is a failure)");
        eprintln!("SKIPPED the_contact_sheet_of_a_run_is_exported: no shared VGG weights (set GAST_SHARED)");
        return;
    };
    let dir = std::env::temp_dir().join(format!("gast-studio-sheet-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("sheet.png");
    let mut app = test_app();
    app.export_sheet(path.clone());
    assert!(
        app.errors.len() == 1 && app.errors[0].contains("start one first"),
        "no run yet, no sheet: {:?}",
        app.errors
    );
    assert!(!path.exists());
    app.errors.clear();

    let vgg = Arc::new(gast_core::vision::Vgg::load(&weights).expect("weights"));
    app.set_session_starter(cpu_starter(vgg, 8, |config| config));
    app.config = StyleConfig {
        resolution: 64,
        texture_scale: 64,
        cycles: 1,
        steps_per_cycle: 6,
        ratio_geo: 0.5,
        ..StyleConfig::default()
    };
    app.start_run();
    poll_until(&mut app, 600, "the run", |a| matches!(a.run.status, RunStatus::Finished { .. } | RunStatus::Failed(_)));
    assert_eq!(app.run.status, RunStatus::Finished { completed: true }, "{:?}", app.errors);
    poll_until(&mut app, 10, "the last snapshot", |a| {
        a.snapshot.as_ref().is_some_and(|s| matches!(&s.gaussians, SharedGaussians::Snapshot(s) if s.step == 6))
    });

    app.export_sheet(path.clone());
    poll_until(&mut app, 300, "the sheet", |a| a.jobs.running == 0);
    assert!(app.errors.is_empty(), "{:?}", app.errors);
    assert!(app.notice.contains(&path.display().to_string()), "the notice does not name the sheet: {}", app.notice);
    let img = image::open(&path).unwrap_or_else(|e| panic!("{}: not an image ({e})", path.display())).to_rgb8();
    // Nine columns of 200 px tiles (RGB, grey depth, JET depth of before / colour-matched /
    // after); a header, the style row and four view rows, each as high as its pictures
    // drawn 200 px wide (at most 200).
    let start = app.run.start().expect("the run's start");
    let maps = &start.style_maps;
    let rows: Vec<u32> = std::iter::once(crate::report::sheet::row_height(maps.width as u32, maps.height as u32))
        .chain(
            crate::report::sheet::spread(&start.cameras, 4)
                .map(|c| crate::report::sheet::row_height(c.width, c.height)),
        )
        .collect();
    assert_eq!(img.width(), 9 * 200 + 10 * 6);
    assert_eq!(img.height(), 2 * 22 + 6 + rows.iter().map(|h| 22 + h + 6).sum::<u32>() + 6, "rows {rows:?}");
    let mut colours: Vec<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    colours.sort_unstable();
    colours.dedup();
    // Every view's before and after RGB tiles show the scene (not one flat colour) and differ.
    let tile = |row: usize, col: u32| {
        let y0 = 2 * 22 + 6 + rows[..row].iter().map(|h| 22 + h + 6).sum::<u32>() + 22;
        let (x0, h) = (6 + col * 206, rows[row]);
        (0..h).flat_map(move |y| (0..200u32).map(move |x| (x0 + x, y0 + y))).collect::<Vec<_>>()
    };
    let luminance = |p: [u8; 3]| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]);
    for view in 1..=4 {
        let before: Vec<[u8; 3]> = tile(view, 0).iter().map(|&(x, y)| img.get_pixel(x, y).0).collect();
        let after: Vec<[u8; 3]> = tile(view, 2).iter().map(|&(x, y)| img.get_pixel(x, y).0).collect();
        let mean = after.iter().map(|&p| luminance(p)).sum::<f64>() / after.len() as f64;
        let spread = (after.iter().map(|&p| (luminance(p) - mean).powi(2)).sum::<f64>() / after.len() as f64).sqrt();
        let changed = before.iter().zip(&after).filter(|(a, b)| a != b).count();
        println!(
            "view {view}: after tile luminance {mean:.1} ± {spread:.1}, {changed} of {} pixels changed",
            after.len()
        );
        assert!(spread > 5.0, "view {view}: the after tile is flat ({spread:.1})");
        assert!(changed > 1000, "view {view}: the after tile equals the before tile");
    }
    println!("sheet {} ({}×{}, {} colours)", path.display(), img.width(), img.height(), colours.len());
    assert!(colours.len() > 500, "{} colours: the sheet looks blank", colours.len());

    // A file as the folder: the error names the path and shows in the bottom panel.
    let bad = path.join("sheet.png");
    app.export_sheet(bad.clone());
    poll_until(&mut app, 300, "the failing sheet", |a| a.jobs.running == 0);
    assert!(
        app.errors.len() == 1
            && app.errors[0].starts_with("cannot write the contact sheet: ")
            && app.errors[0].contains("sheet.png/sheet.png"),
        "{:?}",
        app.errors
    );
    let mut harness = harness_of(app, 800.0);
    harness.run_steps(3);
    harness.get_by_label_contains("cannot write the contact sheet");
    harness.get_by_label("1 error(s)");
    if std::env::var_os("GAST_KEEP_SCREENSHOTS").is_none() {
        std::fs::remove_dir_all(&dir).ok();
    } else {
        println!("kept {}", dir.display());
    }
}

/// A driver without compute storage buffers (the GL fallback's WebGL2-like
/// limits) gets a message naming what is missing and what to install, not
/// the wgpu validation panic; a Vulkan device's limits pass.
#[test]
fn the_viewport_explains_a_driver_it_cannot_use() {
    let gl = wgpu::Limits::downlevel_webgl2_defaults();
    let why = super::viewport_support(&gl, "llvmpipe (GL)").expect_err("no storage buffers");
    assert!(why.contains("offers 0") && why.contains("\"llvmpipe (GL)\""), "{why}");
    assert!(why.contains("mesa-vulkan-drivers"), "{why}");
    assert_eq!(super::viewport_support(&wgpu::Limits::default(), "Vulkan"), Ok(()));
}

#[test]
fn the_loss_legend_keeps_small_losses_readable() {
    use super::controls::loss_label;
    assert_eq!(loss_label(2.0644), "2.064");
    assert_eq!(loss_label(0.0), "0.000");
    // Content and TV losses around 1e-4 keep three significant digits.
    assert_eq!(loss_label(1.234e-4), "1.23e-4");
    assert_eq!(loss_label(-0.00567), "-5.67e-3");
}

#[test]
fn the_window_switch_reads_a_size_or_keeps_the_default() {
    use super::window_size;
    assert_eq!(window_size(Some("1280x1500")), [1280.0, 1500.0]);
    assert_eq!(window_size(Some("900×700")), [900.0, 700.0]);
    for bad in [None, Some(""), Some("1280"), Some("wide x tall"), Some("10x10"), Some("1280x99999")] {
        assert_eq!(window_size(bad), [1280.0, 800.0], "{bad:?}");
    }
}

#[test]
fn the_loss_chart_smooths_and_scales_past_the_first_spike() {
    use super::controls::{chart_range, robust_range, smoothed, smoothing_window};
    // A first-step spike, then a noisy plateau around 1.
    let mut raw: Vec<f32> = (0..200).map(|i| 1.0 + if i % 2 == 0 { 0.2 } else { -0.2 }).collect();
    raw[0] = 50.0;
    raw[7] = f32::NAN;
    let window = smoothing_window(raw.len());
    let s = smoothed(&raw, window);
    assert_eq!(s.len(), raw.len());
    assert!(s.iter().all(|v| v.is_finite()), "a NaN step keeps the running mean");
    let tail = &s[100..];
    let spread = tail.iter().fold(0.0f32, |m, v| m.max((v - 1.0).abs()));
    assert!(spread < 0.1, "smoothed noise {spread}");
    let (lo, hi) = chart_range(&s, window).expect("finite");
    assert!(hi < 10.0 && lo > 0.5, "range {lo}–{hi}: the spike sets the scale");
    assert_eq!(robust_range(&[f32::NAN]), None);
    assert_eq!(smoothed(&[3.0], 1), vec![3.0]);
}

#[test]
fn a_long_warning_shows_its_first_sentence() {
    use super::panels::first_sentence;
    let long = "the learned depth could not be had: the download of Depth Anything V2 failed (no network). \
                Using the built-in relief estimate instead; put the checkpoint in the cache to use it.";
    let (head, rest) = first_sentence(long, 72);
    assert_eq!(head, "the learned depth could not be had");
    assert!(!rest.is_empty());
    let (head, rest) = first_sentence("short and whole.", 72);
    assert_eq!(head, "short and whole");
    assert!(rest.is_empty(), "{rest:?}");
    let (head, _) = first_sentence(&"word ".repeat(40), 72);
    assert!(head.chars().count() <= 72 && !head.ends_with(' '));
}

#[test]
fn the_split_line_drags_and_hides() {
    let (app, _crx, _etx) = app_with_a_run(5);
    let mut harness = harness_of(app, 800.0);
    settle(&mut harness);
    let rect = harness.state().viewport_rect;
    assert!(rect.width() > 100.0, "viewport {rect:?}");
    let drag = |harness: &mut egui_kittest::Harness<'_, StudioApp>, from: egui::Pos2, to: egui::Pos2| {
        harness.hover_at(from);
        harness.step();
        harness.drag_at(from);
        harness.step();
        for k in 1..=4 {
            harness.hover_at(from + (to - from) * (k as f32 / 4.0));
            harness.step();
        }
        harness.drop_at(to);
        harness.run_steps(2);
    };
    // A drag that starts on the line moves it, and the view stays.
    let y = rect.center().y;
    let line = egui::pos2(rect.left() + rect.width() * 0.5, y);
    let yaw = harness.state().view.cam_to_world;
    drag(&mut harness, line, egui::pos2(rect.left() + rect.width() * 0.25, y));
    let split = harness.state().split;
    assert!((split - 0.25).abs() < 0.02, "split {split}");
    assert_eq!(harness.state().view.cam_to_world, yaw, "dragging the line orbited the view");
    // A drag elsewhere orbits and leaves the line.
    drag(
        &mut harness,
        egui::pos2(rect.left() + rect.width() * 0.7, y),
        egui::pos2(rect.left() + rect.width() * 0.8, y),
    );
    assert_eq!(harness.state().split, split);
    assert_ne!(harness.state().view.cam_to_world, yaw, "a drag off the line did not orbit");
    // B hides the comparison: the viewport draws the after side alone.
    assert!((harness.state().shown_split() - split).abs() < 1e-6);
    harness.hover_at(rect.center());
    harness.key_press(egui::Key::B);
    harness.run_steps(2);
    assert!(!harness.state().compare);
    assert_eq!(harness.state().shown_split(), 0.0);
}

#[test]
fn a_cpu_run_is_planned_to_about_ten_minutes() {
    use gast_core::camera::{OrbitOptions, framed_orbit};
    use gast_core::session::plan::{AUTO_RUN_BUDGET_S, StepModel};
    let scene = assets::demo_scene();
    let cameras = framed_orbit(&scene, &OrbitOptions { count: 12, width: 256, height: 256, ..OrbitOptions::default() });
    let mut config = StyleConfig::default();
    let asked = config.schedule().total_steps();
    let (said, step_s) = super::worker::plan_for_cpu(&scene, &cameras, [256, 256], MODEL_GEMM_GFLOPS, &mut config);
    assert!(said.starts_with("planned for about") && said.contains(&format!("{} px", config.resolution)), "{said}");
    // A small preset stays as small as it was.
    let mut small = StyleConfig { resolution: 64, cycles: 2, ..StyleConfig::default() };
    let (said_small, _) = super::worker::plan_for_cpu(&scene, &cameras, [256, 256], MODEL_GEMM_GFLOPS, &mut small);
    assert_eq!((small.resolution, small.cycles), (64, 2), "{said_small}");
    assert!(said_small.contains("as set"), "{said_small}");
    let model = StepModel::for_focus(config.focus.is_object(0.2));
    // The pace the ETA starts from is the plan's: its steps fill the budget.
    let planned = step_s * f64::from(config.schedule().total_steps());
    assert!(step_s > 0.0 && planned <= AUTO_RUN_BUDGET_S * 1.05, "{planned:.0} s planned: {said}");
    let seconds = model.seconds(config.resolution) * f64::from(config.schedule().total_steps());
    assert!(seconds <= AUTO_RUN_BUDGET_S * 1.05, "{seconds:.0} s planned: {said}");
    assert!(config.schedule().total_steps() <= asked && config.resolution >= 256, "{said}");
}

/// The step time under the resolution slider follows the run: fern's
/// planned whole frame (256 px, the style at 64) is the scaled model's
/// 0.30 s, not the object's; `auto` reads as the running session's coverage says.
#[test]
fn the_step_hint_follows_the_runs_focus_and_texture() {
    use super::controls::step_hint;
    use gast_core::session::plan::MODEL_GEMM_GFLOPS;
    use gast_core::style::Focus;
    let fern = StyleConfig { focus: Focus::Frame, resolution: 256, texture_scale: 64, ..StyleConfig::default() };
    assert!(
        step_hint(&fern, None, None, None, None).contains("0.30 s per step at 256 px")
            && step_hint(&fern, None, None, None, None).contains("whole-frame")
    );
    let auto = StyleConfig { focus: Focus::Auto, ..fern.clone() };
    assert_eq!(step_hint(&auto, Some(0.95), None, None, None), step_hint(&fern, None, None, None, None));
    assert!(
        step_hint(&auto, Some(0.2), None, None, None).contains("the object focus"),
        "{}",
        step_hint(&auto, Some(0.2), None, None, None)
    );
    // The style at its full 256 px on a whole frame takes the unscaled model.
    let unscaled = StyleConfig { texture_scale: 256, ..fern };
    assert_ne!(step_hint(&unscaled, None, None, None, None), step_hint(&auto, Some(0.95), None, None, None));
    // The style's size counts: guitar × wave (4,200 × 2,000) at texture
    // scale 1,024 took 1.45 s a step where 256 took 0.18 (2026-12-01).
    let big = StyleConfig { focus: Focus::Object, resolution: 256, texture_scale: 1024, ..StyleConfig::default() };
    let hint = step_hint(&big, None, Some([4200, 2000]), None, None);
    assert!(hint.contains("1.18 s per step at 256 px (the style at 1024 px)"), "{hint}");
    assert!(step_hint(&big, None, None, None, None).contains("0.71 s"), "{}", step_hint(&big, None, None, None, None));
    // Once a run has probed this machine's rate, the hint takes it as the
    // plan does: four times the model machine's halves the step twice; a
    // rate below twice the model's keeps the 2-core CPU's figure.
    let fast = step_hint(&big, None, Some([4200, 2000]), None, Some(4.0 * MODEL_GEMM_GFLOPS));
    assert!(fast.contains("about 0.29 s per step") && fast.contains("on this CPU"), "{fast}");
    assert_eq!(step_hint(&big, None, Some([4200, 2000]), None, Some(1.5 * MODEL_GEMM_GFLOPS)), hint);
    // The open scene's Gaussians count: four playbots (2,000,000) add 2.3 s a step.
    let millions = step_hint(&fern, None, None, Some(2_000_000), None);
    assert!(
        millions.contains("about 2.62 s per step") && millions.contains("89% of it the scene's Gaussians"),
        "{millions}"
    );
}

/// A whole frame planned at the default texture scale takes the reference's
/// ratio of style to frame, as `gast stylize` does; a scale the user moved is kept.
#[test]
fn a_planned_whole_frame_run_keeps_the_references_style_to_frame_ratio() {
    use gast_core::camera::{OrbitOptions, framed_orbit};
    use gast_core::style::Focus;
    let scene = assets::demo_scene();
    let cameras = framed_orbit(&scene, &OrbitOptions { count: 12, width: 256, height: 256, ..OrbitOptions::default() });
    let mut frame = StyleConfig { focus: Focus::Frame, ..StyleConfig::default() };
    let (said, _) = super::worker::plan_for_cpu(&scene, &cameras, [256, 256], MODEL_GEMM_GFLOPS, &mut frame);
    let expected = gast_core::session::plan::frame_texture_scale(frame.resolution, 256);
    assert!(expected < 256 && frame.texture_scale == expected, "{said}");
    assert!(said.contains(&format!("texture scale {expected} px")), "{said}");
    let mut moved = StyleConfig { focus: Focus::Frame, texture_scale: 384, ..StyleConfig::default() };
    super::worker::plan_for_cpu(&scene, &cameras, [256, 256], MODEL_GEMM_GFLOPS, &mut moved);
    assert_eq!(moved.texture_scale, 384);
    let mut object = StyleConfig { focus: Focus::Object, ..StyleConfig::default() };
    super::worker::plan_for_cpu(&scene, &cameras, [256, 256], MODEL_GEMM_GFLOPS, &mut object);
    assert_eq!(object.texture_scale, 256, "an object keeps the style at 256");
}

/// The editor takes what the run's plan set (resolution, cycles, texture
/// scale) when the run starts, and keeps the rest as the user has it: a
/// slider moved during a planned run sent the unplanned 30 cycles back.
#[test]
fn the_editor_takes_the_planned_settings_when_the_run_starts() {
    // The plan's part: other values than the editor's.
    let plan = |config| StyleConfig { resolution: 64, cycles: 1, texture_scale: 32, ..config };
    let mut editor =
        StyleConfig { resolution: 96, cycles: 3, steps_per_cycle: 2, texture_scale: 48, ..StyleConfig::default() };
    editor.weights.tv = 0.5;
    let Some(mut app) = planned_app("the_editor_takes_the_planned_settings_when_the_run_starts", plan, editor) else {
        return;
    };
    run_to_the_end(&mut app);
    let c = &app.config;
    assert_eq!((c.resolution, c.cycles, c.texture_scale), (64, 1, 32), "the plan's settings");
    assert_eq!((c.steps_per_cycle, c.weights.tv), (2, 0.5), "the user's other settings");
}

#[test]
fn a_planned_run_takes_the_cycles_its_first_cycle_paced() {
    // The plan gave 3 of the 5 cycles asked for, at a model's pace of 100 s
    // a step; the steps here take far less, so all 5 fit the ten minutes.
    // (The re-plan must reach the worker before its third cycle ends: 20
    // steps of margin, about 40 ms each here.)
    let plan = |config| StyleConfig { resolution: 64, cycles: 3, texture_scale: 32, ..config };
    let editor =
        StyleConfig { resolution: 96, cycles: 5, steps_per_cycle: 10, texture_scale: 48, ..StyleConfig::default() };
    let Some(mut app) = planned_app("a_planned_run_takes_the_cycles_its_first_cycle_paced", plan, editor) else {
        return;
    };
    app.run.planned_step_s = Some(100.0);
    run_to_the_end(&mut app);
    assert_eq!(app.config.cycles, 5, "the editor holds the re-planned cycles");
    assert_eq!(app.run.steps.len(), 50, "5 cycles of 10 steps ran");
    assert!(
        app.run.log.iter().any(|l| l.starts_with("re-planned after the first cycle: 5 cycles")),
        "{:?}",
        app.run.log
    );
}

/// A test app with `editor` in its editor whose run has started on 4 orbit
/// views through `plan` (standing in for the CPU plan); `None`, said as
/// skipped, without the shared VGG weights.
fn planned_app(test: &str, plan: fn(StyleConfig) -> StyleConfig, editor: StyleConfig) -> Option<StudioApp> {
    let Some(weights) = shared_file("data/weights/vgg19-conv3.safetensors") else {
        assert!(!in_ci(), "the shared VGG weights are missing (CI=true, so this is a failure)");
        eprintln!("SKIPPED {test}: no shared VGG weights");
        return None;
    };
    let vgg = Arc::new(gast_core::vision::Vgg::load(&weights).expect("weights"));
    let mut app = test_app();
    app.set_session_starter(cpu_starter(vgg, 4, plan));
    app.config = editor;
    app.start_run();
    Some(app)
}

/// Polls `app` until its run ends, and checks that it completed.
fn run_to_the_end(app: &mut StudioApp) {
    poll_until(app, 900, "the run", |a| matches!(a.run.status, RunStatus::Finished { .. } | RunStatus::Failed(_)));
    assert_eq!(app.run.status, RunStatus::Finished { completed: true }, "{:?}", app.errors);
}

/// A root-window close request, as the window's close button makes.
fn request_close(harness: &mut egui_kittest::Harness<'_, StudioApp>) -> bool {
    harness.input_mut().viewports.entry(egui::ViewportId::ROOT).or_default().events.push(egui::ViewportEvent::Close);
    harness.step();
    let cancelled = harness
        .output()
        .viewport_output
        .get(&egui::ViewportId::ROOT)
        .is_some_and(|v| v.commands.contains(&egui::ViewportCommand::CancelClose));
    harness.run_steps(2);
    cancelled
}

/// Closing the window, or opening another scene, while the run's result is
/// held by no export asks first (it dropped the minutes of a run without a
/// word): the close is cancelled and the question names the steps; Cancel
/// keeps all; once exported, the close goes through; a newer snapshot asks
/// again; "Open without exporting" opens the scene and ends the run, whose
/// snapshots no longer come in as the new scene's result.
#[test]
fn leaving_an_unexported_result_asks_first() {
    let (app, _crx, _etx) = app_with_a_run(5);
    let mut harness = harness_of(app, 900.0);
    settle(&mut harness);
    assert_eq!(harness.state().unexported_step(), Some(5));
    assert!(request_close(&mut harness), "the close went through with an unexported result");
    harness.get_by_label_contains("The stylized scene is not exported");
    harness.get_by_label_contains("Closing the studio drops the run's result after 5 steps");
    harness.get_by_label("Cancel").click();
    harness.run_steps(2);
    assert!(harness.state().leave.asking.is_none());
    assert!(harness.query_by_label_contains("The stylized scene is not exported").is_none());

    let dir = std::env::temp_dir().join(format!("gast-studio-leave-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let exported = dir.join("stylized.ply");
    harness.state_mut().export_current_scene(exported.clone(), false);
    settle(&mut harness);
    assert!(exported.is_file());
    assert_eq!(harness.state().unexported_step(), None);
    assert!(!request_close(&mut harness), "an exported result still asked");

    // A newer snapshot is not in the export.
    let mut g = (*harness.state().scene.as_ref().expect("scene").scene.gaussians).clone();
    g.sh[0] += 0.5;
    let link = harness.state().run.link.as_ref().expect("the run").snapshots.clone();
    link.put(gast_core::session::Snapshot { step: 9, gaussians: g.clone() });
    harness.run_steps(3);
    assert_eq!(harness.state().unexported_step(), Some(9));
    let other = dir.join("other.ply");
    gast_core::scene::save(&other, &g, &Default::default()).expect("other scene");
    let before = harness.state().scene.as_ref().map(|s| s.scene.version);
    harness.state_mut().open_any(&other);
    harness.run_steps(2);
    assert_eq!(harness.state().scene.as_ref().map(|s| s.scene.version), before, "opened without asking");
    harness.get_by_label_contains("Opening other.ply drops the run's result after 9 steps");
    harness.get_by_label("Open without exporting").click();
    harness.run_steps(2);
    assert_eq!(harness.state().scene.as_ref().map(|s| s.name.as_str()), Some("other.ply"));
    assert!(harness.state().run.link.is_none() && harness.state().snapshot.is_none(), "the old run goes on");
    link.put(gast_core::session::Snapshot { step: 10, gaussians: g });
    harness.run_steps(3);
    assert!(harness.state().snapshot.is_none(), "the old run's snapshot came in as the new scene's");
    assert!(!request_close(&mut harness), "no result, yet the close asked");
    std::fs::remove_dir_all(&dir).ok();
}

/// The question's "Export .ply…" with the path its save dialog returns: a
/// failed write asks again with the error in the question and keeps the
/// window open; a written one closes the window, the scene on disk.
#[test]
fn exporting_from_the_close_question_closes_once_written() {
    let (app, _crx, _etx) = app_with_a_run(5);
    let mut harness = harness_of(app, 900.0);
    settle(&mut harness);
    assert!(request_close(&mut harness), "the close went through with an unexported result");

    let dir = std::env::temp_dir().join(format!("gast-studio-leave-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    // A file where the export's folder would be: the write fails.
    let blocker = dir.join("not-a-folder");
    std::fs::write(&blocker, b"x").expect("blocker");
    harness.state_mut().export_current_scene(blocker.join("stylized.ply"), true);
    settle(&mut harness);
    assert!(harness.state().leave.asking.is_some(), "a failed export dropped the question");
    assert!(!harness.state().leave.quit_confirmed, "a failed export closed the window");
    let error = harness.state().leave.export_error.clone().expect("the export's error in the question");
    assert!(error.contains("not-a-folder"), "the error does not name the file: {error}");
    // In the question (and the status line's log).
    harness.get_by_label_contains("The stylized scene is not exported");
    assert!(harness.query_all_by_label_contains("not-a-folder").count() >= 1, "the question shows no error");

    let exported = dir.join("stylized.ply");
    harness.state_mut().export_current_scene(exported.clone(), true);
    settle(&mut harness);
    let written = gast_core::scene::load(&exported).expect("the exported scene reads back");
    assert_eq!(written.len(), harness.state().scene.as_ref().expect("scene").scene.gaussians.len());
    assert!(harness.state().leave.asking.is_none() && harness.state().leave.quit_confirmed, "the window stays open");
    assert_eq!(harness.state().unexported_step(), None);
    std::fs::remove_dir_all(&dir).ok();
}

/// A run's link to no worker: its channels closed, its slots empty (a
/// starter's answer in tests that only look at what it was asked).
fn idle_link() -> session_link::SessionLink {
    let (commands, _) = crossbeam_channel::unbounded();
    let (_, events) = crossbeam_channel::unbounded();
    session_link::SessionLink {
        commands,
        events,
        snapshots: Arc::default(),
        live: Arc::default(),
        start: Arc::default(),
        worker: None,
    }
}

/// A run kept by a studio that ended without closing is offered by the next
/// one that opens its scene and style: "Discard" removes it; "Go on from it"
/// starts a run from its step with its settings (the starter is handed the
/// kept run and makes no plan), and that studio's close removes what it kept.
#[test]
fn a_kept_run_is_offered_discarded_and_gone_on_from() {
    let dir = std::env::temp_dir().join(format!("gast-studio-kept-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let studio = || {
        let mut app = test_app();
        app.recovery = recovery::Recovery::in_folder(Some(dir.clone()));
        app
    };
    // What a studio killed at step 7 of 20 left.
    let mut killed = studio();
    let (style, size) = killed.style.map(|k| (killed.styles[k].path.clone(), killed.styles[k].size)).expect("a style");
    let slot = killed.new_slot(&style, size, None).expect("a slot in the folder");
    let kept = recovery::Record {
        step: 7,
        total: 20,
        config: StyleConfig { cycles: 2, steps_per_cycle: 10, resolution: 96, ..StyleConfig::default() },
        ..slot.record.clone()
    };
    let scene = (*killed.scene.as_ref().expect("the demo scene").scene.gaussians).clone();
    let keep = || crate::checkpoint::write_with_record(&slot.path, &scene, None, &kept).expect("kept");
    keep();
    drop(killed);

    let offered = |app: StudioApp| {
        let mut harness = harness_of(app, 900.0);
        settle(&mut harness);
        harness.get_by_label_contains("A run left unfinished");
        harness.get_by_label_contains("during a run of this scene with this style: step 7 of 20, kept ");
        harness
    };
    let mut harness = offered(studio());
    harness.get_by_label("Discard").click();
    harness.run_steps(2);
    assert!(harness.query_by_label_contains("A run left unfinished").is_none());
    assert!(harness.query_by_label_contains("Runs left unfinished").is_none(), "the discarded run is listed");
    assert!(!slot.path.exists() && !crate::checkpoint::record_path(&slot.path).exists(), "the kept run is still there");

    keep();
    // Over other views than those it used, it does not go on: the error says why.
    let mut other_views = studio();
    other_views.cameras.pop();
    let mut harness = offered(other_views);
    harness.get_by_label("Go on from it").click();
    harness.run_steps(2);
    let said = harness.state().errors.join("\n");
    assert!(
        said.contains("the kept run used other views (12 views, ") && said.contains("open the cameras it used"),
        "{said}"
    );
    assert!(harness.state().run.link.is_none(), "a run started over other views");

    let (tx, rx) = crossbeam_channel::unbounded();
    let mut app = studio();
    app.set_session_starter(Box::new(move |req: session_link::StartRequest| {
        let _ = tx.send((req.resume.map(|o| o.record.step), req.config.clone(), req.fit_budget, req.keep.is_some()));
        Ok(idle_link())
    }));
    let mut harness = offered(app);
    harness.get_by_label("Go on from it").click();
    harness.run_steps(2);
    let (step, config, planned, keeps) = rx.try_recv().expect("the run started");
    assert_eq!((step, planned, keeps), (Some(7), false, true), "from the kept step, unplanned, kept in turn");
    assert_eq!(config, kept.config, "the kept run's settings");
    assert_eq!(harness.state().config, kept.config, "the editor shows the run's settings");
    assert!(harness.query_by_label_contains("A run left unfinished").is_none());
    harness.state_mut().shut_down();
    assert!(!slot.path.exists(), "the studio's close left its run's state");

    // Start begins afresh and the kept run goes at once.
    keep();
    let mut app = studio();
    app.set_session_starter(Box::new(move |req: session_link::StartRequest| {
        assert!(req.resume.is_none(), "Start went on from the kept run");
        Ok(idle_link())
    }));
    let mut harness = offered(app);
    harness.get_by_label("Start").click();
    harness.run_steps(2);
    assert!(harness.state().run.link.is_some(), "no run started: {:?}", harness.state().errors);
    assert!(!slot.path.exists(), "the kept run stayed after Start");
    std::fs::remove_dir_all(&dir).ok();
}

/// A studio opened on other files (as one restarted without arguments after
/// a crash) lists the runs kept of other scenes and styles: "Open" opens the
/// run's scene and style, whose run is then offered to go on from.
#[test]
fn runs_kept_of_other_files_are_listed_and_open() {
    let dir = std::env::temp_dir().join(format!("gast-studio-kept-other-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let studio = || {
        let mut app = test_app();
        app.recovery = recovery::Recovery::in_folder(Some(dir.join("kept")));
        app
    };
    // The files of the killed studio's run: part of the demo scene, and a style.
    let mut killed = studio();
    let demo = killed.scene.as_ref().expect("the demo scene").scene.gaussians.to_arc();
    let (scene_file, style_file) = (dir.join("part.ply"), dir.join("gradient.png"));
    let part = gast_core::session::subset(&demo, &(0..demo.len() as u32).step_by(3).collect::<Vec<_>>());
    gast_core::scene::save(&scene_file, &part, &Default::default()).expect("the scene file");
    image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([(x * 4) as u8, (y * 5) as u8, 128]))
        .save(&style_file)
        .expect("the style file");
    killed.open_scene(&scene_file);
    killed.open_style(&style_file);
    assert!(killed.errors.is_empty(), "{:?}", killed.errors);
    let slot = killed.new_slot(&style_file, [64, 48], None).expect("a slot");
    // The style's bytes as the studio read them with its image.
    assert_eq!(slot.record.style_file, crate::checkpoint::file_fingerprint(&style_file));
    assert!(slot.record.style_file.as_deref().is_some_and(|f| f.contains(" bytes, ")), "{:?}", slot.record);
    let kept = recovery::Record { step: 5, total: 20, ..slot.record.clone() };
    crate::checkpoint::write_with_record(&slot.path, &part, None, &kept).expect("kept");
    drop(killed);

    let mut harness = harness_of(studio(), 900.0);
    settle(&mut harness);
    harness.get_by_label_contains("Runs left unfinished");
    harness.get_by_label_contains("part.ply with gradient.png: step 5 of 20, kept ");
    harness.get_by_label("Open").click();
    settle(&mut harness);
    assert_eq!(
        harness.state().scene.as_ref().map(|s| s.name.as_str()),
        Some("part.ply"),
        "{:?}",
        harness.state().errors
    );
    harness.get_by_label_contains("A run left unfinished");
    harness.get_by_label_contains("during a run of this scene with this style: step 5 of 20, kept ");
    assert!(harness.query_by_label_contains("Runs left unfinished").is_none());
    drop(harness);

    // Another image written over the style: the run is listed with why it
    // cannot go on, its Open disabled (opening would refuse it), and Discard removes it.
    image::RgbImage::from_fn(64, 48, |x, _| image::Rgb([200, (x * 3) as u8, 10])).save(&style_file).expect("over it");
    let mut harness = harness_of(studio(), 900.0);
    settle(&mut harness);
    harness.get_by_label_contains("part.ply with gradient.png: step 5 of 20, kept ");
    harness.get_by_label_contains("Cannot go on: another image was written over ");
    harness.get_by_label_contains("gradient.png since it was kept.");
    assert!(harness.get_by_label("Open").accesskit_node().is_disabled());
    harness.get_by_label("Discard").click();
    harness.run_steps(2);
    assert!(harness.query_by_label_contains("Runs left unfinished").is_none());
    assert!(!slot.path.exists(), "the discarded run stayed");
    std::fs::remove_dir_all(&dir).ok();
}

/// Settings beyond the sliders' ranges (a preset's, a plan's or a kept
/// run's: 1,512 px on a GPU, 150 cycles of 800 steps, λ_TV 50) stay as they
/// are while the editor shows them.
#[test]
fn the_editor_keeps_settings_beyond_its_sliders() {
    let mut app = test_app();
    let mut wide = StyleConfig { resolution: 1512, cycles: 150, steps_per_cycle: 800, ..StyleConfig::default() };
    wide.weights.tv = 50.0;
    assert!(wide.problems().is_empty(), "{:?}", wide.problems());
    app.config = wide.clone();
    let mut harness = harness_of(app, 1400.0);
    settle(&mut harness);
    assert_eq!(harness.state().config, wide, "the editor changed settings it only showed");
}
