//! `lantern equal-time`: the internal lights against the reference at equal
//! wall time, on scenes with a converged reference (issue 21: the suite of
//! `assets/scenes/suite/` and its references in `tests/data/suite/`, made
//! by `tests/suite/make_references.sh`).
//!
//! For each scene both renderers (CPU) render progressively with seeds
//! other than the converged image's; the clock starts before the renderer
//! is built (the internal lights' placement and walks are paid for) and is
//! paused while the image is measured. At each time `T` of `--times` the
//! internal-lights image is that of a render of its own with `T` as its
//! time limit, as `lantern render --time T` makes it (its light sets are
//! scheduled against that limit: a first set's walks cut short where a
//! whole set would not leave time for a pass, the set in hand run on near
//! the limit), taken at the end of its first pass at or past `T` (so at
//! most one pass more); the reference renders once, its image taken at
//! the end of its first pass at or past the time each of those took (its
//! passes last milliseconds): both have run the same wall time, however
//! long an internal-lights pass is. On the GPU (`--backend gpu`) the same:
//! a render of its own to each time, its first set's walks cut short on
//! the device where a whole set would not fit. Each image is compared
//! with the converged one:
//!
//! - the error of the image mean per channel, `mean(a)/mean(c) − 1`, signed
//!   (the converged mean's own standard error, printed above each table,
//!   is not removed: a signed error has nothing to subtract);
//! - the RMSE of the 8×8 block means ([`block_rmse_against`]) and
//! - the per-pixel RMSE ([`rmse_against`]), both relative to the converged
//!   image's mean, with the converged image's noise removed from their
//!   mean squared errors: `E[(a − c)²] = E[(a − μ)²] + Var[c]` for a
//!   converged image `c` independent of the render, so the mean of its
//!   per-pixel variance of the mean (`NAME_var.exr`), or of its block
//!   means' variance `Σ Var / 64²`, is subtracted (clamped at 0).
//!
//! With `--seeds N` each method renders `N` times at each time (seeds
//! `seed`, `seed + 2`, …; the reference's one more), and the table gives
//! the mean of the signed mean errors and the root mean square of the
//! RMSEs over them: one render's blocks on a thick cloud vary by a tenth
//! from seed to seed, more than most changes measured with this command.
//!
//! Output: a Markdown table per scene on stdout, and `report.md` and
//! `report.csv` (a row per render, with its seed) in `--out`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use glam::Vec3;

use super::args::InternalArgs;
use super::support::{
    gpu_context, gpu_renderer, load_square, renewal_text, variance_path, walk_split_text,
    warn_cut_short,
};
use crate::cpu::{Passes, Renderer};
use crate::gpu::GpuContext;
use crate::render::export::{read_exr, read_exr_metadata, RgbImage};
use crate::render::film::image_mean;
use crate::render::renewal::{first_set_deadline, BalancedRenewal};
use crate::render::stats::{block_rmse_against, compare, rmse_against, BLOCK};
use crate::render::{Film, PreparedScene};
use crate::scene::{Method, RenderSettings};
use crate::session::{Backend, GpuPasses, LightBuilder};

/// Options of `lantern equal-time`.
#[derive(Clone, Debug, clap::Args)]
pub struct EqualTimeArgs {
    /// Scene files (.ron); each needs `NAME.exr` and `NAME_var.exr` in
    /// `--converged-dir`, NAME being the scene file's stem.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Folder of the converged references.
    #[arg(long, default_value = "tests/data/suite")]
    pub converged_dir: PathBuf,
    /// Wall times in seconds at which both renders are measured.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub times: Vec<f64>,
    /// Image side in pixels (overrides the scene's camera; 0 keeps it);
    /// must match the converged references.
    #[arg(long, default_value_t = 0)]
    pub size: u32,
    /// Worker threads for the renders (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Which backend renders both methods (gpu: the internal lights are
    /// placed and walked on the GPU too, each snapshot is read back from
    /// the GPU's accumulation; the read-backs are not counted as time).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
    /// Seed of the internal-lights render (the reference renders with
    /// seed + 1); both must differ from the converged image's.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Renders of each method at each time, with seeds `seed`, `seed + 2`,
    /// … (the reference's one more): the table then gives the mean of the
    /// mean errors and the root mean square of the RMSEs over them, and
    /// the CSV a row per render. One render's blocks on a thick cloud
    /// vary by a tenth from seed to seed.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub seeds: u32,
    /// Output folder for report.md and report.csv.
    #[arg(long, default_value = "target/equal-time")]
    pub out: PathBuf,
    /// Renew the internal lights' set every `resample_every` passes
    /// instead of balancing the sets' length against the passes from the
    /// noise and costs measured while rendering (`lantern render --time`'s
    /// default, which this command measures).
    #[arg(long)]
    pub fixed_renewal: bool,
    /// Internal-lights parameters (default: the scene's).
    #[command(flatten)]
    pub internal: InternalArgs,
}

/// The three errors of an image against a converged one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Errors {
    /// Relative error of the image mean per channel, signed.
    pub mean: Vec3,
    /// RMSE of the 8×8 block means relative to the converged mean, the
    /// converged image's noise removed.
    pub block: f32,
    /// Per-pixel RMSE relative to the converged mean, the converged
    /// image's noise removed.
    pub pixel: f32,
}

/// [`Errors`] of `image` against `converged` (`width` × `height`, row-major)
/// whose per-pixel variance of the mean is `converged_var`.
pub fn errors(
    image: &[Vec3],
    converged: &[Vec3],
    converged_var: &[Vec3],
    width: usize,
    height: usize,
) -> Errors {
    Errors {
        mean: compare(image, converged).0,
        block: block_rmse_against(image, converged, converged_var, width, height),
        pixel: rmse_against(image, converged, converged_var),
    }
}

/// One measurement: a method at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    /// The time asked for.
    pub target: f64,
    /// Seconds actually spent (at least `target`, at most one pass more).
    pub secs: f64,
    /// Samples per pixel by then.
    pub spp: u32,
    /// The errors then.
    pub errors: Errors,
}

/// The converged image that snapshots are measured against.
struct Truth<'a> {
    image: &'a [Vec3],
    var: &'a [Vec3],
    width: usize,
    height: usize,
}

impl Truth<'_> {
    /// Measures `image` (the mean of `spp` passes after `elapsed`, asked
    /// for at `target` seconds) and says so under `label`; `on` names the
    /// backend where it is not the CPU.
    fn snapshot(
        &self,
        label: &str,
        target: f64,
        spp: u32,
        elapsed: Duration,
        image: &[Vec3],
        on: &str,
    ) -> Snapshot {
        let errors = errors(image, self.image, self.var, self.width, self.height);
        eprintln!(
            "{label}: {target} s: {spp} spp in {:.2} s{on}, pixel RMSE {:.2} %",
            elapsed.as_secs_f64(),
            100.0 * errors.pixel
        );
        Snapshot {
            target,
            secs: elapsed.as_secs_f64(),
            spp,
            errors,
        }
    }
}

/// Measures the image at each of `times` (ascending), as the module says:
/// for the internal lights a render of its own to each time, for the
/// reference one render with a snapshot at each; `render_to` renders to
/// the times it is given ([`render_to`] on the CPU, [`gpu_render_to`] on
/// the GPU).
fn snapshots(
    method: Method,
    times: &[f64],
    mut render_to: impl FnMut(&[f64]) -> Result<Vec<Snapshot>>,
) -> Result<Vec<Snapshot>> {
    if method == Method::Internal {
        let mut out = Vec::with_capacity(times.len());
        for &t in times {
            out.extend(render_to(&[t])?);
        }
        return Ok(out);
    }
    render_to(times)
}

/// Renders progressively with `settings` to the last of `times`
/// (ascending) and measures the image at each: the light sets are
/// scheduled against the first as the render's time limit, then against
/// each next.
fn render_to(
    prepared: &Arc<PreparedScene>,
    settings: &RenderSettings,
    times: &[f64],
    truth: &Truth<'_>,
    label: &str,
    balanced: bool,
) -> Result<Vec<Snapshot>> {
    let never = AtomicBool::new(false);
    let start = Instant::now();
    // As `lantern render --time` with the first time as its limit: set 0's
    // walks stop where a whole set would leave no time for its passes.
    let walk_deadline = first_set_deadline(start, times.first().copied());
    let renderer = Renderer::new_within(prepared.clone(), settings, &never, walk_deadline)
        .context("render was cancelled")?;
    let mut elapsed = start.elapsed();
    let mut passes =
        Passes::new(&renderer, balanced, elapsed.as_secs_f64()).with_weighted_sets(&renderer);
    let cam = prepared.camera;
    let mut film = Film::new(cam.width, cam.height);
    let mut out = Vec::new();
    let mut pass = 0;
    for &target in times {
        let due = Duration::from_secs_f64(target);
        while pass == 0 || elapsed < due {
            let start = Instant::now();
            let remaining = due.saturating_sub(elapsed).as_secs_f64();
            let img = passes
                .next_within(&renderer, &never, Some(remaining))
                .context("render was cancelled")?;
            film.add_pass(&img.total);
            elapsed += start.elapsed();
            pass += 1;
        }
        report_set(label, passes.last_set(), passes.balanced());
        let image = passes.weighted_image().unwrap_or_else(|| film.mean());
        out.push(truth.snapshot(label, target, pass, elapsed, &image, ""));
    }
    Ok(out)
}

/// Prints which light set a snapshot ended on and the balanced period,
/// where the passes follow a balanced schedule.
fn report_set(label: &str, set: u32, balanced: Option<&BalancedRenewal>) {
    if let Some(b) = balanced {
        eprintln!(
            "{label}: light set {set} of {} passes (balanced)",
            b.period()
        );
    }
}

/// [`render_to`] on the GPU: the same schedule of light sets (fixed or
/// balanced, [`GpuPasses`]), set 0's walks ending near three quarters of
/// the first time as on the CPU, the passes accumulated on the device and
/// read back at each of `times`; the time counted is the build (pipelines
/// included) and the passes, not the read-backs.
fn gpu_render_to(
    ctx: &GpuContext,
    prepared: &PreparedScene,
    settings: &RenderSettings,
    times: &[f64],
    truth: &Truth<'_>,
    label: &str,
    balanced: bool,
) -> Result<Vec<Snapshot>> {
    let start = Instant::now();
    let walk_deadline = first_set_deadline(start, times.first().copied());
    let (mut renderer, build) = gpu_renderer(ctx, prepared, settings, walk_deadline)?;
    renderer.finish()?;
    let mut elapsed = start.elapsed();
    let set_secs = build.map_or(elapsed.as_secs_f64(), |b| b.whole_set_secs());
    let first_share = build.map_or(1.0, |b| b.walk_share);
    let mut passes =
        GpuPasses::new(&renderer, settings, balanced, set_secs).with_weighted_sets(first_share);
    let mut out = Vec::new();
    for &target in times {
        let due = Duration::from_secs_f64(target);
        while passes.passes() == 0 || elapsed < due {
            let start = Instant::now();
            let remaining = Some(due.saturating_sub(elapsed).as_secs_f64());
            passes.next_within(
                &mut renderer,
                prepared,
                settings,
                LightBuilder::Gpu(ctx),
                remaining,
            )?;
            // (A balanced schedule has waited for the pass already.)
            renderer.finish()?;
            elapsed += start.elapsed();
        }
        report_set(label, passes.last_set(), passes.balanced());
        let image = renderer.read_back()?;
        warn_cut_short(&image);
        let mean = passes
            .weighted_image(&image)
            .unwrap_or_else(|| image.film().mean());
        out.push(truth.snapshot(label, target, passes.passes(), elapsed, &mean, " (GPU)"));
    }
    Ok(out)
}

/// Builds both methods' GPU renderers once, one pass each, on `scene`
/// before anything is timed: a hardware driver compiles the pipelines on
/// first use (6.2 s on the H200, which the first scene's first snapshot
/// counted) and keeps them for the process.
fn warm_up(ctx: &GpuContext, scene: &Path, size: u32) -> Result<()> {
    let prepared = load_square(scene, size)?;
    for method in [Method::Internal, Method::Reference] {
        let mut settings = prepared.scene.render.clone();
        settings.method = method;
        let (mut renderer, _) = gpu_renderer(ctx, &prepared, &settings, None)?;
        renderer.add_pass(0);
        renderer.finish()?;
    }
    Ok(())
}

/// A converged reference and what its header says about it.
struct Converged {
    image: RgbImage,
    var: Vec<Vec3>,
    spp: Option<String>,
    seed: Option<u64>,
}

fn read_converged(dir: &Path, stem: &str, w: u32, h: u32) -> Result<Converged> {
    let path = dir.join(format!("{stem}.exr"));
    let var_path = variance_path(&path);
    let read = |p: &Path| read_exr(p).with_context(|| format!("cannot read {}", p.display()));
    let (image, var) = (read(&path)?, read(&var_path)?);
    for img in [&image, &var] {
        if (img.width, img.height) != (w, h) {
            bail!(
                "{} or {} is {}×{}, but the render is {w}×{h} (--size)",
                path.display(),
                var_path.display(),
                img.width,
                img.height
            );
        }
    }
    let meta = read_exr_metadata(&path).unwrap_or_default();
    let value = |key: &str| meta.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone());
    Ok(Converged {
        spp: value("lantern/spp"),
        seed: value("lantern/seed").and_then(|s| s.parse().ok()),
        image,
        var: var.pixels,
    })
}

/// The converged image's own noise: the median over its brighter pixels
/// (above 5 % of the 99th percentile of their channel mean) of the
/// relative standard error of a pixel, and of an 8×8 block mean; and the
/// relative standard error of its image mean per channel.
fn own_noise(c: &Converged) -> (f64, f64, Vec3) {
    let (w, h) = (c.image.width as usize, c.image.height as usize);
    let median_rel = |values: Vec<(f64, f64)>| {
        let mut bright: Vec<f64> = values.iter().map(|v| v.0).collect();
        bright.sort_by(f64::total_cmp);
        let p99 = bright
            .get((bright.len() * 99 / 100).min(bright.len().saturating_sub(1)))
            .copied()
            .unwrap_or(0.0);
        let mut rel: Vec<f64> = values
            .iter()
            .filter(|(m, _)| *m > 0.05 * p99 && *m > 0.0)
            .map(|(m, v)| v.sqrt() / m)
            .collect();
        rel.sort_by(f64::total_cmp);
        rel.get(rel.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let pixel = median_rel(
        c.image
            .pixels
            .iter()
            .zip(&c.var)
            .map(|(m, v)| (m.element_sum() as f64 / 3.0, v.element_sum() as f64 / 3.0))
            .collect(),
    );
    let mut blocks = Vec::new();
    for by in 0..h / BLOCK {
        for bx in 0..w / BLOCK {
            let (mut m, mut v) = (0.0f64, 0.0f64);
            for y in by * BLOCK..(by + 1) * BLOCK {
                for x in bx * BLOCK..(bx + 1) * BLOCK {
                    m += c.image.pixels[y * w + x].element_sum() as f64 / 3.0;
                    v += c.var[y * w + x].element_sum() as f64 / 3.0;
                }
            }
            let n = (BLOCK * BLOCK) as f64;
            blocks.push((m / n, v / (n * n)));
        }
    }
    let block = median_rel(blocks);
    let n = c.image.pixels.len().max(1) as f32;
    let mean = image_mean(&c.image.pixels).max(Vec3::splat(1e-30));
    let se = (image_mean(&c.var) / n).powf(0.5) / mean;
    (pixel, block, se)
}

/// Runs `lantern equal-time`.
pub fn run(args: &EqualTimeArgs) -> Result<()> {
    let mut times = args.times.clone();
    if times.is_empty() || times.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
        bail!("--times must be positive numbers of seconds, e.g. 1,2,4,8");
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot configure the thread pool")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut report = String::new();
    let mut csv = String::from(
        "scene,method,target_s,secs,spp,mean_err_r,mean_err_g,mean_err_b,block_rmse,pixel_rmse,seed\n",
    );
    let ctx = match args.backend {
        Backend::Cpu => None,
        Backend::Gpu => Some(gpu_context()?),
    };
    if let (Some(ctx), Some(first)) = (&ctx, args.scenes.first()) {
        warm_up(ctx, first, args.size)?;
    }
    for scene in &args.scenes {
        let (section, rows) = pool.install(|| scene_report(args, ctx.as_ref(), scene, &times))?;
        print!("{section}");
        report.push_str(&section);
        csv.push_str(&rows);
    }
    for (name, text) in [("report.md", &report), ("report.csv", &csv)] {
        let path = args.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

/// One scene's Markdown section and CSV rows.
fn scene_report(
    args: &EqualTimeArgs,
    ctx: Option<&GpuContext>,
    scene: &Path,
    times: &[f64],
) -> Result<(String, String)> {
    let prepared = Arc::new(load_square(scene, args.size)?);
    let (w, h) = (prepared.camera.width, prepared.camera.height);
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let converged = read_converged(&args.converged_dir, &stem, w, h)?;

    let mut internal = prepared.scene.render.clone();
    internal.method = Method::Internal;
    args.internal.apply(&mut internal.internal);
    internal.internal.validate(scene)?;
    let mut reference = internal.clone();
    reference.method = Method::Reference;
    // The seeds of each render: the internal lights `seed + 2k`, the
    // reference one more.
    // (At least one: `--seeds` refuses 0, and so does this.)
    let seeds: Vec<(u64, u64)> = (0..u64::from(args.seeds.max(1)))
        .map(|k| {
            let s = args.seed.wrapping_add(2 * k);
            (s, s.wrapping_add(1))
        })
        .collect();
    if let Some(s) = converged.seed {
        if seeds.iter().any(|&(i, r)| s == i || s == r) {
            bail!(
                "{stem}: the converged reference was rendered with seed {s}; choose another --seed"
            );
        }
    }

    let c = &converged.image.pixels;
    let v = &converged.var;
    // The internal lights first: their passes are long, and the reference
    // is then measured at the wall time each of their snapshots took.
    let balanced = !args.fixed_renewal;
    let truth = Truth {
        image: c,
        var: v,
        width: w as usize,
        height: h as usize,
    };
    let measure = |settings: &RenderSettings, times: &[f64], label: String| match ctx {
        None => snapshots(settings.method, times, |times| {
            render_to(&prepared, settings, times, &truth, &label, balanced)
        }),
        Some(ctx) => snapshots(settings.method, times, |times| {
            gpu_render_to(ctx, &prepared, settings, times, &truth, &label, balanced)
        }),
    };
    // Per seed, the reference's snapshots and the internal lights'.
    let mut renders = Vec::with_capacity(seeds.len());
    for &(internal_seed, reference_seed) in &seeds {
        internal.seed = internal_seed;
        reference.seed = reference_seed;
        let internal_snapshots = measure(
            &internal,
            times,
            format!("{stem} internal (seed {internal_seed})"),
        )?;
        let spent: Vec<f64> = internal_snapshots.iter().map(|s| s.secs).collect();
        let mut reference_snapshots = measure(
            &reference,
            &spent,
            format!("{stem} reference (seed {reference_seed})"),
        )?;
        for (r, &t) in reference_snapshots.iter_mut().zip(times) {
            r.target = t;
        }
        renders.push([reference_snapshots, internal_snapshots]);
    }
    // The table's rows: each method at each time, pooled over the seeds.
    let runs: Vec<(&str, Vec<Snapshot>)> = ["reference", "internal"]
        .into_iter()
        .enumerate()
        .map(|(m, name)| {
            let pooled = (0..times.len())
                .map(|k| pool(&renders.iter().map(|r| r[m][k]).collect::<Vec<_>>()))
                .collect();
            (name, pooled)
        })
        .collect();

    let (pixel_noise, block_noise, mean_se) = own_noise(&converged);
    let i = &internal.internal;
    let renderers = match ctx {
        None => format!("{} thread(s)", rayon::current_num_threads()),
        Some(ctx) => format!("GPU ({})", ctx.describe()),
    };
    let mut md = String::new();
    let over = match seeds.as_slice() {
        [(i, r)] => format!("seed {i} (the reference {r})"),
        _ => format!(
            "{} renders of each, seeds {} … {} (the reference's one more): the mean of their mean errors, the root mean square of their RMSEs",
            seeds.len(),
            seeds[0].0,
            seeds[seeds.len() - 1].0
        ),
    };
    let _ = writeln!(
        md,
        "\n### {stem} {w}×{h}, {renderers}: equal time against the converged reference\n"
    );
    let _ = writeln!(md, "{over}\n");
    let _ = writeln!(
        md,
        "converged reference {} ({} spp): its own noise (median relative standard error over the brighter pixels) {:.2} % per pixel, {:.2} % per 8×8 block, removed from the RMSEs; its image mean ±{:.3} / {:.3} / {:.3} % (R/G/B, not removed)\n",
        args.converged_dir.join(format!("{stem}.exr")).display(),
        converged.spp.as_deref().unwrap_or("?"),
        100.0 * pixel_noise,
        100.0 * block_noise,
        100.0 * mean_se.x,
        100.0 * mean_se.y,
        100.0 * mean_se.z,
    );
    let _ = writeln!(
        md,
        "internal lights: M = {}, K = {}, N = {}, s* = {}, SH order {}, clock {:?}, L1 {:?}, {} light sample(s), {}\n",
        i.knobs.lights,
        walk_split_text(i.expert.walks, i.expert.view_walks, prepared.volume.optics.g),
        i.knobs.terms,
        i.knobs.s_star.map_or("auto".to_owned(), |s| s.to_string()),
        i.expert.sh_order,
        i.expert.clock,
        i.expert.l1,
        i.expert.light_samples,
        renewal_text(i.expert.resample_every, !args.fixed_renewal)
    );
    let _ = writeln!(
        md,
        "| method | T s | spent s | spp | mean err R | mean err G | mean err B | 8×8 block RMSE | pixel RMSE | targets (mean ≤ 3 %, block ≤ 5 %, pixel < reference) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|");
    for (k, &target) in times.iter().enumerate() {
        for (name, snaps) in &runs {
            let s = snaps[k];
            let e = s.errors;
            let targets = if *name == "internal" {
                let r = runs[0].1[k].errors;
                let mark = |ok: bool| if ok { "yes" } else { "no" };
                format!(
                    "{} {} {}",
                    mark(e.mean.abs().max_element() <= 0.03),
                    mark(e.block <= 0.05),
                    mark(e.pixel < r.pixel)
                )
            } else {
                String::new()
            };
            let _ = writeln!(
                md,
                "| {name} | {target} | {:.2} | {} | {:+.2} % | {:+.2} % | {:+.2} % | {:.2} % | {:.2} % | {targets} |",
                s.secs,
                s.spp,
                100.0 * e.mean.x,
                100.0 * e.mean.y,
                100.0 * e.mean.z,
                100.0 * e.block,
                100.0 * e.pixel,
            );
        }
    }
    let mut rows = String::new();
    for (render, &(internal_seed, reference_seed)) in renders.iter().zip(&seeds) {
        for (k, &target) in times.iter().enumerate() {
            for (name, snaps, seed) in [
                ("reference", &render[0], reference_seed),
                ("internal", &render[1], internal_seed),
            ] {
                let (s, e) = (snaps[k], snaps[k].errors);
                let _ = writeln!(
                    rows,
                    "{stem},{name},{target},{:.4},{},{:.6},{:.6},{:.6},{:.6},{:.6},{seed}",
                    s.secs, s.spp, e.mean.x, e.mean.y, e.mean.z, e.block, e.pixel
                );
            }
        }
    }
    Ok((md, rows))
}

/// One method's snapshots at one time over several seeds, as the table
/// gives them: the mean of the seconds, the spp and the signed mean
/// errors, the root mean square of the block and pixel RMSEs (what one
/// render's RMSE is in the mean square). One snapshot is itself.
fn pool(snaps: &[Snapshot]) -> Snapshot {
    let n = snaps.len().max(1) as f64;
    let mean = |f: fn(&Snapshot) -> f64| snaps.iter().map(f).sum::<f64>() / n;
    Snapshot {
        target: snaps.first().map_or(0.0, |s| s.target),
        secs: mean(|s| s.secs),
        spp: mean(|s| f64::from(s.spp)).round() as u32,
        errors: Errors {
            mean: snaps.iter().map(|s| s.errors.mean).sum::<Vec3>() / n as f32,
            block: mean(|s| f64::from(s.errors.block).powi(2)).sqrt() as f32,
            pixel: mean(|s| f64::from(s.errors.pixel).powi(2)).sqrt() as f32,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A known pair: the converged image is 1 everywhere, the image 1.1 on
    /// the left half and 0.9 on the right (64 × 16 pixels, so 8 × 2 blocks,
    /// each on one side): mean error 0, block and pixel RMSE 0.1; with
    /// the left half +0.1 and the right +0.0 in the red channel only the
    /// red mean is off by +5 %.
    #[test]
    fn errors_of_a_known_pair() {
        let (w, h) = (64, 16);
        let converged = vec![Vec3::ONE; w * h];
        let none = vec![Vec3::ZERO; w * h];
        let halves: Vec<Vec3> = (0..w * h)
            .map(|i| Vec3::splat(if i % w < w / 2 { 1.1 } else { 0.9 }))
            .collect();
        let e = errors(&halves, &converged, &none, w, h);
        assert!(e.mean.abs().max_element() < 1e-5, "{e:?}");
        assert!(
            (e.block - 0.1).abs() < 1e-5 && (e.pixel - 0.1).abs() < 1e-5,
            "{e:?}"
        );
        let red: Vec<Vec3> = (0..w * h)
            .map(|i| Vec3::new(if i % w < w / 2 { 1.1 } else { 1.0 }, 1.0, 1.0))
            .collect();
        let e = errors(&red, &converged, &none, w, h);
        assert!(
            (e.mean.x - 0.05).abs() < 1e-5 && e.mean.y.abs() < 1e-6,
            "{e:?}"
        );
        // Over all three channels: √(0.01 / 6) per pixel and per block.
        let expected = (0.01f32 / 6.0).sqrt();
        assert!((e.pixel - expected).abs() < 1e-5 && (e.block - expected).abs() < 1e-5);
    }

    /// End to end on a 16² thin sphere with a converged reference made
    /// here: the table has both methods at both times, the spp grow with
    /// the time, the reference's errors fall, and the CSV has a row each.
    #[test]
    fn equal_time_reports_both_methods_at_each_time() {
        let dir = tempfile::tempdir().unwrap();
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let scene = root.join("assets/scenes/thin_sphere.ron");
        let prepared = Arc::new(load_square(&scene, 16).unwrap());
        let mut settings = prepared.scene.render.clone();
        // The converged image is the reference method's (the scene opens on
        // the internal lights).
        settings.method = Method::Reference;
        settings.seed = 99;
        settings.spp = 4096;
        let film = crate::cpu::render(prepared.clone(), &settings, |_| true);
        let meta = vec![("lantern/seed".to_owned(), "99".to_owned())];
        let conv = dir.path().join("thin_sphere.exr");
        crate::render::export::write_exr_with_metadata(&conv, 16, 16, &film.mean(), &meta).unwrap();
        crate::render::export::write_exr(&variance_path(&conv), 16, 16, &film.variance_of_mean())
            .unwrap();
        let args = EqualTimeArgs {
            scenes: vec![scene],
            converged_dir: dir.path().to_owned(),
            times: vec![0.4, 0.1],
            size: 16,
            threads: Some(1),
            backend: Backend::Cpu,
            seed: 5,
            seeds: 1,
            out: dir.path().join("out"),
            fixed_renewal: false,
            internal: InternalArgs {
                lights: Some(256),
                walks: Some(8),
                ..Default::default()
            },
        };
        run(&args).unwrap();
        let csv = std::fs::read_to_string(dir.path().join("out/report.csv")).unwrap();
        let rows: Vec<Vec<&str>> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect())
            .collect();
        assert_eq!(rows.len(), 4, "{csv}");
        let of = |method: &str| -> Vec<(f64, u32, f64)> {
            rows.iter()
                .filter(|r| r[1] == method)
                .map(|r| {
                    (
                        r[3].parse().unwrap(),
                        r[4].parse().unwrap(),
                        r[9].parse().unwrap(),
                    )
                })
                .collect()
        };
        for method in ["reference", "internal"] {
            let r = of(method);
            assert_eq!(r.len(), 2, "{csv}");
            assert!(r[0].0 >= 0.1 && r[1].0 >= 0.4, "{csv}");
            assert!(r[1].1 > r[0].1, "{csv}");
        }
        let r = of("reference");
        assert!(r[1].2 < r[0].2, "{csv}");
        // Both are measured at the same wall time: the reference at the
        // end of its first pass at or past the internal lights' snapshot
        // (one pass of the reference at 16² is well under 50 ms).
        for (r, i) in of("reference").iter().zip(&of("internal")) {
            assert!(r.0 >= i.0 && r.0 - i.0 < 0.05, "{csv}");
        }
        let md = std::fs::read_to_string(dir.path().join("out/report.md")).unwrap();
        assert!(
            md.contains("| internal | 0.4 |") && md.contains("8×8 block RMSE"),
            "{md}"
        );
        // The converged image's seed is refused for the renders, also
        // where it is one of several (97 and 99, the references 98 and 100).
        let same = EqualTimeArgs {
            seed: 99,
            ..args.clone()
        };
        assert!(run(&same).is_err());
        let among = EqualTimeArgs {
            seed: 97,
            seeds: 2,
            ..args.clone()
        };
        assert!(run(&among).is_err());
        // Two seeds: a CSV row per render, each with its seed, and the
        // table says what it pools.
        let two = EqualTimeArgs {
            seeds: 2,
            times: vec![0.1],
            ..args
        };
        run(&two).unwrap();
        let csv = std::fs::read_to_string(dir.path().join("out/report.csv")).unwrap();
        let seeds: Vec<(&str, &str)> = csv
            .lines()
            .skip(1)
            .map(|l| {
                let r: Vec<&str> = l.split(',').collect();
                (r[1], r[10])
            })
            .collect();
        assert_eq!(
            seeds,
            [
                ("reference", "6"),
                ("internal", "5"),
                ("reference", "8"),
                ("internal", "7")
            ],
            "{csv}"
        );
        let md = std::fs::read_to_string(dir.path().join("out/report.md")).unwrap();
        assert!(md.contains("2 renders of each, seeds 5 … 7"), "{md}");
    }

    /// Snapshots over seeds pool as the table gives them: the mean of the
    /// signed mean errors, the root mean square of the RMSEs.
    #[test]
    fn snapshots_over_seeds_pool_by_mean_and_root_mean_square() {
        let snap = |secs: f64, spp: u32, mean: f32, block: f32, pixel: f32| Snapshot {
            target: 2.0,
            secs,
            spp,
            errors: Errors {
                mean: Vec3::splat(mean),
                block,
                pixel,
            },
        };
        let p = pool(&[
            snap(2.0, 4, 0.02, 0.03, 0.1),
            snap(2.2, 5, -0.01, 0.04, 0.2),
        ]);
        assert_eq!((p.target, p.spp), (2.0, 5));
        assert!((p.secs - 2.1).abs() < 1e-12);
        assert!((p.errors.mean - Vec3::splat(0.005)).abs().max_element() < 1e-7);
        assert!((p.errors.block - 0.035355).abs() < 1e-5);
        assert!((p.errors.pixel - 0.158114).abs() < 1e-5);
        let one = snap(2.0, 4, 0.02, 0.03, 0.1);
        assert_eq!(pool(&[one]), one);
    }
}
