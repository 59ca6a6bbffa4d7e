//! The previewer's logic without a window: EXR export with metadata and
//! layers, the error heatmap's RMSE, camera navigation, the session file.

use glam::Vec3;
use lantern::scene::Camera;
use lantern::scene::Method;
use lantern::ui::app::{CompareMode, Session};
use lantern::ui::backend::StreamImage;
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
