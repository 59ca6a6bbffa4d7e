//! Pure mathematics of light transport on `glam` types: random numbers,
//! the Henyey–Greenstein phase function, majorant grids, delta/spectral and
//! ratio tracking, and the estimators built from them ([method §1–§2](crate::doc::method)).
//!
//! This layer is a leaf: it knows nothing of scene files, of threads or of
//! the user interface. A medium is anything that implements
//! [`volume::DensityField`]; the renderers in `cpu/` (and the WGSL mirrors in
//! `shaders/`) call these functions per sample.

pub mod environment;
pub mod frame;
pub mod internal;
pub mod lights;
pub mod majorant;
pub mod phase;
pub mod reference;
pub mod rng;
pub mod sh;
#[cfg(test)]
pub(crate) mod testing;
pub mod tracking;
pub mod volume;
