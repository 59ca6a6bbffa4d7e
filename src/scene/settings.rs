//! Render settings stored with the scene: which estimator, how many
//! samples, and the seed that makes a render reproducible.

use serde::{Deserialize, Serialize};

/// Which estimator renders the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// The unbiased volumetric path tracer (METHOD.md §2): the ground truth.
    #[default]
    Reference,
}

/// Settings of a render, saved with the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSettings {
    /// The estimator.
    pub method: Method,
    /// Samples per pixel of a finished still.
    pub spp: u32,
    /// Seed of every random stream: the same seed gives the same image.
    pub seed: u64,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            method: Method::Reference,
            spp: 64,
            seed: 0,
        }
    }
}
