//! Files: opening and saving scenes (RON) with native dialogs, drag and drop
//! of scenes and volumes, recent files, the example scenes as presets, and
//! export of the still frame (32-bit float EXR with the render settings as
//! metadata and optional layers, or display-transformed PNG).
//!
//! Loading runs on a background thread and is validated completely (the
//! density is read too) before the current scene is replaced, so a bad file
//! only produces a notification. Saving and export write whole files or
//! nothing ([`crate::atomic`]): a failure leaves the previous file and
//! says so in a notification.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver};

use eframe::egui;
use glam::Vec3;

use super::state::{notify, notify_error, Document, Session, Toast};
use super::viewport::Display;
use crate::atomic::write_atomically;
use crate::render::export::{extension, write_png_bytes};
use crate::render::tonemap::to_srgb8;
use crate::render::PreparedScene;
use crate::scene::{DensitySource, GridFormat, GridSource, Method, Scene};
use crate::session::Snapshot;

/// Largest number of recent files remembered.
const RECENT_LIMIT: usize = 10;

/// The example scenes, built in so that they work from any folder; grids
/// are looked up in the source tree's `assets/scenes`.
pub const PRESETS: &[(&str, &str)] = &[
    (
        "Cumulus cloud",
        include_str!("../../assets/scenes/cloud.ron"),
    ),
    (
        "Thin sphere",
        include_str!("../../assets/scenes/thin_sphere.ron"),
    ),
    (
        "Chromatic sphere",
        include_str!("../../assets/scenes/chromatic_sphere.ron"),
    ),
    (
        "Puffs (voxel grid)",
        include_str!("../../assets/scenes/puffs_grid.ron"),
    ),
    (
        "Smoke box (point light)",
        include_str!("../../assets/scenes/smoke_box.ron"),
    ),
];

/// The folder the presets' relative paths refer to.
pub fn presets_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/assets/scenes"))
}

/// The scene shown before anything is opened: the cumulus preset.
pub fn default_scene() -> Scene {
    Scene::from_ron(PRESETS[0].1, Path::new("cloud.ron")).unwrap_or_default()
}

/// A successfully loaded file.
#[derive(Clone, Debug)]
pub struct Loaded {
    /// The file opened.
    pub path: PathBuf,
    /// The resulting scene.
    pub scene: Scene,
    /// The folder that the scene's relative paths refer to.
    pub scene_dir: PathBuf,
    /// A scene file (as opposed to a volume wrapped in the current scene).
    pub is_scene_file: bool,
    /// The medium's world box.
    pub bounds: (Vec3, Vec3),
    /// What makes the picture meaningless or the work very long
    /// ([`crate::render::limits::warnings`]), shown as notifications.
    pub warnings: Vec<String>,
}

/// Whether a dropped file is something the previewer opens.
pub fn is_openable(path: &Path) -> bool {
    matches!(extension(path).as_deref(), Some("ron" | "vdb" | "vol"))
}

/// Loads a scene file, or wraps a `.vdb`/`.vol` volume in `current`, and
/// checks that its density loads.
pub fn load(path: &Path, current: &Scene) -> Result<Loaded, String> {
    let dir = path
        .parent()
        .map(Path::to_owned)
        .unwrap_or_else(|| PathBuf::from("."));
    let (scene, is_scene_file) = match extension(path).as_deref() {
        Some("ron") => (Scene::load(path).map_err(|e| format!("{e:#}"))?, true),
        Some("vdb" | "vol") => {
            let mut scene = current.clone();
            // Absolute, so that the scene still finds it wherever it is saved.
            let absolute = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned());
            scene.medium.density = DensitySource::Grid(GridSource {
                path: absolute,
                format: GridFormat::Auto,
                grid_name: None,
                bounds: None,
            });
            (scene, false)
        }
        _ => {
            return Err(format!(
                "{}: not a scene (.ron) or a volume (.vdb, .vol)",
                path.display()
            ))
        }
    };
    let density = scene
        .load_density(&dir)
        .map_err(|e| format!("cannot open {}: {e:#}", path.display()))?;
    let sky = scene
        .load_environment(&dir)
        .map_err(|e| format!("cannot open {}: {e:#}", path.display()))?;
    let bounds = density.bounds();
    let prepared = PreparedScene::with_loaded(scene.clone(), density, sky);
    let warnings = crate::render::limits::warnings(&prepared, &scene.render)
        .into_iter()
        .map(|w| format!("{}: {w}", path.display()))
        .collect();
    Ok(Loaded {
        path: path.to_owned(),
        scene,
        scene_dir: dir,
        is_scene_file,
        bounds,
        warnings,
    })
}

/// [`load`] on a background thread.
pub fn load_in_background(path: PathBuf, current: Scene) -> Receiver<Result<Loaded, String>> {
    let (tx, rx) = mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("lantern-load".into())
        .spawn(move || {
            let _ = tx.send(load(&path, &current));
        });
    if spawned.is_err() {
        // The receiver then reports a disconnected loader.
    }
    rx
}

/// Moves `path` to the front of the recent list.
pub fn push_recent(recent: &mut Vec<PathBuf>, path: &Path) {
    let path = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned());
    recent.retain(|p| *p != path);
    recent.insert(0, path);
    recent.truncate(RECENT_LIMIT);
}

/// What the File menu or a file dialog asks the application to do.
#[derive(Clone, Debug, PartialEq)]
pub enum FileRequest {
    /// Load this scene or volume (in the background).
    Open(PathBuf),
    /// Save the document to this file.
    Save(PathBuf),
    /// Replace the document with this example scene (name, RON text).
    Preset(&'static str, &'static str),
}

/// What the File menu reads and edits: narrow borrows of the previewer's
/// state.
pub struct FileMenuState<'a> {
    /// The edited document (for the export's metadata).
    pub doc: &'a Document,
    /// The persisted session (recent files, export options, display).
    pub session: &'a mut Session,
    /// The displayed image.
    pub display: &'a Display,
    /// Where the document was read from or last saved to.
    pub path: Option<&'a Path>,
    /// Notifications.
    pub toasts: &'a mut Vec<Toast>,
}

/// Asks for a scene or volume to open.
pub fn open_dialog() -> Option<FileRequest> {
    rfd::FileDialog::new()
        .add_filter("Scenes and volumes", &["ron", "vdb", "vol"])
        .pick_file()
        .map(FileRequest::Open)
}

/// Where to save the scene: to its file `path`, or (`save_as`, or no file
/// yet) where the user says.
pub fn save_dialog(path: Option<&Path>, save_as: bool) -> Option<FileRequest> {
    let target = match (path, save_as) {
        (Some(p), false) => Some(p.to_path_buf()),
        _ => rfd::FileDialog::new()
            .add_filter("Lantern scene", &["ron"])
            .set_file_name("scene.ron")
            .save_file(),
    };
    target.map(FileRequest::Save)
}

/// The File menu; returns what it asks the application to do.
pub fn file_menu_ui(ui: &mut egui::Ui, state: &mut FileMenuState<'_>) -> Option<FileRequest> {
    let mut request = None;
    if ui.button("Open…").clicked() {
        ui.close();
        request = open_dialog();
    }
    if ui.button("Save").clicked() {
        ui.close();
        request = save_dialog(state.path, false);
    }
    if ui.button("Save as…").clicked() {
        ui.close();
        request = save_dialog(state.path, true);
    }
    ui.menu_button("Open recent", |ui| {
        if state.session.recent.is_empty() {
            ui.label("(none)");
        }
        let mut chosen = None;
        for p in &state.session.recent {
            if ui.button(p.display().to_string()).clicked() {
                chosen = Some(p.clone());
            }
        }
        if let Some(p) = chosen {
            ui.close();
            request = Some(FileRequest::Open(p));
        }
    });
    ui.menu_button("Example scenes", |ui| {
        for (name, text) in PRESETS {
            if ui.button(*name).clicked() {
                ui.close();
                request = Some(FileRequest::Preset(name, text));
            }
        }
    });
    ui.separator();
    ui.checkbox(
        &mut state.session.export_layers,
        "EXR: add single-scatter and internal-light layers",
    );
    if ui.button("Export EXR (linear, float)…").clicked() {
        ui.close();
        export_dialog(state, "exr");
    }
    if ui.button("Export PNG (as displayed)…").clicked() {
        ui.close();
        export_dialog(state, "png");
    }
    request
}

/// An example scene from its name and RON text.
pub fn preset_scene(name: &str, text: &str) -> Result<Scene, String> {
    Scene::from_ron(text, Path::new(name)).map_err(|e| format!("{e:#}"))
}

fn export_dialog(state: &mut FileMenuState<'_>, ext: &str) {
    let target = rfd::FileDialog::new()
        .add_filter(ext.to_uppercase(), &[ext])
        .set_file_name(format!("lantern.{ext}"))
        .save_file();
    if let Some(path) = target {
        let result = state
            .display
            .snapshot()
            .ok_or_else(|| "nothing rendered yet".to_string())
            .and_then(|s| export(&path, &s, state.doc, state.session, state.display));
        match result {
            Ok(()) => notify(state.toasts, format!("exported {}", path.display())),
            Err(e) => notify_error(state.toasts, e),
        }
    }
}

/// Writes the shown image (of `display`, in `session`'s comparison mode):
/// `.exr` linear with `doc`'s settings as metadata and layers, `.png`
/// after the display transform.
pub fn export(
    path: &Path,
    snapshot: &Snapshot,
    doc: &Document,
    session: &Session,
    display: &Display,
) -> Result<(), String> {
    let shown = display.shown_estimator(session.compare);
    let stream = snapshot
        .streams
        .iter()
        .find(|s| s.estimator == shown)
        .or_else(|| snapshot.streams.first())
        .ok_or_else(|| "nothing rendered yet".to_string())?;
    // On the GPU backend the image is read back from the device here (the
    // only read-back of the previewer besides its statistics).
    let stream = stream.resolved()?;
    match extension(path).as_deref() {
        Some("exr") => {
            let mut meta = render_metadata(doc);
            meta.push(("spp".into(), stream.spp.to_string()));
            meta.push((
                "method".into(),
                match stream.estimator {
                    Method::Internal => "internal".into(),
                    Method::Reference => "reference".into(),
                },
            ));
            if let Some(sets) = stream.light_sets {
                meta.push(("light_sets".into(), sets.label()));
            }
            let mut layers: Vec<(&str, &[Vec3])> = Vec::new();
            if session.export_layers {
                if let Some(single) = &stream.single {
                    layers.push(("single", single));
                }
                if let Some(internal) = &stream.internal {
                    layers.push(("internal", internal));
                }
            }
            write_exr_with_metadata(
                path,
                stream.width,
                stream.height,
                &stream.mean,
                &layers,
                &meta,
            )
        }
        Some("png") => {
            let bytes = to_srgb8(&stream.mean, session.exposure, session.view);
            write_png_bytes(
                path,
                &bytes,
                stream.width,
                stream.height,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| e.to_string())
        }
        _ => Err(format!(
            "{}: unsupported image format (use .exr or .png)",
            path.display()
        )),
    }
}

/// The render settings written into an EXR header.
pub fn render_metadata(doc: &Document) -> Vec<(String, String)> {
    let i = &doc.scene.render.internal;
    let s = &doc.scene;
    vec![
        (
            "lantern/s_star".into(),
            i.knobs.s_star.map_or("auto".into(), |v| v.to_string()),
        ),
        ("lantern/M".into(), i.knobs.lights.to_string()),
        ("lantern/g".into(), s.medium.g.to_string()),
        ("lantern/N".into(), i.knobs.terms.to_string()),
        ("lantern/K".into(), i.expert.walks.to_string()),
        ("lantern/sh_order".into(), i.expert.sh_order.to_string()),
        ("lantern/seed".into(), s.render.seed.to_string()),
    ]
}

/// Writes 32-bit float linear RGB with extra layers (`NAME.R`, `NAME.G`,
/// `NAME.B` channels) and text attributes.
pub fn write_exr_with_metadata(
    path: &Path,
    width: u32,
    height: u32,
    beauty: &[Vec3],
    layers: &[(&str, &[Vec3])],
    metadata: &[(String, String)],
) -> Result<(), String> {
    use exr::prelude::*;
    let fail = |e: &dyn std::fmt::Display| format!("cannot write {}: {e}", path.display());
    let n = width as usize * height as usize;
    if beauty.len() != n || layers.iter().any(|(_, l)| l.len() != n) {
        return Err(fail(&"image size mismatch"));
    }
    let mut channels: Vec<AnyChannel<FlatSamples>> = Vec::new();
    let mut add = |prefix: &str, pixels: &[Vec3]| {
        for (c, name) in ["R", "G", "B"].iter().enumerate() {
            let full = if prefix.is_empty() {
                (*name).to_string()
            } else {
                format!("{prefix}.{name}")
            };
            let samples = pixels.iter().map(|p| p[c]).collect();
            channels.push(AnyChannel::new(full.as_str(), FlatSamples::F32(samples)));
        }
    };
    add("", beauty);
    for (name, pixels) in layers {
        add(name, pixels);
    }
    let mut other = HashMap::new();
    for (k, v) in metadata {
        let key = Text::new_or_none(k).ok_or_else(|| fail(&format!("bad key {k}")))?;
        let value = Text::new_or_none(v).ok_or_else(|| fail(&format!("bad value {v}")))?;
        other.insert(key, AttributeValue::Text(value));
    }
    let attributes = LayerAttributes {
        other,
        ..LayerAttributes::default()
    };
    let size = (width as usize, height as usize);
    let layer = Layer::new(
        size,
        attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    let image = Image::from_layer(layer);
    write_atomically(path, |out| image.write().to_buffered(out)).map_err(|e| e.to_string())
}

/// Saves a screenshot of the window as PNG.
pub fn save_screenshot(path: &Path, image: &egui::ColorImage) -> Result<(), String> {
    let [w, h] = image.size;
    let mut bytes = Vec::with_capacity(w * h * 4);
    for p in &image.pixels {
        bytes.extend_from_slice(&p.to_array());
    }
    write_png_bytes(
        path,
        &bytes,
        w as u32,
        h as u32,
        image::ExtendedColorType::Rgba8,
    )
    .map_err(|e| e.to_string())
}
