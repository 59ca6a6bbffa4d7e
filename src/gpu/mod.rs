//! The wgpu backend: the estimators of `physics/` as WGSL compute shaders
//! (in `shaders/`, organised like `src/physics/`), run headless or beside
//! the previewer, with progressive accumulation on the GPU.
//!
//! - [`context`]: instance → adapter → device, headless; errors.
//! - [`mirrors`]: `#[repr(C)]` twins of the shader structs, size-checked.
//! - [`shaders`]: the WGSL files and how modules are assembled from them.
//! - [`renderer`]: progressive rendering, one dispatch per pass,
//!   accumulating on the GPU; the reference path tracer ([method §2](crate::doc::method)).
//! - [`gather`]: the internal-lights final gather ([method §6](crate::doc::method)) with the
//!   lights built on the CPU and uploaded with their SH coefficients and
//!   spatial indices.
//! - [`walks`]: the internal lights built on the GPU ([method §4–§5](crate::doc::method)):
//!   placement, time-gated walks and SH projection, finished by the CPU's
//!   spatial indices.
//! - [`display`]: the previewer's display pass (accumulation to an 8-bit
//!   sRGB texture, on the device) and its statistics.

pub mod context;
pub mod display;
pub mod gather;
pub mod mirrors;
pub mod renderer;
pub mod shaders;
pub mod walks;

pub use context::{GpuContext, GpuError};
pub use renderer::{cut_short_passes_text, GpuImage, GpuRenderer};
