//! The command line: headless rendering, export and benchmarks.
//!
//! `lantern render SCENE.ron --out FILE.exr|FILE.png [--backend cpu|gpu]`
//! renders a still; `lantern bench [--backend cpu|gpu] [--size WxH]`
//! measures passes and samples per second on the example scenes;
//! `lantern` alone, or `lantern view [SCENE]`, opens the previewer.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cpu::Renderer;
use crate::gpu::walks::build_internal_lights_gpu;
use crate::gpu::{GpuContext, GpuRenderer};
use crate::physics::internal::BuildTimings;
use crate::render::export::{write_exr_with_metadata, write_image};
use crate::render::film::image_mean;
use crate::render::tonemap::ViewTransform;
use crate::render::{
    internal_params, internal_params_for_set, light_set, light_set_starting, Film, Prepared,
};
use crate::scene::{Clock, InternalSettings, L1Form, Method, Quality, RenderSettings, Scene};

/// Lantern: multiple scattering as internal lights, live.
#[derive(Debug, Parser)]
#[command(name = "lantern", version, about)]
pub struct Cli {
    /// What to do; without one, the previewer opens.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Which backend renders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// The rayon CPU renderer (both methods).
    #[default]
    Cpu,
    /// The wgpu compute renderer (both methods; internal lights built on
    /// the GPU).
    Gpu,
}

/// An image size on the command line: `N` (square) or `WxH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageSize {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl std::str::FromStr for ImageSize {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        let parse = |v: &str| {
            v.trim()
                .parse::<u32>()
                .map_err(|_| format!("{s:?}: expected N or WIDTHxHEIGHT in pixels"))
        };
        let (width, height) = match s.split_once(['x', 'X', '×']) {
            Some((w, h)) => (parse(w)?, parse(h)?),
            None => {
                let n = parse(s)?;
                (n, n)
            }
        };
        Ok(Self { width, height })
    }
}

/// The internal lights' presets on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum QualityArg {
    /// Fewer walks and gather points: fast light sets for live edits.
    Preview,
    /// The settings the accuracy targets are measured with (the default).
    Final,
}

impl From<QualityArg> for Quality {
    fn from(q: QualityArg) -> Self {
        match q {
            QualityArg::Preview => Quality::Preview,
            QualityArg::Final => Quality::Final,
        }
    }
}

/// Overrides of the internal-lights parameters (default: the scene's).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct InternalArgs {
    /// Preset of the internal lights' settings: replaces the scene's, and
    /// the flags below override it.
    #[arg(long, value_enum)]
    pub quality: Option<QualityArg>,
    /// Window length s* (distance, or mean free paths for the optical-depth clock).
    #[arg(long)]
    pub s_star: Option<f32>,
    /// Number of internal lights M.
    #[arg(long = "lights")]
    pub lights: Option<u32>,
    /// Series truncation N (terms k = 0..=N).
    #[arg(long)]
    pub terms: Option<u32>,
    /// Time-gated walks per light K.
    #[arg(long)]
    pub walks: Option<u32>,
    /// Spherical-harmonics order of F and J.
    #[arg(long)]
    pub sh_order: Option<u32>,
    /// Kernel radius h (world units; default: 2.5 x the mean light spacing).
    #[arg(long)]
    pub kernel_radius: Option<f32>,
    /// Uniform fraction u of the light placement.
    #[arg(long)]
    pub uniform_mix: Option<f32>,
    /// What the path-length clock counts.
    #[arg(long, value_enum)]
    pub clock: Option<Clock>,
    /// The form of the gather's L1 (single scatter of the internal lights).
    #[arg(long, value_enum)]
    pub l1: Option<L1Form>,
    /// Scatterings inside the final window that the field form of L1
    /// follows (1: the note's single-scatter kernel; 2, 3: the next terms).
    #[arg(long)]
    pub window_scatters: Option<u32>,
    /// Walks per light towards the camera, for the view's L0 (0: none;
    /// L0 then reads the lights' spherical harmonics).
    #[arg(long)]
    pub view_walks: Option<u32>,
    /// Internal-light samples per camera sample.
    #[arg(long)]
    pub light_samples: Option<u32>,
    /// Share of the lights placed in the camera rays' windows instead of
    /// by density (0..=1).
    #[arg(long)]
    pub view_share: Option<f32>,
    /// Passes per set of internal lights; a fresh set (the seed's next)
    /// after each such run of passes, so the walk noise averages out
    /// (0: one set for the whole render).
    #[arg(long)]
    pub resample_every: Option<u32>,
}

impl InternalArgs {
    /// Writes the given overrides into `settings`.
    pub fn apply(&self, settings: &mut InternalSettings) {
        if let Some(q) = self.quality {
            *settings = Quality::from(q).settings();
        }
        if let Some(v) = self.s_star {
            settings.s_star = Some(v);
        }
        if let Some(v) = self.lights {
            settings.lights = v;
        }
        if let Some(v) = self.terms {
            settings.terms = v;
        }
        if let Some(v) = self.walks {
            settings.walks = v;
        }
        if let Some(v) = self.sh_order {
            settings.sh_order = v;
        }
        if let Some(v) = self.kernel_radius {
            settings.kernel_radius = Some(v);
        }
        if let Some(v) = self.uniform_mix {
            settings.uniform_mix = v;
        }
        if let Some(v) = self.clock {
            settings.clock = v;
        }
        if let Some(v) = self.l1 {
            settings.l1 = v;
        }
        if let Some(v) = self.window_scatters {
            settings.window_scatters = v;
        }
        if let Some(v) = self.view_walks {
            settings.view_walks = v;
        }
        if let Some(v) = self.light_samples {
            settings.light_samples = v;
        }
        if let Some(v) = self.view_share {
            settings.view_share = v;
        }
        if let Some(v) = self.resample_every {
            settings.resample_every = v;
        }
    }
}

/// `lantern render`'s time limit and variance output.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct TimedArgs {
    /// Render passes until this many seconds are spent (the internal
    /// lights' build included), at least one; `--spp` is then an upper
    /// bound (without it the scene's spp is ignored). The spp reached and
    /// the seconds are printed and stored in the EXR header.
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
    /// Also write the variance of each pixel's mean (sample variance /
    /// spp) to this EXR, as `converge --converged` and `equal-time` read
    /// it next to a converged image (`NAME_var.exr` beside `NAME.exr`).
    #[arg(long, value_name = "FILE.exr")]
    pub variance: Option<PathBuf>,
}

/// When a progressive render stops: after `max_spp` passes, or once
/// `seconds` are spent, whichever comes first; the first pass is always
/// rendered, and a pass once begun is finished (a render overshoots its
/// time by at most one pass).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopRule {
    /// At most this many passes (`None`: only the time limits).
    pub max_spp: Option<u32>,
    /// Seconds after which no pass is begun (`None`: only `max_spp`).
    pub seconds: Option<f64>,
}

impl StopRule {
    /// Whether to begin another pass after `passes` passes and `elapsed`
    /// seconds.
    pub fn another(&self, passes: u32, elapsed: f64) -> bool {
        if passes == 0 {
            return true;
        }
        if passes >= self.max_spp.unwrap_or(u32::MAX) {
            return false;
        }
        self.seconds.is_none_or(|s| elapsed < s)
    }
}

/// What `lantern render` stores in an EXR header (`lantern/…` text
/// attributes, read back by [`crate::render::export::read_exr_metadata`]):
/// the spp reached, the seconds spent (the internal lights' build
/// included), the method, the seed, the backend, the time limit if any,
/// and for the internal-lights method its settings (RON) and resolved `s*`.
pub fn render_metadata(
    settings: &RenderSettings,
    spp: u32,
    seconds: f64,
    backend: BackendArg,
    time_limit: Option<f64>,
    s_star: Option<f32>,
) -> Vec<(String, String)> {
    let mut meta = vec![
        ("lantern/spp".to_owned(), spp.to_string()),
        ("lantern/seconds".to_owned(), format!("{seconds:.4}")),
        (
            "lantern/method".to_owned(),
            match settings.method {
                Method::Reference => "reference",
                Method::Internal => "internal",
            }
            .to_owned(),
        ),
        ("lantern/seed".to_owned(), settings.seed.to_string()),
        (
            "lantern/backend".to_owned(),
            format!("{backend:?}").to_lowercase(),
        ),
    ];
    if let Some(t) = time_limit {
        meta.push(("lantern/time_limit".to_owned(), t.to_string()));
    }
    if settings.method == Method::Internal {
        if let Ok(ron) = ron::to_string(&settings.internal) {
            meta.push(("lantern/internal".to_owned(), ron));
        }
        if let Some(s) = s_star {
            meta.push(("lantern/s_star".to_owned(), s.to_string()));
        }
    }
    meta
}

/// Writes a render's image (EXR with `meta` in its header, or PNG) and,
/// if asked, the variance of its pixel means (EXR).
fn write_render(
    out: &Path,
    film: &Film,
    exposure: f32,
    view: ViewTransform,
    meta: &[(String, String)],
    variance: Option<&Path>,
) -> Result<()> {
    let (w, h) = (film.width, film.height);
    if crate::render::export::extension(out).as_deref() == Some("exr") {
        write_exr_with_metadata(out, w, h, &film.mean(), meta)?;
    } else {
        write_image(out, w, h, &film.mean(), exposure, view)?;
    }
    if let Some(path) = variance {
        let mut meta = meta.to_vec();
        meta.push((
            "lantern/content".to_owned(),
            "variance of the pixel mean".to_owned(),
        ));
        write_exr_with_metadata(path, w, h, &film.variance_of_mean(), &meta)?;
    }
    Ok(())
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Open the interactive previewer (the default without a subcommand).
    View {
        /// A scene (.ron) or volume (.vdb, .vol) to open instead of the
        /// last session's scene.
        scene: Option<PathBuf>,
    },
    /// Render a scene to an image file.
    Render {
        /// The scene file (.ron).
        scene: PathBuf,
        /// The estimator (default: the scene's setting).
        #[arg(long, value_enum)]
        method: Option<Method>,
        /// Samples per pixel (default: the scene's setting).
        #[arg(long)]
        spp: Option<u32>,
        /// Output file: .exr (32-bit float, linear) or .png (8-bit sRGB).
        #[arg(long)]
        out: PathBuf,
        /// Random seed (default: the scene's setting).
        #[arg(long)]
        seed: Option<u64>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Which backend renders (gpu: for the internal-lights method the
        /// lights are placed and walked on the GPU too; only their spatial
        /// indices are built on the CPU).
        #[arg(long, value_enum, default_value_t = BackendArg::Cpu)]
        backend: BackendArg,
        /// Exposure in stops, for PNG output.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        exposure: f32,
        /// View transform, for PNG output.
        #[arg(long, value_enum, default_value_t = ViewTransform::Filmic)]
        view: ViewTransform,
        /// Internal-lights parameters.
        #[command(flatten)]
        internal: InternalArgs,
        /// Time limit and variance output.
        #[command(flatten)]
        timed: TimedArgs,
    },
    /// Measure the renderer's speed (samples per second) on scenes.
    Bench {
        /// Scene files (default: every scene in assets/scenes).
        scenes: Vec<PathBuf>,
        /// Samples per pixel per repetition.
        #[arg(long, default_value_t = 8)]
        spp: u32,
        /// Repetitions; the median is reported.
        #[arg(long, default_value_t = 5)]
        repeats: u32,
        /// Image size override: N (square) or WIDTHxHEIGHT, e.g. 1920x1080
        /// (default: the scene's camera).
        #[arg(long)]
        size: Option<ImageSize>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// The estimator.
        #[arg(long, value_enum, default_value_t = Method::Reference)]
        method: Method,
        /// Which backend renders (gpu: for the internal-lights method the
        /// lights are placed and walked on the GPU too; only their spatial
        /// indices are built on the CPU).
        #[arg(long, value_enum, default_value_t = BackendArg::Cpu)]
        backend: BackendArg,
        /// Internal-lights parameters.
        #[command(flatten)]
        internal: InternalArgs,
    },
    /// Measure the internal-lights method against the reference: sweeps of
    /// s* (with (N+1)s* fixed), N and M; prints a table and writes images and
    /// plots.
    Validate(crate::validate::ValidateArgs),
    /// RMSE against time of both renderers against a converged reference,
    /// and their equal-error time ratio; writes a CSV and a PNG plot.
    Converge(crate::converge::ConvergeArgs),
    /// Where the internal-lights image's noise comes from: per-pixel noise
    /// of each part of the gather with one light set and across light sets,
    /// and the distribution of single walks.
    Noise(crate::noise::NoiseArgs),
    /// The internal lights against the reference at equal wall time on
    /// scenes with a converged reference (mean error per channel, 8×8-block
    /// and per-pixel RMSE); writes report.md and report.csv.
    EqualTime(crate::equal_time::EqualTimeArgs),
}

/// Runs the command line; the binary's `main` calls this.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        None => open_previewer(None),
        Some(Command::View { scene }) => open_previewer(scene),
        Some(Command::Render {
            scene,
            method,
            spp,
            out,
            seed,
            threads,
            backend,
            exposure,
            view,
            internal,
            timed,
        }) => {
            set_threads(threads)?;
            render_command(
                &scene, method, spp, &out, seed, backend, exposure, view, &internal, &timed,
            )
        }
        Some(Command::Bench {
            scenes,
            spp,
            repeats,
            size,
            threads,
            method,
            backend,
            internal,
        }) => {
            set_threads(threads)?;
            bench_command(scenes, spp, repeats, size, method, backend, &internal)
        }
        Some(Command::Validate(args)) => crate::validate::run(&args),
        Some(Command::Converge(args)) => crate::converge::run(&args),
        Some(Command::Noise(args)) => crate::noise::run(&args),
        Some(Command::EqualTime(args)) => crate::equal_time::run(&args),
    }
}

/// Opens the previewer; scripted runs (screenshot, latency measurement)
/// are configured through `LANTERN_*` environment variables.
fn open_previewer(scene: Option<PathBuf>) -> Result<()> {
    crate::ui::run(crate::ui::LaunchOptions {
        scene,
        script: crate::ui::app::Script::from_env(),
    })
}

/// Sizes the global thread pool for `--threads` (checked against the
/// cores first: [`crate::render::limits::check_threads`]).
fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        let cores = crate::render::limits::cores();
        if let Some(warning) =
            crate::render::limits::check_threads(n, cores).map_err(anyhow::Error::msg)?
        {
            eprintln!("warning: {warning}");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot configure the thread pool")?;
    }
    Ok(())
}

/// Loads a scene and prepares it for rendering.
pub fn load_prepared(path: &Path) -> Result<Prepared> {
    let scene = Scene::load(path)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    Ok(Prepared::new(scene, dir)?)
}

#[allow(clippy::too_many_arguments)] // one per command-line option
fn render_command(
    scene_path: &Path,
    method: Option<Method>,
    spp: Option<u32>,
    out: &Path,
    seed: Option<u64>,
    backend: BackendArg,
    exposure: f32,
    view: ViewTransform,
    internal: &InternalArgs,
    timed: &TimedArgs,
) -> Result<()> {
    match crate::render::export::extension(out).as_deref() {
        Some("exr") | Some("png") => {}
        _ => bail!("{}: output must end in .exr or .png", out.display()),
    }
    if !exposure.is_finite() {
        bail!("--exposure must be finite");
    }
    if spp == Some(0) {
        bail!("--spp must be at least 1");
    }
    // Before any work: the output can be written, and the image fits.
    crate::atomic::check_writable(out)?;
    if let Some(t) = timed.time {
        if !(t.is_finite() && t > 0.0) {
            bail!("--time must be a positive number of seconds");
        }
    }
    if let Some(v) = &timed.variance {
        if crate::render::export::extension(v).as_deref() != Some("exr") {
            bail!("{}: --variance must end in .exr", v.display());
        }
    }
    let t_load = Instant::now();
    let scene = Scene::load(scene_path)?;
    crate::render::limits::check_image_fits(
        scene.camera.width,
        scene.camera.height,
        &format!("{}: camera.width/height", scene_path.display()),
    )
    .map_err(anyhow::Error::msg)?;
    let dir = scene_path.parent().unwrap_or(Path::new("."));
    let prepared = Arc::new(Prepared::new(scene, dir)?);
    let load_secs = t_load.elapsed().as_secs_f64();
    let mut settings = prepared.scene.render.clone();
    if let Some(m) = method {
        settings.method = m;
    }
    if let Some(s) = spp {
        settings.spp = s;
    }
    if let Some(s) = seed {
        settings.seed = s;
    }
    internal.apply(&mut settings.internal);
    settings
        .internal
        .validate(scene_path)
        .context("invalid internal-lights parameter on the command line")?;
    for warning in crate::render::limits::warnings(&prepared, &settings) {
        eprintln!("warning: {warning}");
    }
    if backend == BackendArg::Gpu {
        let rule = stop_rule(spp, settings.spp, timed);
        return render_gpu(
            scene_path, &prepared, &settings, load_secs, out, exposure, view, rule, timed,
        );
    }
    let method = settings.method;
    let (w, h) = (prepared.camera.width, prepared.camera.height);
    let t_build = Instant::now();
    let never = AtomicBool::new(false);
    let renderer = Renderer::new(prepared.clone(), &settings, &never)
        .context("internal-light build was cancelled")?;
    let build_secs = t_build.elapsed().as_secs_f64();
    if let Some(lights) = renderer.internal_lights() {
        println!(
            "internal lights: M = {}, s* = {:.4}, N = {}, K = {}, h = {:.4}, clock {:?}: placed in {:.3} s, walked in {:.3} s",
            lights.len(),
            lights.s_star,
            lights.params.terms,
            lights.params.walks,
            lights.kernel_radius,
            lights.params.clock,
            lights.timings.placement,
            lights.timings.walks + lights.timings.index,
        );
    }

    let rule = stop_rule(spp, settings.spp, timed);
    let bar = pass_bar(rule);
    let start = Instant::now();
    let mut film = Film::new(w, h);
    let mut single = Film::new(w, h);
    let mut pass = 0;
    while rule.another(pass, t_build.elapsed().as_secs_f64()) {
        let img = renderer
            .pass(pass, &never)
            .context("render was cancelled")?;
        film.add_pass(&img.total);
        single.add_pass(&img.single);
        if let (0, Some(n)) = (pass, rule.max_spp) {
            warn_long_render(start.elapsed().as_secs_f64(), n);
        }
        bar.inc(1);
        pass += 1;
    }
    let spent = t_build.elapsed().as_secs_f64();
    bar.finish_and_clear();
    check_flights()?;
    let sets = pass
        .checked_sub(1)
        .map_or(0, |last| light_set(&settings, last));
    if method == Method::Internal && sets > 0 {
        println!(
            "{sets} more light sets (one every {} passes), walked within the render time below",
            settings.internal.resample_every
        );
    }
    let secs = start.elapsed().as_secs_f64();
    let samples = w as f64 * h as f64 * film.samples as f64;
    let s_star = renderer.internal_lights().map(|l| l.s_star);
    let meta = render_metadata(
        &settings,
        film.samples,
        spent,
        BackendArg::Cpu,
        timed.time,
        s_star,
    );
    write_render(out, &film, exposure, view, &meta, timed.variance.as_deref())?;
    print_time_limit(timed, film.samples, spent);
    let mean = film.image_mean();
    println!(
        "rendered {} ({w}×{h}, {} spp, {:?}) in {:.2} s (+{:.2} s loading, {:.2} s re-sampling): {:.3} M samples/s; image mean RGB {:.5} {:.5} {:.5}; wrote {}",
        scene_path.display(),
        film.samples,
        method,
        secs,
        load_secs,
        build_secs,
        samples / secs / 1e6,
        mean.x,
        mean.y,
        mean.z,
        out.display()
    );
    print_parts(mean, single.image_mean(), method);
    Ok(())
}

/// Renders estimated from the first pass to take longer than this (in
/// seconds) are announced with the estimate.
const LONG_RENDER_SECS: f64 = 600.0;

/// After the first pass (`first` seconds): warns with the estimated time of
/// all `spp` passes if it is long.
fn warn_long_render(first: f64, spp: u32) {
    let total = first * spp as f64;
    if total > LONG_RENDER_SECS {
        eprintln!(
            "warning: the first pass took {first:.3} s, so {spp} passes will take about {} \
             (lower --spp for a shorter render)",
            crate::render::limits::duration(total)
        );
    }
}

/// Fails if any flight was refused for a non-finite ray (see
/// [`crate::physics::tracking::non_finite_flights`]): the image would be
/// wrong, so it is not written over a good one.
fn check_flights() -> Result<()> {
    let n = crate::physics::tracking::non_finite_flights();
    if n > 0 {
        bail!(
            "{n} rays met non-finite values (an infinite or NaN position, direction or \
             distance) and were skipped: the image would be wrong, so it was not written; \
             please report the scene"
        );
    }
    Ok(())
}

/// Prints the image mean split into single scatter and the rest (multiple
/// scatter for the reference, the internal-light part otherwise).
fn print_parts(mean: glam::Vec3, single: glam::Vec3, method: Method) {
    let rest = mean - single;
    println!(
        "  single scatter mean {:.5} {:.5} {:.5}; {} mean {:.5} {:.5} {:.5}",
        single.x,
        single.y,
        single.z,
        match method {
            Method::Reference => "multiple scatter",
            Method::Internal => "internal-light part",
        },
        rest.x,
        rest.y,
        rest.z
    );
}

/// A progress bar over the passes of `rule`: a bar to its spp, or a
/// count of passes when only its time limits.
fn pass_bar(rule: StopRule) -> ProgressBar {
    let (bar, template) = match (rule.seconds, rule.max_spp) {
        (None, Some(spp)) => (
            ProgressBar::new(spp as u64),
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} spp ({eta})",
        ),
        _ => (
            ProgressBar::no_length(),
            "{spinner} [{elapsed_precise}] {pos} spp",
        ),
    };
    bar.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// The stop rule of `lantern render`: `settings_spp` passes, or with
/// `--time` passes until the time is spent, at most `--spp` if given.
fn stop_rule(spp_arg: Option<u32>, settings_spp: u32, timed: &TimedArgs) -> StopRule {
    match timed.time {
        Some(t) => StopRule {
            max_spp: spp_arg,
            seconds: Some(t),
        },
        None => StopRule {
            max_spp: Some(settings_spp),
            seconds: None,
        },
    }
}

/// With `--time`: the spp reached and the seconds spent.
fn print_time_limit(timed: &TimedArgs, spp: u32, spent: f64) {
    if let Some(t) = timed.time {
        println!("--time {t}: {spp} spp in {spent:.3} s (the internal lights' build included)");
    }
}

/// The GPU device for `--backend gpu`, with a notice of what it is.
fn gpu_context() -> Result<GpuContext> {
    let ctx = GpuContext::new_headless()?;
    println!(
        "GPU backend on {}{}",
        ctx.describe(),
        if ctx.is_software() {
            " (software rendering on the CPU: timings are not GPU timings)"
        } else {
            ""
        }
    );
    Ok(ctx)
}

/// `render --backend gpu`: the reference method on the GPU, accumulated
/// there and read back once for the image file.
#[allow(clippy::too_many_arguments)] // render_command's options
fn render_gpu(
    scene_path: &Path,
    prepared: &Prepared,
    settings: &RenderSettings,
    load_secs: f64,
    out: &Path,
    exposure: f32,
    view: ViewTransform,
    rule: StopRule,
    timed: &TimedArgs,
) -> Result<()> {
    let (w, h) = (prepared.camera.width, prepared.camera.height);
    let ctx = gpu_context()?;
    let t_build = Instant::now();
    let (mut renderer, _) = gpu_renderer(&ctx, prepared, settings)?;
    renderer.finish()?;
    let build_secs = t_build.elapsed().as_secs_f64();
    let bar = pass_bar(rule);
    let start = Instant::now();
    let mut sets = 0;
    let mut resample_secs = 0.0;
    let mut pass = 0;
    while rule.another(pass, t_build.elapsed().as_secs_f64()) {
        let renew =
            light_set_starting(settings, pass).filter(|_| settings.method == Method::Internal);
        if let Some(set) = renew {
            // A fresh light set, walked on the GPU like the first.
            let t = Instant::now();
            sets = set;
            let params = internal_params_for_set(prepared, settings, set);
            let lights = build_internal_lights_gpu(&ctx, prepared, &params)?;
            renderer.set_internal_lights(&lights, settings.internal.light_samples)?;
            resample_secs += t.elapsed().as_secs_f64();
        }
        renderer.add_pass(pass);
        // Waiting after each pass keeps the progress bar honest and the
        // queue short; the accumulation itself stays on the GPU.
        renderer.finish()?;
        if let (0, Some(n)) = (pass, rule.max_spp) {
            warn_long_render(start.elapsed().as_secs_f64(), n);
        }
        bar.inc(1);
        pass += 1;
    }
    let spent = t_build.elapsed().as_secs_f64();
    bar.finish_and_clear();
    if sets > 0 {
        println!(
            "{sets} more light sets (one every {} passes) walked in {resample_secs:.2} s, included below",
            settings.internal.resample_every
        );
    }
    let secs = start.elapsed().as_secs_f64();
    let image = renderer.read_back()?;
    let film = image.film();
    let s_star =
        (settings.method == Method::Internal).then(|| internal_params(prepared, settings).s_star);
    let meta = render_metadata(
        settings,
        film.samples,
        spent,
        BackendArg::Gpu,
        timed.time,
        s_star,
    );
    write_render(out, &film, exposure, view, &meta, timed.variance.as_deref())?;
    print_time_limit(timed, film.samples, spent);
    let mean = film.image_mean();
    let single = image_mean(&image.single_mean());
    let samples = w as f64 * h as f64 * film.samples as f64;
    println!(
        "rendered {} ({w}×{h}, {} spp, {:?}, GPU) in {:.2} s (+{:.2} s loading, {:.2} s lights, pipeline and upload, {:.1} MiB on the GPU): {:.3} M samples/s; image mean RGB {:.5} {:.5} {:.5}; wrote {}",
        scene_path.display(),
        film.samples,
        settings.method,
        secs,
        load_secs,
        build_secs,
        renderer.gpu_bytes() as f64 / (1024.0 * 1024.0),
        samples / secs / 1e6,
        mean.x,
        mean.y,
        mean.z,
        out.display()
    );
    print_parts(mean, single, settings.method);
    Ok(())
}

/// The GPU renderer for `settings.method`; for the internal-lights method
/// the lights are built on the GPU first (placement and walks, then the
/// spatial indices on the CPU), and their build times come back too.
fn gpu_renderer(
    ctx: &GpuContext,
    prepared: &Prepared,
    settings: &RenderSettings,
) -> Result<(GpuRenderer, Option<BuildTimings>)> {
    match settings.method {
        Method::Reference => Ok((GpuRenderer::reference(ctx, prepared, settings.seed)?, None)),
        Method::Internal => {
            let params = internal_params(prepared, settings);
            let lights = build_internal_lights_gpu(ctx, prepared, &params)?;
            println!(
                "internal lights (built on the GPU): M = {}, s* = {:.4}, N = {}, K = {}, clock {:?}: placed in {:.3} s, walked in {:.3} s (GPU), indexed in {:.3} s (CPU)",
                lights.len(),
                lights.s_star,
                lights.params.terms,
                lights.params.walks,
                lights.params.clock,
                lights.timings.placement,
                lights.timings.walks,
                lights.timings.index,
            );
            let renderer = GpuRenderer::internal(
                ctx,
                prepared,
                &lights,
                settings.internal.light_samples,
                settings.seed,
            )?;
            Ok((renderer, Some(lights.timings)))
        }
    }
}

/// Times `spp` passes of the GPU renderer `repeats` times (each with its
/// own seed, accumulation cleared); returns the set-up time (internal
/// lights built on the GPU, pipeline, upload), the median render time and,
/// for the internal-lights method, the re-sampling time on the GPU
/// (placement and walks).
fn bench_gpu(
    ctx: &GpuContext,
    prepared: &Prepared,
    spp: u32,
    repeats: u32,
) -> Result<(f64, f64, Option<f64>)> {
    let start = Instant::now();
    let mut settings = prepared.scene.render.clone();
    settings.seed = 0;
    let (mut renderer, timings) = gpu_renderer(ctx, prepared, &settings)?;
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
        timings.map(|t| t.placement + t.walks),
    ))
}

fn bench_command(
    scenes: Vec<PathBuf>,
    spp: u32,
    repeats: u32,
    size: Option<ImageSize>,
    method: Method,
    backend: BackendArg,
    internal: &InternalArgs,
) -> Result<()> {
    if spp == 0 || repeats == 0 {
        bail!("--spp and --repeats must be at least 1");
    }
    let gpu = match backend {
        BackendArg::Cpu => None,
        BackendArg::Gpu => Some(gpu_context()?),
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
            BackendArg::Cpu => "re-sample s",
            BackendArg::Gpu => "set-up s",
        },
        match (backend, method) {
            (BackendArg::Gpu, Method::Internal) => format!(" {:>16}", "GPU re-sample s"),
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
        let prepared = Arc::new(Prepared::new(scene, dir)?);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::export::{read_exr, read_exr_metadata};

    /// The first pass always; then the spp bound, the time, or both.
    #[test]
    fn stop_rule_bounds_passes_and_time() {
        let spp = StopRule {
            max_spp: Some(3),
            seconds: None,
        };
        assert!(spp.another(0, 1e9) && spp.another(2, 1e9) && !spp.another(3, 0.0));
        let time = StopRule {
            max_spp: None,
            seconds: Some(2.0),
        };
        assert!(time.another(0, 5.0), "at least one pass");
        assert!(time.another(1000, 1.99) && !time.another(1, 2.0));
        let both = StopRule {
            max_spp: Some(10),
            seconds: Some(2.0),
        };
        assert!(!both.another(10, 0.5) && !both.another(4, 2.5) && both.another(4, 0.5));
    }

    fn meta_value<'a>(meta: &'a [(String, String)], key: &str) -> &'a str {
        meta.iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
            .unwrap_or_else(|| panic!("{key} missing from {meta:?}"))
    }

    /// `render --time`: passes until the time is spent, the spp and the
    /// seconds in the EXR header with the method and seed, and the variance
    /// file beside it; `--spp` bounds the passes under a long time.
    #[test]
    fn render_time_stores_spp_and_seconds() {
        let dir = tempfile::tempdir().unwrap();
        let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/thin_sphere.ron");
        let out = dir.path().join("timed.exr");
        let var = dir.path().join("timed_var.exr");
        let args = |extra: &[&str]| {
            let mut v: Vec<String> = ["lantern", "render", scene.to_str().unwrap(), "--out"]
                .iter()
                .map(|s| s.to_string())
                .collect();
            v.push(out.to_string_lossy().into_owned());
            v.extend(extra.iter().map(|s| s.to_string()));
            Cli::parse_from(v)
        };
        run(args(&[
            "--time",
            "0.4",
            "--method",
            "reference",
            "--seed",
            "5",
            "--variance",
            var.to_str().unwrap(),
        ]))
        .unwrap();
        let meta = read_exr_metadata(&out).unwrap();
        let spp: u32 = meta_value(&meta, "lantern/spp").parse().unwrap();
        let secs: f64 = meta_value(&meta, "lantern/seconds").parse().unwrap();
        assert!(spp > 1 && secs >= 0.4, "{meta:?}");
        assert_eq!(meta_value(&meta, "lantern/method"), "reference");
        assert_eq!(meta_value(&meta, "lantern/seed"), "5");
        assert_eq!(meta_value(&meta, "lantern/time_limit"), "0.4");
        let (image, variance) = (read_exr(&out).unwrap(), read_exr(&var).unwrap());
        assert_eq!(
            (variance.width, variance.height),
            (image.width, image.height)
        );
        assert!(variance.pixels.iter().any(|v| v.x > 0.0));

        run(args(&[
            "--time", "100", "--spp", "3", "--method", "internal", "--lights", "256", "--walks",
            "4",
        ]))
        .unwrap();
        let meta = read_exr_metadata(&out).unwrap();
        assert_eq!(meta_value(&meta, "lantern/spp"), "3");
        assert_eq!(meta_value(&meta, "lantern/method"), "internal");
        let internal: InternalSettings =
            ron::from_str(meta_value(&meta, "lantern/internal")).unwrap();
        assert_eq!((internal.lights, internal.walks), (256, 4));
        assert!(meta_value(&meta, "lantern/s_star").parse::<f32>().unwrap() > 0.0);
    }
}
