//! The scene suite of `assets/scenes/suite/` (issue 21): each scene holds
//! what its comment claims about it. The optical depths are integrated
//! here from the loaded density (the procedural clouds baked as the
//! renderers bake them), so a change of a scene's knobs that takes it out
//! of its class (thin smoke no longer thin, the cumulus's core no longer
//! 50 mean free paths deep) fails this test. `cargo test --release --test
//! suite_scenes -- --nocapture` prints the measured numbers.

mod common;

use glam::Vec3;
use lantern::render::PreparedScene;
use lantern::scene::Light;

/// The suite, in the order of the issue (and the sky-lit plume of the sky
/// issue after it).
const SUITE: [&str; 7] = [
    "wispy_smoke",
    "smoke_plume",
    "thick_cumulus",
    "thick_sphere_front_lit",
    "chromatic",
    "point_lit",
    "sky_lit_plume",
];

/// `∫ ρ dℓ` along `origin + t·dir` (unit `dir`) over the medium's box,
/// by the midpoint rule with steps of `step`.
fn density_integral(p: &PreparedScene, origin: Vec3, dir: Vec3, step: f32) -> f32 {
    let Some((t0, t1)) = p.volume.clip(origin, dir) else {
        return 0.0;
    };
    let n = ((t1 - t0) / step).ceil().max(1.0) as usize;
    let dt = (t1 - t0) / n as f32;
    (0..n)
        .map(|i| {
            p.volume
                .density
                .density(origin + dir * (t0 + (i as f32 + 0.5) * dt))
        })
        .sum::<f32>()
        * dt
}

/// What is measured of one scene. Optical depths are of the largest
/// channel of `σ_t` (density scale applied).
#[derive(Debug)]
struct Measured {
    /// The largest optical depth along a camera ray (over a 64² grid of
    /// pixel centres).
    camera_max: f32,
    /// The deepest point: the largest, over a 20³ lattice of points in the
    /// box, of the smallest optical depth from the point out of the medium
    /// over 26 directions (how many mean free paths the core is buried).
    core_depth: f32,
    /// Where that point is.
    core: Vec3,
    /// The full chord through the core along the view direction.
    view_chord: f32,
    /// The full chord through the core along the (first) sun's direction.
    sun_chord: Option<f32>,
}

fn measure(p: &PreparedScene) -> Measured {
    let (lo, hi) = p.volume.bounds;
    let sigma = p.volume.optics.sigma_t.max_element();
    let step = (hi - lo).max_element() / 400.0;
    let cam = p.camera;
    let mut camera_max = 0.0f32;
    for j in 0..64 {
        for i in 0..64 {
            let (px, py) = (
                (i as f32 + 0.5) / 64.0 * cam.width as f32,
                (j as f32 + 0.5) / 64.0 * cam.height as f32,
            );
            let tau = sigma * density_integral(p, cam.eye, cam.ray_dir(px, py), step);
            camera_max = camera_max.max(tau);
        }
    }
    let mut dirs = Vec::new();
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    dirs.push(Vec3::new(x as f32, y as f32, z as f32).normalize());
                }
            }
        }
    }
    let mut core_depth = 0.0f32;
    let mut core = (lo + hi) * 0.5;
    let n = 20;
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let f = (Vec3::new(i as f32, j as f32, k as f32) + 0.5) / n as f32;
                let x = lo + (hi - lo) * f;
                if p.volume.density.density(x) <= 0.0 {
                    continue;
                }
                // From x outwards: the ray starts at x, so the clip keeps
                // only the part in front of it.
                let depth = dirs
                    .iter()
                    .map(|d| sigma * density_integral(p, x, *d, step))
                    .fold(f32::INFINITY, f32::min);
                if depth > core_depth {
                    core_depth = depth;
                    core = x;
                }
            }
        }
    }
    let chord = |d: Vec3| {
        let far = core - d * 10.0 * (hi - lo).length();
        sigma * density_integral(p, far, d, step)
    };
    let view_chord = chord(cam.forward);
    let sun_chord = p.scene.lights.iter().find_map(|l| match l {
        Light::Sun { direction, .. } => Some(chord(direction.normalize())),
        Light::Point { .. } => None,
    });
    Measured {
        camera_max,
        core_depth,
        core,
        view_chord,
        sun_chord,
    }
}

fn load(name: &str) -> (PreparedScene, Measured) {
    let p = common::prepare_with(&format!("assets/scenes/suite/{name}.ron"), |_| {});
    let m = measure(&p);
    let o = &p.volume.optics;
    println!(
        "{name}: σ_t {:?}, albedo {:?}, g {}: camera rays up to {:.2} mfp; core {:.2} mfp deep at {:?}, chord through it {:.2} mfp along the view, {} along the sun",
        o.sigma_t.to_array(),
        o.albedo.to_array(),
        o.g,
        m.camera_max,
        m.core_depth,
        m.core.to_array(),
        m.view_chord,
        m.sun_chord.map_or("-".to_owned(), |t| format!("{t:.2} mfp")),
    );
    (p, m)
}

/// Every suite scene loads and is 128² (the size of its converged
/// reference in `tests/data/suite/`).
#[test]
fn suite_scenes_load_at_128() {
    for name in SUITE {
        let (p, _) = load(name);
        assert_eq!((p.camera.width, p.camera.height), (128, 128), "{name}");
    }
}

/// Wispy smoke is thin: no camera ray crosses more than 2 mean free
/// paths, but it is not empty either.
#[test]
fn wispy_smoke_is_thin() {
    let (_, m) = load("wispy_smoke");
    assert!(m.camera_max <= 2.0 && m.camera_max >= 0.5, "{m:?}");
}

/// The smoke plume is dense: 5 to 15 mean free paths through its core
/// along the view, albedo 0.8–0.95.
#[test]
fn smoke_plume_is_dense_smoke() {
    let (p, m) = load("smoke_plume");
    assert!((5.0..=15.0).contains(&m.view_chord), "{m:?}");
    let a = p.volume.optics.albedo;
    assert!(a.min_element() >= 0.8 && a.max_element() <= 0.95, "{a:?}");
}

/// The cumulus's core is at least 50 mean free paths deep along the view
/// and along the sun, at albedo ≥ 0.999 and g ≈ 0.85.
#[test]
fn thick_cumulus_core_is_fifty_mean_free_paths_deep() {
    let (p, m) = load("thick_cumulus");
    assert!(m.view_chord >= 50.0, "{m:?}");
    assert!(m.sun_chord.is_some_and(|t| t >= 50.0), "{m:?}");
    let o = &p.volume.optics;
    assert!(o.albedo.min_element() >= 0.999, "{o:?}");
    assert!((o.g - 0.85).abs() <= 0.02, "{o:?}");
}

/// The thick sphere: optical radius 8–12, g 0.5, lit by a sun that
/// arrives from behind the camera (it travels along the view within 30°).
#[test]
fn thick_sphere_is_lit_from_the_camera_side() {
    let (p, m) = load("thick_sphere_front_lit");
    let radius = 0.5 * m.view_chord;
    assert!((8.0..=12.0).contains(&radius), "{m:?}");
    assert!((p.volume.optics.g - 0.5).abs() < 1e-6);
    let sun = p.lights.suns.first().expect("a sun");
    assert!(sun.direction.dot(p.camera.forward) >= 30f32.to_radians().cos());
}

/// The chromatic medium's extinction differs by at least a factor 2
/// between its channels, and its densest puff is neither thin nor opaque
/// in any channel.
#[test]
fn chromatic_medium_differs_per_channel() {
    let (p, m) = load("chromatic");
    let s = p.volume.optics.sigma_t;
    assert!(s.max_element() >= 2.0 * s.min_element(), "{s:?}");
    let thinnest = m.view_chord * s.min_element() / s.max_element();
    assert!(thinnest >= 1.0 && m.view_chord <= 20.0, "{m:?}");
}

/// The point light sits just outside the medium's box, where `ρ = 0`, so
/// that next-event estimation to it has a bounded variance (inside, even
/// in a gap of `ρ` ≈ 0.01, a collision arbitrarily close to the light
/// makes the variance infinite), with medium of `ρ > 0.2` within half a
/// unit of it.
#[test]
fn point_light_is_just_outside_the_medium() {
    let (p, _) = load("point_lit");
    let light = p.lights.points.first().expect("a point light");
    let (lo, hi) = p.volume.bounds;
    let x = light.position;
    let outside = (lo - x).max(x - hi).max_element();
    println!("point_lit: the light is {outside:.3} outside the medium's box");
    assert!(
        (0.02..=0.2).contains(&outside),
        "{x:?} is {outside} outside"
    );
    // Points on spheres of radius 0.1 to 0.5 around the light (Fibonacci
    // directions).
    let densest = |radius: f32| {
        (0..200)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 200.0;
                let phi = i as f32 * 2.399_963;
                let r = (1.0 - z * z).sqrt();
                let d = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                p.volume.density.density(x + d * radius)
            })
            .fold(0.0f32, f32::max)
    };
    assert!(densest(0.2) < 0.02, "{}", densest(0.2));
    assert!(densest(0.5) > 0.2, "no medium within 0.5 of the light");
}

/// The Mitsuba 3 cross-check's copies of two suite scenes
/// (`tests/data/mitsuba/suite_*.ron`, written by
/// `tests/mitsuba/make_references.py` at 48²) are those scenes but for the
/// image size: camera, optics, lights and the density grid itself.
#[test]
fn mitsuba_copies_are_the_suite_scenes() {
    use lantern::scene::Density;
    for (suite, copy) in [
        ("chromatic", "suite_chromatic"),
        ("point_lit", "suite_point_lit"),
    ] {
        let a = common::prepare_with(&format!("assets/scenes/suite/{suite}.ron"), |_| {});
        let b = common::prepare_with(&format!("tests/data/mitsuba/{copy}.ron"), |_| {});
        let (ca, cb) = (&a.scene.camera, &b.scene.camera);
        assert_eq!(
            (ca.eye, ca.target, ca.up, ca.fov_y_deg),
            (cb.eye, cb.target, cb.up, cb.fov_y_deg),
            "{suite}"
        );
        assert_eq!(a.volume.optics, b.volume.optics, "{suite}");
        assert_eq!(a.volume.bounds, b.volume.bounds, "{suite}");
        let close = |x: Vec3, y: Vec3| (x - y).abs().max_element() < 1e-6;
        let (la, lb) = (&a.lights, &b.lights);
        assert_eq!(
            (la.suns.len(), la.points.len()),
            (lb.suns.len(), lb.points.len())
        );
        for (x, y) in la.suns.iter().zip(&lb.suns) {
            assert!(close(x.direction, y.direction) && close(x.irradiance, y.irradiance));
        }
        for (x, y) in la.points.iter().zip(&lb.points) {
            assert!(close(x.position, y.position) && close(x.intensity, y.intensity));
        }
        match (&a.volume.density, &b.volume.density) {
            (Density::Grid(x), Density::Grid(y)) => {
                assert_eq!((x.dims, &x.data), (y.dims, &y.data), "{suite}")
            }
            _ => panic!("{suite}: both should be grids"),
        }
    }
}

/// The sky-lit plume is the smoke plume's medium under a sun and the clear
/// sky that follows it, the sky not drawn behind it.
#[test]
fn sky_lit_plume_is_the_plume_under_a_clear_sky() {
    let (sky, _) = load("sky_lit_plume");
    let (plume, _) = load("smoke_plume");
    assert_eq!(sky.scene.medium, plume.scene.medium);
    let env = sky.scene.environment.as_ref().expect("an environment");
    assert!(matches!(env.sky, lantern::scene::Sky::ClearSky { .. }));
    assert!(!env.background);
    assert!(sky.scene.first_sun().is_some());
    assert!(sky.lights.environment.is_some());
}
