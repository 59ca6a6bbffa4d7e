//! The previewer's state that its panels edit, apart from the frame loop:
//! the document (the scene), the persisted session, and the
//! notifications. The panels (`controls`, `sky`, `viewport`, `files`) take
//! narrow borrows of these instead of the whole application, so that none
//! of them imports `app`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::render::tonemap::ViewTransform;
use crate::scene::{Method, Scene};
use crate::session::Backend;

/// What is edited, saved and undone: the scene, with the method's
/// settings in `scene.render`.
#[derive(Clone, Debug, PartialEq)]
pub struct Document {
    /// The scene.
    pub scene: Scene,
}

/// What the viewport shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CompareMode {
    /// The internal-lights image.
    #[default]
    Internal,
    /// The reference image.
    Reference,
    /// Internal lights left of a draggable divider, reference right.
    Split,
    /// Per-pixel error of internal lights against the reference.
    Error,
}

impl CompareMode {
    /// The estimators the worker must run for this mode.
    pub fn estimators(self) -> Vec<Method> {
        match self {
            CompareMode::Internal => vec![Method::Internal],
            CompareMode::Reference => vec![Method::Reference],
            CompareMode::Split | CompareMode::Error => {
                vec![Method::Internal, Method::Reference]
            }
        }
    }
}

/// Mouse bindings of the viewport camera.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum NavPreset {
    /// Middle drag orbits, Shift+middle pans, Ctrl+middle or the wheel zooms.
    #[default]
    Blender,
    /// Alt+left orbits, Alt+middle pans, Alt+right zooms (Maya, Houdini).
    AltDrag,
}

/// Which quantity sizes and colours the internal-light gizmos.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum LightQuantity {
    /// `F = G(s*) S₁`, the first gated term.
    F,
    /// `J`, the whole series.
    #[default]
    J,
}

/// Settings of the previewer that survive a restart (eframe's storage).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Session {
    /// The scene open when the previewer was closed.
    pub last_scene: Option<PathBuf>,
    /// Recently opened or saved scenes, newest first.
    pub recent: Vec<PathBuf>,
    /// Display exposure in stops.
    pub exposure: f32,
    /// Display view transform.
    pub view: ViewTransform,
    /// Camera mouse bindings.
    pub nav: NavPreset,
    /// Render resolution relative to the viewport's pixels.
    pub res_scale: f32,
    /// What the viewport shows.
    pub compare: CompareMode,
    /// Position of the split-view divider, 0 (left) to 1 (right).
    pub split: f32,
    /// Stop accumulating at this many samples per pixel.
    pub max_spp: u32,
    /// Draw the internal lights.
    pub show_lights: bool,
    /// Gizmo strength: F or J.
    pub quantity: LightQuantity,
    /// Gizmo strength on a log scale.
    pub log_strength: bool,
    /// Only the lights that contribute to the pixel under the cursor.
    pub contributors_only: bool,
    /// Draw the medium's box.
    pub show_box: bool,
    /// Draw the sun gizmo.
    pub show_sun: bool,
    /// EXR export adds the single-scatter and internal-light layers.
    pub export_layers: bool,
    /// Where to render: the GPU where one is available (the default),
    /// else the CPU.
    pub backend: Backend,
}

/// The session file's name, in eframe's storage folder for Lantern.
pub const SESSION_FILE: &str = "session.ron";

impl Session {
    /// Where the session is kept: [`SESSION_FILE`] in eframe's storage
    /// folder for Lantern (Linux: `~/.local/share/lantern/`), if the
    /// platform has one.
    pub fn path() -> Option<PathBuf> {
        eframe::storage_dir("Lantern").map(|d| d.join(SESSION_FILE))
    }

    /// Reads a session file; `None` if it is missing, too large or not a
    /// session (the previewer then starts from the defaults).
    pub fn load(path: &Path) -> Option<Session> {
        let text = crate::scene::read_text(path, 1 << 20, "session file").ok()?;
        ron::from_str(&text).ok()
    }

    /// Writes the session whole or not at all (creating its folder): a
    /// failed write keeps the previous session file.
    pub fn save(&self, path: &Path) -> Result<(), String> {
        let text = ron::ser::to_string_pretty(self, ron::ser::PrettyConfig::new())
            .map_err(|e| format!("cannot write the session {}: {e}", path.display()))?;
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)
                .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        }
        crate::atomic::write_bytes(path, text.as_bytes()).map_err(|e| e.to_string())
    }
}

impl Default for Session {
    fn default() -> Self {
        Self {
            last_scene: None,
            recent: Vec::new(),
            exposure: 0.0,
            view: ViewTransform::Filmic,
            nav: NavPreset::Blender,
            res_scale: 0.5,
            compare: CompareMode::Internal,
            split: 0.5,
            max_spp: 1024,
            show_lights: true,
            quantity: LightQuantity::J,
            log_strength: true,
            contributors_only: false,
            show_box: true,
            show_sun: true,
            export_layers: true,
            backend: Backend::Gpu,
        }
    }
}

/// A message shown for a few seconds in the corner of the viewport.
#[derive(Clone, Debug)]
pub struct Toast {
    /// The text.
    pub text: String,
    /// An error (red) rather than information.
    pub error: bool,
    /// When it appeared.
    pub born: Instant,
}

/// Shows an information message.
pub fn notify(toasts: &mut Vec<Toast>, text: impl Into<String>) {
    toasts.push(Toast {
        text: text.into(),
        error: false,
        born: Instant::now(),
    });
}

/// Shows an error message (and prints it).
pub fn notify_error(toasts: &mut Vec<Toast>, text: impl Into<String>) {
    let text = text.into();
    eprintln!("lantern: {text}");
    toasts.push(Toast {
        text,
        error: true,
        born: Instant::now(),
    });
}

/// One line with the median and spread of measured latencies.
pub fn latency_report(samples_ms: &[f64], size: [u32; 2], what: &str) -> String {
    let mut s = samples_ms.to_vec();
    s.sort_by(f64::total_cmp);
    let median = if s.is_empty() {
        f64::NAN
    } else if s.len() % 2 == 1 {
        s[s.len() / 2]
    } else {
        0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2])
    };
    format!(
        "lantern: slider-to-image latency at {}x{}, {what}: median {:.1} ms over {} changes (min {:.1}, max {:.1})",
        size[0],
        size[1],
        median,
        s.len(),
        s.first().copied().unwrap_or(f64::NAN),
        s.last().copied().unwrap_or(f64::NAN)
    )
}
