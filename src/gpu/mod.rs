//! The wgpu backend: the estimators of `physics/` as WGSL compute shaders
//! (in `shaders/`, organised like `src/physics/`), run headless or beside
//! the previewer, with progressive accumulation on the GPU.
//!
//! - [`context`]: instance → adapter → device, headless; errors.
//! - [`mirrors`]: `#[repr(C)]` twins of the shader structs, size-checked.
//! - [`shaders`]: the WGSL files and how modules are assembled from them.
//! - [`reference`]: the reference path tracer (METHOD.md §2), one dispatch
//!   per pass, accumulating on the GPU.
//!
//! What exists so far is the reference method; the internal-lights method
//! still runs on the CPU only.

pub mod context;
pub mod mirrors;
pub mod reference;
pub mod shaders;

pub use context::{GpuContext, GpuError};
pub use reference::{GpuImage, ReferenceRenderer};
