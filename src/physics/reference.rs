//! The unbiased reference estimator ([method §2](crate::doc::method)): a volumetric path tracer
//! with spectral tracking for free flights, ratio tracking for shadow rays,
//! next-event estimation to every light, and Russian roulette.
//!
//! Paths are traced backwards from the camera. At a real collision the path
//! arriving along `dir` receives light scattered into `−dir`; the phase
//! function is evaluated between the direction the light travels and `−dir`.

use glam::Vec3;

use super::lights::Lights;
use super::phase;
use super::rng::Rng;
use super::tracking::{free_flight, transmittance_at_rate};
use super::volume::{DensityField, Volume};

/// Collisions after which Russian roulette starts.
pub const RR_START_DEPTH: u32 = 3;

/// In-scattered first-scatter radiance per unit scattering coefficient at
/// `p` towards direction `n` (the direction the light travels after
/// scattering): `S₁(p, n) / b(p) = Σ_lights P(n·ω) T(light, p) E`, with
/// the transmittance estimated by ratio tracking.
#[inline]
pub fn single_scatter_source<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    p: Vec3,
    n: Vec3,
    rng: &mut Rng,
) -> Vec3 {
    single_scatter_source_at_rate(vol, lights, p, n, 1.0, rng)
}

/// [`single_scatter_source`] with the shadow rays' ratio tracking at
/// `rate` times the majorant ([`transmittance_at_rate`]).
#[inline]
pub fn single_scatter_source_at_rate<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    p: Vec3,
    n: Vec3,
    rate: f32,
    rng: &mut Rng,
) -> Vec3 {
    let mut sum = Vec3::ZERO;
    lights.for_each_at(p, |l| {
        let phase = phase::hg(vol.optics.g, l.travel.dot(n));
        let tr = transmittance_at_rate(vol, p, -l.travel, l.distance, rate, rng);
        sum += l.irradiance * tr * phase;
    });
    sum
}

/// One path-traced estimate of the radiance arriving at `origin` from
/// direction `-dir` (i.e. seen by a camera ray with direction `dir`),
/// counting light scattered at most `max_collisions` times (`u32::MAX`:
/// all orders, the unbiased reference; 1: single scattering).
pub fn radiance<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    origin: Vec3,
    dir: Vec3,
    max_collisions: u32,
    rng: &mut Rng,
) -> Vec3 {
    radiance_split(vol, lights, origin, dir, max_collisions, rng).0
}

/// [`radiance`] and, second, its single-scattering part (the light
/// scattered at the first collision only).
pub fn radiance_split<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    origin: Vec3,
    dir: Vec3,
    max_collisions: u32,
    rng: &mut Rng,
) -> (Vec3, Vec3) {
    let mut single = Vec3::ZERO;
    let mut radiance = Vec3::ZERO;
    let mut weight = Vec3::ONE;
    let mut o = origin;
    let mut d = dir;
    let mut depth = 0u32;
    while let Some((t0, t1)) = vol.clip(o, d) {
        let Some(t) = free_flight(vol, o, d, t0, t1, &mut weight, rng) else {
            break;
        };
        let p = o + d * t;
        weight *= vol.optics.albedo;
        let contribution = weight * single_scatter_source(vol, lights, p, -d, rng);
        radiance += contribution;
        if depth == 0 {
            single = contribution;
        }
        depth += 1;
        if depth >= max_collisions {
            break;
        }
        if depth >= RR_START_DEPTH {
            let q = weight.max_element().min(0.95);
            if q <= 0.0 || rng.next_f32() >= q {
                break;
            }
            weight /= q;
        }
        d = phase::sample_hg(vol.optics.g, d, rng.next_f32(), rng.next_f32());
        o = p;
    }
    (radiance, single)
}
