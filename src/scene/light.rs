//! External lights: a sun and point lights ([method §1](crate::doc::method)).
//!
//! Units follow Mitsuba 3: the sun is its `directional` emitter (`direction`
//! is the direction light travels, `irradiance` in W/m² on a surface
//! perpendicular to it) and a point light is its `point` emitter
//! (`intensity` in W/sr). Both are RGB.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// One external light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Light {
    /// A directional light at infinity.
    Sun {
        /// Direction in which the light travels (need not be normalised).
        direction: Vec3,
        /// Irradiance on a surface perpendicular to `direction`, RGB, W/m².
        irradiance: Vec3,
    },
    /// An isotropic point light.
    Point {
        /// Position in world space.
        position: Vec3,
        /// Radiant intensity, RGB, W/sr.
        intensity: Vec3,
    },
}
