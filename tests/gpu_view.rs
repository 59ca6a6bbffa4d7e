//! The previewer on the GPU backend.
//!
//! - The display pass (`shaders/display/`, `gpu::display`): its tone map
//!   equals `render::tonemap` (both view transforms, several exposures,
//!   values around the sRGB threshold, the filmic shoulder, far above 1,
//!   negative and non-finite) within one 8-bit step; the split view and
//!   the heatmap pick the right buffer and ramp; the statistics pass equals
//!   the same sums on the CPU.
//! - The worker (`session::worker`) on the GPU backend renders images whose
//!   mean agrees with the CPU backend's (reference and internal lights,
//!   within 4 standard errors of their difference), a scene too large
//!   for the device falls back to the CPU with a notice, and passes that
//!   the driver cuts short (lavapipe's loop cap) are told once.
//!
//! Without an adapter the GPU cases print a notice and pass, unless
//! `LANTERN_REQUIRE_GPU=1`.

mod common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use lantern::gpu::display::{read_texture, DisplayMode, DisplayPass, DisplaySettings};
use lantern::gpu::mirrors::GpuAccum;
use lantern::gpu::GpuContext;
use lantern::render::film::image_mean;
use lantern::render::tonemap::{to_srgb8, ViewTransform};
use lantern::scene::Method;
use lantern::scene::Scene;
use lantern::session::{Backend, Job, Snapshot, Worker};
use lantern::ui::viewport::heat;
use wgpu::util::DeviceExt;

/// An accumulation buffer holding `means` (one sample's worth of them).
fn accum_buffer(ctx: &GpuContext, means: &[Vec3]) -> wgpu::Buffer {
    let pixels: Vec<GpuAccum> = means
        .iter()
        .map(|m| GpuAccum {
            mean: [m.x, m.y, m.z, 0.0],
            m2: [0.0; 4],
            single_mean: [0.0; 4],
        })
        .collect();
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("test accumulation"),
            contents: bytemuck::cast_slice(&pixels),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        })
}

/// Runs the display pass on `a` (and `b`) and reads the RGBA texture back.
fn display(
    ctx: &GpuContext,
    pass: &DisplayPass,
    a: &[Vec3],
    b: Option<&[Vec3]>,
    width: u32,
    settings: DisplaySettings,
) -> Vec<u8> {
    let height = a.len() as u32 / width;
    let buf_a = accum_buffer(ctx, a);
    let buf_b = b.map(|b| accum_buffer(ctx, b));
    let target = pass.create_target(width, height);
    let view = target.create_view(&Default::default());
    pass.draw(&buf_a, buf_b.as_ref(), width, height, &settings, &view)
        .unwrap_or_else(|e| panic!("{e:#}"));
    read_texture(ctx, &target).unwrap_or_else(|e| panic!("{e:#}"))
}

/// Linear values covering the curves: zero, the sRGB toe and threshold,
/// mid-tones, the filmic shoulder, far above 1, negative, NaN, infinity.
fn test_values() -> Vec<Vec3> {
    let mut scalars = vec![
        0.0, 1e-5, 0.001, 0.003, 0.0031308, 0.0032, 0.01, 0.05, 0.1, 0.18, 0.25, 0.4, 0.5, 0.7,
        0.9, 1.0, 1.2, 2.0, 4.0, 8.0, 10.4, 16.0, 100.0, 1e4, -0.5,
    ];
    for i in 0..64 {
        scalars.push(i as f32 / 40.0);
    }
    let mut v: Vec<Vec3> = scalars
        .windows(3)
        .map(|w| Vec3::new(w[0], w[1], w[2]))
        .collect();
    v.push(Vec3::new(0.18, 0.5, 3.0));
    v.push(Vec3::new(-1.0, 0.0, 1e-3));
    // 96 pixels: a 12 × 8 image.
    v.truncate(96);
    while v.len() < 96 {
        v.push(Vec3::splat(v.len() as f32 * 0.01));
    }
    v
}

#[test]
fn display_tonemap_equals_the_cpu_tonemap() {
    let Some(ctx) = common::gpu() else { return };
    let pass = DisplayPass::new(&ctx).unwrap_or_else(|e| panic!("{e:#}"));
    let values = test_values();
    let mut worst = 0i32;
    let mut checked = 0;
    for view in [ViewTransform::Filmic, ViewTransform::Clamp] {
        for exposure in [-3.0f32, -1.0, 0.0, 0.5, 2.0, 5.0] {
            let settings = DisplaySettings {
                exposure,
                view,
                mode: DisplayMode::Single,
            };
            let gpu = display(&ctx, &pass, &values, None, 12, settings);
            let cpu = to_srgb8(&values, exposure, view);
            for (i, v) in values.iter().enumerate() {
                for c in 0..3 {
                    let g = gpu[i * 4 + c] as i32;
                    let e = cpu[i * 3 + c] as i32;
                    worst = worst.max((g - e).abs());
                    checked += 1;
                    assert!(
                        (g - e).abs() <= 1,
                        "{view:?} at {exposure} stops, linear {v}: GPU {g}, CPU {e} (channel {c})"
                    );
                }
                assert_eq!(gpu[i * 4 + 3], 255, "alpha");
            }
        }
    }
    println!("display tone map: {checked} channel values, largest difference {worst}/255");
}

#[test]
fn display_split_and_heatmap_follow_the_viewport() {
    let Some(ctx) = common::gpu() else { return };
    let pass = DisplayPass::new(&ctx).unwrap_or_else(|e| panic!("{e:#}"));
    let (w, h) = (16u32, 4u32);
    let a: Vec<Vec3> = (0..w * h)
        .map(|i| Vec3::splat(0.1 + 0.01 * i as f32))
        .collect();
    let b: Vec<Vec3> = (0..w * h)
        .map(|i| Vec3::new(0.5, 0.2, 0.9 * (i % 7) as f32))
        .collect();
    let settings = |mode| DisplaySettings {
        exposure: 0.0,
        view: ViewTransform::Filmic,
        mode,
    };
    // Split at a quarter: columns 0–3 from a, 4–15 from b.
    let split = display(
        &ctx,
        &pass,
        &a,
        Some(&b),
        w,
        settings(DisplayMode::Split(0.25)),
    );
    let ca = to_srgb8(&a, 0.0, ViewTransform::Filmic);
    let cb = to_srgb8(&b, 0.0, ViewTransform::Filmic);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let i = y * w as usize + x;
            let expected = if x < 4 { &ca } else { &cb };
            for c in 0..3 {
                let d = split[i * 4 + c] as i32 - expected[i * 3 + c] as i32;
                assert!(
                    d.abs() <= 1,
                    "split view at ({x}, {y}) channel {c}: off by {d}"
                );
            }
        }
    }
    // Heatmap, as `viewport::heat` (which truncates to 8 bits: within 1).
    let scale = 1.7;
    let heatmap = display(
        &ctx,
        &pass,
        &a,
        Some(&b),
        w,
        settings(DisplayMode::Heat(scale)),
    );
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        let t = (*x - *y).abs().element_sum() / 3.0 * scale;
        let e = heat(t);
        for (c, e) in [e.r(), e.g(), e.b()].into_iter().enumerate() {
            let d = heatmap[i * 4 + c] as i32 - e as i32;
            assert!(
                (0..=1).contains(&d),
                "heatmap pixel {i} (t {t}) channel {c}: off by {d}"
            );
        }
    }
}

#[test]
fn statistics_pass_equals_the_cpu_sums() {
    let Some(ctx) = common::gpu() else { return };
    let pass = DisplayPass::new(&ctx).unwrap_or_else(|e| panic!("{e:#}"));
    let (w, h, samples) = (37u32, 29u32, 5u32);
    let n = (w * h) as usize;
    let pixel = |i: usize| {
        let t = i as f32 / n as f32;
        GpuAccum {
            // Some pixels with passes the driver cut short (`mean.w`).
            mean: [
                t,
                0.5 * t,
                1.0 - t,
                (i % 7 == 3) as u32 as f32 * (1 + i % 3) as f32,
            ],
            m2: [0.1 * t, 0.2, 0.3 * t * t, 0.0],
            single_mean: [0.0; 4],
        }
    };
    let a: Vec<GpuAccum> = (0..n).map(pixel).collect();
    let b: Vec<Vec3> = (0..n)
        .map(|i| Vec3::splat((i % 13) as f32 * 0.05))
        .collect();
    let buf_a = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("a"),
            contents: bytemuck::cast_slice(&a),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
    let buf_b = accum_buffer(&ctx, &b);
    let stats = pass
        .stats(&buf_a, Some(&buf_b), w, h, samples)
        .unwrap_or_else(|e| panic!("{e:#}"));
    let lum = Vec3::new(0.2126, 0.7152, 0.0722);
    let k = 1.0 / (samples as f64 * (samples as f64 - 1.0));
    let (mut l, mut v, mut sq, mut m) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (p, q) in a.iter().zip(&b) {
        l += p.mean().dot(lum) as f64;
        v += p.m2().dot(lum) as f64 * k;
        let d = p.mean() - *q;
        sq += d.length_squared() as f64 / 3.0;
        m += q.element_sum() as f64 / 3.0;
    }
    let nf = n as f64;
    let expected = [l / nf, v / nf, sq / nf, m / nf];
    let got = [
        stats.mean_luminance,
        stats.mean_variance,
        stats.mean_sq_diff,
        stats.second_mean,
    ];
    let cut: u64 = a.iter().map(|p| u64::from(p.cut_short_passes())).sum();
    println!(
        "statistics: GPU {got:?}, CPU {expected:?}; passes cut short: GPU {}, CPU {cut}",
        stats.cut_short_passes
    );
    assert!(cut > 0, "the test needs passes cut short");
    assert_eq!(stats.cut_short_passes, cut);
    for (g, e) in got.iter().zip(expected) {
        assert!(
            ((*g as f64) - e).abs() <= 1e-4 * e.abs().max(1e-3),
            "GPU {got:?} vs CPU {expected:?}"
        );
    }
}

/// A job on `scene` at `side`² with one estimator, `spp` samples per pixel
/// and `seed`.
fn job(scene: &str, side: u32, estimator: Method, spp: u32, seed: u64, backend: Backend) -> Job {
    let path = common::root().join(scene);
    let mut scene = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    scene.camera.width = side;
    scene.camera.height = side;
    scene.render.seed = seed;
    Job {
        scene,
        scene_dir: path.parent().expect("scene folder").to_owned(),
        estimators: vec![estimator],
        max_spp: spp,
        backend,
    }
}

/// Submits `job` and waits for its last snapshot (all passes done); also
/// returns the errors the worker reported meanwhile.
fn render_with(worker: &mut Worker, job: Job) -> (Arc<Snapshot>, Vec<String>) {
    let generation = worker.submit(job);
    let start = Instant::now();
    let mut errors = Vec::new();
    loop {
        errors.extend(worker.take_errors());
        if let Some(s) = worker.latest() {
            if s.generation == generation && s.done {
                return (s, errors);
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "the worker did not finish (errors: {errors:?})"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The worker on the GPU backend against the worker on the CPU backend:
/// image means within 4σ of their difference, σ from the GPU's per-pixel
/// variances (read back) scaled for the CPU's sample count (the two
/// backends run the same estimator).
fn worker_agrees(
    scene: &str,
    estimator: Method,
    side: u32,
    gpu_spp: u32,
    cpu_spp: u32,
    seeds: (u64, u64),
) {
    let Some(gpu) = common::gpu() else { return };
    let (ctx, _turn) = gpu.into_parts();
    let mut gpu_worker = Worker::start_with_gpu(Box::new(|_| {}), Some(ctx));
    let t = Instant::now();
    let (gpu_snap, errors) = render_with(
        &mut gpu_worker,
        job(scene, side, estimator, gpu_spp, seeds.0, Backend::Gpu),
    );
    let gpu_secs = t.elapsed().as_secs_f64();
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(gpu_snap.backend, Backend::Gpu);
    let g = &gpu_snap.streams[0];
    assert!(
        g.gpu.is_some() && g.mean.is_empty(),
        "the GPU image must stay on the GPU"
    );
    assert_eq!(g.spp, gpu_spp);
    assert!(
        g.rel_error.is_finite() && g.rel_error > 0.0 && g.rel_error < 1.0,
        "noise {}",
        g.rel_error
    );
    let resolved = g.resolved().unwrap_or_else(|e| panic!("{e}"));
    let variance = g.gpu_variance_of_mean().unwrap_or_else(|e| panic!("{e}"));

    let mut cpu_worker = Worker::start(Box::new(|_| {}));
    let t = Instant::now();
    let (cpu_snap, errors) = render_with(
        &mut cpu_worker,
        job(scene, side, estimator, cpu_spp, seeds.1, Backend::Gpu),
    );
    let cpu_secs = t.elapsed().as_secs_f64();
    assert!(errors.is_empty(), "{errors:?}");
    // A worker without a device renders GPU jobs on the CPU.
    assert_eq!(cpu_snap.backend, Backend::Cpu);
    let c = &cpu_snap.streams[0];
    assert!(c.gpu.is_none());

    let (mg, mc) = (image_mean(&resolved.mean), image_mean(&c.mean));
    let n = variance.len() as f32;
    let var_gpu = variance.iter().copied().sum::<Vec3>() / (n * n);
    let var_cpu = var_gpu * (gpu_spp as f32 / cpu_spp as f32);
    let sigma = (var_gpu + var_cpu).powf(0.5).max(Vec3::splat(1e-12));
    let z = (mg - mc) / sigma;
    // The noise figure of the GPU stream comes from the statistics pass;
    // the same figure from the read-back image must match it.
    let lum = Vec3::new(0.2126, 0.7152, 0.0722);
    let mean_l = resolved.mean.iter().map(|v| v.dot(lum)).sum::<f32>() / n;
    let mean_var = variance.iter().map(|v| v.dot(lum)).sum::<f32>() / n;
    let rel = mean_var.sqrt() / mean_l;
    println!(
        "{scene} {estimator:?} {side}²: GPU worker {gpu_spp} spp mean {:.5?} ({gpu_secs:.2} s), CPU worker {cpu_spp} spp mean {:.5?} ({cpu_secs:.2} s), Δ/σ {:.2?}; noise {:.4} (statistics pass) vs {rel:.4} (read back)",
        mg.to_array(),
        mc.to_array(),
        z.to_array(),
        g.rel_error
    );
    assert!(
        z.abs().max_element() < 4.0,
        "GPU and CPU workers disagree: Δ/σ {z}"
    );
    assert!(
        (g.rel_error - rel).abs() <= 1e-3 * rel.max(1e-3) + 1e-5,
        "noise figure {} vs {rel}",
        g.rel_error
    );
}

#[test]
fn gpu_worker_agrees_with_cpu_worker_reference() {
    worker_agrees(
        "assets/scenes/thin_sphere.ron",
        Method::Reference,
        24,
        256,
        256,
        (2, 1),
    );
}

#[test]
fn gpu_worker_agrees_with_cpu_worker_internal_lights() {
    // The same seed on both sides: it also selects the internal lights,
    // which must be the same set for the two to estimate the same thing.
    worker_agrees(
        "assets/scenes/thin_sphere.ron",
        Method::Internal,
        24,
        64,
        256,
        (1, 1),
    );
}

/// A device whose storage buffers are too small for a 32² accumulation
/// (48 kB): the worker must say so and render on the CPU.
#[test]
fn a_scene_too_large_for_the_device_falls_back_to_the_cpu_with_a_notice() {
    // Held while the test makes its own small device.
    let Some(_gpu) = common::gpu() else { return };
    let small = pollster::block_on(async {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions::default())
            .await
            .expect("adapter");
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                required_limits: wgpu::Limits {
                    max_storage_buffer_binding_size: 16 * 1024,
                    ..wgpu::Limits::downlevel_defaults()
                },
                ..Default::default()
            })
            .await
            .expect("device");
        GpuContext::from_device(&adapter, device, queue).expect("context")
    });
    println!(
        "max_storage_buffer_binding_size {}",
        small.limits.max_storage_buffer_binding_size
    );
    let mut worker = Worker::start_with_gpu(Box::new(|_| {}), Some(small));
    let (snapshot, errors) = render_with(
        &mut worker,
        job(
            "assets/scenes/thin_sphere.ron",
            32,
            Method::Reference,
            4,
            1,
            Backend::Gpu,
        ),
    );
    println!("notices: {errors:?}");
    assert_eq!(snapshot.backend, Backend::Cpu);
    assert!(snapshot.streams[0].gpu.is_none() && !snapshot.streams[0].mean.is_empty());
    assert!(
        errors
            .iter()
            .any(|e| e.contains("max_storage_buffer_binding_size") && e.contains("on the CPU")),
        "{errors:?}"
    );
    // The next job on the same scene goes to the CPU without a new notice.
    let (snapshot, errors) = render_with(
        &mut worker,
        job(
            "assets/scenes/thin_sphere.ron",
            32,
            Method::Reference,
            2,
            3,
            Backend::Gpu,
        ),
    );
    assert_eq!(snapshot.backend, Backend::Cpu);
    assert!(errors.is_empty(), "{errors:?}");
}

/// The previewer tells the user when the GPU driver cuts the gather's
/// passes short (the statistics pass counts them, `ImageStats`), once
/// while the settings that cause it stay: the suite's thick cumulus with
/// 32 points per ray and three window scatterings, which lavapipe's loop
/// cap cuts (as `passes_cut_short_by_the_driver_are_reported` in
/// `tests/gpu.rs` shows for `lantern render`); a hardware driver cuts
/// nothing and nothing is said.
#[test]
fn the_previewer_tells_once_when_the_driver_cuts_passes_short() {
    let Some(gpu) = common::gpu() else { return };
    let llvmpipe = gpu.describe().contains("llvmpipe");
    let (ctx, _turn) = gpu.into_parts();
    let mut worker = Worker::start_with_gpu(Box::new(|_| {}), Some(ctx));
    let heavy = |seed: u64| {
        let mut job = job(
            "assets/scenes/suite/thick_cumulus.ron",
            16,
            Method::Internal,
            2,
            seed,
            Backend::Gpu,
        );
        let internal = &mut job.scene.render.internal;
        internal.knobs.lights = 512;
        internal.expert.walks = 4;
        internal.expert.resample_every = 0;
        internal.expert.light_samples = 32;
        internal.expert.window_scatters = 3;
        job
    };
    let told = |errors: &[String]| {
        errors
            .iter()
            .filter(|e| e.contains("pixel passes short"))
            .count()
    };
    let (snapshot, first) = render_with(&mut worker, heavy(3));
    assert_eq!(snapshot.backend, Backend::Gpu);
    let (_, second) = render_with(&mut worker, heavy(4));
    println!("notices: {first:?} then {second:?}");
    if llvmpipe {
        assert_eq!(told(&first), 1, "{first:?}");
        assert!(first.iter().any(|e| e.contains("render on the CPU")));
    } else {
        assert_eq!(
            told(&first),
            0,
            "a hardware driver cut passes short: {first:?}"
        );
    }
    assert_eq!(
        told(&second),
        0,
        "told again for the same settings: {second:?}"
    );
}
