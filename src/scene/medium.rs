//! The participating medium: where the density is, how strongly it
//! extinguishes and scatters, and its phase function ([method §1](crate::doc::method)).
//!
//! Extinction is `c(x) = density_scale · σ_t · ρ(x)` per RGB channel and
//! scattering `b(x) = α c(x)`, exactly as Mitsuba 3's `heterogeneous` medium
//! (`sigma_t` × `scale`, `albedo`) and `homogeneous` medium read them. The
//! phase function is Henyey–Greenstein with Mitsuba's sign convention
//! (`g > 0` scatters forward).

use std::path::PathBuf;

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// The medium: a density source and its optical properties.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Medium {
    /// Where the density `ρ` comes from.
    pub density: DensitySource,
    /// Multiplies the density everywhere (artist's overall thickness knob).
    #[serde(default = "one")]
    pub density_scale: f32,
    /// Extinction cross-section per unit density, RGB, in 1/world units.
    pub sigma_t: Vec3,
    /// Single-scattering albedo, RGB, each in [0, 1].
    pub albedo: Vec3,
    /// Henyey–Greenstein asymmetry, in (−1, 1); positive scatters forward.
    #[serde(default)]
    pub g: f32,
}

fn one() -> f32 {
    1.0
}

impl Default for Medium {
    fn default() -> Self {
        Self {
            density: DensitySource::Cloud(CloudParams::default()),
            density_scale: 1.0,
            sigma_t: Vec3::splat(8.0),
            albedo: Vec3::splat(0.95),
            g: 0.6,
        }
    }
}

/// Where the density field `ρ(x)` comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum DensitySource {
    /// `ρ = 1` inside a sphere, 0 outside.
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius in world units.
        radius: f32,
    },
    /// `ρ = 1` inside an axis-aligned box, 0 outside.
    Box {
        /// Minimum corner.
        min: Vec3,
        /// Maximum corner.
        max: Vec3,
    },
    /// A procedural cloud (fBm noise shaped by an ellipsoid), baked into a
    /// voxel grid when the scene is loaded.
    Cloud(CloudParams),
    /// A voxel grid read from a file.
    Grid(GridSource),
}

/// Knobs of the procedural cloud. Defaults give a cumulus-like puff.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CloudParams {
    /// Noise seed: each seed is a different cloud.
    pub seed: u32,
    /// Centre of the cloud's bounding box.
    pub center: Vec3,
    /// Full size of the bounding box along each axis.
    pub size: Vec3,
    /// Voxels along the longest axis of the baked grid.
    pub resolution: u32,
    /// How much of the ellipsoid is filled, 0 (nothing) to 1 (solid core).
    pub coverage: f32,
    /// Spatial frequency of the largest noise octave, per box size.
    pub frequency: f32,
    /// Number of fBm octaves.
    pub octaves: u32,
    /// Strength of the noise relative to the ellipsoid shape.
    pub roughness: f32,
    /// Width of the soft edge (0 gives hard edges).
    pub softness: f32,
    /// Flattens the bottom of the cloud, 0 (round) to 1 (flat base).
    pub flat_base: f32,
}

impl Default for CloudParams {
    fn default() -> Self {
        Self {
            seed: 7,
            center: Vec3::ZERO,
            size: Vec3::new(2.4, 1.6, 2.0),
            resolution: 96,
            coverage: 0.55,
            frequency: 2.2,
            octaves: 5,
            roughness: 0.55,
            softness: 0.12,
            flat_base: 0.6,
        }
    }
}

/// A voxel grid on disk.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSource {
    /// Path of the file, relative to the scene file's folder. For raw
    /// float32 data this is the RON header file that describes it.
    pub path: PathBuf,
    /// File format; `Auto` picks it from the extension.
    #[serde(default)]
    pub format: GridFormat,
    /// For OpenVDB files: the float grid to read (default `density`).
    #[serde(default)]
    pub grid_name: Option<String>,
    /// World-space bounds `(min, max)` overriding those stored in the file.
    #[serde(default)]
    pub bounds: Option<(Vec3, Vec3)>,
}

/// Supported voxel-grid file formats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum GridFormat {
    /// From the extension: `.vdb`, `.vol`, or `.ron` (raw header).
    #[default]
    Auto,
    /// Raw little-endian float32 described by a RON header file.
    Raw,
    /// Mitsuba 3 `.vol` (binary, float32).
    MitsubaVol,
    /// OpenVDB `.vdb`, one float grid.
    Vdb,
}
