//! What the commands share, importing none of them: loading and resizing
//! scenes, output folders and the converged images' variance files, a timed
//! CPU render, and the GPU device and renderer of `--backend gpu` (and its
//! warning for passes the driver cut short).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use glam::Vec3;

use crate::cpu::Renderer;
use crate::gpu::walks::build_internal_lights_gpu;
use crate::gpu::{GpuContext, GpuRenderer};
use crate::physics::internal::sources::{walk_split, BuildTimings, InternalParams};
use crate::render::{internal_params, Film, PreparedScene};
use crate::scene::{Method, RenderSettings, Scene};

/// Loads a scene and prepares it for rendering.
pub fn load_prepared(path: &Path) -> Result<PreparedScene> {
    let scene = Scene::load(path)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    Ok(PreparedScene::new(scene, dir)?)
}

/// The GPU device for `--backend gpu`, with a notice of what it is.
pub fn gpu_context() -> Result<GpuContext> {
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

/// What a GPU build of the internal lights tells its caller: its times,
/// and the share of a whole set's walks it walked (less than one where it
/// stopped at its deadline).
#[derive(Clone, Copy, Debug)]
pub struct GpuBuild {
    /// The build's times.
    pub timings: BuildTimings,
    /// [`InternalLights::walk_share`](crate::physics::internal::sources::InternalLights::walk_share).
    pub walk_share: f64,
    /// [`InternalLights::walked`](crate::physics::internal::sources::InternalLights::walked).
    pub walked: u32,
}

impl GpuBuild {
    /// What a whole set's build would take: the time measured over the
    /// share walked (what a balanced schedule weighs later sets by).
    pub fn whole_set_secs(&self) -> f64 {
        crate::render::renewal::whole_set_secs(self.timings.total(), self.walk_share)
    }
}

/// `K` as the reports print it: the spread walks asked for, and where
/// phase walks serve `L₁` in a medium of asymmetry `g` how they are split
/// ([`walk_split`]).
pub fn walk_split_text(walks: u32, view_walks: u32, g: f32) -> String {
    let (spread, view) = walk_split(walks, view_walks, g);
    if (spread, view) == (walks, view_walks) {
        walks.to_string()
    } else {
        format!("{walks} (phase walks serve L1: {spread} spread, {view} towards the eye)")
    }
}

/// `K` as the build messages print it: the walks per light, and where a
/// build stopped at its deadline the share of the set's walks it walked
/// and the fewest walks of any light.
pub fn walks_text(walked: u32, walks: u32, share: f64) -> String {
    if share < 1.0 {
        format!(
            "{walks} ({:.0} % of the set's walks before the time limit, at least {walked} per light)",
            100.0 * share
        )
    } else {
        walks.to_string()
    }
}

/// The header's record of a first light set that a time limit cut short
/// (`lantern/first_set_walks`: the fewest walks of any light;
/// `lantern/first_set_share`: the share of the set's walks walked), none
/// for a whole set.
pub fn first_set_metadata(walked: u32, share: f64) -> Vec<(String, String)> {
    if share < 1.0 {
        vec![
            ("lantern/first_set_walks".to_owned(), walked.to_string()),
            ("lantern/first_set_share".to_owned(), format!("{share:.4}")),
        ]
    } else {
        Vec::new()
    }
}

/// The GPU renderer for `settings.method`; for the internal-lights method
/// the lights are built on the GPU first (placement and walks, then the
/// spatial indices on the CPU), their walks ending near `walk_deadline`
/// if one is given ([`InternalParams::walk_deadline`](crate::physics::internal::sources::InternalParams::walk_deadline)),
/// and what the build took comes back too.
pub fn gpu_renderer(
    ctx: &GpuContext,
    prepared: &PreparedScene,
    settings: &RenderSettings,
    walk_deadline: Option<Instant>,
) -> Result<(GpuRenderer, Option<GpuBuild>)> {
    match settings.method {
        Method::Reference => Ok((GpuRenderer::reference(ctx, prepared, settings.seed)?, None)),
        Method::Internal => {
            let params = InternalParams {
                walk_deadline,
                ..internal_params(prepared, settings)
            };
            let lights = build_internal_lights_gpu(ctx, prepared, &params)?;
            println!(
                "internal lights (built on the GPU): M = {}, s* = {:.4}, N = {}, K = {}, K_v = {}, clock {:?}: placed in {:.3} s, walked in {:.3} s (GPU), indexed in {:.3} s (CPU)",
                lights.len(),
                lights.s_star,
                lights.params.terms,
                walks_text(lights.walked, lights.params.walks, lights.walk_share),
                lights.params.view_walks,
                lights.params.clock,
                lights.timings.placement,
                lights.timings.walks,
                lights.timings.index,
            );
            let renderer = GpuRenderer::internal(
                ctx,
                prepared,
                &lights,
                settings.internal.expert.light_samples,
                settings.seed,
            )?;
            let build = GpuBuild {
                timings: lights.timings,
                walk_share: lights.walk_share,
                walked: lights.walked,
            };
            Ok((renderer, Some(build)))
        }
    }
}

/// Renders `spp` passes with `settings`; returns the image and the times
/// to build and to gather.
pub fn render_timed(
    prepared: &Arc<PreparedScene>,
    settings: &RenderSettings,
    spp: u32,
) -> Result<(Vec<Vec3>, f64, f64)> {
    let never = AtomicBool::new(false);
    let start = Instant::now();
    let renderer =
        Renderer::new(prepared.clone(), settings, &never).context("render was cancelled")?;
    let build = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let cam = prepared.camera;
    let mut film = Film::new(cam.width, cam.height);
    for pass in 0..spp {
        let img = renderer
            .pass(pass, &never)
            .context("render was cancelled")?;
        film.add_pass(&img.total);
    }
    Ok((film.mean(), build, start.elapsed().as_secs_f64()))
}

/// Loads and prepares `scene` with its image resized to `size`² pixels
/// (0 keeps the scene's camera size).
pub fn load_square(scene: &Path, size: u32) -> Result<PreparedScene> {
    let prepared = load_prepared(scene)?;
    let (w, h) = if size == 0 {
        (prepared.camera.width, prepared.camera.height)
    } else {
        (size, size)
    };
    crate::render::limits::check_image_fits(w, h, "--size").map_err(anyhow::Error::msg)?;
    if size == 0 {
        return Ok(prepared);
    }
    let mut resized = prepared.scene.clone();
    resized.camera.width = size;
    resized.camera.height = size;
    resized.validate(scene)?;
    Ok(PreparedScene::with_density(
        resized,
        prepared.volume.density.clone(),
    ))
}

/// The path of a validation output for `scene` under `out`.
pub fn output_dir(out: &Path, scene: &Path) -> PathBuf {
    out.join(
        scene
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
    )
}

/// Where a converged image's per-pixel variance of the mean is read from:
/// `NAME_var.exr` beside `NAME.exr` (`converged.exr` → `converged_var.exr`,
/// as `converge` writes them; `tests/data/suite/NAME_var.exr`, as
/// `tests/suite/make_references.sh` writes them).
pub fn variance_path(converged: &Path) -> PathBuf {
    let stem = converged
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    converged.with_file_name(format!("{stem}_var.exr"))
}

/// How often a render renews its internal lights, in words (the reports'
/// settings line); `balanced`: on the schedule of time-limited renders
/// ([`crate::cpu::Passes`]), whose first sets last `resample_every` passes.
pub fn renewal_text(resample_every: u32, balanced: bool) -> String {
    match (resample_every, balanced) {
        (0, _) => "one light set".to_owned(),
        (p, false) => format!("a fresh light set every {p} passes"),
        (p, true) => format!(
            "light sets balanced against the passes from the measured noise and costs (the first {p} passes long)"
        ),
    }
}

/// Warns if the GPU driver cut pixel passes short
/// ([`GpuImage::cut_short_passes`](crate::gpu::GpuImage::cut_short_passes))
/// or the internal lights' walks
/// ([`GpuImage::cut_short_walks`](crate::gpu::GpuImage::cut_short_walks)):
/// those samples are too dark, and `--backend cpu` has no such limit.
pub fn warn_cut_short(image: &crate::gpu::GpuImage) {
    let all = u64::from(image.width) * u64::from(image.height) * u64::from(image.samples);
    if let Some(text) = crate::gpu::cut_short_passes_text(image.cut_short_passes(), all) {
        eprintln!(
            "warning: {text}; render with --backend cpu, or with fewer light samples or window \
             scatterings"
        );
    }
    if image.cut_short_walks > 0 {
        eprintln!(
            "warning: the GPU driver cut {} of the internal lights' walks short: it caps the \
             loop iterations of one shader invocation (Mesa's software driver does), so those \
             lights are darker than they should be; render with --backend cpu, or with a \
             smaller N (--terms)",
            image.cut_short_walks
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variance_beside_the_converged_image() {
        let p = Path::new("tests/data/suite/chromatic.exr");
        assert_eq!(
            variance_path(p),
            Path::new("tests/data/suite/chromatic_var.exr")
        );
        assert_eq!(
            variance_path(Path::new("out/converged.exr")),
            Path::new("out/converged_var.exr")
        );
    }
}
