//! The interactive previewer (issue 4): an eframe application with the wgpu
//! renderer that drives the renderers live.
//!
//! This is the only layer that knows egui, eframe or rfd. It sits on top of
//! `render`, `cpu` and `scene`; [`backend`] is the single module that calls
//! the renderers, on a worker thread, so that the UI never blocks on a pass.
//!
//! - [`app`]: the application state, the frame loop, undo and the session.
//! - [`controls`]: the side panel of parameters.
//! - [`viewport`]: the progressive image, camera navigation, gizmos and the
//!   comparisons (split view, error heatmap).
//! - [`files`]: scene files, drag and drop, recent files and image export.

pub mod app;
pub mod backend;
pub mod controls;
pub mod files;
pub mod viewport;

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
    let native = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_title("Lantern")
            .with_inner_size([1280.0, 820.0])
            .with_drag_and_drop(true),
        renderer: eframe::Renderer::Wgpu,
        persist_window: options.script.is_none(),
        ..Default::default()
    };
    eframe::run_native(
        "Lantern",
        native,
        Box::new(move |cc| Ok(Box::new(LanternApp::new(cc, options)))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the previewer window: {e}"))
}
