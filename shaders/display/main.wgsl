// The previewer's display pass: reads the accumulation buffers where the
// renderers left them and writes the image egui shows (an rgba8unorm
// storage texture holding sRGB-encoded values, as egui's own textures do).
// Three modes, like src/ui/viewport.rs on the CPU: one estimator; the
// split view (first buffer left of the divider, second right); the error
// heatmap of |first - second| (mean over channels, times `heat_scale`,
// through the ramp of `viewport::heat`).
//
// A second entry point reduces the buffers to the numbers the UI prints:
// the image mean of the first buffer's luminance, the mean of its
// luminance's variance of the mean (the noise figure), the mean squared
// difference of the two buffers (RMSE²) and the second's channel mean.
// Keep `DisplayParams` in sync with `GpuDisplayParams` in
// src/gpu/display.rs.

// The modes `MODE_*` and the view transforms `VIEW_*` come from Rust (the
// generated prelude, src/gpu/shaders.rs: crate::gpu::display::MODE_*,
// VIEW_*).

struct DisplayParams {
    width: u32,
    height: u32,
    mode: u32,
    view: u32,
    exposure: f32,
    // First column shown from the second buffer (split view).
    split_x: u32,
    heat_scale: f32,
    // Samples per pixel of the first buffer (statistics).
    samples: u32,
}

@group(0) @binding(0) var<uniform> params: DisplayParams;
@group(0) @binding(1) var<storage, read> accum_a: array<Accum>;
@group(0) @binding(2) var<storage, read> accum_b: array<Accum>;

// The heatmap's ramp: black, purple, orange, pale yellow for t in [0, 1]
// (`viewport::heat`).
fn heat(t_in: f32) -> vec3<f32> {
    let t = clamp(t_in, 0.0, 1.0);
    var ts = array<f32, 4>(0.0, 0.35, 0.7, 1.0);
    var cs = array<vec3<f32>, 4>(
        vec3<f32>(0.0, 0.0, 0.02),
        vec3<f32>(0.45, 0.05, 0.55),
        vec3<f32>(0.95, 0.45, 0.1),
        vec3<f32>(1.0, 0.98, 0.6),
    );
    for (var k = 0u; k < 3u; k += 1u) {
        if t <= ts[k + 1u] {
            let f = (t - ts[k]) / (ts[k + 1u] - ts[k]);
            return cs[k] + (cs[k + 1u] - cs[k]) * f;
        }
    }
    return cs[3];
}
