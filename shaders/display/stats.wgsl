// The display pass's statistics entry point (see
// shaders/display/main.wgsl): one workgroup reduces every pixel to four
// means, written to `stats`: luminance of the first buffer's mean, its
// luminance's variance of the mean, the squared difference of the two
// buffers averaged over channels, and the second buffer's channel mean;
// then, in `stats[1].x`, the sum over pixels of the first buffer's passes
// that the driver's loop cap cut short (`mean.w`, see
// shaders/common/accumulate.wgsl).

const STATS_THREADS: u32 = 256u;

@group(0) @binding(3) var<storage, read_write> stats: array<vec4<f32>>;

var<workgroup> partial: array<vec4<f32>, STATS_THREADS>;
var<workgroup> partial_cut: array<f32, STATS_THREADS>;

@compute @workgroup_size(STATS_THREADS)
fn display_stats(@builtin(local_invocation_index) t: u32) {
    let count = params.width * params.height;
    let lum = vec3<f32>(0.2126, 0.7152, 0.0722);
    let n = f32(params.samples);
    var var_scale = 0.0;
    if params.samples >= 2u {
        var_scale = 1.0 / (n * (n - 1.0));
    }
    var acc = vec4<f32>(0.0);
    var cut = 0.0;
    for (var i = t; i < count; i += STATS_THREADS) {
        let a = accum_a[i];
        cut += a.mean.w;
        let b = accum_b[i].mean.xyz;
        let d = a.mean.xyz - b;
        acc += vec4<f32>(
            dot(a.mean.xyz, lum),
            dot(max(a.m2.xyz, vec3<f32>(0.0)), lum) * var_scale,
            dot(d, d) / 3.0,
            (b.x + b.y + b.z) / 3.0,
        );
    }
    partial[t] = acc;
    partial_cut[t] = cut;
    workgroupBarrier();
    for (var s = STATS_THREADS / 2u; s > 0u; s = s / 2u) {
        if t < s {
            partial[t] += partial[t + s];
            partial_cut[t] += partial_cut[t + s];
        }
        workgroupBarrier();
    }
    if t == 0u {
        stats[0] = partial[0] / f32(max(count, 1u));
        stats[1] = vec4<f32>(partial_cut[0], 0.0, 0.0, 0.0);
    }
}
