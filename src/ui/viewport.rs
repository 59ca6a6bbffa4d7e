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

use super::app::{CompareMode, LanternApp, LightQuantity, NavPreset, Session};
use super::backend::{Estimator, LightsView, Snapshot, StreamImage};
use crate::render::tonemap::to_srgb8;
use crate::scene::{Camera, CameraFrame, Light, Scene};

/// The image on screen: the snapshot it was made from and its textures.
#[derive(Default)]
pub struct Display {
    snapshot: Option<Arc<Snapshot>>,
    /// The main image (the left one in the split view).
    texture: Option<TextureHandle>,
    /// The right image of the split view.
    texture_right: Option<TextureHandle>,
    /// What the textures were made with.
    made_with: Option<(f32, crate::render::tonemap::ViewTransform, CompareMode)>,
    /// Root-mean-square error of internal lights against the reference.
    pub rmse: Option<f32>,
    /// Mean of the reference image (to state the RMSE relatively).
    pub reference_mean: Option<f32>,
}

impl Display {
    /// Re-makes the textures if the snapshot or the display settings
    /// changed; returns whether it did.
    pub fn update(&mut self, ctx: &egui::Context, snapshot: Arc<Snapshot>, s: &Session) -> bool {
        let key = (s.exposure, s.view, s.compare);
        let same_snapshot = self
            .snapshot
            .as_ref()
            .is_some_and(|old| Arc::ptr_eq(old, &snapshot));
        if same_snapshot && self.made_with == Some(key) {
            return false;
        }
        let find = |e: Estimator| snapshot.streams.iter().find(|st| st.estimator == e);
        let first = snapshot.streams.first();
        let (left, right) = match s.compare {
            CompareMode::Internal => (find(Estimator::Internal).or(first), None),
            CompareMode::Reference => (find(Estimator::Reference).or(first), None),
            CompareMode::Split => (
                find(Estimator::Internal).or(first),
                find(Estimator::Reference),
            ),
            CompareMode::Error => (None, None),
        };
        self.rmse = None;
        self.reference_mean = None;
        let image = if s.compare == CompareMode::Error {
            match (find(Estimator::Internal), find(Estimator::Reference)) {
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
    pub fn shown_estimator(&self, mode: CompareMode) -> Estimator {
        match mode {
            CompareMode::Reference => Estimator::Reference,
            _ => Estimator::Internal,
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
    let mut sq = 0.0f64;
    let mut ref_sum = 0.0f64;
    for (x, y) in a.mean.iter().zip(&b.mean) {
        let d = *x - *y;
        sq += (d.length_squared() / 3.0) as f64;
        ref_sum += (y.element_sum() / 3.0) as f64;
    }
    let rmse = (sq / n).sqrt() as f32;
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

/// Camera navigation state.
#[derive(Clone, Debug, Default)]
pub struct NavState {
    /// The action of the drag in progress.
    pub dragging: Option<NavAction>,
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

/// The camera frame of the document's camera at the render size.
fn frame_of(app: &LanternApp) -> CameraFrame {
    let mut cam = app.doc.scene.camera.clone();
    cam.width = app.render_size[0].max(1);
    cam.height = app.render_size[1].max(1);
    cam.frame()
}

/// Draws the viewport and handles its input.
pub fn viewport_ui(ui: &mut Ui, app: &mut LanternApp) {
    let rect = ui.available_rect_before_wrap();
    let response = ui.allocate_rect(rect, Sense::click_and_drag());
    let ppp = ui.ctx().pixels_per_point();
    let scale = app.session.res_scale.clamp(0.05, 1.0);
    app.render_size = [
        ((rect.width() * ppp * scale).round() as u32).clamp(8, 8192),
        ((rect.height() * ppp * scale).round() as u32).clamp(8, 8192),
    ];
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_gray(16));

    let full_uv = Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0));
    if let Some(t) = &app.display.texture {
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
        bounds.and_then(|b| sun_gizmo(&painter, app, b, &to_screen))
    } else {
        None
    };
    if app.session.show_lights {
        lights_gizmos_ui(ui, app, rect, &to_screen);
    }
    navigate(ui, app, &response, rect, &frame, bounds, sun_handle);
    overlay_ui(&painter, app, rect);
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

/// World position of the sun handle: on a sphere around the box, on the
/// side the sun shines from.
fn sun_handle_world(direction: Vec3, bounds: (Vec3, Vec3)) -> (Vec3, Vec3, f32) {
    let center = 0.5 * (bounds.0 + bounds.1);
    let radius = 0.6 * (bounds.1 - bounds.0).length().max(1e-3);
    (
        center - direction.normalize_or_zero() * radius,
        center,
        radius,
    )
}

fn sun_gizmo(
    painter: &egui::Painter,
    app: &LanternApp,
    bounds: (Vec3, Vec3),
    to_screen: &dyn Fn(Vec3) -> Option<Pos2>,
) -> Option<Pos2> {
    let direction = app.doc.scene.lights.iter().find_map(|l| match l {
        Light::Sun { direction, .. } => Some(*direction),
        _ => None,
    })?;
    let (handle, center, _) = sun_handle_world(direction, bounds);
    let p = to_screen(handle)?;
    let yellow = Color32::from_rgb(255, 210, 60);
    if let Some(c) = to_screen(center) {
        // The direction light travels: from the handle towards the medium.
        let d = (c - p).normalized() * 28.0;
        painter.arrow(p, d, Stroke::new(2.0, yellow));
    }
    painter.circle(p, 7.0, yellow, Stroke::new(1.5, Color32::BLACK));
    for k in 0..8 {
        let a = k as f32 * std::f32::consts::TAU / 8.0;
        let v = Vec2::new(a.cos(), a.sin());
        painter.line_segment([p + v * 9.0, p + v * 13.0], Stroke::new(1.5, yellow));
    }
    Some(p)
}

fn split_divider_ui(ui: &mut Ui, app: &mut LanternApp, rect: Rect) {
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

fn lights_gizmos_ui(
    ui: &mut Ui,
    app: &LanternApp,
    rect: Rect,
    to_screen: &dyn Fn(Vec3) -> Option<Pos2>,
) {
    let Some(lights) = app.display.lights() else {
        return;
    };
    let n = lights.positions.len();
    if n == 0 {
        return;
    }
    let quantity = |i: usize| match app.session.quantity {
        LightQuantity::F => lights.mean_f[i],
        LightQuantity::J => lights.mean_j[i],
    };
    let power: Vec<f32> = (0..n)
        .map(|i| quantity(i).element_sum() / 3.0 * lights.weight[i])
        .collect();
    let max = power.iter().copied().fold(0.0f32, f32::max).max(1e-30);
    let norm = |p: f32| {
        if app.session.log_strength {
            // Three decades below the strongest light map onto [0, 1].
            ((p / max).max(1e-3).log10() + 3.0) / 3.0
        } else {
            p / max
        }
    };
    // Draw at most a few thousand (evenly strided) to stay interactive.
    let stride = n.div_ceil(4096).max(1);
    let painter = ui.painter_at(rect);
    let hover = ui.ctx().pointer_hover_pos().filter(|p| rect.contains(*p));
    let mut nearest: Option<(usize, Pos2, f32)> = None;
    for i in (0..n).step_by(stride) {
        let Some(p) = to_screen(lights.positions[i]) else {
            continue;
        };
        let t = norm(power[i]);
        let radius = 1.5 + 5.0 * t;
        painter.circle_filled(p, radius, heat(0.25 + 0.75 * t));
        if let Some(h) = hover {
            let d = h.distance(p);
            if d < 8.0 && nearest.is_none_or(|(_, _, best)| d < best) {
                nearest = Some((i, p, d));
            }
        }
    }
    if let Some((i, p, _)) = nearest {
        painter.circle_stroke(p, 9.0, Stroke::new(1.5, Color32::WHITE));
        let f = lights.mean_f[i];
        let j = lights.mean_j[i];
        let pos = lights.positions[i];
        egui::Tooltip::always_open(
            ui.ctx().clone(),
            ui.layer_id(),
            ui.scope_id().with("light_tip"),
            egui::PopupAnchor::Pointer,
        )
        .show(|ui: &mut Ui| {
            ui.label(format!("internal light {i}"));
            ui.label(format!(
                "position ({:.3}, {:.3}, {:.3})",
                pos.x, pos.y, pos.z
            ));
            ui.label(format!(
                "ρ {:.4}   V {:.4e}",
                lights.density[i], lights.weight[i]
            ));
            ui.label(format!("F ({:.3e}, {:.3e}, {:.3e})", f.x, f.y, f.z));
            ui.label(format!("J ({:.3e}, {:.3e}, {:.3e})", j.x, j.y, j.z));
        });
    }
}

/// Camera and sun dragging, wheel zoom and the F key.
fn navigate(
    ui: &mut Ui,
    app: &mut LanternApp,
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
            if let (Some(pos), Some(b)) = (response.interact_pointer_pos(), bounds) {
                let px = (pos.x - rect.left()) / rect.width() * frame.width as f32;
                let py = (pos.y - rect.top()) / rect.height() * frame.height as f32;
                drag_sun(&mut app.doc.scene.lights, frame, px, py, b);
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

/// Points the first sun so that its handle sits under render pixel
/// (`px`, `py`).
fn drag_sun(lights: &mut [Light], frame: &CameraFrame, px: f32, py: f32, b: (Vec3, Vec3)) {
    let Some(Light::Sun { direction, .. }) =
        lights.iter_mut().find(|l| matches!(l, Light::Sun { .. }))
    else {
        return;
    };
    let (_, center, radius) = sun_handle_world(*direction, b);
    let ray = frame.ray_dir(px, py);
    let oc = frame.eye - center;
    // Nearest hit of the ray with the handle sphere, or the closest point.
    let bq = oc.dot(ray);
    let disc = bq * bq - (oc.length_squared() - radius * radius);
    let point = if disc >= 0.0 {
        frame.eye + ray * (-bq - disc.sqrt())
    } else {
        frame.eye + ray * (-bq)
    };
    let from = (point - center).normalize_or_zero();
    if from != Vec3::ZERO {
        *direction = -from;
    }
}

fn overlay_ui(painter: &egui::Painter, app: &LanternApp, rect: Rect) {
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
    let noise = snapshot
        .streams
        .iter()
        .map(|s| s.rel_error)
        .fold(0.0f32, f32::max);
    let mut text = if spp == 0 {
        "preview".to_string()
    } else {
        format!("{spp} spp   noise {:.1} %", noise * 100.0)
    };
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
