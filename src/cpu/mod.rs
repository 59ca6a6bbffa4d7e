//! The CPU backend: rayon-parallel, progressive passes of one sample per
//! pixel, for both estimators. Every pixel's random stream depends only on
//! (seed, pixel, pass), so an image reproduces whatever the number of
//! threads. A [`Renderer`] owns what a render needs between passes: the
//! prepared scene and, for the internal-lights method, the cached lights —
//! renewed every `resample_every` passes when the settings ask for it, so
//! that the walk noise averages out over the sets, or, for renders that
//! stop at a time limit, on a schedule balanced while they run
//! ([`Passes`], [`crate::render::renewal`]).

pub mod pixel_lights;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use crate::physics::internal::gather::gather;
use crate::physics::internal::sources::{InternalLights, InternalParams};
use crate::physics::reference::radiance_split;
use crate::physics::rng::{pixel_jitter, Rng};
use crate::render::renewal::{whole_set_secs, BalancedRenewal, WeightedSets};
use crate::render::{internal_params, internal_params_for_set, light_set, Film, PreparedScene};
use crate::scene::{CameraFrame, Method, RenderSettings};

/// One pass (one sample per pixel), by part. Rows top to bottom.
#[derive(Clone, Debug, Default)]
pub struct PassImage {
    /// The full estimate.
    pub total: Vec<Vec3>,
    /// Single scattering: the reference's first collision, or the
    /// internal-lights method's exact `k = 0` march.
    pub single: Vec<Vec3>,
    /// The rest: multiple scattering for the reference, the internal-light
    /// part (`L₀`'s `k ≥ 1` reconstruction plus `L₁`) for the method.
    pub internal: Vec<Vec3>,
}

/// A progressive CPU renderer for one scene and one set of settings.
pub struct Renderer {
    prepared: Arc<PreparedScene>,
    settings: RenderSettings,
    /// Light set 0 (internal-lights method only).
    internal: Option<Arc<InternalLights>>,
    /// The latest later light set and its number, built when a pass first
    /// needs it.
    later: Mutex<Option<(u32, Arc<InternalLights>)>>,
}

impl Renderer {
    /// Builds the renderer; for the internal-lights method this places the
    /// lights and runs the walks. Returns `None` if `cancel` is set first.
    pub fn new(
        prepared: Arc<PreparedScene>,
        settings: &RenderSettings,
        cancel: &AtomicBool,
    ) -> Option<Self> {
        Self::new_within(prepared, settings, cancel, None)
    }

    /// [`Renderer::new`] whose first light set's walks stop after the
    /// round that ends past `walk_deadline`
    /// ([`InternalParams::walk_deadline`]): a render with a time limit
    /// shorter than a whole set's walks gets its first pass in time.
    pub fn new_within(
        prepared: Arc<PreparedScene>,
        settings: &RenderSettings,
        cancel: &AtomicBool,
        walk_deadline: Option<Instant>,
    ) -> Option<Self> {
        let internal = match settings.method {
            Method::Reference => None,
            Method::Internal => {
                let params = InternalParams {
                    walk_deadline,
                    ..internal_params(&prepared, settings)
                };
                Some(Arc::new(prepared.build_internal_lights(&params, cancel)?))
            }
        };
        Some(Self {
            prepared,
            settings: settings.clone(),
            internal,
            later: Mutex::new(None),
        })
    }

    /// A renderer that reuses already built internal lights (which must
    /// belong to `prepared` and `settings`: they are light set 0).
    pub fn with_lights(
        prepared: Arc<PreparedScene>,
        settings: &RenderSettings,
        internal: Option<Arc<InternalLights>>,
    ) -> Self {
        Self {
            prepared,
            settings: settings.clone(),
            internal,
            later: Mutex::new(None),
        }
    }

    /// The prepared scene.
    pub fn prepared(&self) -> &Arc<PreparedScene> {
        &self.prepared
    }

    /// The settings it renders with.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The cached internal lights, light set 0 (internal-lights method
    /// only).
    pub fn internal_lights(&self) -> Option<&InternalLights> {
        self.internal.as_deref()
    }

    /// The cached internal lights, shared.
    pub fn internal_lights_arc(&self) -> Option<&Arc<InternalLights>> {
        self.internal.as_ref()
    }

    /// Light set `set` (`Some(None)` for the reference method): set 0, or
    /// a later set, built here the first time it is asked for (the latest
    /// one is kept). `None` if `cancel` is set while it is built.
    pub fn lights_for_set(
        &self,
        set: u32,
        cancel: &AtomicBool,
    ) -> Option<Option<Arc<InternalLights>>> {
        let Some(first) = &self.internal else {
            return Some(None);
        };
        if set == 0 {
            return Some(Some(first.clone()));
        }
        let mut later = self.later.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((built, lights)) = &*later {
            if *built == set {
                return Some(Some(lights.clone()));
            }
        }
        let params = internal_params_for_set(&self.prepared, &self.settings, set);
        self.build_kept(&mut later, set, &params, cancel).map(Some)
    }

    /// Builds light set `set` (`set` ≥ 1) with an automatic kernel holding
    /// `kernel_neighbours` lights instead of the set's own
    /// ([`kernel_neighbours_for_set`](crate::physics::internal::sources::kernel_neighbours_for_set)),
    /// and keeps it as the latest set ([`Renderer::lights_for_set`] then
    /// returns it): what a balanced schedule chooses
    /// ([`BalancedRenewal::kernel_neighbours`]), its walks stopping after
    /// the round that ends past `walk_deadline` if one is given (a set
    /// begun near a render's time limit,
    /// [`BalancedRenewal::fresh_set_share`]). Returns the share of a whole
    /// set's walks it walked (1 for the reference method or set 0, which
    /// it leaves as they are); `None` if `cancel` is set meanwhile.
    pub fn build_set(
        &self,
        set: u32,
        kernel_neighbours: u32,
        cancel: &AtomicBool,
        walk_deadline: Option<Instant>,
    ) -> Option<f64> {
        if self.internal.is_none() || set == 0 {
            return Some(1.0);
        }
        let params = InternalParams {
            kernel_neighbours,
            walk_deadline,
            ..internal_params_for_set(&self.prepared, &self.settings, set)
        };
        let mut later = self.later.lock().unwrap_or_else(PoisonError::into_inner);
        self.build_kept(&mut later, set, &params, cancel)
            .map(|lights| lights.walk_share)
    }

    /// Builds light set `set` with `params` and keeps it in `later` (the
    /// locked cache of the latest set); `None` if `cancel` is set meanwhile.
    fn build_kept(
        &self,
        later: &mut Option<(u32, Arc<InternalLights>)>,
        set: u32,
        params: &InternalParams,
        cancel: &AtomicBool,
    ) -> Option<Arc<InternalLights>> {
        let lights = Arc::new(self.prepared.build_internal_lights(params, cancel)?);
        *later = Some((set, lights.clone()));
        Some(lights)
    }

    /// One sample along the camera ray through film position `(px, py)`.
    #[inline]
    fn sample(&self, lights: Option<&InternalLights>, dir: Vec3, rng: &mut Rng) -> (Vec3, Vec3) {
        let p = &self.prepared;
        match lights {
            None => radiance_split(&p.volume, &p.lights, p.camera.eye, dir, u32::MAX, rng),
            Some(cache) => {
                let s = gather(
                    &p.volume,
                    &p.lights,
                    cache,
                    p.camera.eye,
                    dir,
                    self.settings.internal.expert.light_samples,
                    rng,
                );
                (s.total(), s.single)
            }
        }
    }

    /// Renders pass number `pass` with the light set it falls in
    /// ([`light_set`]: a fresh one every `resample_every` passes, built by
    /// [`Renderer::lights_for_set`]); `None` if `cancel` is set meanwhile.
    pub fn pass(&self, pass: u32, cancel: &AtomicBool) -> Option<PassImage> {
        self.pass_in_set(pass, light_set(&self.settings, pass), cancel)
    }

    /// Renders pass number `pass` with light set `set` whatever the
    /// settings' `resample_every` says (a [`Passes`] schedule's choice);
    /// `None` if `cancel` is set meanwhile.
    pub fn pass_in_set(&self, pass: u32, set: u32, cancel: &AtomicBool) -> Option<PassImage> {
        let lights = self.lights_for_set(set, cancel)?;
        let lights = lights.as_deref();
        let cam = &self.prepared.camera;
        let width = cam.width as usize;
        let n = width * cam.height as usize;
        let mut total = vec![Vec3::ZERO; n];
        let mut single = vec![Vec3::ZERO; n];
        let seed = self.settings.seed;
        total
            .par_chunks_mut(width)
            .zip(single.par_chunks_mut(width))
            .enumerate()
            .for_each(|(y, (row, row_single))| {
                if cancel.load(Ordering::Relaxed) {
                    return;
                }
                for x in 0..width {
                    let (dir, mut rng) = pixel_ray(cam, seed, x as u32, y as u32, pass);
                    let (t, s) = self.sample(lights, dir, &mut rng);
                    row[x] = t;
                    row_single[x] = s;
                }
            });
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let internal = total.iter().zip(&single).map(|(t, s)| *t - *s).collect();
        Some(PassImage {
            total,
            single,
            internal,
        })
    }

    /// Lights contributing to pixel `(x, y)` with their shares (summing to
    /// one), largest first; empty for the reference method. See
    /// [`pixel_lights::light_shares`].
    pub fn light_shares(&self, x: u32, y: u32) -> Vec<(usize, f32)> {
        match &self.internal {
            None => Vec::new(),
            Some(cache) => {
                let cam = &self.prepared.camera;
                let dir = cam.ray_dir(x as f32 + 0.5, y as f32 + 0.5);
                pixel_lights::light_shares(&self.prepared.volume, cache, cam.eye, dir)
            }
        }
    }
}

/// Runs a renderer's passes one after another with its light sets renewed
/// either every `resample_every` passes (as [`Renderer::pass`]) or, for a
/// render that stops at a time limit, on a schedule balanced from the
/// measured noise and costs ([`BalancedRenewal`]).
pub struct Passes {
    pass: u32,
    set: u32,
    balanced: Option<BalancedRenewal>,
    /// With a balanced schedule, the passes' totals by light set, for the
    /// image that weighs each set by its noise ([`Passes::weighted_image`]).
    sets: Option<WeightedSets>,
}

impl Passes {
    /// Passes of `renderer` from pass 0; `balanced` asks for the balanced
    /// schedule, which applies to the internal-lights method with renewed
    /// sets (`resample_every` > 0: it is the first sets' length);
    /// `build_secs` is what set 0 took to build (counted as a whole set's
    /// build where its walks stopped early: scaled by the share it walked,
    /// [`InternalLights::walk_share`](crate::physics::internal::sources::InternalLights::walk_share)).
    pub fn new(renderer: &Renderer, balanced: bool, build_secs: f64) -> Self {
        let s = renderer.settings();
        let every = s.internal.expert.resample_every;
        let balanced = (balanced && s.method == Method::Internal && every > 0).then(|| {
            let cam = &renderer.prepared().camera;
            let mut b = BalancedRenewal::new(cam.width as usize * cam.height as usize, every);
            let share = renderer.internal_lights().map_or(1.0, |l| l.walk_share);
            b.add_set_build(whole_set_secs(build_secs, share));
            b
        });
        Self {
            pass: 0,
            set: 0,
            balanced,
            sets: None,
        }
    }

    /// These passes, keeping their totals by light set where they follow
    /// a balanced schedule, for [`Passes::weighted_image`] (call before
    /// the first pass; `renderer` is the one passed to [`Passes::new`]).
    pub fn with_weighted_sets(mut self, renderer: &Renderer) -> Self {
        self.sets = self.balanced.as_ref().map(|b| {
            let share = renderer.internal_lights().map_or(1.0, |l| l.walk_share);
            WeightedSets::new(b.pixels(), b.kernel_neighbours(), share)
        });
        self
    }

    /// Renders the next pass (building its light set first if it starts
    /// one); `None` if `cancel` is set meanwhile.
    pub fn next(&mut self, renderer: &Renderer, cancel: &AtomicBool) -> Option<PassImage> {
        self.next_within(renderer, cancel, None)
    }

    /// [`Passes::next`] for a render that stops `remaining` seconds from
    /// now: with a balanced schedule, the set in hand runs on where a fresh
    /// one would not pay before then
    /// ([`BalancedRenewal::next_starts_set_within`]).
    pub fn next_within(
        &mut self,
        renderer: &Renderer,
        cancel: &AtomicBool,
        remaining: Option<f64>,
    ) -> Option<PassImage> {
        let Some(schedule) = &mut self.balanced else {
            let img = renderer.pass(self.pass, cancel)?;
            self.set = light_set(renderer.settings(), self.pass);
            self.pass += 1;
            return Some(img);
        };
        if self.pass > 0 && schedule.next_starts_set_within(remaining) {
            self.set += 1;
            let t = Instant::now();
            let deadline = schedule.walk_deadline(t);
            let kernel = schedule.kernel_neighbours();
            let share = renderer.build_set(self.set, kernel, cancel, deadline)?;
            schedule.add_set_build(whole_set_secs(t.elapsed().as_secs_f64(), share));
            if let Some(sets) = &mut self.sets {
                sets.next_set(schedule.set_noise(), kernel, share);
            }
        }
        let t = Instant::now();
        let img = renderer.pass_in_set(self.pass, self.set, cancel)?;
        schedule.add_pass(&img.total, t.elapsed().as_secs_f64());
        if let Some(sets) = &mut self.sets {
            sets.add_pass(&img.total);
        }
        self.pass += 1;
        Some(img)
    }

    /// The image of the passes so far with each light set's mean weighed
    /// by its noise ([`WeightedSets`]), where the passes follow a balanced
    /// schedule (`None` otherwise: there every set has the same number of
    /// passes and the mean over the passes is the image).
    pub fn weighted_image(&self) -> Option<Vec<Vec3>> {
        let (schedule, sets) = (self.balanced.as_ref()?, self.sets.as_ref()?);
        Some(sets.mean(schedule.set_noise_now()))
    }

    /// Passes rendered.
    pub fn passes(&self) -> u32 {
        self.pass
    }

    /// The light set of the last pass (0 before any).
    pub fn last_set(&self) -> u32 {
        self.set
    }

    /// The balanced schedule, if the passes follow one.
    pub fn balanced(&self) -> Option<&BalancedRenewal> {
        self.balanced.as_ref()
    }
}

/// The camera ray of pixel `(x, y)` in pass `pass`: its direction through
/// the pass's point of the pixel ([`pixel_jitter`]: uniform in each pass,
/// evenly spread over the passes), and the pixel's random stream for the
/// estimate (depending only on seed, pixel and pass).
#[inline]
pub fn pixel_ray(cam: &CameraFrame, seed: u64, x: u32, y: u32, pass: u32) -> (Vec3, Rng) {
    let index = y * cam.width + x;
    let (jx, jy) = pixel_jitter(seed, index, pass);
    (
        cam.ray_dir(x as f32 + jx, y as f32 + jy),
        Rng::for_sample(seed, index, pass),
    )
}

/// Renders `spp` passes into a new film, calling `on_pass` after each; it
/// returns `false` to stop early. Builds the internal lights first when the
/// method needs them.
pub fn render(
    prepared: Arc<PreparedScene>,
    settings: &RenderSettings,
    mut on_pass: impl FnMut(&Film) -> bool,
) -> Film {
    let never = AtomicBool::new(false);
    let cam = prepared.camera;
    let mut film = Film::new(cam.width, cam.height);
    let Some(renderer) = Renderer::new(prepared, settings, &never) else {
        return film;
    };
    for pass in 0..settings.spp {
        let Some(img) = renderer.pass(pass, &never) else {
            break;
        };
        film.add_pass(&img.total);
        if !on_pass(&film) {
            break;
        }
    }
    film
}
