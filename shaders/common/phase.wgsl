// The Henyey–Greenstein phase function (src/doc/method.md §1). Mirrors
// src/physics/phase.rs: `P(μ) = (1 − g²) / (4π (1 + g² − 2gμ)^{3/2})`, μ the
// cosine between the directions light travels before and after scattering.

// From Rust (the generated prelude, src/gpu/shaders.rs): `PI`
// (std::f32::consts::PI) and the |g| below which sampling is isotropic,
// `HG_ISOTROPIC_EPS` (crate::physics::phase::ISOTROPIC_EPS).

// `P(μ)` in 1/sr (`hg`).
fn hg(g: f32, cos_theta: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    return (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
}

// A cosine with density ∝ P(μ) (`sample_hg_cos`).
fn sample_hg_cos(g: f32, u: f32) -> f32 {
    if abs(g) < HG_ISOTROPIC_EPS {
        return 1.0 - 2.0 * u;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    return clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
}

// A scattered direction around unit `dir` with solid-angle pdf
// `hg(g, dir · result)` (`sample_hg`).
fn sample_hg(g: f32, dir: vec3<f32>, u1: f32, u2: f32) -> vec3<f32> {
    return frame_from_spherical(dir, sample_hg_cos(g, u1), 2.0 * PI * u2);
}
