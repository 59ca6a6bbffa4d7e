//! The side panel: the method's four knobs (`s*`, `M`, `g`, `N`) first,
//! then collapsible sections for the medium, the internal lights' finer
//! settings, the external lights, the render and the view ([method §3–§7](crate::doc::method)
//! for what each knob means).
//!
//! Widgets edit the document directly; the frame loop notices the change,
//! restarts the render and records the undo step.

use std::path::Path;
use std::sync::Arc;

use eframe::egui::{self, Slider, Ui};
use egui_plot::{Bar, BarChart, Plot};
use glam::Vec3;

use super::sky::{SkyState, SkyUi};
use super::state::{CompareMode, Document, LightQuantity, NavPreset, Session, Toast};
use super::widgets::rgb_intensity_ui;
use crate::physics::internal::clock::RESOLVED_TERMS;
use crate::physics::internal::sources::{walk_split, PHASE_WALKS_MIN_G};
use crate::physics::sh::MAX_ORDER;
use crate::render::tonemap::ViewTransform;
use crate::scene::settings::MAX_TERMS;
use crate::scene::{Clock, L1Form, Quality};
use crate::scene::{Light, Method};
use crate::session::{Backend, LightsView};

/// Label of the window-length slider (tests find widgets by label).
pub const S_STAR: &str = "s* (window)";
/// Label of the number-of-lights slider.
pub const LIGHTS: &str = "M (internal lights)";
/// Label of the phase-function slider.
pub const PHASE_G: &str = "g (phase)";
/// Label of the series-truncation slider.
pub const TERMS: &str = "N (series terms)";
/// Label of the exposure slider.
pub const EXPOSURE: &str = "exposure (stops)";
/// Label of the GPU backend's button.
pub const BACKEND_GPU: &str = "GPU";
/// Label of the CPU backend's button.
pub const BACKEND_CPU: &str = "CPU";

/// Label of the quality-preset menu.
pub const QUALITY: &str = "quality";
/// Title of the section of the method's finer settings.
pub const EXPERT: &str = "Expert: walks, lobes and kernel";

/// Label of the density-scale slider.
pub const DENSITY_SCALE: &str = "density scale";

/// What the side panel edits and shows: narrow borrows of the previewer's
/// state, and the few figures it displays.
pub struct ControlsState<'a> {
    /// The edited document.
    pub doc: &'a mut Document,
    /// The persisted session (view, comparison, backend choice).
    pub session: &'a mut Session,
    /// The Sky section's own state.
    pub sky: &'a mut SkyUi,
    /// The folder that the scene's relative paths refer to.
    pub scene_dir: &'a Path,
    /// The scene's file, if it has one.
    pub path: Option<&'a Path>,
    /// Notifications.
    pub toasts: &'a mut Vec<Toast>,
    /// Whether the user was told that the GPU is unavailable since they
    /// last chose it (cleared when the backend choice changes).
    pub gpu_notice_shown: &'a mut bool,
    /// Where the image is rendered, in words.
    pub backend_status: String,
    /// The backend that rendered the image on screen.
    pub active_backend: Backend,
    /// The internal lights on screen, for the series-term plot.
    pub lights: Option<Arc<LightsView>>,
    /// Slider-to-screen latencies measured, in milliseconds.
    pub presented_ms: &'a [f64],
    /// The viewport's render size in pixels.
    pub render_size: [u32; 2],
}

impl ControlsState<'_> {
    /// The Sky section's part of the state.
    fn sky_state(&mut self) -> SkyState<'_> {
        SkyState {
            doc: self.doc,
            sky: self.sky,
            scene_dir: self.scene_dir,
            path: self.path,
            toasts: self.toasts,
        }
    }
}

/// Draws the whole panel.
pub fn panel_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    egui::ScrollArea::vertical().show(ui, |ui| {
        ui.heading("Internal lights");
        method_knobs_ui(ui, app);
        ui.add_space(6.0);
        egui::CollapsingHeader::new("Medium")
            .default_open(false)
            .show(ui, |ui| medium_ui(ui, app));
        egui::CollapsingHeader::new(EXPERT)
            .default_open(false)
            .show(ui, |ui| internal_detail_ui(ui, app));
        egui::CollapsingHeader::new("Lights")
            .default_open(false)
            .show(ui, |ui| lights_ui(ui, app));
        egui::CollapsingHeader::new(super::sky::SECTION)
            .default_open(false)
            .show(ui, |ui| super::sky::sky_ui(ui, &mut app.sky_state()));
        egui::CollapsingHeader::new("Render")
            .default_open(true)
            .show(ui, |ui| render_ui(ui, app));
        egui::CollapsingHeader::new("View and gizmos")
            .default_open(true)
            .show(ui, |ui| view_ui(ui, app));
        egui::CollapsingHeader::new("Series terms")
            .default_open(false)
            .show(ui, |ui| terms_plot_ui(ui, app));
    });
}

/// An optional positive value: "auto" or a logarithmic slider.
fn optional_log_ui(
    ui: &mut Ui,
    label: &str,
    value: &mut Option<f32>,
    range: std::ops::RangeInclusive<f32>,
    fallback: f32,
    tip: &str,
) {
    ui.horizontal(|ui| {
        let mut auto = value.is_none();
        if ui
            .checkbox(&mut auto, format!("auto {label}"))
            .on_hover_text(tip)
            .changed()
        {
            *value = if auto { None } else { Some(fallback) };
        }
        if let Some(v) = value {
            ui.add(Slider::new(v, range).logarithmic(true).text(label))
                .on_hover_text(tip);
        }
    });
}

fn method_knobs_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    let internal = &mut app.doc.scene.render.internal;
    optional_log_ui(
        ui,
        S_STAR,
        &mut internal.knobs.s_star,
        0.01..=100.0,
        1.0,
        "Window length s*: the path length after which multiply scattered light \
         becomes an internal light. Short: the final gather is nearly exact \
         single scattering but many series terms are needed; long: fewer terms, \
         but two or more scatterings inside the window are lost (darker, \
         flatter interiors). Units: mean free paths with the optical-depth \
         clock, world units with the geometric one. Auto: half a mean free \
         path.",
    );
    ui.add(
        Slider::new(&mut internal.knobs.lights, 16..=262_144)
            .logarithmic(true)
            .text(LIGHTS),
    )
    .on_hover_text(
        "Number of internal lights M placed in the medium. More lights: smoother \
         glow, less blotchy noise, slower re-sampling. Physically they are point \
         samples of the in-flight light J, placed with probability ∝ density.",
    );
    ui.add(Slider::new(&mut app.doc.scene.medium.g, -0.95..=0.95).text(PHASE_G))
        .on_hover_text(
            "Henyey–Greenstein asymmetry g. Positive: light keeps going forward \
             (bright silver lining when looking towards the sun, darker backlit \
             side); 0: isotropic; negative: back-scattering. Mean cosine of the \
             scattering angle.",
        );
    ui.add(
        Slider::new(&mut internal.knobs.terms, 0..=MAX_TERMS)
            .logarithmic(true)
            .text(TERMS),
    )
    .on_hover_text(
        "Series truncation N: terms k = 0..N of J = Σ G(k s*) S₁. Too few and light \
         that travels longer than (N+1)·s* is lost (a thick cloud's lit body goes \
         dark); the plot of term energies shows when more terms stop adding light. \
         The default, 4096 windows, lets the walks run until they end on their own.",
    );
    let mut quality = internal.quality;
    egui::ComboBox::from_label(QUALITY)
        .selected_text(quality.name())
        .show_ui(ui, |ui| {
            for q in Quality::ALL {
                ui.selectable_value(&mut quality, q, q.name());
            }
        })
        .response
        .on_hover_text(
            "Preset of the expert settings below. Final: what the accuracy figures \
             are measured with. Preview: light sets about four times faster for \
             live edits, noisier passes. Choosing one replaces the expert \
             settings; s*, M and N keep their values.",
        );
    if quality != internal.quality {
        // The preset's expert settings; the knobs stay as they are.
        internal.quality = quality;
        internal.expert = quality.settings().expert;
    }
}

fn medium_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    let m = &mut app.doc.scene.medium;
    ui.add(
        Slider::new(&mut m.density_scale, 0.01..=100.0)
            .logarithmic(true)
            .text(DENSITY_SCALE),
    )
    .on_hover_text(
        "Multiplies the density everywhere: the cloud's overall thickness. Higher: \
         more opaque, brighter edges and darker core; extinction scales linearly.",
    );
    ui.label("σ_t (extinction per unit density, RGB)")
        .on_hover_text(
            "Extinction cross-section per unit density, per channel, in 1/world \
             units. Unequal channels tint the light that goes deep (e.g. more red \
             extinction leaves blue-green cores).",
        );
    ui.horizontal(|ui| {
        for (c, name) in ["σ_t R", "σ_t G", "σ_t B"].iter().enumerate() {
            ui.add(
                egui::DragValue::new(&mut m.sigma_t[c])
                    .speed(0.05)
                    .range(0.0..=10_000.0)
                    .prefix(format!("{} ", &name[4..])),
            )
            .on_hover_text(*name);
        }
    });
    ui.horizontal(|ui| {
        let mut rgb = [m.albedo.x, m.albedo.y, m.albedo.z];
        if ui
            .color_edit_button_rgb(&mut rgb)
            .on_hover_text(
                "Single-scattering albedo α (linear RGB): the fraction of extinction \
                 that scatters rather than absorbs. Near 1: white, glowing clouds; \
                 lower: dark smoke. Multiple scattering is very sensitive to it.",
            )
            .changed()
        {
            m.albedo = Vec3::from(rgb).clamp(Vec3::ZERO, Vec3::ONE);
        }
        ui.label("albedo");
    });
    let mut grey = m.albedo.max_element();
    if ui
        .add(Slider::new(&mut grey, 0.0..=1.0).text("albedo (all channels)"))
        .on_hover_text("Sets the albedo of all channels at once.")
        .changed()
    {
        m.albedo = Vec3::splat(grey);
    }
}

fn internal_detail_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    let s = &mut app.doc.scene.render.internal;
    ui.add(
        Slider::new(&mut s.expert.walks, 1..=4096)
            .logarithmic(true)
            .text("K (walks per light)"),
    )
    .on_hover_text(
        "Time-gated random walks per internal light K. More walks: less flicker \
         between lights, slower re-sampling. Each walk estimates all N+1 terms of \
         J at the light without bias.",
    );
    ui.add(Slider::new(&mut s.expert.sh_order, 0..=MAX_ORDER).text("SH order"))
        .on_hover_text(
            "Spherical-harmonic order of each light's angular lobe. 0: every light \
             glows the same in all directions; higher orders keep the forward peak \
             of J for strongly forward phase functions (costs memory, can ring).",
        );
    optional_log_ui(
        ui,
        "h (kernel radius)",
        &mut s.expert.kernel_radius,
        0.001..=10.0,
        0.05,
        "Kernel radius h that spreads each light's J along camera rays. Small: \
         sharp, blotchy glowing spots; large: smooth but blurred glow (bias). \
         Auto: the mean spacing of the lights.",
    );
    ui.add(Slider::new(&mut s.expert.uniform_mix, 0.0..=1.0).text("u (uniform mix)"))
        .on_hover_text(
            "Fraction u of lights placed uniformly in the box rather than by \
             density. Raise it when light in flight through gaps between puffs \
             (J in empty space) goes missing.",
        );
    egui::ComboBox::from_label("clock")
        .selected_text(match s.expert.clock {
            Clock::Geometric => "geometric",
            Clock::OpticalDepth => "optical depth",
        })
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut s.expert.clock, Clock::OpticalDepth, "optical depth");
            ui.selectable_value(&mut s.expert.clock, Clock::Geometric, "geometric");
        })
        .response
        .on_hover_text(
            "What the path-length clock counts. Optical depth: s* in mean free \
             paths, so every window holds about s* collisions in thin and thick \
             parts alike. Geometric: s* is a distance, as in Tessendorf's note.",
        );
    egui::ComboBox::from_label("L₁ form")
        .selected_text(match s.expert.l1 {
            L1Form::Field => "field",
            L1Form::Points => "point lights",
        })
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut s.expert.l1, L1Form::Field, "field");
            ui.selectable_value(&mut s.expert.l1, L1Form::Points, "point lights");
        })
        .response
        .on_hover_text(
            "How the last scattering inside the window is gathered. Field: from the \
             smooth J reconstructed around the lights (no softening, least bias). \
             Point lights: from each internal light as a softened point source, as \
             in Tessendorf's note; sparkles near lights and darkens dense media at \
             small s*.",
        );
    let most = crate::physics::internal::sources::MAX_WINDOW_SCATTERS;
    ui.add(Slider::new(&mut s.expert.window_scatters, 1..=most).text("window scatterings"))
        .on_hover_text(
            "Scatterings inside the final window s* that the field L₁ follows. 1: \
             Tessendorf's single-scatter kernel, which misses light scattered twice \
             or more within s* (the image darker by about that share in dense \
             media). 2 and 3: the next terms, for longer passes; on the puffs at \
             s* 0.5 two took the bias from 4.7 % to 1.9 %.",
        );
    ui.add(Slider::new(&mut s.expert.view_walks, 0..=64).text("view walks"))
        .on_hover_text(
            "Walks per light towards the camera. The camera sees the multiply \
             scattered light in one direction; walks aimed there estimate it with \
             far less noise than the spherical harmonics of the spread walks (on \
             the puffs 16 of them cut the light sets' noise about fourfold). 0: \
             the harmonics, as in Tessendorf's note. With view walks, moving the \
             camera re-samples the lights.",
        );
    let (walks, view_walks) =
        walk_split(s.expert.walks, s.expert.view_walks, app.doc.scene.medium.g);
    if (walks, view_walks) != (s.expert.walks, s.expert.view_walks) {
        ui.label(format!(
            "|g| ≥ {PHASE_WALKS_MIN_G}: phase walks serve L₁, so each light walks \
             {walks} spread and {view_walks} towards the camera"
        ))
        .on_hover_text(
            "Where the phase function's peak is sharp the image reads no spherical \
             harmonics; the spread walks feed only F, the energies and the gizmos, \
             and three quarters of their time goes to walks towards the camera.",
        );
    }
    ui.add(Slider::new(&mut s.expert.view_share, 0.0..=1.0).text("lights in view"))
        .on_hover_text(
            "Share of the lights placed where the camera reads them: in the first \
             s* of each camera ray inside the medium. The rest are placed by \
             density, as in Tessendorf's note, and give the series' energies. In \
             thick clouds almost no density-placed light stands in that skin, and \
             the image goes dark and blotchy without this. Moving the camera \
             re-samples the lights.",
        );
    ui.add(Slider::new(&mut s.expert.light_samples, 1..=64).text("light samples"))
        .on_hover_text(
            "Internal lights gathered per camera sample. More: less noise per pass, \
             slower passes.",
        );
    ui.add(
        Slider::new(&mut s.expert.resample_every, 0..=1024)
            .logarithmic(true)
            .text("renew lights every"),
    )
    .on_hover_text(
        "Passes rendered with one set of internal lights before a fresh set \
         (the next seed) replaces it, the image keeping what it has \
         accumulated. 0: one set for the whole render, whose walk noise (the \
         blotches that K controls) stays in the image however long it refines; \
         renewed sets average it out, at the cost of their walks. The gizmos \
         show the first set.",
    );
}

fn lights_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    let lights = &mut app.doc.scene.lights;
    let mut remove = None;
    for (i, light) in lights.iter_mut().enumerate() {
        ui.push_id(i, |ui| match light {
            Light::Sun {
                direction,
                irradiance,
            } => {
                ui.label(egui::RichText::new("Sun").strong());
                sun_direction_ui(ui, direction);
                rgb_intensity_ui(
                    ui,
                    irradiance,
                    "sun irradiance",
                    "Irradiance of the sun in W/m² on a surface facing it (colour × \
                     strength). Brightens everything linearly.",
                    LIGHT_STRENGTH_MAX,
                );
            }
            Light::Point {
                position,
                intensity,
            } => {
                ui.horizontal(|ui| {
                    ui.label(egui::RichText::new("Point light").strong());
                    if ui.small_button("remove").clicked() {
                        remove = Some(i);
                    }
                });
                ui.horizontal(|ui| {
                    for c in 0..3 {
                        ui.add(egui::DragValue::new(&mut position[c]).speed(0.01))
                            .on_hover_text("Position of the point light (world units).");
                    }
                });
                rgb_intensity_ui(
                    ui,
                    intensity,
                    "point intensity",
                    "Intensity in W/sr (colour × strength); falls off as 1/r².",
                    LIGHT_STRENGTH_MAX,
                );
            }
        });
        ui.separator();
    }
    if let Some(i) = remove {
        lights.remove(i);
    }
    if ui.button("Add point light").clicked() {
        lights.push(Light::Point {
            position: Vec3::new(0.0, 0.0, 0.0),
            intensity: Vec3::splat(1.0),
        });
    }
}

/// Elevation and azimuth of the direction the sun shines *from*.
fn sun_direction_ui(ui: &mut Ui, direction: &mut Vec3) {
    let from = (-*direction).normalize_or_zero();
    let mut elevation = from.y.clamp(-1.0, 1.0).asin().to_degrees();
    let mut azimuth = from.x.atan2(from.z).to_degrees();
    let tip = "Where the sun is: elevation above the horizon and azimuth around the \
               vertical. Drag the sun gizmo in the viewport for the same.";
    let a = ui
        .add(Slider::new(&mut elevation, -89.0..=89.0).text("sun elevation (°)"))
        .on_hover_text(tip);
    let b = ui
        .add(Slider::new(&mut azimuth, -180.0..=180.0).text("sun azimuth (°)"))
        .on_hover_text(tip);
    if a.changed() || b.changed() {
        let (el, az) = (elevation.to_radians(), azimuth.to_radians());
        *direction = -Vec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    }
}

/// The largest strength the sun's and the point lights' sliders reach.
const LIGHT_STRENGTH_MAX: f32 = 1000.0;

/// The backend switch and a line saying where the image is rendered.
fn backend_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    ui.horizontal(|ui| {
        ui.label("backend");
        let before = app.session.backend;
        ui.selectable_value(&mut app.session.backend, Backend::Gpu, BACKEND_GPU)
            .on_hover_text(
                "Render with wgpu compute shaders on the window's device; the \
                 image stays on the GPU. Falls back to the CPU where there is no \
                 GPU or the scene does not fit.",
            );
        ui.selectable_value(&mut app.session.backend, Backend::Cpu, BACKEND_CPU)
            .on_hover_text("Render with the CPU renderers.");
        if app.session.backend != before {
            *app.gpu_notice_shown = false;
        }
    });
    let status = app.backend_status.clone();
    let fallback = app.session.backend == Backend::Gpu && app.active_backend == Backend::Cpu;
    let text = egui::RichText::new(status).small();
    ui.label(if fallback {
        text.color(ui.visuals().warn_fg_color)
    } else {
        text.weak()
    });
}

fn render_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    backend_ui(ui, app);
    let session = &mut app.session;
    ui.horizontal_wrapped(|ui| {
        for (mode, name, tip) in [
            (
                CompareMode::Internal,
                "Internal lights",
                "The internal-lights approximation.",
            ),
            (
                CompareMode::Reference,
                "Reference",
                "The unbiased path tracer: the ground truth.",
            ),
            (
                CompareMode::Split,
                "Split",
                "Internal lights left, reference right; drag the divider.",
            ),
            (
                CompareMode::Error,
                "Error",
                "Heatmap of |internal − reference| with its RMSE (the reference's \
                 own noise is included and shrinks as it refines).",
            ),
        ] {
            if ui
                .selectable_value(&mut session.compare, mode, name)
                .on_hover_text(tip)
                .clicked()
            {
                // The scene's own method follows the single-image modes.
                match mode {
                    CompareMode::Internal => app.doc.scene.render.method = Method::Internal,
                    CompareMode::Reference => app.doc.scene.render.method = Method::Reference,
                    _ => {}
                }
            }
        }
    });
    ui.add(Slider::new(&mut session.res_scale, 0.1..=1.0).text("resolution scale"))
        .on_hover_text(
            "Render resolution relative to the viewport's pixels. Lower: faster \
         feedback, blurrier image.",
        );
    ui.add(
        Slider::new(&mut session.max_spp, 1..=65_536)
            .logarithmic(true)
            .text("max spp"),
    )
    .on_hover_text("The image stops refining at this many samples per pixel.");
    ui.horizontal(|ui| {
        ui.add(egui::DragValue::new(&mut app.doc.scene.render.seed).prefix("seed "))
            .on_hover_text(
                "Seed of every random stream: the same seed gives the same image \
                 and the same internal lights.",
            );
    });
}

fn view_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    let s = &mut app.session;
    ui.add(Slider::new(&mut s.exposure, -10.0..=10.0).text(EXPOSURE))
        .on_hover_text("Display exposure: multiplies the shown image by 2^stops. Display only.");
    egui::ComboBox::from_label("view transform")
        .selected_text(match s.view {
            ViewTransform::Filmic => "filmic",
            ViewTransform::Clamp => "sRGB clamp",
        })
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut s.view, ViewTransform::Filmic, "filmic");
            ui.selectable_value(&mut s.view, ViewTransform::Clamp, "sRGB clamp");
        })
        .response
        .on_hover_text(
            "Filmic rolls highlights off smoothly (ACES fit); sRGB clamp clips \
             linear values above 1. Display and PNG only; EXR stays linear.",
        );
    egui::ComboBox::from_label("mouse")
        .selected_text(match s.nav {
            NavPreset::Blender => "Blender",
            NavPreset::AltDrag => "Maya / Houdini (Alt-drag)",
        })
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut s.nav, NavPreset::Blender, "Blender");
            ui.selectable_value(&mut s.nav, NavPreset::AltDrag, "Maya / Houdini (Alt-drag)");
        })
        .response
        .on_hover_text(
            "Blender: middle-drag orbits, Shift+middle pans, Ctrl+middle or wheel \
             zooms. Maya/Houdini: Alt+left orbits, Alt+middle pans, Alt+right \
             zooms. F frames the volume.",
        );
    ui.checkbox(&mut s.show_box, "medium box");
    ui.checkbox(&mut s.show_sun, "sun gizmo");
    ui.checkbox(&mut s.show_lights, "internal lights");
    ui.horizontal(|ui| {
        ui.selectable_value(&mut s.quantity, LightQuantity::F, "F")
            .on_hover_text("Size and colour the lights by F = G(s*) S₁, the first gated term.");
        ui.selectable_value(&mut s.quantity, LightQuantity::J, "J")
            .on_hover_text("Size and colour the lights by J, the whole series.");
        ui.checkbox(&mut s.log_strength, "log scale");
    });
    ui.checkbox(
        &mut s.contributors_only,
        "only lights lighting the cursor's pixel",
    )
    .on_hover_text(
        "Shows only the internal lights that contribute to the pixel under the \
             cursor, with their shares.",
    );
    if !app.presented_ms.is_empty() {
        ui.label(
            egui::RichText::new(
                super::state::latency_report(app.presented_ms, app.render_size, "on screen")
                    .trim_start_matches("lantern: ")
                    .to_string(),
            )
            .small()
            .weak(),
        );
    }
}

fn terms_plot_ui(ui: &mut Ui, app: &mut ControlsState<'_>) {
    let Some(lights) = app.lights.clone() else {
        ui.label("The energy of each series term appears once internal lights are sampled.");
        return;
    };
    let grey = |e: &Vec3| e.dot(Vec3::splat(1.0 / 3.0)) as f64;
    let energy = lights.term_energy();
    // Past `RESOLVED_TERMS` the last element sums the remaining terms: it
    // is said in words, not drawn as one more term.
    let folded = lights.terms() > RESOLVED_TERMS;
    let (resolved, tail) = match energy.split_last() {
        Some((last, rest)) if folded => (rest, Some(grey(last))),
        _ => (energy, None),
    };
    let bars: Vec<Bar> = resolved
        .iter()
        .enumerate()
        .map(|(k, e)| Bar::new(k as f64, grey(e)))
        .collect();
    if let Some(tail) = tail {
        let total: f64 = energy.iter().map(grey).sum();
        let share = if total > 0.0 {
            100.0 * tail / total
        } else {
            0.0
        };
        ui.label(format!(
            "terms {RESOLVED_TERMS}–{}: {share:.2} % of the energy (not drawn)",
            lights.terms()
        ));
    }
    Plot::new("term_energy")
        .height(140.0)
        .x_axis_label("term k")
        .y_axis_label("energy")
        .show(ui, |plot| {
            plot.bar_chart(BarChart::new("energy of term k", bars))
        });
}
