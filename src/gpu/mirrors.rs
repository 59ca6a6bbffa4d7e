//! GPU mirrors of the data the shaders read: `#[repr(C)]`, `bytemuck::Pod`
//! structs with explicit padding, laid out as WGSL lays out the structs of
//! `shaders/common/scene.wgsl` and `shaders/common/accumulate.wgsl` (a
//! `vec3<f32>` is 16-byte aligned and 12 bytes long, so each one is followed
//! by a 4-byte scalar or a padding field). Every struct carries a
//! compile-time size check; change a field here and in the shader together.
//!
//! The conversions from the prepared scene live here too, so that what the
//! GPU sees is defined in one place ([method §1](crate::doc::method): the medium, its box and
//! majorants, the external lights, the environment).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

#[cfg(doc)]
use crate::physics::environment::Environment;
use crate::physics::environment::{EnvMap, EnvironmentKind};
use crate::physics::lights::Lights;
use crate::physics::majorant::MajorantGrid;
use crate::render::SceneVolume;
use crate::scene::{CameraFrame, Density};

/// Density-source tags (generated into the WGSL prelude, as are all the
/// tags here: `gpu::shaders::WGSL_CONSTANTS`).
pub const DENSITY_SPHERE: u32 = 0;
/// A box of density one.
pub const DENSITY_BOX: u32 = 1;
/// A voxel grid in the density texture.
pub const DENSITY_GRID: u32 = 2;
/// Light tags (`LIGHT_*` in the WGSL prelude).
pub const LIGHT_SUN: u32 = 0;
/// A point light.
pub const LIGHT_POINT: u32 = 1;

/// The camera frame. Keep in sync with `Camera` in
/// `shaders/common/scene.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuCamera {
    /// Pinhole position.
    pub eye: [f32; 3],
    /// Image width in pixels.
    pub width: u32,
    /// Unit view direction.
    pub forward: [f32; 3],
    /// Image height in pixels.
    pub height: u32,
    /// Right vector scaled by the half-width of the image plane.
    pub right_scaled: [f32; 3],
    /// Padding.
    pub _pad0: u32,
    /// Up vector scaled by the half-height of the image plane.
    pub up_scaled: [f32; 3],
    /// Padding.
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<GpuCamera>() == 64);

/// The medium: optics, box, density source (a tagged union) and majorant
/// grid. Keep in sync with `Medium` in `shaders/common/scene.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMedium {
    /// Extinction per unit density, RGB.
    pub sigma_t: [f32; 3],
    /// One of `DENSITY_*`.
    pub density_kind: u32,
    /// Single-scattering albedo, RGB.
    pub albedo: [f32; 3],
    /// Henyey–Greenstein asymmetry.
    pub g: f32,
    /// Minimum corner of the medium's box.
    pub bounds_min: [f32; 3],
    /// Padding.
    pub _pad0: u32,
    /// Maximum corner of the medium's box.
    pub bounds_max: [f32; 3],
    /// Padding.
    pub _pad1: u32,
    /// Sphere centre, box minimum, or grid box minimum.
    pub shape_a: [f32; 3],
    /// Sphere radius (unused otherwise).
    pub radius: f32,
    /// Box maximum or grid box maximum (unused for a sphere).
    pub shape_b: [f32; 3],
    /// Padding.
    pub _pad2: u32,
    /// Voxels along x, y, z (ones unless a grid).
    pub grid_dims: [u32; 3],
    /// Padding.
    pub _pad3: u32,
    /// Majorant cells along x, y, z.
    pub majorant_res: [u32; 3],
    /// Padding.
    pub _pad4: u32,
    /// Minimum corner of the majorant grid.
    pub majorant_min: [f32; 3],
    /// Padding.
    pub _pad5: u32,
    /// Maximum corner of the majorant grid.
    pub majorant_max: [f32; 3],
    /// Padding.
    pub _pad6: u32,
}
const _: () = assert!(std::mem::size_of::<GpuMedium>() == 160);

/// Everything constant during a render (a uniform buffer). Keep in sync
/// with `Scene` in `shaders/common/scene.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuScene {
    /// Ray generation.
    pub camera: GpuCamera,
    /// The medium.
    pub medium: GpuMedium,
    /// Number of suns (first in the light buffer).
    pub sun_count: u32,
    /// Number of point lights (after the suns).
    pub point_count: u32,
    /// The environment: [`ENV_NONE`], [`ENV_CONSTANT`] or [`ENV_MAP`].
    pub env_kind: u32,
    /// 1 if the camera sees the sky behind the medium.
    pub env_background: u32,
    /// A constant sky's radiance.
    pub env_radiance: [f32; 3],
    /// [`Environment::map_share`].
    pub env_share: f32,
    /// A map's width `W`.
    pub env_width: u32,
    /// A map's height `H`.
    pub env_height: u32,
    /// `cos` of the map's rotation about +y.
    pub env_cos: f32,
    /// `sin` of the map's rotation about +y.
    pub env_sin: f32,
    /// [`EnvMap::inv_total`].
    pub env_inv_total: f32,
    /// Offset in `env_data` of the cells' weights (the vertices start at 0).
    pub env_cells: u32,
    /// Offset in `env_data` of the rows' cumulative table.
    pub env_rows: u32,
    /// Offset in `env_data` of the per-row cumulative tables.
    pub env_cols: u32,
}
const _: () = assert!(std::mem::size_of::<GpuScene>() == 288);

/// No environment.
pub const ENV_NONE: u32 = 0;
/// A constant sky.
pub const ENV_CONSTANT: u32 = 1;
/// A latitude–longitude map.
pub const ENV_MAP: u32 = 2;

/// What changes from pass to pass (a uniform buffer). Keep in sync with
/// `PassParams` in `shaders/common/scene.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuPassParams {
    /// Low 32 bits of the render's seed.
    pub seed_lo: u32,
    /// High 32 bits of the render's seed.
    pub seed_hi: u32,
    /// Pass number: selects the random streams.
    pub pass_index: u32,
    /// Samples per pixel once this pass is added (1 for the first).
    pub sample_count: u32,
}
const _: () = assert!(std::mem::size_of::<GpuPassParams>() == 16);

/// An external light. Keep in sync with `Light` in
/// `shaders/common/scene.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    /// Sun: unit direction of travel; point: position.
    pub vector: [f32; 3],
    /// One of `LIGHT_*`.
    pub kind: u32,
    /// Sun: irradiance; point: intensity (W/sr). RGB.
    pub power: [f32; 3],
    /// Padding.
    pub _pad0: u32,
}
const _: () = assert!(std::mem::size_of::<GpuLight>() == 32);

/// Constants of the cached internal lights and the offsets of their tables
/// in the two packed buffers (see `gpu::gather`). Keep in sync with
/// `GatherParams` in `shaders/common/internal_data.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuGatherParams {
    /// `α σ_t` per unit density.
    pub scatter: [f32; 3],
    /// Henyey–Greenstein asymmetry.
    pub g: f32,
    /// Fine light grid: minimum corner.
    pub fine_min: [f32; 3],
    /// Window length `s*`.
    pub s_star: f32,
    /// Fine light grid: cell size.
    pub fine_cell: [f32; 3],
    /// Reconstruction kernel radius `h`.
    pub kernel_radius: f32,
    /// Fine light grid: cells per axis.
    pub fine_res: [u32; 3],
    /// `L₁`'s kernel softening `h₁`.
    pub softening: f32,
    /// Cluster grid: minimum corner.
    pub cluster_min: [f32; 3],
    /// `max(σ_t)`.
    pub sigma_grey: f32,
    /// Cluster grid: cell size.
    pub cluster_cell: [f32; 3],
    /// One of `CLOCK_*`.
    pub clock: u32,
    /// Cluster grid: cells per axis.
    pub cluster_res: [u32; 3],
    /// SH order.
    pub sh_order: u32,
    /// SH coefficients per light.
    pub sh_count: u32,
    /// Number of internal lights.
    pub light_count: u32,
    /// Arriving lights stored per internal light.
    pub external_count: u32,
    /// Internal-light samples per camera sample.
    pub light_samples: u32,
    /// Vec4 table offsets: lights, SH coefficients, arriving light.
    pub lights_offset: u32,
    /// See `lights_offset`.
    pub multi_offset: u32,
    /// See `lights_offset`.
    pub arrival_offset: u32,
    /// Number of live clusters.
    pub live_count: u32,
    /// Word table offsets: fine grid starts.
    pub fine_starts_offset: u32,
    /// Fine grid ids.
    pub fine_ids_offset: u32,
    /// Cluster grid starts.
    pub cluster_starts_offset: u32,
    /// Cluster grid ids.
    pub cluster_ids_offset: u32,
    /// Cluster powers (f32 bits).
    pub cluster_power_offset: u32,
    /// Per-slot light powers (f32 bits).
    pub light_power_offset: u32,
    /// Live clusters.
    pub live_offset: u32,
    /// One of `L1_*`: the form of `L₁`.
    pub l1_form: u32,
    /// Vec4 table offset: the SH coefficients of the part of `J` the
    /// walks carried through a collision (`L₀`'s reconstruction).
    pub scattered_offset: u32,
    /// Series truncation `N` (the marched single scatter beyond the
    /// window reaches a clock of `(N+1) s*`).
    pub n_terms: u32,
    /// Scatterings inside the window that the field form of `L₁` follows
    /// (`InternalParams::window_scatters`).
    pub window_scatters: u32,
    /// Vec4 table offset: per light the view walks' estimate
    /// (`InternalLights::reconstruct_view`), if `has_view`.
    pub view_offset: u32,
    /// 1: `L₀`'s collided part averages the view walks' estimates; 0: it
    /// evaluates the SH at `scattered_offset`.
    pub has_view: u32,
    /// Vec4 table offset: per light the SH coefficients of the sky's light
    /// arriving there (`InternalLights::sky`), if `has_sky`.
    pub sky_offset: u32,
    /// 1: the lights' `S₁` holds the sky's share (evaluated from the
    /// coefficients at `sky_offset`); 0: no sky.
    pub has_sky: u32,
    /// Vec4 table offset: per light the phase walks' mean
    /// (`InternalLights::reconstruct_phase_view`), if `has_phase_view`.
    pub phase_view_offset: u32,
    /// 1: each scattering of `L₁` reads the phase walks' values along the
    /// direction light leaves it in; 0: the harmonics in the direction it
    /// draws.
    pub has_phase_view: u32,
    /// Padding to a multiple of 16 bytes.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}
const _: () = assert!(std::mem::size_of::<GpuGatherParams>() == 224);

/// The placement grid and mixture of the internal lights
/// (`PlacementDensity`). Keep in sync with `PlacementParams` in
/// `shaders/placement/main.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuPlacementParams {
    /// Minimum corner of the placement grid (the medium's box).
    pub grid_min: [f32; 3],
    /// Uniform fraction `u` of the mixture.
    pub u_mix: f32,
    /// Maximum corner of the placement grid.
    pub grid_max: [f32; 3],
    /// `Z = ∫_B ρ̃`.
    pub integral: f32,
    /// Size of one cell.
    pub cell: [f32; 3],
    /// `|B|`.
    pub box_volume: f32,
    /// Cells per axis.
    pub res: [u32; 3],
    /// Number of cells (entries of the alias table).
    pub cell_count: u32,
    /// Number of lights `M`.
    pub light_count: u32,
    /// `1 / M`.
    pub inv_light_count: f32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<GpuPlacementParams>() == 80);

/// Parameters of the internal lights' walks. Keep in sync with
/// `WalkParams` in `shaders/walks/main.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuWalkParams {
    /// Window length `s*`.
    pub s_star: f32,
    /// Series truncation `N`.
    pub n_terms: u32,
    /// One of `CLOCK_*`.
    pub clock: u32,
    /// Real collisions after which Russian roulette starts.
    pub rr_start: u32,
    /// Walks per light `K`.
    pub walks: u32,
    /// SH order.
    pub sh_order: u32,
    /// SH coefficients per light, `(sh_order + 1)²`.
    pub sh_count: u32,
    /// Ratio-tracking estimates per arriving light.
    pub tr_estimates: u32,
    /// Number of lights `M`.
    pub light_count: u32,
    /// First light of this dispatch.
    pub light_offset: u32,
    /// First walk of this dispatch.
    pub walk_offset: u32,
    /// vec4 per light in the output.
    pub record_stride: u32,
    /// The camera's eye, which the view walks look towards.
    pub eye: [f32; 3],
    /// Walks per light towards the eye (`InternalParams::view_walks`),
    /// after the `walks` spread ones.
    pub view_walks: u32,
    /// Phase walks per light (`sources::phase_walks`), after the view
    /// walks.
    pub phase_walks: u32,
    /// The largest extinction majorant of the medium
    /// (`MajorantGrid::peak`), which bounds the clock of a collision
    /// tail's flights (`Walks::collision_tail`).
    pub majorant_peak: f32,
    /// Padding to a multiple of 16 bytes.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}
const _: () = assert!(std::mem::size_of::<GpuWalkParams>() == 80);

/// One pixel's running statistics on the GPU: Welford mean and sum of
/// squared deviations of the estimate, and the mean of its single-scattering
/// part; `mean[3]` counts the passes that the driver's loop cap cut short
/// (see [`GpuImage::cut_short_passes`](super::GpuImage::cut_short_passes)),
/// `m2[3]` is the sum of squared deviations of the channels' mean
/// ([`GpuAccum::grey_m2`]), `single_mean[3]` is unused. Keep in sync with
/// `Accum` in `shaders/common/accumulate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuAccum {
    /// Running mean of the estimate.
    pub mean: [f32; 4],
    /// Sum of squared deviations from the running mean.
    pub m2: [f32; 4],
    /// Running mean of the single-scattering part.
    pub single_mean: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuAccum>() == 48);

impl GpuCamera {
    /// The GPU form of a camera frame.
    pub fn new(c: &CameraFrame) -> Self {
        Self {
            eye: c.eye.to_array(),
            width: c.width,
            forward: c.forward.to_array(),
            height: c.height,
            right_scaled: c.right_scaled.to_array(),
            up_scaled: c.up_scaled.to_array(),
            ..Self::default()
        }
    }
}

impl GpuMedium {
    /// The GPU form of a volume; its voxels (for a grid) go in a separate
    /// 3D texture (see [`density_voxels`]).
    pub fn new(volume: &SceneVolume) -> Self {
        let MajorantGrid { res, min, max, .. } = volume.majorants;
        let mut m = Self {
            sigma_t: volume.optics.sigma_t.to_array(),
            albedo: volume.optics.albedo.to_array(),
            g: volume.optics.g,
            bounds_min: volume.bounds.0.to_array(),
            bounds_max: volume.bounds.1.to_array(),
            grid_dims: [1; 3],
            majorant_res: res.to_array(),
            majorant_min: min.to_array(),
            majorant_max: max.to_array(),
            ..Self::default()
        };
        match &volume.density {
            Density::Sphere { center, radius } => {
                m.density_kind = DENSITY_SPHERE;
                m.shape_a = center.to_array();
                m.radius = *radius;
            }
            Density::Box { min, max } => {
                m.density_kind = DENSITY_BOX;
                m.shape_a = min.to_array();
                m.shape_b = max.to_array();
            }
            Density::Grid(g) => {
                m.density_kind = DENSITY_GRID;
                m.shape_a = g.bounds_min.to_array();
                m.shape_b = g.bounds_max.to_array();
                m.grid_dims = g.dims.to_array();
            }
        }
        m
    }
}

/// The voxels the density texture holds and its size: the grid's, x
/// fastest, or one unused zero voxel for analytic shapes (a binding cannot
/// be empty).
pub fn density_voxels(density: &Density) -> (&[f32], [u32; 3]) {
    match density {
        Density::Grid(g) => (&g.data, g.dims.to_array()),
        _ => (&[0.0], [1, 1, 1]),
    }
}

/// The lights as the GPU reads them, suns first (the order in which
/// [`Lights::for_each_at`] visits them); one unused element if there are
/// none (a binding cannot be empty).
pub fn gpu_lights(lights: &Lights) -> Vec<GpuLight> {
    let suns = lights.suns.iter().map(|s| GpuLight {
        vector: s.direction.to_array(),
        kind: LIGHT_SUN,
        power: s.irradiance.to_array(),
        _pad0: 0,
    });
    let points = lights.points.iter().map(|p| GpuLight {
        vector: p.position.to_array(),
        kind: LIGHT_POINT,
        power: p.intensity.to_array(),
        _pad0: 0,
    });
    let mut out: Vec<GpuLight> = suns.chain(points).collect();
    if out.is_empty() {
        out.push(GpuLight::default());
    }
    out
}

impl GpuScene {
    /// The constant data of a render.
    pub fn new(camera: &CameraFrame, volume: &SceneVolume, lights: &Lights) -> Self {
        let mut out = Self {
            camera: GpuCamera::new(camera),
            medium: GpuMedium::new(volume),
            sun_count: lights.suns.len() as u32,
            point_count: lights.points.len() as u32,
            ..Self::default()
        };
        if let Some(env) = lights.sky() {
            out.env_background = env.background as u32;
            out.env_share = env.map_share();
            match &env.kind {
                EnvironmentKind::Constant(l) => {
                    out.env_kind = ENV_CONSTANT;
                    out.env_radiance = l.to_array();
                }
                EnvironmentKind::Map(m) => {
                    let (vertices, cells, rows) = env_offsets(m);
                    out.env_kind = ENV_MAP;
                    out.env_width = m.width;
                    out.env_height = m.height;
                    (out.env_cos, out.env_sin) = m.rotation;
                    out.env_inv_total = m.inv_total;
                    out.env_cells = vertices;
                    out.env_rows = cells;
                    out.env_cols = rows;
                }
            }
        }
        out
    }
}

/// Where the parts of a map start in [`gpu_environment`]'s buffer: the
/// cells' weights, the rows' table and the per-row tables (the vertices
/// start at 0).
fn env_offsets(m: &EnvMap) -> (u32, u32, u32) {
    let vertices = m.vertices.len() as u32 * 3;
    let cells = vertices + m.cell_weight.len() as u32;
    let rows = cells + m.row_cdf.len() as u32;
    (vertices, cells, rows)
}

/// The environment map and its sampling tables as the GPU reads them
/// (`env_data`, binding 9): the vertices (3 floats each, row-major), the
/// cells' weights, the rows' cumulative table, the per-row cumulative
/// tables ([`EnvMap`]); one unused zero without a map (a binding cannot be
/// empty).
pub fn gpu_environment(lights: &Lights) -> Vec<f32> {
    match lights.sky().map(|e| &e.kind) {
        Some(EnvironmentKind::Map(m)) => {
            let mut out = Vec::with_capacity(
                m.vertices.len() * 3 + m.cell_weight.len() * 2 + m.row_cdf.len(),
            );
            out.extend(m.vertices.iter().flat_map(|v| v.to_array()));
            out.extend_from_slice(&m.cell_weight);
            out.extend_from_slice(&m.row_cdf);
            out.extend_from_slice(&m.col_cdf);
            debug_assert_eq!(out.len() as u32, env_offsets(m).2 + m.col_cdf.len() as u32);
            out
        }
        _ => vec![0.0],
    }
}

impl GpuAccum {
    /// The running mean of the estimate.
    pub fn mean(&self) -> Vec3 {
        Vec3::from_slice(&self.mean[..3])
    }

    /// The sum of squared deviations of the estimate.
    pub fn m2(&self) -> Vec3 {
        Vec3::from_slice(&self.m2[..3])
    }

    /// The sum of squared deviations of the channels' mean `(r + g + b)/3`
    /// over the passes (its running mean is that of [`GpuAccum::mean`]'s
    /// channels): what a balanced light-set schedule pools over the pixels
    /// ([`crate::render::renewal::BalancedRenewal`]), which the channels'
    /// own sums of squares cannot give (they lack the cross terms).
    pub fn grey_m2(&self) -> f32 {
        self.m2[3]
    }

    /// The running mean of the single-scattering part.
    pub fn single_mean(&self) -> Vec3 {
        Vec3::from_slice(&self.single_mean[..3])
    }

    /// Passes of this pixel that the driver's loop cap cut short.
    pub fn cut_short_passes(&self) -> u32 {
        self.mean[3] as u32
    }
}

// Dispatch sizes, bounds and tags that the WGSL prelude is generated
// from (src/gpu/shaders.rs): defined here, beside the layouts, so that
// the shader assembler imports no pipeline.

/// Workgroup side in pixels of the image passes (`WORKGROUP_SIDE`).
pub const WORKGROUP_SIDE: u32 = 8;

/// Invocations per workgroup of the walks, one walk each per dispatch (the
/// WGSL's `WALK_LANES` is generated from it).
pub const WALK_LANES: u32 = 64;

/// Invocations per workgroup of the placement (the WGSL's
/// `PLACEMENT_LANES`, its `@workgroup_size`, is generated from it).
pub const PLACEMENT_LANES: u32 = 64;

/// `view` of the display's clamp transform (`VIEW_CLAMP`).
pub const VIEW_CLAMP: u32 = 0;
/// `view` of the display's filmic transform.
pub const VIEW_FILMIC: u32 = 1;

/// `mode` of the display's [`DisplayMode::Single`](super::display::DisplayMode::Single).
pub const MODE_SINGLE: u32 = 0;
/// `mode` of the display's [`DisplayMode::Split`](super::display::DisplayMode::Split).
pub const MODE_SPLIT: u32 = 1;
/// `mode` of the display's [`DisplayMode::Heat`](super::display::DisplayMode::Heat).
pub const MODE_HEAT: u32 = 2;

#[cfg(test)]
mod tests {
    use super::*;

    /// Field offsets that WGSL's layout rules fix (a `vec3<f32>` at a
    /// multiple of 16, the scalar after it at +12).
    #[test]
    fn offsets_follow_wgsl_layout() {
        assert_eq!(std::mem::offset_of!(GpuScene, medium), 64);
        assert_eq!(std::mem::offset_of!(GpuScene, sun_count), 224);
        assert_eq!(std::mem::offset_of!(GpuScene, env_radiance), 240);
        assert_eq!(std::mem::offset_of!(GpuScene, env_width), 256);
        assert_eq!(std::mem::offset_of!(GpuMedium, g), 28);
        assert_eq!(std::mem::offset_of!(GpuMedium, grid_dims), 96);
        assert_eq!(std::mem::offset_of!(GpuMedium, majorant_max), 144);
        assert_eq!(std::mem::offset_of!(GpuLight, power), 16);
    }
}
