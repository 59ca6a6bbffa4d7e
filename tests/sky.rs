//! The sky (issue 24): scene files with an environment, white-furnace
//! tests of both methods under a constant sky, and single scattering of an
//! environment map against quadrature.

mod common;

use common::{mean_stderr, sphere};

use std::sync::Arc;

use glam::Vec3;
use lantern::physics::environment::{EnvMap, Environment, EnvironmentKind};
use lantern::physics::lights::Lights;
use lantern::physics::phase::hg;
use lantern::physics::reference::radiance;
use lantern::physics::rng::Rng;
use lantern::physics::volume::Optics;
use lantern::render::PreparedScene;
use lantern::scene::{Environment as SceneEnvironment, Method, Scene, Sky};

/// Chord length of the ray `o + t d` through the sphere of radius `r` at
/// the origin (0 if it misses).
fn chord(o: Vec3, d: Vec3, r: f32) -> f32 {
    let b = o.dot(d);
    let c = o.length_squared() - r * r;
    let disc = b * b - c;
    if disc <= 0.0 {
        0.0
    } else {
        2.0 * disc.sqrt()
    }
}

fn constant_sky(radiance: Vec3, background: bool) -> Lights {
    Lights {
        environment: Some(Arc::new(Environment {
            kind: EnvironmentKind::Constant(radiance),
            background,
        })),
        ..Lights::default()
    }
}

/// White furnace for the reference: a non-absorbing sphere under a
/// uniform sky. Without the background, what the camera sees is exactly
/// the sky's light that the medium scattered, `L (1 − e^{−σ ℓ})` for a chord
/// `ℓ`; with it, the sky itself everywhere.
#[test]
fn reference_furnace() {
    let sky = Vec3::new(1.0, 0.7, 0.4);
    let mut worst = 0.0f32;
    for (sigma, g) in [(2.0f32, 0.0f32), (3.0, 0.6), (1.0, -0.4)] {
        let vol = sphere(
            1.0,
            Optics {
                sigma_t: Vec3::splat(sigma),
                albedo: Vec3::ONE,
                g,
            },
        );
        for (k, (y, background)) in [(0.0f32, false), (0.5, false), (0.85, true), (0.3, true)]
            .into_iter()
            .enumerate()
        {
            let lights = constant_sky(sky, background);
            let origin = Vec3::new(0.1, y, 4.0);
            let dir = Vec3::new(0.0, 0.0, -1.0);
            let mut rng = Rng::for_sample(7, k as u32, (sigma * 10.0) as u32);
            let (est, err) = mean_stderr(40_000, |_| {
                radiance(&vol, &lights, origin, dir, u32::MAX, &mut rng)
            });
            let exact = if background {
                sky
            } else {
                sky * (1.0 - (-sigma * chord(origin, dir, 1.0)).exp())
            };
            for c in 0..3 {
                assert!(
                    (est[c] - exact[c]).abs() < 4.0 * err[c] + 1e-4,
                    "σ {sigma} g {g} y {y} background {background}, channel {c}: {} ± {} vs {}",
                    est[c],
                    err[c],
                    exact[c]
                );
            }
            let rel = ((est - exact).abs() / exact).max_element();
            worst = worst.max(rel);
            assert!((err / exact).max_element() < 0.01, "{err} {exact}");
        }
    }
    println!("reference furnace: largest relative error {worst:.4}");
}

/// A furnace scene: a non-absorbing sphere of optical radius 2 under a
/// uniform sky, 24×24 pixels.
fn furnace_scene(background: bool) -> Scene {
    let text = format!(
        "(
            camera: (eye: (0.0, 0.0, 3.2), target: (0.0, 0.0, 0.0), up: (0.0, 1.0, 0.0),
                     fov_y_deg: 40.0, width: 24, height: 24),
            medium: (
                density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0),
                sigma_t: (2.0, 2.0, 2.0), albedo: (1.0, 1.0, 1.0), g: 0.5,
            ),
            lights: [],
            environment: Some((sky: Constant(radiance: (1.0, 0.7, 0.4)), background: {background})),
            render: (method: Internal, spp: 16, seed: 0),
        )"
    );
    Scene::from_ron(&text, std::path::Path::new("furnace.ron")).unwrap_or_else(|e| panic!("{e}"))
}

/// White furnace for both methods on whole images: with the background,
/// every pixel equals the sky; without it, the scattered part is
/// `L (1 − e^{−σ ℓ})` along each pixel's centre chord (the pixel average
/// over the square differs from it only at the silhouette, which is
/// excluded). The internal lights at their default settings must meet
/// the image mean within 3 %.
#[test]
fn furnace_both_methods() {
    let sky = Vec3::new(1.0, 0.7, 0.4);
    for background in [true, false] {
        let scene = furnace_scene(background);
        let prepared = Arc::new(
            PreparedScene::new(scene, std::path::Path::new(".")).unwrap_or_else(|e| panic!("{e}")),
        );
        let cam = prepared.camera;
        // The expected image (pixel centres), and which pixels are well
        // inside or outside the silhouette.
        let mut expected = Vec::new();
        let mut interior = Vec::new();
        for py in 0..cam.height {
            for px in 0..cam.width {
                let d = cam.ray_dir(px as f32 + 0.5, py as f32 + 0.5);
                let l = chord(cam.eye, d, 1.0);
                // Chords of the pixel's corners: the pixel is uniform if
                // they agree in being inside or not.
                let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
                    .map(|(a, b)| chord(cam.eye, cam.ray_dir(px as f32 + a, py as f32 + b), 1.0));
                let clean = corners.iter().all(|&c| c > 0.3) || corners.iter().all(|&c| c == 0.0);
                expected.push(if background {
                    sky
                } else {
                    sky * (1.0 - (-2.0 * l).exp())
                });
                interior.push(clean && (background || l > 0.3));
            }
        }
        for (method, spp, tol) in [
            (Method::Reference, 256, 0.01f32),
            (Method::Internal, 32, 0.03),
        ] {
            let film = common::render(&prepared, method, 1, spp);
            let img = film.mean();
            let var = film.variance_of_mean();
            let (mut sum_est, mut sum_exp, mut n, mut z_ok) = (Vec3::ZERO, Vec3::ZERO, 0usize, 0);
            for i in 0..img.len() {
                if !interior[i] {
                    continue;
                }
                sum_est += img[i];
                sum_exp += expected[i];
                n += 1;
                let z = ((img[i] - expected[i]).abs() / var[i].max(Vec3::splat(1e-12)).powf(0.5))
                    .max_element();
                z_ok += (z < 4.0) as usize;
            }
            let rel = ((sum_est - sum_exp).abs() / sum_exp).max_element();
            let z_frac = z_ok as f64 / n as f64;
            println!(
                "furnace {method:?} background {background}: mean {:?} vs {:?}, relative \
                 error {rel:.4}, per-pixel |z| < 4 for {:.3} of {n} pixels",
                (sum_est / n as f32).to_array(),
                (sum_exp / n as f32).to_array(),
                z_frac
            );
            assert!(rel < tol, "{method:?} background {background}: {rel}");
            if method == Method::Reference {
                assert!(z_frac > 0.97, "{z_frac}");
            }
        }
    }
}

/// A smooth, coloured map (no sharp features, so that a Fibonacci
/// quadrature of the sphere is accurate).
fn smooth_map() -> EnvMap {
    let (w, h) = (32u32, 16u32);
    let texels: Vec<Vec3> = (0..w * h)
        .map(|k| {
            let (i, j) = ((k % w) as f32, (k / w) as f32);
            let a = (i / w as f32 * std::f32::consts::TAU).cos();
            let b = (j / (h - 1) as f32 * std::f32::consts::PI).cos();
            Vec3::new(1.0 + 0.8 * a, 0.6 + 0.5 * b, 0.3 + 0.25 * a * b) * (1.2 + b)
        })
        .collect();
    EnvMap::new(w, h, &texels, 30.0, 1.0)
}

/// Single scattering of an environment map along a camera ray through a
/// homogeneous sphere (next-event estimation by one-sample MIS between
/// the map and the phase function) against quadrature of
/// `∫ dt T b ∫ dω P L T` in f64.
#[test]
fn map_single_scatter_matches_quadrature() {
    let map = smooth_map();
    let (sigma, albedo, g) = (1.2f32, 0.8f32, 0.5f32);
    let vol = sphere(
        1.0,
        Optics {
            sigma_t: Vec3::splat(sigma),
            albedo: Vec3::splat(albedo),
            g,
        },
    );
    let env = Environment {
        kind: EnvironmentKind::Map(map.clone()),
        background: false,
    };
    let lights = Lights {
        environment: Some(Arc::new(env.clone())),
        ..Lights::default()
    };
    let origin = Vec3::new(0.25, 0.15, 3.0);
    let dir = Vec3::new(-0.02, 0.03, -1.0).normalize();
    let (t0, len) = {
        let b = origin.dot(dir);
        let c = origin.length_squared() - 1.0;
        let disc = (b * b - c).sqrt();
        (-b - disc, 2.0 * disc)
    };
    // Quadrature: midpoint in t, a Fibonacci lattice of directions.
    let (nt, nd) = (64usize, 40_000usize);
    let dirs: Vec<(Vec3, Vec3)> = (0..nd)
        .map(|k| {
            let z = 1.0 - (2 * k + 1) as f32 / nd as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = k as f32 * 2.399_963_2;
            let from = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            (from, env.radiance(from))
        })
        .collect();
    let mut exact = [0.0f64; 3];
    let dw = 4.0 * std::f64::consts::PI / nd as f64;
    for it in 0..nt {
        let t = t0 + (it as f32 + 0.5) / nt as f32 * len;
        let y = origin + dir * t;
        let t_cam = (-(sigma as f64) * (t - t0) as f64).exp();
        let mut s = [0.0f64; 3];
        for (from, l) in &dirs {
            let b = y.dot(*from);
            let c = y.length_squared() - 1.0;
            let exit = -b + (b * b - c).max(0.0).sqrt();
            let w = hg(g, (-*from).dot(-dir)) as f64 * (-(sigma as f64) * exit as f64).exp();
            for ch in 0..3 {
                s[ch] += w * l[ch] as f64;
            }
        }
        for ch in 0..3 {
            exact[ch] += t_cam * (sigma * albedo) as f64 * s[ch] * dw * len as f64 / nt as f64;
        }
    }
    let exact = Vec3::new(exact[0] as f32, exact[1] as f32, exact[2] as f32);
    let mut rng = Rng::for_sample(21, 0, 0);
    let (est, err) = mean_stderr(400_000, |_| {
        radiance(&vol, &lights, origin, dir, 1, &mut rng)
    });
    println!("map single scatter: {est} ± {err} vs quadrature {exact}");
    for c in 0..3 {
        assert!(
            (est[c] - exact[c]).abs() < 4.0 * err[c] + 2e-3 * exact[c],
            "channel {c}: {} ± {} vs {}",
            est[c],
            err[c],
            exact[c]
        );
    }
    assert!((err / exact).max_element() < 0.01, "{err} {exact}");
}

/// A scene file with each kind of sky parses, validates and prepares;
/// written back it reads the same; scenes without an environment still
/// load (the field is optional) and have no sky.
#[test]
fn scene_files_with_a_sky() {
    let dir = tempfile::tempdir().expect("tempdir");
    {
        use exr::prelude::*;
        let channels =
            SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| (x as f32 / 8.0, 0.5, y as f32 / 4.0));
        Image::from_channels((8, 4), channels)
            .write()
            .to_file(dir.path().join("sky.exr"))
            .expect("write exr");
    }
    for sky in [
        "Constant(radiance: (0.3, 0.4, 0.5))",
        "Map(file: \"sky.exr\", rotation_deg: 45.0, scale: 2.0)",
        "Map(file: \"sky.exr\")",
        "ClearSky(turbidity: 3.0)",
    ] {
        let text = format!(
            "(
                camera: (eye: (0.0, 0.0, 3.0), target: (0.0, 0.0, 0.0), up: (0.0, 1.0, 0.0),
                         fov_y_deg: 40.0, width: 8, height: 8),
                medium: (density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0),
                         sigma_t: (1.0, 1.0, 1.0), albedo: (0.9, 0.9, 0.9), g: 0.3),
                lights: [Sun(direction: (0.3, -1.0, 0.2), irradiance: (3.0, 3.0, 3.0))],
                environment: Some((sky: {sky})),
            )"
        );
        let path = dir.path().join("scene.ron");
        let scene = Scene::from_ron(&text, &path).unwrap_or_else(|e| panic!("{sky}: {e}"));
        let again = Scene::from_ron(&scene.to_ron().expect("ron"), &path).expect("reads back");
        assert_eq!(scene, again);
        let prepared = PreparedScene::new(scene, dir.path()).unwrap_or_else(|e| panic!("{e}"));
        let env = prepared.lights.environment.as_ref().expect("a sky");
        assert!(!env.background);
        assert!(!env.is_black(), "{sky}");
    }
    let old = common::prepare("assets/scenes/thin_sphere.ron");
    assert!(old.scene.environment.is_none() && old.lights.environment.is_none());
}

/// Bad skies in scene files: the error names the scene or the map file
/// and the problem; a missing map fails at load, not at render.
#[test]
fn bad_skies_are_refused_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene_with = |sky: &str, lights: &str| {
        format!(
            "(
                camera: (eye: (0.0, 0.0, 3.0), target: (0.0, 0.0, 0.0), up: (0.0, 1.0, 0.0),
                         fov_y_deg: 40.0, width: 8, height: 8),
                medium: (density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0),
                         sigma_t: (1.0, 1.0, 1.0), albedo: (0.9, 0.9, 0.9), g: 0.3),
                lights: [{lights}],
                environment: Some((sky: {sky})),
            )"
        )
    };
    let path = dir.path().join("bad.ron");
    let sun = "Sun(direction: (0.3, -1.0, 0.2), irradiance: (3.0, 3.0, 3.0))";
    for (sky, lights, want) in [
        (
            "Constant(radiance: (-1.0, 0.0, 0.0))",
            sun,
            "Constant.radiance",
        ),
        ("Map(file: \"sky.exr\", scale: -2.0)", sun, "Map.scale"),
        ("ClearSky(turbidity: 30.0)", sun, "turbidity"),
        ("ClearSky()", "", "no Sun"),
        ("Cubemap(file: \"x\")", sun, "Cubemap"),
    ] {
        let e = match Scene::from_ron(&scene_with(sky, lights), &path) {
            Ok(_) => panic!("{sky} accepted"),
            Err(e) => format!("{:#}", anyhow::Error::from(e)),
        };
        assert!(e.contains("bad.ron") && e.contains(want), "{sky}: {e}");
    }
    let scene = Scene::from_ron(&scene_with("Map(file: \"absent.hdr\")", sun), &path).expect("ok");
    let e = match PreparedScene::new(scene, dir.path()) {
        Ok(_) => panic!("a missing map was accepted"),
        Err(e) => format!("{:#}", anyhow::Error::from(e)),
    };
    assert!(e.contains("absent.hdr"), "{e}");
    let _ = SceneEnvironment {
        sky: Sky::Constant {
            radiance: Vec3::ONE,
        },
        background: true,
    };
}

/// The internal lights' own `S₁` holds the sky's share
/// (`physics::internal::sources::sky_arrival`): over the 64 lights of the furnace
/// sphere (optical radius 2, `g` 0.5, so the sky's light at a light falls
/// off towards the sphere's far side), each towards its own direction,
/// `eval_s1` sums to what many one-sample estimates of the sky's
/// single-scatter source at the same points and directions sum to, within
/// 3 % (the harmonics' truncation) and the noise of both (each light's
/// harmonics come from 256 directions: ±9–13 % per light).
#[test]
fn internal_lights_s1_holds_the_sky() {
    let mut scene = furnace_scene(false);
    scene.render.internal.knobs.lights = 64;
    scene.render.internal.expert.walks = 256;
    scene.render.internal.expert.view_share = 0.0;
    let prepared = PreparedScene::new(scene, std::path::Path::new(".")).unwrap();
    let lights = common::build_lights(&prepared, &prepared.scene.render);
    let env = prepared.lights.sky().expect("a sky");
    let mut rng = Rng::for_sample(9, 0, 0);
    let scatter = prepared.volume.optics.albedo * prepared.volume.optics.sigma_t;
    let (mut got, mut want, mut var) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    let mut per_light = Vec::new();
    for (i, light) in lights.lights.iter().enumerate() {
        let n = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        )
        .normalize();
        let s1 = lights.eval_s1(i, n);
        let (w, e) = mean_stderr(4_000, |_| {
            lantern::physics::reference::environment_source(
                &prepared.volume,
                env,
                light.position,
                n,
                lantern::physics::tracking::Transmittance::RATIO,
                &mut rng,
            ) * scatter
                * light.density
        });
        per_light.push((s1 / w).x);
        got += s1;
        want += w;
        var += e * e;
    }
    let err = var.powf(0.5);
    // The lights' own noise, from their spread about the sources.
    let m = per_light.iter().sum::<f32>() / per_light.len() as f32;
    let spread = (per_light.iter().map(|r| (r - m).powi(2)).sum::<f32>()
        / (per_light.len() - 1) as f32)
        .sqrt();
    let own = want * (spread / (per_light.len() as f32).sqrt());
    println!(
        "Σ eval_s1 {got} against Σ sky source {want} ± {err}; per light eval/source {m:.3} ± {spread:.3}"
    );
    for c in 0..3 {
        assert!(
            (got[c] - want[c]).abs() < 0.03 * want[c] + 4.0 * (err[c] + own[c]),
            "channel {c}: {} against {} ± {} (lights ± {})",
            got[c],
            want[c],
            err[c],
            own[c]
        );
    }
    assert!(lights.term_energy[0].min_element() > 0.0);
}
