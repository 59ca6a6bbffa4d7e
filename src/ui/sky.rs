//! The side panel's Sky section: the scene's environment light
//! ([`crate::scene::Environment`]) — none, a constant radiance, a
//! latitude–longitude map or a clear sky that follows the first sun — and
//! whether the camera sees it as the background.
//!
//! Like the other sections, the widgets edit the document directly, so the
//! frame loop records each edit as one undo step and marks the scene
//! unsaved. A map chosen with the file dialog or dropped on the window is
//! read on a background thread first: only a map that loads becomes the
//! sky (rotation 0, scale 1, as one edit); a bad one is reported with the
//! loader's error and the scene stays as it was.
//!
//! A map or a clear sky is previewed as a small latitude–longitude
//! thumbnail in the world's frame (rotation applied), with the first sun's
//! direction circled. The sky is read or baked off the UI thread, once per
//! change of its source; the thumbnail itself is re-drawn from it only
//! when the sky's settings change.
//!
//! The thumbnail's convention is the renderer's
//! ([`crate::physics::environment`]): pixel `(u, v)` (`u` across from the
//! left, `v` down from the top, both in `[0, 1]`) looks towards
//! `(sin 2πu sin θ, cos θ, −cos 2πu sin θ)` with `θ = πv`, so +y is at the
//! top, the centre column looks along +z, the column a quarter of the
//! width from the left edge along +x and the edges along −z.

use std::path::{Component, Path, PathBuf};
use std::sync::mpsc::{self, Receiver};
use std::time::Duration;

use eframe::egui::{self, Color32, Pos2, Rect, Sense, Slider, Stroke, TextureHandle, Ui, Vec2};
use glam::Vec3;

use super::state::{Document, Toast};
use crate::render::export::extension;
use crate::render::tonemap::{to_srgb8, ViewTransform};
use crate::scene::environment::{load_sky_map, map_direction};
use crate::scene::{Environment, LoadedSky, Scene, Sky, SkyMap};

/// Title of the section.
pub const SECTION: &str = "Sky";
/// Label of the choice of no sky.
pub const NONE: &str = "None";
/// Label of the choice of a constant sky.
pub const CONSTANT: &str = "Constant";
/// Label of the choice of a map.
pub const MAP: &str = "Map";
/// Label of the choice of a clear sky.
pub const CLEAR_SKY: &str = "Clear sky";
/// Label of the background checkbox.
pub const BACKGROUND: &str = "draw the sky as the background";
/// Label of the constant sky's strength slider.
pub const RADIANCE: &str = "sky radiance";
/// Label of the map's rotation slider.
pub const ROTATION: &str = "rotation about up (°)";
/// Label of the map's scale slider.
pub const MAP_SCALE: &str = "map intensity";
/// Label of the clear sky's turbidity slider.
pub const TURBIDITY: &str = "turbidity";
/// Label of the clear sky's scale slider.
pub const CLEAR_SCALE: &str = "sky intensity";
/// Label of the button that opens the map file dialog.
pub const CHOOSE_MAP: &str = "Choose map…";

/// Size of the sky thumbnail in texels (2:1, latitude–longitude).
pub const THUMBNAIL: [u32; 2] = [128, 64];

/// Where a thumbnail's sky comes from: what has to be read or baked again
/// when it changes.
#[derive(Clone, Debug, PartialEq)]
enum Source {
    Map { file: PathBuf, dir: PathBuf },
    Clear { turbidity: f32, sun: Option<Vec3> },
}

/// A loaded sky with the source it came from.
type LoadResult = (Source, Result<LoadedSky, String>);

/// The thumbnail of the current sky and the sky it is drawn from.
#[derive(Default)]
struct Thumbnail {
    /// The source of `loaded`, and what reading or baking it gave.
    loaded: Option<LoadResult>,
    /// A source being read or baked on a background thread.
    pending: Option<Receiver<LoadResult>>,
    /// The texture and the settings it was drawn with.
    texture: Option<(Sky, TextureHandle)>,
}

/// State of the Sky section that is not part of the document: the map
/// being read after a drop or a pick, the thumbnail, and the settings of
/// the kinds of sky not chosen now (so that switching back restores them).
#[derive(Default)]
pub struct SkyUi {
    /// A map being read before it becomes the sky: its path and the result.
    pending_map: Option<(PathBuf, Receiver<Result<(), String>>)>,
    /// "Map" chosen without a map yet, with the environment it was chosen
    /// from: the file button is shown and the document is unchanged. Any
    /// other change of the environment (undo, another scene) ends it.
    choosing_map: Option<Option<Environment>>,
    last_constant: Option<Vec3>,
    last_map: Option<Sky>,
    last_clear: Option<Sky>,
    thumbnail: Thumbnail,
}

impl SkyUi {
    /// Whether a map is being read before it becomes the sky.
    pub fn is_loading_map(&self) -> bool {
        self.pending_map.is_some()
    }

    /// Whether a thumbnail has been drawn, and the settings it shows.
    pub fn thumbnail_of(&self) -> Option<&Sky> {
        self.thumbnail.texture.as_ref().map(|(s, _)| s)
    }
}

/// Whether a dropped file is a sky map (`.exr` or `.hdr`).
pub fn is_sky_map(path: &Path) -> bool {
    matches!(extension(path).as_deref(), Some("exr" | "hdr"))
}

/// What the Sky section edits: narrow borrows of the previewer's state.
pub struct SkyState<'a> {
    /// The edited document (its environment).
    pub doc: &'a mut Document,
    /// The section's own state (map being read, last choices, thumbnail).
    pub sky: &'a mut SkyUi,
    /// The folder that the scene's relative paths refer to.
    pub scene_dir: &'a Path,
    /// The scene's file, if it has one (for messages).
    pub path: Option<&'a Path>,
    /// Notifications.
    pub toasts: &'a mut Vec<Toast>,
}

impl SkyState<'_> {
    /// Shows an information message.
    pub fn notify(&mut self, text: impl Into<String>) {
        super::state::notify(self.toasts, text);
    }

    /// Shows an error message.
    pub fn notify_error(&mut self, text: impl Into<String>) {
        super::state::notify_error(self.toasts, text);
    }
}

/// Starts reading the map at `path` on a background thread; once it loads
/// it becomes the sky (rotation 0, scale 1) as one undoable edit
/// ([`poll`]), otherwise the loader's error is shown.
pub fn open_map(app: &mut SkyState<'_>, path: &Path) {
    let (tx, rx) = mpsc::channel();
    let file = path.to_owned();
    let spawned = std::thread::Builder::new()
        .name("lantern-sky-map".into())
        .spawn(move || {
            let result = load_sky_map(&file)
                .map(|_| ())
                .map_err(|e| format!("{:#}", anyhow::Error::from(e)));
            let _ = tx.send(result);
        });
    match spawned {
        Ok(_) => app.sky.pending_map = Some((path.to_owned(), rx)),
        Err(e) => app.notify_error(format!("cannot read {}: {e}", path.display())),
    }
}

/// Applies a map that finished loading (or reports why it did not); called
/// once per frame.
pub fn poll(app: &mut SkyState<'_>, ctx: &egui::Context) {
    let Some((path, rx)) = &app.sky.pending_map else {
        return;
    };
    let result = match rx.try_recv() {
        Ok(r) => r,
        Err(mpsc::TryRecvError::Empty) => {
            ctx.request_repaint_after(Duration::from_millis(20));
            return;
        }
        Err(mpsc::TryRecvError::Disconnected) => Err(format!(
            "{}: the map reader stopped unexpectedly",
            path.display()
        )),
    };
    let path = path.clone();
    app.sky.pending_map = None;
    match result {
        Ok(()) => {
            let file = relative_path(&path, app.scene_dir);
            set_sky(
                app,
                Sky::Map {
                    file,
                    rotation_deg: 0.0,
                    scale: 1.0,
                },
            );
            app.sky.choosing_map = None;
            app.notify(format!("sky map: {}", path.display()));
        }
        Err(e) => app.notify_error(format!("sky map not used: {e}")),
    }
}

/// Sets the sky, keeping the background setting.
fn set_sky(app: &mut SkyState<'_>, sky: Sky) {
    let background = app
        .doc
        .scene
        .environment
        .as_ref()
        .is_some_and(|e| e.background);
    app.doc.scene.environment = Some(Environment { sky, background });
}

/// Which kind of sky is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    None,
    Constant,
    Map,
    Clear,
}

fn kind_of(env: &Option<Environment>) -> Kind {
    match env.as_ref().map(|e| &e.sky) {
        None => Kind::None,
        Some(Sky::Constant { .. }) => Kind::Constant,
        Some(Sky::Map { .. }) => Kind::Map,
        Some(Sky::ClearSky { .. }) => Kind::Clear,
    }
}

/// The error the scene loader gives for a clear sky in this scene (it has
/// no sun), if any.
fn clear_sky_error(app: &SkyState<'_>) -> Option<String> {
    let env = Environment {
        sky: Sky::ClearSky {
            turbidity: 3.0,
            scale: 1.0,
        },
        background: false,
    };
    let name = app
        .path
        .map_or_else(|| PathBuf::from("the scene"), Path::to_path_buf);
    env.validate(&name, app.doc.scene.first_sun())
        .err()
        .map(|e| format!("{:#}", anyhow::Error::from(e)))
}

/// Draws the section.
pub fn sky_ui(ui: &mut Ui, app: &mut SkyState<'_>) {
    let current = kind_of(&app.doc.scene.environment);
    if app
        .sky
        .choosing_map
        .as_ref()
        .is_some_and(|from| *from != app.doc.scene.environment)
    {
        app.sky.choosing_map = None;
    }
    let choosing = app.sky.choosing_map.is_some();
    let shown = if current != Kind::Map && choosing {
        Kind::Map
    } else {
        current
    };
    let no_sun = clear_sky_error(app);
    let mut chosen = shown;
    ui.horizontal_wrapped(|ui| {
        ui.selectable_value(&mut chosen, Kind::None, NONE)
            .on_hover_text("No sky: only the sun and point lights light the medium.");
        ui.selectable_value(&mut chosen, Kind::Constant, CONSTANT)
            .on_hover_text("The same radiance from every direction (Mitsuba's constant).");
        ui.selectable_value(&mut chosen, Kind::Map, MAP)
            .on_hover_text(
                "A latitude–longitude HDR map (.exr or .hdr, 2:1), turned about the up \
             axis (Mitsuba's envmap). Dropping such a file on the window sets it.",
            );
        let clear_tip = match &no_sun {
            Some(e) => format!("Needs a sun: {e}"),
            None => "A clear daylight sky (Preetham et al. 1999) that follows the \
                     scene's first sun."
                .to_string(),
        };
        ui.add_enabled_ui(no_sun.is_none() || current == Kind::Clear, |ui| {
            ui.selectable_value(&mut chosen, Kind::Clear, CLEAR_SKY)
                .on_hover_text(clear_tip.as_str())
                .on_disabled_hover_text(clear_tip.as_str());
        });
    });
    if chosen != shown {
        choose(app, current, chosen);
    }
    if let (Some(e), false) = (&no_sun, current == Kind::Clear) {
        ui.label(
            egui::RichText::new(format!("A clear sky needs a sun: {e}"))
                .small()
                .weak(),
        );
    }

    if app.sky.choosing_map.is_some() && current != Kind::Map {
        // Nothing changes until a map is chosen and loads.
        map_file_ui(ui, app, None);
    } else {
        match app.doc.scene.environment.as_ref().map(|e| e.sky.clone()) {
            Some(Sky::Constant { mut radiance }) => {
                radiance_ui(ui, &mut radiance);
                if let Some(Environment {
                    sky: Sky::Constant { radiance: r },
                    ..
                }) = &mut app.doc.scene.environment
                {
                    *r = radiance;
                }
            }
            Some(Sky::Map { .. }) => map_ui(ui, app),
            Some(Sky::ClearSky { .. }) => clear_ui(ui, app, no_sun.as_deref()),
            None => {}
        }
    }
    if let Some(env) = &mut app.doc.scene.environment {
        ui.checkbox(&mut env.background, BACKGROUND).on_hover_text(
            "Camera rays that leave the medium see the sky behind it (through \
             the medium's transmittance), as Mitsuba does without hide_emitters. \
             Off: the background is black and the sky only lights the medium.",
        );
    }
    thumbnail_ui(ui, app);
}

/// Switches the kind of sky, remembering the settings of the one left.
fn choose(app: &mut SkyState<'_>, current: Kind, chosen: Kind) {
    if let Some(env) = &app.doc.scene.environment {
        match &env.sky {
            Sky::Constant { radiance } => app.sky.last_constant = Some(*radiance),
            s @ Sky::Map { .. } => app.sky.last_map = Some(s.clone()),
            s @ Sky::ClearSky { .. } => app.sky.last_clear = Some(s.clone()),
        }
    }
    app.sky.choosing_map = None;
    match chosen {
        Kind::None => app.doc.scene.environment = None,
        Kind::Constant => {
            let radiance = app.sky.last_constant.unwrap_or(Vec3::splat(0.5));
            set_sky(app, Sky::Constant { radiance });
        }
        Kind::Map => match app.sky.last_map.clone() {
            Some(map) => set_sky(app, map),
            // Nothing changes until a map is chosen and loads.
            None => {
                if current != Kind::Map {
                    app.sky.choosing_map = Some(app.doc.scene.environment.clone());
                }
            }
        },
        Kind::Clear => {
            let sky = app.sky.last_clear.clone().unwrap_or(Sky::ClearSky {
                turbidity: 3.0,
                scale: 1.0,
            });
            set_sky(app, sky);
        }
    }
}

/// The constant sky's radiance as a colour and a logarithmic strength.
fn radiance_ui(ui: &mut Ui, value: &mut Vec3) {
    super::widgets::rgb_intensity_ui(
        ui,
        value,
        RADIANCE,
        "Radiance of the sky in W/m²/sr (colour × strength), the same from \
         every direction. A sky of radiance L gives a horizontal surface an \
         irradiance of πL from above.",
        100.0,
    );
}

/// The map's file line: the path and the button that opens the dialog.
fn map_file_ui(ui: &mut Ui, app: &mut SkyState<'_>, file: Option<&Path>) {
    ui.horizontal_wrapped(|ui| {
        let busy = app.sky.is_loading_map();
        if ui
            .add_enabled(!busy, egui::Button::new(CHOOSE_MAP))
            .on_hover_text("Opens an .exr or .hdr latitude–longitude map.")
            .clicked()
        {
            let picked = rfd::FileDialog::new()
                .add_filter("HDR sky maps", &["exr", "hdr"])
                .pick_file();
            if let Some(path) = picked {
                open_map(app, &path);
            }
        }
        if busy {
            ui.spinner();
        }
        match file {
            Some(f) => ui.label(egui::RichText::new(f.display().to_string()).monospace()),
            None => ui.label(
                egui::RichText::new("no map yet: choose one or drop an .exr/.hdr file").weak(),
            ),
        };
    });
}

fn map_ui(ui: &mut Ui, app: &mut SkyState<'_>) {
    let Some(Environment {
        sky:
            Sky::Map {
                file,
                mut rotation_deg,
                mut scale,
            },
        ..
    }) = app.doc.scene.environment.clone()
    else {
        return;
    };
    map_file_ui(ui, app, Some(&file));
    ui.add(Slider::new(&mut rotation_deg, -180.0..=180.0).text(ROTATION))
        .on_hover_text(
            "Turns the map about the up axis (+y), right-handed, as Mitsuba's \
             to_world = rotate([0, 1, 0], angle).",
        );
    ui.add(
        Slider::new(&mut scale, 0.0..=100.0)
            .logarithmic(true)
            .text(MAP_SCALE),
    )
    .on_hover_text("Multiplies every texel of the map.");
    if let Some(Environment {
        sky: Sky::Map {
            rotation_deg: r,
            scale: s,
            ..
        },
        ..
    }) = &mut app.doc.scene.environment
    {
        (*r, *s) = (rotation_deg, scale);
    }
}

fn clear_ui(ui: &mut Ui, app: &mut SkyState<'_>, no_sun: Option<&str>) {
    let Some(Environment {
        sky: Sky::ClearSky {
            mut turbidity,
            mut scale,
        },
        ..
    }) = app.doc.scene.environment.clone()
    else {
        return;
    };
    match no_sun {
        Some(e) => {
            ui.colored_label(ui.visuals().error_fg_color, e);
        }
        None => {
            ui.label(
                egui::RichText::new(
                    "Follows the scene's first sun: move the sun (Lights) and the sky moves.",
                )
                .small()
                .weak(),
            );
        }
    }
    ui.add(Slider::new(&mut turbidity, 1.7..=10.0).text(TURBIDITY))
        .on_hover_text(
            "Haze of the atmosphere: 1.7 very clear, 10 hazy (whiter, brighter horizon).",
        );
    ui.add(
        Slider::new(&mut scale, 0.0..=100.0)
            .logarithmic(true)
            .text(CLEAR_SCALE),
    )
    .on_hover_text(
        "Multiplies the model's radiance; at 1 a horizontal surface gets about a \
         fifth of the light of a sun of irradiance 3 at 45°.",
    );
    if let Some(Environment {
        sky: Sky::ClearSky {
            turbidity: t,
            scale: s,
        },
        ..
    }) = &mut app.doc.scene.environment
    {
        (*t, *s) = (turbidity, scale);
    }
}

/// The source of the current sky's thumbnail, if it has one.
fn source(app: &SkyState<'_>) -> Option<Source> {
    match app.doc.scene.environment.as_ref().map(|e| &e.sky)? {
        Sky::Constant { .. } => None,
        Sky::Map { file, .. } => Some(Source::Map {
            file: file.clone(),
            dir: app.scene_dir.to_path_buf(),
        }),
        Sky::ClearSky { turbidity, .. } => Some(Source::Clear {
            turbidity: *turbidity,
            sun: app.doc.scene.first_sun(),
        }),
    }
}

/// Reads the map or bakes the clear sky of `source` on a thread.
fn load_in_background(source: Source) -> Option<Receiver<LoadResult>> {
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("lantern-sky-preview".into())
        .spawn(move || {
            let (sky, dir, sun) = match &source {
                Source::Map { file, dir } => (
                    Sky::Map {
                        file: file.clone(),
                        rotation_deg: 0.0,
                        scale: 1.0,
                    },
                    dir.clone(),
                    None,
                ),
                Source::Clear { turbidity, sun } => (
                    Sky::ClearSky {
                        turbidity: *turbidity,
                        scale: 1.0,
                    },
                    PathBuf::new(),
                    *sun,
                ),
            };
            let env = Environment {
                sky,
                background: false,
            };
            let loaded = env
                .load(&dir, sun)
                .map_err(|e| format!("{:#}", anyhow::Error::from(e)));
            let _ = tx.send((source, loaded));
        })
        .ok()?;
    Some(rx)
}

/// The thumbnail with the sun circled, or the loader's error.
fn thumbnail_ui(ui: &mut Ui, app: &mut SkyState<'_>) {
    let Some(wanted) = source(app) else {
        return;
    };
    let ctx = ui.ctx().clone();
    let thumb = &mut app.sky.thumbnail;
    if let Some(rx) = &thumb.pending {
        match rx.try_recv() {
            Ok(result) => {
                thumb.loaded = Some(result);
                thumb.pending = None;
                thumb.texture = None;
            }
            Err(mpsc::TryRecvError::Empty) => {
                ctx.request_repaint_after(Duration::from_millis(30));
            }
            Err(mpsc::TryRecvError::Disconnected) => thumb.pending = None,
        }
    }
    let stale = thumb.loaded.as_ref().is_none_or(|(s, _)| *s != wanted);
    if stale && thumb.pending.is_none() {
        thumb.pending = load_in_background(wanted.clone());
        ctx.request_repaint_after(Duration::from_millis(30));
    }
    let Some((source, loaded)) = &thumb.loaded else {
        ui.spinner();
        return;
    };
    let loaded = match loaded {
        Ok(l) => l,
        Err(e) => {
            if *source == wanted {
                ui.colored_label(ui.visuals().error_fg_color, e.as_str());
            }
            return;
        }
    };
    let Some(sky) = app.doc.scene.environment.as_ref().map(|e| e.sky.clone()) else {
        return;
    };
    // The thumbnail shows the sky in the world's frame: the map turned by
    // its rotation (a clear sky is baked in the world's frame already).
    let rotation = match &sky {
        Sky::Map { rotation_deg, .. } => *rotation_deg,
        _ => 0.0,
    };
    let redraw = thumb.texture.as_ref().is_none_or(|(s, _)| *s != sky);
    if redraw {
        let pixels = match loaded {
            LoadedSky::Map { map, .. } => thumbnail_pixels(map, rotation, THUMBNAIL),
            LoadedSky::Constant(c) => vec![*c; (THUMBNAIL[0] * THUMBNAIL[1]) as usize],
        };
        let image = egui::ColorImage::from_rgb(
            [THUMBNAIL[0] as usize, THUMBNAIL[1] as usize],
            &thumbnail_srgb(&pixels),
        );
        let options = egui::TextureOptions::LINEAR;
        match &mut thumb.texture {
            Some((s, t)) => {
                t.set(image, options);
                *s = sky.clone();
            }
            None => {
                thumb.texture = Some((sky.clone(), ctx.load_texture("lantern-sky", image, options)))
            }
        }
    }
    let Some((_, texture)) = &thumb.texture else {
        return;
    };
    let width = ui.available_width().clamp(64.0, 256.0);
    let (rect, response) = ui.allocate_exact_size(Vec2::new(width, width / 2.0), Sense::hover());
    let painter = ui.painter_at(rect);
    painter.image(
        texture.id(),
        rect,
        Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
        Color32::WHITE,
    );
    // The horizon.
    painter.line_segment(
        [rect.left_center(), rect.right_center()],
        Stroke::new(1.0, Color32::from_white_alpha(60)),
    );
    let sun = app.doc.scene.first_sun();
    if let Some([u, v]) = sun.and_then(sun_marker_uv) {
        let at = rect.min + Vec2::new(u * rect.width(), v * rect.height());
        painter.circle_stroke(at, 5.0, Stroke::new(3.0, Color32::from_black_alpha(160)));
        painter.circle_stroke(at, 5.0, Stroke::new(1.5, Color32::YELLOW));
    }
    let mut tip = "The sky in the world's frame, latitude–longitude: up at the top, +z in \
                   the middle, +x a quarter of the width from the left edge, −z at the \
                   edges."
        .to_string();
    if sun.is_some() {
        tip.push_str(" The circle is the scene's first sun.");
    }
    response.on_hover_text(tip.as_str());
}

/// The map coordinates `[u, v]` (`u` across from the left, in `[0, 1)`;
/// `v` down from the top, in `[0, 1]`) that look towards world direction
/// `d`, for a map without rotation; the inverse of
/// [`crate::scene::environment::map_direction`].
pub fn direction_to_uv(d: Vec3) -> [f32; 2] {
    let d = d.normalize_or(Vec3::Y);
    let mut u = d.x.atan2(-d.z) / std::f32::consts::TAU;
    u -= u.floor();
    if u >= 1.0 {
        u = 0.0;
    }
    [u, d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI]
}

/// Where the thumbnail marks a sun whose light travels along `sun_travel`
/// (the scene's [`Light::Sun`](crate::scene::Light::Sun) direction): the
/// thumbnail coordinates of the direction towards the sun. `None` for a
/// zero direction.
pub fn sun_marker_uv(sun_travel: Vec3) -> Option<[f32; 2]> {
    let to_sun = -sun_travel;
    (to_sun.length_squared() > 0.0 && to_sun.is_finite()).then(|| direction_to_uv(to_sun))
}

/// The radiance of `map` turned by `rotation_deg` about +y towards world
/// direction `from`: the renderer's lookup (texel `i` at
/// `u = (i + ½)/W`, row `j` at `v = j/(H − 1)`, bilinear, wrapping
/// across the seam), without its sampling tables.
pub fn map_radiance(map: &SkyMap, rotation_deg: f32, from: Vec3) -> Vec3 {
    let (w, h) = (map.width.max(1) as usize, map.height.max(2) as usize);
    if map.texels.len() < w * h {
        return Vec3::ZERO;
    }
    let (s, c) = rotation_deg.to_radians().sin_cos();
    // World to the map's frame: the inverse of the rotation about +y.
    let local = Vec3::new(c * from.x - s * from.z, from.y, s * from.x + c * from.z);
    let [u, v] = direction_to_uv(local);
    let mut u = u - 0.5 / w as f32;
    u -= u.floor();
    let x = (u * w as f32).min(w as f32);
    let y = v * (h - 1) as f32;
    let ix = (x as usize).min(w - 1);
    let iy = (y as usize).min(h - 2);
    let (fx, fy) = (x - ix as f32, y - iy as f32);
    let at = |i: usize, j: usize| map.texels[j * w + i % w];
    let top = at(ix, iy) * (1.0 - fx) + at(ix + 1, iy) * fx;
    let bottom = at(ix, iy + 1) * (1.0 - fx) + at(ix + 1, iy + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// The linear radiance of a `size[0] × size[1]` thumbnail of `map` turned
/// by `rotation_deg`, row-major from the top: pixel `(x, y)` shows the
/// direction at `u = (x + ½)/W`, `v = (y + ½)/H` in the world's frame.
pub fn thumbnail_pixels(map: &SkyMap, rotation_deg: f32, size: [u32; 2]) -> Vec<Vec3> {
    let (w, h) = (size[0].max(1), size[1].max(1));
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h {
        let v = (y as f32 + 0.5) / h as f32;
        for x in 0..w {
            let u = (x as f32 + 0.5) / w as f32;
            out.push(map_radiance(map, rotation_deg, map_direction(u, v)));
        }
    }
    out
}

/// 8-bit sRGB of thumbnail pixels, exposed so that their mean luminance
/// sits at mid grey, through the filmic view transform.
pub fn thumbnail_srgb(pixels: &[Vec3]) -> Vec<u8> {
    let luminance = Vec3::new(0.2126, 0.7152, 0.0722);
    let mean =
        pixels.iter().map(|p| p.dot(luminance) as f64).sum::<f64>() / pixels.len().max(1) as f64;
    let exposure = if mean > 0.0 && mean.is_finite() {
        (0.25 / mean).log2() as f32
    } else {
        0.0
    };
    to_srgb8(pixels, exposure, ViewTransform::Filmic)
}

/// `path` as seen from the folder `base`: relative (with `..` where
/// needed) when the two share more than the file system's root, else
/// absolute. Both are made absolute first (resolving links where they
/// exist).
pub fn relative_path(path: &Path, base: &Path) -> PathBuf {
    let absolute = |p: &Path| {
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            if p.is_absolute() {
                p.to_owned()
            } else {
                std::env::current_dir()
                    .map(|d| d.join(p))
                    .unwrap_or_else(|_| p.to_owned())
            }
        })
    };
    let (path, base) = (absolute(path), absolute(base));
    let (p, b): (Vec<Component>, Vec<Component>) =
        (path.components().collect(), base.components().collect());
    let common = p.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let only_root = p
        .iter()
        .take(common)
        .all(|c| matches!(c, Component::RootDir | Component::Prefix(_)));
    if common == 0 || only_root {
        return path;
    }
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &p[common..] {
        out.push(c.as_os_str());
    }
    out
}

/// The scene as it is written to `target`: a map's path (relative to
/// `scene_dir`, the folder the document's paths refer to, or absolute)
/// made relative to the folder of `target` where possible.
pub fn scene_for_saving(scene: &Scene, scene_dir: &Path, target: &Path) -> Scene {
    let mut scene = scene.clone();
    if let Some(Environment {
        sky: Sky::Map { file, .. },
        ..
    }) = &mut scene.environment
    {
        let folder = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        *file = relative_path(&scene_dir.join(&*file), folder);
    }
    scene
}
