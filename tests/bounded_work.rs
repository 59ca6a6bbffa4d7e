//! Never hang, never silently blacken (issue 23): far lights, media denser
//! than the renderers can march, bounds checked before work starts, and
//! warnings for settings that make the picture meaningless.
//!
//! Every case that once hung runs under a time limit here (in a thread, or
//! as a child process that is killed), so that a regression fails instead
//! of stalling the suite.

mod common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{UVec3, Vec3};
use lantern::physics::lights::{Lights, PointLight};
use lantern::render::PreparedScene;
use lantern::scene::{Density, Light, Method, Scene, VoxelGrid};

/// Runs `f` on a thread and fails if it takes longer than `secs`.
fn within<T: Send + 'static>(secs: f64, what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    let start = Instant::now();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    match rx.recv_timeout(Duration::from_secs_f64(secs)) {
        Ok(v) => {
            eprintln!("{what}: {:.2} s", start.elapsed().as_secs_f64());
            v
        }
        Err(_) => panic!("{what} did not finish within {secs} s (a hang)"),
    }
}

/// A 24² sun-lit scene around `density`, `sigma_t` 1, with `edit` applied.
fn scene_with(edit: impl FnOnce(&mut Scene)) -> Scene {
    let text = r#"(
        camera: (eye: (0.0, 0.0, 3.5), target: (0.0, 0.0, 0.0), up: (0.0, 1.0, 0.0), fov_y_deg: 40.0, width: 24, height: 24),
        medium: (
            density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0),
            sigma_t: (1.0, 1.0, 1.0),
            albedo: (0.9, 0.9, 0.9),
            g: 0.5,
        ),
        lights: [Sun(direction: (0.6, -1.0, -0.5), irradiance: (3.0, 3.0, 3.0))],
        render: (method: Reference, spp: 4, seed: 0),
    )"#;
    let mut scene = Scene::from_ron(text, Path::new("test.ron")).unwrap();
    edit(&mut scene);
    scene.validate(Path::new("test.ron")).unwrap();
    scene
}

/// An 8³ grid over [−1, 1]³, zero but for one voxel of `value` at (4, 4, 4).
fn one_dense_voxel(value: f32) -> Density {
    let mut data = vec![0.0f32; 512];
    data[4 + 8 * (4 + 8 * 4)] = value;
    Density::Grid(Arc::new(VoxelGrid {
        dims: UVec3::splat(8),
        bounds_min: Vec3::splat(-1.0),
        bounds_max: Vec3::splat(1.0),
        data,
    }))
}

/// The image mean of `spp` passes of `method`.
fn image_mean(prepared: PreparedScene, method: Method, spp: u32) -> Vec3 {
    let film = common::render(&Arc::new(prepared), method, 3, spp);
    film.image_mean()
}

/// A point light at 3·10¹⁹ once made the internal-lights build (and the
/// reference's shadow rays) track to infinity along a zero direction; at
/// 10¹⁹ it took 0.01 s. Both methods now finish and see the sun.
#[test]
fn a_far_point_light_does_not_hang() {
    for method in [Method::Internal, Method::Reference] {
        let scene = scene_with(|s| {
            s.lights.push(Light::Point {
                position: Vec3::new(3e19, 0.0, 0.0),
                intensity: Vec3::ONE,
            });
            s.render.internal.knobs.lights = 256;
            s.render.internal.expert.walks = 8;
        });
        let mean = within(20.0, &format!("far light, {method:?}"), move || {
            let prepared = PreparedScene::new(scene, Path::new(".")).unwrap();
            image_mean(prepared, method, 1)
        });
        assert!(mean.min_element() > 0.0, "{method:?}: {mean}");
    }
}

/// The light from a far point light is exact at any finite position: the
/// direction and the `I/d²` of a light at 3·10¹⁹ with an intensity of
/// 10³⁸ (which f32 can hold), where `|v|²` overflows.
#[test]
fn far_point_lights_deliver_their_inverse_square_irradiance() {
    for x in [3e19f32, -2e20, 1e30, 3e38] {
        let lights = Lights {
            suns: vec![],
            points: vec![PointLight {
                position: Vec3::new(x, x * 0.5, 0.0),
                intensity: Vec3::splat(1e38),
            }],
            environment: None,
        };
        let p = Vec3::new(0.1, 0.2, 0.3);
        let mut samples = Vec::new();
        lights.for_each_at(p, |l| samples.push(l));
        let l = samples[0];
        let v = p.as_dvec3() - glam::DVec3::new(x as f64, x as f64 * 0.5, 0.0);
        let d = v.length();
        let travel = (v / d).as_vec3();
        assert!(
            (l.travel - travel).length() < 1e-6,
            "{x}: {} vs {travel}",
            l.travel
        );
        assert!(l.distance.is_finite() && l.distance > 0.0, "{x}");
        if d < f32::MAX as f64 {
            assert!(((l.distance as f64 - d) / d).abs() < 1e-6, "{x}");
        }
        let e = 1e38 / (d * d);
        assert!(
            ((l.irradiance.x as f64 - e) / e.max(1e-45)).abs() < 1e-5 || e < 1e-37,
            "{x}: {} vs {e}",
            l.irradiance.x
        );
    }
}

/// One voxel of 10⁶ (and of 10⁸) in an 8³ grid: tracking took
/// `σ_t · length` null collisions per ray (19 s, and over 25 s, instead of
/// 0.02 s). Now clamped to `MAX_DEPTH_PER_VOXEL`, both methods finish at
/// once, the voxel is seen, and `PreparedScene::dense` says what was done.
#[test]
fn a_dense_voxel_renders_at_once() {
    for value in [1e6f32, 1e8] {
        for method in [Method::Reference, Method::Internal] {
            let mean = within(8.0, &format!("voxel {value:e}, {method:?}"), move || {
                let mut scene = scene_with(|s| {
                    s.camera.width = 32;
                    s.camera.height = 32;
                    s.render.internal.knobs.lights = 512;
                    s.render.internal.expert.walks = 8;
                });
                scene.render.method = method;
                let prepared = PreparedScene::with_density(scene, one_dense_voxel(value));
                let note = prepared.dense.expect("the clamp is reported");
                assert!(note.peak >= value as f64 && note.limit < note.peak);
                assert!(note.to_string().contains("opaque"), "{note}");
                image_mean(prepared, method, 8)
            });
            assert!(mean.min_element() > 0.0, "{value:e} {method:?}: {mean}");
        }
    }
}

/// `density_scale` 10²⁰ once overflowed spectral tracking's probabilities
/// and gave a black image. The sphere is opaque either way, so it must
/// look like the same sphere at 10³ (a mean free path of a thousandth of
/// its radius, below the clamp): image means within 5 % (measured 0.6 %).
#[test]
fn an_extreme_density_scale_renders_as_an_opaque_surface() {
    let render = |scale: f32| {
        let scene = scene_with(|s| s.medium.density_scale = scale);
        let prepared = PreparedScene::new(scene, Path::new(".")).unwrap();
        image_mean(prepared, Method::Reference, 64)
    };
    let dense = within(30.0, "density_scale 1e20", move || render(1e20));
    let opaque = render(1e3);
    assert!(opaque.x > 0.01, "{opaque}");
    let ratio = dense / opaque;
    eprintln!("image mean at density_scale 1e20: {dense}, at 1e3: {opaque}");
    assert!(
        (ratio - Vec3::ONE).abs().max_element() < 0.05,
        "1e20: {dense}, 1e3: {opaque}"
    );
}

/// A medium within the limit is not changed at all (the clamp touches only
/// what is denser than `MAX_DEPTH_PER_VOXEL`).
#[test]
fn media_within_the_limit_are_untouched() {
    let scene = scene_with(|_| {});
    let p = PreparedScene::with_density(scene, one_dense_voxel(10.0));
    assert!(p.dense.is_none());
    assert_eq!(p.volume.optics.sigma_t, Vec3::ONE);
    let Density::Grid(g) = &p.volume.density else {
        panic!("a grid")
    };
    assert_eq!(g.max_value(), 10.0);
}

// ---------------------------------------------------------------------------
// The command line: bounds before work, warnings.

fn lantern() -> Command {
    Command::new(env!("CARGO_BIN_EXE_lantern"))
}

/// Runs `lantern ARGS` in `dir`; kills it after `secs`.
fn run(dir: &Path, args: &[&str], secs: f64) -> (bool, String, String) {
    let mut child = lantern()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let out = child.wait_with_output().unwrap();
            return (
                status.success(),
                String::from_utf8_lossy(&out.stdout).into_owned(),
                String::from_utf8_lossy(&out.stderr).into_owned(),
            );
        }
        if start.elapsed().as_secs_f64() > secs {
            let _ = child.kill();
            let _ = child.wait();
            panic!("lantern {args:?} ran past {secs} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Starts `lantern ARGS` and waits up to `secs` for a line of its standard
/// error containing `needle`; then kills it. Returns that line.
fn first_line_with(dir: &Path, args: &[&str], needle: &str, secs: u64) -> String {
    let mut child = lantern()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    let needle = needle.to_owned();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.contains(&needle) {
                let _ = tx.send(line);
                return;
            }
        }
    });
    let got = rx.recv_timeout(Duration::from_secs(secs));
    let _ = child.kill();
    let _ = child.wait();
    got.unwrap_or_else(|_| panic!("no line with the warning within {secs} s: {args:?}"))
}

fn scene_dir(scene: &Scene) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    scene.save(&dir.path().join("scene.ron")).unwrap();
    dir
}

/// `lantern render /dev/zero` read without end (4 GB in 10 s).
#[cfg(unix)]
#[test]
fn an_endless_scene_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, _, err) = run(dir.path(), &["render", "/dev/zero", "--out", "x.exr"], 10.0);
    assert!(!ok);
    assert!(err.contains("/dev/zero") && err.contains("MiB"), "{err}");
}

/// The largest accepted image once aborted with an allocation failure on a
/// 24 GB machine; now refused before rendering, with the estimate. (Where
/// more memory is available the render would go ahead, so this case only
/// runs where it does not fit.)
#[test]
fn an_image_too_large_for_memory_is_refused_before_rendering() {
    let side = lantern::scene::MAX_IMAGE_SIDE;
    let need = side as u64 * side as u64 * lantern::render::limits::BYTES_PER_PIXEL;
    match lantern::render::limits::available_memory() {
        Some(have) if have < need => {}
        other => {
            eprintln!("skipped: {other:?} bytes available, a {side}² render fits");
            return;
        }
    }
    let scene = scene_with(|s| {
        s.camera.width = side;
        s.camera.height = side;
    });
    let dir = scene_dir(&scene);
    let (ok, _, err) = run(dir.path(), &["render", "scene.ron", "--out", "x.exr"], 30.0);
    assert!(!ok);
    assert!(
        err.contains("16384×16384") && err.contains("GiB") && !err.contains("backtrace"),
        "{err}"
    );
}

/// `--threads 10000` created threads until the machine crawled.
#[test]
fn thread_counts_beyond_the_cores_are_refused() {
    let dir = scene_dir(&scene_with(|_| {}));
    let (ok, _, err) = run(
        dir.path(),
        &[
            "render",
            "scene.ron",
            "--out",
            "x.exr",
            "--threads",
            "10000",
        ],
        20.0,
    );
    assert!(!ok);
    assert!(
        err.contains("--threads 10000") && err.contains("cores"),
        "{err}"
    );
}

/// 20,000 suns ran without a word; now refused with the cost.
#[test]
fn thousands_of_lights_are_refused() {
    let mut scene = scene_with(|_| {});
    let sun = scene.lights[0].clone();
    scene.lights = vec![sun; 20_000];
    let e = scene
        .validate(Path::new("suns.ron"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("suns.ron") && e.contains("20000"), "{e}");
}

/// `--spp 4294967295` and the largest `M` and `K` ran without any
/// estimate; now a warning with one comes before (or, for the passes,
/// right after the first) the work.
#[test]
fn long_renders_are_announced_with_an_estimate() {
    let dir = scene_dir(&scene_with(|_| {}));
    let line = first_line_with(
        dir.path(),
        &[
            "render",
            "scene.ron",
            "--out",
            "x.exr",
            "--spp",
            "4294967295",
        ],
        "passes will take about",
        30,
    );
    assert!(line.contains("4294967295 passes will take about"), "{line}");
    let line = first_line_with(
        dir.path(),
        &[
            "render",
            "scene.ron",
            "--out",
            "x.exr",
            "--method",
            "internal",
            "--lights",
            "1048576",
            "--walks",
            "65536",
        ],
        "gated walks",
        30,
    );
    assert!(line.contains("M × K") && line.contains("hours"), "{line}");
}

/// `--s-star 1e-30` or `1e30` and `--kernel-radius 1e30` gave a near-black
/// image without a word.
#[test]
fn meaningless_windows_and_kernels_are_warned_about() {
    let dir = scene_dir(&scene_with(|s| {
        s.camera.width = 8;
        s.camera.height = 8;
        s.render.spp = 1;
        s.render.internal.knobs.lights = 256;
        s.render.internal.expert.walks = 4;
    }));
    for (flag, value, words) in [
        ("--s-star", "1e-30", "far shorter than a voxel"),
        ("--s-star", "1e30", "far longer than the medium"),
        ("--kernel-radius", "1e30", "wider than the medium"),
    ] {
        let (ok, _, err) = run(
            dir.path(),
            &[
                "render",
                "scene.ron",
                "--out",
                "x.exr",
                "--method",
                "internal",
                flag,
                value,
            ],
            60.0,
        );
        assert!(ok, "{err}");
        assert!(
            err.contains("warning") && err.contains(words),
            "{flag} {value}: {err}"
        );
    }
}

/// A volume path that is a folder said "the file name has no extension".
#[test]
fn a_volume_path_that_is_a_folder_says_so() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("clouds")).unwrap();
    let e = lantern::scene::volume::load_grid(
        &dir.path().join("clouds"),
        lantern::scene::GridFormat::Auto,
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("clouds") && e.contains("is a folder"), "{e}");
}

/// `lantern converge --converged bad.exr` said "cannot read X: cannot read
/// X" and never explained the variance file it needs.
#[test]
fn converge_explains_a_bad_or_lonely_converged_image() {
    let dir = scene_dir(&scene_with(|_| {}));
    std::fs::write(dir.path().join("bad.exr"), b"not an exr").unwrap();
    let args = |file: &'static str| {
        [
            "converge",
            "scene.ron",
            "--size",
            "8",
            "--budget",
            "0.01",
            "--converged",
            file,
            "--out",
            "out",
        ]
    };
    let (ok, _, err) = run(dir.path(), &args("bad.exr"), 20.0);
    assert!(!ok);
    assert_eq!(err.matches("cannot read").count(), 1, "{err}");
    assert!(err.contains("bad.exr"), "{err}");
    // A good converged image without its variance file.
    let pixels = vec![Vec3::ONE; 64];
    lantern::render::export::write_exr(&dir.path().join("good.exr"), 8, 8, &pixels).unwrap();
    let (ok, _, err) = run(dir.path(), &args("good.exr"), 20.0);
    assert!(!ok);
    assert!(
        err.contains("converged_var.exr") && err.contains("variance"),
        "{err}"
    );
}
