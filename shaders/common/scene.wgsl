// The data every estimator reads, and its bindings (group 0, bindings 0–4
// and 9).
// Keep in sync with src/gpu/mirrors.rs: each struct here has a
// `#[repr(C)]` twin there with the same field order and size.

// The camera frame (`CameraFrame` in src/scene/camera.rs).
struct Camera {
    eye: vec3<f32>,
    width: u32,
    forward: vec3<f32>,
    height: u32,
    right_scaled: vec3<f32>,
    _pad0: u32,
    up_scaled: vec3<f32>,
    _pad1: u32,
}

// The medium (`Volume` in src/physics/volume.rs): optics, box, density
// source and majorant grid. The density source is a tagged union:
// DENSITY_SPHERE (shape_a = centre, radius), DENSITY_BOX (shape_a = min,
// shape_b = max) or DENSITY_GRID (shape_a/shape_b = grid box, grid_dims,
// voxels in `density_voxels`).
struct Medium {
    sigma_t: vec3<f32>,
    density_kind: u32,
    albedo: vec3<f32>,
    g: f32,
    bounds_min: vec3<f32>,
    _pad0: u32,
    bounds_max: vec3<f32>,
    _pad1: u32,
    shape_a: vec3<f32>,
    radius: f32,
    shape_b: vec3<f32>,
    _pad2: u32,
    grid_dims: vec3<u32>,
    _pad3: u32,
    majorant_res: vec3<u32>,
    _pad4: u32,
    majorant_min: vec3<f32>,
    _pad5: u32,
    majorant_max: vec3<f32>,
    _pad6: u32,
}

// Everything constant during a render.
struct Scene {
    camera: Camera,
    medium: Medium,
    // Suns come first in `lights`, then points (the CPU's order).
    sun_count: u32,
    point_count: u32,
    // The environment (`GpuScene` in src/gpu/mirrors.rs, `Environment` in
    // src/physics/environment.rs): ENV_NONE, ENV_CONSTANT or ENV_MAP.
    env_kind: u32,
    env_background: u32,
    env_radiance: vec3<f32>,
    env_share: f32,
    env_width: u32,
    env_height: u32,
    env_cos: f32,
    env_sin: f32,
    env_inv_total: f32,
    // Offsets in `env_data` of the cells' weights, the rows' table and the
    // per-row tables (the vertices start at 0).
    env_cells: u32,
    env_rows: u32,
    env_cols: u32,
}

// What changes from pass to pass.
struct PassParams {
    seed_lo: u32,
    seed_hi: u32,
    pass_index: u32,
    // Samples per pixel once this pass is added (1 for the first).
    sample_count: u32,
}

// An external light: LIGHT_SUN (vector = unit travel direction, power =
// irradiance) or LIGHT_POINT (vector = position, power = intensity in W/sr).
struct Light {
    vector: vec3<f32>,
    kind: u32,
    power: vec3<f32>,
    _pad0: u32,
}

// The tags `DENSITY_*`, `LIGHT_*` and `ENV_*` come from Rust (the
// generated prelude, src/gpu/shaders.rs: crate::gpu::mirrors::DENSITY_*,
// LIGHT_*, ENV_*).

@group(0) @binding(0) var<uniform> scene: Scene;
@group(0) @binding(1) var<uniform> pass_params: PassParams;
// Voxels of a grid density as a 3D texture (`r32float`, one unused zero
// voxel otherwise). A texture, not a storage buffer: a 512³ grid (512 MiB)
// is far above the storage-buffer binding limit of many devices (128 MiB
// on lavapipe), while 3D textures reach 2048³ texels.
@group(0) @binding(2) var density_voxels: texture_3d<f32>;
// Majorant per coarse cell, x fastest (`MajorantGrid::values`).
@group(0) @binding(3) var<storage, read> majorant_values: array<f32>;
// External lights (at least one element; counts in `scene`).
@group(0) @binding(4) var<storage, read> lights: array<Light>;
// The environment map's vertices and sampling tables (`gpu_environment`;
// one unused zero without a map).
@group(0) @binding(9) var<storage, read> env_data: array<f32>;
