//! The render session, backend-neutral: between the backends (`cpu`,
//! `gpu`) and the two front ends (`cli`, `ui`), knowing neither egui nor
//! the command line.
//!
//! - [`Backend`]: where the passes run, CPU or GPU, the one choice both
//!   `lantern render --backend` and the previewer's backend switch make.
//! - [`renew_gpu_lights`]: the internal lights' renewal every
//!   `resample_every` passes (method §7's averaging of the walk noise over
//!   light sets) for a GPU renderer, written once for the command line and
//!   the previewer (the CPU renderer renews its own sets in
//!   [`crate::cpu::Renderer::pass`], on the same schedule,
//!   [`crate::render::light_set`]).
//! - [`worker`]: the previewer's render session, a worker thread owning
//!   the renderers and films, jobs, cancellation, the low-resolution
//!   first pass and the coarse light set.

pub mod worker;

use std::sync::atomic::AtomicBool;

use crate::gpu::walks::build_internal_lights_gpu;
use crate::gpu::{GpuContext, GpuError, GpuRenderer};
use crate::render::{internal_params_for_set, light_set_starting, PreparedScene};
use crate::scene::{Method, RenderSettings};

pub use worker::{
    GpuStream, Job, LightsView, Snapshot, StreamImage, Waker, Worker, REFINE_INTERVAL,
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
    let lights = match builder {
        LightBuilder::Cpu(cancel) => match prepared.build_internal_lights(&params, cancel) {
            Some(lights) => lights,
            None => return Ok(Renewal::Cancelled),
        },
        LightBuilder::Gpu(ctx) => build_internal_lights_gpu(ctx, prepared, &params)?,
    };
    renderer.set_internal_lights(&lights, settings.internal.expert.light_samples)?;
    Ok(Renewal::Renewed(set))
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
