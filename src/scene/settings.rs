//! Render settings stored with the scene: which estimator, how many
//! samples, the seed that makes a render reproducible, and the parameters
//! of the internal-lights method (METHOD.md §3–§7).

use serde::{Deserialize, Serialize};

/// Which estimator renders the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// The unbiased volumetric path tracer (METHOD.md §2): the ground truth.
    #[default]
    Reference,
    /// Multiple scatter as internal lights (METHOD.md §3–§6).
    Internal,
}

/// What the path-length clock of the internal-lights method counts
/// (METHOD.md §3, §7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ClockKind {
    /// Geometric path length, as in Tessendorf's note: `s*` is a distance.
    Geometric,
    /// Optical depth `∫ max(σ_t) ρ dℓ`: `s*` is a number of mean free
    /// paths, so every window holds on average `s*` collisions.
    #[default]
    OpticalDepth,
}

/// The form of the final gather's single-scatter term `L₁` (METHOD.md §6;
/// the README's "The internal-lights renderer" says how they differ).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum L1Kind {
    /// One scattering of the kernel-reconstructed field `J` (no bounded
    /// kernel, no softening bias).
    #[default]
    Field,
    /// Tessendorf's sum over the point lights with the bounded kernel
    /// `1/(r² + h₁²)`.
    Points,
}

/// Parameters of the internal-lights method. Changing any of them
/// re-samples the internal lights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InternalSettings {
    /// Window length `s*` (world units for the geometric clock, mean free
    /// paths for the optical-depth clock); `None`: the diagonal of the
    /// medium's box (geometric) or its optical depth along the diagonal
    /// through the densest majorant (optical depth), see the README.
    pub s_star: Option<f32>,
    /// Number of internal lights `M`.
    pub lights: u32,
    /// Series truncation `N`: terms `k = 0..=N`.
    pub terms: u32,
    /// Time-gated walks per light `K`.
    pub walks: u32,
    /// Order of the real spherical harmonics that store `F` and `J`.
    pub sh_order: u32,
    /// Kernel radius `h` (world units); `None`: the mean light spacing.
    pub kernel_radius: Option<f32>,
    /// Uniform fraction `u` of the placement density.
    pub uniform_mix: f32,
    /// What the path-length clock counts.
    pub clock: ClockKind,
    /// The form of the gather's `L₁`.
    pub l1: L1Kind,
    /// Scatterings inside the final window that the field form of `L₁`
    /// follows: 1 is the note's single-scatter kernel (METHOD.md §6), 2
    /// and 3 add the next terms of the window's transport (see the
    /// README, "Scatterings inside the window").
    pub window_scatters: u32,
    /// Walks per light along the direction towards the camera, for the
    /// view's `L₀` (0: none, `L₀` reads the lights' spherical harmonics;
    /// see the README, "Walks towards the eye").
    pub view_walks: u32,
    /// Internal-light samples per camera sample in the final gather.
    pub light_samples: u32,
    /// Passes rendered with one set of internal lights before a fresh set
    /// (same parameters, the next seed of the render's seed) replaces it;
    /// 0 keeps one set for the whole render. One set's walk noise is fixed
    /// for all its passes, so with 0 the passes converge to the image of
    /// those lights; with sets drawn afresh they converge to the method's
    /// expectation over light sets, the walk noise averaging out like
    /// pixel noise.
    pub resample_every: u32,
}

impl Default for InternalSettings {
    fn default() -> Self {
        Self {
            s_star: None,
            lights: 4096,
            terms: 16,
            walks: 64,
            sh_order: 3,
            kernel_radius: None,
            uniform_mix: 0.0,
            clock: ClockKind::OpticalDepth,
            l1: L1Kind::Field,
            window_scatters: 1,
            view_walks: 0,
            light_samples: 2,
            resample_every: 0,
        }
    }
}

/// Largest accepted number of internal lights (memory: about 1 KiB each
/// at SH order 4).
pub const MAX_INTERNAL_LIGHTS: u32 = 1 << 20;
/// Largest accepted series truncation `N`.
pub const MAX_TERMS: u32 = 4096;
/// Largest accepted number of walks per light `K`.
pub const MAX_WALKS: u32 = 1 << 16;

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
    /// Parameters of the internal-lights method.
    pub internal: InternalSettings,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            method: Method::Reference,
            spp: 64,
            seed: 0,
            internal: InternalSettings::default(),
        }
    }
}
