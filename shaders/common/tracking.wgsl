// Free-flight sampling and transmittance estimation against the majorant
// grid (src/doc/method.md §2, §4). Mirrors src/physics/tracking.rs:
//
// - `sample_tentative`: exponential steps against the local majorant. The
//   CPU calls back at each tentative collision; here it is an iterator
//   (`sample_tentative_start`, `sample_tentative_next`) that draws random
//   numbers in the same order: the first optical depth before the walk, each
//   next one after the caller has handled a collision.
// - `free_flight`: spectral tracking (Kutz et al. 2017, "max" probabilities).
// - `transmittance`: ratio tracking (Novák et al. 2014) with Russian
//   roulette once the estimate is small.
// Every tentative collision advances the ray by at least one f32 step
// (`tentative_advance`), as on the CPU, so no flight can stall.

// The state of a tentative-collision sampler along one ray.
struct TentativeSampler {
    dda: DdaIterator,
    // The current segment: position reached, its end and majorant.
    t: f32,
    seg_t1: f32,
    majorant: f32,
    has_segment: bool,
    // Optical depth left to the next tentative collision.
    tau: f32,
    // Whether a collision was returned and a fresh `tau` is due.
    redraw: bool,
    // Tentative collisions per unit of the majorant (1, or a ratio-tracking
    // rate above it: `sample_tentative_at_rate`).
    rate: f32,
}

// A tentative collision at distance `t` with the local majorant.
struct TentativeCollision {
    t: f32,
    majorant: f32,
    found: bool,
}

// Starts sampling tentative collisions along `origin + t dir` for
// `t ∈ [t0, t1]` (inside the grid's box).
fn sample_tentative_start(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t0: f32,
    t1: f32,
    rng: ptr<function, Rng>,
) -> TentativeSampler {
    return sample_tentative_start_at_rate(origin, dir, t0, t1, 1.0, rng);
}

// `sample_tentative_start` with tentative collisions at `rate` times the
// local majorant (`sample_tentative_at_rate`); the collisions it returns
// carry that rate as their majorant.
fn sample_tentative_start_at_rate(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t0: f32,
    t1: f32,
    rate: f32,
    rng: ptr<function, Rng>,
) -> TentativeSampler {
    var s: TentativeSampler;
    s.rate = rate;
    s.tau = -log(1.0 - rng_next_f32(rng));
    s.dda = dda_start(origin, dir, t0, t1);
    s.has_segment = false;
    s.redraw = false;
    return s;
}

// The next tentative collision, or `found = false` once the ray reached
// `t1`.
fn sample_tentative_next(s: ptr<function, TentativeSampler>, rng: ptr<function, Rng>) -> TentativeCollision {
    if (*s).redraw {
        (*s).tau = -log(1.0 - rng_next_f32(rng));
        (*s).redraw = false;
    }
    loop {
        if !(*s).has_segment {
            // A local copy: naga 30's SPIR-V writer fails on a pointer to
            // a member of a pointed-to struct passed as an argument
            // ("Expression is not cached").
            var dda = (*s).dda;
            let seg = dda_next(&dda);
            (*s).dda = dda;
            if !seg.valid {
                return TentativeCollision(0.0, 0.0, false);
            }
            if seg.majorant <= 0.0 {
                continue;
            }
            (*s).t = seg.t0;
            (*s).seg_t1 = seg.t1;
            (*s).majorant = seg.majorant * (*s).rate;
            (*s).has_segment = true;
        }
        let m = (*s).majorant;
        let seg_tau = m * ((*s).seg_t1 - (*s).t);
        if (*s).tau >= seg_tau {
            (*s).tau -= seg_tau;
            (*s).has_segment = false;
            continue;
        }
        (*s).t = tentative_advance((*s).t, (*s).tau / m, (*s).seg_t1);
        (*s).redraw = true;
        return TentativeCollision((*s).t, m, true);
    }
    // Unreachable: the loop only returns.
    return TentativeCollision(0.0, 0.0, false);
}

// `t + step`, at least one f32 step beyond `t` (and beyond the smallest
// normal f32), at most `end` (`tracking::advance`): every tentative
// collision moves the ray on, so a flight ends on any finite input.
fn tentative_advance(t: f32, step: f32, end: f32) -> f32 {
    let next_up = bitcast<f32>(bitcast<u32>(max(t, 1.17549435e-38)) + 1u);
    return min(max(t + step, next_up), end);
}

// Where a free flight ended: a real collision at `t`, or none.
struct FreeFlight {
    t: f32,
    hit: bool,
}

// Spectral tracking from `origin` along `dir` over `[t0, t1]`
// (`free_flight`): a real collision or none; `weight` (the path
// throughput) is updated to keep the estimator unbiased per channel and set
// to zero when the path can carry no more light.
fn free_flight(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t0: f32,
    t1: f32,
    weight: ptr<function, vec3<f32>>,
    rng: ptr<function, Rng>,
) -> FreeFlight {
    var s = sample_tentative_start(origin, dir, t0, t1, rng);
    loop {
        let c = sample_tentative_next(&s, rng);
        if !c.found {
            return FreeFlight(0.0, false);
        }
        let m = c.majorant;
        let sigma_t = medium_sigma_t(origin + dir * c.t);
        let sigma_n = max(vec3<f32>(m) - sigma_t, vec3<f32>(0.0));
        let p_real = max_element(*weight * sigma_t);
        let p_null = max_element(*weight * sigma_n);
        let total = p_real + p_null;
        if total <= 0.0 {
            *weight = vec3<f32>(0.0);
            return FreeFlight(0.0, false);
        }
        if rng_next_f32(rng) * total < p_real {
            *weight *= sigma_t * (total / (m * p_real));
            return FreeFlight(c.t, true);
        }
        *weight *= sigma_n * (total / (m * p_null));
    }
    // Unreachable: the loop only returns.
    return FreeFlight(0.0, false);
}

// Ratio-tracking estimate of the transmittance from `origin` along `dir` up
// to distance `t_max` (clipped to the medium), per channel
// (`transmittance`).
fn transmittance(origin: vec3<f32>, dir: vec3<f32>, t_max: f32, rng: ptr<function, Rng>) -> vec3<f32> {
    return transmittance_at_rate(origin, dir, t_max, 1.0, rng);
}

// `transmittance` with tentative collisions at `rate` (at least 1) times
// the majorant (`transmittance_at_rate`): unbiased, and no longer a
// yes-or-no estimate where the majorant is tight.
fn transmittance_at_rate(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t_max: f32,
    rate: f32,
    rng: ptr<function, Rng>,
) -> vec3<f32> {
    let clip = medium_clip(origin, dir);
    if !clip.hit {
        return vec3<f32>(1.0);
    }
    let t1 = min(clip.t1, t_max);
    if t1 <= clip.t0 {
        return vec3<f32>(1.0);
    }
    var tr = vec3<f32>(1.0);
    var s = sample_tentative_start_at_rate(origin, dir, clip.t0, t1, max(rate, 1.0), rng);
    loop {
        let c = sample_tentative_next(&s, rng);
        if !c.found {
            break;
        }
        let sigma_t = medium_sigma_t(origin + dir * c.t);
        tr *= max(vec3<f32>(1.0) - sigma_t / c.majorant, vec3<f32>(0.0));
        let largest = max_element(tr);
        if largest <= 0.0 {
            break;
        }
        if largest < 0.1 {
            // Russian roulette: survive with probability 1/2, doubled.
            if rng_next_f32(rng) < 0.5 {
                tr = vec3<f32>(0.0);
                break;
            }
            tr *= 2.0;
        }
    }
    return tr;
}
