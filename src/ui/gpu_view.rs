//! The GPU backend's side of the window: a [`GpuContext`] on eframe's own
//! wgpu device (so that renders and the window share it), and the shown
//! image as a wgpu texture written by the display pass
//! ([`crate::gpu::display`]) and registered with egui-wgpu's renderer: the
//! image never travels through the CPU.

use eframe::egui;
use eframe::egui_wgpu;

use crate::gpu::display::{DisplayPass, DisplaySettings};
use crate::gpu::{GpuContext, GpuError};

/// `LANTERN_GPU=off` makes the GPU unavailable (tests of the fallback).
pub const DISABLE_VAR: &str = "LANTERN_GPU";

/// The device limits eframe asks for: the adapter's own (as the headless
/// backend does), so that large volumes fit where the hardware allows;
/// WebGL-like defaults on GL, which cannot run the compute shaders anyway.
pub fn wgpu_options() -> egui_wgpu::WgpuConfiguration {
    let mut options = eframe::NativeOptions::default().wgpu_options;
    if let egui_wgpu::WgpuSetup::CreateNew(create) = &mut options.wgpu_setup {
        create.device_descriptor = std::sync::Arc::new(|adapter: &wgpu::Adapter| {
            let limits = if adapter.get_info().backend == wgpu::Backend::Gl {
                wgpu::Limits {
                    max_texture_dimension_2d: 8192,
                    ..wgpu::Limits::downlevel_webgl2_defaults()
                }
            } else {
                adapter.limits()
            };
            wgpu::DeviceDescriptor {
                label: Some("lantern window device"),
                required_limits: limits,
                ..Default::default()
            }
        });
    }
    options
}

/// The GPU context on eframe's device and the display it draws with, or
/// why there is none.
pub fn from_eframe(
    cc: &eframe::CreationContext<'_>,
) -> (Result<GpuContext, String>, Option<GpuView>) {
    if std::env::var(DISABLE_VAR).is_ok_and(|v| v == "off") {
        return (Err(format!("disabled by {DISABLE_VAR}=off")), None);
    }
    let Some(state) = cc.wgpu_render_state.as_ref() else {
        return (Err("the window does not use wgpu".into()), None);
    };
    let made = GpuContext::from_device(&state.adapter, state.device.clone(), state.queue.clone())
        .and_then(|ctx| {
            let view = GpuView::new(state.clone(), &ctx)?;
            Ok((ctx, view))
        });
    match made {
        Ok((ctx, view)) => (Ok(ctx), Some(view)),
        Err(e) => (Err(e.to_string()), None),
    }
}

/// The display texture and its egui id.
struct Target {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    id: egui::TextureId,
}

/// The display pass and the texture egui shows.
pub struct GpuView {
    state: egui_wgpu::RenderState,
    pass: DisplayPass,
    target: Option<Target>,
}

impl GpuView {
    /// Builds the display pipelines on `ctx` (eframe's device).
    pub fn new(state: egui_wgpu::RenderState, ctx: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            pass: DisplayPass::new(ctx)?,
            state,
            target: None,
        })
    }

    /// Enqueues the display of `a` (and `b`) at `width` × `height` into
    /// the texture (re-made and re-registered when the size changes) and
    /// returns its egui id. Does not wait for the GPU.
    pub fn draw(
        &mut self,
        a: &wgpu::Buffer,
        b: Option<&wgpu::Buffer>,
        width: u32,
        height: u32,
        settings: &DisplaySettings,
    ) -> Result<egui::TextureId, GpuError> {
        let fits = self
            .target
            .as_ref()
            .is_some_and(|t| t.texture.width() == width && t.texture.height() == height);
        if !fits {
            let texture = self.pass.create_target(width, height);
            let view = texture.create_view(&Default::default());
            let mut renderer = self.state.renderer.write();
            let id = match self.target.take() {
                Some(old) => {
                    renderer.update_egui_texture_from_wgpu_texture(
                        &self.state.device,
                        &view,
                        wgpu::FilterMode::Linear,
                        old.id,
                    );
                    old.id
                }
                None => renderer.register_native_texture(
                    &self.state.device,
                    &view,
                    wgpu::FilterMode::Linear,
                ),
            };
            self.target = Some(Target { texture, view, id });
        }
        let Some(target) = &self.target else {
            return Err(GpuError::Wgpu {
                context: "the display texture".into(),
                message: "missing".into(),
            });
        };
        self.pass
            .draw(a, b, width, height, settings, &target.view)?;
        Ok(target.id)
    }
}

impl Drop for GpuView {
    fn drop(&mut self) {
        if let Some(t) = self.target.take() {
            self.state.renderer.write().free_texture(&t.id);
        }
    }
}
