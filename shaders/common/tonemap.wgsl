// Display transforms: from linear radiance to display-referred sRGB in
// [0, 1]. Mirrors src/render/tonemap.rs exactly (keep in sync): exposure
// in stops, then the view transform (clamp, or Narkowicz's ACES filmic fit
// clamped to 1), then the sRGB transfer function (IEC 61966-2-1).

// View transforms: the tags `VIEW_*`, from Rust (the generated prelude,
// src/gpu/shaders.rs: crate::gpu::display::VIEW_*).

// The sRGB opto-electronic transfer function (`srgb_encode`).
fn srgb_encode(x: f32) -> f32 {
    let c = clamp(x, 0.0, 1.0);
    if c <= 0.0031308 {
        return 12.92 * c;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

// The filmic curve (`filmic`), mapping [0, inf) onto [0, 1].
fn filmic(x: f32) -> f32 {
    let v = max(x, 0.0);
    return min((v * (2.51 * v + 0.03)) / (v * (2.43 * v + 0.59) + 0.14), 1.0);
}

// One linear pixel to display-referred sRGB (`to_display`).
fn to_display(linear: vec3<f32>, exposure_stops: f32, view: u32) -> vec3<f32> {
    var v = linear * exp2(exposure_stops);
    if view == VIEW_FILMIC {
        v = vec3<f32>(filmic(v.x), filmic(v.y), filmic(v.z));
    }
    return vec3<f32>(srgb_encode(v.x), srgb_encode(v.y), srgb_encode(v.z));
}
