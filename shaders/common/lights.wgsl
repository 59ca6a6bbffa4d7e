// External lights in the form the estimators use (src/doc/method.md §1). Mirrors
// src/physics/lights.rs: what one light delivers at a point, before
// attenuation.

// Smallest squared distance to a point light (`MIN_DIST2`).
const MIN_DIST2: f32 = 1e-8;
// Beyond this offset along an axis a light is far (`FAR_LIGHT`).
const FAR_LIGHT: f32 = 1e19;

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
    return LightSample(u / lu, min(s * lu, BIG), l.power / s / lu / s / lu);
}
