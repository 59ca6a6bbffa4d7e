//! `lantern render`: one still, progressive passes on the CPU or the GPU
//! until a sample count or a time limit, written to EXR (with the
//! settings in its header) or PNG, with the variance of the pixel means
//! if asked.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use super::args::{InternalArgs, TimedArgs};
use super::support::{first_set_metadata, gpu_context, gpu_renderer, walks_text, warn_cut_short};
use crate::cpu::{Passes, Renderer};
use crate::render::export::{write_exr_with_metadata, write_image};
use crate::render::film::image_mean;
use crate::render::renewal::{first_set_deadline, BalancedRenewal};
use crate::render::tonemap::ViewTransform;
use crate::render::{internal_params, Film, PreparedScene};
use crate::scene::{Method, RenderSettings, Scene};
use crate::session::{Backend, GpuPasses, LightBuilder, Renewal};
use glam::Vec3;

/// Options of `lantern render`.
#[derive(Clone, Debug, clap::Args)]
pub struct RenderArgs {
    /// The scene file (.ron).
    pub scene: PathBuf,
    /// The estimator (default: the scene's setting).
    #[arg(long, value_enum)]
    pub method: Option<Method>,
    /// Samples per pixel (default: the scene's setting).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Output file: .exr (32-bit float, linear) or .png (8-bit sRGB).
    #[arg(long)]
    pub out: PathBuf,
    /// Random seed (default: the scene's setting).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Which backend renders (gpu: for the internal-lights method the
    /// lights are placed and walked on the GPU too; only their spatial
    /// indices are built on the CPU).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
    /// Exposure in stops, for PNG output.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub exposure: f32,
    /// View transform, for PNG output.
    #[arg(long, value_enum, default_value_t = ViewTransform::Filmic)]
    pub view: ViewTransform,
    /// Internal-lights parameters.
    #[command(flatten)]
    pub internal: InternalArgs,
    /// Time limit and variance output.
    #[command(flatten)]
    pub timed: TimedArgs,
}

/// When a progressive render stops: after `max_spp` passes, or once
/// `seconds` are spent, whichever comes first; the first pass is always
/// rendered, and a pass once begun is finished (a render overshoots its
/// time by at most one pass: near the limit a balanced schedule keeps the
/// light set in hand rather than build one it could not use,
/// [`crate::render::renewal::BalancedRenewal::fresh_set_share`]).
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

    /// Seconds left before the time limit after `elapsed` (`None`: no time
    /// limit), which the balanced light sets are scheduled against.
    pub fn remaining(&self, elapsed: f64) -> Option<f64> {
        self.seconds.map(|s| s - elapsed)
    }
}

/// What `lantern render` stores in an EXR header (`lantern/…` text
/// attributes, read back by [`crate::render::export::read_exr_metadata`]):
/// the spp reached, the seconds spent (the internal lights' build
/// included), the method, the seed, the backend, the time limit if any,
/// and for the internal-lights method its settings (RON) and resolved `s*`
/// (`lantern render` adds `lantern/first_set_walks` and
/// `lantern/first_set_share` where a time limit cut the first light set's
/// walks short: [`super::support::first_set_metadata`]).
pub fn render_metadata(
    settings: &RenderSettings,
    spp: u32,
    seconds: f64,
    backend: Backend,
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

/// Writes a render's image (EXR with `meta` in its header, or PNG):
/// `image`, the mean of `film`'s passes or, with a balanced schedule of
/// light sets, their sets weighed by their noise
/// ([`WeightedSets`](crate::render::renewal::WeightedSets)); and, if
/// asked, the variance of its pixel means from the spread of `film`'s
/// passes (EXR).
fn write_render(
    out: &Path,
    film: &Film,
    image: &[Vec3],
    exposure: f32,
    view: ViewTransform,
    meta: &[(String, String)],
    variance: Option<&Path>,
) -> Result<()> {
    let (w, h) = (film.width, film.height);
    if crate::render::export::extension(out).as_deref() == Some("exr") {
        write_exr_with_metadata(out, w, h, image, meta)?;
    } else {
        write_image(out, w, h, image, exposure, view)?;
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

/// Runs `lantern render` (the thread pool already sized).
pub fn run(args: &RenderArgs) -> Result<()> {
    let RenderArgs {
        scene: scene_path,
        method,
        spp,
        out,
        seed,
        threads: _,
        backend,
        exposure,
        view,
        internal,
        timed,
    } = args;
    let (method, spp, seed, backend, exposure, view) =
        (*method, *spp, *seed, *backend, *exposure, *view);
    let (scene_path, out) = (scene_path.as_path(), out.as_path());
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
    let prepared = Arc::new(PreparedScene::new(scene, dir)?);
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
    if backend == Backend::Gpu {
        let rule = stop_rule(spp, settings.spp, timed);
        return render_gpu(args, &prepared, &settings, load_secs, rule);
    }
    let method = settings.method;
    let (w, h) = (prepared.camera.width, prepared.camera.height);
    let t_build = Instant::now();
    let never = AtomicBool::new(false);
    // With a time limit, set 0's walks stop early where a whole set would
    // leave no time for its passes.
    let walk_deadline = first_set_deadline(t_build, timed.time);
    let renderer = Renderer::new_within(prepared.clone(), &settings, &never, walk_deadline)
        .context("internal-light build was cancelled")?;
    let build_secs = t_build.elapsed().as_secs_f64();
    if let Some(lights) = renderer.internal_lights() {
        let walks = walks_text(lights.walked, lights.params.walks, lights.walk_share);
        println!(
            "internal lights: M = {}, s* = {:.4}, N = {}, K = {walks}, K_v = {}, h = {:.4}, clock {:?}: placed in {:.3} s, walked in {:.3} s",
            lights.len(),
            lights.s_star,
            lights.params.terms,
            lights.params.view_walks,
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
    let balanced = timed.time.is_some() && !timed.fixed_renewal;
    let mut passes = Passes::new(&renderer, balanced, build_secs).with_weighted_sets(&renderer);
    while rule.another(passes.passes(), t_build.elapsed().as_secs_f64()) {
        let remaining = rule.remaining(t_build.elapsed().as_secs_f64());
        let img = passes
            .next_within(&renderer, &never, remaining)
            .context("render was cancelled")?;
        film.add_pass(&img.total);
        single.add_pass(&img.single);
        if let (1, Some(n)) = (passes.passes(), rule.max_spp) {
            warn_long_render(start.elapsed().as_secs_f64(), n);
        }
        bar.inc(1);
    }
    let spent = t_build.elapsed().as_secs_f64();
    bar.finish_and_clear();
    check_flights()?;
    print_sets(
        &settings,
        passes.last_set(),
        passes.balanced(),
        ", walked within the render time below",
    );
    let secs = start.elapsed().as_secs_f64();
    let samples = w as f64 * h as f64 * film.samples as f64;
    let s_star = renderer.internal_lights().map(|l| l.s_star);
    let mut meta = render_metadata(
        &settings,
        film.samples,
        spent,
        Backend::Cpu,
        timed.time,
        s_star,
    );
    if let Some(l) = renderer.internal_lights() {
        meta.extend(first_set_metadata(l.walked, l.walk_share));
    }
    let image = passes.weighted_image().unwrap_or_else(|| film.mean());
    write_render(
        out,
        &film,
        &image,
        exposure,
        view,
        &meta,
        timed.variance.as_deref(),
    )?;
    print_time_limit(timed, film.samples, spent);
    let mean = image_mean(&image);
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

/// What a render's renewed light sets were, after it: how many, and how
/// long the last lasted and what its kernel held where the schedule was
/// balanced (`extra` ends the line: where the time went).
fn print_sets(
    settings: &RenderSettings,
    sets: u32,
    balanced: Option<&BalancedRenewal>,
    extra: &str,
) {
    if settings.method != Method::Internal || sets == 0 {
        return;
    }
    match balanced {
        None => println!(
            "{sets} more light sets (one every {} passes){extra}",
            settings.internal.expert.resample_every
        ),
        Some(b) => {
            let estimates = b.estimates().map_or(String::new(), |e| {
                format!(
                    " (per-pixel variance of a pass {:.3e}, of a set {:.3e}; {:.3} s a pass, {:.3} s a set)",
                    e.pass_variance, e.set_variance, e.pass_secs, e.set_secs
                )
            });
            let length = match (b.passes_in_set(), b.period()) {
                (n, p) if n > p => {
                    format!("{n} passes long (run on to the time limit; its period {p})")
                }
                (_, p) => format!("{p} passes long"),
            };
            let share = b.planned_share();
            let length = if share < 1.0 {
                format!(
                    "{length}, begun near the time limit to walk {:.0} % of a set's walks",
                    100.0 * share
                )
            } else {
                length
            };
            println!(
                "{sets} more light sets, balanced against the passes: the last {length}{estimates}, its kernel of {} lights ({}){extra}",
                b.kernel_neighbours(),
                b.kernel_reason()
            );
        }
    }
}

/// `render --backend gpu`: the reference method on the GPU, accumulated
/// there and read back once for the image file.
fn render_gpu(
    args: &RenderArgs,
    prepared: &PreparedScene,
    settings: &RenderSettings,
    load_secs: f64,
    rule: StopRule,
) -> Result<()> {
    let (scene_path, out) = (args.scene.as_path(), args.out.as_path());
    let (exposure, view, timed) = (args.exposure, args.view, &args.timed);
    let (w, h) = (prepared.camera.width, prepared.camera.height);
    let ctx = gpu_context()?;
    let t_build = Instant::now();
    let walk_deadline = first_set_deadline(t_build, timed.time);
    let (mut renderer, build) = gpu_renderer(&ctx, prepared, settings, walk_deadline)?;
    renderer.finish()?;
    let build_secs = t_build.elapsed().as_secs_f64();
    // Set 0's own build time (without the pipelines' compilation), which
    // a balanced schedule weighs later sets' builds against.
    let set_secs = build.map_or(build_secs, |b| b.whole_set_secs());
    let bar = pass_bar(rule);
    let start = Instant::now();
    let balanced = timed.time.is_some() && !timed.fixed_renewal;
    let first_share = build.map_or(1.0, |b| b.walk_share);
    let mut passes =
        GpuPasses::new(&renderer, settings, balanced, set_secs).with_weighted_sets(first_share);
    let mut resample_secs = 0.0;
    while rule.another(passes.passes(), t_build.elapsed().as_secs_f64()) {
        // A fresh light set when the pass starts one, walked on the GPU
        // like the first.
        let t = Instant::now();
        let remaining = rule.remaining(t_build.elapsed().as_secs_f64());
        let builder = LightBuilder::Gpu(&ctx);
        let renewal = passes.next_within(&mut renderer, prepared, settings, builder, remaining)?;
        if let Renewal::Renewed(_) = renewal {
            resample_secs += t.elapsed().as_secs_f64();
        }
        // Waiting after each pass keeps the progress bar honest and the
        // queue short; the accumulation itself stays on the GPU.
        renderer.finish()?;
        if let (1, Some(n)) = (passes.passes(), rule.max_spp) {
            warn_long_render(start.elapsed().as_secs_f64(), n);
        }
        bar.inc(1);
    }
    let spent = t_build.elapsed().as_secs_f64();
    bar.finish_and_clear();
    print_sets(
        settings,
        passes.last_set(),
        passes.balanced(),
        &format!(", walked in {resample_secs:.2} s, included below"),
    );
    let secs = start.elapsed().as_secs_f64();
    let image = renderer.read_back()?;
    warn_cut_short(&image);
    let film = image.film();
    let weighted = passes.weighted_image(&image).unwrap_or_else(|| film.mean());
    let s_star =
        (settings.method == Method::Internal).then(|| internal_params(prepared, settings).s_star);
    let mut meta = render_metadata(
        settings,
        film.samples,
        spent,
        Backend::Gpu,
        timed.time,
        s_star,
    );
    if let Some(b) = build {
        meta.extend(first_set_metadata(b.walked, b.walk_share));
    }
    write_render(
        out,
        &film,
        &weighted,
        exposure,
        view,
        &meta,
        timed.variance.as_deref(),
    )?;
    print_time_limit(timed, film.samples, spent);
    let mean = image_mean(&weighted);
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
