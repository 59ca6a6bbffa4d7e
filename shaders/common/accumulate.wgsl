// Progressive accumulation on the GPU: one sample per pixel per pass,
// added to a running mean and sum of squared deviations (Welford's update,
// which stays accurate in f32 over many passes, unlike raw sums of
// squares). Plays the role of src/render/film.rs (`Film::add_pass`): a
// non-finite channel counts as a zero sample.
// Keep `Accum` in sync with `GpuAccum` in src/gpu/mirrors.rs.

// One pixel's running statistics: `mean` and `m2` of the full estimate,
// `single_mean` of its single-scattering part; `mean.w` counts the passes
// whose invocation the driver's loop cap cut short (`loops_cut_short`),
// `m2.w` is the sum of squared deviations of the channels' mean (whose
// running mean is that of `mean.xyz`: what a balanced light-set schedule
// pools, src/render/renewal.rs), `single_mean.w` is unused.
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

// Whether a loop of this invocation has been ended by the driver rather
// than by its own condition, asked once the pass's work is done. Mesa's
// llvmpipe (lavapipe) ends every loop of an invocation once the loops'
// iterations add up to 65 535 in all (`LP_MAX_TGSI_LOOP_ITERATIONS`, one
// counter per invocation), which leaves the estimate silently short. A
// loop of two iterations, its bound read at run time so that no compiler
// unrolls it, then stops after one: that is the sign. `runtime` is any
// value read from a buffer (the pass's sample count): it only keeps the
// bound unknown to the compiler. Hardware drivers have no such cap.
fn loops_cut_short(runtime: u32) -> bool {
    let bound = select(2u, 3u, runtime == 0xffffffffu);
    var n = 0u;
    loop {
        n += 1u;
        if n >= bound {
            break;
        }
    }
    return n < bound;
}

// `a` after adding the sample (`total`, `single`) as sample number
// `count` (1 for the first pass); `cut` counts the pass in `mean.w` as
// one that the driver's loop cap cut short (`loops_cut_short`).
fn accumulate(a: Accum, total: vec3<f32>, single: vec3<f32>, count: u32, cut: bool) -> Accum {
    let x = finite_or_zero(total);
    let s = finite_or_zero(single);
    let n = f32(count);
    let delta = x - a.mean.xyz;
    let mean = a.mean.xyz + delta / n;
    let m2 = a.m2.xyz + delta * (x - mean);
    let third = vec3<f32>(1.0 / 3.0);
    let grey = dot(x, third);
    let grey_m2 = a.m2.w + (grey - dot(a.mean.xyz, third)) * (grey - dot(mean, third));
    let single_mean = a.single_mean.xyz + (s - a.single_mean.xyz) / n;
    let cut_passes = a.mean.w + select(0.0, 1.0, cut);
    return Accum(
        vec4<f32>(mean, cut_passes),
        vec4<f32>(m2, grey_m2),
        vec4<f32>(single_mean, 0.0),
    );
}
