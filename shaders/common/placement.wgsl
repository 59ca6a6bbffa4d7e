// Placement of the internal lights (src/doc/method.md §5): a point with density
// `p(x) = (1 − u) ρ̃(x)/Z + u/|B|` and that pdf. Mirrors
// `PlacementDensity::sample` and `PlacementDensity::pdf` of
// src/physics/internal/placement.rs: `ρ̃` is the trilinear interpolant of `ρ` at the
// corners of the placement grid (built on the CPU and uploaded), a cell is
// chosen by its mass, a corner of it by its value and each coordinate from
// the ramp towards that corner, so the point has density exactly `ρ̃/Z`.
// The one difference: the cell is drawn from Walker's alias table
// (`PlacementDensity::alias_table`) instead of by binary search over the
// CPU's f64 cumulative table, which the GPU lacks. Same distribution,
// other random numbers. The tables are declared by the entry point
// (shaders/placement/main.wgsl).

// Stream index of the placement: `PLACEMENT_STREAM`, from Rust (the
// generated prelude: crate::physics::placement::PLACEMENT_STREAM).

// A placed point and its pdf.
struct PlacedSample {
    position: vec3<f32>,
    pdf: f32,
}

// The high 32 bits of the 64-bit product `a · b` (Hacker's Delight
// `mulhu`): `mul_hi(u, n)` maps 32 random bits `u` to `0..n` with
// probability `1/n` up to `n/2³²`.
fn mul_hi(a: u32, b: u32) -> u32 {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let t = a1 * b0 + ((a0 * b0) >> 16u);
    let w1 = a0 * b1 + (t & 0xffffu);
    return a1 * b1 + (t >> 16u) + (w1 >> 16u);
}

// `ρ` at corner `(i, j, k)` of the placement grid.
fn placement_corner(i: u32, j: u32, k: u32) -> f32 {
    let nx = placement_params.res.x + 1u;
    let ny = placement_params.res.y + 1u;
    return placement_corners[i + nx * (j + ny * k)];
}

// The interpolant `ρ̃(x)`, zero outside the box
// (`PlacementDensity::interpolated_density`).
fn placement_interpolated_density(x: vec3<f32>) -> f32 {
    let pp = placement_params;
    if any(x < pp.grid_min) || any(x > pp.grid_max) {
        return 0.0;
    }
    let g = (x - pp.grid_min) / pp.cell;
    let c = clamp(floor(g), vec3<f32>(0.0), vec3<f32>(pp.res - vec3<u32>(1u)));
    let f = clamp(g - c, vec3<f32>(0.0), vec3<f32>(1.0));
    let ci = vec3<u32>(c);
    let x00 = mix(placement_corner(ci.x, ci.y, ci.z), placement_corner(ci.x + 1u, ci.y, ci.z), f.x);
    let x10 = mix(placement_corner(ci.x, ci.y + 1u, ci.z), placement_corner(ci.x + 1u, ci.y + 1u, ci.z), f.x);
    let x01 = mix(placement_corner(ci.x, ci.y, ci.z + 1u), placement_corner(ci.x + 1u, ci.y, ci.z + 1u), f.x);
    let x11 = mix(placement_corner(ci.x, ci.y + 1u, ci.z + 1u), placement_corner(ci.x + 1u, ci.y + 1u, ci.z + 1u), f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

// The sampling density `p(x)` (`PlacementDensity::pdf`).
fn placement_pdf(x: vec3<f32>) -> f32 {
    let pp = placement_params;
    if any(x < pp.grid_min) || any(x > pp.grid_max) {
        return 0.0;
    }
    let uniform = pp.u_mix / pp.box_volume;
    if pp.u_mix >= 1.0 {
        return uniform;
    }
    return (1.0 - pp.u_mix) * placement_interpolated_density(x) / pp.integral + uniform;
}

// A point with density `ρ̃ / Z` (`sample_interpolant`).
fn placement_sample_interpolant(rng: ptr<function, Rng>) -> vec3<f32> {
    let pp = placement_params;
    let drawn = mul_hi(rng_next_u32(rng), pp.cell_count);
    let entry = placement_alias[drawn];
    var idx = drawn;
    if rng_next_f32(rng) >= bitcast<f32>(entry.x) {
        idx = entry.y;
    }
    let i = idx % pp.res.x;
    let j = (idx / pp.res.x) % pp.res.y;
    let k = idx / (pp.res.x * pp.res.y);
    var values: array<f32, 8>;
    var sum = 0.0;
    for (var bits = 0u; bits < 8u; bits++) {
        values[bits] = placement_corner(i + (bits & 1u), j + ((bits >> 1u) & 1u), k + ((bits >> 2u) & 1u));
        sum += values[bits];
    }
    // A corner with probability ∝ its value, then a ramp towards it along
    // each axis (density 2t or 2(1 − t)).
    var pick = rng_next_f32(rng) * sum;
    var corner = 8u;
    for (var bits = 0u; bits < 8u; bits++) {
        if pick < values[bits] {
            corner = bits;
            break;
        }
        pick -= values[bits];
    }
    // Rounding may leave `pick` past the last corner: take the last one
    // with any weight.
    if corner == 8u {
        corner = 0u;
        for (var bits = 0u; bits < 8u; bits++) {
            if values[bits] > 0.0 {
                corner = bits;
            }
        }
    }
    var local = vec3<f32>(0.0);
    for (var axis = 0u; axis < 3u; axis++) {
        let r = sqrt(rng_next_f32(rng));
        local[axis] = select(1.0 - r, r, ((corner >> axis) & 1u) == 1u);
    }
    return pp.grid_min + pp.cell * (vec3<f32>(f32(i), f32(j), f32(k)) + local);
}

// One point with density `placement_pdf`, and its pdf
// (`PlacementDensity::sample`).
fn placement_sample(rng: ptr<function, Rng>) -> PlacedSample {
    let pp = placement_params;
    var x: vec3<f32>;
    if rng_next_f32(rng) < pp.u_mix {
        let u1 = rng_next_f32(rng);
        let u2 = rng_next_f32(rng);
        let u3 = rng_next_f32(rng);
        x = pp.grid_min + (pp.grid_max - pp.grid_min) * vec3<f32>(u1, u2, u3);
    } else {
        x = placement_sample_interpolant(rng);
    }
    x = clamp(x, pp.grid_min, pp.grid_max);
    return PlacedSample(x, placement_pdf(x));
}
