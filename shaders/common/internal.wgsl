// Evaluating the cached internal lights (src/doc/method.md §5, §6). Mirrors the
// read side of `InternalLights` in src/physics/internal/sources.rs: `S₁` from the
// stored arriving light, the multiply scattered part from its SH
// coefficients (clamped at zero for one light), and the kernel
// reconstruction of `Ĵ` at a point, the normalised average of the lights'
// series, unclamped.

// One internal light (`InternalLight`, plus its reconstruction scale).
struct InternalLight {
    position: vec3<f32>,
    density: f32,
    weight: f32,
    recon_scale: f32,
}

// Light `i`.
fn internal_light(i: u32) -> InternalLight {
    let base = gather_params.lights_offset + 2u * i;
    let a = internal_vec4[base];
    let b = internal_vec4[base + 1u];
    return InternalLight(a.xyz, a.w, b.x, b.y);
}

// `S₁(x_i, n)` from the stored arriving light, the suns' and the sky's
// (`eval_s1`).
fn eval_s1(i: u32, n: vec3<f32>) -> vec3<f32> {
    let light = internal_light(i);
    let count = gather_params.external_count;
    var sum = vec3<f32>(0.0);
    for (var l = 0u; l < count; l++) {
        let arrival = internal_vec4[gather_params.arrival_offset + i * count + l].xyz;
        let s = light_at(l, light.position);
        sum += arrival * hg(gather_params.g, dot(s.travel, n));
    }
    if gather_params.has_sky != 0u {
        // Funk–Hecke: the phase function scales the sky's band `l` by
        // `g^l`; the basis is scaled so, and the sky's series evaluated
        // like the lights' own.
        var y = sh_basis(gather_params.sh_order, n);
        var g_l = 1.0;
        for (var l = 1u; l <= gather_params.sh_order; l++) {
            g_l *= gather_params.g;
            for (var k = l * l; k < (l + 1u) * (l + 1u); k++) {
                y[k] *= g_l;
            }
        }
        sum += max(eval_sh(gather_params.sky_offset, i, &y), vec3<f32>(0.0));
    }
    return sum * gather_params.scatter * light.density;
}

// Light `i`'s SH series for the basis values `y`, unclamped (`eval_sh` of
// the light's coefficients in the table at `offset`: `multi_offset` for the
// multiply scattered part of `J_i`, `scattered_offset` for what of it the
// walks carried through a collision). One band at a time without a loop:
// this runs for every light near every point of the gather, and lavapipe
// ends an invocation's loops after 65 535 iterations in all (sh.wgsl).
fn eval_sh(offset: u32, i: u32, y: ptr<function, array<f32, 25>>) -> vec3<f32> {
    let count = gather_params.sh_count;
    let base = offset + i * count;
    var sum = internal_vec4[base].xyz * (*y)[0];
    if count > 1u {
        sum += internal_vec4[base + 1u].xyz * (*y)[1]
            + internal_vec4[base + 2u].xyz * (*y)[2]
            + internal_vec4[base + 3u].xyz * (*y)[3];
    }
    if count > 4u {
        sum += internal_vec4[base + 4u].xyz * (*y)[4]
            + internal_vec4[base + 5u].xyz * (*y)[5]
            + internal_vec4[base + 6u].xyz * (*y)[6]
            + internal_vec4[base + 7u].xyz * (*y)[7]
            + internal_vec4[base + 8u].xyz * (*y)[8];
    }
    if count > 9u {
        sum += internal_vec4[base + 9u].xyz * (*y)[9]
            + internal_vec4[base + 10u].xyz * (*y)[10]
            + internal_vec4[base + 11u].xyz * (*y)[11]
            + internal_vec4[base + 12u].xyz * (*y)[12]
            + internal_vec4[base + 13u].xyz * (*y)[13]
            + internal_vec4[base + 14u].xyz * (*y)[14]
            + internal_vec4[base + 15u].xyz * (*y)[15];
    }
    if count > 16u {
        sum += internal_vec4[base + 16u].xyz * (*y)[16]
            + internal_vec4[base + 17u].xyz * (*y)[17]
            + internal_vec4[base + 18u].xyz * (*y)[18]
            + internal_vec4[base + 19u].xyz * (*y)[19]
            + internal_vec4[base + 20u].xyz * (*y)[20]
            + internal_vec4[base + 21u].xyz * (*y)[21]
            + internal_vec4[base + 22u].xyz * (*y)[22]
            + internal_vec4[base + 23u].xyz * (*y)[23]
            + internal_vec4[base + 24u].xyz * (*y)[24];
    }
    return sum;
}

// The multiply scattered part of `J_i` for the basis values `y`, clamped at
// zero (`eval_multi_with`).
fn eval_multi_with(i: u32, y: ptr<function, array<f32, 25>>) -> vec3<f32> {
    return max(eval_sh(gather_params.multi_offset, i, y), vec3<f32>(0.0));
}

// `J_i(n)`: `S₁` plus the multiply scattered part (`eval_j`).
fn eval_j(i: u32, n: vec3<f32>) -> vec3<f32> {
    var y = sh_basis(gather_params.sh_order, n);
    return eval_s1(i, n) + eval_multi_with(i, &y);
}

// The factor that turns the kernel average back into `Ĵ` at a point of
// density `density_at_p` (`reconstruction_scale`).
fn reconstruction_scale(density_at_p: f32) -> f32 {
    if gather_params.clock == CLOCK_GEOMETRIC {
        return 1.0;
    }
    return gather_params.sigma_grey * density_at_p;
}

// The kernel reconstruction of the multiply scattered `Ĵ(p, n)` from the
// lights within `h` of `p`, kernel `(1 − r²/h²)²` (`reconstruct_multi`
// with `for_each_kernel_weight` and `LightGrid::for_each_near`). The
// lights' series are summed and averaged unclamped, as on the CPU: a clamp
// would bias `Ĵ` upwards where it is small next to its walk noise.
// `offset` picks the part (`Part` on the CPU): `gather_params.multi_offset` for all of it (`L₁`), `scattered_offset`
// for what the walks carried through a collision (`L₀`).
fn reconstruct_multi(p: vec3<f32>, n: vec3<f32>, density_at_p: f32, offset: u32) -> vec3<f32> {
    return kernel_average(p, n, density_at_p, offset, false);
}

// The normalised kernel average at `p` of each light's series at `offset`
// evaluated towards `n`, or (`per_light`) of its one value at `offset`
// (the view or phase walks' estimate).
fn kernel_average(p: vec3<f32>, n: vec3<f32>, density_at_p: f32, offset: u32, per_light: bool) -> vec3<f32> {
    let scale_p = reconstruction_scale(density_at_p);
    if scale_p <= 0.0 {
        return vec3<f32>(0.0);
    }
    var y: array<f32, 25>;
    if !per_light {
        y = sh_basis(gather_params.sh_order, n);
    }
    let h = gather_params.kernel_radius;
    let inv_h2 = 1.0 / (h * h);
    let res = gather_params.fine_res;
    let lo = light_grid_coords(p - vec3<f32>(h), gather_params.fine_min, gather_params.fine_cell, res);
    let hi = light_grid_coords(p + vec3<f32>(h), gather_params.fine_min, gather_params.fine_cell, res);
    var num = vec3<f32>(0.0);
    var den = 0.0;
    for (var z = lo.z; z <= hi.z; z++) {
        for (var yy = lo.y; yy <= hi.y; yy++) {
            let row = res.x * (yy + res.y * z);
            let a = fine_start(row + lo.x);
            let b = fine_start(row + hi.x + 1u);
            for (var k = a; k < b; k++) {
                let i = fine_id(k);
                let light = internal_light(i);
                let d = light.position - p;
                let q = dot(d, d) * inv_h2;
                if q < 1.0 {
                    let w = (1.0 - q) * (1.0 - q);
                    var value: vec3<f32>;
                    if per_light {
                        value = internal_vec4[offset + i].xyz;
                    } else {
                        value = eval_sh(offset, i, &y);
                    }
                    num += value * (w * light.recon_scale);
                    den += w;
                }
            }
        }
    }
    if den <= 0.0 {
        return vec3<f32>(0.0);
    }
    // Unclamped, so that the average over light sets is unbiased
    // (`InternalLights::reconstruct_multi`).
    return num * (scale_p / den);
}

// `L₀`'s collided part at `p` as the camera sees it: the kernel average of
// the lights' view-walk estimates (`InternalLights::reconstruct_view`), in
// place of `reconstruct_multi(p, n, density_at_p, scattered_offset)`.
fn reconstruct_view(p: vec3<f32>, density_at_p: f32) -> vec3<f32> {
    return kernel_average(p, vec3<f32>(0.0, 0.0, 1.0), density_at_p, gather_params.view_offset, true);
}

// The source one more scattering sends towards the eye at `p`: the kernel
// average of the lights' phase-walk means
// (`InternalLights::reconstruct_phase_view`).
fn reconstruct_phase_view(p: vec3<f32>, density_at_p: f32) -> vec3<f32> {
    return kernel_average(p, vec3<f32>(0.0, 0.0, 1.0), density_at_p, gather_params.phase_view_offset, true);
}
