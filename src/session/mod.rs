//! The render session, backend-neutral: between the backends (`cpu`,
//! `gpu`) and the two front ends (`cli`, `ui`), knowing neither egui nor
//! the command line.
//!
//! - [`Backend`]: where the passes run, CPU or GPU, the one choice both
//!   `lantern render --backend` and the previewer's backend switch make.
//! - [`GpuPasses`]: a GPU renderer's passes with the internal lights
//!   renewed (method §5.5's averaging of the walk noise over light sets)
//!   every `resample_every` passes ([`renew_gpu_lights`]) or on the
//!   balanced schedule of [`crate::render::renewal`], written once for the
//!   command line and the previewer (the CPU's are [`crate::cpu::Passes`],
//!   on the same schedules).
//! - [`worker`]: the previewer's render session, a worker thread owning
//!   the renderers and films, jobs, cancellation, the low-resolution
//!   first pass and the coarse light set.

pub mod worker;

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use crate::gpu::walks::build_internal_lights_gpu;
use crate::gpu::{GpuContext, GpuError, GpuImage, GpuRenderer};
use crate::physics::internal::sources::InternalParams;
use crate::render::renewal::{whole_set_secs, BalancedRenewal, SetNoise, WeightedSets};
use crate::render::{internal_params_for_set, light_set_starting, PreparedScene};
use crate::scene::{Method, RenderSettings};

pub use worker::{
    GpuStream, Job, LightSetStatus, LightsView, Snapshot, StreamImage, Waker, Worker,
    REFINE_INTERVAL,
};

/// Where the passes run.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
pub enum Backend {
    /// The CPU renderers (rayon), both methods.
    #[value(help = "The rayon CPU renderer (both methods)")]
    Cpu,
    /// wgpu compute shaders, both methods: headless for the command line
    /// (which also places and walks the internal lights there), on the
    /// window's device in the previewer (the default there).
    #[default]
    #[value(help = "The wgpu compute renderer (both methods; internal lights built on the GPU)")]
    Gpu,
}

impl Backend {
    /// "GPU" or "CPU".
    pub fn name(self) -> &'static str {
        match self {
            Backend::Gpu => "GPU",
            Backend::Cpu => "CPU",
        }
    }
}

/// Where a renewed light set is placed and walked.
#[derive(Clone, Copy)]
pub enum LightBuilder<'a> {
    /// On the CPU (the previewer), until `cancel` is raised.
    Cpu(&'a AtomicBool),
    /// On the GPU (the command line), spatial indices on the CPU.
    Gpu(&'a GpuContext),
}

/// What [`renew_gpu_lights`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Renewal {
    /// The pass renders with the lights already there.
    Kept,
    /// The pass starts this light set, now on the renderer.
    Renewed(u32),
    /// The CPU build was cancelled; the renderer is unchanged.
    Cancelled,
}

/// Before pass `pass` of `renderer` (rendering with `settings`): if the
/// pass starts a new light set ([`light_set_starting`]; internal-lights
/// method only), builds it with `builder` and hands it to the renderer.
pub fn renew_gpu_lights(
    renderer: &mut GpuRenderer,
    prepared: &PreparedScene,
    settings: &RenderSettings,
    pass: u32,
    builder: LightBuilder<'_>,
) -> Result<Renewal, GpuError> {
    if settings.method != Method::Internal {
        return Ok(Renewal::Kept);
    }
    let Some(set) = light_set_starting(settings, pass) else {
        return Ok(Renewal::Kept);
    };
    let params = internal_params_for_set(prepared, settings, set);
    let walked = set_gpu_lights(renderer, prepared, settings, &params, builder)?;
    Ok(walked.map_or(Renewal::Cancelled, |_| Renewal::Renewed(set)))
}

/// Builds a light set with `params` and hands it to `renderer`; the share
/// of a whole set's walks it walked
/// ([`InternalLights::walk_share`](crate::physics::internal::sources::InternalLights::walk_share):
/// less than 1 where `params` gave a walk deadline), or `None` where the
/// CPU build was cancelled (the renderer unchanged).
fn set_gpu_lights(
    renderer: &mut GpuRenderer,
    prepared: &PreparedScene,
    settings: &RenderSettings,
    params: &InternalParams,
    builder: LightBuilder<'_>,
) -> Result<Option<f64>, GpuError> {
    let lights = match builder {
        LightBuilder::Cpu(cancel) => match prepared.build_internal_lights(params, cancel) {
            Some(lights) => lights,
            None => return Ok(None),
        },
        LightBuilder::Gpu(ctx) => build_internal_lights_gpu(ctx, prepared, params)?,
    };
    renderer.set_internal_lights(&lights, settings.internal.expert.light_samples)?;
    Ok(Some(lights.walk_share))
}

/// A GPU renderer's passes one after another, its light sets renewed
/// either every `resample_every` passes ([`renew_gpu_lights`]) or on a
/// schedule balanced from the measured noise and costs
/// ([`BalancedRenewal`]: the period, and whether a set's kernel stays wide)
/// as [`crate::cpu::Passes`] does on the CPU. The passes accumulate on the
/// GPU, so the balanced schedule times each pass (waiting for it) and
/// reads the accumulated moments back once per set, at its end: the
/// difference from the read-back at its start is the set's per-pixel sums
/// ([`GpuImage::grey_sums`](crate::gpu::GpuImage::grey_sums)).
pub struct GpuPasses {
    pass: u32,
    set: u32,
    balanced: Option<GpuBalance>,
}

/// A balanced schedule fed from a GPU renderer's read-backs.
struct GpuBalance {
    schedule: BalancedRenewal,
    /// Per pixel the running sum and sum of squares when the current set
    /// began.
    at_set_start: Vec<(f64, f64)>,
    /// The passes' totals by light set, where asked for
    /// ([`GpuPasses::with_weighted_sets`]), and per pixel and channel the
    /// running sums and the passes when the current set began.
    sets: Option<(WeightedSets, Vec<[f64; 3]>, u32)>,
}

impl GpuBalance {
    /// Closes the current set (its sums read back from `renderer`) and
    /// builds set `set` with the schedule's kernel, walking `share` of a
    /// whole set's walks ([`BalancedRenewal::fresh_set_share`]), timed for
    /// the schedule as a whole set's build.
    fn renew(
        &mut self,
        renderer: &mut GpuRenderer,
        prepared: &PreparedScene,
        settings: &RenderSettings,
        set: u32,
        share: f64,
        builder: LightBuilder<'_>,
    ) -> Result<Renewal, GpuError> {
        let t = Instant::now();
        let image = renderer.read_back()?;
        let running = image.grey_sums();
        self.schedule
            .replace_set_sums(&grey_set_sums(&running, &self.at_set_start));
        self.at_set_start = running;
        if let Some((sets, then, passes)) = &mut self.sets {
            let now = image.sums();
            sets.replace_current(set_sums(&now, then), image.samples.saturating_sub(*passes));
            (*then, *passes) = (now, image.samples);
        }
        self.schedule.begin_set(share);
        let kernel = self.schedule.kernel_neighbours();
        let params = InternalParams {
            kernel_neighbours: kernel,
            walk_deadline: self.schedule.walk_deadline(t),
            ..internal_params_for_set(prepared, settings, set)
        };
        let Some(walked) = set_gpu_lights(renderer, prepared, settings, &params, builder)? else {
            return Ok(Renewal::Cancelled);
        };
        let secs = whole_set_secs(t.elapsed().as_secs_f64(), walked);
        self.schedule.add_set_build(secs);
        if let Some((sets, _, _)) = &mut self.sets {
            sets.next_set(self.schedule.set_noise(), kernel, walked);
        }
        Ok(Renewal::Renewed(set))
    }
}

/// A light set's per-pixel sum and sum of squares of the channels' mean:
/// the running ones `now` less those when it began.
fn grey_set_sums(now: &[(f64, f64)], then: &[(f64, f64)]) -> Vec<(f64, f64)> {
    now.iter()
        .zip(then)
        .map(|(n, t)| (n.0 - t.0, n.1 - t.1))
        .collect()
}

/// A light set's per-pixel sums: the running sums `now` less those when
/// it began.
fn set_sums(now: &[[f64; 3]], then: &[[f64; 3]]) -> Vec<[f64; 3]> {
    now.iter()
        .zip(then)
        .map(|(n, t)| [n[0] - t[0], n[1] - t[1], n[2] - t[2]])
        .collect()
}

impl GpuPasses {
    /// Passes of `renderer` (rendering with `settings`) from pass 0;
    /// `balanced` asks for the balanced schedule, which applies to the
    /// internal-lights method with renewed sets (`resample_every` > 0: it
    /// is the first sets' length); `build_secs` is what set 0 took to
    /// build.
    pub fn new(
        renderer: &GpuRenderer,
        settings: &RenderSettings,
        balanced: bool,
        build_secs: f64,
    ) -> Self {
        let every = settings.internal.expert.resample_every;
        let balanced = (balanced && settings.method == Method::Internal && every > 0).then(|| {
            let (width, height) = renderer.size();
            let pixels = width as usize * height as usize;
            let mut schedule = BalancedRenewal::new(pixels, every);
            schedule.add_set_build(build_secs);
            GpuBalance {
                schedule,
                at_set_start: vec![(0.0, 0.0); pixels],
                sets: None,
            }
        });
        Self {
            pass: 0,
            set: 0,
            balanced,
        }
    }

    /// Adds the next pass to `renderer`, building the light set it starts
    /// first (with `builder`) if it starts one; with a balanced schedule,
    /// waits for the pass. [`Renewal::Cancelled`] (and no pass) if a CPU
    /// build was cancelled.
    pub fn next(
        &mut self,
        renderer: &mut GpuRenderer,
        prepared: &PreparedScene,
        settings: &RenderSettings,
        builder: LightBuilder<'_>,
    ) -> Result<Renewal, GpuError> {
        self.next_within(renderer, prepared, settings, builder, None)
    }

    /// [`GpuPasses::next`] for a render that stops `remaining` seconds
    /// from now: with a balanced schedule, the set in hand runs on where a
    /// fresh one would not pay before then, and a fresh one may walk part
    /// of its walks ([`BalancedRenewal::fresh_set_share`]).
    pub fn next_within(
        &mut self,
        renderer: &mut GpuRenderer,
        prepared: &PreparedScene,
        settings: &RenderSettings,
        builder: LightBuilder<'_>,
        remaining: Option<f64>,
    ) -> Result<Renewal, GpuError> {
        let renewal = match &mut self.balanced {
            None => renew_gpu_lights(renderer, prepared, settings, self.pass, builder)?,
            Some(b) if self.pass > 0 && b.schedule.set_is_complete() => {
                let share = remaining.map_or(Some(1.0), |r| b.schedule.fresh_set_share(r));
                match share {
                    Some(share) => {
                        b.renew(renderer, prepared, settings, self.set + 1, share, builder)?
                    }
                    None => Renewal::Kept,
                }
            }
            Some(_) => Renewal::Kept,
        };
        match renewal {
            Renewal::Cancelled => return Ok(renewal),
            Renewal::Renewed(set) => self.set = set,
            Renewal::Kept => {}
        }
        let t = Instant::now();
        renderer.add_pass(self.pass);
        if let Some(b) = &mut self.balanced {
            renderer.finish()?;
            b.schedule.add_pass_secs(t.elapsed().as_secs_f64());
        }
        self.pass += 1;
        Ok(renewal)
    }

    /// Passes added.
    pub fn passes(&self) -> u32 {
        self.pass
    }

    /// The light set of the last pass (0 before any).
    pub fn last_set(&self) -> u32 {
        self.set
    }

    /// The balanced schedule, if the passes follow one.
    pub fn balanced(&self) -> Option<&BalancedRenewal> {
        self.balanced.as_ref().map(|b| &b.schedule)
    }

    /// These passes, keeping their totals by light set where they follow
    /// a balanced schedule, for [`GpuPasses::weighted_image`] (as
    /// [`crate::cpu::Passes::with_weighted_sets`]; call before the first
    /// pass). `first_share` is the share of its walks set 0 walked.
    pub fn with_weighted_sets(mut self, first_share: f64) -> Self {
        if let Some(b) = &mut self.balanced {
            let pixels = b.schedule.pixels();
            let sets = WeightedSets::new(pixels, b.schedule.kernel_neighbours(), first_share);
            b.sets = Some((sets, vec![[0.0; 3]; pixels], 0));
        }
        self
    }

    /// The image of `image`, the renderer's accumulated passes read back,
    /// with each light set's mean weighed by its noise ([`WeightedSets`]),
    /// where the passes follow a balanced schedule and keep their sets
    /// ([`GpuPasses::with_weighted_sets`]); `None` otherwise.
    pub fn weighted_image(&self, image: &GpuImage) -> Option<Vec<glam::Vec3>> {
        let b = self.balanced.as_ref()?;
        let (sets, then, passes) = b.sets.as_ref()?;
        let mut sets = sets.clone();
        sets.replace_current(
            set_sums(&image.sums(), then),
            image.samples.saturating_sub(*passes),
        );
        Some(sets.mean(self.set_noise_now(image)))
    }

    /// The noise an image read back now weighs its sets by: the balanced
    /// schedule's, with the current set closed as it stands in `image`
    /// ([`BalancedRenewal::set_noise_now_with`]).
    pub fn set_noise_now(&self, image: &GpuImage) -> Option<SetNoise> {
        let b = self.balanced.as_ref()?;
        let sums = grey_set_sums(&image.grey_sums(), &b.at_set_start);
        b.schedule.set_noise_now_with(&sums)
    }
}

/// How much lower (in nice steps) the render threads run than the UI.
const RENDER_NICE_STEPS: i32 = 8;

/// Lowers the calling thread's scheduling priority (Linux: the nice value
/// is per thread), so that rendering yields the CPU to the UI thread.
pub fn lower_thread_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: plain system calls on the calling thread's own id, with no
    // pointers involved; failure only leaves the priority as it was.
    unsafe {
        let steps = std::env::var("LANTERN_RENDER_NICE")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(RENDER_NICE_STEPS);
        let tid = libc::gettid() as libc::id_t;
        let current = libc::getpriority(libc::PRIO_PROCESS, tid);
        let _ = libc::setpriority(libc::PRIO_PROCESS, tid, (current + steps).min(19));
    }
}
