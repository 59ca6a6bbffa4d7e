// The internal-lights renderer's compute entry point: one invocation per
// pixel, one dispatch per pass; mirrors `Renderer::pass` in src/cpu/mod.rs
// for the internal-lights method (same stream per (seed, pixel, pass), same
// jitter, `gather`) with lights built on the CPU, and accumulates on the
// GPU. `single_mean` holds the exact k = 0 part.

// Running statistics per pixel, rows top to bottom (binding 5).
@group(0) @binding(5) var<storage, read_write> accum: array<Accum>;

// Workgroup side; keep in sync with `WORKGROUP_SIDE` in src/gpu/reference.rs.
const WORKGROUP_SIDE: u32 = 8u;

@compute @workgroup_size(WORKGROUP_SIDE, WORKGROUP_SIDE, 1)
fn gather_pass(@builtin(global_invocation_id) id: vec3<u32>) {
    let width = scene.camera.width;
    let height = scene.camera.height;
    if id.x >= width || id.y >= height {
        return;
    }
    let index = id.y * width + id.x;
    var rng = rng_for_sample(pass_params.seed_lo, pass_params.seed_hi, index, pass_params.pass_index);
    let jx = rng_next_f32(&rng);
    let jy = rng_next_f32(&rng);
    let dir = camera_ray_dir(f32(id.x) + jx, f32(id.y) + jy);
    let s = gather(scene.camera.eye, dir, gather_params.light_samples, &rng);
    let total = s.single + s.reconstructed + s.internal;
    accum[index] = accumulate(accum[index], total, s.single, pass_params.sample_count);
}
