//! # Lantern
//!
//! A previewer of multiple scattering in clouds and smoke through Jerry
//! Tessendorf's idea of *multiple scatter as internal lights*: light that
//! has travelled `k·s*` becomes a source `J`, sampled at points placed by
//! density, and a short single-scatter ray march over `s*` gathers them.
//! The method is explained in [`doc::method`], whose numbered sections the
//! modules cite ("method §n") for the part they implement; [`doc`] holds
//! the other pages (the reference renderer, the scene format, the
//! validation studies, the GPU backend, the architecture).
//!
//! ## Layers and the dependency rule
//!
//! ```text
//! scene/    what is rendered: camera, medium, density sources, lights; RON; loaders
//! physics/  pure math on glam: phase function, tracking, transmittance, estimators
//! render/   backend-neutral: prepared scene, progressive film, tone mapping, export
//! cpu/      the rayon backend
//! gpu/      the wgpu backend: headless device, GPU mirrors, compute pipelines
//! session/  backend-neutral render session: the CPU/GPU choice, light-set renewal, the worker
//! ui/       the interactive previewer (eframe, egui, rfd): the only UI code
//! cli/      headless rendering, export, benchmarks and the measuring commands
//! atomic.rs files written whole or not at all (every writer uses it)
//! doc/      the documentation pages: method, validation, formats (no code)
//! ```
//!
//! `scene` and `physics` are leaves and never import each other (`scene`
//! writes its files through `atomic`, which uses only `std`); `render`
//! uses both; `cpu` and `gpu` use `render`; `session` uses both backends; only
//! `cli` and `ui` sit on top.
//! Renderers know nothing of any user interface.

pub mod atomic;
pub mod cli;
pub mod cpu;
pub mod doc;
pub mod gpu;
pub mod physics;
pub mod render;
pub mod scene;
pub mod session;
pub mod ui;
