// The display pass's image entry point (see shaders/display/main.wgsl).

@group(0) @binding(3) var output: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(WORKGROUP_SIDE, WORKGROUP_SIDE)
fn display_image(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let i = id.y * params.width + id.x;
    var colour: vec3<f32>;
    if params.mode == MODE_HEAT {
        let d = abs(accum_a[i].mean.xyz - accum_b[i].mean.xyz);
        colour = heat((d.x + d.y + d.z) / 3.0 * params.heat_scale);
    } else {
        var m = accum_a[i].mean.xyz;
        if params.mode == MODE_SPLIT && id.x >= params.split_x {
            m = accum_b[i].mean.xyz;
        }
        colour = to_display(m, params.exposure, params.view);
    }
    textureStore(output, vec2<i32>(id.xy), vec4<f32>(colour, 1.0));
}
