//! The unbiased reference estimator ([method §2](crate::doc::method)): a volumetric path tracer
//! with spectral tracking for free flights, ratio tracking for shadow rays,
//! next-event estimation to every light (the environment included), and
//! Russian roulette.
//!
//! Paths are traced backwards from the camera. At a real collision the path
//! arriving along `dir` receives light scattered into `−dir`; the phase
//! function is evaluated between the direction the light travels and `−dir`.

use glam::Vec3;

use super::environment::Environment;
use super::lights::Lights;
use super::phase;
use super::rng::Rng;
use super::tracking::{free_flight, transmittance_at_rate};
use super::volume::{DensityField, Volume};

/// Collisions after which Russian roulette starts.
pub const RR_START_DEPTH: u32 = 3;

/// The most a path (or an internal light's walk) survives Russian roulette
/// at one collision. The roulette keeps a path with probability its weight
/// (largest channel), at most this, and divides the weight by it: in a
/// medium of albedo `α` ≤ 0.999 a path then survives each collision with
/// probability `α` and always carries weight one, the least variance the
/// roulette can leave; a medium that absorbs nothing still ends its paths
/// (after about a thousand collisions past [`RR_START_DEPTH`]), their
/// weight growing by `1/0.999` per collision.
///
/// The roulette used to survive at most 0.95. In a medium of albedo 0.999
/// a survivor's weight then grew by `0.999/0.95` at every collision, and
/// the light reaching deep into a thick cloud, hundreds of collisions long,
/// came back as a few paths of weights in the hundreds: the fireflies of
/// the reference on the suite's thick cumulus, and the internal lights'
/// heavy-tailed walks there. On that cumulus one light set's per-pixel
/// noise fell from 186 % to 40 % of the image mean for 1.7 times the
/// walks' time ([validation §3.7](crate::doc::validation)).
pub const RR_MAX_SURVIVAL: f32 = 0.999;

/// Russian roulette at a collision past [`RR_START_DEPTH`], for the
/// reference's paths and the internal lights' walks alike: keeps the path
/// with probability `q = min(max(weight), RR_MAX_SURVIVAL)` and divides its
/// weight by `q`, so the weight's expectation is unchanged; returns whether
/// the path goes on. Draws one number from `rng` unless `q` is zero.
#[inline]
pub fn roulette(weight: &mut Vec3, rng: &mut Rng) -> bool {
    let q = weight.max_element().min(RR_MAX_SURVIVAL);
    if q <= 0.0 || rng.next_f32() >= q {
        return false;
    }
    *weight /= q;
    true
}

/// In-scattered first-scatter radiance per unit scattering coefficient at
/// `p` towards direction `n` (the direction the light travels after
/// scattering): `S₁(p, n) / b(p) = Σ_lights P(n·ω) T(light, p) E`, with
/// the transmittance estimated by ratio tracking, plus the environment's
/// `∫ P(n·ω) L(−ω) T dω` by one sample ([`environment_source`]). Every
/// estimator's `S₁` comes from here: the reference's next-event
/// estimation, the walks' gates and the gather's marches.
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
    if let Some(env) = lights.sky() {
        sum += environment_source(vol, env, p, n, rate, rng);
    }
    sum
}

/// One estimate of the environment's part of `S₁(p, n) / b(p)`,
/// `∫ P(n·ω) L(−ω) T(p, ∞ along −ω) dω` over the directions `ω` light
/// travels: a direction from the environment with probability
/// [`Environment::map_share`] `q`, from the phase function otherwise, and
/// `P L T / (q p_env + (1 − q) P)` (one-sample MIS with the balance
/// heuristic), the transmittance ratio-tracked at `rate` times the
/// majorant. Draws three numbers from `rng` before tracking.
#[inline]
pub fn environment_source<D: DensityField>(
    vol: &Volume<D>,
    env: &Environment,
    p: Vec3,
    n: Vec3,
    rate: f32,
    rng: &mut Rng,
) -> Vec3 {
    let g = vol.optics.g;
    let q = env.map_share();
    let (u0, u1, u2) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
    let from = if u0 < q {
        match env.sample(u1, u2) {
            Some((d, _)) => d,
            None => return Vec3::ZERO,
        }
    } else {
        // Light travelling along `t` scatters into `n` with density
        // `P(n·t)`: draw `t` about `n`; it comes from `−t`.
        -phase::sample_hg(g, n, u1, u2)
    };
    let phase = phase::hg(g, -from.dot(n));
    let pdf = if q > 0.0 {
        q * env.pdf(from) + (1.0 - q) * phase
    } else {
        phase
    };
    if pdf.is_nan() || pdf <= 0.0 {
        return Vec3::ZERO;
    }
    let radiance = env.radiance(from);
    if radiance == Vec3::ZERO {
        return Vec3::ZERO;
    }
    radiance * (phase / pdf) * transmittance_at_rate(vol, p, from, f32::INFINITY, rate, rng)
}

/// The sky seen behind the medium by a ray travelling along `dir`, with
/// its transmittance (the caller's), when the environment is drawn as the
/// background; zero otherwise.
#[inline]
pub fn background(lights: &Lights, dir: Vec3) -> Vec3 {
    match lights.sky() {
        Some(env) if env.background => env.radiance(dir),
        _ => Vec3::ZERO,
    }
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
/// scattered at the first collision only, plus the background the camera
/// ray sees through the medium when the sky is drawn). Paths that leave
/// the medium after a collision add nothing: next-event estimation at
/// every collision already counts all the light that arrives there from
/// the sky unscattered (the phase-sampled half of its MIS is the path's
/// own continuation, drawn again).
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
    loop {
        let flight = vol
            .clip(o, d)
            .and_then(|(t0, t1)| free_flight(vol, o, d, t0, t1, &mut weight, rng));
        let Some(t) = flight else {
            if depth == 0 {
                // The camera ray left unscattered.
                single = weight * background(lights, d);
                radiance += single;
            }
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
        if depth >= RR_START_DEPTH && !roulette(&mut weight, rng) {
            break;
        }
        d = phase::sample_hg(vol.optics.g, d, rng.next_f32(), rng.next_f32());
        o = p;
    }
    (radiance, single)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// In a grey medium of albedo up to 0.999 the roulette keeps every
    /// survivor at weight one (no weight grows with the path's length, the
    /// heavy tail the old cap of 0.95 made), survives each collision with
    /// probability the albedo, and ends the paths of a medium that absorbs
    /// nothing at the cap's rate.
    #[test]
    fn roulette_keeps_survivors_at_unit_weight() {
        for albedo in [0.5f32, 0.9, 0.99, 0.999, 1.0] {
            let (paths, collisions) = (4000u32, 400u32);
            let (mut survived, mut tried) = (0u64, 0u64);
            let mut largest = 0.0f32;
            for p in 0..paths {
                let mut rng = Rng::for_sample(17, p, 0);
                let mut weight = Vec3::ONE;
                for _ in 0..collisions {
                    weight *= albedo;
                    tried += 1;
                    if !roulette(&mut weight, &mut rng) {
                        break;
                    }
                    survived += 1;
                    largest = largest.max(weight.max_element());
                }
            }
            let rate = survived as f64 / tried as f64;
            let expected = f64::from(albedo.min(RR_MAX_SURVIVAL));
            let se = (expected * (1.0 - expected) / tried as f64).sqrt();
            assert!(
                (rate - expected).abs() < 5.0 * se + 1e-9,
                "albedo {albedo}: survived {rate} per collision, expected {expected} ± {se}"
            );
            // Albedo 1: the weight grows by 1/0.999 per collision, at most
            // 400 times here (1.49).
            let bound = if albedo < 1.0 {
                1.0 + 1e-5
            } else {
                0.999f32.powi(-(collisions as i32)) * 1.001
            };
            assert!(
                largest <= bound,
                "albedo {albedo}: a survivor weighed {largest}"
            );
        }
    }

    /// The roulette keeps the weight's expectation, above the cap and below
    /// it, for a chromatic weight too (its largest channel decides).
    #[test]
    fn roulette_is_unbiased() {
        for w in [
            Vec3::splat(0.3),
            Vec3::new(0.2, 0.6, 0.9),
            Vec3::splat(0.9995),
            Vec3::splat(1.7),
        ] {
            let n = 400_000u32;
            let mut sum = Vec3::ZERO.as_dvec3();
            for i in 0..n {
                let mut rng = Rng::for_sample(19, i, 1);
                let mut weight = w;
                if roulette(&mut weight, &mut rng) {
                    sum += weight.as_dvec3();
                }
            }
            let mean = sum / f64::from(n);
            let q = f64::from(w.max_element().min(RR_MAX_SURVIVAL));
            for c in 0..3 {
                let wc = f64::from(w[c]);
                let se = wc * ((1.0 - q) / q / f64::from(n)).sqrt();
                assert!(
                    (mean[c] - wc).abs() <= 5.0 * se + 1e-6,
                    "weight {w}: channel {c} mean {} ± {se}",
                    mean[c]
                );
            }
        }
    }
}
