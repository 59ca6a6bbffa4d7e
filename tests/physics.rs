//! Physics against mathematics: single scattering in a homogeneous sphere
//! against a numerical integral, and energy conservation with albedo 1.

mod common;

use common::{mean_stderr, sphere};
use glam::Vec3;
use lantern::physics::lights::{Lights, PointLight, Sun};
use lantern::physics::phase::hg;
use lantern::physics::reference::radiance;
use lantern::physics::rng::Rng;
use lantern::physics::volume::Optics;

/// Distance from `p` (inside the unit-radius-R sphere at the origin) to its
/// boundary along `dir`.
fn exit_distance(p: [f64; 3], dir: [f64; 3], r: f64) -> f64 {
    let b = p[0] * dir[0] + p[1] * dir[1] + p[2] * dir[2];
    let c = p[0] * p[0] + p[1] * p[1] + p[2] * p[2] - r * r;
    -b + (b * b - c).max(0.0).sqrt()
}

/// Single scatter along a camera ray through a homogeneous, chromatic
/// sphere lit by a sun and a point light, against composite Simpson
/// quadrature of `∫ T b (P T E) dt` in f64.
#[test]
fn single_scatter_matches_quadrature() {
    let radius = 1.0f64;
    let sigma = [0.7f64, 1.4, 2.5];
    let albedo = [0.9f64, 0.8, 0.6];
    let g = 0.4f64;
    let sun_dir = Vec3::new(0.5, -0.8, 0.3).normalize();
    let sun_e = 2.0f64;
    let point_pos = Vec3::new(1.6, 0.2, 0.5);
    let point_i = 3.0f64;
    let vol = sphere(
        radius as f32,
        Optics {
            sigma_t: Vec3::new(sigma[0] as f32, sigma[1] as f32, sigma[2] as f32),
            albedo: Vec3::new(albedo[0] as f32, albedo[1] as f32, albedo[2] as f32),
            g: g as f32,
        },
    );
    let lights = Lights {
        suns: vec![Sun {
            direction: sun_dir,
            irradiance: Vec3::splat(sun_e as f32),
        }],
        points: vec![PointLight {
            position: point_pos,
            intensity: Vec3::splat(point_i as f32),
        }],
        environment: None,
    };
    // Camera ray off-centre so that the geometry is not symmetric.
    let origin = Vec3::new(0.2, 0.3, 3.0);
    let dir = Vec3::new(-0.05, -0.08, -1.0).normalize();
    // The chord through the sphere itself (the volume's box is larger).
    let (t0, t1) = {
        let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
        let b = o.dot(d);
        let c = o.length_squared() - radius * radius;
        let disc = (b * b - c).sqrt();
        ((-b - disc) as f32, (-b + disc) as f32)
    };

    let exact: [f64; 3] = std::array::from_fn(|c| {
        let n = 4000;
        let (a, b) = (t0 as f64, t1 as f64);
        let h = (b - a) / n as f64;
        let o = origin.as_dvec3();
        let d = dir.as_dvec3();
        let ws = sun_dir.as_dvec3();
        let f = |t: f64| {
            let y = o + d * t;
            let t_cam = (-sigma[c] * (t - a)).exp();
            // Sun: light travels along ws, reaches y from -ws.
            let l_sun = exit_distance(y.to_array(), (-ws).to_array(), radius);
            let sun = hg(g as f32, ws.dot(-d) as f32) as f64 * (-sigma[c] * l_sun).exp() * sun_e;
            // Point light outside the sphere: the part of the segment inside.
            let v = y - point_pos.as_dvec3();
            let dist = v.length();
            let w = v / dist;
            let inside = exit_distance(y.to_array(), (-w).to_array(), radius).min(dist);
            let pt = hg(g as f32, w.dot(-d) as f32) as f64 * (-sigma[c] * inside).exp() * point_i
                / (dist * dist);
            t_cam * sigma[c] * albedo[c] * (sun + pt)
        };
        let mut s = f(a) + f(b);
        for i in 1..n {
            s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    });
    let exact = Vec3::new(exact[0] as f32, exact[1] as f32, exact[2] as f32);

    let mut rng = Rng::for_sample(11, 0, 0);
    let (est, err) = mean_stderr(400_000, |_| {
        radiance(&vol, &lights, origin, dir, 1, &mut rng)
    });
    for c in 0..3 {
        assert!(
            (est[c] - exact[c]).abs() < 4.0 * err[c] + 1e-5,
            "channel {c}: estimate {} ± {} vs quadrature {}",
            est[c],
            err[c],
            exact[c]
        );
    }
    // The test has teeth: the estimate is precise to better than 1 %.
    assert!((err / exact).max_element() < 0.01, "{err} {exact}");
}

/// White furnace: with albedo 1 nothing is absorbed, so the flux the
/// sphere scatters out (all orders) equals the sun's flux intercepted by
/// the sphere minus the part transmitted unscattered,
/// `E πR² − E (π/2)(1 − e^{−2σR}(1 + 2σR))/σ²`. The scattered flux is
/// estimated by integrating the path-traced radiance over a bounding sphere
/// (uniform points, cosine-weighted inward directions).
#[test]
fn albedo_one_conserves_energy() {
    let radius = 1.0f32;
    let sigma = 1.5f32;
    let e = 1.0f32;
    for g in [0.0f32, 0.7] {
        let vol = sphere(
            radius,
            Optics {
                sigma_t: Vec3::splat(sigma),
                albedo: Vec3::ONE,
                g,
            },
        );
        let lights = Lights {
            suns: vec![Sun {
                direction: Vec3::new(0.2, -1.0, 0.1).normalize(),
                irradiance: Vec3::splat(e),
            }],
            points: vec![],
            environment: None,
        };
        let rb = 1.05f32;
        let area = 4.0 * std::f32::consts::PI * rb * rb;
        let mut rng = Rng::for_sample(5, 1, (g * 10.0) as u32);
        let (flux, err) = mean_stderr(300_000, |_| {
            // Uniform point on the bounding sphere.
            let z = 1.0 - 2.0 * rng.next_f32();
            let phi = std::f32::consts::TAU * rng.next_f32();
            let r = (1.0 - z * z).max(0.0).sqrt();
            let n = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            let x = n * rb;
            // Cosine-weighted direction into the sphere (around −n).
            let u1 = rng.next_f32();
            let u2 = rng.next_f32();
            let d = lantern::physics::frame::from_spherical(
                -n,
                (1.0 - u1).sqrt(),
                std::f32::consts::TAU * u2,
            );
            radiance(&vol, &lights, x, d, u32::MAX, &mut rng) * (area * std::f32::consts::PI)
        });
        let s = sigma as f64;
        let r = radius as f64;
        let unscattered = std::f64::consts::PI / 2.0
            * (1.0 - (-2.0 * s * r).exp() * (1.0 + 2.0 * s * r))
            / (s * s);
        let exact = (e as f64 * (std::f64::consts::PI * r * r - unscattered)) as f32;
        assert!(
            (flux.x - exact).abs() < 4.0 * err.x,
            "g={g}: scattered flux {} ± {} vs {}",
            flux.x,
            err.x,
            exact
        );
        assert!(err.x / exact < 0.01);
    }
}
