//! What is rendered: camera, medium, density sources, lights and render
//! settings, read from and written to RON, plus the loaders that turn a
//! density source into something that can be evaluated ([method §1](crate::doc::method)).
//!
//! This layer is a leaf: it knows nothing of the estimators. Every value that
//! comes from a file is validated here, so that the renderers can assume
//! finite, in-range inputs.

pub mod camera;
pub mod cloud;
pub mod environment;
pub mod error;
pub mod grid;
pub mod light;
pub mod medium;
pub mod settings;
pub mod volume;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use serde::{Deserialize, Serialize};

pub use camera::{Camera, CameraFrame};
pub use environment::{Environment, LoadedSky, Sky, SkyMap};
pub use error::SceneError;
pub use grid::VoxelGrid;
pub use light::Light;
pub use medium::{CloudParams, DensitySource, GridFormat, GridSource, Medium};
pub use settings::{Clock, InternalSettings, L1Form, Method, Quality, RenderSettings};

/// Largest image side accepted, in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// Largest scene file read, in bytes: a scene is a few kilobytes of RON,
/// so anything near this is not a scene (`lantern render /dev/zero` once
/// read without end).
pub const MAX_SCENE_BYTES: u64 = 4 << 20;

/// Largest number of external lights in a scene: each scattering event
/// traces a shadow ray to every light, so thousands make a render hundreds
/// of times slower (more than a few dozen already draw a warning).
pub const MAX_LIGHTS: usize = 1024;

/// Reads the UTF-8 text file `path`, refusing (before reading further) a
/// file longer than `limit` bytes; `what` names it in the message.
pub fn read_text(path: &Path, limit: u64, what: &str) -> Result<String, SceneError> {
    use std::io::Read;
    let io = |reason| SceneError::Io {
        path: path.to_owned(),
        reason,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    if file.metadata().map_err(io)?.is_dir() {
        return Err(SceneError::Io {
            path: path.to_owned(),
            reason: std::io::Error::other(format!("is a folder, not a {what}")),
        });
    }
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(SceneError::Io {
            path: path.to_owned(),
            reason: std::io::Error::other(format!(
                "is longer than {} MiB, far more than a {what} holds; not read further",
                limit >> 20
            )),
        });
    }
    String::from_utf8(bytes).map_err(|e| SceneError::Io {
        path: path.to_owned(),
        reason: std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "is not UTF-8 text (byte {} is not), so it is not a {what}",
                e.utf8_error().valid_up_to()
            ),
        ),
    })
}

/// A whole scene, as stored in a `.ron` file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// The camera.
    pub camera: Camera,
    /// The participating medium.
    pub medium: Medium,
    /// External lights.
    pub lights: Vec<Light>,
    /// The sky, if any: at most one environment per scene. Scenes written
    /// before environments existed have none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<Environment>,
    /// Render settings.
    #[serde(default)]
    pub render: RenderSettings,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            camera: Camera::default(),
            medium: Medium::default(),
            lights: vec![Light::Sun {
                direction: Vec3::new(-0.4, -1.0, -0.3),
                irradiance: Vec3::splat(3.0),
            }],
            environment: None,
            render: RenderSettings::default(),
        }
    }
}

/// The density field ready to evaluate: analytic shapes, or a grid loaded
/// from a file or baked from the procedural cloud.
#[derive(Clone, Debug)]
pub enum Density {
    /// `ρ = 1` inside the sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
    },
    /// `ρ = 1` inside the box.
    Box {
        /// Minimum corner.
        min: Vec3,
        /// Maximum corner.
        max: Vec3,
    },
    /// Trilinearly interpolated voxels.
    Grid(Arc<VoxelGrid>),
}

impl Density {
    /// Whether `other` is this very field: the same grid in memory, or the
    /// same analytic shape.
    pub fn same_field(&self, other: &Density) -> bool {
        match (self, other) {
            (Density::Grid(a), Density::Grid(b)) => Arc::ptr_eq(a, b),
            (
                Density::Sphere { center, radius },
                Density::Sphere {
                    center: c,
                    radius: r,
                },
            ) => center == c && radius == r,
            (Density::Box { min, max }, Density::Box { min: a, max: b }) => min == a && max == b,
            _ => false,
        }
    }

    /// The world-space box outside which `ρ = 0`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        match self {
            Density::Sphere { center, radius } => (
                *center - Vec3::splat(*radius),
                *center + Vec3::splat(*radius),
            ),
            Density::Box { min, max } => (*min, *max),
            Density::Grid(g) => (g.bounds_min, g.bounds_max),
        }
    }

    /// `ρ` at world point `p`.
    #[inline]
    pub fn density(&self, p: Vec3) -> f32 {
        match self {
            Density::Sphere { center, radius } => {
                if (p - *center).length_squared() <= radius * radius {
                    1.0
                } else {
                    0.0
                }
            }
            Density::Box { min, max } => {
                if p.cmpge(*min).all() && p.cmple(*max).all() {
                    1.0
                } else {
                    0.0
                }
            }
            Density::Grid(g) => {
                let (lo, hi) = (g.bounds_min, g.bounds_max);
                if p.cmpge(lo).all() && p.cmple(hi).all() {
                    g.sample(p)
                } else {
                    0.0
                }
            }
        }
    }

    /// An upper bound of `ρ` over the world box `[lo, hi]`.
    pub fn max_in_box(&self, lo: Vec3, hi: Vec3) -> f32 {
        match self {
            Density::Sphere { center, radius } => {
                let nearest = center.clamp(lo, hi);
                if (nearest - *center).length_squared() <= radius * radius {
                    1.0
                } else {
                    0.0
                }
            }
            Density::Box { min, max } => {
                if lo.cmple(*max).all() && hi.cmpge(*min).all() {
                    1.0
                } else {
                    0.0
                }
            }
            Density::Grid(g) => g.max_in_box(lo, hi),
        }
    }
}

impl Scene {
    /// Reads and validates a scene file. Grids are not loaded yet: see
    /// [`Scene::load_density`].
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = read_text(path, MAX_SCENE_BYTES, "scene file")?;
        Self::from_ron(&text, path)
    }

    /// Parses and validates RON text; `path` is only used in messages.
    pub fn from_ron(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let scene: Scene = ron::from_str(text).map_err(|e| SceneError::Parse {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        scene.validate(path)?;
        Ok(scene)
    }

    /// The scene as pretty RON text.
    pub fn to_ron(&self) -> Result<String, SceneError> {
        let pretty = ron::ser::PrettyConfig::new().struct_names(false);
        ron::ser::to_string_pretty(self, pretty).map_err(|e| SceneError::Write {
            path: PathBuf::from("<memory>"),
            reason: e.to_string(),
        })
    }

    /// Writes the scene as RON, whole or not at all (a failed save leaves
    /// the previous file unchanged and says so).
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        let text = self.to_ron()?;
        crate::atomic::write_bytes(path, text.as_bytes()).map_err(SceneError::from)
    }

    /// Checks every value against its allowed range; `path` names the
    /// scene in the error.
    pub fn validate(&self, path: &Path) -> Result<(), SceneError> {
        let bad = |field: &str, reason: String| Err(SceneError::invalid(path, field, reason));
        let finite3 = |v: Vec3| v.is_finite();

        let c = &self.camera;
        if c.width == 0 || c.height == 0 {
            return bad(
                "camera.width/height",
                format!("image size {}×{} is empty", c.width, c.height),
            );
        }
        if c.width > MAX_IMAGE_SIDE || c.height > MAX_IMAGE_SIDE {
            return bad(
                "camera.width/height",
                format!(
                    "image size {}×{} exceeds {MAX_IMAGE_SIDE} pixels per side",
                    c.width, c.height
                ),
            );
        }
        if !(finite3(c.eye) && finite3(c.target) && finite3(c.up)) {
            return bad("camera", "eye, target and up must be finite".into());
        }
        let forward = c.target - c.eye;
        if forward.length_squared() < 1e-12 {
            return bad("camera.target", "target coincides with eye".into());
        }
        if forward.normalize().cross(c.up.normalize_or_zero()).length() < 1e-4 {
            return bad(
                "camera.up",
                "up is zero or parallel to the view direction".into(),
            );
        }
        if !(c.fov_y_deg.is_finite() && c.fov_y_deg > 0.0 && c.fov_y_deg < 179.0) {
            return bad(
                "camera.fov_y_deg",
                format!("{} is outside (0, 179) degrees", c.fov_y_deg),
            );
        }

        let m = &self.medium;
        if !(finite3(m.sigma_t) && m.sigma_t.min_element() >= 0.0) {
            return bad(
                "medium.sigma_t",
                format!("{:?} must be finite and non-negative", m.sigma_t.to_array()),
            );
        }
        if m.sigma_t.max_element() > 1e6 {
            return bad(
                "medium.sigma_t",
                format!("{:?} exceeds 1e6 per unit length", m.sigma_t.to_array()),
            );
        }
        if !(finite3(m.albedo) && m.albedo.min_element() >= 0.0 && m.albedo.max_element() <= 1.0) {
            return bad(
                "medium.albedo",
                format!("{:?} must lie in [0, 1]", m.albedo.to_array()),
            );
        }
        if !(m.g.is_finite() && m.g.abs() < 1.0) {
            return bad("medium.g", format!("{} must lie in (-1, 1)", m.g));
        }
        if !(m.density_scale.is_finite() && m.density_scale >= 0.0) {
            return bad(
                "medium.density_scale",
                format!("{} must be finite and non-negative", m.density_scale),
            );
        }
        match &m.density {
            DensitySource::Sphere { center, radius } => {
                if !(finite3(*center) && radius.is_finite() && *radius > 0.0) {
                    return bad(
                        "medium.density.Sphere",
                        "centre must be finite and radius positive".into(),
                    );
                }
            }
            DensitySource::Box { min, max } => {
                if !(finite3(*min) && finite3(*max) && max.cmpgt(*min).all()) {
                    return bad(
                        "medium.density.Box",
                        "min and max must be finite with max > min on every axis".into(),
                    );
                }
            }
            DensitySource::Cloud(p) => cloud::validate(p, path)?,
            DensitySource::Grid(g) => {
                if let Some((lo, hi)) = g.bounds {
                    if !(finite3(lo) && finite3(hi) && hi.cmpgt(lo).all()) {
                        return bad(
                            "medium.density.Grid.bounds",
                            "bounds must be finite with max > min on every axis".into(),
                        );
                    }
                }
            }
        }

        if self.lights.len() > MAX_LIGHTS {
            return bad(
                "lights",
                format!(
                    "{} external lights: at most {MAX_LIGHTS} are accepted, since every \
                     scattering event traces a shadow ray to each (about {} times the work of \
                     one light)",
                    self.lights.len(),
                    self.lights.len()
                ),
            );
        }
        for (i, light) in self.lights.iter().enumerate() {
            match light {
                Light::Sun {
                    direction,
                    irradiance,
                } => {
                    if !(finite3(*direction) && direction.length_squared() > 1e-12) {
                        return bad(
                            &format!("lights[{i}].direction"),
                            "must be finite and non-zero".into(),
                        );
                    }
                    if !(finite3(*irradiance) && irradiance.min_element() >= 0.0) {
                        return bad(
                            &format!("lights[{i}].irradiance"),
                            "must be finite and non-negative".into(),
                        );
                    }
                }
                Light::Point {
                    position,
                    intensity,
                } => {
                    if !finite3(*position) {
                        return bad(&format!("lights[{i}].position"), "must be finite".into());
                    }
                    if !(finite3(*intensity) && intensity.min_element() >= 0.0) {
                        return bad(
                            &format!("lights[{i}].intensity"),
                            "must be finite and non-negative".into(),
                        );
                    }
                }
            }
        }
        if let Some(env) = &self.environment {
            env.validate(path, self.first_sun())?;
        }
        if self.render.spp == 0 {
            return bad("render.spp", "must be at least 1".into());
        }
        self.render.internal.validate(path)
    }

    /// The direction the scene's first sun's light travels, if it has one
    /// (what a clear sky follows).
    pub fn first_sun(&self) -> Option<Vec3> {
        self.lights.iter().find_map(|l| match l {
            Light::Sun { direction, .. } => Some(direction.normalize_or_zero()),
            Light::Point { .. } => None,
        })
    }

    /// Loads the environment map (relative to `scene_dir`, the folder of
    /// the scene file) or bakes the clear sky; `None` without an
    /// environment.
    pub fn load_environment(&self, scene_dir: &Path) -> Result<Option<LoadedSky>, SceneError> {
        self.environment
            .as_ref()
            .map(|env| env.load(scene_dir, self.first_sun()))
            .transpose()
    }

    /// Loads or bakes the density field. Relative grid paths are resolved
    /// against `scene_dir` (the folder of the scene file).
    pub fn load_density(&self, scene_dir: &Path) -> Result<Density, SceneError> {
        match &self.medium.density {
            DensitySource::Sphere { center, radius } => Ok(Density::Sphere {
                center: *center,
                radius: *radius,
            }),
            DensitySource::Box { min, max } => Ok(Density::Box {
                min: *min,
                max: *max,
            }),
            DensitySource::Cloud(p) => Ok(Density::Grid(Arc::new(cloud::bake(p)))),
            DensitySource::Grid(src) => {
                let path = scene_dir.join(&src.path);
                let mut grid = volume::load_grid(&path, src.format, src.grid_name.as_deref())?;
                if let Some((lo, hi)) = src.bounds {
                    grid.bounds_min = lo;
                    grid.bounds_max = hi;
                }
                Ok(Density::Grid(Arc::new(grid)))
            }
        }
    }
}

impl InternalSettings {
    /// Checks every parameter against its allowed range; `path` names the
    /// scene in the error (fields are reported as `render.internal.*`).
    pub fn validate(&self, path: &Path) -> Result<(), SceneError> {
        use settings::{MAX_INTERNAL_LIGHTS, MAX_TERMS, MAX_WALKS};
        let bad = |field: &str, reason: String| {
            Err(SceneError::invalid(
                path,
                &format!("render.internal.{field}"),
                reason,
            ))
        };
        if let Some(s) = self.knobs.s_star {
            if !(s.is_finite() && s > 0.0) {
                return bad("s_star", format!("{s} must be finite and positive"));
            }
        }
        if self.knobs.lights == 0 || self.knobs.lights > MAX_INTERNAL_LIGHTS {
            return bad(
                "lights",
                format!(
                    "M = {} must lie in 1..={MAX_INTERNAL_LIGHTS}",
                    self.knobs.lights
                ),
            );
        }
        if self.knobs.terms > MAX_TERMS {
            return bad(
                "terms",
                format!("N = {} exceeds {MAX_TERMS}", self.knobs.terms),
            );
        }
        if self.expert.walks == 0 || self.expert.walks > MAX_WALKS {
            return bad(
                "walks",
                format!("K = {} must lie in 1..={MAX_WALKS}", self.expert.walks),
            );
        }
        if self.expert.sh_order > settings::MAX_SH_ORDER {
            return bad(
                "sh_order",
                format!(
                    "{} exceeds the highest supported order {}",
                    self.expert.sh_order,
                    settings::MAX_SH_ORDER
                ),
            );
        }
        if let Some(h) = self.expert.kernel_radius {
            if !(h.is_finite() && h > 0.0) {
                return bad("kernel_radius", format!("{h} must be finite and positive"));
            }
        }
        if !(self.expert.uniform_mix.is_finite() && (0.0..=1.0).contains(&self.expert.uniform_mix))
        {
            return bad(
                "uniform_mix",
                format!("{} must lie in [0, 1]", self.expert.uniform_mix),
            );
        }
        let most = settings::MAX_GATHER_POINTS as u32;
        if self.expert.light_samples == 0 || self.expert.light_samples > most {
            return bad(
                "light_samples",
                format!("{} must lie in 1..={most}", self.expert.light_samples),
            );
        }
        if self.expert.view_walks > MAX_WALKS {
            return bad(
                "view_walks",
                format!("{} must lie in 0..={MAX_WALKS}", self.expert.view_walks),
            );
        }
        let most = settings::MAX_WINDOW_SCATTERS;
        if self.expert.window_scatters == 0 || self.expert.window_scatters > most {
            return bad(
                "window_scatters",
                format!("{} must lie in 1..={most}", self.expert.window_scatters),
            );
        }
        Ok(())
    }
}
