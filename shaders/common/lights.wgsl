// External lights in the form the estimators use (src/doc/method.md §1). Mirrors
// src/physics/lights.rs: what one light delivers at a point, before
// attenuation.

// From Rust (the generated prelude, src/gpu/shaders.rs): the smallest
// squared distance to a point light, `MIN_DIST2`
// (crate::physics::lights::MIN_DIST2), and the offset along an axis beyond
// which a light is far, `FAR_LIGHT` (crate::physics::lights::FAR_LIGHT).

// The light arriving at a point from one external light (`LightSample`).
struct LightSample {
    // Unit direction in which the light travels at the point.
    travel: vec3<f32>,
    // Distance to the light along `-travel` (BIG for a sun).
    distance: f32,
    // Unattenuated irradiance at the point, RGB.
    irradiance: vec3<f32>,
}

// Number of external lights.
fn light_count() -> u32 {
    return scene.sun_count + scene.point_count;
}

// Light `i`'s unattenuated arrival at `p` (one step of
// `Lights::for_each_at`).
fn light_at(i: u32, p: vec3<f32>) -> LightSample {
    let l = lights[i];
    if l.kind == LIGHT_SUN {
        return LightSample(l.vector, BIG, l.power);
    }
    let v = p - l.vector;
    let s = max_element(abs(v));
    if s <= FAR_LIGHT {
        let d2 = max(dot(v, v), MIN_DIST2);
        let d = sqrt(d2);
        return LightSample(v / d, d, l.power / d2);
    }
    // A far light (`point_sample`): `|v|²` would overflow.
    let u = v / s;
    let lu = length(u);
    let d = s * lu;
    return LightSample(u / lu, min(d, BIG), far_irradiance(l.power, d));
}

// `power / d²` for a distance `d` whose square overflows, without forming
// any quantity out of range: with `d = m·2^e` (`m` in [0.5, 1)), it is
// `((power·2^-e) / m²)·2^-e`, and `ldexp` is exact. The CPU's
// `power / s / lu / s / lu` is not safe here: a hardware driver may turn
// the divisions into multiplications by reciprocals and regroup them, and
// `(1/d)²` (10⁻³⁹ for a light at 3·10¹⁹) is subnormal, which the GPU
// flushes to zero: the H200's Vulkan driver lit nothing from such a light.
fn far_irradiance(power: vec3<f32>, d: f32) -> vec3<f32> {
    let f = frexp(d);
    let e = vec3<i32>(-f.exp);
    return ldexp(ldexp(power, e) / (f.fract * f.fract), e);
}

// The environment (src/physics/environment.rs): radiance, sampling and pdf
// of a constant sky or a latitude–longitude map, whose vertices and tables
// are in `env_data` (`gpu_environment`).

// Whether the scene has a sky that is not black (`Lights::sky`).
fn env_present() -> bool {
    return scene.env_kind != ENV_NONE;
}

// World direction to the map's frame (`EnvMap::to_local`).
fn env_to_local(d: vec3<f32>) -> vec3<f32> {
    let c = scene.env_cos;
    let s = scene.env_sin;
    return vec3<f32>(c * d.x - s * d.z, d.y, s * d.x + c * d.z);
}

// The map's frame to world (`EnvMap::to_world`).
fn env_to_world(d: vec3<f32>) -> vec3<f32> {
    let c = scene.env_cos;
    let s = scene.env_sin;
    return vec3<f32>(c * d.x + s * d.z, d.y, -s * d.x + c * d.z);
}

// Continuous vertex coordinates of local direction `d` (`EnvMap::grid_coords`).
fn env_grid_coords(d: vec3<f32>) -> vec2<f32> {
    let w = f32(scene.env_width);
    let h = f32(scene.env_height);
    var u = atan2(d.x, -d.z) / (2.0 * PI) - 0.5 / w;
    u -= floor(u);
    let v = acos(clamp(d.y, -1.0, 1.0)) / PI;
    return vec2<f32>(min(u * w, w), v * (h - 1.0));
}

fn env_vertex(i: u32, j: u32) -> vec3<f32> {
    let k = 3u * (j * (scene.env_width + 1u) + i);
    return vec3<f32>(env_data[k], env_data[k + 1u], env_data[k + 2u]);
}

// Radiance arriving from world direction `from` (`Environment::radiance`).
fn env_radiance(towards: vec3<f32>) -> vec3<f32> {
    if scene.env_kind == ENV_CONSTANT {
        return scene.env_radiance;
    }
    if scene.env_kind != ENV_MAP {
        return vec3<f32>(0.0);
    }
    let xy = env_grid_coords(env_to_local(towards));
    let ix = min(u32(xy.x), scene.env_width - 1u);
    let iy = min(u32(xy.y), scene.env_height - 2u);
    let fx = xy.x - f32(ix);
    let fy = xy.y - f32(iy);
    let top = env_vertex(ix, iy) * (1.0 - fx) + env_vertex(ix + 1u, iy) * fx;
    let bottom = env_vertex(ix, iy + 1u) * (1.0 - fx) + env_vertex(ix + 1u, iy + 1u) * fx;
    return top * (1.0 - fy) + bottom * fy;
}

// The pdf in solid angle of `env_sample` drawing `from` (`Environment::pdf`).
fn env_pdf(towards: vec3<f32>) -> f32 {
    if scene.env_kind == ENV_CONSTANT {
        return 1.0 / (4.0 * PI);
    }
    let xy = env_grid_coords(env_to_local(towards));
    let i = min(u32(xy.x), scene.env_width - 1u);
    let j = min(u32(xy.y), scene.env_height - 2u);
    return env_data[scene.env_cells + j * scene.env_width + i] * scene.env_inv_total;
}

// The first index in `env_data[start .. start + n]` whose value exceeds
// `u` (at most `n - 1`): `partition_point(|c| c <= u)`.
fn env_search(start: u32, n: u32, u: f32) -> u32 {
    var lo = 0u;
    var hi = n;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if env_data[start + mid] <= u {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return min(lo, n - 1u);
}

// A direction towards the sky from (u1, u2) and its pdf (`Environment::sample`);
// pdf 0 where nothing can be drawn.
struct EnvSample {
    towards: vec3<f32>,
    pdf: f32,
}

fn env_sample(u1: f32, u2: f32) -> EnvSample {
    if scene.env_kind == ENV_CONSTANT {
        let z = 1.0 - 2.0 * u1;
        let r = sqrt(max(1.0 - z * z, 0.0));
        let phi = 2.0 * PI * u2;
        return EnvSample(vec3<f32>(r * cos(phi), r * sin(phi), z), 1.0 / (4.0 * PI));
    }
    if scene.env_kind != ENV_MAP || scene.env_inv_total <= 0.0 {
        return EnvSample(vec3<f32>(0.0, 1.0, 0.0), 0.0);
    }
    let w = scene.env_width;
    let rows = scene.env_height - 1u;
    let j = env_search(scene.env_rows, rows, u1);
    let lo = select(0.0, env_data[scene.env_rows + j - 1u], j > 0u);
    let span = env_data[scene.env_rows + j] - lo;
    let ru = select(0.5, clamp((u1 - lo) / span, 0.0, 1.0), span > 0.0);
    let row = scene.env_cols + j * w;
    let i = env_search(row, w, u2);
    let clo = select(0.0, env_data[row + i - 1u], i > 0u);
    let cspan = env_data[row + i] - clo;
    let cu = select(0.5, clamp((u2 - clo) / cspan, 0.0, 1.0), cspan > 0.0);
    let weight = env_data[scene.env_cells + j * w + i];
    if weight <= 0.0 {
        return EnvSample(vec3<f32>(0.0, 1.0, 0.0), 0.0);
    }
    let c0 = cos(PI * f32(j) / f32(rows));
    let c1 = cos(PI * f32(j + 1u) / f32(rows));
    let cos_t = clamp(c0 + (c1 - c0) * ru, -1.0, 1.0);
    let sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
    let u = (f32(i) + cu) / f32(w) + 0.5 / f32(w);
    let phi = 2.0 * PI * u;
    let local = vec3<f32>(sin(phi) * sin_t, cos_t, -cos(phi) * sin_t);
    return EnvSample(env_to_world(local), weight * scene.env_inv_total);
}

// The sky behind the medium seen along `dir` when it is drawn as the
// background, zero otherwise (`background`).
fn env_background(dir: vec3<f32>) -> vec3<f32> {
    if scene.env_background == 0u {
        return vec3<f32>(0.0);
    }
    return env_radiance(dir);
}
