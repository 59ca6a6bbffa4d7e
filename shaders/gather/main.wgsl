// The internal-lights renderer's compute entry point: one invocation per
// pixel, one dispatch per pass; mirrors `Renderer::pass` in src/cpu/mod.rs
// for the internal-lights method (same stream per (seed, pixel, pass), same
// jitter, `gather`) with lights built on the CPU, and accumulates on the
// GPU. `single_mean` holds the exact k = 0 part.

// Running statistics per pixel, rows top to bottom (binding 5).
@group(0) @binding(5) var<storage, read_write> accum: array<Accum>;

@compute @workgroup_size(WORKGROUP_SIDE, WORKGROUP_SIDE, 1)
fn gather_pass(@builtin(global_invocation_id) id: vec3<u32>) {
    if !pixel_on_image(id) {
        return;
    }
    let px = pixel_sample(id);
    var rng = px.rng;
    let s = gather(scene.camera.eye, px.dir, gather_params.light_samples, &rng);
    let total = s.single + s.reconstructed + s.internal;
    let cut = loops_cut_short(pass_params.sample_count);
    accum[px.index] = accumulate(accum[px.index], total, s.single, pass_params.sample_count, cut);
}
