//! Backend-neutral rendering: the prepared scene (camera frame, volume,
//! lights) that every estimator reads, the progressive film that passes
//! accumulate into, display transforms, and image export.
//!
//! Sits above `scene` and `physics`; the `cpu` (and later `gpu`) backends
//! sit above it. Nothing here knows about threads or the user interface.

pub mod export;
pub mod film;
pub mod limits;
pub mod plot;
pub mod prepared;
pub mod renewal;
pub mod stats;
pub mod tonemap;

pub use film::Film;
pub use prepared::{
    default_s_star, internal_params, internal_params_for_set, light_set, light_set_starting,
    PreparedScene, SceneVolume,
};
