//! Progressive rendering on the GPU: one compute dispatch per pass adds one
//! sample per pixel to a per-pixel running mean and variance that stays in
//! GPU memory; the image is read back only for export and tests. One
//! [`GpuRenderer`] serves both estimators; they differ in their shader
//! module and the buffers bound after the scene's.
//!
//! The reference method ([method §2](crate::doc::method), `shaders/common/reference.wgsl`,
//! entry point in `shaders/reference/main.wgsl`) mirrors
//! `cpu::Renderer::pass`: the same random stream per (seed, pixel, pass),
//! the same pixel jitter, the same estimator (`physics::reference`), so the
//! two backends agree statistically (not bitwise: `exp`, `log` and fused
//! operations differ). The internal-lights gather is in [`super::gather`].

use glam::Vec3;
use wgpu::util::DeviceExt;

use super::context::{GpuContext, GpuError};
use super::mirrors::{
    density_voxels, gpu_environment, gpu_lights, GpuAccum, GpuPassParams, GpuScene, WORKGROUP_SIDE,
};
use super::shaders::{ModuleSource, REFERENCE_MODULE};
use crate::render::{Film, PreparedScene};

/// A compute pipeline built from one assembled module, with its bind-group
/// layout taken from the shader.
pub(crate) fn compute_pipeline(
    ctx: &GpuContext,
    module: &ModuleSource,
) -> Result<wgpu::ComputePipeline, GpuError> {
    if let Some(p) = ctx.cached_pipeline(module.name, module.entry_point) {
        return Ok(p);
    }
    let source = module.assemble();
    let pipeline = ctx.scoped(&format!("building the {} shader", module.name), || {
        let shader = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(module.name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        ctx.device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(module.name),
                layout: None,
                module: &shader,
                entry_point: Some(module.entry_point),
                compilation_options: Default::default(),
                cache: None,
            })
    })?;
    ctx.cache_pipeline(module.name, module.entry_point, &pipeline);
    Ok(pipeline)
}

/// A storage buffer holding `data`, after checking that the device can bind
/// it.
pub(crate) fn storage_buffer(
    ctx: &GpuContext,
    label: &str,
    data: &[u8],
    extra_usage: wgpu::BufferUsages,
) -> Result<wgpu::Buffer, GpuError> {
    ctx.check_storage_size(label, data.len() as u64)?;
    Ok(ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: data,
            usage: wgpu::BufferUsages::STORAGE | extra_usage,
        }))
}

/// The scene's constant buffers (bindings 0–4 and 9 of
/// `shaders/common/scene.wgsl`).
pub(crate) struct SceneBuffers {
    /// `Scene` uniform.
    pub scene: wgpu::Buffer,
    /// `PassParams` uniform, rewritten before every pass.
    pub pass: wgpu::Buffer,
    /// Density voxels: the view of a 3D `r32float` texture (which it keeps
    /// alive), bound at binding 2.
    pub density_view: wgpu::TextureView,
    /// Majorant per coarse cell.
    pub majorants: wgpu::Buffer,
    /// External lights.
    pub lights: wgpu::Buffer,
    /// The environment map and its sampling tables (binding 9).
    pub environment: wgpu::Buffer,
    /// Bytes held on the GPU by these buffers.
    pub bytes: u64,
}

impl SceneBuffers {
    /// Uploads the prepared scene.
    pub fn new(ctx: &GpuContext, prepared: &PreparedScene) -> Result<Self, GpuError> {
        let vol = &prepared.volume;
        let scene_data = GpuScene::new(&prepared.camera, vol, &prepared.lights);
        let (voxels, dims) = density_voxels(&vol.density);
        let lights = gpu_lights(&prepared.lights);
        let density = density_texture(ctx, voxels, dims)?;
        let density_view = density.create_view(&wgpu::TextureViewDescriptor::default());
        let density_bytes = voxels.len() as u64 * 4;
        let majorants = storage_buffer(
            ctx,
            "majorant grid",
            bytemuck::cast_slice(&vol.majorants.values),
            wgpu::BufferUsages::empty(),
        )?;
        let lights_buf = storage_buffer(
            ctx,
            "light list",
            bytemuck::cast_slice(&lights),
            wgpu::BufferUsages::empty(),
        )?;
        let env = gpu_environment(&prepared.lights);
        let environment = storage_buffer(
            ctx,
            "environment map",
            bytemuck::cast_slice(&env),
            wgpu::BufferUsages::empty(),
        )?;
        let scene = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("scene uniform"),
                contents: bytemuck::bytes_of(&scene_data),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let pass = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("pass uniform"),
                contents: bytemuck::bytes_of(&GpuPassParams::default()),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            });
        let bytes = density_bytes
            + majorants.size()
            + lights_buf.size()
            + environment.size()
            + scene.size()
            + pass.size();
        Ok(Self {
            scene,
            pass,
            density_view,
            majorants,
            lights: lights_buf,
            environment,
            bytes,
        })
    }

    /// Bind-group entries 0–4 and 9.
    pub fn entries(&self) -> [wgpu::BindGroupEntry<'_>; 6] {
        [
            buffer(0, &self.scene),
            buffer(1, &self.pass),
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::TextureView(&self.density_view),
            },
            buffer(3, &self.majorants),
            buffer(4, &self.lights),
            buffer(9, &self.environment),
        ]
    }
}

/// Binds all of `buffer` at `binding`.
fn buffer(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// The density voxels (x fastest, `dims` of them) as a 3D `r32float`
/// texture, after checking the device's 3D texture size; read with
/// `textureLoad` in `shaders/common/volume.wgsl`.
pub(crate) fn density_texture(
    ctx: &GpuContext,
    voxels: &[f32],
    dims: [u32; 3],
) -> Result<wgpu::Texture, GpuError> {
    let max = ctx.limits.max_texture_dimension_3d;
    if dims.iter().any(|&d| d > max) {
        return Err(GpuError::TooManyVoxels {
            what: "density grid".to_owned(),
            dims: format!("{} × {} × {}", dims[0], dims[1], dims[2]),
            max,
        });
    }
    let size = wgpu::Extent3d {
        width: dims[0],
        height: dims[1],
        depth_or_array_layers: dims[2],
    };
    ctx.scoped("uploading the density grid", || {
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("density grid"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        // One slab of z-slices at a time keeps the staging copy wgpu makes
        // small (a 512³ grid is 512 MiB).
        let slice = dims[0] as usize * dims[1] as usize;
        let slab = (64 * 1024 * 1024 / (4 * slice.max(1))).max(1);
        for (n, chunk) in voxels.chunks(slice * slab).enumerate() {
            let z0 = (n * slab) as u32;
            let depth = (chunk.len() / slice.max(1)) as u32;
            ctx.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y: 0, z: z0 },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(chunk),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * dims[0]),
                    rows_per_image: Some(dims[1]),
                },
                wgpu::Extent3d {
                    depth_or_array_layers: depth,
                    ..size
                },
            );
        }
        texture
    })
}

/// Copies `buffer` (which must have `COPY_SRC`) to the CPU.
pub(crate) fn read_buffer<T: bytemuck::Pod>(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    what: &'static str,
) -> Result<Vec<T>, GpuError> {
    let size = buffer.size();
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back staging"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("read-back"),
        });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let (sender, receiver) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = sender.send(r);
    });
    ctx.wait_idle()?;
    let readback = |message: String| GpuError::Readback { what, message };
    receiver
        .recv()
        .map_err(|e| readback(e.to_string()))?
        .map_err(|e| readback(e.to_string()))?;
    let data = {
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| readback(e.to_string()))?;
        bytemuck::pod_collect_to_vec(&view)
    };
    staging.unmap();
    Ok(data)
}

/// The accumulated image read back from the GPU.
#[derive(Clone, Debug)]
pub struct GpuImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel accumulated.
    pub samples: u32,
    /// Per-pixel running statistics, rows top to bottom.
    pub pixels: Vec<GpuAccum>,
    /// Internal lights' walks that the driver cut short, summed over the
    /// light sets the passes were gathered from
    /// ([`InternalLights::cut_short_walks`](crate::physics::internal::sources::InternalLights::cut_short_walks)).
    pub cut_short_walks: u64,
}

impl GpuImage {
    /// The estimate as a film (means and variances as if accumulated on the
    /// CPU).
    pub fn film(&self) -> Film {
        let mean: Vec<Vec3> = self.pixels.iter().map(GpuAccum::mean).collect();
        let m2: Vec<Vec3> = self.pixels.iter().map(GpuAccum::m2).collect();
        Film::from_moments(self.width, self.height, self.samples, &mean, &m2)
    }

    /// Per pixel and channel the sum of the accumulated passes (the
    /// running mean times the passes): differences between two read-backs
    /// give a light set's sums
    /// ([`WeightedSets::replace_current`](crate::render::renewal::WeightedSets::replace_current)).
    pub fn sums(&self) -> Vec<[f64; 3]> {
        let n = f64::from(self.samples);
        self.pixels
            .iter()
            .map(|p| {
                let m = p.mean();
                [n * f64::from(m.x), n * f64::from(m.y), n * f64::from(m.z)]
            })
            .collect()
    }

    /// Per pixel the sum and the sum of squares of the channels' mean
    /// `(r + g + b)/3` over the accumulated passes, from the running mean
    /// and [`GpuAccum::grey_m2`]: the moments a balanced light-set schedule
    /// takes ([`crate::render::renewal::BalancedRenewal::replace_set_sums`],
    /// as differences between two read-backs).
    pub fn grey_sums(&self) -> Vec<(f64, f64)> {
        let n = f64::from(self.samples);
        self.pixels
            .iter()
            .map(|p| {
                let m = f64::from(p.mean().element_sum()) / 3.0;
                (n * m, f64::from(p.grey_m2()) + n * m * m)
            })
            .collect()
    }

    /// The single-scattering part's mean image.
    pub fn single_mean(&self) -> Vec<Vec3> {
        self.pixels.iter().map(GpuAccum::single_mean).collect()
    }

    /// Pixel passes whose estimate the driver cut short, summed over the
    /// image: Mesa's software driver (lavapipe) ends all of an
    /// invocation's loops after 65 535 iterations in all, which leaves
    /// those samples too dark without any error. Zero on hardware drivers
    /// and whenever the work per pixel stays under the cap.
    pub fn cut_short_passes(&self) -> u64 {
        self.pixels
            .iter()
            .map(|p| u64::from(p.cut_short_passes()))
            .sum()
    }
}

/// What to tell the user when the driver cut `cut` of `all` pixel passes
/// short ([`GpuImage::cut_short_passes`]; `None` when it cut none): the
/// share and why the image is too dark, for the command line and the
/// previewer alike, which each add how to avoid it.
pub fn cut_short_passes_text(cut: u64, all: u64) -> Option<String> {
    (cut > 0).then(|| {
        format!(
            "the GPU driver cut {cut} of {all} pixel passes short ({:.3} %): it caps the loop \
             iterations of one shader invocation (Mesa's software driver does), so the image \
             is darker than it should be",
            100.0 * cut as f64 / all.max(1) as f64
        )
    })
}

/// A progressive GPU renderer for one prepared scene and one estimator.
pub struct GpuRenderer {
    pub(crate) ctx: GpuContext,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    buffers: SceneBuffers,
    accum: wgpu::Buffer,
    width: u32,
    height: u32,
    seed: u64,
    samples: u32,
    label: &'static str,
    /// Bytes of the `extra` buffers (counted in `buffers.bytes`).
    extra_bytes: u64,
    /// Walks of the light sets gathered so far that the driver cut short.
    pub(crate) cut_short_walks: u64,
}

/// The bind group of `pipeline`: the scene's buffers (bindings 0–4) and
/// `extra` (binding, buffer) pairs.
pub(crate) fn bind_group(
    ctx: &GpuContext,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    scene: &SceneBuffers,
    extra: &[(u32, &wgpu::Buffer)],
) -> wgpu::BindGroup {
    let mut entries = scene.entries().to_vec();
    for &(binding, buffer) in extra {
        entries.push(wgpu::BindGroupEntry {
            binding,
            resource: buffer.as_entire_binding(),
        });
    }
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

/// A renderer's bind group: the scene's buffers, the accumulation
/// (binding 5) and `extra`.
fn bind(
    ctx: &GpuContext,
    pipeline: &wgpu::ComputePipeline,
    buffers: &SceneBuffers,
    accum: &wgpu::Buffer,
    extra: &[(u32, &wgpu::Buffer)],
    label: &'static str,
) -> Result<wgpu::BindGroup, GpuError> {
    let mut all = vec![(5, accum)];
    all.extend_from_slice(extra);
    ctx.scoped("binding the renderer's buffers", || {
        bind_group(ctx, label, pipeline, buffers, &all)
    })
}

impl GpuRenderer {
    /// The reference path tracer: uploads the scene and builds the
    /// pipeline; `seed` selects the random streams, as on the CPU.
    pub fn reference(
        ctx: &GpuContext,
        prepared: &PreparedScene,
        seed: u64,
    ) -> Result<Self, GpuError> {
        Self::build(ctx, prepared, seed, &REFERENCE_MODULE, &[], 0)
    }

    /// A renderer running `module` over the scene's buffers (bindings
    /// 0–4), the accumulation (5) and `extra` (binding, buffer) pairs
    /// holding `extra_bytes`.
    pub(crate) fn build(
        ctx: &GpuContext,
        prepared: &PreparedScene,
        seed: u64,
        module: &ModuleSource,
        extra: &[(u32, &wgpu::Buffer)],
        extra_bytes: u64,
    ) -> Result<Self, GpuError> {
        let (width, height) = (prepared.camera.width, prepared.camera.height);
        let pipeline = compute_pipeline(ctx, module)?;
        let mut buffers = SceneBuffers::new(ctx, prepared)?;
        buffers.bytes += extra_bytes;
        let pixels = width as u64 * height as u64;
        let accum_bytes = pixels * std::mem::size_of::<GpuAccum>() as u64;
        ctx.check_storage_size("accumulation buffer", accum_bytes)?;
        let label = module.name;
        let accum = ctx.scoped("allocating the accumulation buffer", || {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: accum_bytes.max(16),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        let bind_group = bind(ctx, &pipeline, &buffers, &accum, extra, label)?;
        Ok(Self {
            ctx: ctx.clone(),
            pipeline,
            bind_group,
            buffers,
            accum,
            width,
            height,
            seed,
            samples: 0,
            label,
            extra_bytes,
            cut_short_walks: 0,
        })
    }

    /// Binds other `extra` buffers (holding `extra_bytes`) for the passes
    /// still to come, keeping what has accumulated: the internal lights of
    /// a new light set.
    pub(crate) fn rebind_extra(
        &mut self,
        extra: &[(u32, &wgpu::Buffer)],
        extra_bytes: u64,
    ) -> Result<(), GpuError> {
        self.bind_group = bind(
            &self.ctx,
            &self.pipeline,
            &self.buffers,
            &self.accum,
            extra,
            self.label,
        )?;
        self.buffers.bytes = self.buffers.bytes - self.extra_bytes + extra_bytes;
        self.extra_bytes = extra_bytes;
        Ok(())
    }

    /// Samples per pixel accumulated so far (passes enqueued).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Image size in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The per-pixel accumulation ([`GpuAccum`] per pixel, rows top to
    /// bottom), for a display pass that reads it where it is.
    pub fn accum_buffer(&self) -> &wgpu::Buffer {
        &self.accum
    }

    /// Bytes this renderer holds in GPU memory (scene, majorants, lights,
    /// accumulation).
    pub fn gpu_bytes(&self) -> u64 {
        self.buffers.bytes + self.accum.size()
    }

    /// Enqueues pass number `pass_index` (which selects the random streams,
    /// like `cpu::Renderer::pass`): one sample per pixel, accumulated on the
    /// GPU. Does not wait for it; see [`GpuRenderer::finish`].
    pub fn add_pass(&mut self, pass_index: u32) {
        self.samples += 1;
        let params = GpuPassParams {
            seed_lo: self.seed as u32,
            seed_hi: (self.seed >> 32) as u32,
            pass_index,
            sample_count: self.samples,
        };
        let ctx = &self.ctx;
        ctx.queue
            .write_buffer(&self.buffers.pass, 0, bytemuck::bytes_of(&params));
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some(self.label),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(self.label),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(
                self.width.div_ceil(WORKGROUP_SIDE),
                self.height.div_ceil(WORKGROUP_SIDE),
                1,
            );
        }
        ctx.queue.submit([encoder.finish()]);
    }

    /// Blocks until every enqueued pass has finished.
    pub fn finish(&self) -> Result<(), GpuError> {
        self.ctx.wait_idle()
    }

    /// Clears the accumulation and selects new random streams with `seed`
    /// (a new render of the same scene).
    pub fn reset(&mut self, seed: u64) {
        self.seed = seed;
        let mut encoder = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some(self.label),
            });
        encoder.clear_buffer(&self.accum, 0, None);
        self.ctx.queue.submit([encoder.finish()]);
        self.samples = 0;
    }

    /// Waits for the enqueued passes and reads the accumulated image back.
    pub fn read_back(&self) -> Result<GpuImage, GpuError> {
        let pixels = read_buffer(&self.ctx, &self.accum, "the accumulation buffer")?;
        let n = self.width as usize * self.height as usize;
        Ok(GpuImage {
            width: self.width,
            height: self.height,
            samples: self.samples,
            pixels: pixels.into_iter().take(n).collect(),
            cut_short_walks: self.cut_short_walks,
        })
    }
}
