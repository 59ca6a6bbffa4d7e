//! External lights in the form the estimators use (METHOD.md §1): unit
//! directions, and the first-scatter source `S₁` they produce at a point.

use glam::Vec3;

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
const MIN_DIST2: f32 = 1e-8;

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
            let v = p - l.position;
            let d2 = v.length_squared().max(MIN_DIST2);
            let d = d2.sqrt();
            f(LightSample {
                travel: v / d,
                distance: d,
                irradiance: l.intensity / d2,
            });
        }
    }

    /// Whether there is no light at all.
    pub fn is_empty(&self) -> bool {
        self.suns.is_empty() && self.points.is_empty()
    }
}
