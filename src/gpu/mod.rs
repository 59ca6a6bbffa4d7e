//! The wgpu backend: the estimators of `physics/` as WGSL compute shaders
//! (in `shaders/`, organised like `src/physics/`), run headless or beside
//! the previewer, with progressive accumulation on the GPU.
//!
//! - [`mirrors`]: `#[repr(C)]` twins of the shader structs, size-checked.
//! - [`shaders`]: the WGSL files and how modules are assembled from them.
//!
//! So far: the shaders of the reference method and the data they read; the
//! pipelines come next.

pub mod mirrors;
pub mod shaders;
