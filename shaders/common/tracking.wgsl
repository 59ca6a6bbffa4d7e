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
// - `transmittance_marched`: the unbiased ray march (Kettunen et al. 2021)
//   that the gather uses; `transmittance_by` picks one of the two as the
//   Rust `Transmittance` does (a rate of `TRANSMITTANCE_MARCHED` is the
//   march). Its constants come from Rust (the generated prelude:
//   crate::physics::tracking::{MARCH_SEGMENT_DEPTH, MARCH_STRIDE_DEPTH,
//   MARCH_MAX_TERMS}).
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

// What spectral tracking made of a tentative collision (`TentativeEvent`).
const EVENT_REAL: u32 = 0u;
const EVENT_NULL: u32 = 1u;
const EVENT_DEAD: u32 = 2u;

// Spectral tracking's choice at a tentative collision with extinction
// `sigma_t` under the majorant `m` (`spectral_event_with`): real with
// probability `p_real / (p_real + p_null)`, `weight` updated so that the
// estimate stays unbiased per channel, or set to zero (`EVENT_DEAD`) where
// the path can carry no more light.
fn spectral_event(sigma_t: vec3<f32>, m: f32, weight: ptr<function, vec3<f32>>, rng: ptr<function, Rng>) -> u32 {
    let sigma_n = max(vec3<f32>(m) - sigma_t, vec3<f32>(0.0));
    let p_real = max_element(*weight * sigma_t);
    let p_null = max_element(*weight * sigma_n);
    let total = p_real + p_null;
    if total <= 0.0 {
        *weight = vec3<f32>(0.0);
        return EVENT_DEAD;
    }
    if rng_next_f32(rng) * total < p_real {
        *weight *= sigma_t * (total / (m * p_real));
        return EVENT_REAL;
    }
    *weight *= sigma_n * (total / (m * p_null));
    return EVENT_NULL;
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
        let event = spectral_event(medium_sigma_t(origin + dir * c.t), c.majorant, weight, rng);
        if event == EVENT_REAL {
            return FreeFlight(c.t, true);
        }
        if event == EVENT_DEAD {
            return FreeFlight(0.0, false);
        }
    }
    // Unreachable: the loop only returns.
    return FreeFlight(0.0, false);
}

// A free flight and one of its tentative collisions drawn for a
// track-length reading (`ProbedFlight`): the real collision at `t` if
// `hit`; the probe at `probe_t` with the weight on arriving there if
// `probed`; `depth`, the sum of `σ_g ρ/m̄` over the tentative collisions.
struct ProbedFlight {
    t: f32,
    hit: bool,
    probe_t: f32,
    probe_w: vec3<f32>,
    probed: bool,
    depth: f32,
}

// `free_flight` that also draws one of its tentative collisions (the real
// one included), each with a chance proportional to `σ_g ρ/m̄` there, from
// `pick`, a stream apart from the flight's (`free_flight_probed`): the
// probe's reading times `depth`, with the weight on arriving, estimates
// `∫ W σ_g ρ f dt` over the track.
fn free_flight_probed(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t0: f32,
    t1: f32,
    weight: ptr<function, vec3<f32>>,
    rng: ptr<function, Rng>,
    pick: ptr<function, Rng>,
) -> ProbedFlight {
    var f = ProbedFlight(0.0, false, 0.0, vec3<f32>(0.0), false, 0.0);
    var s = sample_tentative_start(origin, dir, t0, t1, rng);
    loop {
        let c = sample_tentative_next(&s, rng);
        if !c.found {
            return f;
        }
        let m = c.majorant;
        let sigma_t = medium_sigma_t(origin + dir * c.t);
        let share = max_element(sigma_t) / m;
        if share > 0.0 {
            f.depth += share;
            if rng_next_f32(pick) * f.depth < share {
                f.probe_t = c.t;
                f.probe_w = *weight;
                f.probed = true;
            }
        }
        let event = spectral_event(sigma_t, m, weight, rng);
        if event == EVENT_REAL {
            f.t = c.t;
            f.hit = true;
            return f;
        }
        if event == EVENT_DEAD {
            return f;
        }
    }
    // Unreachable: the loop only returns.
    return f;
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
    let span = in_medium(origin, dir, t_max);
    if !span.hit {
        return vec3<f32>(1.0);
    }
    var tr = vec3<f32>(1.0);
    var s = sample_tentative_start_at_rate(origin, dir, span.t0, span.t1, max(rate, 1.0), rng);
    loop {
        let c = sample_tentative_next(&s, rng);
        if !c.found {
            break;
        }
        let sigma_t = medium_sigma_t(origin + dir * c.t);
        tr *= max(vec3<f32>(1.0) - sigma_t / c.majorant, vec3<f32>(0.0));
        if !roulette_small(&tr, rng) {
            break;
        }
    }
    return tr;
}

// The stretch `[t0, t1]` of the ray `origin + t dir`, `t <= t_max`, inside
// the medium's box (`in_medium`), `hit` false where it is empty: what every
// transmittance estimate integrates over.
fn in_medium(origin: vec3<f32>, dir: vec3<f32>, t_max: f32) -> Interval {
    let clip = medium_clip(origin, dir);
    let t1 = min(clip.t1, t_max);
    return Interval(clip.t0, t1, clip.hit && t1 > clip.t0);
}

// Russian roulette on a running transmittance estimate (`roulette_small`):
// once its largest channel in magnitude is below 0.1 it survives with
// probability 1/2, doubled; `false`, with `tr` zero, where it was dropped
// or carries nothing.
fn roulette_small(tr: ptr<function, vec3<f32>>, rng: ptr<function, Rng>) -> bool {
    let largest = max_element(abs(*tr));
    if !(largest > 0.0) {
        *tr = vec3<f32>(0.0);
        return false;
    }
    if largest < 0.1 {
        if rng_next_f32(rng) < 0.5 {
            *tr = vec3<f32>(0.0);
            return false;
        }
        *tr *= 2.0;
    }
    return true;
}

// The transmittance by ratio tracking at `rate` times the majorant, or by
// the unbiased ray march where `rate` is `TRANSMITTANCE_MARCHED`
// (`Transmittance::estimate`).
fn transmittance_by(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t_max: f32,
    rate: f32,
    rng: ptr<function, Rng>,
) -> vec3<f32> {
    if rate == TRANSMITTANCE_MARCHED {
        return transmittance_marched(origin, dir, t_max, rng);
    }
    return transmittance_at_rate(origin, dir, t_max, rate, rng);
}

// The unbiased ray-marched transmittance (`transmittance_marched`): the ray
// cut into segments of majorant optical depth `MARCH_SEGMENT_DEPTH` (one
// segment of its own depth where it holds less), two jittered marches of
// each segment's optical depth, `e^{-x0}` times the rouletted power series
// of `e^{x0 - tau}` with each later factor from a march of its own
// (`close_segment`), the running product rouletted below 0.1.
//
// Written as one loop around one walk of the majorant grid with one
// density lookup in it: Mesa inlines every call, and the gather makes a
// dozen transmittance calls (a walk per step of the method, as on the CPU,
// made the gather's pipeline too large for lavapipe to compile in
// reasonable time and memory). Each turn of the loop is one walk: the
// first measures the ray's majorant depth up to one segment's worth (the
// CPU's first walk); then, per segment, its two first marches together
// (which also find where the segment ends) and each factor of its series.
// The random numbers are drawn in the CPU's order; where the CPU walks the
// ray once for the first marches, this walks each segment from its start
// (the same points up to rounding).
fn transmittance_marched(
    origin: vec3<f32>,
    dir: vec3<f32>,
    t_max: f32,
    rng: ptr<function, Rng>,
) -> vec3<f32> {
    let span = in_medium(origin, dir, t_max);
    if !span.hit {
        return vec3<f32>(1.0);
    }
    let t1 = span.t1;
    // One segment of the ray's own depth where it holds at most
    // `MARCH_SEGMENT_DEPTH` (`short`), else segments of exactly that, the
    // last cut short. Set by the measuring turn.
    var short = true;
    var depth = MARCH_SEGMENT_DEPTH;
    var stride = 1.0;

    var tr = vec3<f32>(1.0);
    // The segment: its start, its end (once its first marches found it)
    // and whether it is the ray's last.
    var seg_t = span.t0;
    var seg_end = t1;
    var last = true;
    // The series: the first march's depth, the current term and the sum,
    // the next factor's index and the probability it was drawn with. `k`
    // is 1 for the measuring turn, 0 while the segment's first marches
    // are due.
    var x0 = vec3<f32>(0.0);
    var term = vec3<f32>(0.0);
    var sum = vec3<f32>(1.0);
    var k = 1u;
    var p = 1.0;
    loop {
        let measuring = k == 1u;
        let first = k == 0u;
        // One march from `seg_t`: the points `stride` apart in majorant
        // depth from a random offset (two interleaved sequences for the
        // segment's first marches), at most `depth` of it; none while
        // measuring.
        var na = BIG;
        var nb = BIG;
        var span_end = seg_end;
        if !measuring {
            na = rng_next_f32(rng) * stride;
        }
        if first {
            nb = rng_next_f32(rng) * stride;
        }
        if first || measuring {
            span_end = t1;
        }
        var xa = vec3<f32>(0.0);
        var xb = vec3<f32>(0.0);
        var s = 0.0;
        var reached = false;
        var t_end = t1;
        var dda = dda_start(origin, dir, seg_t, span_end);
        loop {
            let seg = dda_next(&dda);
            if !seg.valid {
                break;
            }
            let m = seg.majorant;
            let a = seg.t0;
            let sb = s + m * (seg.t1 - a);
            if measuring {
                s = sb;
                if sb > MARCH_SEGMENT_DEPTH {
                    // Long: the segments are `MARCH_SEGMENT_DEPTH` deep.
                    short = false;
                    break;
                }
                continue;
            }
            if m <= 0.0 {
                continue;
            }
            let lim = min(sb, depth);
            loop {
                let n = min(na, nb);
                if n >= lim {
                    break;
                }
                let v = medium_sigma_t(origin + dir * (a + (n - s) / m)) / m;
                if na <= nb {
                    xa += v;
                    na += stride;
                } else {
                    xb += v;
                    nb += stride;
                }
            }
            if first && !short && sb >= depth {
                // The segment ends where its majorant depth is `depth`:
                // always past `seg_t`, as on the CPU (tracking.rs says why).
                t_end = clamp(a + (depth - s) / m, seg_t, seg.t1);
                reached = true;
                break;
            }
            // Past its last point; a long ray's first marches walk on to
            // where the segment ends.
            if (short || !first) && na >= depth && nb >= depth {
                break;
            }
            s = sb;
        }
        if measuring {
            if !(s < BIG) {
                return vec3<f32>(1.0);
            }
            if short {
                if s <= 0.0 {
                    return vec3<f32>(1.0);
                }
                depth = s;
            }
            stride = depth / max(ceil(depth / MARCH_STRIDE_DEPTH), 1.0);
            k = 0u;
            continue;
        }
        if first {
            x0 = xa * stride;
            term = x0 - xb * stride;
            sum = vec3<f32>(1.0) + term;
            seg_end = t_end;
            last = !reached;
            k = 2u;
        } else {
            term *= (x0 - xa * stride) / (f32(k) * p);
            sum += term;
            k += 1u;
        }
        // The series' next factor, taken with probability `p`.
        if k < MARCH_MAX_TERMS {
            p = min(max_element(abs(term)) * 4.0, 1.0);
            if p > 0.0 && rng_next_f32(rng) < p {
                continue;
            }
        }
        tr *= exp(-x0) * sum;
        if last || !roulette_small(&tr, rng) {
            return tr;
        }
        seg_t = seg_end;
        seg_end = t1;
        k = 0u;
    }
    // Unreachable: the loop only returns.
    return tr;
}
