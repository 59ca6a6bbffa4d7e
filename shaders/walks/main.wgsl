// The internal lights' walks (src/doc/method.md §4, §5): one workgroup per light,
// one time-gated walk per invocation and dispatch. Mirrors the walk loop of
// `InternalLights::build_at` in src/physics/internal/sources.rs: `K` directions on a
// spherical Fibonacci lattice under a random rotation, one
// `accumulate_j_from(…, first = 1, …)` per direction, projected onto real
// SH (`F`: the k = 1 term; `multi`: Σ_{k≥1}), the per-term energies
// `E_k += V_i Ĵ_k 4π/K`, and the light arriving from each external light
// (ratio tracking, `tr_estimates` per light). A dispatch covers the walks
// `walk_offset .. walk_offset + 64` of each light and adds its sums to
// `walk_out`, so that no invocation runs more than one walk (lavapipe caps
// the loop iterations of an invocation). WGSL has no float atomics: the
// workgroup reduces its walks in shared memory, eight quantities a round.
//
// Random streams (the CPU uses one stream per light for everything): the
// rotation, then the arrival from `(seed, i, WALK_STREAM)`, walk `w` from
// `(seed, i, WALK_STREAM + 1 + w)`. Same estimator, other random numbers.
//
// Per light, `walk_out` holds `record_stride` vec4 (xyz used): `sh_count`
// coefficients of `F`, `sh_count` of the multiply scattered part,
// `sh_count` of what of it the walks carried through a collision,
// `external_count` arriving lights, `min(n_terms, GPU_MAX_GATES − 1) + 1`
// term energies, then with
// view walks one more: their mean collided part per unit chance towards
// the eye (walks `K .. K + view_walks` of the light, all along
// `normalize(eye − x)`; "Walks towards the eye" in
// src/physics/internal/sources.rs), then with phase walks one more: their
// mean of all of `Σ_{k≥1} J_k` (walks `K + view_walks .. + phase_walks`,
// each along the direction towards the eye turned by one draw of the
// phase function; `phase_walks` in src/physics/internal/sources.rs).
// The first vec4's `w` counts the walks
// of the light that the driver's loop cap cut short (`loops_cut_short`:
// their terms are too small). Keep
// `WalkParams` in sync with `GpuWalkParams` in src/gpu/mirrors.rs.

// From Rust (the generated prelude, src/gpu/shaders.rs): the stream index
// of the walks, `WALK_STREAM` (crate::physics::internal::WALK_STREAM), and the
// invocations (walks) per workgroup, `WALK_LANES`
// (crate::gpu::walks::WALK_LANES).

// Quantities reduced per round of the workgroup reduction.
const ROUND: u32 = 8u;

// `π (3 − √5)`, the golden angle of the spherical Fibonacci lattice:
// `GOLDEN_ANGLE`, from Rust (the generated prelude:
// crate::physics::internal::GOLDEN_ANGLE).

// Parameters of the walks.
struct WalkParams {
    s_star: f32,
    n_terms: u32,
    clock: u32,
    rr_start: u32,
    // Walks per light `K`.
    walks: u32,
    sh_order: u32,
    sh_count: u32,
    // Transmittance estimates per arriving light.
    tr_estimates: u32,
    light_count: u32,
    // First light and first walk of this dispatch.
    light_offset: u32,
    walk_offset: u32,
    record_stride: u32,
    // The camera's eye and the walks per light towards it.
    eye: vec3<f32>,
    view_walks: u32,
    // Phase walks per light, after the view walks.
    phase_walks: u32,
    // The medium's largest extinction majorant (`majorant_peak`).
    majorant_peak: f32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(5) var<uniform> walk_params: WalkParams;
// Two vec4 per light, as the placement writes them.
@group(0) @binding(6) var<storage, read> placed: array<vec4<f32>>;
// Per light `record_stride` vec4 (see above), accumulated.
@group(0) @binding(7) var<storage, read_write> walk_out: array<vec4<f32>>;

var<workgroup> partial: array<vec4<f32>, WALK_LANES * ROUND>;

// Rotates `v` by the unit quaternion `q` (xyz: vector part).
fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

// A uniformly random rotation (Shoemake's uniform unit quaternion,
// `random_rotation`).
fn random_rotation(rng: ptr<function, Rng>) -> vec4<f32> {
    let u1 = rng_next_f32(rng);
    let u2 = rng_next_f32(rng);
    let u3 = rng_next_f32(rng);
    let a = sqrt(1.0 - u1);
    let b = sqrt(u1);
    let tau = 2.0 * PI;
    return normalize(vec4<f32>(a * sin(tau * u2), a * cos(tau * u2), b * sin(tau * u3), b * cos(tau * u3)));
}

// The direction from `x` towards the eye, +z where they coincide (the
// CPU's `try_normalize().unwrap_or(Vec3::Z)`).
fn eye_direction(x: vec3<f32>) -> vec3<f32> {
    let v = walk_params.eye - x;
    if dot(v, v) > 0.0 {
        return normalize(v);
    }
    return vec3<f32>(0.0, 0.0, 1.0);
}

@compute @workgroup_size(WALK_LANES, 1, 1)
fn walk_lights(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let wp = walk_params;
    let i = wp.light_offset + group.x;
    if i >= wp.light_count {
        return;
    }
    let light = placed[2u * i];
    let x = light.xyz;
    let rho = light.w;
    let volume = placed[2u * i + 1u].x;
    let count = wp.sh_count;
    // The last slot of the per-term outputs: terms past it add to it
    // (`term_slot`), so the walks still run to gate `N`.
    let terms = min(wp.n_terms, GPU_MAX_GATES - 1u);
    let record = i * wp.record_stride;
    let n_ext = light_count();
    let energy_at = record + 3u * count + n_ext;
    let scatter = scene.medium.albedo * scene.medium.sigma_t;

    var rng = rng_for_sample(pass_params.seed_lo, pass_params.seed_hi, i, WALK_STREAM);
    let rotation = random_rotation(&rng);
    let phi0 = 2.0 * PI * rng_next_f32(&rng);
    let w_dir = 4.0 * PI / f32(wp.walks);

    // This invocation's walk.
    let w = wp.walk_offset + lane;
    var per_walk: GateTerms;
    var n = vec3<f32>(0.0, 0.0, 1.0);
    // A spread walk (SH, F, energies) or a walk towards the eye.
    let spread = w < wp.walks;
    let towards_eye = !spread && w < wp.walks + wp.view_walks;
    let phase_turned = !spread && !towards_eye && w < wp.walks + wp.view_walks + wp.phase_walks;
    let walked = spread || towards_eye || phase_turned;
    if walked {
        var walk_rng = rng_for_sample(pass_params.seed_lo, pass_params.seed_hi, i, WALK_STREAM + 1u + w);
        if spread {
            let z = 1.0 - f32(2u * w + 1u) / f32(wp.walks);
            let phi = phi0 + f32(w) * GOLDEN_ANGLE;
            let s = sqrt(max(1.0 - z * z, 0.0));
            n = quat_rotate(rotation, vec3<f32>(s * cos(phi), s * sin(phi), z));
        } else if towards_eye {
            n = eye_direction(x);
        } else {
            let u1 = rng_next_f32(&walk_rng);
            let u2 = rng_next_f32(&walk_rng);
            n = sample_hg(scene.medium.g, eye_direction(x), u1, u2);
        }
        let settings = GateSettings(wp.s_star, wp.n_terms, wp.clock, wp.rr_start);
        // The walks towards the eye keep only the collided part; they and
        // the phase walks sum the terms, so they read their collision
        // tails where those pay (`collision_tail`, `COLLISION_TAIL_MIN_G`).
        walk_collided_only = towards_eye;
        walk_sums_terms = (towards_eye || phase_turned)
            && abs(scene.medium.g) >= COLLISION_TAIL_MIN_G;
        walk_majorant_peak = wp.majorant_peak;
        accumulate_j_from(x, n, settings, 1u, &walk_rng, &per_walk);
    }
    // Asked once the walk is done (accumulate.wgsl): whether the driver
    // ended its loops, counted in the record's first `w`.
    let cut = walked && loops_cut_short(wp.light_count);
    var total = vec3<f32>(0.0);
    for (var k = 1u; k <= terms; k++) {
        total += per_walk[k];
    }
    // What the walk carried through a collision (`walk_unscattered`: the
    // rest, which the gather marches exactly), per unit chance of the
    // collision (`Part::Scattered`).
    // The walks towards the eye share `x` and `n`: their sum is divided by
    // the chance once, where the workgroup reduces it (below).
    var after_collision = vec3<f32>(0.0);
    if spread || towards_eye {
        after_collision = total - walk_unscattered;
        if spread && any(after_collision != vec3<f32>(0.0)) {
            after_collision /= collision_probability(wp.s_star, x, -n);
        }
    }
    var first = vec3<f32>(0.0);
    if terms >= 1u {
        first = per_walk[1];
    }
    let y = sh_basis(wp.sh_order, n);

    // Only spread walks feed the harmonics and the energies, only walks
    // towards the eye the view estimate.
    // Phase walks only their value: all of `Σ_{k≥1} J_k`.
    var view = vec3<f32>(0.0);
    var phase = vec3<f32>(0.0);
    if towards_eye || phase_turned {
        if towards_eye {
            view = after_collision / f32(wp.view_walks);
        } else {
            phase = total / f32(wp.phase_walks);
        }
        total = vec3<f32>(0.0);
        after_collision = vec3<f32>(0.0);
        first = vec3<f32>(0.0);
        per_walk = GateTerms();
    }

    // Quantities: F's coefficients, the multiply scattered part's, its
    // collided part's, the energies of k = 1..=N (k = 0 comes from the
    // arrival below), then the view estimate if there are view walks.
    let spread_quantities = 3u * count + terms;
    let view_quantities = spread_quantities + min(wp.view_walks, 1u);
    let quantities = view_quantities + min(wp.phase_walks, 1u);
    for (var base = 0u; base < quantities; base += ROUND) {
        for (var j = 0u; j < ROUND; j++) {
            let q = base + j;
            var v = vec3<f32>(0.0);
            if q < count {
                v = first * (y[q] * w_dir);
            } else if q < 2u * count {
                v = total * (y[q - count] * w_dir);
            } else if q < 3u * count {
                v = after_collision * (y[q - 2u * count] * w_dir);
            } else if q < spread_quantities {
                v = per_walk[q - 3u * count + 1u] * (volume * w_dir);
            } else if q < view_quantities {
                v = view;
            } else if q < quantities {
                v = phase;
            }
            partial[lane * ROUND + j] = vec4<f32>(v, select(0.0, 1.0, cut && q == 0u));
        }
        workgroupBarrier();
        let q = base + lane;
        if lane < ROUND && q < quantities {
            var sum = vec3<f32>(0.0);
            var cut_walks = 0.0;
            for (var l = 0u; l < WALK_LANES; l++) {
                sum += partial[l * ROUND + lane].xyz;
                cut_walks += partial[l * ROUND + lane].w;
            }
            var slot = record + q;
            if q >= view_quantities {
                slot = record + wp.record_stride - 1u;
            } else if q >= spread_quantities {
                slot = record + wp.record_stride - 1u - min(wp.phase_walks, 1u);
                if any(sum != vec3<f32>(0.0)) {
                    sum /= collision_probability(wp.s_star, x, -eye_direction(x));
                }
            } else if q >= 3u * count {
                slot = energy_at + 1u + (q - 3u * count);
            }
            walk_out[slot] += vec4<f32>(sum, cut_walks);
        }
        workgroupBarrier();
    }

    // The light arriving from each external light, and E_0 = V ρ α σ_t Σ T E
    // (∫ S₁ dn, the phase function being normalised), once per light.
    if lane == 0u && wp.walk_offset == 0u {
        var sum = vec3<f32>(0.0);
        for (var l = 0u; l < n_ext; l++) {
            let s = light_at(l, x);
            var t = vec3<f32>(0.0);
            for (var e = 0u; e < wp.tr_estimates; e++) {
                t += transmittance(x, -s.travel, s.distance, &rng);
            }
            let arrival = s.irradiance * t / f32(wp.tr_estimates);
            walk_out[record + 3u * count + l] = vec4<f32>(arrival, 0.0);
            sum += arrival;
        }
        walk_out[energy_at] = vec4<f32>(volume * rho * scatter * sum, 0.0);
    }
}
