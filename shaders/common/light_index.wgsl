// Spatial indices over the internal lights (src/doc/method.md §6). Mirrors the
// lookups of `LightGrid` in src/physics/internal/light_index.rs: bucket grids whose
// cell `c` lists `ids[starts[c]..starts[c+1]]`, cells x fastest.

// The (clamped) cell coordinates of `p` in a grid (`cell_coords`).
fn light_grid_coords(p: vec3<f32>, grid_min: vec3<f32>, cell: vec3<f32>, res: vec3<u32>) -> vec3<u32> {
    return vec3<u32>(clamp(floor((p - grid_min) / cell), vec3<f32>(0.0), vec3<f32>(res - vec3<u32>(1u))));
}

// `starts[c]` of the fine grid.
fn fine_start(c: u32) -> u32 {
    return internal_words[gather_params.fine_starts_offset + c];
}

// `ids[k]` of the fine grid.
fn fine_id(k: u32) -> u32 {
    return internal_words[gather_params.fine_ids_offset + k];
}

// `starts[c]` of the cluster grid.
fn cluster_start(c: u32) -> u32 {
    return internal_words[gather_params.cluster_starts_offset + c];
}

// `ids[k]` of the cluster grid.
fn cluster_id(k: u32) -> u32 {
    return internal_words[gather_params.cluster_ids_offset + k];
}

// The box of cluster cell `c`, as (min, max) columns (`cell_box`).
fn cluster_box(c: u32) -> mat2x3<f32> {
    let res = gather_params.cluster_res;
    let v = vec3<f32>(f32(c % res.x), f32((c / res.x) % res.y), f32(c / (res.x * res.y)));
    let lo = gather_params.cluster_min + v * gather_params.cluster_cell;
    return mat2x3<f32>(lo, lo + gather_params.cluster_cell);
}
