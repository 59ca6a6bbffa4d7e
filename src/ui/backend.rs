//! The one module of the previewer that talks to the renderers.
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

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use glam::Vec3;

use crate::render::{Film, Prepared};
use crate::scene::{Density, DensitySource, Method, Scene};

pub use compat::{ClockKind, InternalSettings};

/// The internal-lights settings, mirrored here until the internal-lights
/// renderer lands in `scene::settings`; the fields are those of the
/// announced API so that only this module changes when it does.
mod compat {
    use serde::{Deserialize, Serialize};

    /// What the path-length clock counts (METHOD.md §3).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
    pub enum ClockKind {
        /// Geometric path length: `s*` is a distance.
        Geometric,
        /// Optical depth: `s*` is a number of mean free paths.
        #[default]
        OpticalDepth,
    }

    /// Parameters of the internal-lights method (METHOD.md §3–§7).
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    #[serde(default)]
    pub struct InternalSettings {
        /// Window length `s*`; `None`: automatic.
        pub s_star: Option<f32>,
        /// Number of internal lights `M`.
        pub lights: u32,
        /// Series truncation `N`.
        pub terms: u32,
        /// Time-gated walks per light `K`.
        pub walks: u32,
        /// Spherical-harmonic order of `F` and `J`.
        pub sh_order: u32,
        /// Kernel radius `h`; `None`: automatic.
        pub kernel_radius: Option<f32>,
        /// Uniform fraction `u` of the placement density.
        pub uniform_mix: f32,
        /// What the path-length clock counts.
        pub clock: ClockKind,
        /// Internal-light samples per camera sample.
        pub light_samples: u32,
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
                light_samples: 2,
            }
        }
    }
}

/// Which estimator a stream of passes uses, as the UI sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Estimator {
    /// Multiple scatter as internal lights.
    Internal,
    /// The unbiased path tracer.
    Reference,
}

/// Whether this build has the internal-lights renderer.
pub const HAS_INTERNAL: bool = false;

/// Everything that determines the picture.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// The scene; its camera's width and height are the render size.
    pub scene: Scene,
    /// The internal-lights settings.
    pub internal: InternalSettings,
    /// Folder that grid paths are relative to.
    pub scene_dir: PathBuf,
    /// One stream per estimator to show (two for the comparisons).
    pub estimators: Vec<Estimator>,
    /// Stop after this many samples per pixel.
    pub max_spp: u32,
}

/// The internal lights as the gizmos need them.
#[derive(Clone, Debug, Default)]
pub struct LightsView {
    /// World positions.
    pub positions: Vec<Vec3>,
    /// Density `ρ` at each light.
    pub density: Vec<f32>,
    /// Volume weight `V_i` of each light.
    pub weight: Vec<f32>,
    /// Mean of `F_i` over directions (RGB).
    pub mean_f: Vec<Vec3>,
    /// Mean of `J_i` over directions (RGB).
    pub mean_j: Vec<Vec3>,
    /// The window length `s*` in world units.
    pub s_star: f32,
    /// Energy carried by each series term `k = 0..N`.
    pub term_energy: Vec<Vec3>,
}

/// The image of one estimator so far.
#[derive(Clone, Debug)]
pub struct StreamImage {
    /// The estimator.
    pub estimator: Estimator,
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
}

/// What the worker last produced for a job.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// Which submission this belongs to (see [`Worker::submit`]).
    pub generation: u64,
    /// One image per requested estimator (same order).
    pub streams: Vec<StreamImage>,
    /// The internal lights, when the internal method runs.
    pub lights: Option<Arc<LightsView>>,
    /// Whether every stream reached `max_spp`.
    pub done: bool,
    /// The medium's world box.
    pub bounds: Option<(Vec3, Vec3)>,
}

/// State shared between the UI and the worker.
struct Shared {
    latest: Mutex<Option<Arc<Snapshot>>>,
    errors: Mutex<Vec<String>>,
    wake: Box<dyn Fn() + Send + Sync>,
}

enum Command {
    Run {
        generation: u64,
        job: Box<Job>,
        cancel: Arc<AtomicBool>,
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
    /// Starts the worker; `wake` is called (from the worker thread) after
    /// every new snapshot or error.
    pub fn start(wake: Box<dyn Fn() + Send + Sync>) -> Self {
        let (tx, rx) = mpsc::channel();
        let shared = Arc::new(Shared {
            latest: Mutex::new(None),
            errors: Mutex::new(Vec::new()),
            wake,
        });
        let worker_shared = shared.clone();
        let thread = std::thread::Builder::new()
            .name("lantern-render".into())
            .spawn(move || worker_loop(rx, worker_shared))
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
    (shared.wake)();
}

fn publish(shared: &Shared, snapshot: Snapshot) {
    if let Ok(mut l) = shared.latest.lock() {
        *l = Some(Arc::new(snapshot));
    }
    (shared.wake)();
}

/// The density of the last scene, kept because baking a procedural cloud
/// or reading a grid is far slower than a pass.
struct DensityCache {
    key: Option<(DensitySource, PathBuf)>,
    density: Option<Density>,
}

impl DensityCache {
    fn get(&mut self, scene: &Scene, dir: &PathBuf) -> Result<Density, String> {
        let key = (scene.medium.density.clone(), dir.clone());
        if self.key.as_ref() != Some(&key) || self.density.is_none() {
            let density = scene.load_density(dir).map_err(|e| format!("{e:#}"))?;
            self.key = Some(key);
            self.density = Some(density);
        }
        self.density.clone().ok_or_else(|| "no density".to_string())
    }
}

/// A renderer for one estimator: the adapter over `cpu`.
struct Engine {
    prepared: Arc<Prepared>,
    estimator: Estimator,
    seed: u64,
}

impl Engine {
    fn build(prepared: Arc<Prepared>, estimator: Estimator, job: &Job) -> Engine {
        Engine {
            prepared,
            estimator,
            seed: job.scene.render.seed,
        }
    }

    /// One sample per pixel; `None` if cancelled.
    fn pass(&self, pass: u32, cancel: &AtomicBool) -> Option<Vec<Vec3>> {
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let method = match self.estimator {
            // Until the internal-lights renderer lands, both streams run the
            // reference so that the rest of the previewer can be exercised.
            Estimator::Internal | Estimator::Reference => Method::Reference,
        };
        let out = crate::cpu::render_pass(&self.prepared, method, self.seed, pass);
        (!cancel.load(Ordering::Relaxed)).then_some(out)
    }

    fn lights(&self) -> Option<LightsView> {
        None
    }
}

/// Target duration of the low-resolution first pass.
const PREVIEW_BUDGET: Duration = Duration::from_millis(35);

fn worker_loop(rx: Receiver<Command>, shared: Arc<Shared>) {
    let mut cache = DensityCache {
        key: None,
        density: None,
    };
    // Seconds per full-resolution pixel-sample, measured; guides the
    // preview's downscale factor.
    let mut secs_per_sample: f64 = 2e-6;
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
            } => (generation, job, cancel),
        };
        // Skip to the newest job if several queued up.
        if let Ok(c) = rx.try_recv() {
            next = Some(c);
            continue;
        }
        next = run_job(
            generation,
            &job,
            &cancel,
            &rx,
            &shared,
            &mut cache,
            &mut secs_per_sample,
        );
    }
}

/// Renders `job` until it is done or replaced; returns the command that
/// replaced it, if any.
fn run_job(
    generation: u64,
    job: &Job,
    cancel: &AtomicBool,
    rx: &Receiver<Command>,
    shared: &Shared,
    cache: &mut DensityCache,
    secs_per_sample: &mut f64,
) -> Option<Command> {
    let density = match cache.get(&job.scene, &job.scene_dir) {
        Ok(d) => d,
        Err(e) => {
            push_error(shared, e);
            return rx.recv().ok();
        }
    };
    if let Ok(c) = rx.try_recv() {
        return Some(c);
    }
    let (width, height) = (job.scene.camera.width, job.scene.camera.height);

    // Low-resolution first look.
    let full_samples = width as f64 * height as f64 * job.estimators.len() as f64;
    let expected = full_samples * *secs_per_sample;
    let factor = (expected / PREVIEW_BUDGET.as_secs_f64())
        .sqrt()
        .ceil()
        .clamp(1.0, 16.0) as u32;
    if factor > 1 {
        let mut small = job.scene.clone();
        small.camera.width = (width / factor).max(1);
        small.camera.height = (height / factor).max(1);
        let prepared = Arc::new(Prepared::with_density(small.clone(), density.clone()));
        let mut streams = Vec::new();
        for &estimator in &job.estimators {
            let engine = Engine::build(prepared.clone(), estimator, job);
            let Some(mean) = engine.pass(0, cancel) else {
                return rx.recv().ok();
            };
            streams.push(StreamImage {
                estimator,
                width: small.camera.width,
                height: small.camera.height,
                spp: 0,
                mean,
                rel_error: 1.0,
                single: None,
                internal: None,
            });
        }
        publish(
            shared,
            Snapshot {
                generation,
                streams,
                lights: None,
                done: false,
                bounds: Some(density.bounds()),
            },
        );
        if let Ok(c) = rx.try_recv() {
            return Some(c);
        }
    }

    let bounds = Some(density.bounds());
    let prepared = Arc::new(Prepared::with_density(job.scene.clone(), density));
    let engines: Vec<Engine> = job
        .estimators
        .iter()
        .map(|&e| Engine::build(prepared.clone(), e, job))
        .collect();
    let lights = engines.iter().find_map(|e| e.lights()).map(Arc::new);
    let mut films: Vec<Film> = engines.iter().map(|_| Film::new(width, height)).collect();
    for pass in 0..job.max_spp {
        for (engine, film) in engines.iter().zip(films.iter_mut()) {
            let start = Instant::now();
            let Some(samples) = engine.pass(pass, cancel) else {
                return rx.recv().ok();
            };
            let secs = start.elapsed().as_secs_f64();
            *secs_per_sample = secs / (width as f64 * height as f64).max(1.0);
            film.add_pass(&samples);
        }
        let streams = engines
            .iter()
            .zip(&films)
            .map(|(e, f)| stream_image(e.estimator, f))
            .collect();
        publish(
            shared,
            Snapshot {
                generation,
                streams,
                lights: lights.clone(),
                done: pass + 1 == job.max_spp,
                bounds,
            },
        );
        if let Ok(c) = rx.try_recv() {
            return Some(c);
        }
    }
    // Done: wait for the next job.
    loop {
        match rx.recv_timeout(Duration::from_secs(3600)) {
            Ok(c) => return Some(c),
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return None,
        }
    }
}

fn stream_image(estimator: Estimator, film: &Film) -> StreamImage {
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
        single: None,
        internal: None,
    }
}
