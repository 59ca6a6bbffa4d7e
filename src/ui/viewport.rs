//! The viewport: the progressive image with its sample counter and
//! convergence indicator, the display transform (exposure and view, for
//! display only), camera navigation (Blender bindings or the Alt-drag
//! preset; F frames the volume), the gizmos (medium box, draggable sun,
//! internal lights with their F/J strength, reach `s*` and lobe) and the
//! comparisons (split view with a draggable divider, error heatmap with its
//! RMSE).

use std::sync::Arc;

use eframe::egui::{self, Color32, Pos2, Rect, Sense, Stroke, TextureHandle, Ui, Vec2};
use glam::Vec3;

use super::state::{CompareMode, Document, LightQuantity, NavPreset, Session};
use crate::render::tonemap::to_srgb8;
use crate::scene::{Camera, CameraFrame, Light, Method, Scene};
use crate::session::{LightsView, Snapshot, StreamImage};

/// The image on screen: the snapshot it was made from and its textures.
///
/// On the CPU backend the means are tone-mapped here and uploaded; on the
/// GPU backend the display pass writes a texture on the device from the
/// accumulation buffers ([`super::gpu_view`]), composing the split view
/// and the heatmap there too.
#[derive(Default)]
pub struct Display {
    /// The GPU display, where the window has a GPU.
    gpu_view: Option<super::gpu_view::GpuView>,
    /// The texture the GPU display wrote, when the image on screen came
    /// from the GPU.
    gpu_texture: Option<egui::TextureId>,
    snapshot: Option<Arc<Snapshot>>,
    /// The main image (the left one in the split view).
    texture: Option<TextureHandle>,
    /// The right image of the split view.
    texture_right: Option<TextureHandle>,
    /// What the textures were made with (the divider only matters to the
    /// GPU display, which composes the split view itself).
    made_with: Option<(f32, crate::render::tonemap::ViewTransform, CompareMode, f32)>,
    /// Root-mean-square error of internal lights against the reference.
    pub rmse: Option<f32>,
    /// Mean of the reference image (to state the RMSE relatively).
    pub reference_mean: Option<f32>,
}

impl Display {
    /// Re-makes the textures if the snapshot or the display settings
    /// changed; returns whether it did.
    pub fn update(&mut self, ctx: &egui::Context, snapshot: Arc<Snapshot>, s: &Session) -> bool {
        let on_gpu = snapshot.streams.iter().any(|st| st.gpu.is_some());
        let split = if on_gpu && s.compare == CompareMode::Split {
            s.split
        } else {
            0.0
        };
        let key = (s.exposure, s.view, s.compare, split);
        let same_snapshot = self
            .snapshot
            .as_ref()
            .is_some_and(|old| Arc::ptr_eq(old, &snapshot));
        if same_snapshot && self.made_with == Some(key) {
            return false;
        }
        if on_gpu {
            match self.update_gpu(&snapshot, s) {
                Ok(()) => {
                    self.snapshot = Some(snapshot);
                    self.made_with = Some(key);
                    return true;
                }
                Err(e) => {
                    // Keep what is on screen; say why once per snapshot.
                    eprintln!("lantern: the GPU display failed: {e}");
                    self.snapshot = Some(snapshot);
                    self.made_with = Some(key);
                    return false;
                }
            }
        }
        self.gpu_texture = None;
        let find = |e: Method| snapshot.streams.iter().find(|st| st.estimator == e);
        let first = snapshot.streams.first();
        let (left, right) = match s.compare {
            CompareMode::Internal => (find(Method::Internal).or(first), None),
            CompareMode::Reference => (find(Method::Reference).or(first), None),
            CompareMode::Split => (find(Method::Internal).or(first), find(Method::Reference)),
            CompareMode::Error => (None, None),
        };
        self.rmse = None;
        self.reference_mean = None;
        let image = if s.compare == CompareMode::Error {
            match (find(Method::Internal), find(Method::Reference)) {
                (Some(a), Some(b)) if a.mean.len() == b.mean.len() => {
                    let (img, rmse, mean) = error_heatmap(a, b);
                    self.rmse = Some(rmse);
                    self.reference_mean = Some(mean);
                    Some(img)
                }
                _ => first.map(|st| color_image(st, s)),
            }
        } else {
            left.map(|st| color_image(st, s))
        };
        if let Some(image) = image {
            set_texture(ctx, &mut self.texture, "render", image);
        }
        match right {
            Some(st) => set_texture(
                ctx,
                &mut self.texture_right,
                "render_right",
                color_image(st, s),
            ),
            None => self.texture_right = None,
        }
        self.snapshot = Some(snapshot);
        self.made_with = Some(key);
        true
    }

    /// Gives the display the GPU view it draws GPU snapshots with.
    pub fn set_gpu_view(&mut self, view: Option<super::gpu_view::GpuView>) {
        self.gpu_view = view;
    }

    /// The texture of the image on screen when the GPU display made it
    /// (the whole image, split view included).
    pub fn gpu_texture(&self) -> Option<egui::TextureId> {
        self.gpu_texture
    }

    /// Draws a GPU snapshot with the display pass.
    fn update_gpu(&mut self, snapshot: &Snapshot, s: &Session) -> Result<(), String> {
        use crate::gpu::display::{DisplayMode, DisplaySettings};
        let view = self
            .gpu_view
            .as_mut()
            .ok_or_else(|| "no GPU display in this window".to_string())?;
        let find = |e: Method| {
            snapshot
                .streams
                .iter()
                .find(|st| st.estimator == e && st.gpu.is_some())
        };
        let first = snapshot.streams.iter().find(|st| st.gpu.is_some());
        let internal = find(Method::Internal).or(first);
        let reference = find(Method::Reference);
        self.rmse = None;
        self.reference_mean = None;
        let (a, b, mode) = match s.compare {
            CompareMode::Internal => (internal, None, DisplayMode::Single),
            CompareMode::Reference => (reference.or(first), None, DisplayMode::Single),
            CompareMode::Split if reference.is_some() => {
                (internal, reference, DisplayMode::Split(s.split))
            }
            CompareMode::Error => match (snapshot.error_stats, reference) {
                (Some((rmse, mean)), Some(r)) => {
                    self.rmse = Some(rmse);
                    self.reference_mean = Some(mean);
                    let scale = if mean > 0.0 { 1.0 / mean } else { 1.0 };
                    (internal, Some(r), DisplayMode::Heat(scale))
                }
                _ => (first, None, DisplayMode::Single),
            },
            CompareMode::Split => (first, None, DisplayMode::Single),
        };
        let a = a.ok_or_else(|| "no image".to_string())?;
        let buffer = |st: &StreamImage| st.gpu.as_ref().map(|g| g.accum.clone());
        let a_buf = buffer(a).ok_or_else(|| "no GPU image".to_string())?;
        let b_buf = b.and_then(buffer);
        let settings = DisplaySettings {
            exposure: s.exposure,
            view: s.view,
            mode,
        };
        let id = view
            .draw(&a_buf, b_buf.as_ref(), a.width, a.height, &settings)
            .map_err(|e| e.to_string())?;
        self.gpu_texture = Some(id);
        self.texture = None;
        self.texture_right = None;
        Ok(())
    }

    /// The snapshot on screen.
    pub fn snapshot(&self) -> Option<Arc<Snapshot>> {
        self.snapshot.clone()
    }

    /// Samples per pixel on screen (the least of the streams).
    pub fn spp(&self) -> u32 {
        self.snapshot
            .as_ref()
            .and_then(|s| s.streams.iter().map(|st| st.spp).min())
            .unwrap_or(0)
    }

    /// Generation of the snapshot on screen.
    pub fn generation(&self) -> u64 {
        self.snapshot.as_ref().map_or(0, |s| s.generation)
    }

    /// The internal lights of the snapshot on screen.
    pub fn lights(&self) -> Option<Arc<LightsView>> {
        self.snapshot.as_ref().and_then(|s| s.lights.clone())
    }

    /// The estimator whose image a still export writes.
    pub fn shown_estimator(&self, mode: CompareMode) -> Method {
        match mode {
            CompareMode::Reference => Method::Reference,
            _ => Method::Internal,
        }
    }
}

fn set_texture(
    ctx: &egui::Context,
    slot: &mut Option<TextureHandle>,
    name: &str,
    image: egui::ColorImage,
) {
    let options = egui::TextureOptions::LINEAR;
    match slot {
        Some(t) if t.size() == image.size => t.set(image, options),
        _ => *slot = Some(ctx.load_texture(name, image, options)),
    }
}

fn color_image(stream: &StreamImage, s: &Session) -> egui::ColorImage {
    let rgb = to_srgb8(&stream.mean, s.exposure, s.view);
    egui::ColorImage::from_rgb([stream.width as usize, stream.height as usize], &rgb)
}

/// A perceptual-ish ramp (black, purple, orange, yellow) for `t` in [0, 1].
pub fn heat(t: f32) -> Color32 {
    let t = t.clamp(0.0, 1.0);
    let stops = [
        (0.0, [0.0, 0.0, 0.02]),
        (0.35, [0.45, 0.05, 0.55]),
        (0.7, [0.95, 0.45, 0.1]),
        (1.0, [1.0, 0.98, 0.6]),
    ];
    let mut c = stops[3].1;
    for w in stops.windows(2) {
        let ((t0, a), (t1, b)) = (w[0], w[1]);
        if t <= t1 {
            let f = (t - t0) / (t1 - t0);
            c = [
                a[0] + (b[0] - a[0]) * f,
                a[1] + (b[1] - a[1]) * f,
                a[2] + (b[2] - a[2]) * f,
            ];
            break;
        }
    }
    Color32::from_rgb(
        (c[0] * 255.0) as u8,
        (c[1] * 255.0) as u8,
        (c[2] * 255.0) as u8,
    )
}

/// The heatmap of `|a − b|` (mean over channels, scaled so that the
/// reference's mean maps to the top of the ramp), the RMSE over all pixels
/// and channels, and the reference's mean.
pub fn error_heatmap(a: &StreamImage, b: &StreamImage) -> (egui::ColorImage, f32, f32) {
    let n = a.mean.len().max(1) as f64;
    let ref_sum: f64 = b.mean.iter().map(|y| (y.element_sum() / 3.0) as f64).sum();
    let rmse = crate::render::stats::rmse(&a.mean, &b.mean) as f32;
    let mean = (ref_sum / n) as f32;
    let scale = if mean > 0.0 { 1.0 / mean } else { 1.0 };
    let pixels = a
        .mean
        .iter()
        .zip(&b.mean)
        .map(|(x, y)| heat(((*x - *y).abs().element_sum() / 3.0) * scale))
        .collect();
    let image = egui::ColorImage {
        size: [a.width as usize, a.height as usize],
        source_size: Vec2::new(a.width as f32, a.height as f32),
        pixels,
    };
    (image, rmse, mean)
}

/// How a drag in the viewport moves the camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NavAction {
    /// Rotate about the target.
    Orbit,
    /// Move eye and target together in the image plane.
    Pan,
    /// Move the eye towards the target.
    Zoom,
    /// Move the sun gizmo.
    Sun,
}

/// Camera navigation and picking state.
#[derive(Clone, Debug, Default)]
pub struct NavState {
    /// The action of the drag in progress.
    pub dragging: Option<NavAction>,
    /// The light shares of the pixel under the cursor…
    pub shares: Vec<(usize, f32)>,
    /// …for this (generation, x, y).
    pub shares_key: Option<(u64, u32, u32)>,
}

/// The world box of the medium as far as the scene says (grids without
/// explicit bounds need the loaded file: see [`Snapshot`]).
pub fn scene_bounds(scene: &Scene) -> Option<(Vec3, Vec3)> {
    use crate::scene::DensitySource;
    match &scene.medium.density {
        DensitySource::Sphere { center, radius } => Some((
            *center - Vec3::splat(*radius),
            *center + Vec3::splat(*radius),
        )),
        DensitySource::Box { min, max } => Some((*min, *max)),
        DensitySource::Cloud(c) => Some((c.center - 0.5 * c.size, c.center + 0.5 * c.size)),
        DensitySource::Grid(g) => g.bounds,
    }
}

/// Moves the camera so that the medium's box fills the view (the F key).
pub fn frame_bounds(camera: &mut Camera, bounds: (Vec3, Vec3), aspect: f32) {
    let (lo, hi) = bounds;
    let center = 0.5 * (lo + hi);
    let radius = (0.5 * (hi - lo).length()).max(1e-3);
    let half_fov = 0.5 * camera.fov_y_deg.to_radians();
    let half_fov = if aspect < 1.0 {
        (half_fov.tan() * aspect).atan()
    } else {
        half_fov
    };
    let distance = radius / half_fov.sin().max(1e-3) * 1.05;
    let dir = (camera.eye - camera.target).normalize_or_zero();
    let dir = if dir == Vec3::ZERO { Vec3::Z } else { dir };
    camera.target = center;
    camera.eye = center + dir * distance;
}

/// Frames the medium of `scene` if its box is known from the scene alone.
pub fn frame_volume(scene: &mut Scene, aspect: f32) {
    if let Some(b) = scene_bounds(scene) {
        frame_bounds(&mut scene.camera, b, aspect);
    }
}

/// What the viewport edits and shows: narrow borrows of the previewer's
/// state.
pub struct ViewportState<'a> {
    /// The edited document (camera, sun).
    pub doc: &'a mut Document,
    /// The persisted session (comparison, split, gizmos, mouse bindings).
    pub session: &'a mut Session,
    /// The displayed image and its texture.
    pub display: &'a Display,
    /// Camera-navigation state.
    pub nav: &'a mut NavState,
    /// The render size in pixels, set here from the viewport's size.
    pub render_size: &'a mut [u32; 2],
    /// Render at this size whatever the viewport's (scripted runs).
    pub forced_render_size: Option<[u32; 2]>,
}

impl ViewportState<'_> {
    /// Width over height of the render.
    pub fn render_aspect(&self) -> f32 {
        self.render_size[0] as f32 / self.render_size[1].max(1) as f32
    }
}

/// The camera frame of the document's camera at the render size.
fn frame_of(app: &ViewportState<'_>) -> CameraFrame {
    let mut cam = app.doc.scene.camera.clone();
    cam.width = app.render_size[0].max(1);
    cam.height = app.render_size[1].max(1);
    cam.frame()
}

/// Draws the viewport and handles its input.
pub fn viewport_ui(ui: &mut Ui, app: &mut ViewportState<'_>) {
    let rect = ui.available_rect_before_wrap();
    let response = ui.allocate_rect(rect, Sense::click_and_drag());
    let ppp = ui.ctx().pixels_per_point();
    let scale = app.session.res_scale.clamp(0.05, 1.0);
    *app.render_size = app.forced_render_size.unwrap_or([
        ((rect.width() * ppp * scale).round() as u32).clamp(8, 8192),
        ((rect.height() * ppp * scale).round() as u32).clamp(8, 8192),
    ]);
    let painter = ui.painter_at(rect);
    // The image keeps its aspect (a scripted render size may differ from
    // the viewport's); everything below maps to this rectangle.
    let outer = rect;
    let rect = fit_rect(outer, app.render_aspect());
    // Only the margins need a background: every covered pixel costs a
    // software rasterizer time on each frame.
    if app.display.snapshot().is_none() || (rect.size() - outer.size()).length() > 1.0 {
        painter.rect_filled(outer, 0.0, Color32::from_gray(16));
    }

    let full_uv = Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0));
    if let Some(id) = app.display.gpu_texture() {
        painter.image(id, rect, full_uv, Color32::WHITE);
    } else if let Some(t) = &app.display.texture {
        if app.session.compare == CompareMode::Split {
            let x = rect.left() + app.session.split.clamp(0.0, 1.0) * rect.width();
            let left = Rect::from_min_max(rect.min, Pos2::new(x, rect.bottom()));
            let uv_left = Rect::from_min_max(Pos2::ZERO, Pos2::new(app.session.split, 1.0));
            painter.image(t.id(), left, uv_left, Color32::WHITE);
            if let Some(r) = &app.display.texture_right {
                let right = Rect::from_min_max(Pos2::new(x, rect.top()), rect.max);
                let uv_right =
                    Rect::from_min_max(Pos2::new(app.session.split, 0.0), Pos2::new(1.0, 1.0));
                painter.image(r.id(), right, uv_right, Color32::WHITE);
            }
        } else {
            painter.image(t.id(), rect, full_uv, Color32::WHITE);
        }
    }

    let frame = frame_of(app);
    let to_screen = |p: Vec3| -> Option<Pos2> {
        frame.project(p).map(|(x, y)| {
            Pos2::new(
                rect.left() + x / frame.width as f32 * rect.width(),
                rect.top() + y / frame.height as f32 * rect.height(),
            )
        })
    };
    let bounds =
        scene_bounds(&app.doc.scene).or_else(|| app.display.snapshot().and_then(|s| s.bounds));

    if app.session.show_box {
        if let Some((lo, hi)) = bounds {
            draw_box(&painter, lo, hi, &to_screen);
        }
    }
    split_divider_ui(ui, app, rect);
    let sun_handle = if app.session.show_sun {
        sun_gizmo(&painter, app, rect, &frame, bounds, &to_screen)
    } else {
        None
    };
    if app.session.show_lights {
        lights_gizmos_ui(ui, app, rect, &frame, &to_screen);
    }
    navigate(ui, app, &response, rect, &frame, bounds, sun_handle);
    overlay_ui(&painter, app, outer);
}

/// The largest rectangle of width/height `aspect` centred in `outer`.
fn fit_rect(outer: Rect, aspect: f32) -> Rect {
    let aspect = aspect.max(1e-3);
    let size = if outer.width() / outer.height().max(1.0) > aspect {
        Vec2::new(outer.height() * aspect, outer.height())
    } else {
        Vec2::new(outer.width(), outer.width() / aspect)
    };
    Rect::from_center_size(outer.center(), size)
}

fn draw_box(painter: &egui::Painter, lo: Vec3, hi: Vec3, to_screen: &dyn Fn(Vec3) -> Option<Pos2>) {
    let corner = |i: usize| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let stroke = Stroke::new(1.0, Color32::from_rgba_unmultiplied(150, 200, 255, 110));
    for a in 0..8usize {
        for bit in [1usize, 2, 4] {
            let b = a | bit;
            if b != a {
                if let (Some(p), Some(q)) = (to_screen(corner(a)), to_screen(corner(b))) {
                    painter.line_segment([p, q], stroke);
                }
            }
        }
    }
}

/// The sun gizmo's globe: a disc in the image's lower-left corner that
/// stands for the sphere of directions seen from the camera; the sun's dot
/// sits where the sun is (hollow when it is behind the medium).
fn sun_globe(rect: Rect) -> (Pos2, f32) {
    let radius = (0.09 * rect.height()).clamp(28.0, 60.0);
    (
        Pos2::new(rect.left() + radius + 14.0, rect.bottom() - radius - 14.0),
        radius,
    )
}

/// The unit direction the first sun shines from.
fn sun_from(lights: &[Light]) -> Option<Vec3> {
    lights.iter().find_map(|l| match l {
        Light::Sun { direction, .. } => Some((-*direction).normalize_or_zero()),
        _ => None,
    })
}

/// Camera axes: right, up, and towards the viewer.
fn camera_axes(frame: &CameraFrame) -> (Vec3, Vec3, Vec3) {
    (
        frame.right_scaled.normalize_or_zero(),
        frame.up_scaled.normalize_or_zero(),
        -frame.forward,
    )
}

fn sun_gizmo(
    painter: &egui::Painter,
    app: &ViewportState<'_>,
    rect: Rect,
    frame: &CameraFrame,
    bounds: Option<(Vec3, Vec3)>,
    to_screen: &dyn Fn(Vec3) -> Option<Pos2>,
) -> Option<Pos2> {
    let from = sun_from(&app.doc.scene.lights)?;
    let yellow = Color32::from_rgb(255, 210, 60);
    // A 3D arrow through the medium's centre: the way the light travels.
    if let Some((lo, hi)) = bounds {
        let center = 0.5 * (lo + hi);
        let length = 0.35 * (hi - lo).length();
        if let (Some(a), Some(b)) = (to_screen(center + from * length), to_screen(center)) {
            painter.arrow(a, b - a, Stroke::new(1.5, yellow.gamma_multiply(0.7)));
        }
    }
    let (c, r) = sun_globe(rect);
    let (right, up, toward) = camera_axes(frame);
    painter.circle(
        c,
        r,
        Color32::from_black_alpha(120),
        Stroke::new(1.0, Color32::from_gray(140)),
    );
    painter.line_segment(
        [c - Vec2::X * r, c + Vec2::X * r],
        Stroke::new(0.5, Color32::from_gray(90)),
    );
    painter.line_segment(
        [c - Vec2::Y * r, c + Vec2::Y * r],
        Stroke::new(0.5, Color32::from_gray(90)),
    );
    let p = c + Vec2::new(from.dot(right), -from.dot(up)) * r;
    if from.dot(toward) >= 0.0 {
        painter.circle(p, 6.0, yellow, Stroke::new(1.0, Color32::BLACK));
    } else {
        painter.circle_stroke(p, 6.0, Stroke::new(2.0, yellow));
    }
    painter.text(
        c + Vec2::new(0.0, r + 2.0),
        egui::Align2::CENTER_TOP,
        "sun",
        egui::FontId::proportional(11.0),
        Color32::from_gray(200),
    );
    Some(p)
}

/// Moves the first sun so that its dot sits under `pos` on the globe,
/// keeping it on the same side (in front of or behind the medium).
fn drag_sun(lights: &mut [Light], frame: &CameraFrame, rect: Rect, pos: Pos2) {
    let Some(old_from) = sun_from(lights) else {
        return;
    };
    let (c, r) = sun_globe(rect);
    let (right, up, toward) = camera_axes(frame);
    let mut v = Vec2::new(pos.x - c.x, c.y - pos.y) / r;
    if v.length() > 1.0 {
        v = v.normalized();
    }
    let z = (1.0 - v.length_sq()).max(0.0).sqrt();
    let z = if old_from.dot(toward) >= 0.0 { z } else { -z };
    let from = (right * v.x + up * v.y + toward * z).normalize_or_zero();
    if from == Vec3::ZERO {
        return;
    }
    if let Some(Light::Sun { direction, .. }) =
        lights.iter_mut().find(|l| matches!(l, Light::Sun { .. }))
    {
        *direction = -from;
    }
}

fn split_divider_ui(ui: &mut Ui, app: &mut ViewportState<'_>, rect: Rect) {
    if app.session.compare != CompareMode::Split {
        return;
    }
    let x = rect.left() + app.session.split.clamp(0.0, 1.0) * rect.width();
    let handle = Rect::from_center_size(
        Pos2::new(x, rect.center().y),
        Vec2::new(12.0, rect.height()),
    );
    let r = ui.interact(handle, ui.scope_id().with("split_divider"), Sense::drag());
    if r.dragged() {
        if let Some(pos) = r.interact_pointer_pos() {
            app.session.split = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 1.0);
        }
    }
    let r = r.on_hover_cursor(egui::CursorIcon::ResizeHorizontal);
    let colour = if r.hovered() || r.dragged() {
        Color32::WHITE
    } else {
        Color32::from_gray(200)
    };
    ui.painter().line_segment(
        [Pos2::new(x, rect.top()), Pos2::new(x, rect.bottom())],
        Stroke::new(2.0, colour),
    );
    let label_at = |x: f32, text: &str, align| {
        ui.painter().text(
            Pos2::new(x, rect.top() + 24.0),
            align,
            text,
            egui::FontId::proportional(13.0),
            Color32::WHITE,
        );
    };
    label_at(x - 8.0, "internal lights", egui::Align2::RIGHT_TOP);
    label_at(x + 8.0, "reference", egui::Align2::LEFT_TOP);
}

/// Most internal lights drawn at once (evenly strided beyond): enough to
/// show where they are, few enough to leave the image readable.
const MAX_DRAWN_LIGHTS: usize = 1500;

fn lights_gizmos_ui(
    ui: &mut Ui,
    app: &mut ViewportState<'_>,
    rect: Rect,
    frame: &CameraFrame,
    to_screen: &dyn Fn(Vec3) -> Option<Pos2>,
) {
    let Some(snapshot) = app.display.snapshot() else {
        return;
    };
    let Some(lights) = snapshot.lights.clone() else {
        return;
    };
    let n = lights.len();
    if n == 0 {
        return;
    }
    let quantity = |i: usize| match app.session.quantity {
        LightQuantity::F => lights.mean_f[i],
        LightQuantity::J => lights.mean_j[i],
    };
    let power: Vec<f32> = (0..n)
        .map(|i| quantity(i).element_sum() / 3.0 * lights.weight(i))
        .collect();
    let max = power.iter().copied().fold(0.0f32, f32::max).max(1e-30);
    let log = app.session.log_strength;
    let norm = |p: f32| {
        if log {
            // Three decades below the strongest light map onto [0, 1].
            ((p / max).max(1e-3).log10() + 3.0) / 3.0
        } else {
            p / max
        }
    };
    let painter = ui.painter_at(rect);
    let hover = ui.ctx().pointer_hover_pos().filter(|p| rect.contains(*p));

    // Which lights to draw: all (strided to a few thousand), or those that
    // light the pixel under the cursor, with their shares.
    let shares: Option<Vec<(usize, f32)>> = if app.session.contributors_only {
        hover.map(|h| {
            let x = ((h.x - rect.left()) / rect.width() * frame.width as f32) as u32;
            let y = ((h.y - rect.top()) / rect.height() * frame.height as f32) as u32;
            let key = (snapshot.generation, x, y);
            if app.nav.shares_key != Some(key) {
                app.nav.shares = snapshot.light_shares(x, y);
                app.nav.shares_key = Some(key);
            }
            app.nav.shares.clone()
        })
    } else {
        None
    };
    let indices: Vec<usize> = match &shares {
        Some(list) => list.iter().map(|(i, _)| *i).filter(|&i| i < n).collect(),
        None => (0..n)
            .step_by(n.div_ceil(MAX_DRAWN_LIGHTS).max(1))
            .collect(),
    };
    let mut nearest: Option<(usize, Pos2, f32)> = None;
    for &i in &indices {
        let Some(p) = to_screen(lights.position(i)) else {
            continue;
        };
        let t = norm(power[i]);
        // Small and translucent, so that the image stays readable.
        painter.circle_filled(p, 1.0 + 3.5 * t, heat(0.25 + 0.75 * t).gamma_multiply(0.6));
        if let Some(h) = hover {
            let d = h.distance(p);
            if d < 8.0 && nearest.is_none_or(|(_, _, best)| d < best) {
                nearest = Some((i, p, d));
            }
        }
    }
    if let Some(list) = &shares {
        // Label the largest shares next to their lights.
        for (i, share) in list.iter().take(12) {
            if let Some(p) = to_screen(lights.position(*i)) {
                painter.circle_stroke(
                    p,
                    3.0 + 12.0 * share.sqrt(),
                    Stroke::new(1.0, Color32::WHITE),
                );
                painter.text(
                    p + Vec2::new(8.0, -8.0),
                    egui::Align2::LEFT_BOTTOM,
                    format!("{:.0} %", share * 100.0),
                    egui::FontId::proportional(11.0),
                    Color32::WHITE,
                );
            }
        }
        if let Some(h) = hover {
            painter.text(
                h + Vec2::new(14.0, 14.0),
                egui::Align2::LEFT_TOP,
                format!("{} lights light this pixel", list.len()),
                egui::FontId::proportional(12.0),
                Color32::WHITE,
            );
        }
    }
    if let Some((i, p, _)) = nearest {
        painter.circle_stroke(p, 9.0, Stroke::new(1.5, Color32::WHITE));
        // The reach s* around the light.
        let depth = (lights.position(i) - frame.eye).dot(frame.forward);
        let focal = 0.5 * rect.height() / frame.up_scaled.length().max(1e-6);
        let reach = lights.reach(i);
        if depth > 0.0 && reach.is_finite() {
            let radius = reach * focal / depth;
            painter.circle_stroke(
                p,
                radius.min(4.0 * rect.width()),
                Stroke::new(1.0, Color32::from_rgba_unmultiplied(255, 220, 120, 160)),
            );
        }
        light_tooltip(ui, &lights, i, frame);
    }
}

/// Position, ρ, V, F and J of light `i`, and a polar glyph of its lobes in
/// the image plane.
fn light_tooltip(ui: &Ui, lights: &LightsView, i: usize, frame: &CameraFrame) {
    let f = lights.mean_f[i];
    let j = lights.mean_j[i];
    let pos = lights.position(i);
    let right = frame.right_scaled.normalize_or_zero();
    let up = frame.up_scaled.normalize_or_zero();
    egui::Tooltip::always_open(
        ui.ctx().clone(),
        ui.layer_id(),
        ui.scope_id().with("light_tip"),
        egui::PopupAnchor::Pointer,
    )
    .show(|ui: &mut Ui| {
        ui.label(egui::RichText::new(format!("internal light {i}")).strong());
        ui.label(format!(
            "position ({:.3}, {:.3}, {:.3})",
            pos.x, pos.y, pos.z
        ));
        ui.label(format!(
            "ρ {:.4}   V {:.4e}",
            lights.density(i),
            lights.weight(i)
        ));
        ui.label(format!("F ({:.3e}, {:.3e}, {:.3e})", f.x, f.y, f.z));
        ui.label(format!("J ({:.3e}, {:.3e}, {:.3e})", j.x, j.y, j.z));
        let unit = if lights.optical_clock() { " mfp" } else { "" };
        ui.label(format!(
            "reach s* {:.3}{unit} (≈ {:.3} world)",
            lights.s_star(),
            lights.reach(i)
        ));
        // The lobes: radiance leaving the light in each direction of the
        // image plane (J white, F orange), normalised to the largest.
        let size = 120.0;
        let (response, painter) = ui.allocate_painter(Vec2::splat(size), Sense::hover());
        let c = response.rect.center();
        const STEPS: usize = 72;
        let samples: Vec<(Vec2, f32, f32)> = (0..STEPS)
            .map(|k| {
                let a = k as f32 / STEPS as f32 * std::f32::consts::TAU;
                let dir = right * a.cos() + up * a.sin();
                let (f, j) = lights.lobe(i, dir);
                let lum = |v: Vec3| (v.element_sum() / 3.0).max(0.0);
                (Vec2::new(a.cos(), -a.sin()), lum(f), lum(j))
            })
            .collect();
        // Each lobe is normalised to its own peak: the glyph shows shapes
        // (F is typically far weaker than J); the numbers above give sizes.
        let peak = |pick: usize| {
            samples
                .iter()
                .map(|s| if pick == 1 { s.1 } else { s.2 })
                .fold(0.0f32, f32::max)
                .max(1e-30)
        };
        painter.circle_stroke(c, 0.45 * size, Stroke::new(0.5, Color32::from_gray(80)));
        for (pick, colour) in [
            (1usize, Color32::from_rgb(255, 160, 60)),
            (2, Color32::WHITE),
        ] {
            let max = peak(pick);
            let points: Vec<Pos2> = samples
                .iter()
                .map(|s| {
                    let v = if pick == 1 { s.1 } else { s.2 };
                    c + s.0 * (0.45 * size * v / max)
                })
                .collect();
            painter.add(egui::Shape::closed_line(points, Stroke::new(1.5, colour)));
        }
        ui.label(
            egui::RichText::new(
                "lobe shapes in the image plane (each to its peak): J white, F orange",
            )
            .small(),
        );
    });
}

/// Camera and sun dragging, wheel zoom and the F key.
fn navigate(
    ui: &mut Ui,
    app: &mut ViewportState<'_>,
    response: &egui::Response,
    rect: Rect,
    frame: &CameraFrame,
    bounds: Option<(Vec3, Vec3)>,
    sun_handle: Option<Pos2>,
) {
    let (modifiers, scroll) = ui.input(|i| (i.modifiers, i.smooth_scroll_delta.y));
    if response.drag_started() {
        let press = response.interact_pointer_pos();
        let near_sun = matches!((press, sun_handle), (Some(a), Some(b)) if a.distance(b) < 14.0);
        let primary = response.dragged_by(egui::PointerButton::Primary);
        let middle = response.dragged_by(egui::PointerButton::Middle);
        let secondary = response.dragged_by(egui::PointerButton::Secondary);
        app.nav.dragging = match app.session.nav {
            _ if primary && near_sun && !modifiers.alt => Some(NavAction::Sun),
            NavPreset::Blender if middle && modifiers.shift => Some(NavAction::Pan),
            NavPreset::Blender if middle && modifiers.command => Some(NavAction::Zoom),
            NavPreset::Blender if middle => Some(NavAction::Orbit),
            NavPreset::AltDrag if modifiers.alt && primary => Some(NavAction::Orbit),
            NavPreset::AltDrag if modifiers.alt && middle => Some(NavAction::Pan),
            NavPreset::AltDrag if modifiers.alt && secondary => Some(NavAction::Zoom),
            _ => None,
        };
    }
    if !response.dragged() {
        app.nav.dragging = None;
    }
    let delta = response.drag_delta();
    let cam = &mut app.doc.scene.camera;
    match app.nav.dragging {
        Some(NavAction::Orbit) => orbit(cam, -delta.x * 0.006, -delta.y * 0.006),
        Some(NavAction::Pan) => pan(cam, delta, rect.height()),
        Some(NavAction::Zoom) => zoom(cam, (delta.x - delta.y) * 0.01),
        Some(NavAction::Sun) => {
            if let Some(pos) = response.interact_pointer_pos() {
                drag_sun(&mut app.doc.scene.lights, frame, rect, pos);
            }
        }
        None => {}
    }
    if response.hovered() && scroll != 0.0 {
        zoom(&mut app.doc.scene.camera, scroll * 0.002);
    }
    let frame_key = response.hovered() && ui.input(|i| i.key_pressed(egui::Key::F));
    if frame_key && !ui.ctx().egui_wants_keyboard_input() {
        if let Some(b) = bounds {
            let aspect = app.render_aspect();
            frame_bounds(&mut app.doc.scene.camera, b, aspect);
        }
    }
}

/// Rotates the eye about the target: `yaw` about the camera's up axis,
/// `pitch` about its right axis, in radians.
pub fn orbit(cam: &mut Camera, yaw: f32, pitch: f32) {
    let up = cam.up.normalize_or_zero();
    let offset = cam.eye - cam.target;
    let yawed = glam::Quat::from_axis_angle(up, yaw) * offset;
    let right = (-yawed).cross(up).normalize_or_zero();
    let pitched = glam::Quat::from_axis_angle(right, pitch) * yawed;
    // Stop short of the poles, where the view would align with up.
    let cos = pitched.normalize_or_zero().dot(up).abs();
    cam.eye = cam.target + if cos < 0.995 { pitched } else { yawed };
}

/// Moves eye and target by a screen-space drag of `delta` points in a
/// viewport `height` points tall.
pub fn pan(cam: &mut Camera, delta: Vec2, height: f32) {
    let forward = (cam.target - cam.eye).normalize_or_zero();
    let right = forward.cross(cam.up).normalize_or_zero();
    let up = right.cross(forward);
    let distance = (cam.target - cam.eye).length();
    let per_point = 2.0 * distance * (0.5 * cam.fov_y_deg.to_radians()).tan() / height.max(1.0);
    let shift = (-delta.x * right + delta.y * up) * per_point;
    cam.eye += shift;
    cam.target += shift;
}

/// Moves the eye towards the target by the factor `exp(-amount)`.
pub fn zoom(cam: &mut Camera, amount: f32) {
    let offset = cam.eye - cam.target;
    let scaled = offset * (-amount).exp();
    if scaled.length() > 1e-3 {
        cam.eye = cam.target + scaled;
    }
}

fn overlay_ui(painter: &egui::Painter, app: &ViewportState<'_>, rect: Rect) {
    let Some(snapshot) = app.display.snapshot() else {
        painter.text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            "rendering…",
            egui::FontId::proportional(16.0),
            Color32::GRAY,
        );
        return;
    };
    let spp = app.display.spp();
    // The passes' spread, scaled where the light sets' shared noise is
    // measured (`LightSetStatus::noise_scale`).
    let noise = snapshot
        .streams
        .iter()
        .map(|s| s.rel_error * s.light_sets.and_then(|l| l.noise_scale).unwrap_or(1.0))
        .fold(0.0f32, f32::max);
    let mut text = if spp == 0 {
        "preview".to_string()
    } else {
        format!("{spp} spp   noise {:.1} %", noise * 100.0)
    };
    if let Some(sets) = snapshot.streams.iter().find_map(|s| s.light_sets) {
        text.push_str(&format!("   {}", sets.label()));
    }
    if snapshot.done {
        text.push_str("   done");
    }
    if let (Some(rmse), Some(mean)) = (app.display.rmse, app.display.reference_mean) {
        let rel = if mean > 0.0 { rmse / mean * 100.0 } else { 0.0 };
        text.push_str(&format!("   RMSE {rmse:.4} ({rel:.1} % of mean)"));
    }
    let at = rect.left_top() + Vec2::new(10.0, 8.0);
    let galley = painter.layout_no_wrap(text, egui::FontId::monospace(13.0), Color32::WHITE);
    let bg = Rect::from_min_size(at - Vec2::splat(4.0), galley.size() + Vec2::new(8.0, 14.0));
    painter.rect_filled(bg, 4.0, Color32::from_black_alpha(150));
    painter.galley(at, galley, Color32::WHITE);
    // Convergence bar: full at 1 % relative noise (log scale from 100 %).
    let converged = if spp == 0 {
        0.0
    } else {
        ((-noise.max(1e-4).log10()) / 2.0).clamp(0.0, 1.0)
    };
    let bar = Rect::from_min_size(
        Pos2::new(bg.left() + 4.0, bg.bottom() - 6.0),
        Vec2::new((bg.width() - 8.0) * converged, 3.0),
    );
    painter.rect_filled(bar, 1.0, Color32::from_rgb(90, 200, 120));
}
