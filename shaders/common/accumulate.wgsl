// Progressive accumulation on the GPU: one sample per pixel per pass,
// added to a running mean and sum of squared deviations (Welford's update,
// which stays accurate in f32 over many passes, unlike raw sums of
// squares). Plays the role of src/render/film.rs (`Film::add_pass`): a
// non-finite channel counts as a zero sample.
// Keep `Accum` in sync with `GpuAccum` in src/gpu/mirrors.rs.

// One pixel's running statistics: `mean` and `m2` of the full estimate,
// `single_mean` of its single-scattering part (w components unused).
struct Accum {
    mean: vec4<f32>,
    m2: vec4<f32>,
    single_mean: vec4<f32>,
}

// `v` with non-finite channels replaced by zero (bit test: comparisons
// with NaN may be folded away by shader compilers).
fn finite_or_zero(v: vec3<f32>) -> vec3<f32> {
    let exponent = bitcast<vec3<u32>>(v) & vec3<u32>(0x7f800000u);
    return select(v, vec3<f32>(0.0), exponent == vec3<u32>(0x7f800000u));
}

// `a` after adding the sample (`total`, `single`) as sample number
// `count` (1 for the first pass).
fn accumulate(a: Accum, total: vec3<f32>, single: vec3<f32>, count: u32) -> Accum {
    let x = finite_or_zero(total);
    let s = finite_or_zero(single);
    let n = f32(count);
    let delta = x - a.mean.xyz;
    let mean = a.mean.xyz + delta / n;
    let m2 = a.m2.xyz + delta * (x - mean);
    let single_mean = a.single_mean.xyz + (s - a.single_mean.xyz) / n;
    return Accum(vec4<f32>(mean, 0.0), vec4<f32>(m2, 0.0), vec4<f32>(single_mean, 0.0));
}
