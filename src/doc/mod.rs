//! Lantern's documentation pages: the method, the reference renderer, the
//! scene format, the validation studies, the GPU backend and the
//! architecture, each a markdown file in `src/doc/` shown by
//! `cargo doc --open`. Comments in the code cite the method's sections as
//! "method §n".
//!
//! - [`method`]: multiple scatter as internal lights, in Lantern's words.
//! - [`reference`](mod@reference): the unbiased path tracer everything is measured
//!   against.
//! - [`scene_format`]: the RON scene files, units and conventions.
//! - [`validation`]: what the tests assert, the accuracy at the defaults,
//!   the commands that regenerate every study, and a historical record.
//! - [`gpu`]: the wgpu backend.
//! - [`architecture`]: the layers and how a render flows through them.

#[doc = include_str!("method.md")]
pub mod method {}

#[doc = include_str!("reference.md")]
pub mod reference {}

#[doc = include_str!("scene_format.md")]
pub mod scene_format {}

#[doc = include_str!("validation.md")]
pub mod validation {}

#[doc = include_str!("gpu.md")]
pub mod gpu {}

#[doc = include_str!("architecture.md")]
pub mod architecture {}
