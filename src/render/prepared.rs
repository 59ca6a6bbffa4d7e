//! A scene turned into what the estimators need: the camera frame, the
//! density field with its majorant grid, and the lights as unit vectors.

use std::path::Path;

use glam::Vec3;

use crate::physics::lights::{Lights, PointLight, Sun};
use crate::physics::volume::{DensityField, Optics, Volume};
use crate::scene::{CameraFrame, Density, Light, Scene, SceneError};

/// Majorant cells along the longest axis of the medium's box.
pub const MAJORANT_CELLS: u32 = 32;

/// The medium type every CPU estimator runs on.
pub type SceneVolume = Volume<Density>;

impl DensityField for Density {
    #[inline]
    fn density(&self, p: Vec3) -> f32 {
        Density::density(self, p)
    }
    fn bounds(&self) -> (Vec3, Vec3) {
        Density::bounds(self)
    }
    fn max_in_box(&self, lo: Vec3, hi: Vec3) -> f32 {
        Density::max_in_box(self, lo, hi)
    }
}

/// Everything a renderer needs for one scene.
pub struct Prepared {
    /// The scene as loaded (settings included).
    pub scene: Scene,
    /// Ray generation.
    pub camera: CameraFrame,
    /// The medium.
    pub volume: SceneVolume,
    /// External lights.
    pub lights: Lights,
}

impl Prepared {
    /// Loads the density (grids are read relative to `scene_dir`) and
    /// builds the volume.
    pub fn new(scene: Scene, scene_dir: &Path) -> Result<Self, SceneError> {
        let density = scene.load_density(scene_dir)?;
        Ok(Self::with_density(scene, density))
    }

    /// Builds from an already loaded density field.
    pub fn with_density(scene: Scene, density: Density) -> Self {
        let m = &scene.medium;
        let optics = Optics {
            sigma_t: m.sigma_t * m.density_scale,
            albedo: m.albedo,
            g: m.g,
        };
        let volume = Volume::new(density, optics, MAJORANT_CELLS);
        let lights = lights_of(&scene.lights);
        Self {
            camera: scene.camera.frame(),
            volume,
            lights,
            scene,
        }
    }
}

/// Converts scene lights to the estimators' form (unit directions).
pub fn lights_of(lights: &[Light]) -> Lights {
    let mut out = Lights::default();
    for l in lights {
        match *l {
            Light::Sun {
                direction,
                irradiance,
            } => out.suns.push(Sun {
                direction: direction.normalize_or_zero(),
                irradiance,
            }),
            Light::Point {
                position,
                intensity,
            } => out.points.push(PointLight {
                position,
                intensity,
            }),
        }
    }
    out
}
