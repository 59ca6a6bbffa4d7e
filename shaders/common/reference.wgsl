// The unbiased reference estimator (src/doc/method.md §2). Mirrors
// src/physics/reference.rs: a volumetric path tracer with spectral tracking
// for free flights, ratio tracking for shadow rays, next-event estimation to
// every light, and Russian roulette. Paths are traced backwards from the
// camera; at a real collision the path arriving along `dir` receives light
// scattered into `-dir`.

// Collisions after which Russian roulette starts: `RR_START_DEPTH`, and the
// most a path survives the roulette at one collision: `RR_MAX_SURVIVAL`,
// from Rust (the generated prelude: crate::physics::reference).

// A guard against a path that never ends, which the CPU does not need: the
// roulette survives at most `RR_MAX_SURVIVAL` (0.999) per collision, so a
// path reaches the guard with probability below 0.999^65536 (3e-29).
const MAX_COLLISIONS_GUARD: u32 = 65536u;

// Russian roulette at a collision past `RR_START_DEPTH`, for the reference's
// paths and the internal lights' walks alike (`roulette`): keeps the path
// with probability `q = min(max(weight), RR_MAX_SURVIVAL)` and divides its
// weight by `q`; returns whether it goes on. Draws one number unless `q` is
// zero.
fn roulette(weight: ptr<function, vec3<f32>>, rng: ptr<function, Rng>) -> bool {
    let q = min(max_element(*weight), RR_MAX_SURVIVAL);
    if q <= 0.0 || rng_next_f32(rng) >= q {
        return false;
    }
    *weight /= q;
    return true;
}

// `S₁(p, n) / b(p)`: in-scattered first-scatter radiance per unit scattering
// coefficient at `p` towards `n`, transmittance by ratio tracking
// (`single_scatter_source`).
fn single_scatter_source(p: vec3<f32>, n: vec3<f32>, rng: ptr<function, Rng>) -> vec3<f32> {
    return single_scatter_source_with(p, n, 1.0, rng);
}

// `single_scatter_source` with the shadow rays' transmittance by
// `transmittance_by` at `rate` (`single_scatter_source_with`; the gather
// passes `GATHER_TRANSMITTANCE`, the march).
fn single_scatter_source_with(p: vec3<f32>, n: vec3<f32>, rate: f32, rng: ptr<function, Rng>) -> vec3<f32> {
    return scatter_source(p, n, rate, 0.0, rng);
}

// The walks' gates' `S₁(p, n) / b(p)` (`gate_scatter_source`): each light's
// shadow ray traced with probability `q = min(1, P · GATE_PHASE_ROULETTE)`
// (twice `P` over the isotropic phase function's value) and its term divided
// by `q`.
fn gate_scatter_source(p: vec3<f32>, n: vec3<f32>, rng: ptr<function, Rng>) -> vec3<f32> {
    return scatter_source(p, n, 1.0, GATE_PHASE_ROULETTE, rng);
}

// `single_scatter_source_with` with each light's shadow ray traced with
// probability `q = min(1, P · roulette)` (its term divided by `q`; one number
// drawn first where `q < 1`), every one for `roulette` 0 (`scatter_source`).
// The environment's sampled direction is the loop's last turn, so that the
// shadow ray is traced at one place: Mesa inlines every call, and the
// gather's march is long.
fn scatter_source(p: vec3<f32>, n: vec3<f32>, rate: f32, roulette: f32, rng: ptr<function, Rng>) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    let count = light_count();
    let turns = count + select(0u, 1u, env_present());
    for (var i = 0u; i < turns; i++) {
        var ray: ShadowRay;
        if i < count {
            let l = light_at(i, p);
            let phase = hg(scene.medium.g, dot(l.travel, n));
            let q = select(1.0, min(phase * roulette, 1.0), roulette > 0.0);
            if q < 1.0 && rng_next_f32(rng) >= q {
                continue;
            }
            ray = ShadowRay(-l.travel, l.distance, l.irradiance * (phase / q));
        } else {
            ray = environment_ray(p, n, rng);
            if all(ray.weight == vec3<f32>(0.0)) {
                continue;
            }
        }
        sum += ray.weight * transmittance_by(p, ray.towards, ray.distance, rate, rng);
    }
    return sum;
}

// A shadow ray of `S₁`: its direction, length and the source's weight
// before the transmittance.
struct ShadowRay {
    towards: vec3<f32>,
    distance: f32,
    weight: vec3<f32>,
}

// The environment's part of `S₁(p, n) / b(p)` by one-sample MIS between the
// map and the phase function (`environment_source`): the direction drawn
// and its weight, zero where it carries nothing.
fn environment_ray(p: vec3<f32>, n: vec3<f32>, rng: ptr<function, Rng>) -> ShadowRay {
    let none = ShadowRay(n, 0.0, vec3<f32>(0.0));
    let g = scene.medium.g;
    let q = scene.env_share;
    let u0 = rng_next_f32(rng);
    let u1 = rng_next_f32(rng);
    let u2 = rng_next_f32(rng);
    var towards: vec3<f32>;
    if u0 < q {
        let s = env_sample(u1, u2);
        if s.pdf <= 0.0 {
            return none;
        }
        towards = s.towards;
    } else {
        towards = -sample_hg(g, n, u1, u2);
    }
    let phase = hg(g, -dot(towards, n));
    var pdf = phase;
    if q > 0.0 {
        pdf = q * env_pdf(towards) + (1.0 - q) * phase;
    }
    if !(pdf > 0.0) {
        return none;
    }
    let radiance = env_radiance(towards);
    if all(radiance == vec3<f32>(0.0)) {
        return none;
    }
    return ShadowRay(towards, BIG, radiance * (phase / pdf));
}

// A radiance estimate and its single-scattering part.
struct RadianceSplit {
    radiance: vec3<f32>,
    single: vec3<f32>,
}

// One path-traced estimate of the radiance arriving at `origin` from
// `-dir`, counting at most `max_collisions` scatterings (0xffffffff: all
// orders), and its single-scattering part (`radiance_split`).
fn radiance_split(origin: vec3<f32>, dir: vec3<f32>, max_collisions: u32, rng: ptr<function, Rng>) -> RadianceSplit {
    let albedo = scene.medium.albedo;
    let g = scene.medium.g;
    var single = vec3<f32>(0.0);
    var radiance = vec3<f32>(0.0);
    var weight = vec3<f32>(1.0);
    var o = origin;
    var d = dir;
    var depth = 0u;
    loop {
        let clip = medium_clip(o, d);
        var escaped = !clip.hit;
        var t = 0.0;
        if clip.hit {
            let flight = free_flight(o, d, clip.t0, clip.t1, &weight, rng);
            escaped = !flight.hit;
            t = flight.t;
        }
        if escaped {
            if depth == 0u {
                // The camera ray left unscattered.
                single = weight * env_background(d);
                radiance += single;
            }
            break;
        }
        let flight_t = t;
        let p = o + d * flight_t;
        weight *= albedo;
        let contribution = weight * single_scatter_source(p, -d, rng);
        radiance += contribution;
        if depth == 0u {
            single = contribution;
        }
        depth += 1u;
        if depth >= max_collisions || depth >= MAX_COLLISIONS_GUARD {
            break;
        }
        if depth >= RR_START_DEPTH && !roulette(&weight, rng) {
            break;
        }
        let u1 = rng_next_f32(rng);
        let u2 = rng_next_f32(rng);
        d = sample_hg(g, d, u1, u2);
        o = p;
    }
    return RadianceSplit(radiance, single);
}
