//! The interactive previewer (issue 4): an eframe application with the wgpu
//! renderer that drives the renderers live.
//!
//! This is the only layer that knows egui, eframe or rfd. It sits on top of
//! [`crate::session`], whose worker thread calls the renderers, so that the
//! UI never blocks on a pass; it edits jobs and shows snapshots.
//!
//! - [`app`]: the application, the frame loop, undo, scripted runs.
//! - [`state`]: what the panels edit: the document, the session, the
//!   notifications (no panel imports [`app`]).
//! - [`controls`]: the side panel of parameters.
//! - [`sky`]: the Sky section (environment light), its thumbnail, and
//!   sky maps dropped on the window.
//! - [`viewport`]: the progressive image, camera navigation, gizmos and the
//!   comparisons (split view, error heatmap).
//! - [`files`]: scene files, drag and drop, recent files and image export.
//! - [`widgets`]: small widgets shared by the panels.
//! - [`gpu_view`]: the GPU backend on the window's own device, and the
//!   shown image as a texture written on the GPU.

pub mod app;
pub mod controls;
pub mod files;
pub mod gpu_view;
pub mod sky;
pub mod state;
pub mod viewport;
pub mod widgets;

use std::path::PathBuf;

pub use app::LanternApp;

/// Options of a previewer run that do not come from the saved session.
#[derive(Clone, Debug, Default)]
pub struct LaunchOptions {
    /// Scene to open instead of the last one.
    pub scene: Option<PathBuf>,
    /// Automated run (tests, README screenshot, latency measurement).
    pub script: Option<app::Script>,
}

/// Opens the previewer window and runs until it is closed.
pub fn run(options: LaunchOptions) -> anyhow::Result<()> {
    // Rendering runs on rayon's global pool: its threads run below the UI.
    let _ = rayon::ThreadPoolBuilder::new()
        .thread_name(|i| format!("lantern-pass-{i}"))
        .start_handler(|_| crate::session::lower_thread_priority())
        .build_global();
    let native = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_title("Lantern")
            .with_inner_size([1280.0, 820.0])
            .with_drag_and_drop(true),
        renderer: eframe::Renderer::Wgpu,
        persist_window: options.script.is_none(),
        wgpu_options: gpu_view::wgpu_options(),
        ..Default::default()
    };

    eframe::run_native(
        "Lantern",
        native,
        Box::new(move |cc| Ok(Box::new(LanternApp::new(cc, options)))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the previewer window: {e}"))
}
