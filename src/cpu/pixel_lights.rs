//! Which internal lights make a pixel, and by how much: a deterministic
//! estimate of each light's part of the internal-light terms (`L₀`'s
//! reconstruction and `L₁`, [method §6](crate::doc::method)) along one camera ray, for the
//! previewer's "lights of this pixel" mode.
//!
//! The window of the ray is cut into [`STEPS`] midpoints. At each, the
//! camera-side transmittance comes from a midpoint quadrature of the
//! extinction; each light within reach adds its kernel-reconstruction weight
//! times the part of `J` that `L₀` reconstructs (what the walks carried
//! through a collision, times the chance of one from the point) and its
//! single-scatter term `V_i b P T J / (r² + h²)`, with the light-side
//! transmittance from a coarser quadrature ([`SHADOW_STEPS`] points).
//! Luminance-like sums of the RGB parts are normalised to shares.
//! `L₁`'s part is attributed by the note's point-light form for both
//! [`crate::physics::internal::sources::L1Form`]s: the field form spreads each
//! light's `J` over its kernel, which changes the shares of neighbouring
//! lights little and would cost a volume integral per pixel to follow.

use glam::Vec3;

use crate::physics::internal::chances::collision_probability;

use crate::physics::internal::clock::{march_clock, Clock, ClockMarch, ClockRay};
use crate::physics::internal::sources::InternalLights;
use crate::physics::phase;
use crate::physics::sh::{sh_basis, MAX_COUNT};
use crate::physics::volume::{DensityField, Volume};

/// Points along the camera ray's window.
pub const STEPS: usize = 48;
/// Points along each light-to-ray segment.
pub const SHADOW_STEPS: usize = 12;

fn optical_depth<D: DensityField>(vol: &Volume<D>, a: Vec3, b: Vec3, steps: usize) -> Vec3 {
    let d = b - a;
    let mut sum = 0.0;
    for s in 0..steps {
        sum += vol
            .density
            .density(a + d * ((s as f32 + 0.5) / steps as f32));
    }
    vol.optics.sigma_t * (sum * d.length() / steps as f32)
}

/// The lights that contribute to the camera ray `eye + t dir`, with their
/// shares (summing to one), largest first.
pub fn light_shares<D: DensityField>(
    vol: &Volume<D>,
    cache: &InternalLights,
    eye: Vec3,
    dir: Vec3,
) -> Vec<(usize, f32)> {
    let Some((t_in, t_out)) = vol.clip(eye, dir) else {
        return Vec::new();
    };
    let x = eye + dir * t_in;
    let len = t_out - t_in;
    let clock = cache.params.clock;
    let ray = ClockRay {
        clock,
        s_star: cache.s_star,
        origin: x,
        dir,
        t_exit: len,
    };
    let window = match march_clock(vol, &ray, 0.0, len, cache.s_star) {
        ClockMarch::Reached(t) => t,
        ClockMarch::Exhausted(_) => len,
    };
    if window <= 0.0 {
        return Vec::new();
    }
    let n = -dir;
    let h1 = cache.softening;
    let dt = window / STEPS as f32;
    let mut share = vec![0.0f32; cache.len()];
    let mut basis = [0.0f32; MAX_COUNT];
    sh_basis(cache.sh_order(), n, &mut basis);
    let mut tau = Vec3::ZERO;
    for s in 0..STEPS {
        let t = (s as f32 + 0.5) * dt;
        let y = x + dir * t;
        let rho = vol.density.density(y);
        tau += vol.optics.sigma_t * rho * (0.5 * dt);
        let tr = (-tau).exp();
        tau += vol.optics.sigma_t * rho * (0.5 * dt);
        let lum = |v: Vec3| v.x + v.y + v.z;
        // Reconstruction weights of the lights within h.
        let mut weights = Vec::new();
        let mut den = 0.0f32;
        cache.for_each_kernel_weight(y, |i, k| {
            weights.push((i, k));
            den += k;
        });
        let scale_y = cache.reconstruction_scale(rho);
        if den > 0.0 && scale_y > 0.0 {
            // The collided part is stored per unit chance of the collision.
            let chance = collision_probability(vol, cache.s_star, y, dir);
            for (i, k) in weights {
                let j = cache.eval_scattered_with(i, &basis) * chance;
                share[i] += lum(tr * j) * k * cache.recon_scale[i] * scale_y / den * dt;
            }
        }
        if rho <= 0.0 {
            continue;
        }
        let b = cache.scatter * rho;
        for (i, l) in cache.lights.iter().enumerate() {
            let to_y = y - l.position;
            let r = to_y.length();
            if r <= 0.0 || (clock == Clock::Geometric && t + r > cache.s_star) {
                continue;
            }
            let tau_l = optical_depth(vol, l.position, y, SHADOW_STEPS);
            // Grey optical depths: σ_t's largest channel, the clock's rate.
            if clock == Clock::OpticalDepth
                && tau.max_element() + tau_l.max_element() > cache.s_star
            {
                continue;
            }
            let nl = to_y / r;
            let j = cache.eval_j(i, nl);
            let p = phase::hg(cache.g, nl.dot(n));
            let c = b * tr * (-tau_l).exp() * j * (l.weight * p / (r * r + h1 * h1)) * dt;
            share[i] += lum(c);
        }
    }
    let total: f32 = share.iter().sum();
    if total <= 0.0 || !total.is_finite() {
        return Vec::new();
    }
    let mut out: Vec<(usize, f32)> = share
        .into_iter()
        .enumerate()
        .filter(|(_, s)| *s > 0.0)
        .map(|(i, s)| (i, s / total))
        .collect();
    out.sort_by(|a, b| b.1.total_cmp(&a.1));
    out
}
