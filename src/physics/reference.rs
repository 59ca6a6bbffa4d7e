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
use super::tracking::{free_flight, Transmittance};
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
    single_scatter_source_with(vol, lights, p, n, Transmittance::RATIO, rng)
}

/// [`single_scatter_source`] with the shadow rays' transmittance
/// estimated by `tr` (the gather's: [`Transmittance::Marched`]).
#[inline]
pub fn single_scatter_source_with<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    p: Vec3,
    n: Vec3,
    tr: Transmittance,
    rng: &mut Rng,
) -> Vec3 {
    scatter_source(vol, lights, p, n, tr, None, rng)
}

/// [`single_scatter_source_with`], each light's shadow ray traced with
/// probability `q = min(1, P · c)` for `roulette` `Some(c)` (its term
/// divided by `q`; one number drawn first where `q < 1`), every one for
/// `None`.
#[inline]
fn scatter_source<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    p: Vec3,
    n: Vec3,
    estimator: Transmittance,
    roulette: Option<f32>,
    rng: &mut Rng,
) -> Vec3 {
    let mut sum = Vec3::ZERO;
    lights.for_each_at(p, |l| {
        let phase = phase::hg(vol.optics.g, l.travel.dot(n));
        let q = roulette.map_or(1.0, |c| (phase * c).min(1.0));
        if q < 1.0 && rng.next_f32() >= q {
            return;
        }
        let tr = estimator.estimate(vol, p, -l.travel, l.distance, rng);
        sum += l.irradiance * tr * (phase / q);
    });
    if let Some(env) = lights.sky() {
        sum += environment_source(vol, env, p, n, estimator, rng);
    }
    sum
}

/// The walks' gates' `S₁(p, n) / b(p)` ([`single_scatter_source`]'s
/// estimate with its shadow rays rouletted by the phase function): each
/// external light's shadow ray is traced with probability
/// `q = min(1, 2 P(n·ω)/P_iso)` ([`GATE_PHASE_ROULETTE`]), `P_iso = 1/4π`
/// the isotropic phase function's value, and its term divided by `q`; the
/// environment's part is [`environment_source`]'s. Unbiased, the same expectation as
/// [`single_scatter_source`].
///
/// Why: a walk adds `S₁` at every gate, twice per mean free path at the
/// default window, and in a forward-scattering medium most gates face their
/// lights at angles where `P` is a small fraction of its mean (for `g`
/// 0.85 and directions spread evenly, the ray is traced at 41 % of the
/// gates, for a second moment of `P` 0.1 % higher); the gates' shadow rays
/// took about a third of a light set's time in a thick cloud. The
/// gather's marches and the reference keep every shadow ray: there one
/// sample carries the pixel's single scatter, not one of hundreds of gates.
/// Draws one number before a light's shadow ray where `q < 1`.
#[inline]
pub fn gate_scatter_source<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    p: Vec3,
    n: Vec3,
    rng: &mut Rng,
) -> Vec3 {
    scatter_source(
        vol,
        lights,
        p,
        n,
        Transmittance::RATIO,
        Some(GATE_PHASE_ROULETTE),
        rng,
    )
}

/// `2/P_iso = 8π`: [`gate_scatter_source`] traces a light's shadow ray
/// with probability `min(1, P · GATE_PHASE_ROULETTE)`, so that only the
/// directions where the phase function is below half the isotropic one's
/// value are rouletted. For directions spread evenly that is 1 % of them
/// at `g` 0.3 (a second moment of `P` 0.3 % higher), 16 % at 0.5 (1.1 %)
/// and 59 % at 0.85 (0.1 %). At `2π` (every direction below twice the
/// isotropic value) the suite's smoke plume (`g` 0.3) had a quarter more
/// light-set variance.
pub const GATE_PHASE_ROULETTE: f32 = 8.0 * std::f32::consts::PI;

/// One estimate of the environment's part of `S₁(p, n) / b(p)`,
/// `∫ P(n·ω) L(−ω) T(p, ∞ along −ω) dω` over the directions `ω` light
/// travels: a direction from the environment with probability
/// [`Environment::map_share`] `q`, from the phase function otherwise, and
/// `P L T / (q p_env + (1 − q) P)` (one-sample MIS with the balance
/// heuristic), the transmittance estimated by `tr`. Draws three numbers
/// from `rng` before the transmittance.
#[inline]
pub fn environment_source<D: DensityField>(
    vol: &Volume<D>,
    env: &Environment,
    p: Vec3,
    n: Vec3,
    tr: Transmittance,
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
    radiance * (phase / pdf) * tr.estimate(vol, p, from, f32::INFINITY, rng)
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

    /// The gates' rouletted `S₁` ([`gate_scatter_source`]) has
    /// [`single_scatter_source`]'s mean: in a heterogeneous medium of `g`
    /// 0.85 lit by a sun and a point light, at points and directions that
    /// face the lights at every angle (so that `q` ranges from 1 to a few
    /// percent), 40 000 estimates of each on independent streams agree
    /// within 4.5 standard errors per channel; and the roulette skips
    /// shadow rays (backwards from the sun, near its face, the rouletted
    /// estimate is mostly exactly zero where the full one almost never is).
    #[test]
    fn gate_roulette_keeps_the_mean() {
        use crate::physics::lights::{PointLight, Sun};
        use crate::physics::testing::{boxed, mean_and_its_variance};
        let mut vol = boxed(1.2, 0.8, 0.95, 2.0, 4);
        vol.optics.g = 0.85;
        let lights = Lights {
            suns: vec![Sun {
                direction: Vec3::new(0.6, -1.0, -0.5).normalize(),
                irradiance: Vec3::new(3.0, 2.0, 1.0),
            }],
            points: vec![PointLight {
                position: Vec3::new(-1.5, 0.5, 1.0),
                intensity: Vec3::new(2.0, 2.0, 4.0),
            }],
            environment: None,
        };
        let mut checked = 0;
        for (i, cos) in [-1.0f32, -0.3, 0.2, 0.6, 0.9, 0.99].into_iter().enumerate() {
            // A direction at `cos` to the sun's travel direction.
            let t = lights.suns[0].direction;
            let side = t.any_orthonormal_vector();
            let n = (t * cos + side * (1.0 - cos * cos).max(0.0).sqrt()).normalize();
            let p = Vec3::new(0.1 * i as f32 - 0.2, -0.3, 0.15);
            let count = 40_000;
            let (full, full_var) = mean_and_its_variance(count, 5, i as u32, |rng| {
                single_scatter_source(&vol, &lights, p, n, rng)
            });
            let (gated, gated_var) = mean_and_its_variance(count, 6, i as u32, |rng| {
                gate_scatter_source(&vol, &lights, p, n, rng)
            });
            for c in 0..3 {
                let z = (gated[c] - full[c]) / (full_var[c] + gated_var[c]).sqrt();
                assert!(
                    z.abs() < 4.5,
                    "cos {cos}, channel {c}: rouletted {} against {} (z = {z})",
                    gated[c],
                    full[c]
                );
            }
            checked += 1;
        }
        assert_eq!(checked, 6);
        // Backwards from the sun (`q` ≈ 0.09 for it; the point light stands
        // elsewhere) most of the sun's shadow rays are skipped: the
        // rouletted estimate is mostly exactly zero where ratio tracking
        // seldom is.
        let t = lights.suns[0].direction;
        let sun_only = Lights {
            points: Vec::new(),
            ..lights.clone()
        };
        // Near the face the sun enters by: ratio tracking seldom reaches zero.
        let p = Vec3::new(-0.2, 1.8, 0.1);
        let zeros = |f: &dyn Fn(&mut Rng) -> Vec3| {
            (0..2000u32)
                .filter(|&w| f(&mut Rng::for_sample(9, w, 0)) == Vec3::ZERO)
                .count()
        };
        let full = zeros(&|rng| single_scatter_source(&vol, &sun_only, p, -t, rng));
        let gated = zeros(&|rng| gate_scatter_source(&vol, &sun_only, p, -t, rng));
        assert!(
            full < 20 && gated > 1700,
            "zero estimates: {gated} of 2000 rouletted, {full} of 2000 in full"
        );
    }

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
