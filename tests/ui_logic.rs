//! The previewer's logic without a window: EXR export with metadata and
//! layers, the error heatmap's RMSE, camera navigation, the session file.

use glam::Vec3;
use lantern::scene::Camera;
use lantern::scene::Method;
use lantern::session::StreamImage;
use lantern::ui::app::{CompareMode, Session};
use lantern::ui::{files, viewport};

fn stream(estimator: Method, value: Vec3, n: usize) -> StreamImage {
    StreamImage {
        estimator,
        width: n as u32,
        height: 1,
        spp: 4,
        mean: vec![value; n],
        rel_error: 0.1,
        single: None,
        internal: None,
        gpu: None,
        light_sets: None,
    }
}

#[test]
fn exr_export_carries_layers_and_render_settings() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("still.exr");
    let beauty = vec![Vec3::new(1.0, 2.0, 3.0); 6];
    let single = vec![Vec3::new(0.25, 0.5, 0.75); 6];
    let meta = vec![
        ("lantern/M".to_string(), "4096".to_string()),
        ("lantern/s_star".to_string(), "auto".to_string()),
    ];
    files::write_exr_with_metadata(&path, 3, 2, &beauty, &[("single", &single)], &meta)
        .expect("write exr");

    let image = exr::prelude::read_all_flat_layers_from_file(&path).expect("read exr");
    let layer = &image.layer_data[0];
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for expected in ["R", "G", "B", "single.R", "single.G", "single.B"] {
        assert!(
            names.iter().any(|n| n == expected),
            "{expected} missing in {names:?}"
        );
    }
    let b = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "single.B")
        .expect("single.B");
    match &b.sample_data {
        exr::prelude::FlatSamples::F32(v) => assert!(v.iter().all(|&x| x == 0.75)),
        other => panic!("not 32-bit float: {other:?}"),
    }
    let text = format!("{:?}", layer.attributes.other);
    assert!(
        text.contains("lantern/M") && text.contains("4096"),
        "{text}"
    );
}

#[test]
fn exr_export_refuses_mismatched_layers() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.exr");
    let beauty = vec![Vec3::ONE; 4];
    let short = vec![Vec3::ONE; 3];
    let err = files::write_exr_with_metadata(&path, 2, 2, &beauty, &[("single", &short)], &[])
        .expect_err("size mismatch");
    assert!(err.contains("bad.exr"), "{err}");
}

#[test]
fn error_heatmap_reports_the_rmse() {
    let a = stream(Method::Internal, Vec3::splat(1.5), 8);
    let b = stream(Method::Reference, Vec3::splat(1.0), 8);
    let (image, rmse, mean) = viewport::error_heatmap(&a, &b);
    assert_eq!(image.size, [8, 1]);
    assert!((rmse - 0.5).abs() < 1e-6, "rmse {rmse}");
    assert!((mean - 1.0).abs() < 1e-6);
    let (_, zero, _) = viewport::error_heatmap(&b, &b);
    assert_eq!(zero, 0.0);
}

#[test]
fn orbit_keeps_the_distance_and_framing_shows_the_whole_box() {
    let mut cam = Camera::default();
    let d0 = (cam.eye - cam.target).length();
    viewport::orbit(&mut cam, 0.7, 0.4);
    assert!(((cam.eye - cam.target).length() - d0).abs() < 1e-4);
    // Orbiting past the pole stops short of it instead of flipping.
    viewport::orbit(&mut cam, 0.0, 3.0);
    assert!(cam.eye.is_finite());

    let bounds = (Vec3::new(5.0, -1.0, -2.0), Vec3::new(9.0, 1.0, 0.0));
    viewport::frame_bounds(&mut cam, bounds, 1.5);
    cam.width = 300;
    cam.height = 200;
    let frame = cam.frame();
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { bounds.0.x } else { bounds.1.x },
            if i & 2 == 0 { bounds.0.y } else { bounds.1.y },
            if i & 4 == 0 { bounds.0.z } else { bounds.1.z },
        );
        let (x, y) = frame.project(corner).expect("in front of the camera");
        assert!(
            (0.0..=300.0).contains(&x) && (0.0..=200.0).contains(&y),
            "{x} {y}"
        );
    }
}

#[test]
fn pan_moves_eye_and_target_together_and_zoom_approaches_the_target() {
    let mut cam = Camera::default();
    let offset = cam.eye - cam.target;
    viewport::pan(&mut cam, eframe::egui::Vec2::new(30.0, -10.0), 400.0);
    assert!(((cam.eye - cam.target) - offset).length() < 1e-5);
    assert!(cam.target.x < 0.0, "dragging right moves the scene right");
    let d = (cam.eye - cam.target).length();
    viewport::zoom(&mut cam, 0.5);
    assert!(((cam.eye - cam.target).length() - d * (-0.5f32).exp()).abs() < 1e-4);
}

#[test]
fn the_session_round_trips_and_tolerates_old_files() {
    let session = Session {
        exposure: 1.5,
        compare: CompareMode::Split,
        recent: vec!["/tmp/a.ron".into()],
        ..Session::default()
    };
    let text = ron::to_string(&session).expect("serialise");
    let back: Session = ron::from_str(&text).expect("deserialise");
    assert_eq!(back, session);
    // Missing fields take their defaults (the session of an older build).
    let old: Session = ron::from_str("(exposure: -2.0)").expect("old session");
    assert_eq!(old.exposure, -2.0);
    assert_eq!(old.res_scale, Session::default().res_scale);
}

/// The sky thumbnail's lat-long mapping is the renderer's: the inverse of
/// `map_direction`, +z in the middle, +x a quarter of the width from the left, up on top.
#[test]
fn sky_thumbnail_mapping_inverts_the_maps_directions() {
    use lantern::scene::environment::map_direction;
    use lantern::ui::sky::{direction_to_uv, sun_marker_uv};
    for i in 0..16 {
        for j in 1..8 {
            let (u, v) = (i as f32 / 16.0 + 0.01, j as f32 / 8.0);
            let [u2, v2] = direction_to_uv(map_direction(u, v));
            assert!(
                (u - u2).abs() < 1e-4 && (v - v2).abs() < 1e-4,
                "{u} {v}: {u2} {v2}"
            );
        }
    }
    let near = |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).abs() < 1e-5 && (a[1] - b[1]).abs() < 1e-5;
    assert!(near(direction_to_uv(Vec3::Z), [0.5, 0.5]));
    assert!(near(direction_to_uv(Vec3::X), [0.25, 0.5]));
    assert!(near(direction_to_uv(Vec3::NEG_X), [0.75, 0.5]));
    assert!(near(direction_to_uv(Vec3::NEG_Z), [0.0, 0.5]));
    assert_eq!(direction_to_uv(Vec3::Y)[1], 0.0);
    // The marker sits where the light comes from: a sun shining down along
    // −z from 45° above the horizon is marked in the middle, a quarter down.
    let travel = Vec3::new(0.0, -1.0, -1.0).normalize();
    let m = sun_marker_uv(travel).expect("a sun");
    assert!(near(m, [0.5, 0.25]), "{m:?}");
    assert_eq!(sun_marker_uv(Vec3::ZERO), None);
}

/// The thumbnail's lookup is the renderer's bilinear map lookup, rotation
/// included, and a bright texel shows under the marker of its direction.
#[test]
fn sky_thumbnail_agrees_with_the_renderers_lookup_and_rotation() {
    use lantern::physics::environment::EnvMap;
    use lantern::scene::environment::map_direction;
    use lantern::scene::SkyMap;
    use lantern::ui::sky::{direction_to_uv, map_radiance, thumbnail_pixels};
    let (w, h) = (32u32, 16u32);
    let mut texels: Vec<Vec3> = (0..w * h)
        .map(|k| Vec3::new((k % w) as f32 / w as f32, (k / w) as f32 / h as f32, 0.25))
        .collect();
    let env = EnvMap::new(w, h, &texels, 30.0, 1.0);
    let map = SkyMap {
        width: w,
        height: h,
        texels: texels.clone(),
    };
    for k in 0..200 {
        let d = map_direction((k as f32 * 0.618_034).fract(), (k as f32 + 0.5) / 200.0);
        let (a, b) = (map_radiance(&map, 30.0, d), env.radiance(d));
        assert!((a - b).length() < 1e-4, "{d}: {a} against {b}");
    }
    // One bright texel, the map turned by 50°: the brightest thumbnail
    // pixel is where that texel's direction, turned, is marked.
    texels.iter_mut().for_each(|t| *t = Vec3::splat(0.1));
    let (i, j) = (5usize, 6usize);
    texels[j * w as usize + i] = Vec3::splat(100.0);
    let map = SkyMap {
        width: w,
        height: h,
        texels,
    };
    let local = map_direction((i as f32 + 0.5) / w as f32, j as f32 / (h - 1) as f32);
    let world = glam::Quat::from_rotation_y(50f32.to_radians()) * local;
    let size = [128u32, 64u32];
    let pixels = thumbnail_pixels(&map, 50.0, size);
    let brightest = (0..pixels.len())
        .max_by(|&a, &b| pixels[a].x.total_cmp(&pixels[b].x))
        .expect("pixels");
    let at = [
        (brightest % 128) as f32 / 128.0 + 0.5 / 128.0,
        (brightest / 128) as f32 / 64.0 + 0.5 / 64.0,
    ];
    let want = direction_to_uv(world);
    assert!(
        (at[0] - want[0]).abs() < 1.5 / 128.0 && (at[1] - want[1]).abs() < 1.5 / 64.0,
        "brightest at {at:?}, texel turned to {want:?}"
    );
    let bytes = lantern::ui::sky::thumbnail_srgb(&pixels);
    assert_eq!(bytes.len(), 128 * 64 * 3);
}

/// Sky map paths are saved relative to the scene's folder where they can
/// be, with `..` for a sibling folder.
#[test]
fn sky_map_paths_are_saved_relative_to_the_scene() {
    use lantern::scene::{Environment, Scene, Sky};
    use lantern::ui::sky::{relative_path, scene_for_saving};
    let dir = tempfile::tempdir().expect("temp dir");
    let root = std::fs::canonicalize(dir.path()).expect("dir");
    std::fs::create_dir_all(root.join("maps")).expect("maps");
    std::fs::create_dir_all(root.join("scenes/deep")).expect("scenes");
    std::fs::write(root.join("maps/sky.exr"), b"x").expect("map");
    assert_eq!(
        relative_path(&root.join("maps/sky.exr"), &root.join("scenes/deep")),
        std::path::PathBuf::from("../../maps/sky.exr")
    );
    assert_eq!(
        relative_path(&root.join("maps/sky.exr"), &root),
        std::path::PathBuf::from("maps/sky.exr")
    );
    let scene = Scene {
        environment: Some(Environment {
            sky: Sky::Map {
                file: "maps/sky.exr".into(),
                rotation_deg: 10.0,
                scale: 2.0,
            },
            background: true,
        }),
        ..Scene::default()
    };
    // The document's paths refer to `root`; saved into scenes/, the map is
    // one folder up.
    let saved = scene_for_saving(&scene, &root, &root.join("scenes/a.ron"));
    match saved.environment.as_ref().map(|e| &e.sky) {
        Some(Sky::Map {
            file,
            rotation_deg,
            scale,
        }) => {
            assert_eq!(file, &std::path::PathBuf::from("../maps/sky.exr"));
            assert_eq!((*rotation_deg, *scale), (10.0, 2.0));
        }
        other => panic!("{other:?}"),
    }
    // Saved and reopened from there, the scene finds its map.
    let path = root.join("scenes/a.ron");
    saved.save(&path).expect("save");
    let back = Scene::load(&path).expect("load");
    match back.environment.as_ref().map(|e| &e.sky) {
        Some(Sky::Map { file, .. }) => assert!(root.join("scenes").join(file).exists()),
        other => panic!("{other:?}"),
    }
}
