// The reference renderer's compute entry point: one invocation per pixel,
// one dispatch per pass; mirrors `Renderer::pass` in src/cpu/mod.rs for
// the reference method (same random stream per (seed, pixel, pass), same
// jitter, same estimator) and accumulates on the GPU.

// Running statistics per pixel, rows top to bottom (binding 5).
@group(0) @binding(5) var<storage, read_write> accum: array<Accum>;

@compute @workgroup_size(WORKGROUP_SIDE, WORKGROUP_SIDE, 1)
fn reference_pass(@builtin(global_invocation_id) id: vec3<u32>) {
    if !pixel_on_image(id) {
        return;
    }
    let px = pixel_sample(id);
    var rng = px.rng;
    let s = radiance_split(scene.camera.eye, px.dir, 0xffffffffu, &rng);
    let cut = loops_cut_short(pass_params.sample_count);
    accum[px.index] = accumulate(accum[px.index], s.radiance, s.single, pass_params.sample_count, cut);
}
