//! Every writer of the library on a "full disk" (issue 23): this test
//! binary lowers its own file-size limit (`RLIMIT_FSIZE`, with `SIGXFSZ`
//! ignored) so that any write past a few hundred bytes fails with `EFBIG`,
//! then writes over existing files with each writer: image export (EXR,
//! PNG), the previewer's EXR export with layers and its screenshot, scene
//! save, the session, exported grids (raw and `.vol`) and plots. Each must
//! fail, name the file, say it was kept, and leave the old bytes and no
//! temporary file.
//!
//! One test in its own binary: the limit is process-wide, and no other
//! test may write while it is lowered.

#![cfg(unix)]

use std::path::Path;

use glam::{UVec3, Vec3};
use lantern::render::export::{write_exr, write_png};
use lantern::render::plot::{Plot, Series};
use lantern::render::tonemap::ViewTransform;
use lantern::scene::volume::{write_mitsuba_vol, write_raw};
use lantern::scene::{Scene, VoxelGrid};
use lantern::ui::app::Session;
use lantern::ui::files;

/// The file-size limit while writing, in bytes.
const LIMIT: u64 = 200;

fn old_bytes() -> Vec<u8> {
    (0..3000u32).map(|i| (i * 13 % 253) as u8).collect()
}

fn set_limit(bytes: libc::rlim_t) {
    let lim = libc::rlimit {
        rlim_cur: bytes,
        rlim_max: libc::RLIM_INFINITY,
    };
    // SAFETY: plain system calls on this process's own limits.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        assert_eq!(libc::setrlimit(libc::RLIMIT_FSIZE, &lim), 0);
    }
}

#[test]
fn every_writer_keeps_the_previous_file_on_a_full_disk() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let names = [
        "image.exr",
        "image.png",
        "layers.exr",
        "shot.png",
        "scene.ron",
        "session.ron",
        "grid.ron",
        "grid.raw",
        "grid.vol",
        "plot.png",
    ];
    for n in names {
        std::fs::write(d.join(n), old_bytes()).unwrap();
    }
    let pixels: Vec<Vec3> = (0..64 * 64)
        .map(|i| Vec3::new(i as f32, (i * 7 % 13) as f32, 0.5))
        .collect();
    let data: Vec<f32> = (0..512).map(|i| i as f32).collect();
    let grid = VoxelGrid {
        dims: UVec3::splat(8),
        bounds_min: Vec3::ZERO,
        bounds_max: Vec3::ONE,
        data,
    };
    let mut scene = Scene::default();
    scene.camera.width = 77;
    let session = Session {
        recent: (0..50)
            .map(|i| format!("/some/long/path/{i}.ron").into())
            .collect(),
        ..Session::default()
    };
    let shot: Vec<eframe::egui::Color32> = (0..4096u32)
        .map(|i| eframe::egui::Color32::from_rgb((i % 251) as u8, (i * 7 % 253) as u8, 9))
        .collect();
    let image = eframe::egui::ColorImage::new([64, 64], shot);
    let mut plot = Plot::new("p", "x", "y", false);
    plot.add(Series::new(
        "s",
        [1.0, 0.0, 0.0],
        vec![(0.0, 1.0), (1.0, 2.0)],
    ));

    set_limit(LIMIT as libc::rlim_t);
    let results: Vec<(&str, Result<(), String>)> = vec![
        (
            "image.exr",
            write_exr(&d.join("image.exr"), 64, 64, &pixels).map_err(|e| e.to_string()),
        ),
        (
            "image.png",
            write_png(
                &d.join("image.png"),
                64,
                64,
                &pixels,
                0.0,
                ViewTransform::Clamp,
            )
            .map_err(|e| e.to_string()),
        ),
        (
            "layers.exr",
            files::write_exr_with_metadata(
                &d.join("layers.exr"),
                64,
                64,
                &pixels,
                &[("single", &pixels)],
                &[("lantern/M".into(), "4096".into())],
            ),
        ),
        (
            "shot.png",
            files::save_screenshot(&d.join("shot.png"), &image),
        ),
        (
            "scene.ron",
            scene.save(&d.join("scene.ron")).map_err(|e| e.to_string()),
        ),
        ("session.ron", session.save(&d.join("session.ron"))),
        (
            "grid.raw",
            write_raw(&d.join("grid.ron"), &grid).map_err(|e| e.to_string()),
        ),
        (
            "grid.vol",
            write_mitsuba_vol(&d.join("grid.vol"), &grid).map_err(|e| e.to_string()),
        ),
        (
            "plot.png",
            plot.save(&d.join("plot.png")).map_err(|e| format!("{e:#}")),
        ),
    ];
    set_limit(libc::RLIM_INFINITY);

    for (name, result) in results {
        let e = result.expect_err(&format!("{name}: the write cannot succeed"));
        assert!(
            e.contains(name) && e.contains("kept unchanged"),
            "{name}: the message must name it and say it was kept: {e}"
        );
    }
    for n in names {
        assert_eq!(
            std::fs::read(d.join(n)).unwrap(),
            old_bytes(),
            "{n} was changed"
        );
    }
    let leftovers: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name())
        .filter(|n| n.to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // With room again, each writes.
    write_exr(&d.join("image.exr"), 64, 64, &pixels).unwrap();
    scene.save(&d.join("scene.ron")).unwrap();
    session.save(&d.join("session.ron")).unwrap();
    assert_eq!(Session::load(&d.join("session.ron")), Some(session));
    assert_eq!(Scene::load(&d.join("scene.ron")).unwrap().camera.width, 77);
    assert!(Path::new(&d.join("image.exr")).exists());
}
