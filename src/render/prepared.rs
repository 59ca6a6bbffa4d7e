//! A scene turned into what the estimators need: the camera frame, the
//! density field with its majorant grid, the lights as unit vectors, and
//! (built when first needed) the internal lights' placement density.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, PoisonError};

use glam::Vec3;

use crate::physics::environment::{EnvMap, Environment, EnvironmentKind};
use crate::physics::internal::placement::PlacementDensity;
use crate::physics::internal::sources::{
    kernel_neighbours_for_set, placement_density, walk_split, InternalLights, InternalParams,
};
use crate::physics::internal::view_placement::ViewFrame;
use crate::physics::lights::{Lights, PointLight, Sun};
use crate::physics::volume::{DensityField, Optics, Volume};
use crate::scene::settings::DEFAULT_S_STAR;
use crate::scene::{
    CameraFrame, Clock, Density, Light, LoadedSky, RenderSettings, Scene, SceneError, Sky,
};

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

/// The largest optical depth per voxel that the renderers march: denser
/// media have their extinction clamped to it (see [`DenseLimit`]).
///
/// At this depth one voxel transmits `e^{-100} ≈ 3.7·10⁻⁴⁴`, below the
/// smallest normal `f32` (`1.2·10⁻³⁸`): as opaque as the estimators' `f32`
/// arithmetic can say. Denser voxels only move the medium's lit surface
/// less than a hundredth of a voxel further out, while delta and ratio
/// tracking take about one step per unit of majorant optical depth, so a
/// voxel of `σ_t ρ = 10⁶` per unit length would cost millions of steps per
/// ray (the hang of issue 23) and a `density_scale` of `10²⁰` overflows
/// `f32` in spectral tracking's probabilities (a black image).
pub const MAX_DEPTH_PER_VOXEL: f32 = 100.0;

/// A medium denser than [`MAX_DEPTH_PER_VOXEL`], and what was done: its
/// extinction is clamped to `limit` per unit length, so that it renders as
/// the opaque lit surface it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenseLimit {
    /// The largest extinction of the medium as given, per unit length
    /// (`density_scale · max σ_t · max ρ`).
    pub peak: f64,
    /// The extinction it is clamped to, per unit length:
    /// [`MAX_DEPTH_PER_VOXEL`] over `voxel`.
    pub limit: f64,
    /// The length the limit refers to: the smallest side of a voxel (for
    /// the analytic shapes, of a majorant cell).
    pub voxel: f32,
    /// The fraction of voxels that were clamped (1 for analytic shapes).
    pub clamped_fraction: f64,
}

impl std::fmt::Display for DenseLimit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the extinction reaches {:.3e} per unit length (density_scale × σ_t × density), \
             {:.1e} mean free paths across a voxel of {:.3e} (for a sphere or box, a \
             {MAJORANT_CELLS}th of its size), more than the {MAX_DEPTH_PER_VOXEL} the renderers \
             march; clamped to {:.3e} per unit length",
            self.peak,
            self.peak * self.voxel as f64,
            self.voxel,
            self.limit,
        )?;
        if self.clamped_fraction < 1.0 {
            write!(
                f,
                " in {:.3} % of the voxels",
                100.0 * self.clamped_fraction
            )?;
        }
        write!(f, ", where the medium renders as an opaque lit surface")
    }
}

/// The length a medium's density varies over: a voxel's smallest side
/// for a grid, a majorant cell's for the analytic shapes (whose density
/// is constant inside).
pub fn feature_length(density: &Density) -> f32 {
    match density {
        Density::Grid(g) => g.voxel_size().min_element(),
        _ => {
            let (lo, hi) = density.bounds();
            (hi - lo).max_element() / MAJORANT_CELLS as f32
        }
    }
}

/// The optics of `medium` over `density`, with extinction above
/// [`MAX_DEPTH_PER_VOXEL`] clamped (then the density and what was done
/// are returned changed). Media within the limit keep their density and
/// `σ_t · density_scale` exactly.
fn clamp_dense(
    medium: &crate::scene::Medium,
    density: Density,
) -> (Optics, Density, Option<DenseLimit>) {
    let sigma = medium.sigma_t.as_dvec3() * medium.density_scale as f64;
    let plain = Optics {
        sigma_t: medium.sigma_t * medium.density_scale,
        albedo: medium.albedo,
        g: medium.g,
    };
    let voxel = feature_length(&density);
    let limit = MAX_DEPTH_PER_VOXEL as f64 / voxel.max(f32::MIN_POSITIVE) as f64;
    let sigma_max = sigma.max_element();
    let finite = plain.sigma_t.is_finite();
    match density {
        Density::Grid(grid) => {
            let peak = sigma_max * grid.max_value() as f64;
            if peak <= limit && finite {
                return (plain, Density::Grid(grid), None);
            }
            // ρ' = min(ρ σ_max / limit, 1) and σ' = σ limit / σ_max: the
            // same product σ'ρ' = σρ below the limit, the limit above it,
            // every factor finite.
            let k = sigma_max / limit;
            let mut clamped = 0usize;
            let data: Vec<f32> = grid
                .data
                .iter()
                .map(|&v| {
                    let scaled = v as f64 * k;
                    if scaled > 1.0 {
                        clamped += 1;
                        1.0
                    } else {
                        scaled as f32
                    }
                })
                .collect();
            let fraction = clamped as f64 / grid.data.len().max(1) as f64;
            let grid = crate::scene::VoxelGrid {
                data,
                ..(*grid).clone()
            };
            let optics = Optics {
                sigma_t: (sigma * (limit / sigma_max)).as_vec3(),
                ..plain
            };
            let note = (peak > limit).then_some(DenseLimit {
                peak,
                limit,
                voxel,
                clamped_fraction: fraction,
            });
            (optics, Density::Grid(Arc::new(grid)), note)
        }
        analytic => {
            // ρ is 0 or 1: clamp each channel.
            if sigma_max <= limit && finite {
                return (plain, analytic, None);
            }
            let optics = Optics {
                sigma_t: sigma.min(glam::DVec3::splat(limit)).as_vec3(),
                ..plain
            };
            let note = DenseLimit {
                peak: sigma_max,
                limit,
                voxel,
                clamped_fraction: 1.0,
            };
            (optics, analytic, Some(note))
        }
    }
}

/// Everything a renderer needs for one scene.
pub struct PreparedScene {
    /// The scene as loaded (settings included).
    pub scene: Scene,
    /// Ray generation.
    pub camera: CameraFrame,
    /// The medium.
    pub volume: SceneVolume,
    /// External lights.
    pub lights: Lights,
    /// Set when the medium was denser than the renderers march and its
    /// extinction was clamped (see [`MAX_DEPTH_PER_VOXEL`]).
    pub dense: Option<DenseLimit>,
    /// The internal lights' placement density for one `u_mix` (its bits),
    /// built when first needed: like the majorant grid it depends on the
    /// medium only, so re-sampling after a change of `s*`, `M`, `N`, `K`,
    /// `g` or the seed (a renewed light set) reuses it.
    placement: Arc<PlacementCache>,
    /// The density field as given (before any clamp): what
    /// [`PreparedScene::with_scene`] compares.
    given: Density,
}

impl PreparedScene {
    /// Loads the density and the environment map (both read relative to
    /// `scene_dir`) and builds the volume.
    pub fn new(scene: Scene, scene_dir: &Path) -> Result<Self, SceneError> {
        let density = scene.load_density(scene_dir)?;
        let sky = scene.load_environment(scene_dir)?;
        Ok(Self::with_loaded(scene, density, sky))
    }

    /// Builds from an already loaded density field; a medium denser than
    /// [`MAX_DEPTH_PER_VOXEL`] is clamped (and `dense` says so). A constant
    /// or clear sky is built here; an environment *map* is not read (use
    /// [`PreparedScene::with_loaded`] with [`Scene::load_environment`]), and
    /// without it the scene has no sky.
    pub fn with_density(scene: Scene, density: Density) -> Self {
        let sky = match scene.environment.as_ref().map(|e| &e.sky) {
            Some(Sky::Map { .. }) | None => None,
            Some(_) => scene.load_environment(Path::new("")).ok().flatten(),
        };
        Self::with_loaded(scene, density, sky)
    }

    /// Builds from an already loaded density field and environment
    /// ([`Scene::load_environment`]).
    pub fn with_loaded(scene: Scene, density: Density, sky: Option<LoadedSky>) -> Self {
        let given = density.clone();
        let (optics, density, dense) = clamp_dense(&scene.medium, density);
        let volume = Volume::new(density, optics, MAJORANT_CELLS);
        let mut lights = lights_of(&scene.lights);
        lights.environment = sky_of(&scene, sky.as_ref());
        Self {
            camera: scene.camera.frame(),
            volume,
            lights,
            scene,
            dense,
            placement: Arc::new(Mutex::new(None)),
            given,
        }
    }

    /// This scene's medium for `scene` over `density` and `sky` (as
    /// [`PreparedScene::with_loaded`]), without building it again when the two
    /// media share their density field (the same grid in memory, or the
    /// same shape) and extinction (the previewer's edits of the camera,
    /// the lights, the albedo, `g` or the method's settings, and its
    /// reduced-resolution previews): the volume and its majorant grid are
    /// copied, the placement density's cache shared, the sky's sampling
    /// tables too while the sky and the sun it may follow are the same, and
    /// only the albedo, `g`, the camera and the lights taken from `scene`.
    /// On the cloud at 512² a rebuild took 22–34 ms of the previewer's
    /// latency.
    pub fn with_scene(&self, scene: Scene, density: Density, sky: &Option<LoadedSky>) -> Self {
        let (a, b) = (&self.scene.medium, &scene.medium);
        let same_medium = self.given.same_field(&density)
            && a.density_scale.to_bits() == b.density_scale.to_bits()
            && a.sigma_t.to_array().map(f32::to_bits) == b.sigma_t.to_array().map(f32::to_bits);
        if !same_medium {
            return Self::with_loaded(scene, density, sky.clone());
        }
        let mut volume = self.volume.clone();
        volume.optics.albedo = scene.medium.albedo;
        volume.optics.g = scene.medium.g;
        let mut lights = lights_of(&scene.lights);
        lights.environment = if self.scene.environment == scene.environment
            && self.scene.first_sun() == scene.first_sun()
        {
            self.lights.environment.clone()
        } else {
            sky_of(&scene, sky.as_ref())
        };
        Self {
            camera: scene.camera.frame(),
            volume,
            lights,
            dense: self.dense,
            placement: self.placement.clone(),
            given: density,
            scene,
        }
    }

    /// The placement density of the internal lights with uniform fraction
    /// `u_mix`, built the first time it is asked for (and again when
    /// `u_mix` changes).
    pub fn placement_density(&self, u_mix: f32) -> Arc<PlacementDensity> {
        let mut cached = self
            .placement
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some((bits, density)) = &*cached {
            if *bits == u_mix.to_bits() {
                return density.clone();
            }
        }
        let density = Arc::new(placement_density(&self.volume, u_mix));
        *cached = Some((u_mix.to_bits(), density.clone()));
        density
    }

    /// [`InternalLights::build`] for this scene with the cached placement
    /// density (the same lights; `timings.placement` includes building the
    /// density when it was not cached yet). `None` if `cancel` is set
    /// meanwhile.
    pub fn build_internal_lights(
        &self,
        params: &InternalParams,
        cancel: &AtomicBool,
    ) -> Option<InternalLights> {
        InternalLights::build_placed(
            &self.volume,
            &self.lights,
            params,
            || self.placement_density(params.uniform_mix),
            cancel,
        )
    }
}

/// The placement density built for one `u_mix` (its bits), shared by the
/// [`PreparedScene`] of one medium.
type PlacementCache = Mutex<Option<(u32, Arc<PlacementDensity>)>>;

/// `scene`'s loaded `sky` in the estimators' form, drawn behind the medium
/// if the scene says so.
fn sky_of(scene: &Scene, sky: Option<&LoadedSky>) -> Option<Arc<Environment>> {
    let background = scene.environment.as_ref().is_some_and(|e| e.background);
    sky.map(|s| Arc::new(environment_of(s, background)))
}

/// The estimators' form of a loaded sky: the map's vertices and sampling
/// tables ([`EnvMap`]).
pub fn environment_of(sky: &LoadedSky, background: bool) -> Environment {
    let kind = match sky {
        LoadedSky::Constant(l) => EnvironmentKind::Constant(*l),
        LoadedSky::Map {
            map,
            rotation_deg,
            scale,
        } => EnvironmentKind::Map(EnvMap::new(
            map.width,
            map.height,
            &map.texels,
            *rotation_deg,
            *scale,
        )),
    };
    Environment { kind, background }
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

/// The internal-lights parameters of `settings` for this scene, with the
/// defaults resolved (`s*`: [`default_s_star`]) and the walks split for
/// the medium ([`walk_split`]: where phase walks serve `L₁`, most of the
/// spread walks' time goes towards the eye). These are the parameters
/// of light set 0; see
/// [`internal_params_for_set`].
pub fn internal_params(prepared: &PreparedScene, settings: &RenderSettings) -> InternalParams {
    internal_params_for_set(prepared, settings, 0)
}

/// Which set of internal lights renders pass `pass` (see
/// `Expert::resample_every`): 0 throughout when sets are not
/// renewed.
pub fn light_set(settings: &RenderSettings, pass: u32) -> u32 {
    match settings.internal.expert.resample_every {
        0 => 0,
        every => pass / every,
    }
}

/// The later light set that begins at pass `pass`, if one does: where a
/// progressive loop over passes `0, 1, …` renews its lights.
pub fn light_set_starting(settings: &RenderSettings, pass: u32) -> Option<u32> {
    let every = settings.internal.expert.resample_every;
    (every > 0 && pass > 0 && pass.is_multiple_of(every)).then(|| pass / every)
}

/// [`internal_params`] for light set `set`: the same parameters, with the
/// seed of set 0 (the render's) advanced by `set` steps of the golden
/// ratio (every stream hashes the whole seed, so the sets' placements and
/// walks are independent), and the automatic kernel holding fewer lights
/// in later sets ([`kernel_neighbours_for_set`]).
pub fn internal_params_for_set(
    prepared: &PreparedScene,
    settings: &RenderSettings,
    set: u32,
) -> InternalParams {
    let s = &settings.internal;
    let clock = s.expert.clock;
    let s_star = s
        .knobs
        .s_star
        .unwrap_or_else(|| default_s_star(&prepared.volume, clock));
    // Where phase walks serve `L₁`, most of the spread walks' time goes
    // towards the eye instead.
    let (walks, view_walks) = walk_split(
        s.expert.walks,
        s.expert.view_walks,
        prepared.volume.optics.g,
    );
    InternalParams {
        s_star,
        lights: s.knobs.lights as usize,
        terms: s.knobs.terms,
        walks,
        sh_order: s.expert.sh_order,
        kernel_radius: s.expert.kernel_radius,
        kernel_neighbours: kernel_neighbours_for_set(set),
        uniform_mix: s.expert.uniform_mix,
        clock,
        l1: s.expert.l1,
        window_scatters: s.expert.window_scatters,
        view_walks,
        // Only the view walks tie the lights to the camera: without them
        // moving the camera must not re-sample the lights.
        eye: if s.expert.view_walks > 0 || s.expert.view_share > 0.0 {
            prepared.camera.eye
        } else {
            glam::Vec3::ZERO
        },
        view_share: s.expert.view_share,
        // Like the eye: only lights placed in the camera's windows depend
        // on the rest of the camera.
        view_frame: if s.expert.view_share > 0.0 {
            let f = prepared.camera;
            ViewFrame {
                eye: f.eye,
                forward: f.forward,
                right_scaled: f.right_scaled,
                up_scaled: f.up_scaled,
            }
        } else {
            ViewFrame::default()
        },
        seed: settings
            .seed
            .wrapping_add((set as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
        walk_deadline: None,
    }
}

/// The default window `s*` (see [`internal_params`]): [`DEFAULT_S_STAR`]
/// mean free paths, which with the optical-depth clock is the number
/// itself; with the geometric clock that many mean free paths at the mean
/// extinction of the medium where it is not empty (`max(σ_t) ρ̄` with `ρ̄`
/// the mean of the non-zero densities of a 24³ midpoint rule), so that
/// the window holds the same share of scatterings however large the box.
pub fn default_s_star(volume: &SceneVolume, clock: Clock) -> f32 {
    match clock {
        Clock::OpticalDepth => DEFAULT_S_STAR,
        Clock::Geometric => {
            const N: usize = 24;
            let (lo, hi) = volume.bounds;
            let (mut sum, mut count) = (0.0f64, 0usize);
            for k in 0..N {
                for j in 0..N {
                    for i in 0..N {
                        let f = (Vec3::new(i as f32, j as f32, k as f32) + 0.5) / N as f32;
                        let rho = volume.density.density(lo + (hi - lo) * f);
                        if rho > 0.0 {
                            sum += rho as f64;
                            count += 1;
                        }
                    }
                }
            }
            let mean = if count > 0 {
                (sum / count as f64) as f32
            } else {
                0.0
            };
            let c = volume.optics.sigma_t.max_element() * mean;
            let s = DEFAULT_S_STAR / c;
            if s > 0.0 && s.is_finite() {
                s
            } else {
                (hi - lo).length()
            }
        }
    }
}
