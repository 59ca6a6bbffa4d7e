//! The previewer's display pass on the GPU: the accumulation buffers of
//! [`GpuRenderer`](super::GpuRenderer)s become the shown image without a
//! trip through the CPU (`shaders/display/`), and a one-workgroup
//! reduction gives the numbers the previewer prints.
//!
//! The image is an `Rgba8Unorm` texture holding sRGB-encoded values (what
//! a UI toolkit such as egui expects of its textures), written by a compute
//! shader with the exposure and view transform of `render::tonemap`
//! (`shaders/common/tonemap.wgsl`). Three modes, as the previewer's
//! viewport has on the CPU: one estimator, the split view and the error
//! heatmap. Nothing here knows of a UI: the caller owns the texture and
//! hands in its view.

use wgpu::util::DeviceExt;

use super::context::{GpuContext, GpuError};
use super::mirrors::{
    GpuAccum, MODE_HEAT, MODE_SINGLE, MODE_SPLIT, VIEW_CLAMP, VIEW_FILMIC, WORKGROUP_SIDE,
};
use super::renderer::{compute_pipeline, read_buffer, GpuImage};
use super::shaders::{DISPLAY_MODULE, DISPLAY_STATS_MODULE};
use crate::render::tonemap::ViewTransform;

/// The format of the display texture.
pub const DISPLAY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// What the display pass draws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DisplayMode {
    /// The first buffer's mean.
    Single,
    /// The first buffer left of `split` (0 to 1 of the width), the second
    /// right of it.
    Split(f32),
    /// `|first − second|` averaged over channels, times `scale`, through
    /// the heat ramp (black, purple, orange, yellow).
    Heat(f32),
}

/// Display settings of one dispatch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplaySettings {
    /// Exposure in stops.
    pub exposure: f32,
    /// View transform.
    pub view: ViewTransform,
    /// What to draw.
    pub mode: DisplayMode,
}

/// `DisplayParams` of `shaders/display/main.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuDisplayParams {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// 0 single, 1 split, 2 heatmap.
    pub mode: u32,
    /// [`VIEW_CLAMP`] or [`VIEW_FILMIC`].
    pub view: u32,
    /// Exposure in stops.
    pub exposure: f32,
    /// First column taken from the second buffer (split view).
    pub split_x: u32,
    /// Heatmap scale.
    pub heat_scale: f32,
    /// Samples per pixel in the first buffer (statistics).
    pub samples: u32,
}
const _: () = assert!(std::mem::size_of::<GpuDisplayParams>() == 32);

/// The four means of the statistics pass.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImageStats {
    /// Image mean of the first buffer's luminance.
    pub mean_luminance: f32,
    /// Image mean of the variance of the first buffer's per-pixel mean
    /// luminance (0 below two samples).
    pub mean_variance: f32,
    /// Mean over pixels and channels of the squared difference of the two
    /// buffers' means (RMSE²).
    pub mean_sq_diff: f32,
    /// Mean over pixels and channels of the second buffer's mean.
    pub second_mean: f32,
    /// The first buffer's pixel passes that the driver's loop cap cut
    /// short, summed over its pixels (what
    /// [`GpuImage::cut_short_passes`](crate::gpu::GpuImage::cut_short_passes)
    /// counts after a read-back).
    pub cut_short_passes: u64,
}

impl ImageStats {
    /// Relative standard error of the image, `sqrt(mean σ²) / mean L`, as
    /// the CPU path computes it (1 when unknown).
    pub fn rel_error(&self, samples: u32) -> f32 {
        if self.mean_luminance > 0.0 && samples >= 2 {
            self.mean_variance.max(0.0).sqrt() / self.mean_luminance
        } else {
            1.0
        }
    }

    /// Root-mean-square difference of the two buffers.
    pub fn rmse(&self) -> f32 {
        self.mean_sq_diff.max(0.0).sqrt()
    }
}

/// The display and statistics pipelines on one device.
pub struct DisplayPass {
    ctx: GpuContext,
    image: wgpu::ComputePipeline,
    stats: wgpu::ComputePipeline,
}

impl DisplayPass {
    /// Builds both pipelines.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            ctx: ctx.clone(),
            image: compute_pipeline(ctx, &DISPLAY_MODULE)?,
            stats: compute_pipeline(ctx, &DISPLAY_STATS_MODULE)?,
        })
    }

    /// A texture the display pass can write and a UI can sample, of
    /// `width` × `height` pixels.
    pub fn create_target(&self, width: u32, height: u32) -> wgpu::Texture {
        self.ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("display image"),
            size: wgpu::Extent3d {
                width: width.max(1),
                height: height.max(1),
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DISPLAY_FORMAT,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    }

    fn params(
        width: u32,
        height: u32,
        samples: u32,
        settings: &DisplaySettings,
    ) -> GpuDisplayParams {
        let (mode, split_x, heat_scale) = match settings.mode {
            DisplayMode::Single => (MODE_SINGLE, width, 1.0),
            DisplayMode::Split(s) => (
                MODE_SPLIT,
                (s.clamp(0.0, 1.0) * width as f32).round() as u32,
                1.0,
            ),
            DisplayMode::Heat(scale) => (MODE_HEAT, width, scale),
        };
        GpuDisplayParams {
            width,
            height,
            mode,
            view: match settings.view {
                ViewTransform::Clamp => VIEW_CLAMP,
                ViewTransform::Filmic => VIEW_FILMIC,
            },
            exposure: settings.exposure,
            split_x,
            heat_scale,
            samples,
        }
    }

    fn bind_group(
        &self,
        pipeline: &wgpu::ComputePipeline,
        params: &GpuDisplayParams,
        a: &wgpu::Buffer,
        b: &wgpu::Buffer,
        out: wgpu::BindingResource<'_>,
    ) -> wgpu::BindGroup {
        let uniform = self
            .ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("display uniform"),
                contents: bytemuck::bytes_of(params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        self.ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("display"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: uniform.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: a.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: b.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: out,
                    },
                ],
            })
    }

    /// Enqueues the display of `a` (and `b`, for the split view and the
    /// heatmap; `a` again otherwise), images of `width` × `height`, into
    /// `target` (a view of a [`DisplayPass::create_target`] texture of that
    /// size). Does not wait for the GPU; validation errors are returned.
    pub fn draw(
        &self,
        a: &wgpu::Buffer,
        b: Option<&wgpu::Buffer>,
        width: u32,
        height: u32,
        settings: &DisplaySettings,
        target: &wgpu::TextureView,
    ) -> Result<(), GpuError> {
        let params = Self::params(width, height, 0, settings);
        self.ctx.scoped("the display pass", || {
            let group = self.bind_group(
                &self.image,
                &params,
                a,
                b.unwrap_or(a),
                wgpu::BindingResource::TextureView(target),
            );
            let mut encoder =
                self.ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("display"),
                    });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("display"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.image);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(
                    width.div_ceil(WORKGROUP_SIDE),
                    height.div_ceil(WORKGROUP_SIDE),
                    1,
                );
            }
            self.ctx.queue.submit([encoder.finish()]);
        })
    }

    /// The statistics of `a` (holding `samples` samples per pixel) and of
    /// its difference from `b` (`a` itself when `None`). Waits for the GPU
    /// and reads 32 bytes back: for a worker thread, never a UI thread.
    pub fn stats(
        &self,
        a: &wgpu::Buffer,
        b: Option<&wgpu::Buffer>,
        width: u32,
        height: u32,
        samples: u32,
    ) -> Result<ImageStats, GpuError> {
        let settings = DisplaySettings {
            exposure: 0.0,
            view: ViewTransform::Clamp,
            mode: DisplayMode::Single,
        };
        let params = Self::params(width, height, samples, &settings);
        let out = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("display statistics"),
            size: 32,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        self.ctx.scoped("the statistics pass", || {
            let group = self.bind_group(
                &self.stats,
                &params,
                a,
                b.unwrap_or(a),
                out.as_entire_binding(),
            );
            let mut encoder =
                self.ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("display statistics"),
                    });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("display statistics"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.stats);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(1, 1, 1);
            }
            self.ctx.queue.submit([encoder.finish()]);
        })?;
        let v: Vec<f32> = read_buffer(&self.ctx, &out, "the display statistics")?;
        let at = |i: usize| v.get(i).copied().unwrap_or(0.0);
        Ok(ImageStats {
            mean_luminance: at(0),
            mean_variance: at(1),
            mean_sq_diff: at(2),
            second_mean: at(3),
            // A sum of whole counts, exact in f32 up to 2²⁴.
            cut_short_passes: at(4).max(0.0).round() as u64,
        })
    }
}

/// Reads a display texture back as tightly packed RGBA8 rows (export and
/// tests; waits for the GPU).
pub fn read_texture(ctx: &GpuContext, texture: &wgpu::Texture) -> Result<Vec<u8>, GpuError> {
    let (width, height) = (texture.width(), texture.height());
    let row = width * 4;
    let padded =
        row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("display read-back"),
        size: padded as u64 * height as u64,
        usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("display read-back"),
        });
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(height),
            },
        },
        texture.size(),
    );
    ctx.queue.submit([encoder.finish()]);
    let bytes: Vec<u8> = read_buffer(ctx, &buffer, "the display texture")?;
    Ok(bytes
        .chunks(padded as usize)
        .flat_map(|r| r[..row as usize].iter().copied())
        .collect())
}

/// Reads an accumulation buffer of `width` × `height` pixels holding
/// `samples` samples per pixel back as an image (export and tests; waits
/// for the GPU).
pub fn read_accum(
    ctx: &GpuContext,
    accum: &wgpu::Buffer,
    width: u32,
    height: u32,
    samples: u32,
) -> Result<GpuImage, GpuError> {
    let pixels: Vec<GpuAccum> = read_buffer(ctx, accum, "the accumulation buffer")?;
    let n = width as usize * height as usize;
    Ok(GpuImage {
        width,
        height,
        samples,
        pixels: pixels.into_iter().take(n).collect(),
        cut_short_walks: 0,
    })
}
