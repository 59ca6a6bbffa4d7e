//! The final gather of the internal-lights method (METHOD.md §6): the
//! radiance at the point `x` where a camera ray enters the medium's box,
//! `L ≈ L₀ + L₁`, from a window of the path-length clock that starts at `x`.
//!
//! One call is one unbiased estimate *given the cached internal lights*,
//! so passes average to the method's image; its parts are:
//!
//! - **single**: the `k = 0` part of `L₀`, `∫ T S₁ dt` over the window,
//!   by spectral tracking to one real collision and next-event estimation
//!   to the external lights (the reference estimator stopped at one
//!   scattering and at the window's end).
//! - **reconstructed**: the `k ≥ 1` part of `L₀`, `∫ T Ĵ dt` with `Ĵ` the
//!   kernel reconstruction of [`InternalLights::reconstruct_multi`], at
//!   stratified points of the window with ratio-tracked transmittance.
//! - **internal**: `L₁`, single scatter of the internal lights with the
//!   bounded kernel `1/(r² + h₁²)` (`h₁`: [`InternalLights::softening`])
//!   and the window condition (clock from `x`
//!   to `y` plus clock from `y` to `x_i` at most `s*`). Each sample draws
//!   one light: a cluster with probability `∝ P_c / (d_c² + h²)`
//!   (`P_c`: the cluster's power `Σ V_i J̄_i`, `d_c`: its distance from the
//!   window's segment of the ray), then a light of the cluster `∝ V_i J̄_i`;
//!   then a point on the ray by equiangular sampling about the light, whose
//!   density is proportional to the kernel `1/(r² + h²)` itself, so that
//!   the kernel cancels; then both transmittances by ratio tracking.
//!   Every light with `J̄_i > 0` has a positive probability, so the
//!   estimate is unbiased for the sum over the cached lights.

use glam::Vec3;

use super::gated_walk::{march_clock, Clock, ClockMarch};
use super::internal::InternalLights;
use super::lights::Lights;
use super::phase;
use super::reference::single_scatter_source;
use super::rng::Rng;
use super::tracking::{free_flight, transmittance};
use super::volume::{DensityField, Volume};

/// One gather estimate, by part.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GatherSample {
    /// `L₀`'s `k = 0` part: single scatter inside the window.
    pub single: Vec3,
    /// `L₀`'s `k ≥ 1` part: the reconstructed `J` along the ray.
    pub reconstructed: Vec3,
    /// `L₁`: single scatter of the internal lights.
    pub internal: Vec3,
}

impl GatherSample {
    /// `L₀ + L₁`.
    pub fn total(&self) -> Vec3 {
        self.single + self.reconstructed + self.internal
    }
}

/// The clock's advance along the ray from `origin` (inside or on the box)
/// over `[0, t]`, `t ≤ t_exit`.
#[inline]
fn clock_to<D: DensityField>(
    vol: &Volume<D>,
    clock: Clock,
    origin: Vec3,
    dir: Vec3,
    t: f32,
    t_exit: f32,
) -> f32 {
    match clock {
        Clock::Geometric => t,
        Clock::OpticalDepth => {
            match march_clock(vol, clock, origin, dir, 0.0, t_exit, t, f32::INFINITY) {
                ClockMarch::Exhausted(d) => d,
                ClockMarch::Reached(_) => f32::INFINITY,
            }
        }
    }
}

/// Distance from `p` to the segment `a + t d`, `t ∈ [0, len]` (`d` unit).
#[inline]
fn distance_to_segment(p: Vec3, a: Vec3, d: Vec3, len: f32) -> f32 {
    let t = (p - a).dot(d).clamp(0.0, len);
    (p - (a + d * t)).length()
}

/// One estimate of `L₀ + L₁` for the camera ray `eye + t dir` (`dir` unit),
/// with `samples` stratified points for the reconstructed part and
/// `samples` internal-light samples.
pub fn gather<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    cache: &InternalLights,
    eye: Vec3,
    dir: Vec3,
    samples: u32,
    rng: &mut Rng,
) -> GatherSample {
    let mut out = GatherSample::default();
    let Some((t_in, t_out)) = vol.clip(eye, dir) else {
        return out;
    };
    let x = eye + dir * t_in;
    let len = t_out - t_in;
    let s_star = cache.s_star;
    let clock = cache.params.clock;
    // The window's end along the ray.
    let window = match march_clock(vol, clock, x, dir, 0.0, len, len, s_star) {
        ClockMarch::Reached(t) => t,
        ClockMarch::Exhausted(_) => len,
    };
    if window <= 0.0 {
        return out;
    }
    let n = -dir;

    // L₀, k = 0: one collision inside the window, next-event estimation.
    let mut weight = Vec3::ONE;
    if let Some(t) = free_flight(vol, x, dir, 0.0, window, &mut weight, rng) {
        let y = x + dir * t;
        out.single = weight * vol.optics.albedo * single_scatter_source(vol, lights, y, n, rng);
    }

    let samples = samples.max(1);
    // L₀, k ≥ 1: stratified points, ratio-tracked transmittance.
    let step = window / samples as f32;
    for j in 0..samples {
        let t = (j as f32 + rng.next_f32()) * step;
        let y = x + dir * t;
        let rho = vol.density.density(y);
        let j_hat = cache.reconstruct_multi(y, n, rho);
        if j_hat == Vec3::ZERO {
            continue;
        }
        let tr = transmittance(vol, x, dir, t, rng);
        out.reconstructed += tr * j_hat * step;
    }

    // L₁: internal lights.
    if cache.live_clusters.is_empty() {
        return out;
    }
    let h = cache.softening;
    let h2 = h * h;
    let grid = &cache.clusters;
    let mut cdf: Vec<(u32, f32)> = Vec::with_capacity(cache.live_clusters.len());
    let mut total = 0.0f32;
    for &c in &cache.live_clusters {
        let (lo, hi) = grid.cell_box(c as usize);
        let centre = 0.5 * (lo + hi);
        let half_diag = 0.5 * (hi - lo).length();
        if clock == Clock::Geometric && (centre - x).length() - half_diag > s_star {
            continue;
        }
        let d = (distance_to_segment(centre, x, dir, window) - half_diag).max(0.0);
        total += cache.cluster_power[c as usize] / (d * d + h2);
        cdf.push((c, total));
    }
    if total <= 0.0 {
        return out;
    }
    let inv_samples = 1.0 / samples as f32;
    for _ in 0..samples {
        // A cluster, then a light in it.
        let u = rng.next_f32() * total;
        let k = cdf.partition_point(|&(_, w)| w <= u).min(cdf.len() - 1);
        let (c, cum) = cdf[k];
        let prev = if k == 0 { 0.0 } else { cdf[k - 1].1 };
        let p_cluster = (cum - prev) / total;
        let range = grid.cell_range(c as usize);
        let powers = &cache.light_power[range.clone()];
        let cluster_power = cache.cluster_power[c as usize];
        let mut pick = rng.next_f32() * cluster_power;
        let mut slot = powers.len() - 1;
        for (s, &p) in powers.iter().enumerate() {
            if pick < p {
                slot = s;
                break;
            }
            pick -= p;
        }
        // Rounding may leave `pick` past the end: the last light with power.
        if powers[slot] <= 0.0 {
            slot = powers.iter().rposition(|&p| p > 0.0).unwrap_or(slot);
        }
        let q = p_cluster * powers[slot] / cluster_power;
        if q <= 0.0 {
            continue;
        }
        let i = grid.ids()[range.start + slot] as usize;
        let light = &cache.lights[i];
        let xi = light.position;

        // Equiangular sampling of t ∈ [0, window] for the kernel
        // 1/(r² + h²) = 1/(D² + h² + (t − t_c)²).
        let t_c = (xi - x).dot(dir);
        let d2 = ((xi - x) - dir * t_c).length_squared() + h2;
        let dd = d2.sqrt();
        let theta_a = ((0.0 - t_c) / dd).atan();
        let theta_b = ((window - t_c) / dd).atan();
        let span = theta_b - theta_a;
        if span <= 0.0 {
            continue;
        }
        let t = (t_c + dd * (theta_a + rng.next_f32() * span).tan()).clamp(0.0, window);
        let y = x + dir * t;
        let rho_y = vol.density.density(y);
        if rho_y <= 0.0 {
            continue;
        }
        let to_y = y - xi;
        let r = to_y.length();
        if r <= 0.0 {
            continue;
        }
        let n_light = to_y / r;
        // The window condition on the total path length.
        let within = match clock {
            Clock::Geometric => t + r <= s_star,
            Clock::OpticalDepth => {
                let a = clock_to(vol, clock, x, dir, t, len);
                if a > s_star {
                    false
                } else {
                    let back = -n_light;
                    match vol.clip(y, back) {
                        Some((_, exit)) => {
                            a + clock_to(vol, clock, y, back, r.min(exit), exit) <= s_star
                        }
                        None => true,
                    }
                }
            }
        };
        if !within {
            continue;
        }
        let j = cache.eval_j(i, n_light);
        if j == Vec3::ZERO {
            continue;
        }
        let tr = transmittance(vol, x, dir, t, rng) * transmittance(vol, y, -n_light, r, rng);
        if tr == Vec3::ZERO {
            continue;
        }
        let b = cache.scatter * rho_y;
        let p = phase::hg(cache.g, n_light.dot(n));
        // V_i b P T T J / (r² + h²) / (q · pdf(t)), with
        // 1 / ((r² + h²) pdf(t)) = span / D'.
        out.internal += b * tr * j * (light.weight * p * span / dd / q * inv_samples);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::internal::{InternalLight, InternalParams};
    use crate::physics::sh::sh_count;
    use crate::physics::volume::Optics;

    /// Density 1 in the cube [−1, 1]³.
    struct Cube;

    impl DensityField for Cube {
        fn density(&self, p: Vec3) -> f32 {
            if p.abs().max_element() <= 1.0 {
                1.0
            } else {
                0.0
            }
        }
        fn bounds(&self) -> (Vec3, Vec3) {
            (Vec3::splat(-1.0), Vec3::splat(1.0))
        }
        fn max_in_box(&self, _: Vec3, _: Vec3) -> f32 {
            1.0
        }
    }

    /// One isotropic internal light in a homogeneous cube gathers, on
    /// average, to the quadrature of METHOD.md §6's `L₀` (its kernel
    /// reconstruction: `J` within `h` of the light) plus `L₁`, for both
    /// clocks (which agree here: with ρ = 1, τ = σ_t ℓ).
    #[test]
    fn one_isotropic_light_matches_quadrature() {
        let sigma = 0.6f32;
        let albedo = 0.8f32;
        let g = 0.4f32;
        let vol = Volume::new(
            Cube,
            Optics {
                sigma_t: Vec3::splat(sigma),
                albedo: Vec3::splat(albedo),
                g,
            },
            8,
        );
        let xi = Vec3::new(0.2, -0.1, 0.3);
        let v = 0.05f32;
        let j0 = Vec3::new(1.0, 0.5, 0.25);
        let h = 0.3f32;
        let s_geo = 1.6f32;
        let eye = Vec3::new(-3.0, 0.05, 0.1);
        let dir = Vec3::X;

        // Quadrature (f64) over t ∈ [0, s*] from the entry point x.
        let x = Vec3::new(-1.0, 0.05, 0.1);
        let steps = 400_000;
        let dt = s_geo as f64 / steps as f64;
        let (mut l0, mut l1) = (0.0f64, 0.0f64);
        for s in 0..steps {
            let t = (s as f64 + 0.5) * dt;
            let y = x + dir * t as f32;
            let tr = (-(sigma as f64) * t).exp();
            let r = (y - xi).length() as f64;
            if r < h as f64 {
                l0 += tr * dt;
            }
            if t + r <= s_geo as f64 {
                let n_light = (y - xi) / r as f32;
                let p = phase::hg(g, n_light.dot(-dir)) as f64;
                let h1 = (h * crate::physics::internal::L1_SOFTENING) as f64;
                l1 += tr * (albedo * sigma) as f64 * p * (-(sigma as f64) * r).exp() * v as f64
                    / (r * r + h1 * h1)
                    * dt;
            }
        }
        let expect = (l0 + l1) as f32 * j0;

        for (clock, s_star) in [
            (Clock::Geometric, s_geo),
            (Clock::OpticalDepth, sigma * s_geo),
        ] {
            let params = InternalParams {
                s_star,
                lights: 1,
                terms: 1,
                walks: 1,
                sh_order: 1,
                kernel_radius: Some(h),
                uniform_mix: 0.0,
                clock,
                seed: 0,
            };
            let count = sh_count(1);
            let mut multi = vec![Vec3::ZERO; count];
            multi[0] = j0 * (2.0 * std::f32::consts::PI.sqrt());
            let cache = InternalLights::assemble(
                &vol,
                &Lights::default(),
                &params,
                vec![InternalLight {
                    position: xi,
                    density: 1.0,
                    weight: v,
                }],
                vec![Vec3::ZERO; count],
                multi,
                Vec::new(),
                vec![Vec3::ZERO; 2],
                8.0,
            );
            let n = 400_000u32;
            let (mut sum, mut sum2) = (Vec3::ZERO.as_dvec3(), Vec3::ZERO.as_dvec3());
            for i in 0..n {
                let mut rng = Rng::for_sample(17, i, 0);
                let s = gather(&vol, &Lights::default(), &cache, eye, dir, 1, &mut rng);
                assert_eq!(s.single, Vec3::ZERO);
                let v = s.total().as_dvec3();
                sum += v;
                sum2 += v * v;
            }
            let mean = sum / n as f64;
            let var = (sum2 / n as f64 - mean * mean).max(glam::DVec3::ZERO) / n as f64;
            let se = glam::DVec3::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt());
            eprintln!("{clock:?}: gather {mean:?} ± {se:?}, quadrature {expect:?}");
            for c in 0..3 {
                let e = expect[c] as f64;
                assert!(
                    (mean[c] - e).abs() <= 4.0 * se[c] + 1e-4 * e,
                    "{clock:?} channel {c}: {} ± {} vs {e}",
                    mean[c],
                    se[c]
                );
                assert!(se[c] < 0.01 * e, "too noisy to tell: {} vs {e}", se[c]);
            }
        }
    }
}
