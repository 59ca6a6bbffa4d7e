// The final gather of the internal-lights method (src/doc/method.md §6). Mirrors
// `gather` and `field_l1_at` in src/physics/internal/gather.rs, part for part. The
// window `[0, w]` of the camera ray is cut into `samples` strata with one
// jittered point `y` each (transmittance `T(x, y)` by ratio tracking),
// placed by `points_along` (uniform, or following the extinction for the
// optical-depth clock):
//
// - `single`: the k = 0 part of L₀, `∫ T b S₁ dt`, a marched single
//   scatter with `S₁(y)` by next-event estimation at every point, and the
//   unscattered part of the k ≥ 1 terms, the same march on the rest of
//   the ray up to a clock of `(N+1) s*` (`single_beyond_window`).
// - `reconstructed`: the rest of the k ≥ 1 part of L₀, `∫ T Ĵ dt` with `Ĵ`
//   the kernel reconstruction of what the walks carried through a
//   collision (`reconstruct_multi` at `scattered_offset`, per unit chance
//   of the collision, times `collision_probability` at `y`, the window's
//   points sharing one march: `chance_at`).
// - `internal`: L₁, in the form `gather_params.l1_form` says:
//   - field (`L1_FIELD`, default): at each point `y`, one scattering of
//     the reconstructed field `J = S₁ + Ĵ` at `x' = y − r n'`, `n'` drawn
//     from the phase function and `r` up to where the clock's budget
//     runs out, uniform in the clock (`field_l1_at`); the point-light loop
//     is skipped.
//   - points (`L1_POINTS`, the note's eq. 23): one light per sample, a
//     cluster ∝ P_c / (d_c² + h₁²) and a light ∝ V_i J̄_i, equiangular
//     sampling of the ray about it. The CPU keeps the clusters' running
//     sums in a vector; here the selection scans the live clusters again
//     with the same arithmetic, which picks the same cluster without
//     per-thread storage.

// Where the gather's points go along a stretch of a ray (`SegmentPdf` in
// src/physics/internal/segment_pdf.rs): `SEGMENT_PIECES` equal pieces, uniform
// (geometric clock) or each in proportion to the chance that light is
// stopped in it, `e^{−τ_l} (1 − e^{−c_l Δ})` with `c_l` the larger grey
// extinction at its ends and `τ_l` by the trapezoid rule, mixed with the
// uniform share `SEGMENT_DEFENSIVE` (optical-depth clock); uniform within a
// piece.
// The gather estimates every transmittance as `GATHER_TRANSMITTANCE` says
// (`transmittance_by`: the unbiased ray march). It and `SEGMENT_PIECES`,
// `SEGMENT_DEFENSIVE` come from Rust (the generated prelude:
// crate::physics::gather::GATHER_TRANSMITTANCE,
// crate::physics::segment_pdf::{PIECES, DEFENSIVE}).

struct SegmentPdf {
    t0: f32,
    width: f32,
    prob: array<f32, SEGMENT_PIECES>,
}

// `SegmentPdf::uniform` over `[t0, t1]`.
fn segment_pdf_uniform(t0: f32, t1: f32) -> SegmentPdf {
    var pdf: SegmentPdf;
    pdf.t0 = t0;
    pdf.width = max(t1 - t0, 0.0) / f32(SEGMENT_PIECES);
    for (var l = 0u; l < SEGMENT_PIECES; l++) {
        pdf.prob[l] = 1.0 / f32(SEGMENT_PIECES);
    }
    return pdf;
}

// The gather's points along `[t0, t1]` of `origin + t dir` (`points_along`):
// `SegmentPdf::by_extinction` for the optical-depth clock.
fn points_along(clock: u32, origin: vec3<f32>, dir: vec3<f32>, t0: f32, t1: f32) -> SegmentPdf {
    var pdf = segment_pdf_uniform(t0, t1);
    if clock == CLOCK_GEOMETRIC {
        return pdf;
    }
    let sigma_g = max_element(scene.medium.sigma_t);
    var stopped: array<f32, SEGMENT_PIECES>;
    var tau = 0.0;
    var total = 0.0;
    var c_a = sigma_g * density(origin + dir * t0);
    for (var l = 0u; l < SEGMENT_PIECES; l++) {
        let c_b = sigma_g * density(origin + dir * (t0 + f32(l + 1u) * pdf.width));
        stopped[l] = exp(-tau) * (1.0 - exp(-max(c_a, c_b) * pdf.width));
        total += stopped[l];
        tau += 0.5 * (c_a + c_b) * pdf.width;
        c_a = c_b;
    }
    if total > 0.0 && total < BIG {
        let share = SEGMENT_DEFENSIVE / f32(SEGMENT_PIECES);
        for (var l = 0u; l < SEGMENT_PIECES; l++) {
            pdf.prob[l] = (1.0 - SEGMENT_DEFENSIVE) * stopped[l] / total + share;
        }
    }
    return pdf;
}

// The point for `u ∈ [0, 1)` and `1 / pdf` there (`SegmentPdf::sample`).
fn segment_sample(pdf: ptr<function, SegmentPdf>, u: f32) -> vec2<f32> {
    var acc = 0.0;
    var l = 0u;
    while l < SEGMENT_PIECES - 1u && acc + (*pdf).prob[l] <= u {
        acc += (*pdf).prob[l];
        l += 1u;
    }
    let p = (*pdf).prob[l];
    let within = clamp((u - acc) / p, 0.0, 1.0);
    return vec2<f32>((*pdf).t0 + (f32(l) + within) * (*pdf).width, (*pdf).width / p);
}

// One gather estimate, by part (`GatherSample`).
struct GatherSample {
    single: vec3<f32>,
    reconstructed: vec3<f32>,
    internal: vec3<f32>,
}

// The clock's advance along the ray from `origin` over `[0, t]`,
// `t ≤ t_exit` (`clock_to`).
fn clock_to(clock: u32, origin: vec3<f32>, dir: vec3<f32>, t: f32, t_exit: f32) -> f32 {
    if clock == CLOCK_GEOMETRIC {
        return t;
    }
    let m = march_clock(clock, gather_params.s_star, origin, dir, 0.0, t_exit, t, BIG);
    if m.reached {
        return BIG;
    }
    return m.value;
}

// Distance from `p` to the segment `a + t d`, `t ∈ [0, len]`
// (`distance_to_segment`).
fn distance_to_segment(p: vec3<f32>, a: vec3<f32>, d: vec3<f32>, len: f32) -> f32 {
    let t = clamp(dot(p - a, d), 0.0, len);
    return length(p - (a + d * t));
}

// The selection weight of live cluster `c` for the window `x + t dir`,
// `t ∈ [0, window]`, or a negative number when it is out of reach (the
// loop body that builds the CPU's `cdf`).
fn cluster_weight(c: u32, x: vec3<f32>, dir: vec3<f32>, window: f32, h2: f32) -> f32 {
    let bx = cluster_box(c);
    let centre = 0.5 * (bx[0] + bx[1]);
    let half_diag = 0.5 * length(bx[1] - bx[0]);
    if gather_params.clock == CLOCK_GEOMETRIC && length(centre - x) - half_diag > gather_params.s_star {
        return -1.0;
    }
    let d = max(distance_to_segment(centre, x, dir, window) - half_diag, 0.0);
    let power = bitcast<f32>(internal_words[gather_params.cluster_power_offset + c]);
    return power / (d * d + h2);
}

// The unscattered part of L₀'s k ≥ 1 terms, the single scatter on the rest
// of the ray up to a clock of `(N+1) s*`, marched at `samples` stratified
// points (`single_beyond_window`).
fn single_beyond_window(
    x: vec3<f32>,
    dir: vec3<f32>,
    window: f32,
    len: f32,
    samples: u32,
    rng: ptr<function, Rng>,
) -> vec3<f32> {
    let terms = gather_params.n_terms;
    if terms == 0u || window >= len {
        return vec3<f32>(0.0);
    }
    // The clock is at `s*` at the window's end: march on from there (not
    // again from `x`) for the remaining `N s*`.
    let budget = gather_params.s_star * f32(terms);
    let em = march_clock(
        gather_params.clock, gather_params.s_star, x, dir, window, len, len, budget,
    );
    let end = select(len, em.value, em.reached);
    if end <= window {
        return vec3<f32>(0.0);
    }
    let n = -dir;
    var points = points_along(gather_params.clock, x, dir, window, end);
    var sum = vec3<f32>(0.0);
    for (var j = 0u; j < samples; j++) {
        let ts = segment_sample(&points, (f32(j) + rng_next_f32(rng)) / f32(samples));
        let t = ts.x;
        let step = ts.y / f32(samples);
        let y = x + dir * t;
        let rho = density(y);
        if rho <= 0.0 {
            continue;
        }
        let s1 = gather_params.scatter * rho * single_scatter_source_with(y, n, GATHER_TRANSMITTANCE, rng);
        if all(s1 == vec3<f32>(0.0)) {
            continue;
        }
        sum += transmittance_by(x, dir, t, GATHER_TRANSMITTANCE, rng) * s1 * step;
    }
    return sum;
}

// One estimate of `L₀ + L₁` for the camera ray `eye + t dir` with
// `samples` stratified points and internal-light samples (`gather`).
fn gather(eye: vec3<f32>, dir: vec3<f32>, samples_in: u32, rng: ptr<function, Rng>) -> GatherSample {
    var out = GatherSample(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    let sky = env_background(dir);
    let clip = medium_clip(eye, dir);
    if !clip.hit {
        out.single = sky;
        return out;
    }
    let x = eye + dir * clip.t0;
    let len = clip.t1 - clip.t0;
    if any(sky != vec3<f32>(0.0)) {
        // The sky behind the medium, through all of it.
        out.single = sky * transmittance_by(x, dir, len, GATHER_TRANSMITTANCE, rng);
    }
    let s_star = gather_params.s_star;
    let clock = gather_params.clock;
    // The window's end along the ray.
    let wm = march_clock(clock, s_star, x, dir, 0.0, len, len, s_star);
    let window = select(len, wm.value, wm.reached);
    if window <= 0.0 {
        return out;
    }
    let n = -dir;

    let field = gather_params.l1_form == L1_FIELD;
    let samples = max(samples_in, 1u);
    // L₀ (both parts) and, for the field form, L₁: stratified points of
    // the window, ratio-tracked transmittance from `x`.
    // The strata from the window's far end back, so that the collided
    // part's chances share one march (`ChancesAlongRay`).
    // The points' jitters are the stream's next `samples` numbers, drawn
    // in order as on the CPU (which places every point first) and read
    // back here from the last (`rng_previous_f32`), so that both backends
    // give a camera sample the same numbers for the same things.
    var points = points_along(clock, x, dir, 0.0, window);
    var chances = chances_along_ray(x, dir, len, s_star);
    for (var j = 0u; j < samples; j++) {
        rng_next_u32(rng);
    }
    var jitters = *rng;
    for (var jj = 0u; jj < samples; jj++) {
        let j = samples - 1u - jj;
        let ts = segment_sample(&points, (f32(j) + rng_previous_f32(&jitters)) / f32(samples));
        let t = ts.x;
        let step = ts.y / f32(samples);
        let y = x + dir * t;
        let rho = density(y);
        // The collided part is stored per unit chance of the collision.
        var j_hat: vec3<f32>;
        if gather_params.has_view != 0u {
            j_hat = reconstruct_view(y, rho);
        } else {
            j_hat = reconstruct_multi(y, n, rho, gather_params.scattered_offset);
        }
        if any(j_hat != vec3<f32>(0.0)) {
            j_hat *= chance_at(&chances, t);
        }
        var s1 = vec3<f32>(0.0);
        var l1 = vec3<f32>(0.0);
        if rho > 0.0 {
            s1 = gather_params.scatter * rho * single_scatter_source_with(y, n, GATHER_TRANSMITTANCE, rng);
            if field {
                // (The CPU marches once for all the points' clocks,
                // `clock_at_each`: the same lattice from `x`.)
                let budget = s_star - clock_to(clock, x, dir, t, len);
                l1 = field_l1_at(n, budget, y, rho, rng);
            }
        }
        if all(j_hat == vec3<f32>(0.0)) && all(l1 == vec3<f32>(0.0)) && all(s1 == vec3<f32>(0.0)) {
            continue;
        }
        let tr = transmittance_by(x, dir, t, GATHER_TRANSMITTANCE, rng);
        out.reconstructed += tr * j_hat * step;
        out.internal += tr * l1 * step;
        out.single += tr * s1 * step;
    }
    out.single += single_beyond_window(x, dir, window, len, samples, rng);
    if field {
        return out;
    }

    // L₁ as the note writes it: a sum over the internal lights.
    let live = gather_params.live_count;
    if live == 0u {
        return out;
    }
    let h = gather_params.softening;
    let h2 = h * h;
    var total = 0.0;
    for (var k = 0u; k < live; k++) {
        let c = internal_words[gather_params.live_offset + k];
        let w = cluster_weight(c, x, dir, window, h2);
        if w >= 0.0 {
            total += w;
        }
    }
    if total <= 0.0 {
        return out;
    }
    let inv_samples = 1.0 / f32(samples);
    for (var s = 0u; s < samples; s++) {
        // A cluster: the first whose running sum exceeds u, else the last.
        let u = rng_next_f32(rng) * total;
        var cum = 0.0;
        var prev = 0.0;
        var c = 0u;
        for (var k = 0u; k < live; k++) {
            let ck = internal_words[gather_params.live_offset + k];
            let w = cluster_weight(ck, x, dir, window, h2);
            if w < 0.0 {
                continue;
            }
            prev = cum;
            cum += w;
            c = ck;
            if cum > u {
                break;
            }
        }
        let p_cluster = (cum - prev) / total;
        // Then a light in it, ∝ its power.
        let start = cluster_start(c);
        let end = cluster_start(c + 1u);
        let count = end - start;
        let cluster_power = bitcast<f32>(internal_words[gather_params.cluster_power_offset + c]);
        var pick = rng_next_f32(rng) * cluster_power;
        var slot = count - 1u;
        for (var k = 0u; k < count; k++) {
            let p = bitcast<f32>(internal_words[gather_params.light_power_offset + start + k]);
            if pick < p {
                slot = k;
                break;
            }
            pick -= p;
        }
        // Rounding may leave `pick` past the end: the last light with power.
        if bitcast<f32>(internal_words[gather_params.light_power_offset + start + slot]) <= 0.0 {
            for (var k = count; k > 0u; k--) {
                if bitcast<f32>(internal_words[gather_params.light_power_offset + start + k - 1u]) > 0.0 {
                    slot = k - 1u;
                    break;
                }
            }
        }
        let slot_power = bitcast<f32>(internal_words[gather_params.light_power_offset + start + slot]);
        let q = p_cluster * slot_power / cluster_power;
        if q <= 0.0 {
            continue;
        }
        let i = cluster_id(start + slot);
        let light = internal_light(i);
        let xi = light.position;

        // Equiangular sampling of t ∈ [0, window] for the kernel
        // 1/(r² + h²) = 1/(D² + h² + (t − t_c)²).
        let t_c = dot(xi - x, dir);
        let off = (xi - x) - dir * t_c;
        let d2 = dot(off, off) + h2;
        let dd = sqrt(d2);
        let theta_a = atan((0.0 - t_c) / dd);
        let theta_b = atan((window - t_c) / dd);
        let span = theta_b - theta_a;
        if span <= 0.0 {
            continue;
        }
        let t = clamp(t_c + dd * tan(theta_a + rng_next_f32(rng) * span), 0.0, window);
        let y = x + dir * t;
        let rho_y = density(y);
        if rho_y <= 0.0 {
            continue;
        }
        let to_y = y - xi;
        let r = length(to_y);
        if r <= 0.0 {
            continue;
        }
        let n_light = to_y / r;
        // The window condition on the total path length.
        var within = false;
        if clock == CLOCK_GEOMETRIC {
            within = t + r <= s_star;
        } else {
            let a = clock_to(clock, x, dir, t, len);
            if a <= s_star {
                let back = -n_light;
                let bc = medium_clip(y, back);
                if bc.hit {
                    within = a + clock_to(clock, y, back, min(r, bc.t1), bc.t1) <= s_star;
                } else {
                    within = true;
                }
            }
        }
        if !within {
            continue;
        }
        let jv = eval_j(i, n_light);
        if all(jv == vec3<f32>(0.0)) {
            continue;
        }
        // T(x, y) T(y, light), both in one loop (one inlined march).
        var tr = vec3<f32>(1.0);
        for (var leg = 0u; leg < 2u; leg++) {
            let from_y = leg == 1u;
            tr *= transmittance_by(
                select(x, y, from_y),
                select(dir, -n_light, from_y),
                select(t, r, from_y),
                GATHER_TRANSMITTANCE,
                rng,
            );
        }
        if all(tr == vec3<f32>(0.0)) {
            continue;
        }
        let b = gather_params.scatter * rho_y;
        let p = hg(gather_params.g, dot(n_light, n));
        // V_i b P T T J / (r² + h²) / (q · pdf(t)), with
        // 1 / ((r² + h²) pdf(t)) = span / D'.
        out.internal += b * tr * jv * (light.weight * p * span / dd / q * inv_samples);
    }
    return out;
}

// The distance `r` from `origin` along `back` to `L₁`'s source within
// `budget` of the clock, `1/pdf(r)` and the clock it uses (`source_distance`
// in gather.rs): uniform up to where the budget or the box ends (geometric
// clock), or where a clock drawn uniformly in `[0, budget]` is reached,
// `pdf = rate / budget` (optical depth). Not found where the line misses
// the box or the clock is past its exit: no source.
struct SourceDistance {
    found: bool,
    r: f32,
    inv_pdf: f32,
    used: f32,
}

fn source_distance(
    origin: vec3<f32>,
    back: vec3<f32>,
    budget: f32,
    rng: ptr<function, Rng>,
) -> SourceDistance {
    let bc = medium_clip(origin, back);
    if !bc.hit {
        return SourceDistance(false, 0.0, 0.0, 0.0);
    }
    let exit = bc.t1;
    let clock = gather_params.clock;
    if clock == CLOCK_GEOMETRIC {
        let r_max = min(budget, exit);
        let r = rng_next_f32(rng) * r_max;
        return SourceDistance(r_max > 0.0, r, r_max, r);
    }
    let c = rng_next_f32(rng) * budget;
    let m = march_clock(clock, gather_params.s_star, origin, back, 0.0, exit, exit, c);
    if !m.reached || m.rate <= 0.0 {
        return SourceDistance(false, 0.0, 0.0, 0.0);
    }
    let inv_pdf = budget / m.rate;
    return SourceDistance(inv_pdf > 0.0, m.value, inv_pdf, c);
}

// One scattering of `L₁` at `y` (light leaving along `n`: the eye for the
// first, the last step's direction for the further ones) of the multiply
// scattered source read from the lights' phase walks along `n`
// (`phase_view_l1` in gather.rs): `b(y) ∫ dr T(y, x') J̃(x')`, `x' = y − r n`, one sample of
// `r` as `field_l1_at` draws it.
fn phase_view_l1(
    n: vec3<f32>,
    budget: f32,
    y: vec3<f32>,
    rho_y: f32,
    rng: ptr<function, Rng>,
) -> vec3<f32> {
    let back = -n;
    let d = source_distance(y, back, budget, rng);
    if !d.found {
        return vec3<f32>(0.0);
    }
    let xp = y + back * d.r;
    let j = reconstruct_phase_view(xp, density(xp));
    if all(j == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    return gather_params.scatter * rho_y * transmittance_by(y, back, d.r, GATHER_TRANSMITTANCE, rng) * d.inv_pdf * j;
}

// `L₁`'s integrand at the camera-ray point `y = x + t dir` (without
// `T(x, y)`; `budget_in`: `s*` less the clock from `x` to `y`), one
// sample: `b(y) ∫ dn' P(n·n') ∫ dr T(y, x') J(x', n')` over the window,
// with `x' = y − r n'`, `n'` drawn from the phase function and `r` within
// the clock's remaining budget (uniformly in the clock), so that
// `d³x' = r² dr dn'` cancels the `1/r²`; with `window_scatters` m > 1 the
// same step again from `x'` within what is left of the budget, m − 1
// more times (`field_l1_at`).
fn field_l1_at(
    n: vec3<f32>,
    budget_in: f32,
    y: vec3<f32>,
    rho_y: f32,
    rng: ptr<function, Rng>,
) -> vec3<f32> {
    var budget = budget_in;
    let scatters = max(gather_params.window_scatters, 1u);
    var point = y;
    var rho_point = rho_y;
    var towards = n;
    var throughput = vec3<f32>(1.0);
    var sum = vec3<f32>(0.0);
    for (var scattering = 1u; scattering <= scatters; scattering++) {
        if budget <= 0.0 {
            break;
        }
        if scattering > 1u {
            // Russian roulette on this further scattering, kept with the
            // share of a window left in the budget (`field_l1_at` in
            // gather.rs).
            let keep = min(budget / gather_params.s_star, 1.0);
            if keep < 1.0 {
                if rng_next_f32(rng) >= keep {
                    break;
                }
                throughput /= keep;
            }
        }
        // With phase walks each scattering's multiply scattered source is
        // theirs, read along the direction light leaves the scattering
        // point in; the direction drawn below then serves `S₁` and the
        // further scatterings only.
        let phase_view = gather_params.has_phase_view == 1u;
        if phase_view {
            sum += throughput * phase_view_l1(towards, budget, point, rho_point, rng);
        }
        let u1 = rng_next_f32(rng);
        let u2 = rng_next_f32(rng);
        let travel = sample_hg(gather_params.g, towards, u1, u2);
        let back = -travel;
        let d = source_distance(point, back, budget, rng);
        if !d.found {
            break;
        }
        let r = d.r;
        let inv_pdf = d.inv_pdf;
        let xp = point + back * r;
        let rho = density(xp);
        var jv = vec3<f32>(0.0);
        if !phase_view {
            jv = reconstruct_multi(xp, travel, rho, gather_params.multi_offset);
        }
        if rho > 0.0 {
            jv += gather_params.scatter * rho * single_scatter_source_with(xp, travel, GATHER_TRANSMITTANCE, rng);
        }
        let more = scattering < scatters && rho > 0.0;
        if all(jv == vec3<f32>(0.0)) && !more {
            break;
        }
        throughput *= gather_params.scatter * rho_point
            * transmittance_by(point, back, r, GATHER_TRANSMITTANCE, rng) * inv_pdf;
        sum += throughput * jv;
        if !more || all(throughput == vec3<f32>(0.0)) {
            break;
        }
        budget -= d.used;
        point = xp;
        rho_point = rho;
        towards = travel;
    }
    return sum;
}
