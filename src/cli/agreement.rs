//! `lantern validate`, the agreement of the two estimators: how close the internal-lights method comes to the
//! reference, and how the error moves with `s*`, `N` and `M` ([method §7](crate::doc::method)).
//!
//! Renders the reference at a high sample count, then the internal-lights
//! method over three sweeps around the given base settings: `s*` shrinking
//! with `(N+1)·s*` held fixed, `N` growing, `M` growing. For each run it
//! reports the relative error of the image mean per channel, the RMSE
//! relative to the reference's mean, the time to place and walk, and the
//! time to gather; it writes every image (EXR) and one PNG plot of the
//! errors per sweep into the output folder.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use glam::Vec3;

use super::args::InternalArgs;
use super::support::{load_square, output_dir, render_timed};
use crate::render::export::write_exr;
use crate::render::internal_params;
use crate::render::plot::{Plot, Series};
use crate::render::stats::compare;
use crate::scene::{Method, RenderSettings};

/// Options of `lantern validate`.
#[derive(Clone, Debug, clap::Args)]
pub struct ValidateArgs {
    /// The scene file (.ron).
    pub scene: PathBuf,
    /// Samples per pixel of the reference.
    #[arg(long, default_value_t = 1024)]
    pub reference_spp: u32,
    /// Samples per pixel of each internal-lights image.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Image side in pixels (overrides the scene's camera; 0 keeps it).
    #[arg(long, default_value_t = 96)]
    pub size: u32,
    /// Output folder for the images, plots and table.
    #[arg(long, default_value = "target/validate")]
    pub out: PathBuf,
    /// Factors of s* for its sweep (with (N+1) s* fixed).
    #[arg(long, value_delimiter = ',', default_value = "1,0.5,0.25,0.125")]
    pub s_factors: Vec<f32>,
    /// Values of N for its sweep.
    #[arg(long, value_delimiter = ',', default_value = "0,1,2,4,8,16")]
    pub n_values: Vec<u32>,
    /// Values of M for its sweep.
    #[arg(long, value_delimiter = ',', default_value = "256,1024,4096,16384")]
    pub m_values: Vec<u32>,
    /// Base internal-lights parameters (default: the scene's).
    #[command(flatten)]
    pub internal: InternalArgs,
}

/// One row of the table.
#[derive(Clone, Debug)]
pub struct Row {
    /// Which sweep.
    pub sweep: &'static str,
    /// The swept value, as printed.
    pub value: f32,
    /// The resolved parameters: s*, N, M.
    pub s_star: f32,
    /// Series truncation.
    pub terms: u32,
    /// Lights.
    pub lights: u32,
    /// Relative error of the image mean per channel (signed).
    pub mean_error: Vec3,
    /// RMSE over pixels and channels, relative to the reference's mean.
    pub rmse: f32,
    /// Seconds to place and walk.
    pub resample_secs: f64,
    /// Seconds to gather all passes.
    pub gather_secs: f64,
}

/// Runs `lantern validate`.
pub fn run(args: &ValidateArgs) -> Result<()> {
    if args.spp == 0 || args.reference_spp == 0 {
        bail!("--spp and --reference-spp must be at least 1");
    }
    let prepared = Arc::new(load_square(&args.scene, args.size)?);
    let out_dir = output_dir(&args.out, &args.scene);
    let stem = out_dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    crate::atomic::check_writable(&out_dir.join("table.md"))?;
    let (w, h) = (prepared.camera.width, prepared.camera.height);

    let mut base = prepared.scene.render.clone();
    base.method = Method::Internal;
    args.internal.apply(&mut base.internal);
    base.internal.validate(&args.scene)?;
    let resolved = internal_params(&prepared, &base);
    base.internal.knobs.s_star = Some(resolved.s_star);

    let mut reference_settings = base.clone();
    reference_settings.method = Method::Reference;
    reference_settings.seed = base.seed.wrapping_add(1_000_003);
    eprintln!("{stem}: reference at {} spp…", args.reference_spp);
    let (reference, _, ref_secs) =
        render_timed(&prepared, &reference_settings, args.reference_spp)?;
    write_exr(&out_dir.join("reference.exr"), w, h, &reference)?;

    let s0 = resolved.s_star;
    let n0 = resolved.terms;
    let span = (n0 + 1) as f32 * s0;
    let mut runs: Vec<(&'static str, f32, RenderSettings)> = Vec::new();
    for &f in &args.s_factors {
        let mut s = base.clone();
        let s_star = s0 * f;
        s.internal.knobs.s_star = Some(s_star);
        s.internal.knobs.terms = ((span / s_star).round() as u32).saturating_sub(1);
        runs.push(("s*", f, s));
    }
    for &n in &args.n_values {
        let mut s = base.clone();
        s.internal.knobs.terms = n;
        runs.push(("N", n as f32, s));
    }
    for &m in &args.m_values {
        let mut s = base.clone();
        s.internal.knobs.lights = m;
        runs.push(("M", m as f32, s));
    }

    let mut rows = Vec::new();
    for (sweep, value, settings) in runs {
        settings.internal.validate(&args.scene)?;
        eprintln!("{stem}: {sweep} = {value}…");
        let (image, build, gather) = render_timed(&prepared, &settings, args.spp)?;
        let (mean_error, rmse) = compare(&image, &reference);
        let name = format!("internal_{}_{}.exr", sweep.replace('*', "star"), value);
        write_exr(&out_dir.join(name), w, h, &image)?;
        rows.push(Row {
            sweep,
            value,
            s_star: settings.internal.knobs.s_star.unwrap_or(s0),
            terms: settings.internal.knobs.terms,
            lights: settings.internal.knobs.lights,
            mean_error,
            rmse,
            resample_secs: build,
            gather_secs: gather,
        });
    }

    let table = format_table(&Table {
        stem: &stem,
        base: &base,
        s0,
        args,
        size: (w, h),
        ref_secs,
        rows: &rows,
    });
    print!("{table}");
    crate::atomic::write_bytes(&out_dir.join("table.md"), table.as_bytes())?;
    for sweep in ["s*", "N", "M"] {
        let sel: Vec<&Row> = rows.iter().filter(|r| r.sweep == sweep).collect();
        if sel.len() < 2 {
            continue;
        }
        let xs: Vec<f32> = sel.iter().map(|r| r.value).collect();
        let mut plot = Plot::new(
            &format!("{stem}: error against {sweep}"),
            sweep,
            "error %",
            sweep != "N" || xs.iter().all(|&x| x > 0.0),
        );
        plot.add(Series::new(
            "RMSE",
            [0.9, 0.9, 0.9],
            xs.iter()
                .zip(&sel)
                .map(|(&x, r)| (x, 100.0 * r.rmse))
                .collect(),
        ));
        for (c, colour) in [[0.95, 0.3, 0.3], [0.3, 0.85, 0.3], [0.35, 0.5, 1.0]]
            .into_iter()
            .enumerate()
        {
            plot.add(Series::new(
                ["|mean R|", "|mean G|", "|mean B|"][c],
                colour,
                xs.iter()
                    .zip(&sel)
                    .map(|(&x, r)| (x, 100.0 * r.mean_error[c].abs()))
                    .collect(),
            ));
        }
        let file = out_dir.join(format!("error_vs_{}.png", sweep.replace('*', "star")));
        plot.save(&file)?;
    }
    eprintln!("{stem}: wrote {}", out_dir.display());
    Ok(())
}

/// What the table of `lantern validate` shows: its header's settings and
/// the rows.
struct Table<'a> {
    /// The scene's name.
    stem: &'a str,
    /// The base settings the sweeps vary.
    base: &'a RenderSettings,
    /// The base settings' resolved `s*`.
    s0: f32,
    /// The command's options (sample counts).
    args: &'a ValidateArgs,
    /// Image width and height.
    size: (u32, u32),
    /// Seconds the reference took.
    ref_secs: f64,
    /// One row per run.
    rows: &'a [Row],
}

/// The table as Markdown.
fn format_table(table: &Table<'_>) -> String {
    let Table {
        stem,
        base,
        s0,
        args,
        size: (w, h),
        ref_secs,
        rows,
    } = *table;
    let i = &base.internal;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "\n### {stem} ({w}×{h}; reference {} spp in {:.1} s; internal {} spp; base s* = {:.4}, N = {}, M = {}, K = {}, SH order {}, u = {}, clock {:?})\n",
        args.reference_spp, ref_secs, args.spp, s0, i.knobs.terms, i.knobs.lights, i.expert.walks, i.expert.sh_order, i.expert.uniform_mix, i.expert.clock
    );
    let _ = writeln!(
        t,
        "| sweep | value | s* | N | M | mean err R | mean err G | mean err B | RMSE | place+walk s | gather s |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            t,
            "| {} | {} | {:.4} | {} | {} | {:+.2}% | {:+.2}% | {:+.2}% | {:.2}% | {:.3} | {:.2} |",
            r.sweep,
            r.value,
            r.s_star,
            r.terms,
            r.lights,
            100.0 * r.mean_error.x,
            100.0 * r.mean_error.y,
            100.0 * r.mean_error.z,
            100.0 * r.rmse,
            r.resample_secs,
            r.gather_secs
        );
    }
    t
}
