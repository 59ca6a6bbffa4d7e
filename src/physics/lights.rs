//! External lights in the form the estimators use ([method §1](crate::doc::method)): unit
//! directions, and the first-scatter source `S₁` they produce at a point;
//! the environment, if any, rides along ([`super::environment`]).

use std::sync::Arc;

use glam::Vec3;

use super::environment::Environment;

/// A directional light at infinity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sun {
    /// Unit direction in which the light travels.
    pub direction: Vec3,
    /// Irradiance perpendicular to `direction`, RGB.
    pub irradiance: Vec3,
}

/// An isotropic point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// Position in world space.
    pub position: Vec3,
    /// Intensity in W/sr, RGB.
    pub intensity: Vec3,
}

/// All external lights of a scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Lights {
    /// Directional lights.
    pub suns: Vec<Sun>,
    /// Point lights.
    pub points: Vec<PointLight>,
    /// The sky, if the scene has one. [`Lights::for_each_at`] does not
    /// visit it (it is no single direction); the first-scatter source adds
    /// it ([`super::reference::single_scatter_source`]).
    pub environment: Option<Arc<Environment>>,
}

/// The light arriving at a point from one external light, before
/// attenuation: where it comes from and how strong it is.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction in which the light travels at the point.
    pub travel: Vec3,
    /// Distance to the light along `-travel` (infinite for a sun).
    pub distance: f32,
    /// Unattenuated irradiance at the point, RGB.
    pub irradiance: Vec3,
}

/// Smallest squared distance to a point light, so that `1/r²` stays finite.
pub const MIN_DIST2: f32 = 1e-8;

/// Beyond this offset along an axis a point light is "far": `|v|²` could
/// overflow `f32` (`(10¹⁹)² = 10³⁸` of `3.4·10³⁸`), so its distance and
/// direction are computed from `v` scaled down by its largest component.
pub const FAR_LIGHT: f32 = 1e19;

/// The arrival from a point light of `intensity` at offset `v` (from the
/// light to the point). Exact for any finite `v`: a light at `3·10¹⁹` once
/// gave an infinite `|v|²`, a zero direction and a shadow ray of infinite
/// length whose tracking never ended.
#[inline]
pub fn point_sample(v: Vec3, intensity: Vec3) -> LightSample {
    let s = v.abs().max_element();
    if s <= FAR_LIGHT {
        let d2 = v.length_squared().max(MIN_DIST2);
        let d = d2.sqrt();
        return LightSample {
            travel: v / d,
            distance: d,
            irradiance: intensity / d2,
        };
    }
    // `u` has components in [−1, 1], one of them ±1: `|u| ∈ [1, √3]`.
    let u = v / s;
    let lu = u.length();
    LightSample {
        travel: u / lu,
        // Past `f32::MAX` only for `s > 1.96·10³⁸`; the shadow ray is
        // clipped to the medium's box, so the largest finite length does.
        distance: (s * lu).min(f32::MAX),
        // `I / d²` without forming `d²`.
        irradiance: intensity / s / lu / s / lu,
    }
}

impl Lights {
    /// Calls `f` once per light with its unattenuated arrival at `p`.
    #[inline]
    pub fn for_each_at(&self, p: Vec3, mut f: impl FnMut(LightSample)) {
        for s in &self.suns {
            f(LightSample {
                travel: s.direction,
                distance: f32::INFINITY,
                irradiance: s.irradiance,
            });
        }
        for l in &self.points {
            f(point_sample(p - l.position, l.intensity));
        }
    }

    /// Whether there is no light at all (no sun, no point light, no sky
    /// that is not black).
    pub fn is_empty(&self) -> bool {
        self.suns.is_empty()
            && self.points.is_empty()
            && self.environment.as_ref().is_none_or(|e| e.is_black())
    }

    /// The environment, unless there is none or it is black.
    #[inline]
    pub fn sky(&self) -> Option<&Environment> {
        self.environment.as_deref().filter(|e| !e.is_black())
    }
}
