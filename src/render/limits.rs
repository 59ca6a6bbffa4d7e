//! Bounds checked before work starts, and warnings for settings that make
//! the picture meaningless.
//!
//! - [`check_image_memory`]: the memory a render of `W×H` needs, against
//!   the memory available (Linux: `MemAvailable` in `/proc/meminfo`).
//! - [`check_threads`]: a thread count against the machine's cores.
//! - [`warnings`]: a medium clamped as opaque, a window `s*` far shorter
//!   than a voxel or far longer than the medium, a kernel wider than the
//!   medium, many external lights, and work estimates for large `spp`,
//!   `M` and `K`.
//!
//! Every message names the flag or field and gives the estimate.

use crate::physics::internal::clock::Clock;
use crate::render::prepared::{default_s_star, feature_length, internal_params};
use crate::render::PreparedScene;
use crate::scene::{Method, RenderSettings};

/// Bytes of memory a CPU render needs per pixel: two films of `f64` sums
/// and squared sums (96), one pass's images (36), the mean (12) and the
/// encoder's copy (up to 24), rounded up.
pub const BYTES_PER_PIXEL: u64 = 176;

/// At most this many worker threads per core are accepted.
pub const MAX_THREADS_PER_CORE: usize = 4;

/// More external lights than this draw a warning: each scattering event
/// traces a shadow ray to every light.
pub const MANY_LIGHTS: usize = 16;

/// Gated walks per light set (`M·K`) above which a warning estimates the
/// build time.
pub const MANY_WALKS: u64 = 1 << 26;

/// Walks per second assumed for that estimate: about what two cores do on
/// the example scenes at `N = 32` ([validation](crate::doc::validation) §4,
/// "Re-sampling speed": `M = 4096`,
/// `K = 64` in 0.1–0.25 s).
pub const WALKS_PER_SECOND: f64 = 1.0e6;

/// Passes above which a warning says that the time per pass is printed
/// after the first (and how long that makes the render).
pub const MANY_PASSES: u32 = 1 << 20;

/// How much shorter than a voxel (or longer than the medium's diagonal) the
/// window may be before a warning.
pub const WINDOW_RATIO: f32 = 100.0;

/// The memory available to this process, in bytes, where the platform says
/// (Linux: `MemAvailable`); `None` elsewhere, and then no check is made.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|rest| {
            rest.trim()
                .trim_end_matches("kB")
                .trim()
                .parse::<u64>()
                .ok()
        })
        .map(|kib| kib.saturating_mul(1024))
}

/// Bytes as GiB with two decimals.
fn gib(bytes: u64) -> String {
    format!("{:.2} GiB", bytes as f64 / (1u64 << 30) as f64)
}

/// Checks that a `width×height` render fits in the available memory
/// (`available`, e.g. [`available_memory`]; `None`: no check). `what`
/// names the setting in the message.
pub fn check_image_memory(
    width: u32,
    height: u32,
    available: Option<u64>,
    what: &str,
) -> Result<(), String> {
    let need = u64::from(width) * u64::from(height) * BYTES_PER_PIXEL;
    match available {
        Some(have) if need > have => Err(format!(
            "{what}: a {width}×{height} render needs about {} ({BYTES_PER_PIXEL} bytes per \
             pixel), but only {} of memory is available; render a smaller image",
            gib(need),
            gib(have)
        )),
        _ => Ok(()),
    }
}

/// [`check_image_memory`] against this machine's [`available_memory`]:
/// what the commands check before they render.
pub fn check_image_fits(width: u32, height: u32, what: &str) -> Result<(), String> {
    check_image_memory(width, height, available_memory(), what)
}

/// Checks a `--threads` value against `cores`: at least 1 and at most
/// [`MAX_THREADS_PER_CORE`] per core. More threads than cores is allowed
/// with a warning (returned), since they only add overhead.
pub fn check_threads(threads: usize, cores: usize) -> Result<Option<String>, String> {
    let cores = cores.max(1);
    let most = cores * MAX_THREADS_PER_CORE;
    if threads == 0 {
        return Err("--threads must be at least 1".into());
    }
    if threads > most {
        return Err(format!(
            "--threads {threads}: this machine has {cores} cores, and at most {most} threads \
             ({MAX_THREADS_PER_CORE} per core) are accepted; more only slow the render down"
        ));
    }
    Ok((threads > cores).then(|| {
        format!(
            "--threads {threads} is more than the {cores} cores: the extra threads only add \
             overhead"
        )
    }))
}

/// The number of cores, 1 if unknown.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Seconds as a short human duration.
pub fn duration(secs: f64) -> String {
    if secs < 120.0 {
        format!("{secs:.0} s")
    } else if secs < 2.0 * 3600.0 {
        format!("{:.0} minutes", secs / 60.0)
    } else if secs < 2.0 * 86400.0 {
        format!("{:.1} hours", secs / 3600.0)
    } else {
        format!("{:.1} days", secs / 86400.0)
    }
}

/// Warnings for `settings` on `prepared`, each a sentence naming the field
/// or flag: nothing is refused here, but each says why the picture may be
/// meaningless or the work very long.
pub fn warnings(prepared: &PreparedScene, settings: &RenderSettings) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(dense) = &prepared.dense {
        out.push(format!("medium: {dense}"));
    }
    let n_lights = prepared.lights.suns.len() + prepared.lights.points.len();
    if n_lights > MANY_LIGHTS {
        out.push(format!(
            "lights: {n_lights} external lights; every scattering event traces a shadow ray to \
             each, so the render takes about {n_lights} times as long as with one"
        ));
    }
    if settings.spp > MANY_PASSES {
        out.push(format!(
            "spp: {} passes of {}×{} pixels ({:.2e} camera samples); the estimated time is \
             printed after the first pass",
            settings.spp,
            prepared.camera.width,
            prepared.camera.height,
            settings.spp as f64 * prepared.camera.width as f64 * prepared.camera.height as f64
        ));
    }
    if settings.method == Method::Internal {
        internal_warnings(prepared, settings, &mut out);
    }
    out
}

fn internal_warnings(prepared: &PreparedScene, settings: &RenderSettings, out: &mut Vec<String>) {
    let s = &settings.internal;
    let walks = u64::from(s.knobs.lights) * u64::from(s.expert.walks);
    if walks > MANY_WALKS {
        out.push(format!(
            "render.internal: M × K = {} × {} = {walks:.3e} gated walks per light set (each up \
             to N + 1 = {} windows): about {} to build at {WALKS_PER_SECOND:.0e} walks/s",
            s.knobs.lights,
            s.expert.walks,
            s.knobs.terms + 1,
            duration(walks as f64 / WALKS_PER_SECOND)
        ));
    }
    let vol = &prepared.volume;
    let (lo, hi) = vol.bounds;
    let diagonal = (hi - lo).length();
    let voxel = feature_length(&vol.density);
    let params = internal_params(prepared, settings);
    let s_star = params.s_star;
    // The window as a length: for the optical-depth clock, at the medium's
    // mean extinction (the default s* is the diagonal's optical depth).
    let (length, unit) = match params.clock {
        Clock::Geometric => (s_star, "world units"),
        Clock::OpticalDepth => {
            let diagonal_depth = default_s_star(vol, Clock::OpticalDepth);
            (s_star / diagonal_depth * diagonal, "mean free paths")
        }
    };
    if length < voxel / WINDOW_RATIO {
        out.push(format!(
            "render.internal.knobs.s_star: the window s* = {s_star:e} {unit} spans about {length:.3e} \
             world units, far shorter than a voxel ({voxel:.3e}): the series then needs \
             N ≈ {:.1e} terms to reach across the medium and the image is nearly black",
            (diagonal / length).min(1e30)
        ));
    } else if length > WINDOW_RATIO * diagonal {
        out.push(format!(
            "render.internal.knobs.s_star: the window s* = {s_star:e} {unit} spans about {length:.3e} \
             world units, far longer than the medium's diagonal ({diagonal:.3e}): no light \
             reaches the next window, so the internal lights carry nothing"
        ));
    }
    if let Some(h) = s.expert.kernel_radius {
        if h > diagonal {
            out.push(format!(
                "render.internal.expert.kernel_radius: h = {h:e} is wider than the medium's diagonal \
                 ({diagonal:.3e}): every light is spread over the whole medium and the image \
                 loses its detail (and nearly all its multiple scatter for h ≫ the medium)"
            ));
        } else if h < voxel / WINDOW_RATIO {
            out.push(format!(
                "render.internal.expert.kernel_radius: h = {h:e} is far smaller than a voxel \
                 ({voxel:.3e}): almost no light falls within its kernel and the image is noisy \
                 or black"
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_memory_is_checked_against_what_is_available() {
        // 16384² needs 44 GiB; a machine with 24 GiB refuses it.
        let e =
            check_image_memory(16384, 16384, Some(24 << 30), "camera.width/height").unwrap_err();
        assert!(
            e.contains("16384×16384") && e.contains("44.00 GiB") && e.contains("24.00 GiB"),
            "{e}"
        );
        assert!(check_image_memory(1920, 1080, Some(24 << 30), "x").is_ok());
        assert!(check_image_memory(16384, 16384, None, "x").is_ok());
    }

    #[test]
    fn thread_counts_are_bounded_by_the_cores() {
        let e = check_threads(10_000, 2).unwrap_err();
        assert!(
            e.contains("--threads 10000") && e.contains("2 cores"),
            "{e}"
        );
        assert!(check_threads(0, 2).is_err());
        assert_eq!(check_threads(2, 2), Ok(None));
        assert!(check_threads(8, 2).unwrap().is_some());
        assert!(check_threads(9, 2).is_err());
    }

    #[test]
    fn durations_read_naturally() {
        assert_eq!(duration(30.0), "30 s");
        assert_eq!(duration(600.0), "10 minutes");
        assert_eq!(duration(36_000.0), "10.0 hours");
        assert_eq!(duration(864_000.0), "10.0 days");
    }
}
