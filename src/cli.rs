//! The command line: headless rendering, export and benchmarks.
//!
//! `lantern render SCENE.ron --out FILE.exr|FILE.png` renders a still;
//! `lantern bench` measures samples per second on the example scenes;
//! `lantern` alone, or `lantern view [SCENE]`, opens the previewer.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use crate::render::export::write_image;
use crate::render::tonemap::ViewTransform;
use crate::render::Prepared;
use crate::scene::{Method, Scene};

/// Lantern: multiple scattering as internal lights, live.
#[derive(Debug, Parser)]
#[command(name = "lantern", version, about)]
pub struct Cli {
    /// What to do; without one, the previewer opens.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Estimator names on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// The unbiased volumetric path tracer.
    Reference,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Reference => Method::Reference,
        }
    }
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
        method: Option<MethodArg>,
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
        /// Exposure in stops, for PNG output.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        exposure: f32,
        /// View transform, for PNG output.
        #[arg(long, value_enum, default_value_t = ViewTransform::Filmic)]
        view: ViewTransform,
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
        /// Image side override in pixels (default: the scene's camera).
        #[arg(long)]
        size: Option<u32>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
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
            exposure,
            view,
        }) => {
            set_threads(threads)?;
            render_command(
                &scene,
                method.map(Method::from),
                spp,
                &out,
                seed,
                exposure,
                view,
            )
        }
        Some(Command::Bench {
            scenes,
            spp,
            repeats,
            size,
            threads,
        }) => {
            set_threads(threads)?;
            bench_command(scenes, spp, repeats, size)
        }
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

fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
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

fn render_command(
    scene_path: &Path,
    method: Option<Method>,
    spp: Option<u32>,
    out: &Path,
    seed: Option<u64>,
    exposure: f32,
    view: ViewTransform,
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
    let t_load = Instant::now();
    let prepared = load_prepared(scene_path)?;
    let load_secs = t_load.elapsed().as_secs_f64();
    let settings = &prepared.scene.render;
    let method = method.unwrap_or(settings.method);
    let spp = spp.unwrap_or(settings.spp);
    let seed = seed.unwrap_or(settings.seed);
    let (w, h) = (prepared.camera.width, prepared.camera.height);

    let bar = ProgressBar::new(spp as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} spp ({eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    let film = crate::cpu::render(&prepared, method, seed, spp, |_| {
        bar.inc(1);
        true
    });
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    let samples = w as f64 * h as f64 * film.samples as f64;
    write_image(out, w, h, &film.mean(), exposure, view)?;
    let mean = film.image_mean();
    println!(
        "rendered {} ({w}×{h}, {} spp, {:?}) in {:.2} s (+{:.2} s loading): {:.3} M samples/s; image mean RGB {:.5} {:.5} {:.5}; wrote {}",
        scene_path.display(),
        film.samples,
        method,
        secs,
        load_secs,
        samples / secs / 1e6,
        mean.x,
        mean.y,
        mean.z,
        out.display()
    );
    Ok(())
}

fn bench_command(scenes: Vec<PathBuf>, spp: u32, repeats: u32, size: Option<u32>) -> Result<()> {
    if spp == 0 || repeats == 0 {
        bail!("--spp and --repeats must be at least 1");
    }
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
        "{:<28} {:>9} {:>6} {:>12} {:>14}",
        "scene", "size", "spp", "median s", "M samples/s"
    );
    for path in scenes {
        let mut scene = Scene::load(&path)?;
        if let Some(s) = size {
            scene.camera.width = s;
            scene.camera.height = s;
            scene.validate(&path)?;
        }
        let dir = path.parent().unwrap_or(Path::new("."));
        let prepared = Prepared::new(scene, dir)?;
        let (w, h) = (prepared.camera.width, prepared.camera.height);
        let mut times = Vec::new();
        for r in 0..repeats {
            let start = Instant::now();
            let film = crate::cpu::render(&prepared, Method::Reference, r as u64, spp, |_| true);
            times.push(start.elapsed().as_secs_f64());
            std::hint::black_box(film.samples);
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        let samples = w as f64 * h as f64 * spp as f64;
        println!(
            "{:<28} {:>9} {:>6} {:>12.3} {:>14.3}",
            path.file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default(),
            format!("{w}×{h}"),
            spp,
            median,
            samples / median / 1e6
        );
    }
    Ok(())
}
