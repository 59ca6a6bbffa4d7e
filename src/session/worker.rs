//! The previewer's render session: the one place the previewer's
//! renderers run (moved here from `ui::backend`; no egui).
//!
//! A worker thread owns the renderers and the progressive films; the UI
//! thread sends it a [`Job`] whenever anything that changes the picture
//! changes, and reads back the latest [`Snapshot`]. A new job cancels the
//! one in flight (its cancel flag is raised before the job is queued), so
//! the UI never waits on a pass (issue 4, "Never blocking").
//!
//! The first pass of every job is rendered at a reduced resolution chosen
//! from the measured cost of a full pass, so that a slider change shows an
//! updated (coarser) image within a frame or two; full-resolution passes
//! then accumulate into the film.
//!
//! Nothing here knows of egui: the worker wakes the UI through a plain
//! callback.
//!
//! Two backends ([`Backend`]): on the CPU the worker accumulates
//! [`Film`]s and publishes their means; on the GPU it drives
//! [`GpuRenderer`]s, whose accumulation stays on the device: a snapshot
//! then carries the accumulation buffers ([`GpuStream`]) for the UI's
//! display pass, and the noise figure and RMSE come from a small
//! reduction on the GPU read back here, on the worker thread (16 bytes per
//! stream and pass). The internal lights are built on the CPU for both
//! backends, and the per-pixel light shares (gizmo hover) always come from
//! a CPU renderer. Where the GPU cannot take a job (a scene too large for
//! the device, a device error) the worker reports it and renders that job
//! on the CPU.
//!
//! The previewer refines until it is stopped, as a render with a time
//! limit does, so on both backends its internal lights' sets follow the
//! balanced schedule of [`crate::render::renewal`] ([`crate::cpu::Passes`],
//! [`GpuPasses`]): how long a set lasts, and whether its kernel stays wide
//! where the sets' noise outweighs the passes' (a thick cumulus).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use glam::Vec3;

use super::{Backend, GpuPasses, LightBuilder, Renewal};
use crate::cpu::{Passes, Renderer};
use crate::gpu::display::{read_accum, DisplayPass, ImageStats};
use crate::gpu::{GpuContext, GpuError, GpuRenderer};
use crate::physics::internal::clock::Clock;
use crate::physics::internal::sources::InternalLights;
use crate::render::renewal::BalancedRenewal;
use crate::render::{Film, PreparedScene};
use crate::scene::{Density, DensitySource, Method, Scene};

pub use crate::scene::InternalSettings;

/// Everything that determines the picture.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// The scene (with the internal-lights settings); its camera's width
    /// and height are the render size.
    pub scene: Scene,
    /// Folder that grid paths are relative to.
    pub scene_dir: PathBuf,
    /// One stream per estimator to show (two for the comparisons).
    pub estimators: Vec<Method>,
    /// Stop after this many samples per pixel.
    pub max_spp: u32,
    /// Where to render (the GPU only where the worker has a device).
    pub backend: Backend,
}

/// The internal lights as the gizmos need them.
#[derive(Clone, Debug)]
pub struct LightsView {
    lights: Arc<InternalLights>,
    /// Extinction per unit density (largest channel), for the reach.
    sigma_max: f32,
    /// Mean of `F_i` over directions (RGB), per light.
    pub mean_f: Vec<Vec3>,
    /// Mean of `J_i` over directions (RGB), per light.
    pub mean_j: Vec<Vec3>,
}

impl LightsView {
    fn new(lights: Arc<InternalLights>, scene: &Scene) -> Self {
        let n = lights.lights.len();
        Self {
            mean_f: (0..n).map(|i| lights.mean_f(i)).collect(),
            mean_j: (0..n).map(|i| lights.mean_j(i)).collect(),
            sigma_max: scene.medium.sigma_t.max_element() * scene.medium.density_scale,
            lights,
        }
    }

    /// Number of lights.
    pub fn len(&self) -> usize {
        self.lights.lights.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.lights.lights.is_empty()
    }

    /// Position `x_i`.
    pub fn position(&self, i: usize) -> Vec3 {
        self.lights.lights[i].position
    }

    /// Density `ρ(x_i)`.
    pub fn density(&self, i: usize) -> f32 {
        self.lights.lights[i].density
    }

    /// Volume weight `V_i`.
    pub fn weight(&self, i: usize) -> f32 {
        self.lights.lights[i].weight
    }

    /// `F_i` and `J_i` towards direction `dir` (the direction light
    /// travels), RGB.
    pub fn lobe(&self, i: usize, dir: Vec3) -> (Vec3, Vec3) {
        (self.lights.eval_f(i, dir), self.lights.eval_j(i, dir))
    }

    /// The window `s*` in the clock's units.
    pub fn s_star(&self) -> f32 {
        self.lights.s_star
    }

    /// Whether `s*` counts optical depth (mean free paths).
    pub fn optical_clock(&self) -> bool {
        matches!(self.lights.params.clock, Clock::OpticalDepth)
    }

    /// The reach `s*` around light `i` in world units: exact for the
    /// geometric clock; for the optical-depth clock, `s*` mean free paths
    /// at the light's own density (an indication: the clock runs faster
    /// in denser parts).
    pub fn reach(&self, i: usize) -> f32 {
        if self.optical_clock() {
            let c = self.sigma_max * self.density(i);
            if c > 0.0 {
                self.lights.s_star / c
            } else {
                f32::INFINITY
            }
        } else {
            self.lights.s_star
        }
    }

    /// The kernel radius `h` in use.
    pub fn kernel_radius(&self) -> f32 {
        self.lights.kernel_radius
    }

    /// Energy carried by each series term `k = 0..N`; where `N` exceeds
    /// [`RESOLVED_TERMS`](crate::physics::internal::clock::RESOLVED_TERMS),
    /// the last element sums the terms from it to `N`.
    pub fn term_energy(&self) -> &[Vec3] {
        &self.lights.term_energy
    }

    /// The series truncation `N` these lights were built with.
    pub fn terms(&self) -> u32 {
        self.lights.params.terms
    }
}

/// The image of one estimator so far.
#[derive(Clone, Debug)]
pub struct StreamImage {
    /// The estimator.
    pub estimator: Method,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel accumulated (0 for the low-resolution preview).
    pub spp: u32,
    /// Mean linear radiance, row-major, row 0 at the top.
    pub mean: Vec<Vec3>,
    /// Relative standard error of the image: `sqrt(mean σ²) / mean L`.
    pub rel_error: f32,
    /// Single-scatter layer, when the estimator splits it out.
    pub single: Option<Vec<Vec3>>,
    /// Internal-light layer, when the estimator splits it out.
    pub internal: Option<Vec<Vec3>>,
    /// On the GPU backend: the accumulation on the device (`mean` and the
    /// layers are then empty; see [`StreamImage::resolved`]).
    pub gpu: Option<GpuStream>,
    /// Where the internal lights' renewed sets stand (none for the
    /// reference, a preview, or lights that are not renewed).
    pub light_sets: Option<LightSetStatus>,
}

/// Where an internal-lights stream's renewed light sets stand: which set
/// the last pass used and what the balanced schedule chose for its
/// kernel ([`BalancedRenewal`]), for the overlay and the export.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSetStatus {
    /// The light set of the last pass (0: the first).
    pub set: u32,
    /// Lights the set's automatic kernel holds.
    pub kernel_neighbours: u32,
    /// Whether the sets' noise outweighs the passes' (the kernel then
    /// stays wide); `None` until the schedule has measured it.
    pub sets_outweigh_passes: Option<bool>,
    /// The factor on a noise figure read from the passes' spread for the
    /// noise the passes of one set share (the square root of
    /// [`BalancedRenewal::noise_inflation`]); `None` until measured.
    pub noise_scale: Option<f32>,
}

impl LightSetStatus {
    /// The status after a pass of light set `set` on a balanced
    /// `schedule`; `None` without one.
    pub fn of(set: u32, schedule: Option<&BalancedRenewal>) -> Option<Self> {
        schedule.map(|b| LightSetStatus {
            set,
            kernel_neighbours: b.kernel_neighbours(),
            sets_outweigh_passes: b.sets_outweigh_passes(),
            noise_scale: b.noise_inflation().map(|f| f.sqrt() as f32),
        })
    }

    /// In words, short: "light set 7, kernel 22 lights (shrinking slowly:
    /// noisy sets)".
    pub fn label(&self) -> String {
        let why = match self.sets_outweigh_passes {
            Some(true) => " (shrinking slowly: noisy sets)",
            Some(false) => " (shrunk: quiet sets)",
            None => "",
        };
        format!(
            "light set {}, kernel {} lights{why}",
            self.set, self.kernel_neighbours
        )
    }
}

/// A stream's accumulation on the GPU.
#[derive(Clone, Debug)]
pub struct GpuStream {
    /// The device.
    pub ctx: GpuContext,
    /// [`GpuAccum`](crate::gpu::mirrors::GpuAccum) per pixel, rows top to
    /// bottom.
    pub accum: wgpu::Buffer,
}

impl StreamImage {
    /// The image with its means on the CPU: itself on the CPU backend, a
    /// read-back of the accumulation on the GPU backend (waits for the GPU:
    /// export and tests only).
    pub fn resolved(&self) -> Result<std::borrow::Cow<'_, StreamImage>, String> {
        let Some(gpu) = &self.gpu else {
            return Ok(std::borrow::Cow::Borrowed(self));
        };
        let image = read_accum(&gpu.ctx, &gpu.accum, self.width, self.height, self.spp)
            .map_err(|e| format!("{e:#}"))?;
        let film = image.film();
        let mean = film.mean();
        let single = image.single_mean();
        let internal = mean.iter().zip(&single).map(|(t, s)| *t - *s).collect();
        Ok(std::borrow::Cow::Owned(StreamImage {
            mean,
            single: Some(single),
            internal: Some(internal),
            gpu: None,
            ..self.clone()
        }))
    }

    /// Variance of each pixel's mean (empty on the CPU backend, where
    /// [`StreamImage`] keeps only means; read back on the GPU backend).
    pub fn gpu_variance_of_mean(&self) -> Result<Vec<Vec3>, String> {
        let Some(gpu) = &self.gpu else {
            return Ok(Vec::new());
        };
        let image = read_accum(&gpu.ctx, &gpu.accum, self.width, self.height, self.spp)
            .map_err(|e| format!("{e:#}"))?;
        Ok(image.film().variance_of_mean())
    }
}

/// What the worker last produced for a job.
#[derive(Clone)]
pub struct Snapshot {
    /// Which submission this belongs to (see [`Worker::submit`]).
    pub generation: u64,
    /// One image per requested estimator (same order).
    pub streams: Vec<StreamImage>,
    /// The internal lights, when the internal method runs.
    pub lights: Option<Arc<LightsView>>,
    /// The full-resolution internal-lights renderer, for the per-pixel
    /// light shares.
    pub shares: Option<Arc<Renderer>>,
    /// Whether every stream reached `max_spp`.
    pub done: bool,
    /// The medium's world box.
    pub bounds: Option<(Vec3, Vec3)>,
    /// Where the images were rendered.
    pub backend: Backend,
    /// On the GPU backend with both estimators: the RMSE of internal
    /// lights against the reference and the reference's mean (from the
    /// statistics pass; the CPU backend's UI computes them from the means).
    pub error_stats: Option<(f32, f32)>,
}

/// State shared between the UI and the worker.
struct Shared {
    latest: Mutex<Option<Arc<Snapshot>>>,
    errors: Mutex<Vec<String>>,
    wake: Waker,
}

/// Tells the UI that something new is there, to be shown within the given
/// delay (zero: at once).
pub type Waker = Box<dyn Fn(Duration) + Send + Sync>;

/// How soon refinements of an image already on screen must be shown: often
/// enough to watch the noise go, rarely enough that redrawing the window
/// (in software, on machines without a GPU) does not take the CPU from the
/// render.
pub const REFINE_INTERVAL: Duration = Duration::from_millis(200);

enum Command {
    Run {
        generation: u64,
        job: Box<Job>,
        cancel: Arc<AtomicBool>,
        sent: Instant,
    },
    Quit,
}

/// The render thread and its mailbox.
pub struct Worker {
    tx: Sender<Command>,
    shared: Arc<Shared>,
    cancel: Arc<AtomicBool>,
    generation: u64,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts a worker with the CPU backend only; `wake` is called (from
    /// the worker thread) after every new snapshot or error.
    pub fn start(wake: Waker) -> Self {
        Self::start_with_gpu(wake, None)
    }

    /// Starts the worker; jobs asking for [`Backend::Gpu`] run on `gpu`
    /// (on the CPU where it is `None`).
    pub fn start_with_gpu(wake: Waker, gpu: Option<GpuContext>) -> Self {
        let (tx, rx) = mpsc::channel();
        let shared = Arc::new(Shared {
            latest: Mutex::new(None),
            errors: Mutex::new(Vec::new()),
            wake,
        });
        let worker_shared = shared.clone();
        let thread = std::thread::Builder::new()
            .name("lantern-render".into())
            .spawn(move || {
                super::lower_thread_priority();
                worker_loop(rx, worker_shared, gpu)
            })
            .ok();
        if thread.is_none() {
            push_error(&shared, "cannot start the render thread".into());
        }
        Self {
            tx,
            shared,
            cancel: Arc::new(AtomicBool::new(false)),
            generation: 0,
            thread,
        }
    }

    /// Cancels the pass in flight and starts `job`; returns its generation.
    pub fn submit(&mut self, job: Job) -> u64 {
        self.cancel.store(true, Ordering::Relaxed);
        self.cancel = Arc::new(AtomicBool::new(false));
        self.generation += 1;
        let sent = self.tx.send(Command::Run {
            generation: self.generation,
            job: Box::new(job),
            cancel: self.cancel.clone(),
            sent: Instant::now(),
        });
        if sent.is_err() {
            push_error(&self.shared, "the render thread has stopped".into());
        }
        self.generation
    }

    /// The latest snapshot, if any.
    pub fn latest(&self) -> Option<Arc<Snapshot>> {
        self.shared.latest.lock().ok().and_then(|l| l.clone())
    }

    /// Errors reported since the last call.
    pub fn take_errors(&self) -> Vec<String> {
        self.shared
            .errors
            .lock()
            .map(|mut e| std::mem::take(&mut *e))
            .unwrap_or_default()
    }
}

impl Snapshot {
    /// The internal lights that light render pixel (`x`, `y`), with their
    /// shares (summing to one), largest first.
    pub fn light_shares(&self, x: u32, y: u32) -> Vec<(usize, f32)> {
        self.shares
            .as_ref()
            .map(|r| r.light_shares(x, y))
            .unwrap_or_default()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
        let _ = self.tx.send(Command::Quit);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn push_error(shared: &Shared, message: String) {
    if let Ok(mut e) = shared.errors.lock() {
        e.push(message);
    }
    (shared.wake)(Duration::ZERO);
}

fn publish(shared: &Shared, snapshot: Snapshot) {
    // The first images of a job are shown at once, refinements in batches.
    let first = snapshot.streams.iter().all(|s| s.spp <= 1);
    if let Ok(mut l) = shared.latest.lock() {
        *l = Some(Arc::new(snapshot));
    }
    (shared.wake)(if first {
        Duration::ZERO
    } else {
        REFINE_INTERVAL
    });
}

/// The density of the last scene, kept because baking a procedural cloud
/// or reading a grid is far slower than a pass.
struct DensityCache {
    key: Option<(DensitySource, PathBuf)>,
    density: Option<Density>,
    /// The last job's medium, whose volume and majorants the next job
    /// reuses when only what does not change them changed
    /// ([`PreparedScene::with_scene`]).
    prepared: Option<Arc<PreparedScene>>,
    /// The sky of the last scene (a map is read, a clear sky baked, once).
    sky_key: Option<(Option<crate::scene::Environment>, Option<[u32; 3]>, PathBuf)>,
    sky: Option<crate::scene::LoadedSky>,
}

impl DensityCache {
    fn get(&mut self, scene: &Scene, dir: &Path) -> Result<Density, String> {
        let key = (scene.medium.density.clone(), dir.to_path_buf());
        if self.key.as_ref() != Some(&key) || self.density.is_none() {
            let density = scene.load_density(dir).map_err(|e| format!("{e:#}"))?;
            self.key = Some(key);
            self.density = Some(density);
        }
        self.density.clone().ok_or_else(|| "no density".to_string())
    }

    /// `scene`'s medium over `density` (from [`DensityCache::get`]),
    /// reusing the last job's volume where it can, and kept for the next.
    fn prepare(
        &mut self,
        scene: &Scene,
        density: &Density,
        sky: &Option<crate::scene::LoadedSky>,
    ) -> Arc<PreparedScene> {
        let prepared = Arc::new(match &self.prepared {
            Some(last) => last.with_scene(scene.clone(), density.clone(), sky),
            None => PreparedScene::with_loaded(scene.clone(), density.clone(), sky.clone()),
        });
        self.prepared = Some(prepared.clone());
        prepared
    }

    /// The scene's sky, loaded (`None` without one).
    fn sky(
        &mut self,
        scene: &Scene,
        dir: &Path,
    ) -> Result<Option<crate::scene::LoadedSky>, String> {
        let sun = scene.first_sun().map(|d| d.to_array().map(f32::to_bits));
        let key = (scene.environment.clone(), sun, dir.to_path_buf());
        if self.sky_key.as_ref() != Some(&key) {
            self.sky = scene.load_environment(dir).map_err(|e| format!("{e:#}"))?;
            self.sky_key = Some(key);
        }
        Ok(self.sky.clone())
    }
}

/// The internal lights of the last job: they depend on the medium, the
/// external lights, the method's settings and the seed, not on the camera,
/// so orbiting or resizing reuses them.
#[derive(Default)]
struct LightsCache {
    key: Option<(Scene, PathBuf)>,
    lights: Option<Arc<InternalLights>>,
}

impl LightsCache {
    fn key_of(job: &Job) -> (Scene, PathBuf) {
        let mut scene = job.scene.clone();
        // The lights do not depend on the camera, except for the view
        // walks' eye (`InternalParams::eye`) and, for the lights placed in
        // the camera's windows, the whole camera (`InternalParams::view_frame`).
        let camera = std::mem::take(&mut scene.camera);
        if scene.render.internal.expert.view_share > 0.0 {
            scene.camera = camera;
        } else if scene.render.internal.expert.view_walks > 0 {
            scene.camera.eye = camera.eye;
        }
        scene.render.spp = 0;
        scene.render.method = Method::Internal;
        // Light set 0 does not depend on whether or how often later sets
        // replace it.
        scene.render.internal.expert.resample_every = 0;
        (scene, job.scene_dir.clone())
    }
}

/// The settings of one stream: the job's, with its estimator.
fn settings_for(job: &Job, estimator: Method) -> crate::scene::RenderSettings {
    let mut settings = job.scene.render.clone();
    settings.method = estimator;
    settings
}

/// Target duration of the low-resolution first pass.
const PREVIEW_BUDGET: Duration = Duration::from_millis(20);

/// The most a preview divides the image's width and height by.
const MAX_PREVIEW_FACTOR: f64 = 16.0;

/// The fewest light samples a preview takes (fewer than the settings' only
/// where the settings ask for more).
const MIN_PREVIEW_LIGHT_SAMPLES: u32 = 2;

/// Light samples per camera sample for an internal-lights preview whose
/// pass at the coarsest resolution would take `1/share` of its budget
/// (`share` ≤ 1): the settings' `full` scaled by `share`, at least
/// [`MIN_PREVIEW_LIGHT_SAMPLES`].
///
/// The first image after an edit on the CPU comes from a coarse light set
/// (few lights: a wide kernel that costs several times more per sample)
/// at 1/16 of the width; on the cloud at 512² under Xvfb it still took
/// 50–55 ms (median) on two cores against a 20 ms budget, 32 ms with two
/// light samples, and the image missed the frame after the edit more
/// often. Fewer light samples leave `L₁`'s estimate unbiased and the
/// preview noisier until the full passes replace it: at 32² over the
/// suite 1.2–1.8× the per-pixel error of eight samples, 1.5–2.8× with one
/// (hence the floor; cost is not proportional to the samples).
fn preview_light_samples(full: u32, share: f64) -> u32 {
    if share >= 1.0 || share.is_nan() {
        return full;
    }
    let floor = MIN_PREVIEW_LIGHT_SAMPLES.min(full.max(1));
    ((f64::from(full) * share).round() as u32).clamp(floor, full.max(1))
}

/// The worker's GPU: the device and the statistics pass.
struct GpuWorker {
    ctx: GpuContext,
    stats: DisplayPass,
    /// The density (and folder) of the last job the GPU could not take:
    /// later jobs on it go to the CPU without a new notice.
    failed_for: Option<(DensitySource, PathBuf)>,
    /// Whether the user was told that the driver cuts passes short since
    /// the last image published without a cut pass: told once while the
    /// settings that cause it stay, again if it comes back.
    cut_told: std::cell::Cell<bool>,
}

fn worker_loop(rx: Receiver<Command>, shared: Arc<Shared>, gpu: Option<GpuContext>) {
    let mut cache = DensityCache {
        key: None,
        density: None,
        prepared: None,
        sky_key: None,
        sky: None,
    };
    let mut lights_cache = LightsCache::default();
    let mut gpu = gpu.and_then(|ctx| match DisplayPass::new(&ctx) {
        Ok(stats) => Some(GpuWorker {
            ctx,
            stats,
            failed_for: None,
            cut_told: std::cell::Cell::new(false),
        }),
        Err(e) => {
            push_error(
                &shared,
                format!("GPU backend unavailable ({e}); rendering on the CPU"),
            );
            None
        }
    });
    // Seconds per full-resolution pixel-sample, measured per backend and
    // estimator, of the full passes and of the previews (whose coarse
    // lights cost several times more per sample: few lights with a wide
    // kernel); the latter guides the preview's downscale factor.
    let mut secs_per_sample = [[2e-6f64; 2]; 2];
    let mut preview_secs = [[2e-6f64; 2]; 2];
    let mut next: Option<Command> = None;
    loop {
        let command = match next.take() {
            Some(c) => c,
            None => match rx.recv() {
                Ok(c) => c,
                Err(_) => return,
            },
        };
        let (generation, job, cancel) = match command {
            Command::Quit => return,
            Command::Run {
                generation,
                job,
                cancel,
                sent,
            } => {
                trace("queued", sent);
                (generation, job, cancel)
            }
        };
        // Skip to the newest job if several queued up.
        if let Ok(c) = rx.try_recv() {
            next = Some(c);
            continue;
        }
        let mut ctx = JobContext {
            generation,
            job: &job,
            cancel: &cancel,
            rx: &rx,
            shared: &shared,
            secs_per_sample: &mut secs_per_sample,
            preview_secs: &mut preview_secs,
            gpu: None,
        };
        let density_key = (job.scene.medium.density.clone(), job.scene_dir.clone());
        if job.backend == Backend::Gpu {
            ctx.gpu = gpu
                .as_mut()
                .filter(|g| g.failed_for.as_ref() != Some(&density_key));
        }
        next = ctx.run(&mut cache, &mut lights_cache);
    }
}

/// One job being rendered.
struct JobContext<'a> {
    generation: u64,
    job: &'a Job,
    cancel: &'a AtomicBool,
    rx: &'a Receiver<Command>,
    shared: &'a Shared,
    secs_per_sample: &'a mut [[f64; 2]; 2],
    /// The same for the previews ([`JobContext::preview`]).
    preview_secs: &'a mut [[f64; 2]; 2],
    /// The GPU, when this job runs there.
    gpu: Option<&'a mut GpuWorker>,
}

impl JobContext<'_> {
    /// What to do when the job was cancelled or failed: wait for the next.
    fn next_command(&self) -> Option<Command> {
        self.rx.recv().ok()
    }

    /// A newer command, if one is waiting.
    fn newer(&self) -> Option<Command> {
        self.rx.try_recv().ok()
    }

    /// The backend this job renders on.
    fn backend(&self) -> Backend {
        if self.gpu.is_some() {
            Backend::Gpu
        } else {
            Backend::Cpu
        }
    }

    fn publish(&self, streams: Vec<StreamImage>, extra: SnapshotExtra) {
        publish(
            self.shared,
            Snapshot {
                generation: self.generation,
                streams,
                lights: extra.lights,
                shares: extra.shares,
                done: extra.done,
                bounds: extra.bounds,
                backend: self.backend(),
                error_stats: extra.error_stats,
            },
        );
    }

    /// Gives up on the GPU for this job (and later ones on the same
    /// density) after `error`, with a notice.
    fn gpu_failed(&mut self, error: &GpuError) {
        let job = self.job;
        if let Some(gpu) = self.gpu.take() {
            gpu.failed_for = Some((job.scene.medium.density.clone(), job.scene_dir.clone()));
        }
        push_error(
            self.shared,
            format!("GPU backend: {error}; rendering on the CPU instead"),
        );
    }

    /// Renders the job until it is done or replaced; returns the command
    /// that replaced it, if any.
    fn run(&mut self, cache: &mut DensityCache, lights_cache: &mut LightsCache) -> Option<Command> {
        let job = self.job;
        let density = match cache.get(&job.scene, &job.scene_dir) {
            Ok(d) => d,
            Err(e) => {
                push_error(self.shared, e);
                return self.next_command();
            }
        };
        let sky = match cache.sky(&job.scene, &job.scene_dir) {
            Ok(s) => s,
            Err(e) => {
                push_error(self.shared, e);
                return self.next_command();
            }
        };
        if let Some(c) = self.newer() {
            return Some(c);
        }
        let bounds = Some(density.bounds());
        let (width, height) = (job.scene.camera.width, job.scene.camera.height);
        let t0 = Instant::now();
        let prepared = cache.prepare(&job.scene, &density, &sky);
        trace("prepare", t0);

        // The internal lights, from the cache when only the camera changed.
        // Otherwise a coarse set (few lights, few walks) is built first, so
        // that a first image appears at once while the full set builds.
        let wants_internal = job.estimators.contains(&Method::Internal);
        let key = LightsCache::key_of(job);
        let cached = if lights_cache.key.as_ref() == Some(&key) {
            lights_cache.lights.clone()
        } else {
            None
        };
        let mut preview = PreviewInput {
            density: &density,
            prepared: &prepared,
            sky: &sky,
            bounds,
        };
        let lights = if !wants_internal {
            if let Some(c) = self.preview(&mut preview, None) {
                return Some(c);
            }
            None
        } else if let Some(lights) = cached {
            if let Some(c) = self.preview(&mut preview, Some(lights.clone())) {
                return Some(c);
            }
            Some(lights)
        } else {
            let settings = settings_for(job, Method::Internal);
            let mut coarse_settings = settings.clone();
            coarse_settings.internal.knobs.lights =
                settings.internal.knobs.lights.min(COARSE_LIGHTS);
            coarse_settings.internal.expert.walks =
                settings.internal.expert.walks.min(COARSE_WALKS);
            coarse_settings.internal.expert.view_walks =
                settings.internal.expert.view_walks.min(COARSE_WALKS);
            let is_coarse = coarse_settings != settings;
            if is_coarse {
                let t = Instant::now();
                let Some(coarse) = Renderer::new(prepared.clone(), &coarse_settings, self.cancel)
                else {
                    return self.next_command();
                };
                trace("coarse lights", t);
                if let Some(c) = self.preview(&mut preview, coarse.internal_lights_arc().cloned()) {
                    return Some(c);
                }
            }
            let t = Instant::now();
            let Some(renderer) = Renderer::new(prepared.clone(), &settings, self.cancel) else {
                return self.next_command();
            };
            trace("lights", t);
            let built = renderer.internal_lights_arc().cloned();
            lights_cache.key = Some(key);
            lights_cache.lights = built.clone();
            if !is_coarse {
                if let Some(c) = self.preview(&mut preview, built.clone()) {
                    return Some(c);
                }
            }
            built
        };
        let lights_view = lights
            .clone()
            .map(|l| Arc::new(LightsView::new(l, &job.scene)));
        // The per-pixel light shares come from a CPU renderer on both
        // backends (cheap to make: the lights are shared).
        let shares = wants_internal.then(|| {
            Arc::new(Renderer::with_lights(
                prepared.clone(),
                &settings_for(job, Method::Internal),
                lights.clone(),
            ))
        });
        if let Some(c) = self.newer() {
            return Some(c);
        }
        let extra = |done, error_stats| SnapshotExtra {
            lights: lights_view.clone(),
            shares: shares.clone(),
            done,
            bounds,
            error_stats,
        };

        if self.gpu.is_some() {
            match self.run_gpu(&prepared, lights.as_deref(), &extra) {
                Ok(next) => return next,
                Err(e) => self.gpu_failed(&e),
            }
        }

        let engines: Vec<(Method, Arc<Renderer>)> = job
            .estimators
            .iter()
            .map(|&e| {
                let renderer = match (&shares, e) {
                    (Some(r), Method::Internal) => r.clone(),
                    _ => {
                        let settings = settings_for(job, e);
                        Arc::new(Renderer::with_lights(prepared.clone(), &settings, None))
                    }
                };
                (e, renderer)
            })
            .collect();
        let film = || Film::new(width, height);
        let mut films: Vec<[Film; 3]> = engines.iter().map(|_| [film(), film(), film()]).collect();
        // The previewer refines until it is stopped, as a timed render
        // does: its light sets follow the balanced schedule.
        let set_secs = set_build_secs(lights.as_deref());
        let mut schedules: Vec<Passes> = engines
            .iter()
            .map(|(_, r)| Passes::new(r, true, set_secs))
            .collect();
        for pass in 0..job.max_spp {
            let pass_start = Instant::now();
            for (((estimator, engine), film), passes) in engines
                .iter()
                .zip(films.iter_mut())
                .zip(schedules.iter_mut())
            {
                let start = Instant::now();
                let set = passes.last_set();
                let Some(image) = passes.next(engine, self.cancel) else {
                    return self.next_command();
                };
                if passes.last_set() != set {
                    trace_set(passes.last_set(), passes.balanced());
                }
                let secs = start.elapsed().as_secs_f64();
                self.secs_per_sample[Backend::Cpu as usize][*estimator as usize] =
                    secs / (width as f64 * height as f64).max(1.0);
                film[0].add_pass(&image.total);
                film[1].add_pass(&image.single);
                film[2].add_pass(&image.internal);
            }
            trace("CPU pass", pass_start);
            let streams = engines
                .iter()
                .zip(&films)
                .zip(&schedules)
                .map(|(((e, _), f), p)| {
                    stream_image(*e, f, LightSetStatus::of(p.last_set(), p.balanced()))
                })
                .collect();
            self.publish(streams, extra(pass + 1 == job.max_spp, None));
            if let Some(c) = self.newer() {
                return Some(c);
            }
        }
        self.wait_for_next()
    }

    /// Done: waits for the next job.
    fn wait_for_next(&self) -> Option<Command> {
        loop {
            match self.rx.recv_timeout(Duration::from_secs(3600)) {
                Ok(c) => return Some(c),
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    /// The job's full-resolution passes on the GPU: one dispatch per
    /// estimator and pass, waited for (so that a new job never queues
    /// behind many passes), then the statistics pass; returns the command
    /// that replaced the job, or the error that stops the GPU from taking
    /// it (nothing published then is wrong, only incomplete).
    fn run_gpu(
        &mut self,
        prepared: &PreparedScene,
        lights: Option<&InternalLights>,
        extra: &dyn Fn(bool, Option<(f32, f32)>) -> SnapshotExtra,
    ) -> Result<Option<Command>, GpuError> {
        let job = self.job;
        let Some(gpu) = self.gpu.as_deref() else {
            return Ok(self.next_command());
        };
        let (width, height) = (prepared.camera.width, prepared.camera.height);
        let t = Instant::now();
        let mut engines = gpu_engines(&gpu.ctx, job, prepared, lights)?;
        trace("GPU upload", t);
        if let Some(c) = self.newer() {
            return Ok(Some(c));
        }
        // Balanced light sets, as on the CPU.
        let set_secs = set_build_secs(lights);
        let mut schedules: Vec<GpuPasses> = engines
            .iter()
            .map(|(e, r)| GpuPasses::new(r, &settings_for(job, *e), true, set_secs))
            .collect();
        for pass in 0..job.max_spp {
            if self.cancel.load(Ordering::Relaxed) {
                return Ok(self.next_command());
            }
            let start = Instant::now();
            for ((e, engine), passes) in engines.iter_mut().zip(schedules.iter_mut()) {
                // A fresh light set when the pass starts one (built on the
                // CPU, as the first).
                let settings = settings_for(job, *e);
                let builder = LightBuilder::Cpu(self.cancel);
                match passes.next(engine, prepared, &settings, builder)? {
                    Renewal::Cancelled => return Ok(self.next_command()),
                    Renewal::Renewed(set) => trace_set(set, passes.balanced()),
                    Renewal::Kept => {}
                }
            }
            gpu.ctx.wait_idle()?;
            trace("GPU pass", start);
            let secs = start.elapsed().as_secs_f64() / engines.len().max(1) as f64;
            for (e, _) in &engines {
                self.secs_per_sample[Backend::Gpu as usize][*e as usize] =
                    secs / (width as f64 * height as f64).max(1.0);
            }
            let light_sets: Vec<Option<LightSetStatus>> = schedules
                .iter()
                .map(|p| LightSetStatus::of(p.last_set(), p.balanced()))
                .collect();
            let rendered = gpu_streams(gpu, &engines, &light_sets)?;
            tell_cut_short(self.shared, &gpu.cut_told, rendered.cut_short);
            self.publish(
                rendered.streams,
                extra(pass + 1 == job.max_spp, rendered.error_stats),
            );
            if let Some(c) = self.newer() {
                return Ok(Some(c));
            }
        }
        Ok(self.wait_for_next())
    }
}

/// Seconds light set 0 took to build (none without lights): what a
/// balanced schedule weighs the later sets' builds against.
fn set_build_secs(lights: Option<&InternalLights>) -> f64 {
    lights.map_or(0.0, |l| l.timings.total())
}

/// One GPU renderer per estimator of `job`.
fn gpu_engines(
    ctx: &GpuContext,
    job: &Job,
    prepared: &PreparedScene,
    lights: Option<&InternalLights>,
) -> Result<Vec<(Method, GpuRenderer)>, GpuError> {
    job.estimators
        .iter()
        .map(|&e| {
            let settings = settings_for(job, e);
            let renderer = match e {
                Method::Reference => GpuRenderer::reference(ctx, prepared, settings.seed)?,
                Method::Internal => {
                    let lights = lights.ok_or_else(|| GpuError::Wgpu {
                        context: "the internal-lights gather".into(),
                        message: "the internal lights were not built".into(),
                    })?;
                    GpuRenderer::internal(
                        ctx,
                        prepared,
                        lights,
                        settings.internal.expert.light_samples,
                        settings.seed,
                    )?
                }
            };
            Ok((e, renderer))
        })
        .collect()
}

/// Streams rendered on the GPU and what the statistics pass said of them.
struct GpuStreams {
    /// One per engine.
    streams: Vec<StreamImage>,
    /// With both estimators: the RMSE of internal lights against the
    /// reference, and the reference's mean.
    error_stats: Option<(f32, f32)>,
    /// Pixel passes that the driver cut short, and all pixel passes, over
    /// the streams.
    cut_short: (u64, u64),
}

/// Tells the user once (`told`) that the GPU driver cut `cut.0` of
/// `cut.1` pixel passes short (the image too dark: lavapipe's loop cap
/// with heavy gather settings), and forgets it once an image comes with
/// no pass cut, so that it is told again if it comes back.
fn tell_cut_short(shared: &Shared, told: &std::cell::Cell<bool>, (cut, all): (u64, u64)) {
    match crate::gpu::cut_short_passes_text(cut, all) {
        Some(text) if !told.get() => {
            told.set(true);
            push_error(
                shared,
                format!(
                    "warning: {text}; render on the CPU, or with fewer light samples or window \
                     scatterings (Expert)"
                ),
            );
        }
        Some(_) => {}
        None => told.set(false),
    }
}

/// The streams of GPU renderers whose passes have finished, with their
/// noise figures (and, with both estimators, the RMSE of internal lights
/// against the reference and the reference's mean) from the statistics
/// pass.
/// `light_sets` holds each engine's light-set status (missing: none).
fn gpu_streams(
    gpu: &GpuWorker,
    engines: &[(Method, GpuRenderer)],
    light_sets: &[Option<LightSetStatus>],
) -> Result<GpuStreams, GpuError> {
    let reference = engines
        .iter()
        .find(|(e, _)| *e == Method::Reference)
        .map(|(_, r)| r.accum_buffer());
    let mut error_stats = None;
    let mut streams = Vec::new();
    let mut cut = (0u64, 0u64);
    for (i, (estimator, engine)) in engines.iter().enumerate() {
        let (width, height) = engine.size();
        let other = match estimator {
            Method::Internal => reference,
            Method::Reference => None,
        };
        let stats: ImageStats = gpu.stats.stats(
            engine.accum_buffer(),
            other,
            width,
            height,
            engine.samples(),
        )?;
        if other.is_some() {
            error_stats = Some((stats.rmse(), stats.second_mean));
        }
        cut.0 += stats.cut_short_passes;
        cut.1 += u64::from(width) * u64::from(height) * u64::from(engine.samples());
        streams.push(StreamImage {
            estimator: *estimator,
            width,
            height,
            spp: engine.samples(),
            mean: Vec::new(),
            rel_error: stats.rel_error(engine.samples()),
            single: None,
            internal: None,
            gpu: Some(GpuStream {
                ctx: gpu.ctx.clone(),
                accum: engine.accum_buffer().clone(),
            }),
            light_sets: light_sets.get(i).copied().flatten(),
        });
    }
    Ok(GpuStreams {
        streams,
        error_stats,
        cut_short: cut,
    })
}

/// What the low-resolution first look needs.
struct PreviewInput<'a> {
    density: &'a Density,
    /// The job's medium at full resolution (the preview copies its volume).
    prepared: &'a PreparedScene,
    sky: &'a Option<crate::scene::LoadedSky>,
    bounds: Option<(Vec3, Vec3)>,
}

/// Lights of the coarse set built before the full one.
const COARSE_LIGHTS: u32 = 128;
/// Walks per light of the coarse set.
const COARSE_WALKS: u32 = 4;

/// Prints the duration of a worker stage when `LANTERN_TRACE` is set.
fn trace(stage: &str, since: Instant) {
    if std::env::var_os("LANTERN_TRACE").is_some() {
        eprintln!(
            "lantern: {stage} {:.1} ms",
            since.elapsed().as_secs_f64() * 1e3
        );
    }
}

/// Prints, when `LANTERN_TRACE` is set, that light set `set` begins, with
/// what the balanced schedule chose for it (its kernel and why, its
/// length).
fn trace_set(set: u32, schedule: Option<&BalancedRenewal>) {
    if std::env::var_os("LANTERN_TRACE").is_none() {
        return;
    }
    match (LightSetStatus::of(set, schedule), schedule) {
        (Some(status), Some(b)) => {
            eprintln!("lantern: {}, {} passes", status.label(), b.period())
        }
        _ => eprintln!("lantern: light set {set} (fixed schedule)"),
    }
}

impl JobContext<'_> {
    /// Renders and publishes one pass at a reduced resolution chosen so that
    /// it takes about [`PREVIEW_BUDGET`] (on the job's backend; on the CPU
    /// if the GPU fails); returns a newer command if one arrived (or the
    /// wait after a cancellation).
    fn preview(
        &mut self,
        input: &mut PreviewInput<'_>,
        lights: Option<Arc<InternalLights>>,
    ) -> Option<Command> {
        let job = self.job;
        let (width, height) = (job.scene.camera.width, job.scene.camera.height);
        let backend = self.backend() as usize;
        let expected: f64 = job
            .estimators
            .iter()
            .map(|&e| width as f64 * height as f64 * self.preview_secs[backend][e as usize])
            .sum();
        let factor = (expected / PREVIEW_BUDGET.as_secs_f64())
            .sqrt()
            .ceil()
            .clamp(1.0, MAX_PREVIEW_FACTOR) as u32;
        if factor <= 1 {
            return None;
        }
        // Where even the coarsest preview overruns its budget, the CPU's
        // internal-lights preview takes fewer light samples
        // ([`preview_light_samples`]); its cost is taken as proportional.
        let at_factor = expected / (factor * factor) as f64;
        let light_share = if self.gpu.is_none() {
            (PREVIEW_BUDGET.as_secs_f64() / at_factor).min(1.0)
        } else {
            1.0
        };
        let full_samples = job.scene.render.internal.expert.light_samples;
        let samples = preview_light_samples(full_samples, light_share);
        let t = Instant::now();
        let mut small = job.scene.clone();
        small.camera.width = (width / factor).max(1);
        small.camera.height = (height / factor).max(1);
        let prepared_small = Arc::new(input.prepared.with_scene(
            small.clone(),
            input.density.clone(),
            input.sky,
        ));
        let gpu_streams = self.gpu.as_deref().map(|gpu| {
            let mut engines = gpu_engines(&gpu.ctx, job, &prepared_small, lights.as_deref())?;
            for (_, engine) in engines.iter_mut() {
                engine.add_pass(0);
            }
            gpu.ctx.wait_idle()?;
            gpu_streams(gpu, &engines, &[]).map(|rendered| rendered.streams)
        });
        let streams = match gpu_streams {
            Some(Ok(mut streams)) => {
                for s in &mut streams {
                    s.spp = 0;
                    s.rel_error = 1.0;
                }
                streams
            }
            // The full passes will report the GPU's trouble, if it lasts.
            Some(Err(_)) | None => {
                let mut streams = Vec::new();
                for &estimator in &job.estimators {
                    let mut settings = settings_for(job, estimator);
                    settings.internal.expert.light_samples = samples;
                    let cached = if estimator == Method::Internal {
                        lights.clone()
                    } else {
                        None
                    };
                    let renderer = Renderer::with_lights(prepared_small.clone(), &settings, cached);
                    let Some(pass) = renderer.pass(0, self.cancel) else {
                        return self.next_command();
                    };
                    streams.push(StreamImage {
                        estimator,
                        width: small.camera.width,
                        height: small.camera.height,
                        spp: 0,
                        mean: pass.total,
                        rel_error: 1.0,
                        single: None,
                        internal: None,
                        gpu: None,
                        light_sets: None,
                    });
                }
                streams
            }
        };
        // What this preview cost against what was expected of it: the next
        // preview's factor follows.
        let predicted: f64 = job
            .estimators
            .iter()
            .map(|&e| {
                let pixels = f64::from(small.camera.width) * f64::from(small.camera.height);
                let share = if e == Method::Internal {
                    f64::from(samples) / f64::from(full_samples.max(1))
                } else {
                    1.0
                };
                pixels * self.preview_secs[backend][e as usize] * share
            })
            .sum();
        let ratio = (t.elapsed().as_secs_f64() / predicted.max(1e-9)).clamp(0.1, 10.0);
        for &e in &job.estimators {
            self.preview_secs[backend][e as usize] *= ratio;
        }
        let view = lights.map(|l| Arc::new(LightsView::new(l, &job.scene)));
        self.publish(
            streams,
            SnapshotExtra {
                lights: view,
                shares: None,
                done: false,
                bounds: input.bounds,
                error_stats: None,
            },
        );
        trace(
            &format!("preview (1/{factor} of the size, {samples} light samples)"),
            t,
        );
        self.newer()
    }
}

/// The parts of a snapshot besides the images.
struct SnapshotExtra {
    lights: Option<Arc<LightsView>>,
    shares: Option<Arc<Renderer>>,
    done: bool,
    bounds: Option<(Vec3, Vec3)>,
    error_stats: Option<(f32, f32)>,
}

fn stream_image(
    estimator: Method,
    films: &[Film; 3],
    light_sets: Option<LightSetStatus>,
) -> StreamImage {
    let film = &films[0];
    let mean = film.mean();
    let variance = film.variance_of_mean();
    let luminance = |v: Vec3| v.dot(Vec3::new(0.2126, 0.7152, 0.0722));
    let n = mean.len().max(1) as f64;
    let mean_l: f64 = mean.iter().map(|&v| luminance(v) as f64).sum::<f64>() / n;
    let mean_var: f64 = variance.iter().map(|&v| luminance(v) as f64).sum::<f64>() / n;
    let rel_error = if mean_l > 0.0 && film.samples >= 2 {
        (mean_var.sqrt() / mean_l) as f32
    } else {
        1.0
    };
    StreamImage {
        estimator,
        width: film.width,
        height: film.height,
        spp: film.samples,
        mean,
        rel_error,
        single: Some(films[1].mean()),
        internal: Some(films[2].mean()),
        gpu: None,
        light_sets,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::internal::sources::KERNEL_NEIGHBOURS;

    /// The driver's cut passes are told once while they last (a toast for
    /// every pass of every job would bury the window), with their share
    /// and what to do; a job whose passes are whole again re-arms it.
    #[test]
    fn cut_short_passes_are_told_once_while_they_last() {
        let shared = Shared {
            latest: Mutex::new(None),
            errors: Mutex::new(Vec::new()),
            wake: Box::new(|_| {}),
        };
        let told = std::cell::Cell::new(false);
        let taken = |shared: &Shared| std::mem::take(&mut *shared.errors.lock().expect("errors"));
        tell_cut_short(&shared, &told, (0, 4096));
        assert!(taken(&shared).is_empty());
        tell_cut_short(&shared, &told, (1024, 4096));
        let said = taken(&shared);
        assert_eq!(said.len(), 1, "{said:?}");
        assert!(
            said[0].contains("1024 of 4096 pixel passes short (25.000 %)")
                && said[0].contains("render on the CPU"),
            "{}",
            said[0]
        );
        tell_cut_short(&shared, &told, (2048, 8192));
        assert!(taken(&shared).is_empty(), "told twice");
        tell_cut_short(&shared, &told, (0, 4096));
        tell_cut_short(&shared, &told, (5, 4096));
        assert_eq!(taken(&shared).len(), 1, "not told again when it came back");
    }

    /// A preview within its budget keeps the settings' light samples; one
    /// over it takes them in proportion, never fewer than two (or than the
    /// settings' own, where those are fewer).
    #[test]
    fn previews_over_budget_take_fewer_light_samples() {
        assert_eq!(preview_light_samples(8, 1.0), 8);
        assert_eq!(preview_light_samples(8, f64::NAN), 8);
        assert_eq!(preview_light_samples(8, 0.5), 4);
        assert_eq!(preview_light_samples(8, 0.3), 2);
        assert_eq!(preview_light_samples(8, 0.01), 2);
        assert_eq!(preview_light_samples(1, 0.1), 1);
    }

    /// The overlay's light-set status: none without a balanced schedule;
    /// a fresh schedule's first set holds the first set's kernel, undecided; the
    /// decision reads in words.
    #[test]
    fn light_set_status_says_what_the_schedule_chose() {
        assert_eq!(LightSetStatus::of(3, None), None);
        let mut schedule = BalancedRenewal::new(4, 2);
        schedule.add_set_build(0.1);
        let first = LightSetStatus::of(0, Some(&schedule)).expect("balanced");
        assert_eq!(
            (
                first.kernel_neighbours,
                first.sets_outweigh_passes,
                first.noise_scale
            ),
            (KERNEL_NEIGHBOURS, None, None)
        );
        assert_eq!(
            first.label(),
            format!("light set 0, kernel {KERNEL_NEIGHBOURS} lights")
        );
        let wide = LightSetStatus {
            set: 7,
            kernel_neighbours: 22,
            sets_outweigh_passes: Some(true),
            noise_scale: Some(1.4),
        };
        assert_eq!(
            wide.label(),
            "light set 7, kernel 22 lights (shrinking slowly: noisy sets)"
        );
        let shrunk = LightSetStatus {
            sets_outweigh_passes: Some(false),
            kernel_neighbours: 16,
            ..wide
        };
        assert_eq!(
            shrunk.label(),
            "light set 7, kernel 16 lights (shrunk: quiet sets)"
        );
    }

    fn job(eye: Vec3, view_walks: u32) -> Job {
        let mut scene = Scene::default();
        scene.camera.eye = eye;
        scene.render.internal.expert.view_walks = view_walks;
        scene.render.internal.expert.view_share = 0.0;
        Job {
            scene,
            scene_dir: PathBuf::from("."),
            estimators: vec![Method::Internal],
            max_spp: 1,
            backend: Backend::Cpu,
        }
    }

    /// Moving the camera keeps the cached lights, unless they hold view
    /// walks towards the old eye.
    #[test]
    fn lights_cache_follows_the_eye_only_with_view_walks() {
        let (a, b) = (Vec3::new(0.0, 0.0, 4.0), Vec3::new(1.0, 0.5, 4.0));
        assert!(LightsCache::key_of(&job(a, 0)) == LightsCache::key_of(&job(b, 0)));
        assert!(LightsCache::key_of(&job(a, 16)) != LightsCache::key_of(&job(b, 16)));
        assert!(LightsCache::key_of(&job(a, 16)) == LightsCache::key_of(&job(a, 16)));
    }

    /// Lights placed in the camera's windows follow the whole camera.
    #[test]
    fn lights_cache_follows_the_camera_with_lights_in_view() {
        let in_view = |eye: Vec3, fov: f32| {
            let mut j = job(eye, 0);
            j.scene.render.internal.expert.view_share = 0.5;
            j.scene.camera.fov_y_deg = fov;
            LightsCache::key_of(&j)
        };
        let a = Vec3::new(0.0, 0.0, 4.0);
        assert!(in_view(a, 40.0) == in_view(a, 40.0));
        assert!(in_view(a, 40.0) != in_view(Vec3::new(1.0, 0.5, 4.0), 40.0));
        assert!(in_view(a, 40.0) != in_view(a, 30.0));
    }
}
