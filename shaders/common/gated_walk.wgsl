// The path-length clock and the time-gated backward walk that estimates
// `J_N = Σ_{k=0}^{N} G(k s*) S₁` at a point (src/doc/method.md §3, §4, §7). Mirrors
// src/physics/internal/clock.rs (`march_clock`) and walk.rs (the private
// `Walks::walk` and `Walks::accumulate_j_from`). WGSL has no closures, so
// the CPU's `on_gate` callback of `accumulate_j_from` is written out as
// `gate_add`.

// From Rust (the generated prelude, src/gpu/shaders.rs): the clock tags
// `CLOCK_*` (crate::scene::Clock::tag); the largest majorant optical
// depth of one step of the optical-depth clock's quadrature, as a fraction
// of the window `s*`, `CLOCK_SPLIT_WINDOW`
// (crate::physics::gated_walk::CLOCK_SPLIT_WINDOW), and the most steps in
// one majorant cell, `CLOCK_MAX_STEPS`
// (crate::physics::gated_walk::CLOCK_MAX_STEPS).

// The quadrature step in a majorant cell of extinction majorant `m` under
// the window `s_star`, `cell` being the cell's smallest extent
// (`clock_step`).
fn clock_step(cell: f32, m: f32, s_star: f32) -> f32 {
    let steps = ceil(m * cell / (CLOCK_SPLIT_WINDOW * s_star));
    if steps > 1.0 {
        return cell / min(steps, CLOCK_MAX_STEPS);
    }
    return cell;
}

// The phase in (0, 1] of the optical-depth clock's lattice along a ray, a
// hash of its direction (`lattice_phase`): every march along one ray
// measures the same clock, neighbouring rays unrelated ones.
fn lattice_phase(dir: vec3<f32>) -> f32 {
    var s = pcg_hash(bitcast<u32>(dir.z) >> PHASE_DROPPED_BITS);
    s = pcg_hash((bitcast<u32>(dir.y) >> PHASE_DROPPED_BITS) ^ s);
    s = pcg_hash((bitcast<u32>(dir.x) >> PHASE_DROPPED_BITS) ^ s);
    return 1.0 - rng_unit(s);
}

// The `i`-th step `(p0, p1)` of the clock's lattice in the cell `[a, b]`
// and where its rate is sampled (`lattice_step`): a whole step at its
// middle, the first and the last step that the cell's faces cut where
// each point of the cell weighs once over the phase.
fn lattice_step(a: f32, b: f32, h: f32, phase: f32, i: u32) -> vec3<f32> {
    let end = a + (f32(i) + phase) * h;
    if i == 0u {
        if end < b {
            return vec3<f32>(a, end, a + 0.5 * phase * phase * h);
        }
        return vec3<f32>(a, b, 0.5 * (a + b));
    }
    let p0 = a + (f32(i) - 1.0 + phase) * h;
    if end < b {
        return vec3<f32>(p0, end, 0.5 * (p0 + end));
    }
    let l = max(b - p0, 0.0);
    return vec3<f32>(p0, b, b - 0.5 * l * l / h);
}

// Slots of a walk's per-term output on the GPU (a private array per
// invocation): `GPU_MAX_GATES`, from Rust (the generated prelude:
// crate::physics::internal::clock::RESOLVED_TERMS + 1). Terms past the last
// slot add to it (`term_slot`), so a walk still runs to gate `N`.

// A walk that never ends is guarded against as a reference path is
// (`MAX_COLLISIONS_GUARD` of reference.wgsl), which the CPU does not need;
// its Russian roulette is the reference's `roulette`.

// Collisions of a walk after which its directions are guided; later ones
// come from the phase function alone: `GUIDED_COLLISIONS`, from Rust (the
// generated prelude: crate::physics::gated_walk::GUIDED_COLLISIONS).

// Per-gate terms of one walk, `k = 0..=N`.
alias GateTerms = array<vec3<f32>, GPU_MAX_GATES>;

// Parameters of the time-gated walk (`GateSettings`).
struct GateSettings {
    s_star: f32,
    n_terms: u32,
    clock: u32,
    rr_start: u32,
}

// Where a clock budget runs out along a ray (`ClockMarch`): `reached` at
// ray parameter `value`, or the ray ended first and the clock advanced by
// `value`; `rate`: where reached, the clock's rate in the quadrature step
// there (`march_clock_rate`; one for the geometric clock), zero otherwise.
struct ClockMarch {
    value: f32,
    reached: bool,
    rate: f32,
}

// Advances the clock (gating windows of `s_star`) along `origin + t dir`
// from `t0` (inside or on the box) towards `t_stop ≤ t_exit`
// (`march_clock`).
fn march_clock(
    clock: u32,
    s_star: f32,
    origin: vec3<f32>,
    dir: vec3<f32>,
    t0: f32,
    t_exit: f32,
    t_stop_in: f32,
    budget: f32,
) -> ClockMarch {
    let t_stop = min(t_stop_in, t_exit);
    if clock == CLOCK_GEOMETRIC {
        let span = max(t_stop - t0, 0.0);
        if span >= budget {
            return ClockMarch(t0 + max(budget, 0.0), true, 1.0);
        }
        return ClockMarch(span, false, 0.0);
    }
    if budget <= 0.0 {
        return ClockMarch(t0, true, 0.0);
    }
    let m = scene.medium;
    let cell = (m.majorant_max - m.majorant_min) / vec3<f32>(m.majorant_res);
    let cell_min = max(min(min(cell.x, cell.y), cell.z), 1e-12);
    let sigma_g = max_element(m.sigma_t);
    let phase = lattice_phase(dir);
    var acc = 0.0;
    var it = dda_start(origin, dir, t0, t_exit);
    loop {
        let seg = dda_next(&it);
        if !seg.valid || seg.t0 >= t_stop {
            break;
        }
        if seg.majorant <= 0.0 {
            // The majorant bounds ρ: nothing to count in this cell.
            if seg.t1 < t_stop {
                continue;
            }
            break;
        }
        let a = seg.t0;
        let b = seg.t1;
        let h = clock_step(cell_min, seg.majorant, s_star);
        var i = 0u;
        loop {
            let step = lattice_step(a, b, h, phase, i);
            let p0 = step.x;
            if p0 >= b {
                break;
            }
            let p1 = step.y;
            let c = sigma_g * density(origin + dir * step.z);
            let end = min(p1, t_stop);
            let d_tau = c * max(end - p0, 0.0);
            if c > 0.0 && acc + d_tau >= budget {
                return ClockMarch(min(p0 + (budget - acc) / c, end), true, c);
            }
            acc += d_tau;
            if p1 >= t_stop {
                return ClockMarch(acc, false, 0.0);
            }
            i += 1u;
        }
    }
    return ClockMarch(acc, false, 0.0);
}

// From Rust (the generated prelude): the least `collision_probability`
// returns, `COLLISION_FLOOR` (crate::physics::gated_walk::COLLISION_FLOOR),
// and the optical depth past which it is one, `COLLISION_DEPTH`
// (crate::physics::gated_walk::COLLISION_DEPTH).

// The chance that light travelling from `p` along `d` collides before it
// leaves the box, `1 − e^{−τ}` with `τ` the grey optical depth to the exit
// by the optical-depth clock's quadrature, one past `COLLISION_DEPTH`,
// never below `COLLISION_FLOOR`
// (`collision_probability`): the walks divide their collided part by it,
// the gather multiplies the reconstruction by it.
fn collision_probability(s_star: f32, p: vec3<f32>, d: vec3<f32>) -> f32 {
    let clip = medium_clip(p, d);
    if !clip.hit {
        return COLLISION_FLOOR;
    }
    var chances = chances_along_ray(p, d, clip.t1, s_star);
    return chance_at(&chances, 0.0);
}

// `collision_probability` at points of one ray asked for from its far end
// back (`ChancesAlongRay`): the nearest point asked for so far and its
// optical depth to the exit (`known_t` negative: none yet), and whether that
// depth reached `COLLISION_DEPTH`.
struct ChancesAlongRay {
    origin: vec3<f32>,
    dir: vec3<f32>,
    t_exit: f32,
    s_star: f32,
    known_t: f32,
    known_tau: f32,
    saturated: bool,
}

fn chances_along_ray(origin: vec3<f32>, dir: vec3<f32>, t_exit: f32, s_star: f32) -> ChancesAlongRay {
    return ChancesAlongRay(origin, dir, t_exit, s_star, -1.0, 0.0, false);
}

// The chance at `origin + t dir` of a collision along `dir` before the
// exit: one march to `COLLISION_DEPTH` for the first point, then the
// stretch from each point to the one asked for before it.
fn chance_at(c: ptr<function, ChancesAlongRay>, t_in: f32) -> f32 {
    if (*c).saturated {
        return 1.0;
    }
    var t = min(t_in, (*c).t_exit);
    var t_stop = (*c).t_exit;
    var budget = COLLISION_DEPTH;
    if (*c).known_t >= 0.0 {
        t = min(t, (*c).known_t);
        t_stop = (*c).known_t;
        budget = COLLISION_DEPTH - (*c).known_tau;
    }
    let m = march_clock(
        CLOCK_OPTICAL_DEPTH, (*c).s_star, (*c).origin, (*c).dir, t, (*c).t_exit, t_stop, budget,
    );
    if m.reached {
        (*c).saturated = true;
        return 1.0;
    }
    (*c).known_tau += m.value;
    (*c).known_t = t;
    return max(1.0 - exp(-(*c).known_tau), COLLISION_FLOOR);
}

// The sum over gates of what `accumulate_j_from` added before the walk's
// first collision (`accumulate_j_split`'s `unscattered`, summed over k):
// reset at the start of each walk.
var<private> walk_unscattered: vec3<f32>;

// When true, `accumulate_j_from` adds only what the walk carries through a
// collision and skips the shadow rays of the gates before its first one
// (`accumulate_collided`: the walks towards the eye, which discard that
// part); `walk_unscattered` then stays zero. Set per walk by the caller.
var<private> walk_collided_only: bool;

// When true, a walk on the optical-depth clock reads the rest of its path
// once per flight after `COLLISION_TAIL_AFTER` collisions (`collision_tail`):
// the walks towards the eye and the phase walks, whose callers sum the
// terms, in a medium of `|g|` ≥ `COLLISION_TAIL_MIN_G`. Set per walk by the
// caller, with `walk_majorant_peak`, the medium's largest extinction
// majorant, which bounds the tail's clock. `COLLISION_TAIL_AFTER` and
// `COLLISION_TAIL_MIN_G` come from Rust (the generated prelude:
// crate::physics::internal::walk).
var<private> walk_sums_terms: bool;
var<private> walk_majorant_peak: f32;

// Probability that a walk's direction after a collision is drawn towards an
// external light rather than from the phase function, and the
// Henyey–Greenstein parameter of those lobes: `GUIDE_PROBABILITY` and
// `GUIDE_G`, from Rust (the generated prelude:
// crate::physics::gated_walk::{GUIDE_PROBABILITY, GUIDE_G}).

// The external lights' unshadowed irradiance at `p` summed (largest
// channel of each): `irradiance_total` (src/physics/internal/guiding.rs),
// whose `None` is a sum not above 0 or above 1e38 here.
fn irradiance_total(p: vec3<f32>) -> f32 {
    let count = light_count();
    var total = 0.0;
    for (var i = 0u; i < count; i++) {
        total += max(max_element(light_at(i, p).irradiance), 0.0);
    }
    return total;
}

// The external light chosen at `p` in proportion to its unshadowed
// irradiance by `u` in [0, 1), `total` being `irradiance_total`'s
// (`light_by_irradiance`): the first whose share holds `u · total`, or the
// last that shines where rounding leaves it past the end.
struct ChosenLight {
    found: bool,
    light: LightSample,
}

fn light_by_irradiance(p: vec3<f32>, total: f32, u: f32) -> ChosenLight {
    var pick = u * total;
    var chosen: ChosenLight;
    chosen.found = false;
    var has_last = false;
    var last: LightSample;
    let count = light_count();
    for (var i = 0u; i < count; i++) {
        let l = light_at(i, p);
        let w = max(max_element(l.irradiance), 0.0);
        if w > 0.0 {
            last = l;
            has_last = true;
            if !chosen.found && pick < w {
                chosen = ChosenLight(true, l);
            }
            pick -= w;
        }
    }
    if !chosen.found && has_last {
        chosen = ChosenLight(true, last);
    }
    return chosen;
}

// A walk's next direction and the factor its weight takes.
struct GuidedDirection {
    dir: vec3<f32>,
    factor: f32,
}

// A backward walk's next direction after a collision at `p`, coming in along
// `dir` (`guided_direction`): with probability `1 − GUIDE_PROBABILITY` from
// the phase function, otherwise from a lobe about the direction towards one
// external light chosen in proportion to its unshadowed irradiance at `p`
// (largest channel); the factor is the phase function over the mixture's
// density. `u1, u2` place the direction in its lobe; the choice of lobe
// draws from `rng`, after them, as the CPU does.
fn guided_direction(
    g: f32,
    p: vec3<f32>,
    dir: vec3<f32>,
    u1: f32,
    u2: f32,
    rng: ptr<function, Rng>,
) -> GuidedDirection {
    let count = light_count();
    let total = irradiance_total(p);
    if !(total > 0.0) || total > 1.0e38 {
        return GuidedDirection(sample_hg(g, dir, u1, u2), 1.0);
    }
    let u = rng_next_f32(rng);
    var next = sample_hg(g, dir, u1, u2);
    if u < GUIDE_PROBABILITY {
        // A light in proportion to its irradiance, then its lobe.
        let chosen = light_by_irradiance(p, total, u / GUIDE_PROBABILITY);
        if chosen.found {
            next = sample_hg(GUIDE_G, -chosen.light.travel, u1, u2);
        }
    }
    let p_phase = hg(g, dot(dir, next));
    var p_lobes = 0.0;
    for (var i = 0u; i < count; i++) {
        let l = light_at(i, p);
        let w = max(max_element(l.irradiance), 0.0);
        if w > 0.0 {
            p_lobes += w / total * hg(GUIDE_G, dot(next, -l.travel));
        }
    }
    let mixture = (1.0 - GUIDE_PROBABILITY) * p_phase + GUIDE_PROBABILITY * p_lobes;
    if mixture > 0.0 {
        return GuidedDirection(next, p_phase / mixture);
    }
    return GuidedDirection(next, 0.0);
}

// A collision's second flight (`second_flight`,
// src/physics/internal/guiding.rs), taken in media of `g` ≥
// `SECOND_FLIGHT_MIN_G` instead of guided directions: whether there is one,
// its direction, and the balance-heuristic factors `P/(P + q)` of its gates
// and of the gates of the walk's own flight. `SECOND_FLIGHT_MIN_G` and
// `SECOND_FLIGHT_MAX_DEPTH` come from Rust (the generated prelude).
struct SecondFlight {
    valid: bool,
    dir: vec3<f32>,
    factor: f32,
    own_factor: f32,
}

// `P/(P + q)` at the direction `d`: the phase function about the incoming
// `dir` against the lobe about `towards`, both of the medium's `g`.
fn flight_balance(g: f32, dir: vec3<f32>, towards: vec3<f32>, d: vec3<f32>) -> f32 {
    let p_phase = hg(g, dot(dir, d));
    let q = hg(g, dot(d, towards));
    if p_phase + q > 0.0 {
        return p_phase / (p_phase + q);
    }
    return 0.0;
}

// The second flight of a backward walk at a collision at `p`, where it came
// in along `dir` and drew its own direction `own` from the phase function:
// one light chosen in proportion to its unshadowed irradiance by `u`; none
// where the majorant's optical depth towards it reaches
// `SECOND_FLIGHT_MAX_DEPTH` (up to the box's edge or a point light) or no
// light shines; else its direction from the lobe about the direction
// towards the light, placed by `u1, u2`.
fn second_flight(
    p: vec3<f32>,
    dir: vec3<f32>,
    own: vec3<f32>,
    u: f32,
    u1: f32,
    u2: f32,
) -> SecondFlight {
    var none: SecondFlight;
    none.valid = false;
    let total = irradiance_total(p);
    if !(total > 0.0) || total > 1.0e38 {
        return none;
    }
    let chosen = light_by_irradiance(p, total, u);
    if !chosen.found {
        return none;
    }
    let light = chosen.light;
    let towards = -light.travel;
    let clip = medium_clip(p, towards);
    if !clip.hit {
        return none;
    }
    let depth = majorant_depth(p, towards, clip.t0, min(clip.t1, light.distance), SECOND_FLIGHT_MAX_DEPTH);
    if depth >= SECOND_FLIGHT_MAX_DEPTH {
        return none;
    }
    let g = scene.medium.g;
    let second = sample_hg(g, towards, u1, u2);
    return SecondFlight(
        true,
        second,
        flight_balance(g, dir, towards, second),
        flight_balance(g, dir, towards, own),
    );
}

// One gate of `accumulate_j_from` (its `on_gate` closure): adds
// `w · α σ_t · ρ · (S₁/b)(z_k, n_k)` to term `k`, with `ρ = ρ(z_k)` for the
// geometric clock and `ρ(z)` for the optical-depth clock, and to
// `walk_unscattered` too if the walk has not collided yet (nothing before
// the first collision, and no shadow ray, with `walk_collided_only`).
fn gate_add(
    k: u32,
    w: vec3<f32>,
    zk: vec3<f32>,
    nk: vec3<f32>,
    scattered: bool,
    settings: GateSettings,
    first: u32,
    rho_z: f32,
    rng: ptr<function, Rng>,
    out: ptr<function, GateTerms>,
) {
    if k < first || all(w == vec3<f32>(0.0)) || (walk_collided_only && !scattered) {
        return;
    }
    var rho = rho_z;
    if settings.clock == CLOCK_GEOMETRIC {
        rho = density(zk);
    }
    if rho <= 0.0 {
        return;
    }
    let scatter = scene.medium.albedo * scene.medium.sigma_t;
    let source = gate_scatter_source(zk, nk, rng);
    let v = w * scatter * rho * source;
    (*out)[min(k, GPU_MAX_GATES - 1u)] += v;
    if !scattered {
        walk_unscattered += v;
    }
}

// A walk's own state at a collision, kept while the collision's second
// flight runs (`Resume` on the CPU): position, direction, weight, next
// gate and clock.
struct OwnFlight {
    origin: vec3<f32>,
    dir: vec3<f32>,
    weight: vec3<f32>,
    next: u32,
    clock: f32,
}

// Where a walk hands its gates over to `collision_tail`, or the tail hands
// the walk back (`TailState`): at a collision, with the walk's new
// direction and weight, that collision's second flight, the exact clock
// there and the collisions so far. `back` is false where the walk ended.
struct TailState {
    origin: vec3<f32>,
    dir: vec3<f32>,
    weight: vec3<f32>,
    second: SecondFlight,
    clock: f32,
    collisions: u32,
    back: bool,
}

// Whether a flight from `p` along `d` may reach the clock `end` from the
// clock bound `bound` (`collision_tail`'s test): the medium's largest
// majorant times the chord first, the cells' majorants where that says it
// might.
fn tail_may_reach(p: vec3<f32>, d: vec3<f32>, bound: f32, end: f32) -> bool {
    let clip = medium_clip(p, d);
    if !clip.hit {
        return false;
    }
    if bound + walk_majorant_peak * (clip.t1 - clip.t0) < end {
        return false;
    }
    return bound + majorant_depth(p, d, clip.t0, clip.t1, end - bound) >= end;
}

// The rest of a walk that sums its terms, from the collision `at` on, by a
// track-length estimator with one reading per flight
// (`Walks::collision_tail`): each flight read once, at one of its
// tentative collisions drawn `∝ σ_g ρ/m̄` (`free_flight_probed`),
// `(1/s*) W Σ(σ_g ρ/m̄) (S₁/b)` there, also the last flight that leaves the
// medium; the second flight with its factor, the own flight with the
// other; no clock. Its flights, directions and roulette draw from a stream
// of their own, started from `rng`; the probes from `rng` itself. The clock's bound grows by the medium's largest
// majorant times each own flight's length; where a collision's flights
// may reach the series' end `(N + ½) s*`, the tail walks its path again
// from `at` on the same stream, reading nothing and marching the clock
// over its own flights, and returns that collision with the exact clock
// (`back`); otherwise it returns with `back` false when the walk ends.
// One loop, one flight per iteration of its inner two (the second
// flight, then the own), so that the shader holds one more tracking loop.
fn collision_tail(
    at: TailState,
    settings: GateSettings,
    rho_z: f32,
    rng: ptr<function, Rng>,
    out: ptr<function, GateTerms>,
) -> TailState {
    let s_star = max(settings.s_star, 1e-12);
    let per_gate = 1.0 / s_star;
    let end = (f32(settings.n_terms) + 0.5) * s_star;
    let k = min(u32(floor(at.clock / s_star)) + 1u, settings.n_terms);
    let path_start = pcg_hash(rng_next_u32(rng));
    var path = Rng(path_start);
    var state = at;
    var bound = at.clock;
    var steps = 0u;
    var replay = false;
    var replay_to = 0u;
    var clock = at.clock;
    loop {
        if replay && steps == replay_to {
            state.clock = clock;
            state.back = true;
            return state;
        }
        if !replay {
            var near = tail_may_reach(state.origin, state.dir, bound, end);
            if state.second.valid {
                near = near || tail_may_reach(state.origin, state.second.dir, bound, end);
            }
            if near {
                replay = true;
                replay_to = steps;
                steps = 0u;
                state = at;
                path = Rng(path_start);
                clock = at.clock;
                continue;
            }
        }
        var own_hit = false;
        for (var f = 0u; f < 2u; f++) {
            let second_flight_now = f == 0u;
            var d = state.dir;
            var w = state.weight;
            var flies = true;
            if second_flight_now {
                flies = state.second.valid;
                d = state.second.dir;
                w = state.weight * state.second.factor;
            }
            let clip = medium_clip(state.origin, d);
            flies = flies && clip.hit;
            if flies {
                let flight = free_flight_probed(state.origin, d, clip.t0, clip.t1, &w, &path, rng);
                var own_factor = 1.0;
                if !second_flight_now && state.second.valid {
                    own_factor = state.second.own_factor;
                }
                if flight.probed && !replay {
                    let at_probe = state.origin + d * flight.probe_t;
                    let w_read = flight.probe_w * (own_factor * flight.depth * per_gate);
                    gate_add(k, w_read, at_probe, -d, true, settings, 1u, rho_z, rng, out);
                }
                if !second_flight_now {
                    state.weight = w;
                    if flight.hit {
                        own_hit = true;
                        if replay {
                            let m = march_clock(
                                CLOCK_OPTICAL_DEPTH, settings.s_star, state.origin, d, clip.t0, clip.t1, flight.t, BIG,
                            );
                            if !m.reached {
                                clock += m.value;
                            }
                        } else {
                            bound += walk_majorant_peak * (flight.t - clip.t0);
                        }
                        state.origin += d * flight.t;
                    }
                }
            }
        }
        state.back = false;
        if !own_hit {
            return state;
        }
        state.weight *= scene.medium.albedo;
        state.collisions += 1u;
        if state.collisions >= MAX_COLLISIONS_GUARD {
            return state;
        }
        // (Through a plain variable: naga 30 writes no SPIR-V for a pointer
        // to a field of a local struct passed to a function.)
        var survivor = state.weight;
        if state.collisions >= settings.rr_start && !roulette(&survivor, &path) {
            return state;
        }
        state.weight = survivor;
        let u1 = rng_next_f32(&path);
        let u2 = rng_next_f32(&path);
        let incoming = state.dir;
        let seconds = scene.medium.g >= SECOND_FLIGHT_MIN_G;
        if state.collisions <= GUIDED_COLLISIONS && !seconds {
            let next_dir = guided_direction(scene.medium.g, state.origin, incoming, u1, u2, &path);
            state.dir = next_dir.dir;
            state.weight *= next_dir.factor;
        } else {
            state.dir = sample_hg(scene.medium.g, incoming, u1, u2);
        }
        state.second.valid = false;
        if seconds {
            let u = rng_next_f32(&path);
            let v1 = rng_next_f32(&path);
            let v2 = rng_next_f32(&path);
            state.second = second_flight(state.origin, incoming, state.dir, u, v1, v2);
        }
        steps += 1u;
    }
    // Unreachable: the loop only returns.
    return state;
}

// Adds one walk's estimate of `Ĵ_k(z, n)`, `k = first..=N`, to `out`
// (`accumulate_j_from`, with the walk of `walk` inlined): a backward walk
// from `z` along `−n` by spectral tracking, albedo and Russian roulette at
// real collisions, phase-sampled directions, gates at clock `k s*`; leaving
// the box ends it. Terms from `GPU_MAX_GATES − 1` on share the last slot.
// `walk_unscattered` receives the part added before the first collision.
// Where `g` ≥ `SECOND_FLIGHT_MIN_G` each collision may also take a second
// flight (`second_flight`), run as a state of the same loop — so that the
// shader holds one flight, which Mesa's compiler inlines once — before the
// walk resumes its own flight from the collision.
fn accumulate_j_from(
    z: vec3<f32>,
    n: vec3<f32>,
    settings: GateSettings,
    first: u32,
    rng: ptr<function, Rng>,
    out: ptr<function, GateTerms>,
) {
    walk_unscattered = vec3<f32>(0.0);
    let rho_z = density(z);
    if settings.clock == CLOCK_OPTICAL_DEPTH && rho_z <= 0.0 {
        return;
    }
    let geometric = settings.clock == CLOCK_GEOMETRIC;
    let s_star = max(settings.s_star, 0.0);
    let last = settings.n_terms;
    var weight = vec3<f32>(1.0);
    gate_add(0u, weight, z, n, false, settings, first, rho_z, rng, out);
    if last == 0u {
        return;
    }
    var next = 1u;
    var origin = z;
    var dir = -n;
    // Clock value at `origin`.
    var clock_at_origin = 0.0;
    var collisions = 0u;
    // Second flights (`second_flight`): whether they are taken, whether one
    // runs, whether it has just ended, and the factor of the gates of the
    // walk's own flight since its last collision. While one runs, the walk's
    // own state at the collision waits in `own`.
    let seconds = scene.medium.g >= SECOND_FLIGHT_MIN_G;
    var in_second = false;
    var second_ended = false;
    var own_factor = 1.0;
    var own: OwnFlight;
    // One flight per iteration: from `origin` to the next gate, the next
    // real collision, or the exit of the box, whichever comes first.
    loop {
        if second_ended {
            // The walk resumes its own flight from the collision.
            origin = own.origin;
            dir = own.dir;
            weight = own.weight;
            next = own.next;
            clock_at_origin = own.clock;
            in_second = false;
            second_ended = false;
        }
        let clip = medium_clip(origin, dir);
        if !clip.hit {
            if in_second {
                second_ended = true;
                continue;
            }
            return;
        }
        var clock_at_enter = clock_at_origin;
        if geometric {
            clock_at_enter = clock_at_origin + clip.t0;
        }
        // Gates in the vacuum before the box (only when `z` is outside it,
        // and only for the geometric clock), or at a flight's start where
        // rounding put the clock on the gate.
        while geometric && f32(next) * s_star <= clock_at_enter {
            let t = f32(next) * s_star - clock_at_origin;
            var factor = own_factor;
            if in_second {
                factor = 1.0;
            }
            gate_add(next, weight * factor, origin + dir * t, -dir, collisions > 0u, settings, first, rho_z, rng, out);
            if next == last {
                if in_second {
                    second_ended = true;
                    break;
                }
                return;
            }
            next += 1u;
        }
        if second_ended {
            continue;
        }
        let gate_clock = f32(next) * s_star;
        let budget = gate_clock - clock_at_enter;
        // The CPU marches the optical-depth clock only once the majorant
        // optical depth says the gate may be near (`LazyClock`,
        // `optical_depth_flight`: the same clock on the same lattice, and
        // the same estimator). Here the flight marches to the gate and
        // again to the collision.
        let march = march_clock(
            settings.clock, settings.s_star, origin, dir, clip.t0, clip.t1, clip.t1, budget,
        );
        var flight_end = clip.t1;
        if march.reached {
            flight_end = march.value;
        }
        let flight = free_flight(origin, dir, clip.t0, flight_end, &weight, rng);
        if flight.hit && in_second {
            // A second flight ends at its first collision.
            second_ended = true;
            continue;
        }
        if flight.hit {
            let to_hit = march_clock(
                settings.clock, settings.s_star, origin, dir, clip.t0, clip.t1, flight.t, BIG,
            );
            var advanced = 0.0;
            if !to_hit.reached {
                advanced = to_hit.value;
            }
            // Rounding must not put the collision past the gate.
            clock_at_origin = min(clock_at_enter + advanced, gate_clock);
            origin += dir * flight.t;
            weight *= scene.medium.albedo;
            collisions += 1u;
            if collisions >= MAX_COLLISIONS_GUARD {
                return;
            }
            if collisions >= settings.rr_start && !roulette(&weight, rng) {
                return;
            }
            let u1 = rng_next_f32(rng);
            let u2 = rng_next_f32(rng);
            let incoming = dir;
            if collisions <= GUIDED_COLLISIONS && !seconds {
                let next_dir = guided_direction(scene.medium.g, origin, dir, u1, u2, rng);
                dir = next_dir.dir;
                weight *= next_dir.factor;
            } else {
                dir = sample_hg(scene.medium.g, dir, u1, u2);
            }
            own_factor = 1.0;
            var second: SecondFlight;
            second.valid = false;
            if seconds {
                let u = rng_next_f32(rng);
                let v1 = rng_next_f32(rng);
                let v2 = rng_next_f32(rng);
                second = second_flight(origin, incoming, dir, u, v1, v2);
            }
            if walk_sums_terms && !geometric && collisions >= COLLISION_TAIL_AFTER {
                let back = collision_tail(
                    TailState(origin, dir, weight, second, clock_at_origin, collisions, false),
                    settings,
                    rho_z,
                    rng,
                    out,
                );
                if !back.back {
                    return;
                }
                // The series' end is near: the gates take the walk over
                // again from the collision the tail stopped at.
                next = u32(floor(back.clock / s_star)) + 1u;
                if next > last {
                    return;
                }
                origin = back.origin;
                dir = back.dir;
                weight = back.weight;
                collisions = back.collisions;
                clock_at_origin = back.clock;
                second = back.second;
            }
            if second.valid {
                own_factor = second.own_factor;
                own = OwnFlight(origin, dir, weight, next, clock_at_origin);
                in_second = true;
                dir = second.dir;
                weight *= second.factor;
            }
        } else {
            // No gate before the exit: the walk (or its second flight) left
            // the box, and nothing comes back from the vacuum outside it.
            if all(weight == vec3<f32>(0.0)) || !march.reached {
                if in_second {
                    second_ended = true;
                    continue;
                }
                return;
            }
            origin += dir * march.value;
            // A second flight's weight carries its factor.
            var factor = own_factor;
            if in_second {
                factor = 1.0;
            }
            gate_add(next, weight * factor, origin, -dir, collisions > 0u, settings, first, rho_z, rng, out);
            if next == last {
                if in_second {
                    second_ended = true;
                    continue;
                }
                return;
            }
            next += 1u;
            // The flight goes on from the gate: flights are memoryless, and
            // the quadrature lattice is re-anchored here.
            clock_at_origin = gate_clock;
        }
    }
}
