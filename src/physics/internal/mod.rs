//! The internal-lights method ([method](crate::doc::method)): multiple
//! scattering split by path length into windows of a clock, the light that
//! has travelled `k` windows turned into sources `J` held by `M` points in
//! the medium, and a short single-scatter march over one window that
//! gathers them.
//!
//! The files follow the method's steps, each with its tests:
//!
//! - [`clock`]: what the clock counts (distance or grey optical depth) and
//!   how it is marched along a ray (§3, §7);
//! - [`walk`]: the time-gated backward walk that estimates the series
//!   `J_N = Σ_k G(k s*) S₁` at a point (§4), with [`guiding`] for its
//!   directions after a collision and [`chances`] for the chance that it
//!   collides at all;
//! - [`placement`] and [`view_placement`]: where the `M` lights stand (§5);
//! - [`sources`]: the lights themselves, `S₁`, `F` and `J` at each, built
//!   from the walks and stored as spherical harmonics (§5);
//! - [`light_index`] and [`reconstruction`]: the lights near a point and
//!   the kernel average of their `J` there (§6);
//! - [`segment_pdf`] and [`gather`]: the final gather along a camera ray,
//!   `L ≈ L₀ + L₁` (§6).
//!
//! The CPU renderer (`crate::cpu`) calls these per sample; the GPU's
//! WGSL (`shaders/`) mirrors them.

pub mod chances;
pub mod clock;
pub mod gather;
pub mod guiding;
pub mod light_index;
pub mod placement;
pub mod reconstruction;
pub mod segment_pdf;
pub mod sources;
pub mod view_placement;
pub mod walk;
