// The placement's entry point: one invocation per internal light, light `i`
// from stream `(seed, i, PLACEMENT_STREAM)` (`sample_lights` in
// src/physics/internal/placement.rs), writing two vec4 per light to `placed`:
// (x_i, ρ(x_i)) and (V_i = 1/(M p(x_i)), p(x_i), 0, 0). The seed comes in
// `pass_params`. Keep `PlacementParams` in sync with `GpuPlacementParams`
// in src/gpu/mirrors.rs.

// The placement grid and the mixture (`PlacementDensity`).
struct PlacementParams {
    grid_min: vec3<f32>,
    u_mix: f32,
    grid_max: vec3<f32>,
    // `Z = ∫_B ρ̃`.
    integral: f32,
    cell: vec3<f32>,
    box_volume: f32,
    res: vec3<u32>,
    cell_count: u32,
    light_count: u32,
    inv_light_count: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(5) var<uniform> placement_params: PlacementParams;
// Per cell: the alias table's threshold (f32 bits) and alias.
@group(0) @binding(6) var<storage, read> placement_alias: array<vec2<u32>>;
// `ρ` at the `(res + 1)³` corners, x fastest.
@group(0) @binding(7) var<storage, read> placement_corners: array<f32>;
// Two vec4 per light (see above).
@group(0) @binding(8) var<storage, read_write> placed: array<vec4<f32>>;

@compute @workgroup_size(PLACEMENT_LANES, 1, 1)
fn place_lights(@builtin(global_invocation_id) id: vec3<u32>) {
    // The scene's bindings are shared by every pipeline (one bind group
    // for all, built by the renderer); these three are otherwise unused here
    // and would drop out of the layout derived from the shader.
    _ = majorant_values[0];
    _ = lights[0];
    _ = env_data[0];
    let i = id.x;
    if i >= placement_params.light_count {
        return;
    }
    var rng = rng_for_sample(pass_params.seed_lo, pass_params.seed_hi, i, PLACEMENT_STREAM);
    let s = placement_sample(&rng);
    var weight = 0.0;
    if s.pdf > 0.0 {
        weight = placement_params.inv_light_count / s.pdf;
    }
    placed[2u * i] = vec4<f32>(s.position, density(s.position));
    placed[2u * i + 1u] = vec4<f32>(weight, s.pdf, 0.0, 0.0);
}
