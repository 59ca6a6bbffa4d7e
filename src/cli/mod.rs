//! The command line: headless rendering, export, benchmarks and the
//! measuring commands of the [validation](crate::doc::validation) page.
//!
//! `lantern render SCENE.ron --out FILE.exr|FILE.png [--backend cpu|gpu]`
//! renders a still; `lantern bench [--backend cpu|gpu] [--size WxH]`
//! measures passes and samples per second on the example scenes;
//! `lantern` alone, or `lantern view [SCENE]`, opens the previewer.
//!
//! Layout, without cycles: this module parses and dispatches; one module
//! per command ([`render`], [`bench`](mod@bench), [`agreement`] for `validate`,
//! [`converge`], [`variance`] for `noise`, [`equal_time`]) sits below it;
//! below those, [`args`] (the shared flags) and [`support`] (loading
//! scenes, output paths, timed renders) import no command. The image
//! statistics the commands report are [`crate::render::stats`].

pub mod agreement;
pub mod args;
pub mod bench;
pub mod converge;
pub mod equal_time;
pub mod render;
pub mod support;
pub mod variance;

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

pub use args::{ImageSize, InternalArgs, QualityArg, TimedArgs};
pub use render::{render_metadata, RenderArgs, StopRule};
pub use support::load_prepared;

/// Lantern: multiple scattering as internal lights, live.
#[derive(Debug, Parser)]
#[command(name = "lantern", version, about)]
pub struct Cli {
    /// What to do; without one, the previewer opens.
    #[command(subcommand)]
    pub command: Option<Command>,
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
    Render(render::RenderArgs),
    /// Measure the renderer's speed (samples per second) on scenes.
    Bench(bench::BenchArgs),
    /// Measure the internal-lights method against the reference: sweeps of
    /// s* (with (N+1)s* fixed), N and M; prints a table and writes images and
    /// plots.
    Validate(agreement::ValidateArgs),
    /// RMSE against time of both renderers against a converged reference,
    /// and their equal-error time ratio; writes a CSV and a PNG plot.
    Converge(converge::ConvergeArgs),
    /// Where the internal-lights image's noise comes from: per-pixel noise
    /// of each part of the gather with one light set and across light sets,
    /// the walks' share of a set's noise measured from that set alone, and
    /// the distribution of single walks.
    Noise(variance::NoiseArgs),
    /// The internal lights against the reference at equal wall time on
    /// scenes with a converged reference (mean error per channel, 8×8-block
    /// and per-pixel RMSE); writes report.md and report.csv.
    EqualTime(equal_time::EqualTimeArgs),
}

/// Runs the command line; the binary's `main` calls this.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        None => open_previewer(None),
        Some(Command::View { scene }) => open_previewer(scene),
        Some(Command::Render(args)) => {
            set_threads(args.threads)?;
            render::run(&args)
        }
        Some(Command::Bench(args)) => {
            set_threads(args.threads)?;
            bench::run(&args)
        }
        Some(Command::Validate(args)) => agreement::run(&args),
        Some(Command::Converge(args)) => converge::run(&args),
        Some(Command::Noise(args)) => variance::run(&args),
        Some(Command::EqualTime(args)) => equal_time::run(&args),
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

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::render::export::{read_exr, read_exr_metadata};
    use crate::scene::InternalSettings;

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
        assert_eq!((internal.knobs.lights, internal.expert.walks), (256, 4));
        assert!(meta_value(&meta, "lantern/s_star").parse::<f32>().unwrap() > 0.0);
        assert!(
            !meta.iter().any(|(k, _)| k == "lantern/first_set_walks"),
            "a first set walked whole: {meta:?}"
        );

        // A limit far shorter than a light set's walks: one round of them,
        // recorded in the header, and still an image.
        run(args(&[
            "--time", "0.0001", "--method", "internal", "--lights", "256", "--walks", "16",
        ]))
        .unwrap();
        let meta = read_exr_metadata(&out).unwrap();
        assert_eq!(meta_value(&meta, "lantern/first_set_walks"), "1");
        // One round of the 16 (the walks towards the eye as many).
        assert_eq!(meta_value(&meta, "lantern/first_set_share"), "0.0625");
        assert_eq!(meta_value(&meta, "lantern/spp"), "1");
        assert!(read_exr(&out).unwrap().pixels.iter().any(|v| v.x > 0.0));
    }
}
