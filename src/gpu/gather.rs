//! The final gather of the internal-lights method ([method §6](crate::doc::method)) on the
//! GPU, both forms of `L₁` (the field form and the point lights,
//! [`L1Form`](crate::scene::L1Form), chosen in the uniform), with the internal lights built on
//! the CPU ([`InternalLights::build`]) or on the GPU
//! ([`super::walks::build_internal_lights_gpu`]) and uploaded once:
//! positions and weights, the SH coefficients of
//! the multiply scattered part of `J`, the light arriving at each light
//! from the external ones and from the sky, and both spatial indices of
//! `physics::internal::light_index` (the fine grid of the kernel reconstruction and
//! the cluster grid of the light selection, which only the points form
//! reads).
//!
//! To stay within the eight storage buffers per shader stage that every
//! device offers, the tables are packed into two buffers, `vec4` data and
//! 32-bit words, at offsets given in [`GpuGatherParams`]; the layout is
//! written out in `shaders/common/internal_data.wgsl`.

use super::context::{GpuContext, GpuError};
use super::mirrors::GpuGatherParams;
use super::renderer::{storage_buffer, GpuRenderer};
use super::shaders::GATHER_MODULE;
use crate::physics::internal::sources::InternalLights;
use crate::render::PreparedScene;

/// The cached lights packed for the GPU.
pub struct PackedLights {
    /// Constants and table offsets.
    pub params: GpuGatherParams,
    /// Per light two vec4, then SH coefficients, then arriving light.
    pub vec4: Vec<[f32; 4]>,
    /// Grid starts and ids, powers (f32 bits), live clusters.
    pub words: Vec<u32>,
}

/// Packs `cache` for `shaders/common/internal_data.wgsl`, with
/// `light_samples` internal-light samples per camera sample.
pub fn pack_lights(cache: &InternalLights, light_samples: u32) -> PackedLights {
    let n = cache.lights.len();
    let mut vec4: Vec<[f32; 4]> = Vec::new();
    let lights_offset = vec4.len() as u32;
    for (l, scale) in cache.lights.iter().zip(&cache.recon_scale) {
        let p = l.position;
        vec4.push([p.x, p.y, p.z, l.density]);
        vec4.push([l.weight, *scale, 0.0, 0.0]);
    }
    let multi_offset = vec4.len() as u32;
    vec4.extend(cache.multi_coeffs.iter().map(|c| [c.x, c.y, c.z, 0.0]));
    let scattered_offset = vec4.len() as u32;
    vec4.extend(cache.scattered_coeffs.iter().map(|c| [c.x, c.y, c.z, 0.0]));
    let arrival_offset = vec4.len() as u32;
    vec4.extend(cache.arrival.iter().map(|c| [c.x, c.y, c.z, 0.0]));
    let view_offset = vec4.len() as u32;
    let has_view = cache.has_view();
    vec4.extend(cache.view.iter().map(|v| [v.x, v.y, v.z, 0.0]));
    let phase_view_offset = vec4.len() as u32;
    let has_phase_view = cache.has_phase_view();
    vec4.extend(cache.phase_view.iter().map(|v| [v.x, v.y, v.z, 0.0]));
    let sky_offset = vec4.len() as u32;
    let has_sky = !cache.sky.is_empty();
    vec4.extend(cache.sky.iter().map(|c| [c.x, c.y, c.z, 0.0]));
    if vec4.is_empty() {
        vec4.push([0.0; 4]);
    }

    let mut words: Vec<u32> = Vec::new();
    let mut table = |data: &mut dyn Iterator<Item = u32>| {
        let offset = words.len() as u32;
        words.extend(data);
        offset
    };
    let fine = &cache.fine;
    let clusters = &cache.clusters;
    let fine_starts_offset = table(&mut fine.starts().iter().copied());
    let fine_ids_offset = table(&mut fine.ids().iter().copied());
    let cluster_starts_offset = table(&mut clusters.starts().iter().copied());
    let cluster_ids_offset = table(&mut clusters.ids().iter().copied());
    let cluster_power_offset = table(&mut cache.cluster_power.iter().map(|p| p.to_bits()));
    let light_power_offset = table(&mut cache.light_power.iter().map(|p| p.to_bits()));
    let live_offset = table(&mut cache.live_clusters.iter().copied());
    if words.is_empty() {
        words.push(0);
    }

    let params = GpuGatherParams {
        scatter: cache.scatter.to_array(),
        g: cache.g,
        fine_min: fine.min().to_array(),
        s_star: cache.s_star,
        fine_cell: fine.cell_size().to_array(),
        kernel_radius: cache.kernel_radius,
        fine_res: fine.resolution().to_array(),
        softening: cache.softening,
        cluster_min: clusters.min().to_array(),
        sigma_grey: cache.sigma_grey,
        cluster_cell: clusters.cell_size().to_array(),
        clock: cache.params.clock.tag(),
        cluster_res: clusters.resolution().to_array(),
        sh_order: cache.sh_order,
        sh_count: cache.sh_count as u32,
        light_count: n as u32,
        external_count: (cache.arrival.len() / n.max(1)) as u32,
        light_samples,
        lights_offset,
        multi_offset,
        arrival_offset,
        live_count: cache.live_clusters.len() as u32,
        fine_starts_offset,
        fine_ids_offset,
        cluster_starts_offset,
        cluster_ids_offset,
        cluster_power_offset,
        light_power_offset,
        live_offset,
        l1_form: cache.params.l1.tag(),
        scattered_offset,
        n_terms: cache.params.terms,
        window_scatters: cache.params.window_scatters.max(1),
        view_offset,
        has_view: u32::from(has_view),
        sky_offset,
        has_sky: u32::from(has_sky),
        phase_view_offset,
        has_phase_view: u32::from(has_phase_view),
        _pad0: 0,
        _pad1: 0,
        _pad2: 0,
    };
    PackedLights {
        params,
        vec4,
        words,
    }
}

impl GpuRenderer {
    /// The internal-lights method's final gather with lights already built
    /// on the CPU for this scene (`cache`), `light_samples` internal-light
    /// samples per camera sample (the setting `light_samples`), and `seed`
    /// for the random streams, as on the CPU.
    pub fn internal(
        ctx: &GpuContext,
        prepared: &PreparedScene,
        cache: &InternalLights,
        light_samples: u32,
        seed: u64,
    ) -> Result<Self, GpuError> {
        let (buffers, bytes) = upload_lights(ctx, cache, light_samples)?;
        let [params, vec4, words] = &buffers;
        let mut renderer = Self::build(
            ctx,
            prepared,
            seed,
            &GATHER_MODULE,
            &[(6, params), (7, vec4), (8, words)],
            bytes,
        )?;
        renderer.cut_short_walks = cache.cut_short_walks;
        Ok(renderer)
    }

    /// Gathers the passes still to come from another set of internal
    /// lights of the same scene and parameters (a renewed light set, see
    /// `Expert::resample_every`), keeping what has accumulated.
    pub fn set_internal_lights(
        &mut self,
        cache: &InternalLights,
        light_samples: u32,
    ) -> Result<(), GpuError> {
        let (buffers, bytes) = upload_lights(&self.ctx, cache, light_samples)?;
        let [params, vec4, words] = &buffers;
        self.rebind_extra(&[(6, params), (7, vec4), (8, words)], bytes)?;
        self.cut_short_walks += cache.cut_short_walks;
        Ok(())
    }
}

/// The gather's light buffers (uniform, vec4 tables, index tables) for
/// `cache`, and their size in bytes.
fn upload_lights(
    ctx: &GpuContext,
    cache: &InternalLights,
    light_samples: u32,
) -> Result<([wgpu::Buffer; 3], u64), GpuError> {
    use wgpu::util::DeviceExt;
    let packed = pack_lights(cache, light_samples);
    let params = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("gather uniform"),
            contents: bytemuck::bytes_of(&packed.params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    let vec4 = storage_buffer(
        ctx,
        "internal lights (vec4 tables)",
        bytemuck::cast_slice(&packed.vec4),
        wgpu::BufferUsages::empty(),
    )?;
    let words = storage_buffer(
        ctx,
        "internal lights (index tables)",
        bytemuck::cast_slice(&packed.words),
        wgpu::BufferUsages::empty(),
    )?;
    let bytes = params.size() + vec4.size() + words.size();
    Ok(([params, vec4, words], bytes))
}
