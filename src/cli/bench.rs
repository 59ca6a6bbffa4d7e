//! `lantern bench`: passes and samples per second of either backend on
//! the example scenes (median of repetitions), with the internal lights'
//! re-sampling or the GPU's set-up time.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use super::args::{ImageSize, InternalArgs};
use super::support::{gpu_context, gpu_renderer};
use crate::cpu::Renderer;
use crate::gpu::GpuContext;
use crate::render::PreparedScene;
use crate::scene::{Method, Scene};
use crate::session::Backend;

/// Options of `lantern bench`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Scene files (default: every scene in assets/scenes).
    pub scenes: Vec<PathBuf>,
    /// Samples per pixel per repetition.
    #[arg(long, default_value_t = 8)]
    pub spp: u32,
    /// Repetitions; the median is reported.
    #[arg(long, default_value_t = 5)]
    pub repeats: u32,
    /// Image size override: N (square) or WIDTHxHEIGHT, e.g. 1920x1080
    /// (default: the scene's camera).
    #[arg(long)]
    pub size: Option<ImageSize>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// The estimator.
    #[arg(long, value_enum, default_value_t = Method::Reference)]
    pub method: Method,
    /// Which backend renders (gpu: for the internal-lights method the
    /// lights are placed and walked on the GPU too; only their spatial
    /// indices are built on the CPU).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
    /// Internal-lights parameters.
    #[command(flatten)]
    pub internal: InternalArgs,
}

/// Times `spp` passes of the GPU renderer `repeats` times (each with its
/// own seed, accumulation cleared); returns the set-up time (internal
/// lights built on the GPU, pipeline, upload), the median render time and,
/// for the internal-lights method, the re-sampling time on the GPU
/// (placement and walks).
fn bench_gpu(
    ctx: &GpuContext,
    prepared: &PreparedScene,
    spp: u32,
    repeats: u32,
) -> Result<(f64, f64, Option<f64>)> {
    let start = Instant::now();
    let mut settings = prepared.scene.render.clone();
    settings.seed = 0;
    let (mut renderer, lights) = gpu_renderer(ctx, prepared, &settings, None)?;
    renderer.finish()?;
    let build = start.elapsed().as_secs_f64();
    // One untimed pass: the first dispatch may still compile or page in.
    renderer.add_pass(0);
    renderer.finish()?;
    let mut times = Vec::new();
    for r in 0..repeats {
        renderer.reset(r as u64);
        renderer.finish()?;
        let start = Instant::now();
        for pass in 0..spp {
            renderer.add_pass(pass);
        }
        renderer.finish()?;
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok((
        build,
        times[times.len() / 2],
        lights.map(|b| b.timings.placement + b.timings.walks),
    ))
}

/// Runs `lantern bench` (the thread pool already sized).
pub fn run(args: &BenchArgs) -> Result<()> {
    let BenchArgs {
        scenes,
        spp,
        repeats,
        size,
        threads: _,
        method,
        backend,
        internal,
    } = args;
    let (spp, repeats, size, method, backend) = (*spp, *repeats, *size, *method, *backend);
    let scenes = scenes.clone();
    if spp == 0 || repeats == 0 {
        bail!("--spp and --repeats must be at least 1");
    }
    let gpu = match backend {
        Backend::Cpu => None,
        Backend::Gpu => Some(gpu_context()?),
    };
    let scenes = if scenes.is_empty() {
        let mut v: Vec<PathBuf> = std::fs::read_dir("assets/scenes")
            .context("cannot list assets/scenes (run from the repository root or name scenes)")?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "ron"))
            .collect();
        v.sort();
        v
    } else {
        scenes
    };
    println!(
        "{:<28} {:>10} {:>6} {:>12} {:>10} {:>14} {:>14}{}",
        "scene",
        "size",
        "spp",
        "median s",
        "passes/s",
        "M samples/s",
        match backend {
            Backend::Cpu => "re-sample s",
            Backend::Gpu => "set-up s",
        },
        match (backend, method) {
            (Backend::Gpu, Method::Internal) => format!(" {:>16}", "GPU re-sample s"),
            _ => String::new(),
        }
    );
    for path in scenes {
        let mut scene = Scene::load(&path)?;
        if let Some(s) = size {
            scene.camera.width = s.width;
            scene.camera.height = s.height;
            scene.validate(&path)?;
        }
        crate::render::limits::check_image_fits(
            scene.camera.width,
            scene.camera.height,
            &format!("{}: --size", path.display()),
        )
        .map_err(anyhow::Error::msg)?;
        scene.render.method = method;
        internal.apply(&mut scene.render.internal);
        scene.render.internal.validate(&path)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let prepared = Arc::new(PreparedScene::new(scene, dir)?);
        let (w, h) = (prepared.camera.width, prepared.camera.height);
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default();
        if let Some(ctx) = &gpu {
            let (build, median, resample) = bench_gpu(ctx, &prepared, spp, repeats)
                .with_context(|| format!("{}", path.display()))?;
            print_bench_row(&name, w, h, spp, median, build, resample);
            continue;
        }
        let never = AtomicBool::new(false);
        let mut times = Vec::new();
        let mut builds = Vec::new();
        for r in 0..repeats {
            let mut settings = prepared.scene.render.clone();
            settings.seed = r as u64;
            let start = Instant::now();
            let renderer =
                Renderer::new(prepared.clone(), &settings, &never).context("cancelled")?;
            builds.push(start.elapsed().as_secs_f64());
            let start = Instant::now();
            for pass in 0..spp {
                std::hint::black_box(renderer.pass(pass, &never));
            }
            times.push(start.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        builds.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        let build = builds[builds.len() / 2];
        print_bench_row(&name, w, h, spp, median, build, None);
    }
    Ok(())
}

/// One row of `lantern bench`'s table: median pass time per `spp`
/// passes, passes and samples per second, the re-sampling (CPU) or set-up
/// (GPU) time, and the GPU's re-sampling time (placement and walks) if any.
fn print_bench_row(
    name: &str,
    w: u32,
    h: u32,
    spp: u32,
    median: f64,
    build: f64,
    gpu_resample: Option<f64>,
) {
    let samples = w as f64 * h as f64 * spp as f64;
    println!(
        "{:<28} {:>10} {:>6} {:>12.3} {:>10.2} {:>14.3} {:>14.3}{}",
        name,
        format!("{w}×{h}"),
        spp,
        median,
        spp as f64 / median,
        samples / median / 1e6,
        build,
        gpu_resample
            .map(|t| format!(" {t:>16.3}"))
            .unwrap_or_default()
    );
}
