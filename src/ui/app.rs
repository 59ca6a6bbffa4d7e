//! The previewer's state and frame loop: the edited document with undo and
//! redo, the persisted session, notifications, the worker that renders, and
//! the scripted runs used by tests and the README screenshot.
//!
//! Every frame the document (plus the viewport size and view mode) is
//! turned into a [`Job`]; when it differs from the job in flight, the
//! worker is told, which cancels the pass in flight and restarts the image.

use std::path::{Path, PathBuf};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use eframe::egui;

use super::controls::ControlsState;
use super::files::{self, FileMenuState, FileRequest, Loaded};
use super::sky::SkyState;
pub use super::state::{
    latency_report, CompareMode, Document, LightQuantity, NavPreset, Session, Toast, SESSION_FILE,
};
use super::viewport::{Display, NavState, ViewportState};
use super::LaunchOptions;
use crate::scene::{Method, Scene};
use crate::session::{Backend, Job, Worker};

/// A scripted run: tests, the README screenshot and the latency measurement
/// drive the real window through these (from environment variables).
#[derive(Clone, Debug, Default)]
pub struct Script {
    /// Save a screenshot here once `min_spp` is reached, then quit.
    pub screenshot: Option<PathBuf>,
    /// Samples per pixel to wait for.
    pub min_spp: u32,
    /// Measure slider-to-image latency over this many changes, then quit.
    pub latency_changes: u32,
    /// Give up (exit with an error message) after this long.
    pub timeout: Duration,
    /// Render at exactly this size instead of the viewport's.
    pub render_size: Option<[u32; 2]>,
    /// Measure the UI's frame rate for this many seconds while the render
    /// thread re-samples the lights and refines, then quit.
    pub fps_secs: f32,
    /// What the viewport shows (`LANTERN_VIEW`: internal, reference, split
    /// or error); default: the scene's method.
    pub compare: Option<CompareMode>,
}

impl Script {
    /// Reads `LANTERN_SCREENSHOT`, `LANTERN_SCRIPT_SPP`,
    /// `LANTERN_LATENCY_CHANGES` and `LANTERN_SCRIPT_TIMEOUT_SECS`; `None`
    /// when neither a screenshot nor a measurement is asked for.
    pub fn from_env() -> Option<Script> {
        let var = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
        let screenshot = var("LANTERN_SCREENSHOT").map(PathBuf::from);
        let latency_changes = var("LANTERN_LATENCY_CHANGES")
            .and_then(|v| v.parse().ok())
            .unwrap_or(0);
        let fps_secs = var("LANTERN_FPS_SECS")
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0);
        if screenshot.is_none() && latency_changes == 0 && fps_secs <= 0.0 {
            return None;
        }
        Some(Script {
            screenshot,
            min_spp: var("LANTERN_SCRIPT_SPP")
                .and_then(|v| v.parse().ok())
                .unwrap_or(4),
            latency_changes,
            timeout: Duration::from_secs(
                var("LANTERN_SCRIPT_TIMEOUT_SECS")
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(300),
            ),
            fps_secs,
            compare: var("LANTERN_VIEW").and_then(|v| match v.as_str() {
                "internal" => Some(CompareMode::Internal),
                "reference" => Some(CompareMode::Reference),
                "split" => Some(CompareMode::Split),
                "error" => Some(CompareMode::Error),
                _ => None,
            }),
            render_size: var("LANTERN_RENDER_SIZE").and_then(|v| {
                let (w, h) = v.split_once('x')?;
                Some([w.parse().ok()?, h.parse().ok()?])
            }),
        })
    }
}

/// Whether the GPU backend can be used in this run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GpuStatus {
    /// A device shared with the window: its adapter's description.
    Ready(String),
    /// Why there is none (the CPU renders instead).
    Unavailable(String),
}

/// Undo and redo of edits: snapshots of the document, recorded when an
/// edit ends (no mouse button held), so a slider drag is one step.
#[derive(Debug)]
pub struct History {
    undo: Vec<Document>,
    redo: Vec<Document>,
    committed: Document,
}

impl History {
    /// Largest number of undo steps kept.
    pub const LIMIT: usize = 200;

    /// A history whose current state is `doc`.
    pub fn new(doc: &Document) -> Self {
        Self {
            undo: Vec::new(),
            redo: Vec::new(),
            committed: doc.clone(),
        }
    }

    /// Records `doc` as a new step if it differs from the last one.
    pub fn commit(&mut self, doc: &Document) {
        if *doc != self.committed {
            let previous = std::mem::replace(&mut self.committed, doc.clone());
            self.undo.push(previous);
            if self.undo.len() > Self::LIMIT {
                self.undo.remove(0);
            }
            self.redo.clear();
        }
    }

    /// The state before the last step, if any.
    pub fn undo(&mut self, doc: &mut Document) -> bool {
        self.commit(doc);
        match self.undo.pop() {
            Some(previous) => {
                self.redo
                    .push(std::mem::replace(&mut self.committed, previous.clone()));
                *doc = previous;
                true
            }
            None => false,
        }
    }

    /// The state undone last, if any.
    pub fn redo(&mut self, doc: &mut Document) -> bool {
        match self.redo.pop() {
            Some(next) => {
                self.undo
                    .push(std::mem::replace(&mut self.committed, next.clone()));
                *doc = next;
                true
            }
            None => false,
        }
    }

    /// Whether there is something to undo.
    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    /// Whether there is something to redo.
    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }
}

/// Progress of a scripted run.
#[derive(Debug, Default)]
struct ScriptState {
    started: Option<Instant>,
    screenshot_requested: bool,
    changes_done: u32,
    last_change: Option<Instant>,
    screenshot: Option<Receiver<std::sync::Arc<egui::ColorImage>>>,
    reported: bool,
    frames: Vec<Instant>,
    ui_ms: Vec<f64>,
    cpu_ms: Vec<f64>,
    backend_reported: bool,
}

/// The previewer application.
pub struct LanternApp {
    /// Persisted settings.
    pub session: Session,
    /// The edited document.
    pub doc: Document,
    /// Where the document was read from or last saved to.
    pub path: Option<PathBuf>,
    /// The folder that grid paths are relative to.
    pub scene_dir: PathBuf,
    /// The document as last saved (unsaved changes = differs).
    pub saved: Document,
    /// Undo and redo.
    pub history: History,
    /// The render thread.
    pub worker: Worker,
    /// The job in flight, and its generation.
    pub submitted: Option<(Job, u64)>,
    /// The displayed image and its texture.
    pub display: Display,
    /// Camera-navigation state of the viewport.
    pub nav: NavState,
    /// Notifications.
    pub toasts: Vec<Toast>,
    /// Whether the GPU backend is available.
    pub gpu: GpuStatus,
    /// Whether the user was told that the GPU is unavailable since they
    /// last chose it.
    pub gpu_notice_shown: bool,
    /// A scene being loaded in the background.
    pending_load: Option<Receiver<Result<Loaded, String>>>,
    /// The viewport's render size in pixels (after the resolution scale).
    pub render_size: [u32; 2],
    /// Render at this size whatever the viewport's (scripted runs).
    pub forced_render_size: Option<[u32; 2]>,
    /// When the job of each pending generation was submitted (latency).
    change_at: Option<(u64, Instant)>,
    /// Slider-to-image latencies measured, in milliseconds.
    pub latency_ms: Vec<f64>,
    /// The same, until the frame that shows the image has been presented
    /// (measured at the start of the next frame).
    pub presented_ms: Vec<f64>,
    /// The change whose image is in the frame being presented.
    presenting: Option<Instant>,
    /// Whether the close dialog is open.
    confirm_close: bool,
    /// Whether closing was confirmed.
    close_confirmed: bool,
    script: Option<Script>,
    script_state: ScriptState,
    /// The Sky section's state outside the document (map being read,
    /// thumbnail).
    pub sky: super::sky::SkyUi,
}

impl LanternApp {
    /// The application inside eframe: restores the session and opens the
    /// scene given on the command line, or the last one.
    pub fn new(cc: &eframe::CreationContext<'_>, options: LaunchOptions) -> Self {
        let session: Session = if options.script.is_some() {
            Session::default()
        } else {
            // Lantern's own session file first (written whole or not at
            // all), else what an older build left in eframe's storage.
            Session::path()
                .and_then(|p| Session::load(&p))
                .or_else(|| {
                    cc.storage
                        .and_then(|s| eframe::get_value(s, eframe::APP_KEY))
                })
                .unwrap_or_default()
        };
        let ctx = cc.egui_ctx.clone();
        let (gpu, gpu_view) = super::gpu_view::from_eframe(cc);
        let worker = Worker::start_with_gpu(
            Box::new(move |within| {
                if within.is_zero() {
                    ctx.request_repaint();
                } else {
                    ctx.request_repaint_after(within);
                }
            }),
            gpu.as_ref().ok().cloned(),
        );
        let mut app = Self::with_worker(session, worker);
        app.gpu = match &gpu {
            Ok(ctx) => GpuStatus::Ready(ctx.describe()),
            Err(reason) => GpuStatus::Unavailable(reason.clone()),
        };
        app.display.set_gpu_view(gpu_view);
        // Scripted runs and the latency measurement pick the backend.
        match std::env::var("LANTERN_BACKEND").as_deref() {
            Ok("cpu") => app.session.backend = Backend::Cpu,
            Ok("gpu") => app.session.backend = Backend::Gpu,
            _ => {
                // A software rasteriser (lavapipe, llvmpipe) runs the compute
                // shaders on the CPU cores, at about half the CPU renderer's
                // speed and in passes that cannot be interrupted, which
                // stalls the window (measured on the cloud at 512²: 3 frames/s
                // against 9.5, src/doc/validation.md §4); start on the CPU there
                // and say so. The switch still selects the GPU.
                if let Ok(ctx) = &gpu {
                    if ctx.is_software() && app.session.backend == Backend::Gpu {
                        app.session.backend = Backend::Cpu;
                        let text = format!(
                            "{} is a software GPU: rendering on the CPU, which is faster \
                             here (Render ▸ backend selects the GPU)",
                            ctx.adapter_info.name
                        );
                        eprintln!("lantern: {text}");
                        app.notify(text);
                    }
                }
            }
        }
        app.forced_render_size = options.script.as_ref().and_then(|s| s.render_size);
        app.script = options.script;
        let wanted = options.scene.or_else(|| app.session.last_scene.clone());
        if let Some(path) = wanted {
            app.open_now(&path);
        }
        if let Some(mode) = app.script.as_ref().and_then(|s| s.compare) {
            app.session.compare = mode;
        }
        app
    }

    /// An application with the default scene and no window (tests): no
    /// display device, so the CPU backend (choosing the GPU shows the
    /// fallback notice).
    pub fn headless() -> Self {
        let session = Session {
            backend: Backend::Cpu,
            ..Session::default()
        };
        let mut app = Self::with_worker(session, Worker::start(Box::new(|_| {})));
        app.gpu = GpuStatus::Unavailable("no window: the previewer runs without a display".into());
        app
    }

    fn with_worker(session: Session, worker: Worker) -> Self {
        let doc = Document {
            scene: files::default_scene(),
        };
        Self {
            session,
            saved: doc.clone(),
            history: History::new(&doc),
            doc,
            path: None,
            scene_dir: PathBuf::from("."),
            worker,
            submitted: None,
            display: Display::default(),
            nav: NavState::default(),
            toasts: Vec::new(),
            gpu: GpuStatus::Unavailable("not set up".into()),
            gpu_notice_shown: false,
            pending_load: None,
            render_size: [256, 256],
            forced_render_size: None,
            change_at: None,
            latency_ms: Vec::new(),
            presented_ms: Vec::new(),
            presenting: None,
            confirm_close: false,
            close_confirmed: false,
            script: None,
            script_state: ScriptState::default(),
            sky: Default::default(),
        }
    }

    /// Whether the document differs from the file.
    pub fn is_dirty(&self) -> bool {
        self.doc != self.saved
    }

    /// Shows an information message.
    pub fn notify(&mut self, text: impl Into<String>) {
        super::state::notify(&mut self.toasts, text);
    }

    /// Shows an error message.
    pub fn notify_error(&mut self, text: impl Into<String>) {
        super::state::notify_error(&mut self.toasts, text);
    }

    /// Starts loading a scene (or a volume, wrapped in the current scene)
    /// in the background; the current document stays until it succeeds.
    pub fn open(&mut self, path: &Path) {
        let current = self.doc.scene.clone();
        self.pending_load = Some(files::load_in_background(path.to_owned(), current));
    }

    /// Loads a scene synchronously (startup and tests).
    pub fn open_now(&mut self, path: &Path) {
        match files::load(path, &self.doc.scene) {
            Ok(loaded) => self.apply_loaded(loaded),
            Err(e) => self.notify_error(e),
        }
    }

    /// Replaces the document with an unmodified `scene` (whose relative
    /// paths refer to `scene_dir`): fresh undo history, nothing unsaved,
    /// the view following the scene's method.
    pub fn replace_scene(&mut self, scene: Scene, scene_dir: PathBuf) {
        self.session.compare = match scene.render.method {
            Method::Internal => CompareMode::Internal,
            Method::Reference => CompareMode::Reference,
        };
        self.doc = Document { scene };
        self.saved = self.doc.clone();
        self.scene_dir = scene_dir;
        self.history = History::new(&self.doc);
    }

    fn apply_loaded(&mut self, loaded: Loaded) {
        self.replace_scene(loaded.scene, loaded.scene_dir);
        if loaded.is_scene_file {
            self.path = Some(loaded.path.clone());
            self.session.last_scene = Some(loaded.path.clone());
        } else {
            // A volume dropped in: a new, unsaved scene around it.
            self.saved = Document {
                scene: Scene::default(),
            };
            self.path = None;
            let aspect = self.render_aspect();
            super::viewport::frame_bounds(&mut self.doc.scene.camera, loaded.bounds, aspect);
            self.history = History::new(&self.doc);
        }
        files::push_recent(&mut self.session.recent, &loaded.path);
        self.notify(format!("opened {}", loaded.path.display()));
        for warning in loaded.warnings {
            self.notify_error(format!("warning: {warning}"));
        }
    }

    /// Saves the document to `path`.
    pub fn save_to(&mut self, path: &Path) {
        // A sky map's path is written relative to the scene's new folder.
        let scene = super::sky::scene_for_saving(&self.doc.scene, &self.scene_dir, path);
        match scene.save(path) {
            Ok(()) => {
                self.saved = self.doc.clone();
                self.path = Some(path.to_owned());
                self.session.last_scene = Some(path.to_owned());
                files::push_recent(&mut self.session.recent, path);
                self.notify(format!("saved {}", path.display()));
            }
            Err(e) => self.notify_error(format!("{e:#}")),
        }
    }

    /// Undoes the last edit.
    pub fn undo(&mut self) {
        if !self.history.undo(&mut self.doc) {
            self.notify("nothing to undo");
        }
    }

    /// Redoes the last undone edit.
    pub fn redo(&mut self) {
        if !self.history.redo(&mut self.doc) {
            self.notify("nothing to redo");
        }
    }

    /// Width over height of the render.
    pub fn render_aspect(&self) -> f32 {
        self.render_size[0] as f32 / self.render_size[1].max(1) as f32
    }

    /// The job that the current state asks for.
    pub fn job(&self) -> Job {
        let mut scene = self.doc.scene.clone();
        scene.camera.width = self.render_size[0].max(1);
        scene.camera.height = self.render_size[1].max(1);
        let estimators = self.session.compare.estimators();
        Job {
            scene,
            scene_dir: self.scene_dir.clone(),
            estimators,
            max_spp: self.session.max_spp.max(1),
            backend: self.requested_backend(),
        }
    }

    /// The backend the next job asks for: the chosen one, if available.
    pub fn requested_backend(&self) -> Backend {
        match (&self.session.backend, &self.gpu) {
            (Backend::Gpu, GpuStatus::Ready(_)) => Backend::Gpu,
            _ => Backend::Cpu,
        }
    }

    /// The backend that rendered the image on screen (the requested one
    /// before the first image).
    pub fn active_backend(&self) -> Backend {
        self.display
            .snapshot()
            .map_or_else(|| self.requested_backend(), |s| s.backend)
    }

    /// One line saying where the image is rendered and, where that is not
    /// the chosen backend, why.
    pub fn backend_status(&self) -> String {
        let active = self.active_backend();
        match (&self.gpu, active) {
            (GpuStatus::Ready(adapter), Backend::Gpu) => {
                format!("rendering on the GPU: {adapter}")
            }
            (GpuStatus::Unavailable(reason), _) if self.session.backend == Backend::Gpu => {
                format!("GPU unavailable ({reason}): rendering on the CPU")
            }
            (_, Backend::Cpu) if self.session.backend == Backend::Gpu => {
                "the GPU could not take this scene: rendering on the CPU".to_string()
            }
            _ => "rendering on the CPU".to_string(),
        }
    }

    /// Does what the File menu or a file dialog asked, if anything.
    pub fn file_request(&mut self, request: Option<FileRequest>) {
        match request {
            None => {}
            Some(FileRequest::Open(path)) => self.open(&path),
            Some(FileRequest::Save(path)) => self.save_to(&path),
            Some(FileRequest::Preset(name, text)) => self.open_preset(name, text),
        }
    }

    /// Replaces the document with an example scene.
    pub fn open_preset(&mut self, name: &str, text: &str) {
        match files::preset_scene(name, text) {
            Ok(scene) => {
                self.replace_scene(scene, files::presets_dir());
                self.path = None;
                self.notify(format!("example scene: {name}"));
            }
            Err(e) => self.notify_error(e),
        }
    }

    /// The side panel's part of the state.
    fn controls_state(&mut self) -> ControlsState<'_> {
        ControlsState {
            backend_status: self.backend_status(),
            active_backend: self.active_backend(),
            lights: self.display.lights(),
            doc: &mut self.doc,
            session: &mut self.session,
            sky: &mut self.sky,
            scene_dir: &self.scene_dir,
            path: self.path.as_deref(),
            toasts: &mut self.toasts,
            gpu_notice_shown: &mut self.gpu_notice_shown,
            presented_ms: &self.presented_ms,
            render_size: self.render_size,
        }
    }

    /// The Sky section's part of the state.
    pub fn sky_state(&mut self) -> SkyState<'_> {
        SkyState {
            doc: &mut self.doc,
            sky: &mut self.sky,
            scene_dir: &self.scene_dir,
            path: self.path.as_deref(),
            toasts: &mut self.toasts,
        }
    }

    /// Tells once (per choice of the GPU) that the GPU is unavailable.
    fn gpu_notice(&mut self) {
        if self.session.backend != Backend::Gpu {
            self.gpu_notice_shown = false;
            return;
        }
        if self.gpu_notice_shown {
            return;
        }
        if let GpuStatus::Unavailable(reason) = &self.gpu {
            let text = format!("GPU backend unavailable ({reason}); rendering on the CPU");
            self.gpu_notice_shown = true;
            self.notify_error(text);
        }
    }

    /// Sends the job to the worker if it changed; returns whether it did.
    pub fn sync_job(&mut self) -> bool {
        let job = self.job();
        if self.submitted.as_ref().map(|(j, _)| j) == Some(&job) {
            return false;
        }
        let generation = self.worker.submit(job.clone());
        self.submitted = Some((job, generation));
        self.change_at = Some((generation, Instant::now()));
        true
    }

    /// The generation of the job in flight (0 before the first).
    pub fn generation(&self) -> u64 {
        self.submitted.as_ref().map_or(0, |(_, g)| *g)
    }

    /// Draws the whole application into `ui` (one frame).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let frame_start = Instant::now();
        if let Some(at) = self.presenting.take() {
            self.presented_ms.push(at.elapsed().as_secs_f64() * 1e3);
        }
        let ctx = ui.ctx().clone();
        for e in self.worker.take_errors() {
            self.notify_error(e);
        }
        self.gpu_notice();
        self.poll_load();
        self.handle_dropped_files(&ctx);
        self.shortcuts(&ctx);

        egui::Panel::top("menu").show(ui, |ui| self.menu_ui(ui));
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                super::controls::panel_ui(ui, &mut self.controls_state())
            });
        egui::CentralPanel::no_frame().show(ui, |ui| {
            super::viewport::viewport_ui(
                ui,
                &mut ViewportState {
                    doc: &mut self.doc,
                    session: &mut self.session,
                    display: &self.display,
                    nav: &mut self.nav,
                    render_size: &mut self.render_size,
                    forced_render_size: self.forced_render_size,
                },
            )
        });

        // An edit ends when no mouse button is held.
        if !ctx.input(|i| i.pointer.any_down()) {
            self.history.commit(&self.doc);
        }
        self.sync_job();
        if let Some(snapshot) = self.worker.latest() {
            let generation = snapshot.generation;
            if self.display.update(&ctx, snapshot, &self.session) {
                if let Some((g, at)) = self.change_at {
                    if generation >= g {
                        self.latency_ms.push(at.elapsed().as_secs_f64() * 1e3);
                        self.change_at = None;
                        self.presenting = Some(at);
                        ctx.request_repaint();
                    }
                }
            }
        }
        self.toasts_ui(&ctx);
        self.close_ui(&ctx);
        self.script_step(&ctx);
        if self.script.is_some() {
            self.script_state
                .ui_ms
                .push(frame_start.elapsed().as_secs_f64() * 1e3);
        }
    }

    fn poll_load(&mut self) {
        let Some(rx) = &self.pending_load else {
            return;
        };
        match rx.try_recv() {
            Ok(Ok(loaded)) => {
                self.pending_load = None;
                self.apply_loaded(loaded);
            }
            Ok(Err(e)) => {
                self.pending_load = None;
                self.notify_error(e);
            }
            Err(std::sync::mpsc::TryRecvError::Empty) => {}
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                self.pending_load = None;
                self.notify_error("the loader stopped unexpectedly");
            }
        }
    }

    fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_owned())
                .collect()
        });
        super::sky::poll(&mut self.sky_state(), ctx);
        if let Some(path) = dropped.first() {
            if super::sky::is_sky_map(path) {
                super::sky::open_map(&mut self.sky_state(), path);
            } else if files::is_openable(path) {
                self.open(path);
            } else {
                self.notify_error(format!(
                    "{}: not a scene (.ron), a volume (.vdb, .vol) or a sky map (.exr, .hdr)",
                    path.display()
                ));
            }
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        use egui::{Key, KeyboardShortcut, Modifiers};
        let undo = KeyboardShortcut::new(Modifiers::COMMAND, Key::Z);
        let redo = KeyboardShortcut::new(Modifiers::COMMAND | Modifiers::SHIFT, Key::Z);
        let redo_y = KeyboardShortcut::new(Modifiers::COMMAND, Key::Y);
        let open = KeyboardShortcut::new(Modifiers::COMMAND, Key::O);
        let save = KeyboardShortcut::new(Modifiers::COMMAND, Key::S);
        // Longest modifier set first: Ctrl+Shift+Z must not read as Ctrl+Z.
        if ctx.input_mut(|i| i.consume_shortcut(&redo) || i.consume_shortcut(&redo_y)) {
            self.redo();
        }
        if ctx.input_mut(|i| i.consume_shortcut(&undo)) {
            self.undo();
        }
        if ctx.input_mut(|i| i.consume_shortcut(&open)) {
            self.file_request(files::open_dialog());
        }
        if ctx.input_mut(|i| i.consume_shortcut(&save)) {
            self.file_request(files::save_dialog(self.path.as_deref(), false));
        }
    }

    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                let request = files::file_menu_ui(
                    ui,
                    &mut FileMenuState {
                        doc: &self.doc,
                        session: &mut self.session,
                        display: &self.display,
                        path: self.path.as_deref(),
                        toasts: &mut self.toasts,
                    },
                );
                self.file_request(request);
            });
            ui.menu_button("Edit", |ui| {
                if ui
                    .add_enabled(self.history.can_undo(), egui::Button::new("Undo"))
                    .clicked()
                {
                    self.undo();
                }
                if ui
                    .add_enabled(self.history.can_redo(), egui::Button::new("Redo"))
                    .clicked()
                {
                    self.redo();
                }
            });
            ui.separator();
            let name = self
                .path
                .as_ref()
                .and_then(|p| p.file_name())
                .map_or("untitled".to_string(), |n| n.to_string_lossy().into_owned());
            let star = if self.is_dirty() { " •" } else { "" };
            ui.label(format!("{name}{star}"));
        });
    }

    fn toasts_ui(&mut self, ctx: &egui::Context) {
        const LIFE: Duration = Duration::from_secs(6);
        self.toasts.retain(|t| t.born.elapsed() < LIFE);
        if self.toasts.is_empty() {
            return;
        }
        egui::Area::new(egui::Id::unique("lantern_toasts"))
            .anchor(egui::Align2::RIGHT_BOTTOM, [-12.0, -12.0])
            .order(egui::Order::Foreground)
            .show(ctx, |ui| {
                for t in &self.toasts {
                    let colour = if t.error {
                        egui::Color32::from_rgb(120, 30, 30)
                    } else {
                        egui::Color32::from_rgb(40, 60, 90)
                    };
                    egui::Frame::popup(ui.style()).fill(colour).show(ui, |ui| {
                        ui.set_max_width(420.0);
                        ui.label(egui::RichText::new(&t.text).color(egui::Color32::WHITE));
                    });
                }
            });
        ctx.request_repaint_after(Duration::from_millis(500));
    }

    fn close_ui(&mut self, ctx: &egui::Context) {
        if ctx.input(|i| i.viewport().close_requested())
            && self.is_dirty()
            && !self.close_confirmed
            && self.script.is_none()
        {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.confirm_close = true;
        }
        if !self.confirm_close {
            return;
        }
        let modal = egui::Modal::new(egui::Id::unique("lantern_confirm_close")).show(ctx, |ui| {
            ui.heading("Unsaved changes");
            ui.label("The scene has changes that are not saved. Quit anyway?");
            ui.horizontal(|ui| {
                if ui.button("Save and quit").clicked() {
                    self.file_request(files::save_dialog(self.path.as_deref(), false));
                    if !self.is_dirty() {
                        self.close_confirmed = true;
                        self.confirm_close = false;
                        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                    }
                }
                if ui.button("Quit without saving").clicked() {
                    self.close_confirmed = true;
                    self.confirm_close = false;
                    ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                }
                if ui.button("Cancel").clicked() {
                    self.confirm_close = false;
                }
            });
        });
        if modal.should_close() {
            self.confirm_close = false;
        }
    }

    /// Drives a scripted run: waits for samples, then takes a screenshot or
    /// measures latency by moving the phase slider back and forth.
    fn script_step(&mut self, ctx: &egui::Context) {
        let Some(script) = self.script.clone() else {
            return;
        };
        let generation = self.generation();
        let current = self.display.generation() == generation && generation > 0;
        let status = self.backend_status();
        let state = &mut self.script_state;
        let started = *state.started.get_or_insert_with(Instant::now);
        // Poll gently: a software rasterizer (CI) shares the CPU with the
        // render thread, and the worker wakes the UI on every new image.
        ctx.request_repaint_after(Duration::from_millis(100));
        if started.elapsed() > script.timeout {
            eprintln!("lantern: scripted run timed out");
            std::process::exit(3);
        }
        let spp = self.display.spp();
        if !state.backend_reported && current && spp >= 1 {
            state.backend_reported = true;
            println!("lantern: {status}");
        }

        if script.fps_secs > 0.0 {
            if state.frames.is_empty() {
                if !current {
                    return;
                }
                // Start with a change, so the lights re-sample meanwhile.
                let g = &mut self.doc.scene.medium.g;
                *g = if *g > 0.5 { 0.3 } else { 0.7 };
            }
            state.frames.push(Instant::now());
            ctx.request_repaint();
            let first = state.frames[0];
            if first.elapsed().as_secs_f32() >= script.fps_secs {
                println!("{}", fps_report(&state.frames));
                let median = |v: &[f64]| {
                    let mut v = v.to_vec();
                    v.sort_by(f64::total_cmp);
                    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
                };
                println!(
                    "lantern: per frame: {:.1} ms in LanternApp::ui, {:.1} ms eframe frame time without vsync waits (medians)",
                    median(&state.ui_ms),
                    median(&state.cpu_ms)
                );
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            return;
        }

        if state.changes_done < script.latency_changes {
            // Change g once the previous change has been shown and the image
            // has been refining for a moment (the change then cancels a
            // pass in flight, as a person's would).
            let ready = self.change_at.is_none()
                && self.presenting.is_none()
                && current
                && state
                    .last_change
                    .is_none_or(|t| t.elapsed() > Duration::from_millis(400));
            if ready {
                let g = &mut self.doc.scene.medium.g;
                *g = if *g > 0.5 { 0.3 } else { 0.7 };
                state.changes_done += 1;
                state.last_change = Some(Instant::now());
                if state.changes_done == 1 {
                    // The first one after start-up measures nothing useful.
                    self.latency_ms.clear();
                    self.presented_ms.clear();
                }
            }
            return;
        }
        if script.latency_changes > 0 && !state.reported {
            if self.change_at.is_some() || self.presenting.is_some() {
                return;
            }
            state.reported = true;
            println!(
                "{}",
                latency_report(
                    &self.latency_ms,
                    self.render_size,
                    "to the frame that shows it"
                )
            );
            println!(
                "{}",
                latency_report(
                    &self.presented_ms,
                    self.render_size,
                    "until that frame is presented"
                )
            );
            if script.screenshot.is_none() {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                return;
            }
        }
        if let Some(path) = &script.screenshot {
            if !state.screenshot_requested && current && spp >= script.min_spp {
                state.screenshot_requested = true;
                let (tx, rx) = std::sync::mpsc::channel();
                state.screenshot = Some(rx);
                let repaint = ctx.clone();
                ctx.request_screenshot(move |image| {
                    let _ = tx.send(image);
                    repaint.request_repaint();
                });
            }
            let shot = state.screenshot.as_ref().and_then(|rx| rx.try_recv().ok());
            if let Some(image) = shot {
                match files::save_screenshot(path, &image) {
                    Ok(()) => println!(
                        "lantern: screenshot at {spp} spp saved to {}",
                        path.display()
                    ),
                    Err(e) => {
                        eprintln!("lantern: {e}");
                        std::process::exit(2);
                    }
                }
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }
}

/// One line with the frame rate over the frame times `frames`.
pub fn fps_report(frames: &[Instant]) -> String {
    let mut gaps: Vec<f64> = frames
        .windows(2)
        .map(|w| (w[1] - w[0]).as_secs_f64() * 1e3)
        .collect();
    gaps.sort_by(f64::total_cmp);
    let at = |q: f64| {
        gaps.get(((gaps.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let total = frames
        .last()
        .zip(frames.first())
        .map_or(0.0, |(b, a)| (*b - *a).as_secs_f64());
    format!(
        "lantern: UI while rendering: {:.1} frames/s over {:.1} s; frame interval median {:.1} ms, 95th percentile {:.1} ms, max {:.1} ms",
        gaps.len() as f64 / total.max(1e-9),
        total,
        at(0.5),
        at(0.95),
        at(1.0)
    )
}

impl eframe::App for LanternApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        if self.script.is_some() {
            if let Some(secs) = frame.info().cpu_usage {
                self.script_state.cpu_ms.push(secs as f64 * 1e3);
            }
        }
        LanternApp::ui(self, ui);
    }

    fn save(&mut self, _storage: &mut dyn eframe::Storage) {
        if self.script.is_none() {
            if let Some(path) = Session::path() {
                if let Err(e) = self.session.save(&path) {
                    eprintln!("lantern: {e}");
                }
            }
        }
    }
}
