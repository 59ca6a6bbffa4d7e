//! The previewer's controls, driven by their labels with egui_kittest (no
//! window, no GPU): moving a slider changes the settings, restarts the
//! image, and can be undone.

use std::time::{Duration, Instant};

use eframe::egui;
use egui_kittest::kittest::{NodeT, Queryable};
use egui_kittest::Harness;
use lantern::scene::Method;
use lantern::ui::app::CompareMode;
use lantern::ui::controls;
use lantern::ui::LanternApp;

fn harness() -> Harness<'static, LanternApp> {
    let mut app = LanternApp::headless();
    // A small image keeps the passes short in tests.
    app.session.res_scale = 0.1;
    Harness::builder()
        .with_size([1200.0, 800.0])
        .build_ui_state(|ui, app: &mut LanternApp| app.ui(ui), app)
}

/// Steps the UI until the worker shows an image of the current job.
fn wait_for_image(h: &mut Harness<'static, LanternApp>) {
    let start = Instant::now();
    loop {
        h.step();
        let app = h.state();
        if app.generation() > 0 && app.display.generation() == app.generation() {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no image for generation {} (showing {})",
            app.generation(),
            app.display.generation()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn slider(h: &Harness<'static, LanternApp>, label: &str) -> f64 {
    let node = h.get_by_role_and_label(egui::accesskit::Role::Slider, label);
    node.accesskit_node()
        .numeric_value()
        .unwrap_or_else(|| panic!("slider {label} has no value"))
}

#[test]
fn moving_the_four_knobs_changes_the_settings_and_restarts_the_image() {
    let mut h = harness();
    h.run_steps(3);
    wait_for_image(&mut h);
    let first = h.state().generation();

    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::PHASE_G)
        .set_value_accesskit(0.2);
    h.run_steps(2);
    assert!((h.state().doc.scene.medium.g - 0.2).abs() < 1e-6);
    assert!((slider(&h, controls::PHASE_G) - 0.2).abs() < 1e-6);
    assert!(h.state().generation() > first, "the image did not restart");
    wait_for_image(&mut h);

    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::LIGHTS)
        .set_value_accesskit(1000.0);
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.render.internal.knobs.lights, 1000);

    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::TERMS)
        .set_value_accesskit(5.0);
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.render.internal.knobs.terms, 5);

    // s* starts automatic; unticking "auto" shows its slider.
    assert_eq!(h.state().doc.scene.render.internal.knobs.s_star, None);
    h.get_by_label(&format!("auto {}", controls::S_STAR))
        .click();
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.render.internal.knobs.s_star, Some(1.0));
    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::S_STAR)
        .set_value_accesskit(2.5);
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.render.internal.knobs.s_star, Some(2.5));
    let before = h.state().generation();
    wait_for_image(&mut h);
    assert!(h.state().generation() >= before);
}

#[test]
fn undo_and_redo_restore_parameter_edits() {
    let mut h = harness();
    h.run_steps(3);
    let g0 = h.state().doc.scene.medium.g;
    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::PHASE_G)
        .set_value_accesskit(-0.3);
    h.run_steps(2);
    assert!((h.state().doc.scene.medium.g + 0.3).abs() < 1e-6);
    assert!(h.state().is_dirty());

    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert!((h.state().doc.scene.medium.g - g0).abs() < 1e-6, "undo");
    assert!(!h.state().is_dirty());

    h.key_press_modifiers(
        egui::Modifiers::COMMAND | egui::Modifiers::SHIFT,
        egui::Key::Z,
    );
    h.run_steps(2);
    assert!((h.state().doc.scene.medium.g + 0.3).abs() < 1e-6, "redo");
}

#[test]
fn exposure_is_display_only() {
    let mut h = harness();
    h.run_steps(3);
    wait_for_image(&mut h);
    let generation = h.state().generation();
    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::EXPOSURE)
        .set_value_accesskit(2.0);
    h.run_steps(2);
    assert_eq!(h.state().session.exposure, 2.0);
    assert_eq!(
        h.state().generation(),
        generation,
        "exposure must not restart the render"
    );
}

#[test]
fn a_bad_scene_file_keeps_the_current_scene_and_says_why() {
    let mut h = harness();
    h.run_steps(2);
    let dir = tempfile::tempdir().expect("temp dir");
    let bad = dir.path().join("broken.ron");
    std::fs::write(&bad, "( camera: oops )").expect("write");
    let before = h.state().doc.clone();
    h.state_mut().open_now(&bad);
    h.run_steps(2);
    assert_eq!(h.state().doc, before);
    let toast = h
        .state()
        .toasts
        .iter()
        .find(|t| t.error)
        .expect("an error notification");
    assert!(toast.text.contains("broken.ron"), "{}", toast.text);
}

/// A scene the renderers must clamp (a medium far denser than they march)
/// opens, with a notification saying what was done (issue 23); a volume
/// path that is a folder is refused and the scene kept.
#[test]
fn a_clamped_medium_opens_with_a_warning_and_a_folder_is_refused() {
    let mut h = harness();
    h.run_steps(1);
    let dir = tempfile::tempdir().expect("temp dir");
    let mut scene = lantern::scene::Scene::default();
    scene.medium.density = lantern::scene::DensitySource::Sphere {
        center: glam::Vec3::ZERO,
        radius: 1.0,
    };
    scene.medium.density_scale = 1e20;
    let path = dir.path().join("opaque.ron");
    scene.save(&path).expect("save");
    h.state_mut().open_now(&path);
    h.run_steps(1);
    assert_eq!(h.state().doc.scene.medium.density_scale, 1e20);
    let toast = h
        .state()
        .toasts
        .iter()
        .find(|t| t.text.contains("warning"))
        .expect("a warning");
    assert!(
        toast.text.contains("opaque.ron") && toast.text.contains("opaque lit surface"),
        "{}",
        toast.text
    );
    std::fs::create_dir(dir.path().join("cloud.vdb")).expect("folder");
    let before = h.state().doc.clone();
    h.state_mut().open_now(&dir.path().join("cloud.vdb"));
    assert_eq!(h.state().doc, before);
    assert!(
        h.state()
            .toasts
            .iter()
            .any(|t| t.error && t.text.contains("is a folder")),
        "{:?}",
        h.state().toasts.iter().map(|t| &t.text).collect::<Vec<_>>()
    );
}

#[test]
fn split_and_error_views_render_both_estimators_and_show_the_rmse() {
    let mut h = harness();
    h.state_mut().doc.scene.render.internal.knobs.lights = 256;
    h.state_mut().doc.scene.render.internal.expert.walks = 8;
    h.run_steps(3);
    h.get_by_label("Split").click();
    h.run_steps(2);
    assert_eq!(h.state().session.compare, CompareMode::Split);
    let job = h.state().job();
    assert_eq!(job.estimators, vec![Method::Internal, Method::Reference]);
    wait_for_image(&mut h);

    h.get_by_label("Error").click();
    h.run_steps(2);
    assert_eq!(h.state().session.compare, CompareMode::Error);
    // The display re-derives the heatmap from the same streams.
    let start = Instant::now();
    while h.state().display.rmse.is_none() {
        assert!(start.elapsed() < Duration::from_secs(120), "no RMSE");
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let rmse = h.state().display.rmse.unwrap_or(f32::NAN);
    assert!(rmse.is_finite() && rmse >= 0.0, "rmse {rmse}");

    // Choosing a single method also sets the scene's method.
    h.get_by_label("Reference").click();
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.render.method, Method::Reference);
    assert_eq!(h.state().job().estimators, vec![Method::Reference]);
}

#[test]
fn a_dropped_volume_replaces_the_medium_and_is_framed() {
    let mut h = harness();
    h.run_steps(2);
    let vol = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/volumes/puffs.vol");
    let eye_before = h.state().doc.scene.camera.eye;
    h.state_mut().open_now(&vol);
    h.run_steps(2);
    let app = h.state();
    match &app.doc.scene.medium.density {
        lantern::scene::DensitySource::Grid(g) => {
            assert!(
                g.path.is_absolute() && g.path.ends_with("puffs.vol"),
                "{:?}",
                g.path
            )
        }
        other => panic!("medium not replaced: {other:?}"),
    }
    assert!(app.is_dirty(), "a volume makes a new, unsaved scene");
    assert_ne!(app.doc.scene.camera.eye, eye_before, "not framed");
    assert!(app.toasts.iter().all(|t| !t.error));
    wait_for_image(&mut h);
}

#[test]
fn the_series_term_plot_appears_with_the_internal_lights() {
    let mut h = harness();
    h.run_steps(1);
    h.get_by_label("Series terms").click();
    h.run_steps(2);
    assert!(h
        .query_by_label_contains("appears once internal lights are sampled")
        .is_some());
    h.get_by_label("Series terms").click();
    h.state_mut().doc.scene.render.internal.knobs.lights = 256;
    h.state_mut().doc.scene.render.internal.expert.walks = 8;
    h.state_mut().doc.scene.render.internal.knobs.terms = 6;
    h.state_mut().session.compare = CompareMode::Internal;
    h.run_steps(2);
    let start = Instant::now();
    loop {
        h.step();
        let lights = h.state().display.lights();
        // The full set (not the coarse preview set) carries N + 1 terms.
        if lights.as_ref().is_some_and(|l| l.len() == 256) {
            let energy = lights.map(|l| l.term_energy().len()).unwrap_or(0);
            assert_eq!(energy, 7, "terms k = 0..=N");
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no internal lights"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    h.get_by_label("Series terms").click();
    h.run_steps(2);
    // With lights, the section shows the plot instead of its placeholder.
    assert!(h
        .query_by_label_contains("appears once internal lights are sampled")
        .is_none());
}

#[test]
fn closing_with_unsaved_changes_asks_first() {
    let mut h = harness();
    h.run_steps(2);
    // Without changes, closing is not intercepted.
    request_close(&mut h);
    assert!(h.query_by_label("Quit without saving").is_none());

    h.get_by_role_and_label(egui::accesskit::Role::Slider, controls::PHASE_G)
        .set_value_accesskit(0.1);
    h.run_steps(2);
    request_close(&mut h);
    assert!(h.query_by_label("Quit without saving").is_some());
    h.get_by_label("Cancel").click();
    h.run_steps(2);
    assert!(h.query_by_label("Quit without saving").is_none());
    assert!(h.state().is_dirty(), "cancel keeps the edits");
}

fn request_close(h: &mut Harness<'static, LanternApp>) {
    h.input_mut()
        .viewports
        .entry(egui::ViewportId::ROOT)
        .or_default()
        .events
        .push(egui::ViewportEvent::Close);
    h.run_steps(2);
}

#[test]
fn every_control_has_an_accessible_name_and_a_slider_moves_albedo() {
    let mut h = harness();
    h.run_steps(2);
    for section in [
        "Medium",
        controls::EXPERT,
        "Lights",
        lantern::ui::sky::SECTION,
    ] {
        h.get_by_label(section).click();
        h.run_steps(2);
    }
    // The sky's widgets too, with a thumbnail shown.
    h.get_by_label(lantern::ui::sky::CLEAR_SKY).click();
    let start = Instant::now();
    while h.state().sky.thumbnail_of().is_none() {
        assert!(start.elapsed() < Duration::from_secs(30), "no thumbnail");
        std::thread::sleep(Duration::from_millis(10));
        h.step();
    }
    h.run_steps(2);
    h.check_accessibility();
    h.get_by_role_and_label(egui::accesskit::Role::Slider, "albedo (all channels)")
        .set_value_accesskit(0.5);
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.medium.albedo, glam::Vec3::splat(0.5));
    h.get_by_role_and_label(egui::accesskit::Role::Slider, "K (walks per light)")
        .set_value_accesskit(32.0);
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.render.internal.expert.walks, 32);
}

#[test]
fn contributing_lights_of_the_pixel_under_the_cursor_and_f_frames_the_volume() {
    let mut h = harness();
    h.state_mut().doc.scene.render.internal.knobs.lights = 256;
    h.state_mut().doc.scene.render.internal.expert.walks = 8;
    h.state_mut().session.compare = CompareMode::Internal;
    h.state_mut().session.contributors_only = true;
    h.run_steps(2);
    // Wait for the full-resolution image of the full light set.
    let start = Instant::now();
    while !(h.state().display.spp() >= 1
        && h.state().display.lights().is_some_and(|l| l.len() == 256))
    {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no internal lights"
        );
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    // The cloud is in the middle of the viewport (right of the panel).
    let centre = egui::pos2(760.0, 420.0);
    h.hover_at(centre);
    h.run_steps(2);
    let shares = h.state().nav.shares.clone();
    assert!(h.state().nav.shares_key.is_some(), "shares not queried");
    assert!(!shares.is_empty(), "no light lights the cloud's centre");
    let total: f32 = shares.iter().map(|(_, s)| s).sum();
    assert!((total - 1.0).abs() < 1e-3, "shares sum to {total}");

    // F frames the medium: the camera then looks at the box's centre.
    h.state_mut().doc.scene.camera.target = glam::Vec3::new(3.0, 0.0, 0.0);
    h.key_press(egui::Key::F);
    h.run_steps(2);
    let target = h.state().doc.scene.camera.target;
    assert!(target.length() < 1e-4, "target {target}");
}

#[test]
fn an_example_scene_opens_clean_and_follows_its_method() {
    let mut h = harness();
    h.run_steps(2);
    h.state_mut().doc.scene.medium.g = -0.5;
    h.run_steps(2);
    assert!(h.state().is_dirty());
    let (name, text) = lantern::ui::files::PRESETS[1];
    h.state_mut().open_preset(name, text);
    h.run_steps(2);
    let app = h.state();
    assert!(!app.is_dirty(), "a preset is not an unsaved change");
    assert!(!app.history.can_undo());
    let expected = match app.doc.scene.render.method {
        Method::Internal => CompareMode::Internal,
        Method::Reference => CompareMode::Reference,
    };
    assert_eq!(app.session.compare, expected);
    wait_for_image(&mut h);
}

/// Without a display device (as here) choosing the GPU backend keeps the
/// CPU rendering and says why, in a notification and in the panel;
/// choosing the CPU again removes the warning.
#[test]
fn choosing_the_gpu_without_one_falls_back_to_the_cpu_with_a_notice() {
    use lantern::session::Backend;
    let mut h = harness();
    h.run_steps(2);
    assert_eq!(h.state().session.backend, Backend::Cpu);
    assert!(h.state().toasts.is_empty());
    h.get_by_label(controls::BACKEND_GPU).click();
    h.run_steps(2);
    assert_eq!(h.state().session.backend, Backend::Gpu);
    assert_eq!(
        h.state().job().backend,
        Backend::Cpu,
        "no GPU: the job runs on the CPU"
    );
    let toast = h
        .state()
        .toasts
        .iter()
        .find(|t| t.error)
        .expect("a fallback notification");
    assert!(
        toast.text.contains("GPU backend unavailable")
            && toast.text.contains("rendering on the CPU"),
        "{}",
        toast.text
    );
    assert!(h
        .query_by_label_contains("GPU unavailable (no window")
        .is_some());
    wait_for_image(&mut h);
    assert_eq!(h.state().active_backend(), Backend::Cpu);
    // Once per choice: more frames add no more notices.
    h.run_steps(3);
    assert_eq!(h.state().toasts.iter().filter(|t| t.error).count(), 1);

    h.get_by_label(controls::BACKEND_CPU).click();
    h.run_steps(2);
    assert_eq!(h.state().session.backend, Backend::Cpu);
    assert!(h.query_by_label_contains("GPU unavailable").is_none());
    assert!(h.query_by_label("rendering on the CPU").is_some());
}

/// The committed 64×32 sky map.
fn sky_map() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mitsuba/sky_map.exr")
}

fn open_sky_section(h: &mut Harness<'static, LanternApp>) {
    h.get_by_label(lantern::ui::sky::SECTION).click();
    h.run_steps(2);
}

/// A file dropped on the window, as an integration hands it to egui.
#[derive(Debug)]
struct Dropped(std::path::PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &std::path::Path {
        &self.0
    }

    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

/// Drops `path` on the window and steps until the map has been read.
fn drop_file(h: &mut Harness<'static, LanternApp>, path: &std::path::Path) {
    h.input_mut()
        .dropped_files
        .push(std::sync::Arc::new(Dropped(path.to_owned())));
    h.step();
    let start = Instant::now();
    while h.state().sky.is_loading_map() {
        assert!(start.elapsed() < Duration::from_secs(30), "map not read");
        std::thread::sleep(Duration::from_millis(10));
        h.step();
    }
    h.run_steps(2);
}

#[test]
fn choosing_a_constant_sky_and_the_background_are_undoable_edits() {
    use lantern::scene::{Environment, Sky};
    use lantern::ui::sky;
    let mut h = harness();
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.environment, None);
    open_sky_section(&mut h);
    assert!(
        h.query_by_label(sky::BACKGROUND).is_none(),
        "no sky: no checkbox"
    );
    // "Map" without a map yet offers the file and changes nothing.
    h.get_by_label(sky::MAP).click();
    h.run_steps(2);
    assert!(h.query_by_label(sky::CHOOSE_MAP).is_some());
    assert_eq!(h.state().doc.scene.environment, None);
    assert!(!h.state().is_dirty());
    h.get_by_label(sky::CONSTANT).click();
    h.run_steps(2);
    assert!(
        matches!(
            h.state().doc.scene.environment,
            Some(Environment {
                sky: Sky::Constant { .. },
                background: false
            })
        ),
        "{:?}",
        h.state().doc.scene.environment
    );
    assert!(h.state().is_dirty());
    assert!(
        h.state().job().scene.environment.is_some(),
        "the render follows"
    );

    h.get_by_label(sky::BACKGROUND).click();
    h.run_steps(2);
    assert!(h
        .state()
        .doc
        .scene
        .environment
        .as_ref()
        .is_some_and(|e| e.background));

    h.get_by_role_and_label(egui::accesskit::Role::Slider, sky::RADIANCE)
        .set_value_accesskit(2.0);
    h.run_steps(2);
    match &h.state().doc.scene.environment {
        Some(Environment {
            sky: Sky::Constant { radiance },
            ..
        }) => assert!((radiance.max_element() - 2.0).abs() < 1e-4, "{radiance}"),
        other => panic!("{other:?}"),
    }

    // Undo: the radiance, then the background, then the sky itself.
    for _ in 0..2 {
        h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
        h.run_steps(2);
    }
    assert!(h
        .state()
        .doc
        .scene
        .environment
        .as_ref()
        .is_some_and(|e| !e.background));
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().doc.scene.environment, None);
    assert!(!h.state().is_dirty());

    // A clear sky follows the sun; without one it says what the loader says.
    h.get_by_label(sky::CLEAR_SKY).click();
    h.run_steps(2);
    assert!(matches!(
        h.state().doc.scene.environment.as_ref().map(|e| &e.sky),
        Some(Sky::ClearSky { .. })
    ));
    assert!(h
        .query_by_label_contains("Follows the scene's first sun")
        .is_some());
    h.get_by_label(sky::NONE).click();
    h.state_mut().doc.scene.lights.clear();
    h.run_steps(2);
    assert!(
        h.query_by_label_contains("has no Sun light").is_some(),
        "the loader's error is shown"
    );
}

#[test]
fn a_dropped_map_becomes_the_sky_with_a_thumbnail_and_undo_removes_it() {
    use lantern::scene::Sky;
    let mut h = harness();
    h.run_steps(2);
    open_sky_section(&mut h);
    drop_file(&mut h, &sky_map());
    let app = h.state();
    let env = app.doc.scene.environment.clone().expect("a sky");
    let Sky::Map {
        file,
        rotation_deg,
        scale,
    } = &env.sky
    else {
        panic!("{env:?}")
    };
    assert_eq!((*rotation_deg, *scale), (0.0, 1.0));
    // Relative to the scene's folder where it can be, and found from it.
    assert!(file.is_relative(), "{file:?}");
    assert_eq!(
        std::fs::canonicalize(app.scene_dir.join(file)).expect("the map is found"),
        std::fs::canonicalize(sky_map()).expect("map")
    );
    assert!(
        app.toasts.iter().all(|t| !t.error),
        "{:?}",
        app.toasts.iter().map(|t| &t.text).collect::<Vec<_>>()
    );
    assert!(app.is_dirty());
    assert!(
        h.query_by_label(&file.display().to_string()).is_some(),
        "the path is shown"
    );

    // The thumbnail is built off the UI thread, then drawn.
    let start = Instant::now();
    while h.state().sky.thumbnail_of() != Some(&env.sky) {
        assert!(start.elapsed() < Duration::from_secs(30), "no thumbnail");
        std::thread::sleep(Duration::from_millis(10));
        h.step();
    }
    h.get_by_role_and_label(egui::accesskit::Role::Slider, lantern::ui::sky::ROTATION)
        .set_value_accesskit(30.0);
    h.run_steps(2);
    assert!(matches!(
        h.state().doc.scene.environment.as_ref().map(|e| &e.sky),
        Some(Sky::Map { rotation_deg, .. }) if (*rotation_deg - 30.0).abs() < 1e-4
    ));
    assert!(
        matches!(
            h.state().sky.thumbnail_of(),
            Some(Sky::Map { rotation_deg, .. }) if (*rotation_deg - 30.0).abs() < 1e-4
        ),
        "the thumbnail follows the rotation"
    );

    for _ in 0..2 {
        h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
        h.run_steps(2);
    }
    assert_eq!(
        h.state().doc.scene.environment,
        None,
        "one undo step per edit"
    );
    assert!(!h.state().is_dirty());
    wait_for_image(&mut h);
}

#[test]
fn a_bad_dropped_map_leaves_the_scene_and_names_the_file() {
    let mut h = harness();
    h.run_steps(2);
    let dir = tempfile::tempdir().expect("temp dir");
    let truncated = dir.path().join("truncated_sky.exr");
    let bytes = std::fs::read(sky_map()).expect("map");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).expect("write");
    let square = dir.path().join("square_sky.exr");
    {
        use exr::prelude::*;
        let channels = SpecificChannels::rgb(|_: Vec2<usize>| (1.0f32, 1.0f32, 1.0f32));
        Image::from_channels((16, 16), channels)
            .write()
            .to_file(&square)
            .expect("write exr");
    }
    let nan = dir.path().join("nan_sky.exr");
    {
        use exr::prelude::*;
        let channels = SpecificChannels::rgb(|Vec2(x, _): Vec2<usize>| {
            (if x == 3 { f32::NAN } else { 1.0f32 }, 1.0f32, 1.0f32)
        });
        Image::from_channels((8, 4), channels)
            .write()
            .to_file(&nan)
            .expect("write exr");
    }
    let missing = dir.path().join("missing_sky.hdr");
    let before = h.state().doc.clone();
    for (path, why) in [
        (&truncated, "OpenEXR"),
        (&square, "16×16"),
        (&nan, "non-negative"),
        (&missing, "missing_sky.hdr"),
    ] {
        h.state_mut().toasts.clear();
        drop_file(&mut h, path);
        assert_eq!(h.state().doc, before, "{path:?} changed the scene");
        let name = path.file_name().and_then(|n| n.to_str()).expect("name");
        let toast = h
            .state()
            .toasts
            .iter()
            .find(|t| t.error)
            .unwrap_or_else(|| panic!("no error for {name}"));
        assert!(
            toast.text.contains(name) && toast.text.contains(why),
            "{}",
            toast.text
        );
    }
    assert!(!h.state().history.can_undo(), "nothing to undo");
    assert!(!h.state().is_dirty());
}

/// Saving writes the map's path so that the saved scene finds it: here the
/// scene's folder shares no folder with the map's, so the path is absolute.
#[test]
fn a_saved_scene_finds_its_dropped_map() {
    use lantern::scene::{Scene, Sky};
    let mut h = harness();
    h.run_steps(2);
    drop_file(&mut h, &sky_map());
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("with_sky.ron");
    h.state_mut().save_to(&path);
    assert!(!h.state().is_dirty());
    let saved = Scene::load(&path).expect("the saved scene loads");
    let Some(Sky::Map { file, .. }) = saved.environment.as_ref().map(|e| &e.sky) else {
        panic!("{:?}", saved.environment)
    };
    let found = dir.path().join(file);
    assert_eq!(
        std::fs::canonicalize(found).expect("the map is found"),
        std::fs::canonicalize(sky_map()).expect("map")
    );
    assert!(
        saved.load_environment(dir.path()).is_ok(),
        "the saved scene's sky loads"
    );
}
