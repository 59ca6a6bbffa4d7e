//! `lantern converge`: RMSE against time for both renderers, measured in
//! one run (issue 3's equal-error time ratio).
//!
//! A converged reference image is rendered first (or read from an EXR
//! written by an earlier run). Then the reference path tracer ([method
//! §2](crate::doc::method)) and the internal-lights renderer (§3–§6; its clock starts before
//! placement and walks, so re-sampling is paid for) render progressively
//! with other seeds; at checkpoints spaced by a factor `√2` in samples the
//! clock is paused and the image's RMSE against the converged one, relative
//! to its mean, is recorded. The converged image's own noise is removed
//! from each RMSE: `RMSE² − mean(Var[converged pixel])`, the part of the
//! squared error that its per-pixel variance of the mean explains (it would
//! otherwise put a floor under both curves).
//!
//! Output: a table (time, spp, RMSE per checkpoint), `curves.csv`,
//! `rmse_vs_time.png` (log-log), and for the target RMSE the first time
//! each renderer reached it and their ratio, or the lowest RMSE reached if
//! it never did.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use glam::Vec3;

use super::args::InternalArgs;
use super::support::{
    load_square, output_dir, render_timed, renewal_text, variance_path, walk_split_text,
};
use crate::cpu::Renderer;
use crate::render::export::{read_exr, write_exr};
use crate::render::film::image_mean;
use crate::render::plot::{Plot, Series};
use crate::render::stats::rmse_against;
use crate::render::{Film, PreparedScene};
use crate::scene::{Method, RenderSettings};

/// Options of `lantern converge`.
#[derive(Clone, Debug, clap::Args)]
pub struct ConvergeArgs {
    /// The scene file (.ron).
    pub scene: PathBuf,
    /// Image side in pixels (overrides the scene's camera; 0 keeps it).
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    /// Samples per pixel of the converged reference.
    #[arg(long, default_value_t = 2048)]
    pub reference_spp: u32,
    /// Read the converged reference from this EXR (written by an earlier
    /// run as `converged.exr`, or by `tests/suite/make_references.sh`),
    /// with its variance in `NAME_var.exr` beside `NAME.exr`, instead of
    /// rendering it.
    #[arg(long)]
    pub converged: Option<PathBuf>,
    /// Seconds each renderer may run.
    #[arg(long, default_value_t = 60.0)]
    pub budget: f64,
    /// The RMSE (relative to the image mean) whose time is compared.
    #[arg(long, default_value_t = 0.05)]
    pub target: f32,
    /// Output folder.
    #[arg(long, default_value = "target/converge")]
    pub out: PathBuf,
    /// After the curves, measure what the internal-lights image converges
    /// to: two independent renders of this many passes each (other seeds,
    /// so other light sets), whose difference gives their noise, and the
    /// error of their average less that noise the method's bias against
    /// the converged reference, also by brightness quarter of the
    /// converged image (0: not measured).
    #[arg(long, default_value_t = 0)]
    pub floor_passes: u32,
    /// Internal-lights parameters (default: the scene's).
    #[command(flatten)]
    pub internal: InternalArgs,
}

/// One checkpoint of a curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checkpoint {
    /// Seconds since the renderer started (re-sampling included).
    pub secs: f64,
    /// Samples per pixel so far.
    pub spp: u32,
    /// RMSE relative to the converged image's mean, its noise removed.
    pub rmse: f32,
}

/// What a pair of independent renders `a1`, `a2` (same settings, other
/// seeds) says about their expectation against `converged`: the bias,
/// `√(mean (ā − c)² − mean Var[c] − mean (a1 − a2)²/4)` (the squared error
/// of their average `ā` less the converged image's noise and less theirs,
/// which `(a1 − a2)²/4` estimates without bias), and the noise of `ā`,
/// `√(mean (a1 − a2)²/4)`; both relative to the converged image's mean.
/// The bias is clamped at 0 (an estimate of a square may fall below 0).
pub fn split_bias(
    a1: &[Vec3],
    a2: &[Vec3],
    converged: &[Vec3],
    converged_var: &[Vec3],
) -> (f32, f32) {
    let n = a1.len().max(1) as f64 * 3.0;
    let mut sums = ErrorSums::default();
    for (((x, y), c), v) in a1.iter().zip(a2).zip(converged).zip(converged_var) {
        sums.add(*x, *y, *c, *v);
    }
    let mean = (sums.converged / n).max(1e-30);
    let bias = (sums.excess() / n).max(0.0).sqrt() / mean;
    let noise = (sums.half / n).sqrt() / mean;
    (bias as f32, noise as f32)
}

/// Sums over pixel channels of what [`split_bias`] and
/// [`bias_by_brightness`] compare: the renders' average `ā = (a₁ + a₂)/2`,
/// the converged image `c`, the squared error `(ā − c)²`, the renders' own
/// noise `(a₁ − a₂)²/4` and the converged image's `Var[c]`.
#[derive(Clone, Copy, Debug, Default)]
struct ErrorSums {
    average: f64,
    converged: f64,
    squared_error: f64,
    half: f64,
    var: f64,
}

impl ErrorSums {
    /// Adds one pixel's three channels.
    fn add(&mut self, a1: Vec3, a2: Vec3, c: Vec3, var: Vec3) {
        for k in 0..3 {
            let (x, y, c) = (a1[k] as f64, a2[k] as f64, c[k] as f64);
            let avg = 0.5 * (x + y);
            self.average += avg;
            self.converged += c;
            self.squared_error += (avg - c).powi(2);
            self.half += 0.25 * (x - y).powi(2);
            self.var += var[k] as f64;
        }
    }

    /// The squared error less both noises: the squared bias's sum.
    fn excess(&self) -> f64 {
        self.squared_error - self.var - self.half
    }
}

/// One brightness band of [`bias_by_brightness`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrightnessBand {
    /// The converged image's mean over the band's pixels.
    pub converged_mean: f64,
    /// The relative error of the renders' mean over the band,
    /// `mean(ā) / mean(c) − 1`.
    pub mean_error: f64,
    /// The band's share of [`split_bias`]'s squared bias (its terms of the
    /// same sum; the shares add up to the unclamped square, relative to
    /// the whole converged image's mean squared).
    pub bias_share: f64,
}

/// [`split_bias`]'s squared bias split into `bands` bands of equal pixel
/// count by the converged image's brightness (the sum of its channels),
/// darkest first: where in the image the bias is, and whether it is an
/// offset of the band's mean or structure within it.
pub fn bias_by_brightness(
    a1: &[Vec3],
    a2: &[Vec3],
    converged: &[Vec3],
    converged_var: &[Vec3],
    bands: usize,
) -> Vec<BrightnessBand> {
    let pixels = a1
        .len()
        .min(a2.len())
        .min(converged.len())
        .min(converged_var.len());
    let bands = bands.clamp(1, pixels.max(1));
    let mut order: Vec<usize> = (0..pixels).collect();
    order.sort_by(|&i, &j| {
        converged[i]
            .element_sum()
            .total_cmp(&converged[j].element_sum())
    });
    let n = pixels.max(1) as f64 * 3.0;
    let image_mean = (converged[..pixels]
        .iter()
        .map(|c| c.element_sum() as f64)
        .sum::<f64>()
        / n)
        .max(1e-30);
    (0..bands)
        .map(|b| {
            let band = &order[b * pixels / bands..(b + 1) * pixels / bands];
            let mut sums = ErrorSums::default();
            for &i in band {
                sums.add(a1[i], a2[i], converged[i], converged_var[i]);
            }
            let count = (band.len().max(1) * 3) as f64;
            BrightnessBand {
                converged_mean: sums.converged / count,
                mean_error: if sums.converged > 0.0 {
                    sums.average / sums.converged - 1.0
                } else {
                    0.0
                },
                bias_share: sums.excess() / n / (image_mean * image_mean),
            }
        })
        .collect()
}

/// The first time a curve is at or below `target`, linearly interpolated
/// in log RMSE between the checkpoints around the crossing.
pub fn time_to(curve: &[Checkpoint], target: f32) -> Option<f64> {
    let i = curve.iter().position(|c| c.rmse <= target)?;
    if i == 0 {
        return Some(curve[0].secs);
    }
    let (a, b) = (curve[i - 1], curve[i]);
    let la = (a.rmse.max(1e-12) as f64).ln();
    let lb = (b.rmse.max(1e-12) as f64).ln();
    let lt = (target as f64).ln();
    let f = if la > lb { (la - lt) / (la - lb) } else { 1.0 };
    Some(a.secs + f.clamp(0.0, 1.0) * (b.secs - a.secs))
}

/// Whether `spp` passes reach the next checkpoint of the sequence
/// 1, 2, 3, 4, 6, 8, 11, 16, 23, 32, … (`√2^k` rounded), `next` being
/// the unrounded next one; moves `next` past `spp` when it does. (It
/// once skipped 3 and 6 by rounding down, which left a slow renderer's
/// third pass, where its curve crosses the target, unrecorded.)
fn checkpoint_due(next: &mut f64, spp: u32) -> bool {
    if (spp as f64) < next.round() {
        return false;
    }
    while next.round() <= spp as f64 {
        *next *= std::f64::consts::SQRT_2;
    }
    true
}

/// Renders progressively with `settings` for at most `budget` (and at most
/// `max_spp` passes), recording a checkpoint whenever the sample count
/// reaches the next of 1, 2, 3, 4, 6, 8, 11, 16, … (factor ≈ √2).
fn curve(
    prepared: &Arc<PreparedScene>,
    settings: &RenderSettings,
    budget: Duration,
    max_spp: u32,
    converged: &[Vec3],
    converged_var: &[Vec3],
    label: &str,
) -> Result<Vec<Checkpoint>> {
    let never = AtomicBool::new(false);
    let mut elapsed = Duration::ZERO;
    let start = Instant::now();
    let renderer =
        Renderer::new(prepared.clone(), settings, &never).context("render was cancelled")?;
    elapsed += start.elapsed();
    let cam = prepared.camera;
    let mut film = Film::new(cam.width, cam.height);
    let mut out = Vec::new();
    let mut next = 1.0f64;
    for pass in 0..max_spp {
        let start = Instant::now();
        let img = renderer
            .pass(pass, &never)
            .context("render was cancelled")?;
        film.add_pass(&img.total);
        elapsed += start.elapsed();
        let spp = pass + 1;
        let last = elapsed >= budget || spp == max_spp;
        if checkpoint_due(&mut next, spp) || last {
            let rmse = rmse_against(&film.mean(), converged, converged_var);
            out.push(Checkpoint {
                secs: elapsed.as_secs_f64(),
                spp,
                rmse,
            });
            eprintln!(
                "{label}: {spp} spp, {:.2} s, RMSE {:.2} %",
                elapsed.as_secs_f64(),
                100.0 * rmse
            );
        }
        if last {
            break;
        }
    }
    Ok(out)
}

/// Runs `lantern converge`.
pub fn run(args: &ConvergeArgs) -> Result<()> {
    if !(args.budget > 0.0 && args.budget.is_finite()) {
        bail!("--budget must be a positive number of seconds");
    }
    if !(args.target > 0.0 && args.target.is_finite()) {
        bail!("--target must be a positive relative RMSE (e.g. 0.05)");
    }
    let prepared = Arc::new(load_square(&args.scene, args.size)?);
    let (w, h) = (prepared.camera.width, prepared.camera.height);
    let out_dir = output_dir(&args.out, &args.scene);
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    crate::atomic::check_writable(&out_dir.join("curves.csv"))?;
    let stem = out_dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();

    let mut internal = prepared.scene.render.clone();
    internal.method = Method::Internal;
    args.internal.apply(&mut internal.internal);
    internal.internal.validate(&args.scene)?;
    let mut reference = internal.clone();
    reference.method = Method::Reference;

    let (converged, converged_var) = match &args.converged {
        Some(path) => {
            let mean = read_exr(path).context(
                "--converged names the converged image (NAME.exr, or converged.exr of an \
                 earlier run)",
            )?;
            let var_path = variance_path(path);
            let var = read_exr(&var_path).with_context(|| {
                format!(
                    "--converged {} also needs its per-pixel variance of the mean, {} in the \
                     same folder (`lantern converge` writes converged_var.exr beside \
                     converged.exr; `lantern render --variance` writes one too)",
                    path.display(),
                    var_path.display()
                )
            })?;
            let (cw, ch, vw, vh) = (mean.width, mean.height, var.width, var.height);
            if (cw, ch) != (w, h) || (vw, vh) != (w, h) {
                bail!(
                    "{} is {cw}×{ch} and {} is {vw}×{vh}, but the render is {w}×{h} (--size)",
                    path.display(),
                    var_path.display()
                );
            }
            (mean.pixels, var.pixels)
        }
        None => {
            eprintln!("{stem}: converged reference at {} spp…", args.reference_spp);
            let never = AtomicBool::new(false);
            let mut settings = reference.clone();
            settings.seed = reference.seed.wrapping_add(7_777_777);
            let renderer = Renderer::new(prepared.clone(), &settings, &never)
                .context("render was cancelled")?;
            let mut film = Film::new(w, h);
            for pass in 0..args.reference_spp {
                let img = renderer
                    .pass(pass, &never)
                    .context("render was cancelled")?;
                film.add_pass(&img.total);
            }
            let (mean, var) = (film.mean(), film.variance_of_mean());
            write_exr(&out_dir.join("converged.exr"), w, h, &mean)?;
            write_exr(&out_dir.join("converged_var.exr"), w, h, &var)?;
            (mean, var)
        }
    };
    // The converged image's own noise, relative to its mean.
    let n = 3.0 * converged.len().max(1) as f64;
    let mean: f64 = converged
        .iter()
        .map(|v| (v.x + v.y + v.z) as f64)
        .sum::<f64>()
        / n;
    let var: f64 = converged_var
        .iter()
        .map(|v| (v.x + v.y + v.z) as f64)
        .sum::<f64>()
        / n;
    let noise = var.sqrt() / mean.max(1e-30);

    let budget = Duration::from_secs_f64(args.budget);
    let max_spp = 1 << 20;
    let ref_curve = curve(
        &prepared,
        &reference,
        budget,
        max_spp,
        &converged,
        &converged_var,
        "reference",
    )?;
    let int_curve = curve(
        &prepared,
        &internal,
        budget,
        max_spp,
        &converged,
        &converged_var,
        "internal",
    )?;

    let mut csv = String::from("method,secs,spp,rmse\n");
    for (name, c) in [("reference", &ref_curve), ("internal", &int_curve)] {
        for p in c.iter() {
            let _ = writeln!(csv, "{name},{:.4},{},{:.6}", p.secs, p.spp, p.rmse);
        }
    }
    let csv_path = out_dir.join("curves.csv");
    crate::atomic::write_bytes(&csv_path, csv.as_bytes())?;
    let mut plot = Plot::new(
        &format!("{stem} {w}x{h}: RMSE against time"),
        "seconds",
        "RMSE %",
        true,
    )
    .log_y(true);
    for (name, colour, c) in [
        ("reference", [0.9, 0.9, 0.9], &ref_curve),
        ("internal lights", [1.0, 0.75, 0.3], &int_curve),
    ] {
        plot.add(Series::new(
            name,
            colour,
            c.iter().map(|p| (p.secs as f32, 100.0 * p.rmse)).collect(),
        ));
    }
    plot.add(Series::new(
        "target",
        [0.4, 0.7, 1.0],
        vec![
            (
                ref_curve.first().map_or(0.01, |p| p.secs as f32),
                100.0 * args.target,
            ),
            (args.budget as f32, 100.0 * args.target),
        ],
    ));
    plot.save(&out_dir.join("rmse_vs_time.png"))?;

    let i = &internal.internal;
    let mut report = String::new();
    let _ = writeln!(
        report,
        "\n### {stem} {w}×{h}: time to {:.1} % RMSE (converged reference {}, its own noise {:.2} % removed; budget {:.0} s each)\n",
        100.0 * args.target,
        match &args.converged {
            Some(path) => format!("read from {}", path.display()),
            None => format!("{} spp", args.reference_spp),
        },
        100.0 * noise,
        args.budget
    );
    let _ = writeln!(
        report,
        "internal lights: M = {}, K = {}, N = {}, s* = {}, SH order {}, clock {:?}, L1 {:?}, {} window scattering(s), {} view walks, {}\n",
        i.knobs.lights,
        walk_split_text(i.expert.walks, i.expert.view_walks, prepared.volume.optics.g),
        i.knobs.terms,
        i.knobs.s_star
            .map_or("scene default".to_owned(), |s| s.to_string()),
        i.expert.sh_order,
        i.expert.clock,
        i.expert.l1,
        i.expert.window_scatters,
        i.expert.view_walks,
        renewal_text(i.expert.resample_every, false)
    );
    let _ = writeln!(
        report,
        "| renderer | time to target | lowest RMSE (at s, spp) |"
    );
    let _ = writeln!(report, "|---|---|---|");
    let mut times = Vec::new();
    for (name, c) in [("reference", &ref_curve), ("internal lights", &int_curve)] {
        let t = time_to(c, args.target);
        times.push(t);
        let best = c
            .iter()
            .min_by(|a, b| a.rmse.total_cmp(&b.rmse))
            .copied()
            .unwrap_or(Checkpoint {
                secs: 0.0,
                spp: 0,
                rmse: f32::NAN,
            });
        let _ = writeln!(
            report,
            "| {name} | {} | {:.2} % ({:.2} s, {} spp) |",
            t.map_or("not reached".to_owned(), |t| format!("{t:.2} s")),
            100.0 * best.rmse,
            best.secs,
            best.spp
        );
    }
    let _ = match (times[0], times[1]) {
        (Some(r), Some(i)) => writeln!(
            report,
            "\nequal-error time ratio (reference / internal): {:.2}",
            r / i
        ),
        (Some(_), None) => writeln!(
            report,
            "\nthe internal-lights renderer did not reach the target within the budget"
        ),
        (None, _) => writeln!(
            report,
            "\nthe reference did not reach the target within the budget; raise --budget"
        ),
    };
    if args.floor_passes > 0 {
        let p = args.floor_passes;
        eprintln!("{stem}: the internal lights' floor, 2 × {p} passes…");
        let start = Instant::now();
        let render = |offset: u64| {
            let mut settings = internal.clone();
            settings.seed = internal.seed.wrapping_add(offset);
            render_timed(&prepared, &settings, p).map(|(image, _, _)| image)
        };
        let (a1, a2) = (render(101)?, render(202)?);
        let secs = start.elapsed().as_secs_f64();
        let (bias, noise) = split_bias(&a1, &a2, &converged, &converged_var);
        let m = |img: &[Vec3]| image_mean(img).element_sum() as f64;
        let _ = writeln!(
            report,
            "\nwhat the internal lights converge to (two renders of {p} passes, {secs:.1} s): \
             bias {:.2} % RMSE against the converged reference, its noise removed \
             (the average's own noise {:.2} %); image mean {:+.2} %",
            100.0 * bias,
            100.0 * noise,
            100.0 * ((m(&a1) + m(&a2)) / (2.0 * m(&converged)).max(1e-30) - 1.0)
        );
        let _ = writeln!(
            report,
            "\n| brightness quarter (converged image) | its mean | error of its mean | share of bias² |\n|---|---|---|---|"
        );
        let bands = bias_by_brightness(&a1, &a2, &converged, &converged_var, 4);
        let total: f64 = bands.iter().map(|b| b.bias_share).sum();
        for (q, b) in bands.iter().enumerate() {
            let _ = writeln!(
                report,
                "| {} | {:.5} | {:+.2} % | {:.0} % |",
                ["darkest", "second", "third", "brightest"][q],
                b.converged_mean,
                100.0 * b.mean_error,
                if total > 0.0 {
                    100.0 * b.bias_share / total
                } else {
                    0.0
                }
            );
        }
    }
    print!("{report}");
    crate::atomic::write_bytes(&out_dir.join("report.md"), report.as_bytes())?;
    eprintln!("{stem}: wrote {}", out_dir.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checkpoints at 1, 2, 3, 4, 6, 8, 11, 16, 23, 32, 45, 64 passes.
    #[test]
    fn checkpoints_follow_root_two_rounded() {
        let mut next = 1.0f64;
        let due: Vec<u32> = (1..=64)
            .filter(|&spp| checkpoint_due(&mut next, spp))
            .collect();
        assert_eq!(due, [1, 2, 3, 4, 6, 8, 11, 16, 23, 32, 45, 64]);
    }

    /// End to end at 16² with a short budget: both curves are written, and
    /// the reference's RMSE falls as its samples grow (by at least half
    /// from its first checkpoint to its last, which at hundreds of passes
    /// is a drop of several times). The budget is wall time on a machine
    /// the other tests share: at 0.5 s, with the library's heavier tests
    /// running beside it on two cores, the reference reached only 45
    /// passes (stalls of 125 ms between passes); 2 s leaves room.
    #[test]
    fn curves_are_written_and_the_reference_converges() {
        let dir = tempfile::tempdir().unwrap();
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let args = ConvergeArgs {
            scene: root.join("assets/scenes/thin_sphere.ron"),
            size: 16,
            reference_spp: 512,
            converged: None,
            budget: 2.0,
            target: 0.05,
            out: dir.path().to_owned(),
            floor_passes: 8,
            internal: InternalArgs {
                lights: Some(256),
                walks: Some(8),
                ..Default::default()
            },
        };
        run(&args).unwrap();
        let out = dir.path().join("thin_sphere");
        let csv = std::fs::read_to_string(out.join("curves.csv")).unwrap();
        let rows = |name: &str| -> Vec<(u32, f32)> {
            csv.lines()
                .filter(|l| l.starts_with(&format!("{name},")))
                .map(|l| {
                    let f: Vec<&str> = l.split(',').collect();
                    (f[2].parse().unwrap(), f[3].parse().unwrap())
                })
                .collect()
        };
        let reference = rows("reference");
        let internal = rows("internal");
        assert!(reference.len() >= 5 && !internal.is_empty(), "{csv}");
        let (first, last) = (reference[0], reference[reference.len() - 1]);
        assert!(last.0 > 64, "{csv}");
        assert!(last.1 < 0.5 * first.1, "{csv}");
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert!(
            report.contains("what the internal lights converge to"),
            "{report}"
        );
        for f in [
            "report.md",
            "rmse_vs_time.png",
            "converged.exr",
            "converged_var.exr",
        ] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
    }

    /// Two renders with a known bias (+0.1 on a converged image of 1) and
    /// Gaussian noise (σ 0.2 each, so 0.2/√2 in their average): the split
    /// recovers both; with no bias it finds (almost) none.
    #[test]
    fn split_bias_separates_bias_from_noise() {
        let n = 40_000;
        let mut rng = crate::physics::rng::Rng::for_sample(5, 0, 0);
        let mut gauss = || {
            let (u, v) = (rng.next_f32().max(1e-12), rng.next_f32());
            (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
        };
        let converged = vec![Vec3::ONE; n];
        let var = vec![Vec3::splat(1e-4); n];
        let mut noisy = |bias: f32| -> Vec<Vec3> {
            (0..n)
                .map(|_| Vec3::new(gauss(), gauss(), gauss()) * 0.2 + Vec3::splat(1.0 + bias))
                .collect()
        };
        let (a1, a2) = (noisy(0.1), noisy(0.1));
        let (bias, noise) = split_bias(&a1, &a2, &converged, &var);
        assert!((bias - 0.1).abs() < 0.005, "bias {bias}");
        assert!((noise - 0.2 / 2f32.sqrt()).abs() < 0.003, "noise {noise}");
        let (b1, b2) = (noisy(0.0), noisy(0.0));
        let (bias, _) = split_bias(&b1, &b2, &converged, &var);
        assert!(bias < 0.02, "bias {bias}");
    }

    /// A bias on the brighter half only: the split puts all of it there,
    /// with that half's mean error, and its shares add up to the square of
    /// [`split_bias`]'s bias (no noise, so nothing is clamped).
    #[test]
    fn bias_by_brightness_finds_the_biased_band() {
        let n = 1000;
        let converged: Vec<Vec3> = (0..n)
            .map(|i| Vec3::splat(if i % 2 == 0 { 0.1 } else { 1.0 }))
            .collect();
        let var = vec![Vec3::ZERO; n];
        let render: Vec<Vec3> = converged
            .iter()
            .map(|c| if c.x > 0.5 { *c * 1.04 } else { *c })
            .collect();
        let bands = bias_by_brightness(&render, &render, &converged, &var, 2);
        assert_eq!(bands.len(), 2);
        assert!((bands[0].converged_mean - 0.1).abs() < 1e-6, "{bands:?}");
        assert!(bands[0].mean_error.abs() < 1e-6 && bands[0].bias_share.abs() < 1e-9);
        assert!((bands[1].converged_mean - 1.0).abs() < 1e-6, "{bands:?}");
        assert!((bands[1].mean_error - 0.04).abs() < 1e-5, "{bands:?}");
        let (bias, _) = split_bias(&render, &render, &converged, &var);
        let total: f64 = bands.iter().map(|b| b.bias_share).sum();
        assert!(
            (total - (bias as f64).powi(2)).abs() < 1e-4 * total,
            "shares {total}, bias² {}",
            (bias as f64).powi(2)
        );
    }

    #[test]
    fn time_to_interpolates_in_log_rmse() {
        let c = [
            Checkpoint {
                secs: 1.0,
                spp: 1,
                rmse: 0.2,
            },
            Checkpoint {
                secs: 2.0,
                spp: 2,
                rmse: 0.05,
            },
        ];
        // ln 0.1 is halfway between ln 0.2 and ln 0.05.
        assert!((time_to(&c, 0.1).unwrap() - 1.5).abs() < 1e-9);
        assert_eq!(time_to(&c, 0.3), Some(1.0));
        assert_eq!(time_to(&c, 0.01), None);
    }
}
