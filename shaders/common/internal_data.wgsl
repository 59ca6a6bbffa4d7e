// The cached internal lights as the gather reads them (bindings 6–8).
// Keep in sync with `GpuGatherParams` in src/gpu/mirrors.rs and with
// src/gpu/gather.rs, which packs `InternalLights` (src/physics/internal/sources.rs)
// and its two `LightGrid`s (src/physics/internal/light_index.rs) into two buffers:
//
// - `internal_vec4`: per light two vec4 (position, ρ(x_i); V_i, the
//   reconstruction scale), then `sh_count` SH coefficients of the multiply
//   scattered part of J per light (`multi_offset`), then `sh_count` of the
//   part of it the walks carried through a collision per light
//   (`scattered_offset`), then `external_count` arriving lights per light
//   (`T E`), then, with view walks, one vec4 per light: their estimate of
//   the collided part towards the eye (`view_offset`), then, under a sky,
//   `sh_count` SH coefficients per light of the sky's light arriving there
//   (`sky_offset`).
// - `internal_words`: the fine grid's `starts` and `ids`, the cluster
//   grid's `starts` and `ids`, cluster powers and per-slot light powers (f32
//   bits), and the live clusters; each table at an offset given below.

// Constants of the internal lights and offsets of their tables.
struct GatherParams {
    scatter: vec3<f32>,
    g: f32,
    fine_min: vec3<f32>,
    s_star: f32,
    fine_cell: vec3<f32>,
    kernel_radius: f32,
    fine_res: vec3<u32>,
    softening: f32,
    cluster_min: vec3<f32>,
    sigma_grey: f32,
    cluster_cell: vec3<f32>,
    clock: u32,
    cluster_res: vec3<u32>,
    sh_order: u32,
    sh_count: u32,
    light_count: u32,
    external_count: u32,
    light_samples: u32,
    lights_offset: u32,
    multi_offset: u32,
    arrival_offset: u32,
    live_count: u32,
    fine_starts_offset: u32,
    fine_ids_offset: u32,
    cluster_starts_offset: u32,
    cluster_ids_offset: u32,
    cluster_power_offset: u32,
    light_power_offset: u32,
    live_offset: u32,
    l1_form: u32,
    scattered_offset: u32,
    n_terms: u32,
    // Scatterings inside the window that the field form of L₁ follows
    // (`InternalParams::window_scatters`).
    window_scatters: u32,
    // Vec4 table offset of the view walks' estimates, one per light, read
    // when `has_view` is 1 (`InternalLights::reconstruct_view`).
    view_offset: u32,
    has_view: u32,
    // Vec4 table offset of the sky's arriving light, `sh_count` SH
    // coefficients per light, read when `has_sky` is 1
    // (`InternalLights::sky`).
    sky_offset: u32,
    has_sky: u32,
    // Vec4 table offset of the phase walks' means, one per light, read
    // when `has_phase_view` is 1 (`InternalLights::reconstruct_phase_view`).
    phase_view_offset: u32,
    has_phase_view: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// The clock tags `CLOCK_*` and the forms of the gather's L₁, `L1_*`, come
// from Rust (the generated prelude, src/gpu/shaders.rs:
// crate::scene::{Clock, L1Form}::tag).

@group(0) @binding(6) var<uniform> gather_params: GatherParams;
@group(0) @binding(7) var<storage, read> internal_vec4: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read> internal_words: array<u32>;
