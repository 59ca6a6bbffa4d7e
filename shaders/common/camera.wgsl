// Ray generation. Mirrors `CameraFrame::ray_dir` in src/scene/camera.rs:
// (0, 0) is the top-left corner of the image, (width, height) the
// bottom-right, in pixel units.

// Unit direction of the camera ray through image position (`px`, `py`).
fn camera_ray_dir(px: f32, py: f32) -> vec3<f32> {
    let c = scene.camera;
    let sx = 2.0 * px / f32(c.width) - 1.0;
    let sy = 1.0 - 2.0 * py / f32(c.height);
    return normalize(c.forward + c.right_scaled * sx + c.up_scaled * sy);
}

// Workgroup side in pixels of the per-pixel entry points:
// `WORKGROUP_SIDE`, from Rust (the generated prelude, src/gpu/shaders.rs:
// crate::gpu::renderer::WORKGROUP_SIDE).

// The start of one pixel's sample in a pass (mirrors `pixel_ray` in
// src/cpu/mod.rs): its index (rows top to bottom), its random stream for
// (seed, pixel, pass), and the camera ray through the pass's point of it
// (`pixel_jitter`).
struct PixelSample {
    index: u32,
    dir: vec3<f32>,
    rng: Rng,
}

fn pixel_sample(id: vec3<u32>) -> PixelSample {
    let index = id.y * scene.camera.width + id.x;
    let j = pixel_jitter(pass_params.seed_lo, pass_params.seed_hi, index, pass_params.pass_index);
    let rng = rng_for_sample(pass_params.seed_lo, pass_params.seed_hi, index, pass_params.pass_index);
    let dir = camera_ray_dir(f32(id.x) + j.x, f32(id.y) + j.y);
    return PixelSample(index, dir, rng);
}

// Whether the invocation `id` lies on the image (the dispatch rounds up
// to whole workgroups).
fn pixel_on_image(id: vec3<u32>) -> bool {
    return id.x < scene.camera.width && id.y < scene.camera.height;
}
